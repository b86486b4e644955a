#include "phos/fit/decay_fit.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <numeric>

#include <ceres/ceres.h>
#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>

#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/fit/small_nnls.h"
#include "solver_options.h"

namespace phos {

bool DecayFitOptions::IsValid(std::string* error) const {
  if (components < 0 || components > 4) return *error = "components must be 1 to 4 (or 0 to choose)", false;
  if (components == 0 && (max_components < 1 || max_components > 4))
    return *error = "max components must be 1 to 4", false;
  if (rate_grid_size < 8) return *error = "rate grid needs at least 8 rates", false;
  if (max_iterations < 1) return *error = "max iterations must be positive", false;
  return true;
}

namespace {

// The curve in the fit's own units: times and values divided by the
// curve's scales (ScaleOfCurve: the span, the largest |value|), then each
// channel divided by its own largest |value| so every parameter is of order
// 1, and weights multiplied by the same factor, so the weighted residuals are
// those of the scaled curve and channels weigh as they do in the data.
struct Data {
  int m = 0, C = 0;
  bool background = false;
  Eigen::ArrayXd t;
  std::vector<Eigen::ArrayXd> y, w;  // per channel
  std::vector<double> scale;         // per channel
};

// Residuals of one channel, with the analytic Jacobian. Parameter blocks:
// log rates (nc), amplitudes (nc), and the background (1) if fitted.
class ChannelDecayCost final : public ceres::CostFunction {
 public:
  ChannelDecayCost(const Data& d, int channel, int nc) : d_(d), c_(channel), nc_(nc) {
    set_num_residuals(d.m);
    mutable_parameter_block_sizes()->push_back(nc);
    mutable_parameter_block_sizes()->push_back(nc);
    if (d.background) mutable_parameter_block_sizes()->push_back(1);
  }

  bool Evaluate(double const* const* p, double* residuals, double** jacobians) const override {
    const double* theta = p[0];
    const double* A = p[1];
    const double B = d_.background ? p[2][0] : 0.0;
    const auto& w = d_.w[c_];
    // Vectorized over the samples (Eigen's packet exp): the exponentials are
    // most of the cost of a fit.
    Eigen::ArrayXd model = Eigen::ArrayXd::Constant(d_.m, B);
    Eigen::ArrayXXd e(d_.m, nc_);
    for (int i = 0; i < nc_; ++i) {
      e.col(i) = (-std::exp(theta[i]) * d_.t).exp();
      model += A[i] * e.col(i);
    }
    Eigen::Map<Eigen::ArrayXd>(residuals, d_.m) = w * (d_.y[c_] - model);
    if (jacobians == nullptr) return true;
    // Row-major m x nc blocks.
    using RowMajor = Eigen::Array<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
    if (jacobians[0] != nullptr) {
      Eigen::Map<RowMajor> J(jacobians[0], d_.m, nc_);
      for (int i = 0; i < nc_; ++i) J.col(i) = (A[i] * std::exp(theta[i])) * w * d_.t * e.col(i);
    }
    if (jacobians[1] != nullptr) {
      Eigen::Map<RowMajor> J(jacobians[1], d_.m, nc_);
      for (int i = 0; i < nc_; ++i) J.col(i) = -w * e.col(i);
    }
    if (d_.background && jacobians[2] != nullptr) Eigen::Map<Eigen::ArrayXd>(jacobians[2], d_.m) = -w;
    return true;
  }

