// Times `FitDecay` on CSV curves in process, the way the comparison with R's
// fit_CWCurve times R (repeated calls after a warm-up, the median taken), and
// prints one line per file: "<file> <median ms> <rss> <components> <iterations>".
// Used by scripts/compare-luminescence.sh.
// Usage: fit_timing [--reference] COMPONENTS FILE.csv...
//   COMPONENTS 1..3: that many; 0: chosen by BIC over 1..3 (as fit_CWCurve's
//   n.components.max = 3). --reference: time FitDecayReference (Ceres) instead.

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "phos/fit/decay_fit.h"
#include "phos/util/csv.h"
#include "phos/util/error.h"

namespace {

constexpr int kTimedRuns = 21;

double MedianOf(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  const bool reference = argc > 1 && std::string(argv[1]) == "--reference";
  if (reference) --argc, ++argv;
  if (argc < 3) {
    std::fprintf(stderr, "usage: fit_timing [--reference] COMPONENTS FILE.csv...\n");
    return 2;
  }
  const auto fit_decay = reference ? phos::FitDecayReference : phos::FitDecay;
  phos::DecayFitOptions options;
  options.components = std::atoi(argv[1]);
  options.max_components = 3;
  int status = 0;
  for (int f = 2; f < argc; ++f) {
    try {
      phos::CsvTable table = phos::ReadCsv(argv[f]);
      phos::Curve curve{table.columns[0], {table.columns.at(1)}, {table.header.at(1)}};
      phos::DecayFitSummary fit = fit_decay(curve, options, argv[f]);  // warm-up
      std::vector<double> seconds;
      for (int repeat = 0; repeat < kTimedRuns; ++repeat) {
        const auto start = std::chrono::steady_clock::now();
        fit = fit_decay(curve, options, argv[f]);
        seconds.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
      }
      std::printf("%s %.4f %.10g %d %d\n", argv[f], MedianOf(seconds) * 1e3, fit.rss, fit.n_components, fit.iterations);
    } catch (const phos::UserError& e) {
      std::printf("%s - - - -\n", argv[f]);
      std::fprintf(stderr, "fit_timing: %s\n", e.what());
      status = 2;
    }
  }
  return status;
}
