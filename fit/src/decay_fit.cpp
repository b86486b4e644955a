#include "phos/fit/decay_fit.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <numeric>

#include <ceres/ceres.h>
#include <Eigen/Core>

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

// The curve in the fit's own units: each channel divided by its largest
// |value| so every parameter is of order 1 for Ceres, and weights multiplied
// by the same factor, so the weighted residuals are those of the data's
// units and the objective is unchanged.
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

struct Fit {
  std::vector<double> theta;           // log rates
  std::vector<std::vector<double>> A;  // [c][i], fit units
  std::vector<double> B;               // [c], fit units
  double wrss = std::numeric_limits<double>::infinity();
  int iterations = 0;
  bool valid = false;
  std::string why_invalid;
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

// Adds one component to `start` (rates fixed) by scanning the grid; returns
// the best projection. Each candidate only needs its own column's inner
// products with the others, so the scan is one small matrix product.
Fit ScanNewComponent(const Data& d, const std::vector<double>& rates, const Eigen::ArrayXd& grid,
                     const Eigen::MatrixXd& grid_columns) {
  const int p = static_cast<int>(rates.size());
  Fit best;
  std::vector<double> trial = rates;
  trial.push_back(0);
  // Columns of the components already present (and the background).
  const int q = p + (d.background ? 1 : 0);
  const Eigen::MatrixXd Phi = DesignMatrix(d, rates.data(), p);
  std::vector<double> cost(grid.size(), 0.0);
  std::vector<bool> usable(grid.size(), true);
  for (int g = 0; g < grid.size(); ++g)
    for (double r : rates)
      if (std::fabs(std::log(grid[g] / r)) < 0.15) usable[g] = false;  // too close to an existing rate
  Eigen::VectorXd weighted_column(d.m);
  for (int c = 0; c < d.C; ++c) {
    const Eigen::VectorXd w2 = d.w[c].square().matrix();
    const Eigen::VectorXd w2y = (d.w[c].square() * d.y[c]).matrix();
    const Eigen::MatrixXd WPhi = d.w[c].matrix().asDiagonal() * Phi;
    const SmallMatrix G_old = Gram(WPhi);
    const SmallVector b_old = InnerProducts(Phi, w2y);
    const double yy = (d.w[c] * d.y[c]).matrix().squaredNorm();
    // New component first among the constrained ones: order [A_new, A_old..., B].
    SmallMatrix G(q + 1, q + 1);
    SmallVector b(q + 1);
    G.block(1, 1, q, q) = G_old;
    b.tail(q) = b_old;
    for (int g = 0; g < grid.size(); ++g) {
      if (!usable[g]) continue;
      // One column at a time: no m x grid temporaries (they would be fresh
      // pages from the kernel on every call).
      weighted_column = w2.cwiseProduct(grid_columns.col(g));
      G(0, 0) = weighted_column.dot(grid_columns.col(g));
      for (int i = 0; i < q; ++i) G(i + 1, 0) = G(0, i + 1) = Phi.col(i).dot(weighted_column);
      b[0] = weighted_column.dot(d.y[c].matrix());
      SmallNnlsResult r = SolveSmallNnls(G, b, p + 1);
      cost[g] += std::max(0.0, yy + 2 * r.cost);
    }
  }
  int chosen = -1;
  for (int g = 0; g < grid.size(); ++g)
    if (usable[g] && (chosen < 0 || cost[g] < cost[chosen])) chosen = g;
  if (chosen < 0) return best;
  trial.back() = grid[chosen];
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

// Ceres refinement of the rates of `fit` by variable projection, then the
// amplitudes and background at the refined rates.
void Refine(const Data& d, int max_iterations, Fit* fit) {
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

// The most components a decay fit places (DecayFitOptions: 1..4).
constexpr int kMaxDecayComponents = 4;

}  // namespace

DecayFitSummary FitDecay(const Curve& curve, const DecayFitOptions& options, const std::string& where) {
  const auto start = std::chrono::steady_clock::now();
  std::string error;
  if (!options.IsValid(&error)) ThrowUserError(where, "options", error);
  const int max_nc = options.components > 0 ? options.components : options.max_components;
  const int C = curve.channel_count();
  if (C == 0) ValidateCurve(curve, 1, where);  // names the missing value column (and spares a division by 0)
  // Every parameter needs a sample, plus one for the noise.
  const std::size_t parameters = static_cast<std::size_t>(max_nc) * (1 + C) + (options.background ? C : 0);
  ValidateCurve(curve, std::max<std::size_t>(3, parameters / C + 1), where);

  Data d;
  d.m = static_cast<int>(curve.size());
  d.C = C;
  d.background = options.background;
  d.t = Eigen::Map<const Eigen::ArrayXd>(curve.t_s.data(), d.m);
  bool any_variation = false;
  for (int c = 0; c < C; ++c) {
    const auto& v = curve.channels[c];
    Eigen::ArrayXd y = Eigen::Map<const Eigen::ArrayXd>(v.data(), d.m);
    const double scale = y.abs().maxCoeff();
    any_variation = any_variation || (scale > 0 && (y.maxCoeff() - y.minCoeff()) > 1e-12 * scale);
    const double s = scale > 0 ? scale : 1.0;
    d.scale.push_back(s);
    d.y.push_back(y / s);
    std::vector<double> w = SampleWeights(v, options.weighting);
    if (options.weighting == Weighting::kPoisson && curve.exposure_s.size() == v.size())
      for (std::size_t j = 0; j < w.size(); ++j) w[j] *= std::sqrt(curve.exposure_s[j]);
    d.w.push_back(Eigen::Map<const Eigen::ArrayXd>(w.data(), d.m) * s);
  }
  if (!any_variation) ThrowUserError(where, "", "every value is the same: there is no decay to fit");

  // Rates the data can resolve: from a twentieth of one per span (slower
  // looks constant) to three per smallest step between distinct times
  // (faster is over before the second one; replicates are no step).
  const double span = curve.t_s.back() - curve.t_s.front();
  const double spacing = SmallestTimeStep(curve);
  const double k_lo = 0.02 / span, k_hi = std::max(3.0 / spacing, 10 * k_lo);
  Eigen::ArrayXd grid(options.rate_grid_size);
  for (int g = 0; g < grid.size(); ++g)
    grid[g] = k_lo * std::pow(k_hi / k_lo, static_cast<double>(g) / (grid.size() - 1));
  // Candidate columns e^{-k t} of the scan. On a uniform time axis (the
  // usual camera schedule) they are powers of one factor: a multiply per
  // sample instead of an exp (relative drift ~ m eps, irrelevant to a scan).
  Eigen::MatrixXd grid_columns(d.m, grid.size());
  bool uniform = true;
  for (int j = 2; j < d.m && uniform; ++j)
    uniform = std::fabs((d.t[j] - d.t[j - 1]) - (d.t[1] - d.t[0])) <= 1e-9 * (d.t[1] - d.t[0]);
  for (int g = 0; g < grid.size(); ++g) {
    if (!uniform) {
      grid_columns.col(g) = (-grid[g] * d.t).exp().matrix();
      continue;
    }
    const double step = std::exp(-grid[g] * (d.t[1] - d.t[0]));
    double value = std::exp(-grid[g] * d.t[0]);
    for (int j = 0; j < d.m; ++j, value *= step) grid_columns(j, g) = value;
  }
  const double theta_lo = std::log(k_lo / 10), theta_hi = std::log(k_hi * 10);

  std::vector<Fit> fits;
  std::vector<double> rates;
  int iterations = 0;
  for (int nc = 1; nc <= max_nc; ++nc) {
    Fit fit = ScanNewComponent(d, rates, grid, grid_columns);
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
      Refine(d, options.max_iterations, &fit);
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
      Refine(d, options.max_iterations, &candidate);
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
    Fit next = ScanNewComponent(d, rates, grid, grid_columns);
    if (!next.theta.empty()) {
      Refine(d, options.max_iterations, &next);
      iterations += next.iterations;
      retry_from(fits.back(), next);
    }
  }

  DecayFitSummary summary;
  const double N = static_cast<double>(d.m) * C;
  for (std::size_t f = 0; f < fits.size(); ++f) {
    const double nc = static_cast<double>(f + 1);
    const double P = nc * (1 + C) + (options.background ? C : 0);
    const double bic = N * std::log(std::max(fits[f].wrss / N, 1e-300)) + P * std::log(N);
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
  const int nc = chosen + 1;

  // Uncertainties: the covariance of the refined parameters, scaled by the
  // reduced chi-square (the weights set the shape of the noise, not its size).
  std::vector<double> theta_var(nc, 0.0);
  std::vector<std::vector<double>> amplitude_var(C, std::vector<double>(nc, 0.0));
  const double dof = std::max(1.0, N - (nc * (1 + C) + (options.background ? C : 0)));
  const double reduced_chi2 = fit.wrss / dof;
  ceres::Covariance::Options covariance_options;
  covariance_options.algorithm_type = ceres::DENSE_SVD;
  covariance_options.null_space_rank = -1;  // a vanished component must not fail the rest
  if (options.compute_uncertainties) {
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

  // Back to the data's units, fastest component first.
  std::vector<int> order(nc);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) { return fit.theta[a] > fit.theta[b]; });
  for (int i : order) {
    DecayComponent component;
    component.rate = std::exp(fit.theta[i]);
    component.rate_stderr = component.rate * std::sqrt(std::max(0.0, theta_var[i]));  // d k = k d(log k)
    for (int c = 0; c < C; ++c) {
      component.amplitude.push_back(fit.A[c][i] * d.scale[c]);
      component.amplitude_stderr.push_back(std::sqrt(std::max(0.0, amplitude_var[c][i])) * d.scale[c]);
    }
    summary.components.push_back(component);
  }
  for (int c = 0; c < C; ++c) summary.background.push_back(fit.B[c] * d.scale[c]);
  summary.n_components = nc;
  summary.weighted_rss = fit.wrss;
  summary.iterations = iterations;
  summary.rss = 0;
  for (int c = 0; c < C; ++c)
    for (int j = 0; j < d.m; ++j) {
      const double r = curve.channels[c][j] - EvaluateDecay(summary, c, curve.t_s[j]);
      summary.rss += r * r;
    }
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

double EvaluateDecay(const DecayFitSummary& fit, int channel, double t_s) {
  double value = fit.background.empty() ? 0.0 : fit.background[channel];
  for (const DecayComponent& component : fit.components)
    value += component.amplitude[channel] * std::exp(-component.rate * t_s);
  return value;
}

}  // namespace phos
