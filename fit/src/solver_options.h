#pragma once
// The Ceres settings every curve fit in fit/ shares: small dense problems
// (tens of parameters at most, up to thousands of residuals), so dense QR,
// one thread, no logging, and convergence judged relative to the cost.

#include <ceres/ceres.h>

namespace phos {

// Ceres reports through glog, and glog writes warnings and errors (a solve
// ended by invalid steps, a rank-deficient covariance) to stderr whatever
// Solver::Options::logging_type says, with a "Logging before
// InitGoogleLogging" banner: a page of log lines under phos's own one-line
// message. phos says what went wrong in its own words, so glog keeps only
// FATAL (a broken invariant of Ceres's, which aborts). Once per process.
inline void SilenceCeresLogging() {
  static const bool silenced = [] {
    FLAGS_minloglevel = google::GLOG_FATAL;
    return true;
  }();
  (void)silenced;
}

// `function_tolerance`: stop when the cost changes by less than this
// fraction of itself. 1e-10 is far below what the noise of a measured curve
// can tell apart; exact-data tests get tighter values. The gradient
// tolerance and the initial trust region are absolute: the fits solve in
// scaled units (curve.h: CurveScale), where they are of order 1.
inline ceres::Solver::Options SmallDenseSolverOptions(int max_iterations, double function_tolerance) {
  SilenceCeresLogging();
  ceres::Solver::Options options;
  options.linear_solver_type = ceres::DENSE_QR;
  options.max_num_iterations = max_iterations;
  options.function_tolerance = function_tolerance;
  options.gradient_tolerance = 1e-14;
  options.parameter_tolerance = 1e-12;
  options.logging_type = ceres::SILENT;
  options.minimizer_progress_to_stdout = false;
  options.num_threads = 1;
  return options;
}

// The covariance the curve fits compute (dense SVD: a component or level
// that vanished, a rank-deficient direction, must not fail the rest).
inline ceres::Covariance::Options SmallDenseCovarianceOptions() {
  SilenceCeresLogging();
  ceres::Covariance::Options options;
  options.algorithm_type = ceres::DENSE_SVD;
  options.null_space_rank = -1;
  return options;
}

}  // namespace phos
