#pragma once
// The Ceres settings every curve fit in fit/ shares: small dense problems
// (tens of parameters at most, up to thousands of residuals), so dense QR,
// one thread, no logging, and convergence judged relative to the cost.

#include <ceres/ceres.h>

namespace phos {

// `function_tolerance`: stop when the cost changes by less than this
// fraction of itself. 1e-10 is far below what the noise of a measured curve
// can tell apart; exact-data tests get tighter values.
inline ceres::Solver::Options SmallDenseSolverOptions(int max_iterations, double function_tolerance) {
  ceres::Solver::Options options;
  options.linear_solver_type = ceres::DENSE_QR;
  options.max_num_iterations = max_iterations;
  options.function_tolerance = function_tolerance;
  options.gradient_tolerance = 1e-14;
  options.parameter_tolerance = 1e-12;
  options.logging_type = ceres::SILENT;
  options.num_threads = 1;
  return options;
}

}  // namespace phos