 private:
  const Data& d_;
  int c_, nc_;
};

// The most components a decay fit places (DecayFitOptions: 1..4).
constexpr int kMaxDecayComponents = 4;

struct Fit {
  std::vector<double> theta;           // log rates
  std::vector<std::vector<double>> A;  // [c][i], fit units
  std::vector<double> B;               // [c], fit units
  double wrss = std::numeric_limits<double>::infinity();
  int iterations = 0;
  bool valid = false;
  std::string why_invalid;
  // The last refinement's: a stage only placed (never refined) counts as converged.
  bool converged = true;
  std::string termination;
};

// A'A and A'v for a tall matrix with at most 5 columns, by dot products:
// Eigen's general product would pack 1000-row panels for a 3 x 3 result.
SmallMatrix Gram(const Eigen::MatrixXd& A) {
  SmallMatrix G(A.cols(), A.cols());
  for (Eigen::Index i = 0; i < A.cols(); ++i)
    for (Eigen::Index j = 0; j <= i; ++j) G(i, j) = G(j, i) = A.col(i).dot(A.col(j));
  return G;
}
SmallVector InnerProducts(const Eigen::MatrixXd& A, const Eigen::VectorXd& v) {
  SmallVector b(A.cols());
  for (Eigen::Index i = 0; i < A.cols(); ++i) b[i] = A.col(i).dot(v);
  return b;
}

// The model's columns for given rates: e^{-k_i t} per component, then a
// column of ones for the background when it is fitted.
Eigen::MatrixXd DesignMatrix(const Data& d, const double* rates, int count) {
  Eigen::MatrixXd Phi(d.m, count + (d.background ? 1 : 0));
  for (int i = 0; i < count; ++i) Phi.col(i) = (-rates[i] * d.t).exp().matrix();
  if (d.background) Phi.col(count).setOnes();
  return Phi;
}

// Variable projection for fixed rates: amplitudes (>= 0) and background
// (free) solved exactly per channel. Fills A, B and wrss.
void Project(const Data& d, const std::vector<double>& rates, Fit* fit) {
  const int p = static_cast<int>(rates.size());
  const Eigen::MatrixXd Phi = DesignMatrix(d, rates.data(), p);
  fit->A.assign(d.C, std::vector<double>(p, 0.0));
  fit->B.assign(d.C, 0.0);
  fit->wrss = 0;
  for (int c = 0; c < d.C; ++c) {
    Eigen::MatrixXd WPhi = d.w[c].matrix().asDiagonal() * Phi;
    Eigen::VectorXd wy = (d.w[c] * d.y[c]).matrix();
    SmallNnlsResult r = SolveSmallNnls(Gram(WPhi), InnerProducts(WPhi, wy), p);
    fit->wrss += std::max(0.0, wy.squaredNorm() + 2 * r.cost);
    for (int i = 0; i < p; ++i) fit->A[c][i] = r.x[i];
    if (d.background) fit->B[c] = r.x[p];
  }
}

// The rates a new component is scanned over, their columns e^{-k t}, and
// per channel the columns' weighted inner products that do not depend on
// the components already placed: with the data, with themselves and with
// the background's column of ones. Computed once per fit, not per stage.
struct RateGrid {
  Eigen::ArrayXd rates;
  Eigen::MatrixXd columns;                                   // m x rates
  std::vector<Eigen::ArrayXd> with_y, with_self, with_ones;  // [channel][rate]
};

RateGrid MakeRateGrid(const Data& d, Eigen::ArrayXd rates) {
  RateGrid grid;
  const int n = static_cast<int>(rates.size());
  grid.columns.resize(d.m, n);
  // On a uniform time axis (the usual camera schedule) a column is powers
  // of one factor: a multiply per sample instead of an exp (relative drift
  // ~ m eps / 8, irrelevant to a scan), in 8 interleaved chains so the
  // multiplies do not wait on each other.
  bool uniform = d.m >= 2;
  for (int j = 2; j < d.m && uniform; ++j)
    uniform = std::fabs((d.t[j] - d.t[j - 1]) - (d.t[1] - d.t[0])) <= 1e-9 * (d.t[1] - d.t[0]);
  for (int g = 0; g < n; ++g) {
    if (!uniform) {
      grid.columns.col(g) = (-rates[g] * d.t).exp().matrix();
      continue;
    }
    constexpr int kChains = 8;
    const double dt = d.t[1] - d.t[0];
    double value[kChains];
    for (int l = 0; l < kChains; ++l) value[l] = std::exp(-rates[g] * (d.t[0] + l * dt));
    const double step = std::exp(-rates[g] * kChains * dt);
    double* out = grid.columns.col(g).data();
    int j = 0;
    for (; j + kChains <= d.m; j += kChains)
      for (int l = 0; l < kChains; ++l) {
        out[j + l] = value[l];
        value[l] *= step;
      }
    for (int l = 0; j < d.m; ++j, ++l) out[j] = value[l];
  }
  for (int c = 0; c < d.C; ++c) {
    const Eigen::ArrayXd w2 = d.w[c].square();
    Eigen::ArrayXd with_y(n), with_self(n), with_ones(n);
    for (int g = 0; g < n; ++g) {
      const auto column = grid.columns.col(g).array();
      with_y[g] = (w2 * column * d.y[c]).sum();
      with_self[g] = (w2 * column.square()).sum();
      with_ones[g] = (w2 * column).sum();
    }
    grid.with_y.push_back(with_y);
    grid.with_self.push_back(with_self);
    grid.with_ones.push_back(with_ones);
  }
  grid.rates = std::move(rates);
  return grid;
}

// Adds one component to `start` (rates fixed) by scanning the grid; returns
// the best projection. Each candidate only needs its own column's inner
// products with the others, so the scan is one small matrix product.
Fit ScanNewComponent(const Data& d, const std::vector<double>& rates, const RateGrid& grid) {
  const int p = static_cast<int>(rates.size());
  const int n = static_cast<int>(grid.rates.size());
  Fit best;
  std::vector<double> trial = rates;
  trial.push_back(0);
  // Columns of the components already present (and the background).
  const int q = p + (d.background ? 1 : 0);
  const Eigen::MatrixXd Phi = DesignMatrix(d, rates.data(), p);
  std::vector<double> cost(n, 0.0);
  std::vector<bool> usable(n, true);
  for (int g = 0; g < n; ++g)
    for (double r : rates)
      if (std::fabs(std::log(grid.rates[g] / r)) < 0.15) usable[g] = false;  // too close to an existing rate
  for (int c = 0; c < d.C; ++c) {
    const Eigen::VectorXd w2 = d.w[c].square().matrix();
    const Eigen::VectorXd w2y = (d.w[c].square() * d.y[c]).matrix();
    const Eigen::MatrixXd WPhi = d.w[c].matrix().asDiagonal() * Phi;
    const SmallMatrix G_old = Gram(WPhi);
    const SmallVector b_old = InnerProducts(Phi, w2y);
    const double yy = (d.w[c] * d.y[c]).matrix().squaredNorm();
    // The components present, weighted twice: their inner product with a
    // candidate's column is then a plain dot product.
    const Eigen::MatrixXd W2Phi = w2.asDiagonal() * Phi.leftCols(p);
    // New component first among the constrained ones: order [A_new, A_old..., B].
    SmallMatrix G(q + 1, q + 1);
    SmallVector b(q + 1);
    G.block(1, 1, q, q) = G_old;
    b.tail(q) = b_old;
    for (int g = 0; g < n; ++g) {
      if (!usable[g]) continue;
      G(0, 0) = grid.with_self[c][g];
      for (int i = 0; i < p; ++i) G(i + 1, 0) = G(0, i + 1) = W2Phi.col(i).dot(grid.columns.col(g));
      if (d.background) G(q, 0) = G(0, q) = grid.with_ones[c][g];
      b[0] = grid.with_y[c][g];
      SmallNnlsResult r = SolveSmallNnls(G, b, p + 1);
      cost[g] += std::max(0.0, yy + 2 * r.cost);
    }
  }
  int chosen = -1;
  for (int g = 0; g < n; ++g)
    if (usable[g] && (chosen < 0 || cost[g] < cost[chosen])) chosen = g;
  if (chosen < 0) return best;
  trial.back() = grid.rates[chosen];
  Project(d, trial, &best);
  best.theta.clear();
  for (double r : trial) best.theta.push_back(std::log(r));
  return best;
}

// The variable-projection problem Ceres refines: parameters are the log
// rates only; for each, the amplitudes (>= 0) and background are solved
// exactly (Golub and Pereyra 1973), and the Jacobian is Kaufman's (1975):
// the derivative of the residual with the amplitudes held, projected onto
// the complement of the columns in use. Fewer parameters, better conditioned
// and with no amplitude to start from: a stage converges in a few
// iterations.
class VarProCost final : public ceres::CostFunction {
 public:
  VarProCost(const Data& d, int nc) : d_(d), nc_(nc) {
    set_num_residuals(d.m * d.C);
    mutable_parameter_block_sizes()->push_back(nc);
  }

