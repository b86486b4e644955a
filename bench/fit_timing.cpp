// Times `FitDecay` on one CSV in process, the way the comparison with R's
// fit_CWCurve times R (repeated calls after a warm-up), and prints
// "<best ms> <rss> <components>". Used by scripts/compare-luminescence.sh.
// Usage: fit_timing FILE.csv COMPONENTS   (COMPONENTS 0: choose by BIC up to 4)

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>

#include "phos/fit/decay_fit.h"
#include "phos/util/csv.h"
#include "phos/util/error.h"

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: fit_timing FILE.csv COMPONENTS\n");
    return 2;
  }
  try {
    phos::CsvTable table = phos::ReadCsv(argv[1]);
    phos::Curve curve{table.columns[0], {table.columns.at(1)}, {table.header.at(1)}};
    phos::DecayFitOptions options;
    options.components = std::atoi(argv[2]);
    options.max_components = 4;
    phos::DecayFitSummary fit = phos::FitDecay(curve, options, argv[1]);  // warm-up
    double best = 1e30;
    for (int repeat = 0; repeat < 20; ++repeat) {
      auto start = std::chrono::steady_clock::now();
      fit = phos::FitDecay(curve, options, argv[1]);
      best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    }
    std::printf("%.4f %.10g %d\n", best * 1e3, fit.rss, fit.n_components);
  } catch (const phos::UserError& e) {
    std::fprintf(stderr, "fit_timing: %s\n", e.what());
    return 2;
  }
  return 0;
}
