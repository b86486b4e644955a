#include "phos/model/reference.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos {

long double ReferenceAdvance(long double r, double a_in, double kr_in, double h_s, const ReferenceOptions& options,
                             ReferenceStats* stats) {
  if (h_s <= 0) return r;
  const long double a = a_in, kr = kr_in, k = a + kr;
  // Dormand-Prince is stable for h k below about 3.3; far past that the step
  // size is set by stability, not accuracy. Refuse up front if even
  // stability-limited steps would exceed the budget.
  const long double min_steps = k * static_cast<long double>(h_s) / 3.3L;
  if (min_steps > static_cast<long double>(options.max_steps))
    ThrowUserError(
        "", "--integrator reference",
        "this interval is too stiff for the explicit reference (k*h = " + FormatShort(static_cast<double>(k * h_s)) +
            ", over " + std::to_string(options.max_steps) + " steps); use --integrator exact");

  auto f = [&](long double x) { return a * (1.0L - x) - kr * x; };  // Eq. 8.1
  // Butcher tableau of Dormand and Prince (1980).
  constexpr long double a21 = 1.0L / 5, a31 = 3.0L / 40, a32 = 9.0L / 40, a41 = 44.0L / 45, a42 = -56.0L / 15,
                        a43 = 32.0L / 9, a51 = 19372.0L / 6561, a52 = -25360.0L / 2187, a53 = 64448.0L / 6561,
                        a54 = -212.0L / 729, a61 = 9017.0L / 3168, a62 = -355.0L / 33, a63 = 46732.0L / 5247,
                        a64 = 49.0L / 176, a65 = -5103.0L / 18656;
  constexpr long double b1 = 35.0L / 384, b3 = 500.0L / 1113, b4 = 125.0L / 192, b5 = -2187.0L / 6784, b6 = 11.0L / 84;
  // Difference between the 5th- and 4th-order weights: the error estimate.
  constexpr long double e1 = b1 - 5179.0L / 57600, e3 = b3 - 7571.0L / 16695, e4 = b4 - 393.0L / 640,
                        e5 = b5 + 92097.0L / 339200, e6 = b6 - 187.0L / 2100, e7 = -1.0L / 40;

  long double t = 0, H = h_s;
  long double step = std::min<long double>(H, k > 0 ? 0.01L / k : H);
  long double k1 = f(r);
  std::int64_t steps = 0;
  ReferenceStats local;
  while (t < H) {
    if (++steps > options.max_steps)
      ThrowUserError(
          "", "--integrator reference",
          "more than " + std::to_string(options.max_steps) + " steps for one interval; use --integrator exact");
    step = std::min(step, H - t);
    long double k2 = f(r + step * (a21 * k1));
    long double k3 = f(r + step * (a31 * k1 + a32 * k2));
    long double k4 = f(r + step * (a41 * k1 + a42 * k2 + a43 * k3));
    long double k5 = f(r + step * (a51 * k1 + a52 * k2 + a53 * k3 + a54 * k4));
    long double k6 = f(r + step * (a61 * k1 + a62 * k2 + a63 * k3 + a64 * k4 + a65 * k5));
    long double next = r + step * (b1 * k1 + b3 * k3 + b4 * k4 + b5 * k5 + b6 * k6);
    long double k7 = f(next);  // first-same-as-last: k1 of the next step
    local.evaluations += 6;
    long double error = step * (e1 * k1 + e3 * k3 + e4 * k4 + e5 * k5 + e6 * k6 + e7 * k7);
    long double scale =
        options.absolute_tolerance + options.relative_tolerance * std::max(std::fabs(r), std::fabs(next));
    long double ratio = std::fabs(error) / scale;
    if (ratio <= 1.0L) {
      t += step;
      r = next;
      k1 = k7;
      ++local.accepted;
    } else {
      ++local.rejected;
    }
    long double factor = ratio > 0 ? 0.9L * std::pow(ratio, -0.2L) : 5.0L;
    step *= std::clamp(factor, 0.2L, 5.0L);
  }
  if (stats) {
    stats->accepted += local.accepted;
    stats->rejected += local.rejected;
    stats->evaluations += local.evaluations;
  }
  return r;
}

}  // namespace phos