  bool Evaluate(double const* const* p, double* residuals, double** jacobians) const override {
    const int m = d_.m, q = nc_ + (d_.background ? 1 : 0);
    double k[4];
    for (int i = 0; i < nc_; ++i) {
      k[i] = std::exp(p[0][i]);
      // A trial step to a rate that over- or underflows is refused (Ceres
      // shrinks the step) instead of evaluated to NaN, which Ceres reports
      // as a page of log lines on stderr.
      if (!std::isfinite(k[i]) || !(k[i] > 0)) return false;
    }
    const Eigen::MatrixXd Phi = DesignMatrix(d_, k, nc_);
    for (int c = 0; c < d_.C; ++c) {
      const Eigen::MatrixXd WPhi = d_.w[c].matrix().asDiagonal() * Phi;
      const Eigen::VectorXd wy = (d_.w[c] * d_.y[c]).matrix();
      const SmallNnlsResult x = SolveSmallNnls(Gram(WPhi), InnerProducts(WPhi, wy), nc_);
      Eigen::Map<Eigen::VectorXd> r(residuals + c * m, m);
      r = wy - WPhi * x.x;
      if (jacobians == nullptr || jacobians[0] == nullptr) continue;
      // Columns in use: components with a positive amplitude, and the background.
      std::vector<int> active;
      for (int i = 0; i < q; ++i)
        if (i >= nc_ || x.x[i] > 0) active.push_back(i);
      // Orthonormal basis of the columns in use, by Gram-Schmidt done twice
      // ("twice is enough", Giraud et al. 2005): at most 5 columns of m.
      Eigen::MatrixXd Q(m, static_cast<int>(active.size()));
      int rank = 0;
      for (int a : active) {
        Eigen::VectorXd v = WPhi.col(a);
        const double norm0 = v.norm();
        for (int pass = 0; pass < 2; ++pass)
          for (int b = 0; b < rank; ++b) v -= Q.col(b).dot(v) * Q.col(b);
        const double norm = v.norm();
        if (norm > 1e-12 * norm0) Q.col(rank++) = v / norm;  // drop a column the others already span
      }
      Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> J(jacobians[0] + c * m * nc_,
                                                                                           m, nc_);
      for (int i = 0; i < nc_; ++i) {
        // d r / d log k_i with the amplitudes held, w t k_i e^{-k_i t} A_i,
        // projected onto the complement of the columns in use.
        Eigen::VectorXd v = (d_.w[c] * d_.t * Phi.col(i).array()).matrix() * (k[i] * x.x[i]);
        for (int b = 0; b < rank; ++b) v -= Q.col(b).dot(v) * Q.col(b);
        J.col(i) = v;
      }
    }
    return true;
  }

 private:
  const Data& d_;
  int nc_;
};

// The variable-projection problem at given log rates, reduced to what a
// Levenberg-Marquardt step needs: 0.5 |r|^2 and, for Kaufman's Jacobian J
// (the same one VarProCost writes out for Ceres), J'J and J'r, which are
// nc x nc and nc. J is never formed: with V_i = w t k_i A_i e^{-k_i t} (the
// derivative of the residual with the amplitudes held) and Q an orthonormal
// basis of the columns in use, J = (I - QQ')V, so J'J = V'V - (Q'V)'(Q'V)
// and J'r = V'r - (Q'V)'(Q'r): inner products of length m only, into
// buffers sized once per refinement.
//
// It also gives the exact Hessian of the reduced objective (the amplitudes
// eliminated, their active set held), for Newton steps: Gauss-Newton
// converges only linearly on these curves, whose residuals are large
// (noise and misfit), about 10 iterations per stage. With the full
// problem's Hessian H (parameters log rates and amplitudes x), the reduced
// one is H_tt - H_tx G^-1 H_xt, G = Phi'Phi over the columns in use:
//   H_tt = V'V + diag(x_i T_i),   T_i = sum r w k_i t e_i (1 - k_i t),
//   H_tx = -V'Phi + S,            S_ia = [a = i] s_i, s_i = sum r w k_i t e_i,
// and with Phi = QR, G^-1 = R^-1 R^-T, so with M = R^-T S':
//   H_red = J'J + diag(x T) + (Q'V)'M + M'(Q'V) - M'M.
class VarProNormalEquations {
 public:
  VarProNormalEquations(const Data& d, int nc)
      : d_(d),
        nc_(nc),
        q_(nc + (d.background ? 1 : 0)),
        E_(d.m, nc),
        WPhi_(d.m, q_),
        Q_(d.m, q_),
        V_(d.m, nc),
        r_(d.m) {
    for (int c = 0; c < d.C; ++c) wy_.push_back(d.w[c] * d.y[c]);
  }

