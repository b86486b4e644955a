#include "phos/fit/charge_fit.h"

#include <array>
#include <chrono>
#include <cmath>
#include <limits>

#include <ceres/ceres.h>
#include <Eigen/Dense>

#include "phos/util/error.h"
#include "solver_options.h"

namespace phos {
namespace {

// One channel c of C: L(t) = Linf - (Linf - L0) e^{-kt} = L0 e^{-kt} + Linf (1 - e^{-kt}).
// One parameter block for the whole fit, [log k, L0_0, Linf_0, L0_1, ...]:
// for one channel it is the three-parameter problem itself; a block for the
// rate and one per channel's levels measured 13% slower on bench_fit's
// 1000-sample curve.
class ChargeCost final : public ceres::CostFunction {
 public:
  ChargeCost(const Eigen::ArrayXd& t, const Eigen::ArrayXd& y, const Eigen::ArrayXd& w, int channel, int channels)
      : t_(t), y_(y), w_(w), c_(channel), n_(1 + 2 * channels) {
    set_num_residuals(static_cast<int>(t.size()));
    mutable_parameter_block_sizes()->push_back(n_);
  }

  bool Evaluate(double const* const* p, double* residuals, double** jacobians) const override {
    const double k = std::exp(p[0][0]), L0 = p[0][1 + 2 * c_], Linf = p[0][2 + 2 * c_];
    // A step to an overflowing rate is refused quietly (false), not
    // evaluated to e^{-inf * 0} = NaN, which Ceres reports in a page on stderr.
    if (!std::isfinite(k)) return false;
    double* J = jacobians != nullptr ? jacobians[0] : nullptr;
    if (J != nullptr) std::fill(J, J + t_.size() * n_, 0.0);
    for (int j = 0; j < t_.size(); ++j) {
      const double e = std::exp(-k * t_[j]);
      residuals[j] = w_[j] * (y_[j] - (L0 * e + Linf * (1 - e)));
      if (J == nullptr) continue;
      double* row = J + j * n_;
      row[0] = w_[j] * (L0 - Linf) * t_[j] * k * e;  // d/d log k of -(model)
      row[1 + 2 * c_] = -w_[j] * e;
      row[2 + 2 * c_] = -w_[j] * (1 - e);
    }
    return true;
  }

