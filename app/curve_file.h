#pragma once
// A curve file (a plain text table: t, then one column per channel) as the
// curve fits under `phos fit` read it: decay-curve and charge-curve
// (app/cmd_fit_curve.cpp), schedule-curve (app/cmd_fit_schedule.cpp).

#include <optional>
#include <string>
#include <vector>

#include "phos/fit/curve.h"

namespace phos::app {

// A file's curve as the fits get it: windowed, sorted, and what was done to it.
struct LoadedCurve {
  std::string file;
  Curve curve;
  TimeOrder order;
  std::size_t samples_in_file = 0;
  std::vector<std::string> warnings;
};

// Reads `path`; keeps the samples with from_s <= t <= to_s (either may be
// absent; a window with no sample is a UserError naming --from or --to);
// sorts them by time.
LoadedCurve LoadCurveFile(const std::string& path, std::optional<double> from_s = std::nullopt,
                          std::optional<double> to_s = std::nullopt);

}  // namespace phos::app