  struct Point {
    double cost = 0;  // 0.5 |r|^2, as Ceres counts it
    SmallMatrix JtJ;
    SmallVector Jtr;
    SmallMatrix hessian;  // of the reduced objective (JtJ where a column in use was dropped as dependent)
  };

  // False where a rate over- or underflows (as VarProCost refuses it).
  bool Evaluate(const double* theta, Point* out) {
    double k[kMaxDecayComponents];
    for (int i = 0; i < nc_; ++i) {
      k[i] = std::exp(theta[i]);
      if (!std::isfinite(k[i]) || !(k[i] > 0)) return false;
      E_.col(i) = (-k[i] * d_.t).exp();
    }
    out->cost = 0;
    out->JtJ = SmallMatrix::Zero(nc_, nc_);
    out->Jtr = SmallVector::Zero(nc_);
    out->hessian = SmallMatrix::Zero(nc_, nc_);
    bool exact = true;
    for (int c = 0; c < d_.C; ++c) {
      const Eigen::ArrayXd& w = d_.w[c];
      for (int i = 0; i < nc_; ++i) WPhi_.col(i) = w * E_.col(i);
      if (d_.background) WPhi_.col(nc_) = w;
      SmallMatrix G(q_, q_);
      SmallVector b(q_);
      for (int i = 0; i < q_; ++i) {
        b[i] = (WPhi_.col(i) * wy_[c]).sum();
        for (int j = 0; j <= i; ++j) G(i, j) = G(j, i) = (WPhi_.col(i) * WPhi_.col(j)).sum();
      }
      const SmallNnlsResult x = SolveSmallNnls(G, b, nc_);
      r_ = wy_[c];
      for (int i = 0; i < q_; ++i)
        if (x.x[i] != 0) r_ -= x.x[i] * WPhi_.col(i);
      out->cost += 0.5 * r_.square().sum();
      // Orthonormal basis of the columns in use (components with a positive
      // amplitude, and the background), by Gram-Schmidt done twice ("twice
      // is enough", Giraud et al. 2005).
      int rank = 0, active = 0, column_of[5];
      SmallMatrix R = SmallMatrix::Zero(q_, q_);  // Q'Phi over the columns in use: upper triangular
      for (int a = 0; a < q_; ++a) {
        if (a < nc_ && !(x.x[a] > 0)) continue;
        ++active;
        auto v = Q_.col(rank);
        v = WPhi_.col(a);
        const double norm0 = std::sqrt(v.square().sum());
        for (int pass = 0; pass < 2; ++pass)
          for (int o = 0; o < rank; ++o) {
            const double projection = (Q_.col(o) * v).sum();
            R(o, rank) += projection;
            v -= projection * Q_.col(o);
          }
        const double norm = std::sqrt(v.square().sum());
        if (norm > 1e-12 * norm0) {
          v /= norm;
          R(rank, rank) = norm;
          column_of[rank++] = a;
        } else {
          R.col(rank).setZero();  // a column the others already span
        }
      }
      exact = exact && rank == active;
      double QtV[5][kMaxDecayComponents], Qtr[5], T[kMaxDecayComponents], s_[kMaxDecayComponents];
      for (int i = 0; i < nc_; ++i) {
        // w k t e^{-k t}: the derivative of a column with respect to its log rate, negated.
        V_.col(i) = WPhi_.col(i) * d_.t * k[i];
        s_[i] = (V_.col(i) * r_).sum();
        T[i] = s_[i] - k[i] * (V_.col(i) * d_.t * r_).sum();
        V_.col(i) *= x.x[i];
      }
      for (int o = 0; o < rank; ++o) {
        Qtr[o] = (Q_.col(o) * r_).sum();
        for (int i = 0; i < nc_; ++i) QtV[o][i] = (Q_.col(o) * V_.col(i)).sum();
      }
      // M = R^-T S' by forward substitution (R' is lower triangular).
      double M[5][kMaxDecayComponents];
      for (int i = 0; i < nc_; ++i)
        for (int o = 0; o < rank; ++o) {
          double value = column_of[o] == i ? s_[i] : 0.0;
          for (int p = 0; p < o; ++p) value -= R(p, o) * M[p][i];
          M[o][i] = value / R(o, o);
        }
      for (int i = 0; i < nc_; ++i) {
        double g = (V_.col(i) * r_).sum();
        for (int o = 0; o < rank; ++o) g -= QtV[o][i] * Qtr[o];
        out->Jtr[i] += g;
        for (int j = 0; j <= i; ++j) {
          double h = (V_.col(i) * V_.col(j)).sum();
          for (int o = 0; o < rank; ++o) h -= QtV[o][i] * QtV[o][j];
          out->JtJ(i, j) += h;
          double second = i == j ? x.x[i] * T[i] : 0.0;
          for (int o = 0; o < rank; ++o) second += QtV[o][i] * M[o][j] + M[o][i] * QtV[o][j] - M[o][i] * M[o][j];
          out->hessian(i, j) += h + second;
        }
      }
    }
    for (int i = 0; i < nc_; ++i)
      for (int j = 0; j < i; ++j) {
        out->JtJ(j, i) = out->JtJ(i, j);
        out->hessian(j, i) = out->hessian(i, j);
      }
    if (!exact) out->hessian = out->JtJ;
    return std::isfinite(out->cost) && out->Jtr.allFinite() && out->JtJ.allFinite() && out->hessian.allFinite();
  }