 private:
  const Eigen::ArrayXd& t_;
  const Eigen::ArrayXd& y_;
  const Eigen::ArrayXd& w_;
  int c_, n_;
};

// One channel in the fit's units: the scaled curve's values (curve.h:
// CurveScale) divided by their largest |value| (parameters of order 1 for
// Ceres), weights multiplied by it (channels weigh as they do in the data).
struct Channel {
  Eigen::ArrayXd y, w;
  Eigen::ArrayXd w2, w2y;  // w^2 and w^2 y, for the scan
  double sum_w2 = 0, sum_w2y = 0;
  double scale = 1;
  double levels[2] = {0, 0};  // L0, Linf in fit units
};

// For rate k, a channel's L0 and Linf from the 2 x 2 normal equations of the
// columns e^{-kt} and 1 - e^{-kt} (weighted): three dot products, no
// factorization. Returns the weighted cost, or infinity when k leaves the
// columns indistinguishable.
double SolveLevels(const Eigen::ArrayXd& t, double k, Channel* channel) {
  const Eigen::ArrayXd e = (-k * t).exp();
  const Eigen::ArrayXd &w2 = channel->w2, &w2y = channel->w2y;
  const double ee = (w2 * e * e).sum(), e1 = (w2 * e).sum(), ey = (w2y * e).sum();
  // Columns u = e, v = 1 - e: u'u = ee, u'v = e1 - ee, v'v = sum_w2 - 2 e1 + ee.
  const double uu = ee, uv = e1 - ee, vv = channel->sum_w2 - 2 * e1 + ee, uy = ey, vy = channel->sum_w2y - ey;
  const double det = uu * vv - uv * uv;
  if (!(std::fabs(det) > 1e-14 * uu * vv)) return std::numeric_limits<double>::infinity();
  const double L0 = (vv * uy - uv * vy) / det, Linf = (uu * vy - uv * uy) / det;
  channel->levels[0] = L0;
  channel->levels[1] = Linf;
  return (w2 * (channel->y - L0 * e - Linf * (1 - e)).square()).sum();
}

}  // namespace

ChargeFitSummary FitCharge(const Curve& curve, const ChargeFitOptions& options, const std::string& where) {
  const auto start = std::chrono::steady_clock::now();
  ValidateCurve(curve, 4, where);
  // Solved in the curve's own units, so nothing below (the scan's
  // determinant test, Ceres's absolute gradient tolerance and trust region)
  // depends on the units of the data or of the time.
  const CurveScale units = ScaleOfCurve(curve, where);
  const Curve scaled = ScaledCurve(curve, units);
  const int m = static_cast<int>(curve.size()), C = curve.channel_count();
  const Eigen::ArrayXd t = Eigen::Map<const Eigen::ArrayXd>(scaled.t_s.data(), m);
  std::vector<Channel> channels(C);
  bool any_variation = false;
  for (int c = 0; c < C; ++c) {
    const Eigen::ArrayXd raw = Eigen::Map<const Eigen::ArrayXd>(scaled.channels[c].data(), m);
    const double scale = raw.abs().maxCoeff();
    any_variation = any_variation || (scale > 0 && raw.maxCoeff() - raw.minCoeff() > 1e-12 * scale);
    channels[c].scale = scale > 0 ? scale : 1.0;
    channels[c].y = raw / channels[c].scale;
    const std::vector<double> weights = SampleWeights(scaled.channels[c], options.weighting);
    channels[c].w = Eigen::Map<const Eigen::ArrayXd>(weights.data(), m) * channels[c].scale;
    channels[c].w2 = channels[c].w.square();
    channels[c].w2y = channels[c].w2 * channels[c].y;
    channels[c].sum_w2 = channels[c].w2.sum();
    channels[c].sum_w2y = channels[c].w2y.sum();
  }
  if (!any_variation) ThrowUserError(where, "", "every value is the same: there is no growth to fit");

  // Scan log k; the levels of every channel by linear least squares for each.
  const double span = scaled.t_s.back() - scaled.t_s.front();
  const double k_lo = 0.02 / span, k_hi = std::max(3.0 / SmallestTimeStep(scaled), 10 * k_lo);
  double best_cost = std::numeric_limits<double>::infinity(), log_k = 0;
  std::vector<std::array<double, 2>> best_levels(C, {0.0, 0.0});
  for (int g = 0; g < options.rate_grid_size; ++g) {
    const double k = k_lo * std::pow(k_hi / k_lo, static_cast<double>(g) / (options.rate_grid_size - 1));
    double cost = 0;
    for (Channel& channel : channels) cost += SolveLevels(t, k, &channel);
    if (cost < best_cost) {
      best_cost = cost;
      log_k = std::log(k);
      for (int c = 0; c < C; ++c) best_levels[c] = {channels[c].levels[0], channels[c].levels[1]};
    }
  }

  // [log k, L0_0, Linf_0, L0_1, Linf_1, ...] in fit units.
  std::vector<double> params = {log_k};
  for (const auto& levels : best_levels) params.insert(params.end(), levels.begin(), levels.end());
  ceres::Problem problem;
  for (int c = 0; c < C; ++c)
    problem.AddResidualBlock(new ChargeCost(t, channels[c].y, channels[c].w, c, C), nullptr, params.data());
  // No bounds on log k (they would make Ceres project every step with a
  // line search); a rate at the edge of what the samples resolve is caught below.
  const ceres::Solver::Options solver_options = SmallDenseSolverOptions(options.max_iterations, 1e-14);
  ceres::Solver::Summary solver_summary;
  ceres::Solve(solver_options, &problem, &solver_summary);
  // A failed solve (non-finite residuals) must not reach the covariance:
  // ceres::Covariance dereferenced null on the non-finite Jacobian of
  // negative times (e^{-kt} overflowing) and crashed.
  if (!solver_summary.IsSolutionUsable()) ThrowUserError(where, "", "the fit failed: " + solver_summary.message);

  ChargeFitSummary summary;
  log_k = params[0];
  summary.rate = std::exp(log_k) / units.time_s;
  summary.iterations = static_cast<int>(solver_summary.iterations.size());
  summary.converged = solver_summary.termination_type == ceres::CONVERGENCE;
  if (!summary.converged) summary.termination = solver_summary.message;
  // A level that is not reached and a rate at the edge of what the samples
  // resolve mean the curve shows no saturating growth.
  const double edge = std::log(1.05);
  if (!std::isfinite(log_k) || log_k <= std::log(k_lo) + edge || log_k >= std::log(k_hi) - edge)
    ThrowUserError(where, "",
                   "the curve does not approach a level within its time span (no saturating growth or fall)");

  const int n = static_cast<int>(params.size());
  std::vector<double> variance(n, 0.0);
  ceres::Covariance covariance(SmallDenseCovarianceOptions());
  std::vector<std::pair<const double*, const double*>> pairs = {{params.data(), params.data()}};
  if (covariance.Compute(pairs, &problem)) {
    const double reduced_chi2 = 2 * solver_summary.final_cost / std::max(1, m * C - n);
    std::vector<double> block(n * n);
    covariance.GetCovarianceBlock(params.data(), params.data(), block.data());
    for (int i = 0; i < n; ++i) variance[i] = block[i * n + i] * reduced_chi2;
  }
  summary.rate_stderr = summary.rate * std::sqrt(std::max(0.0, variance[0]));
  // Back to the data's units; the residuals summed in the scaled curve's,
  // where their squares cannot overflow or underflow.
  double rss = 0;
  for (int c = 0; c < C; ++c) {
    const double s = channels[c].scale, L0 = params[1 + 2 * c] * s, Linf = params[2 + 2 * c] * s;
    for (int j = 0; j < m; ++j) {
      const double e = std::exp(-std::exp(log_k) * t[j]);
      const double r = scaled.channels[c][j] - (L0 * e + Linf * (1 - e));
      rss += r * r;
    }
    const double to_data = s * units.value;
    summary.levels.push_back({L0 * units.value, Linf * units.value,
                              to_data * std::sqrt(std::max(0.0, variance[1 + 2 * c])),
                              to_data * std::sqrt(std::max(0.0, variance[2 + 2 * c]))});
  }
  summary.rss = rss * units.value * units.value;
  summary.L0 = summary.levels[0].L0;
  summary.Linf = summary.levels[0].Linf;
  summary.L0_stderr = summary.levels[0].L0_stderr;
  summary.Linf_stderr = summary.levels[0].Linf_stderr;
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

}  // namespace phos
