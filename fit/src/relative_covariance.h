#pragma once
// 1-sigma uncertainties and the condition number of a solved Ceres problem,
// computed in relative terms.
//
// ceres::Covariance inverts J'J in the problem's own units. The excitation
// and joint problems mix a signal S of about 1e4 DN/s with rates a of about
// 1e-2 /s, so J'J spans 1e12 and more before the data's own conditioning
// counts; a rank-revealing inverse then drops real, merely ill-scaled
// directions and reports uncertainties far too small. Here every parameter
// of a `relative` block is scaled by itself (d residual / d log p), which
// makes the matrix's spread the data's alone, and the inverse is taken on
// that; a parameter at 0 (at its bound) is left out, with no uncertainty.

#include <vector>

#include <ceres/ceres.h>

namespace phos {

struct CovarianceBlock {
  double* values;
  int size;
  // The first `relative` values are scales (relative terms, left out at 0);
  // the rest are offsets (a background), taken in their own units.
  int relative;
};

struct RelativeCovariance {
  bool ok = false;
  std::vector<std::vector<double>> stderr_per_block;  // same shape as the blocks; 0 where left out
  double condition_number = 0;                        // of the weighted Jacobian, relative parameters
};

// `blocks` must list every free parameter block of `problem`. `chi2`: the
// reduced chi-square the covariance is scaled by (1 for known weights).
RelativeCovariance ComputeRelativeCovariance(ceres::Problem& problem, const std::vector<CovarianceBlock>& blocks,
                                             double chi2);

}  // namespace phos