 private:
  const Data& d_;
  int nc_, q_;
  std::vector<Eigen::ArrayXd> wy_;  // per channel
  Eigen::ArrayXXd E_, WPhi_, Q_, V_;
  Eigen::ArrayXd r_;
};

// Levenberg-Marquardt over the log rates (at most 4 parameters) on the normal
// equations, (J'J + D / radius) step = -J'r with D = diag(J'J): the
// trust-region strategy of Ceres's LEVENBERG_MARQUARDT (radius update of
// Nielsen 1999, as in Madsen, Nielsen and Tingleff 2004) and the same
// tolerances as the Ceres refinement (RefineWithCeres), without Ceres's
// general machinery. For an m x 3 Jacobian that machinery (a QR of the whole
// Jacobian, column scaling, array checks on every iteration) cost more than
// evaluating the model. Returns the iterations taken.
// GCC 12 warns (-Warray-bounds) that Eigen's vectorized norm() and dot()
// could read a second 4-double packet past a SmallVector's 5 entries: it does
// not see that the packet loop stops at the vector's size (at most 5), so the
// warning is switched off for this function alone.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Warray-bounds"
int LevenbergMarquardt(const Data& d, int max_iterations, std::vector<double>* theta, bool* converged) {
  constexpr double kFunctionTolerance = 1e-10, kGradientTolerance = 1e-12, kParameterTolerance = 1e-10;
  constexpr double kMinRelativeDecrease = 1e-3;  // a step must achieve this share of its predicted decrease
  constexpr double kMinDiagonal = 1e-6, kMaxDiagonal = 1e32;  // Ceres's min/max_lm_diagonal
  const int nc = static_cast<int>(theta->size());
  VarProNormalEquations equations(d, nc);
  VarProNormalEquations::Point here, there;
  // Converged: stopped by a tolerance, as Ceres's CONVERGENCE (the trust
  // region shrinking below its minimum included); not when the iterations
  // ran out or the model stopped being finite.
  *converged = false;
  if (!equations.Evaluate(theta->data(), &here)) return 0;
  SmallVector x(nc);
  for (int i = 0; i < nc; ++i) x[i] = (*theta)[i];
  double radius = 1e4, decrease = 2;  // Ceres's initial_trust_region_radius
  int iteration = 0;
  bool stopped = false;  // by a tolerance
  while (iteration < max_iterations && !stopped) {
    ++iteration;
    if (here.Jtr.cwiseAbs().maxCoeff() <= kGradientTolerance) {
      stopped = true;
      break;
    }
    // Newton's model where the reduced Hessian is positive definite (near a
    // minimum), Gauss-Newton's (Kaufman's J'J) elsewhere.
    const bool newton = here.hessian.llt().info() == Eigen::Success;
    const SmallMatrix& B = newton ? here.hessian : here.JtJ;
    SmallMatrix A = B;
    for (int i = 0; i < nc; ++i) A(i, i) += std::clamp(here.JtJ(i, i), kMinDiagonal, kMaxDiagonal) / radius;
    const SmallVector step = A.ldlt().solve(-here.Jtr);
    if (!step.allFinite()) break;
    if (step.norm() <= kParameterTolerance * (x.norm() + kParameterTolerance)) {
      stopped = true;
      break;
    }
    const SmallVector candidate = x + step;
    const double predicted = -(here.Jtr.dot(step) + 0.5 * step.dot(B * step));
    // Converged when even Newton's model (exact near the minimum) promises
    // less than the function tolerance (there rounding decides whether a step
    // "succeeds", and rejecting it only shrinks the region step by step).
    if (newton && predicted <= kFunctionTolerance * here.cost) {
      stopped = true;
      break;
    }
    const bool evaluated = equations.Evaluate(candidate.data(), &there);
    const double actual = evaluated ? here.cost - there.cost : -1;
    if (evaluated && predicted > 0 && actual > kMinRelativeDecrease * predicted) {
      const double rho = actual / predicted;
      const double previous = here.cost;
      x = candidate;
      std::swap(here, there);
      radius = std::min(1e16, radius / std::max(1.0 / 3.0, 1.0 - std::pow(2 * rho - 1, 3)));
      decrease = 2;
      stopped = actual <= kFunctionTolerance * previous;
    } else {
      radius /= decrease;
      decrease *= 2;
      stopped = radius < 1e-32;
    }
  }
  for (int i = 0; i < nc; ++i) (*theta)[i] = x[i];
  *converged = stopped;
  return iteration;
}
#pragma GCC diagnostic pop

// Refinement of the rates of `fit` by variable projection, then the
// amplitudes and background at the refined rates.
void Refine(const Data& d, int max_iterations, Fit* fit) {
  fit->iterations += LevenbergMarquardt(d, max_iterations, &fit->theta, &fit->converged);
  if (!fit->converged)
    fit->termination = "no tolerance met in " + std::to_string(max_iterations) + " iterations (max_iterations)";
  std::vector<double> rates;
  for (double th : fit->theta) rates.push_back(std::exp(th));
  Project(d, rates, fit);
}

// The same refinement by Ceres (the first implementation, for
// FitDecayReference).
void RefineWithCeres(const Data& d, int max_iterations, Fit* fit) {
  const int nc = static_cast<int>(fit->theta.size());
  ceres::Problem problem;
  problem.AddResidualBlock(new VarProCost(d, nc), nullptr, fit->theta.data());
  // No bounds on log k: Ceres would then project every step with a line
  // search that evaluates the Jacobian twice per iteration. A rate that
  // leaves [theta_lo, theta_hi] is caught after the solve instead.
  ceres::Solver::Options options = SmallDenseSolverOptions(max_iterations, 1e-10);
  // Looser than the shared defaults: the rates are converged to well below
  // their uncertainty, and every iteration counts toward the < 1 ms budget.
  options.gradient_tolerance = 1e-12;
  options.parameter_tolerance = 1e-10;
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  fit->iterations += static_cast<int>(summary.iterations.size());
  fit->converged = summary.IsSolutionUsable() && summary.termination_type == ceres::CONVERGENCE;
  fit->termination = fit->converged ? "" : summary.message;
  std::vector<double> rates;
  for (double th : fit->theta) rates.push_back(std::exp(th));
  Project(d, rates, fit);
}

void CheckComponents(double theta_lo, double theta_hi, Fit* fit) {
  const int nc = static_cast<int>(fit->theta.size());
  double largest = 0;
  for (const auto& a : fit->A)
    for (double v : a) largest = std::max(largest, v);
  fit->valid = true;
  for (double th : fit->theta)
    if (th < theta_lo || th > theta_hi) {
      fit->valid = false;
      fit->why_invalid = "a rate left the range the samples resolve";
    }
  for (int i = 0; i < nc; ++i) {
    double here = 0;
    for (const auto& a : fit->A) here = std::max(here, a[i]);
    if (!(here > 1e-9 * largest)) {
      fit->valid = false;
      fit->why_invalid = "a component has no amplitude";
    }
    for (int j = 0; j < i; ++j)
      if (std::fabs(fit->theta[i] - fit->theta[j]) < std::log(1.02)) {
        fit->valid = false;
        fit->why_invalid = "two rates coincide";
      }
  }
}

// How the rates are refined and their covariance computed: by our own
// Levenberg-Marquardt on the normal equations (FitDecay), or by Ceres for
// both (FitDecayReference, the first implementation).
enum class Solver { kOwn, kCeres };

DecayFitSummary FitDecayWith(const Curve& curve, const DecayFitOptions& options, const std::string& where,
                             Solver solver) {
  const auto refine = solver == Solver::kOwn ? Refine : RefineWithCeres;
  const auto start = std::chrono::steady_clock::now();
  std::string error;
  if (!options.IsValid(&error)) ThrowUserError(where, "options", error);
  const int max_nc = options.components > 0 ? options.components : options.max_components;
  const int C = curve.channel_count();
  if (C == 0) ValidateCurve(curve, 1, where);  // names the missing value column (and spares a division by 0)
  // Every parameter needs a sample, plus one for the noise.
  const std::size_t parameters = static_cast<std::size_t>(max_nc) * (1 + C) + (options.background ? C : 0);
  ValidateCurve(curve, std::max<std::size_t>(3, parameters / C + 1), where);

  // Solved in the curve's own units (curve.h: CurveScale), so nothing below
  // depends on the units of the data or of the time.
  const CurveScale units = ScaleOfCurve(curve, where);
  const Curve scaled = ScaledCurve(curve, units);
  Data d;
  d.m = static_cast<int>(curve.size());
  d.C = C;
  d.background = options.background;
  d.t = Eigen::Map<const Eigen::ArrayXd>(scaled.t_s.data(), d.m);
  const bool exposures = options.weighting == Weighting::kPoisson && scaled.exposure_s.size() == curve.size();
  // A weighted squared residual of the data per one of the scaled curve, as
  // its log (value scales of 1e200 square to infinity): the data's Poisson
  // weights, 1 / sqrt(value / exposure), are the scaled ones over
  // sqrt(value scale / exposure scale).
  const double log_weighted_unit = options.weighting == Weighting::kNone
                                       ? 2 * std::log(units.value)
                                       : std::log(units.value) + (exposures ? std::log(units.exposure_s) : 0.0);
  bool any_variation = false;
  for (int c = 0; c < C; ++c) {
    const auto& v = scaled.channels[c];
    Eigen::ArrayXd y = Eigen::Map<const Eigen::ArrayXd>(v.data(), d.m);
    const double scale = y.abs().maxCoeff();
    any_variation = any_variation || (scale > 0 && (y.maxCoeff() - y.minCoeff()) > 1e-12 * scale);
    const double s = scale > 0 ? scale : 1.0;
    d.scale.push_back(s);
    d.y.push_back(y / s);
    std::vector<double> w = SampleWeights(v, options.weighting);
    if (exposures)
      for (std::size_t j = 0; j < w.size(); ++j) w[j] *= std::sqrt(scaled.exposure_s[j]);
    d.w.push_back(Eigen::Map<const Eigen::ArrayXd>(w.data(), d.m) * s);
  }
  if (!any_variation) ThrowUserError(where, "", "every value is the same: there is no decay to fit");

  // Rates the data can resolve: from a twentieth of one per span (slower
  // looks constant) to three per smallest step between distinct times
  // (faster is over before the second one; replicates are no step).
  const double span = scaled.t_s.back() - scaled.t_s.front();
  const double spacing = SmallestTimeStep(scaled);
  const double k_lo = 0.02 / span, k_hi = std::max(3.0 / spacing, 10 * k_lo);
  Eigen::ArrayXd grid_rates(options.rate_grid_size);
  for (int g = 0; g < grid_rates.size(); ++g)
    grid_rates[g] = k_lo * std::pow(k_hi / k_lo, static_cast<double>(g) / (grid_rates.size() - 1));
  const RateGrid grid = MakeRateGrid(d, std::move(grid_rates));
  const double theta_lo = std::log(k_lo / 10), theta_hi = std::log(k_hi * 10);

  std::vector<Fit> fits;
  std::vector<double> rates;
  int iterations = 0;
  for (int nc = 1; nc <= max_nc; ++nc) {
    Fit fit = ScanNewComponent(d, rates, grid);
    if (fit.theta.empty()) break;  // no room for another rate
    if (nc == 1) {
      // A decay must stand out of the noise: the best single exponential
      // against a constant level, by an F statistic of at least 20. A rising,
      // or flat and noisy, curve is met only by a nearly constant
      // exponential, which explains next to nothing; a dim decay that is
      // over after a few samples still passes.
      double about_constant = 0;
      for (int c = 0; c < C; ++c) {
        const Eigen::ArrayXd w2 = d.w[c].square();
        const double level = (w2 * d.y[c]).sum() / w2.sum();
        about_constant += (w2 * (d.y[c] - level).square()).sum();
      }
      const double N = static_cast<double>(d.m) * C;
      const double F = ((about_constant - fit.wrss) / C) / (fit.wrss / std::max(1.0, N - 2.0 * C));
      if (!(F >= 20))
        ThrowUserError(where, "", "no decaying component: the values do not decrease over time (beyond their scatter)");
    }
    // With the count fixed, the stages before the last only place starting
    // rates (the grid scan already solves their amplitudes exactly); when
    // the count is chosen, every stage is a candidate and is refined.
    if (options.components == 0 || nc == max_nc) {
      refine(d, options.max_iterations, &fit);
      iterations += fit.iterations;
    }
    CheckComponents(theta_lo, theta_hi, &fit);
    rates.clear();
    for (double th : fit.theta) rates.push_back(std::exp(th));
    fits.push_back(std::move(fit));
  }

  // A stage whose greedy start collapsed (two rates onto one state, or a
  // component with nothing left) is tried again from the next stage's
  // rates less one of them, each refined: a fast state that dominates can
  // pull the second rate onto itself before the slow state is seen, and
  // the stage after it finds both (backward elimination).
  auto retry_from = [&](Fit& stage, const Fit& next) {
    for (std::size_t drop = 0; drop < next.theta.size(); ++drop) {
      Fit candidate;
      std::vector<double> start;
      for (std::size_t i = 0; i < next.theta.size(); ++i)
        if (i != drop) {
          candidate.theta.push_back(next.theta[i]);
          start.push_back(std::exp(next.theta[i]));
        }
      Project(d, start, &candidate);
      refine(d, options.max_iterations, &candidate);
      iterations += candidate.iterations;
      CheckComponents(theta_lo, theta_hi, &candidate);
      if (candidate.valid && (!stage.valid || candidate.wrss < stage.wrss)) stage = std::move(candidate);
    }
  };
  if (options.components == 0) {
    for (std::size_t f = 0; f + 1 < fits.size(); ++f)
      if (!fits[f].valid) retry_from(fits[f], fits[f + 1]);
  } else if (!fits.empty() && !fits.back().valid && max_nc < kMaxDecayComponents &&
             curve.size() * C > static_cast<std::size_t>(max_nc + 1) * (1 + C) + (options.background ? C : 0)) {
    // A fixed count that collapsed: one stage more, for its rates only.
    Fit next = ScanNewComponent(d, rates, grid);
    if (!next.theta.empty()) {
      refine(d, options.max_iterations, &next);
      iterations += next.iterations;
      retry_from(fits.back(), next);
    }
  }

  DecayFitSummary summary;
  const double N = static_cast<double>(d.m) * C;
  for (std::size_t f = 0; f < fits.size(); ++f) {
    const double nc = static_cast<double>(f + 1);
    const double P = nc * (1 + C) + (options.background ? C : 0);
    // In the data's units (the same log_weighted_unit added to every
    // count's, which leaves their differences, and so the choice, as they are).
    const double bic = N * (std::log(std::max(fits[f].wrss / N, 1e-300)) + log_weighted_unit) + P * std::log(N);
    summary.bic.push_back(fits[f].valid ? bic : std::numeric_limits<double>::quiet_NaN());
  }
  int chosen = -1;
  if (options.components > 0) {
    chosen = static_cast<int>(fits.size()) - 1;
    summary.choice = "fixed at " + std::to_string(options.components) + " by the caller";
    if (chosen + 1 < options.components) summary.choice += "; only " + std::to_string(chosen + 1) + " could be placed";
    if (!fits[chosen].valid) summary.choice += " (warning: " + fits[chosen].why_invalid + ")";
  } else {
    // The fewest components whose BIC is within 2 of the lowest (a smaller
    // difference is "not worth more than a bare mention", Kass and Raftery 1995).
    double lowest = std::numeric_limits<double>::infinity();
    for (double b : summary.bic)
      if (!std::isnan(b)) lowest = std::min(lowest, b);
    for (std::size_t f = 0; f < fits.size() && chosen < 0; ++f)
      if (!std::isnan(summary.bic[f]) && summary.bic[f] <= lowest + 2) chosen = static_cast<int>(f);
    if (chosen < 0) chosen = 0;
    summary.choice = "BIC over 1.." + std::to_string(fits.size()) + " components: the fewest within 2 of the lowest";
  }
  Fit& fit = fits[chosen];
  summary.converged = fit.converged;
  summary.termination = fit.termination;
  const int nc = chosen + 1;

  // Uncertainties: the covariance of the refined parameters, scaled by the
  // reduced chi-square (the weights set the shape of the noise, not its size).
  std::vector<double> theta_var(nc, 0.0);
  std::vector<std::vector<double>> amplitude_var(C, std::vector<double>(nc, 0.0));
  const double dof = std::max(1.0, N - (nc * (1 + C) + (options.background ? C : 0)));
  const double reduced_chi2 = fit.wrss / dof;
  const ceres::Covariance::Options covariance_options = SmallDenseCovarianceOptions();
  if (options.compute_uncertainties && solver == Solver::kOwn) {
    // Rates: as below, (J'J)^+ from the normal equations the refinement
    // solves, with the same rule for a degenerate direction as Ceres's
    // DENSE_SVD with null_space_rank -1: eigenvalues of J'J (squared
    // singular values of J) below 1e-14 of the largest are dropped.
    VarProNormalEquations equations(d, nc);
    VarProNormalEquations::Point at;
    if (equations.Evaluate(fit.theta.data(), &at)) {
      Eigen::SelfAdjointEigenSolver<SmallMatrix> eigen(at.JtJ);
      const Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 5, 1> lambda = eigen.eigenvalues();
      const double largest = lambda.maxCoeff();
      SmallMatrix inverse = SmallMatrix::Zero(nc, nc);
      for (int e = 0; e < nc; ++e)
        if (lambda[e] > 1e-14 * largest)
          inverse += eigen.eigenvectors().col(e) * eigen.eigenvectors().col(e).transpose() / lambda[e];
      for (int i = 0; i < nc; ++i) theta_var[i] = inverse(i, i) * reduced_chi2;
    }
  } else if (options.compute_uncertainties) {
    // Rates: the covariance of the variable-projection problem. Its Jacobian
    // is the rates' Jacobian projected off the amplitudes' columns, so J'J is
    // the Schur complement of the full normal matrix: the rates' marginal
    // covariance, amplitudes accounted for, from an nc-column Jacobian.
    ceres::Problem problem;
    problem.AddResidualBlock(new VarProCost(d, nc), nullptr, fit.theta.data());
    ceres::Covariance covariance(covariance_options);
    std::vector<std::pair<const double*, const double*>> pairs = {{fit.theta.data(), fit.theta.data()}};
    if (covariance.Compute(pairs, &problem)) {
      std::vector<double> block(nc * nc);
      covariance.GetCovarianceBlock(fit.theta.data(), fit.theta.data(), block.data());
      for (int i = 0; i < nc; ++i) theta_var[i] = block[i * nc + i] * reduced_chi2;
    }
  }
  if (options.amplitude_uncertainties) {
    // Amplitudes: the covariance of the full problem (every parameter).
    ceres::Problem::Options problem_options;
    problem_options.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    ceres::Problem problem(problem_options);
    std::vector<std::unique_ptr<ceres::CostFunction>> costs;
    for (int c = 0; c < C; ++c) {
      costs.push_back(std::make_unique<ChannelDecayCost>(d, c, nc));
      std::vector<double*> blocks = {fit.theta.data(), fit.A[c].data()};
      if (d.background) blocks.push_back(&fit.B[c]);
      problem.AddResidualBlock(costs.back().get(), nullptr, blocks);
    }
    ceres::Covariance covariance(covariance_options);
    std::vector<std::pair<const double*, const double*>> pairs;
    for (int c = 0; c < C; ++c) pairs.push_back({fit.A[c].data(), fit.A[c].data()});
    if (covariance.Compute(pairs, &problem)) {
      std::vector<double> block(nc * nc);
      for (int c = 0; c < C; ++c) {
        covariance.GetCovarianceBlock(fit.A[c].data(), fit.A[c].data(), block.data());
        for (int i = 0; i < nc; ++i) amplitude_var[c][i] = block[i * nc + i] * reduced_chi2;
      }
    }
  }

  // Back to the data's units, fastest component first. The residuals are
  // summed in the scaled curve's units (EvaluateDecay's model, a column at a
  // time), where their squares cannot overflow or underflow, then scaled.
  std::vector<int> order(nc);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) { return fit.theta[a] > fit.theta[b]; });
  std::vector<Eigen::ArrayXd> model(C, Eigen::ArrayXd::Zero(d.m));
  for (int c = 0; c < C; ++c) model[c].setConstant(fit.B[c] * d.scale[c]);
  for (int i : order) {
    DecayComponent component;
    const double rate = std::exp(fit.theta[i]);  // per unit of scaled time
    component.rate = rate / units.time_s;
    component.rate_stderr = component.rate * std::sqrt(std::max(0.0, theta_var[i]));  // d k = k d(log k)
    const Eigen::ArrayXd column = (-rate * d.t).exp();
    for (int c = 0; c < C; ++c) {
      const double scale = d.scale[c] * units.value;
      component.amplitude.push_back(fit.A[c][i] * scale);
      component.amplitude_stderr.push_back(std::sqrt(std::max(0.0, amplitude_var[c][i])) * scale);
      model[c] += (fit.A[c][i] * d.scale[c]) * column;
    }
    summary.components.push_back(component);
  }
  for (int c = 0; c < C; ++c) summary.background.push_back(fit.B[c] * d.scale[c] * units.value);
  summary.n_components = nc;
  summary.weighted_rss = options.weighting == Weighting::kNone
                             ? fit.wrss * units.value * units.value
                             : fit.wrss * units.value * (exposures ? units.exposure_s : 1.0);
  summary.iterations = iterations;
  double rss = 0;
  for (int c = 0; c < C; ++c)
    rss += (Eigen::Map<const Eigen::ArrayXd>(scaled.channels[c].data(), d.m) - model[c]).square().sum();
  summary.rss = rss * units.value * units.value;
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

}  // namespace

DecayFitSummary FitDecay(const Curve& curve, const DecayFitOptions& options, const std::string& where) {
  return FitDecayWith(curve, options, where, Solver::kOwn);
}

DecayFitSummary FitDecayReference(const Curve& curve, const DecayFitOptions& options, const std::string& where) {
  return FitDecayWith(curve, options, where, Solver::kCeres);
}

double EvaluateDecay(const DecayFitSummary& fit, int channel, double t_s) {
  double value = fit.background.empty() ? 0.0 : fit.background[channel];
  for (const DecayComponent& component : fit.components)
    value += component.amplitude[channel] * std::exp(-component.rate * t_s);
  return value;
}

}  // namespace phos
