#pragma once
// Non-negative least squares for the handful of linear parameters of a
// variable-projection fit (amplitudes of at most 4 exponentials, plus an
// optional unconstrained background), on the normal equations G x = b.
//
// With p <= 5 unknowns, every support set S of the constrained ones is tried
// (at most 16): the optimum is the unconstrained solution on its own support,
// and it is the best of the candidates whose constrained entries are >= 0.
// This is exact, needs no iteration, and costs nothing next to forming G.

#include <Eigen/Core>

namespace phos {

// At most 5 unknowns: fixed-capacity storage, so solving allocates nothing.
using SmallMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 5, 5>;
using SmallVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 5, 1>;

// Up to 64 x 64, for the few dense decompositions fit/ does itself
// (conditions, covariances of a few dozen parameters). A bounded type of our
// own, never Eigen::MatrixXd: phos is built for x86-64-v3 and Debian's Ceres
// is not, and an Eigen template instantiated for MatrixXd in both (the
// JacobiSVD that Ceres's BDCSVD calls for its covariance, say) is one symbol
// at link time: whichever copy wins corrupts the other's memory.
using BoundedMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 64, 64>;

struct SmallNnlsResult {
  SmallVector x;
  double cost = 0;  // 0.5 x'Gx - b'x (add 0.5 y'y for the half squared residual)
  bool ok = false;
};

// Minimizes 0.5 x'Gx - b'x subject to x[i] >= 0 for i < constrained; the
// remaining entries are free.
SmallNnlsResult SolveSmallNnls(const SmallMatrix& G, const SmallVector& b, int constrained);

}  // namespace phos
