#pragma once
// Charge fits: the saturating growth of emission under constant light,
//
//   L(t) = Linf - (Linf - L0) exp(-k t),
//
// which Eq. 8.1 gives for one state (k = a + kr, Linf at equilibrium). L0
// and Linf enter linearly, so they are solved exactly for each rate of a
// log-spaced scan, and Ceres then refines all three (k as log k) with an
// analytic Jacobian.

#include <string>

#include "phos/fit/curve.h"

namespace phos {

struct ChargeFitOptions {
  Weighting weighting = Weighting::kNone;
  int rate_grid_size = 64;
  int max_iterations = 100;
};

struct ChargeFitSummary {
  double L0 = 0, Linf = 0, rate = 0;
  double L0_stderr = 0, Linf_stderr = 0, rate_stderr = 0;
  double rss = 0;       // plain sum of squared residuals
  int iterations = 0;
  double seconds = 0;
};

// Fits the first channel of the curve. A curve that neither grows nor falls
// toward a level (constant, or too short) is a UserError naming `where`.
ChargeFitSummary FitCharge(const Curve& curve, const ChargeFitOptions& options, const std::string& where);

}  // namespace phos
