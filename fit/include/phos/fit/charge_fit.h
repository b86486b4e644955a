#pragma once
// Charge fits: the saturating growth of emission under constant light,
//
//   L_c(t) = Linf_c - (Linf_c - L0_c) exp(-k t),
//
// which Eq. 8.1 gives for one state (k = a + kr, Linf at equilibrium), for
// one or more channels (bands, colours, detectors) that share the rate k and
// have their own levels. L0_c and Linf_c enter linearly, so they are solved
// exactly for each rate of a log-spaced scan, and Ceres then refines all of
// them (k as log k) with an analytic Jacobian.

#include <string>
#include <vector>

#include "phos/fit/curve.h"

namespace phos {

struct ChargeFitOptions {
  Weighting weighting = Weighting::kNone;
  int rate_grid_size = 64;
  int max_iterations = 100;
};

struct ChargeLevels {
  double L0 = 0, Linf = 0;
  double L0_stderr = 0, Linf_stderr = 0;
};

struct ChargeFitSummary {
  // The first channel's levels (the whole fit for one channel).
  double L0 = 0, Linf = 0, rate = 0;
  double L0_stderr = 0, Linf_stderr = 0, rate_stderr = 0;
  std::vector<ChargeLevels> levels;  // per channel; levels[0] is L0, Linf above
  double rss = 0;                    // plain sum of squared residuals, every channel
  int iterations = 0;
  double seconds = 0;
  // Whether Ceres stopped at a tolerance (CONVERGENCE) rather than at
  // max_iterations; termination is its message when not.
  bool converged = true;
  std::string termination;
};

// Fits every channel of the curve with one shared rate. A curve that neither
// grows nor falls toward a level (constant in every channel, or too short) is
// a UserError naming `where`. Times may repeat (replicates), not decrease.
ChargeFitSummary FitCharge(const Curve& curve, const ChargeFitOptions& options, const std::string& where);

}  // namespace phos
