#include "phos/fit/small_nnls.h"

#include <Eigen/Cholesky>
#include <limits>

#include "phos/util/error.h"

namespace phos {

SmallNnlsResult SolveSmallNnls(const SmallMatrix& G, const SmallVector& b, int constrained) {
  const int p = static_cast<int>(b.size());
  PHOS_CHECK(constrained >= 0 && constrained <= p && p <= 5);
  SmallNnlsResult best;
  best.cost = std::numeric_limits<double>::infinity();
  best.x = SmallVector::Zero(p);
  for (int mask = 0; mask < (1 << constrained); ++mask) {
    int support[5], s = 0;
    for (int i = 0; i < constrained; ++i)
      if (mask & (1 << i)) support[s++] = i;
    for (int i = constrained; i < p; ++i) support[s++] = i;
    SmallVector x = SmallVector::Zero(p);
    if (s > 0) {
      SmallMatrix Gs(s, s);
      SmallVector bs(s);
      for (int i = 0; i < s; ++i) {
        bs[i] = b[support[i]];
        for (int j = 0; j < s; ++j) Gs(i, j) = G(support[i], support[j]);
      }
      Eigen::LDLT<SmallMatrix> ldlt(Gs);
      if (ldlt.info() != Eigen::Success) continue;
      SmallVector xs = ldlt.solve(bs);
      if (!xs.allFinite()) continue;
      bool feasible = true;
      for (int i = 0; i < s; ++i) {
        if (support[i] < constrained && xs[i] < 0) feasible = false;
        x[support[i]] = xs[i];
      }
      if (!feasible) continue;
    }
    const double cost = 0.5 * x.dot(G * x) - b.dot(x);
    if (cost < best.cost) {
      best.cost = cost;
      best.x = x;
      best.ok = true;
    }
  }
  return best;
}

}  // namespace phos
