#include "phos/fit/charge_fit.h"

#include <chrono>
#include <cmath>
#include <limits>

#include <ceres/ceres.h>
#include <Eigen/Dense>

#include "phos/util/error.h"
#include "solver_options.h"

namespace phos {
namespace {

// L(t) = Linf - (Linf - L0) e^{-kt} = L0 e^{-kt} + Linf (1 - e^{-kt}); blocks: [log k, L0, Linf].
class ChargeCost final : public ceres::SizedCostFunction<ceres::DYNAMIC, 3> {
 public:
  ChargeCost(const Eigen::ArrayXd& t, const Eigen::ArrayXd& y, const Eigen::ArrayXd& w)
      : t_(t), y_(y), w_(w) {
    set_num_residuals(static_cast<int>(t.size()));
  }

  bool Evaluate(double const* const* p, double* residuals, double** jacobians) const override {
    const double k = std::exp(p[0][0]), L0 = p[0][1], Linf = p[0][2];
    for (int j = 0; j < t_.size(); ++j) {
      const double e = std::exp(-k * t_[j]);
      residuals[j] = w_[j] * (y_[j] - (L0 * e + Linf * (1 - e)));
      if (jacobians != nullptr && jacobians[0] != nullptr) {
        jacobians[0][3 * j + 0] = w_[j] * (L0 - Linf) * t_[j] * k * e;  // d/d log k of -(model)
        jacobians[0][3 * j + 1] = -w_[j] * e;
        jacobians[0][3 * j + 2] = -w_[j] * (1 - e);
      }
    }
    return true;
  }

 private:
  const Eigen::ArrayXd& t_;
  const Eigen::ArrayXd& y_;
  const Eigen::ArrayXd& w_;
};

}  // namespace

ChargeFitSummary FitCharge(const Curve& curve, const ChargeFitOptions& options, const std::string& where) {
  const auto start = std::chrono::steady_clock::now();
  ValidateCurve(curve, 4, where);
  const int m = static_cast<int>(curve.size());
  Eigen::ArrayXd t = Eigen::Map<const Eigen::ArrayXd>(curve.t_s.data(), m);
  const Eigen::ArrayXd raw = Eigen::Map<const Eigen::ArrayXd>(curve.channels[0].data(), m);
  const double scale = raw.abs().maxCoeff();
  if (!(scale > 0) || raw.maxCoeff() - raw.minCoeff() <= 1e-12 * scale)
    ThrowUserError(where, "", "every value is the same: there is no growth to fit");
  const Eigen::ArrayXd y = raw / scale;
  std::vector<double> weights = SampleWeights(curve.channels[0], options.weighting);
  const Eigen::ArrayXd w = Eigen::Map<const Eigen::ArrayXd>(weights.data(), m) * scale;

  // Scan log k; L0 and Linf by linear least squares for each.
  const double span = curve.t_s.back() - curve.t_s.front();
  double spacing = span;
  for (int j = 1; j < m; ++j) spacing = std::min(spacing, curve.t_s[j] - curve.t_s[j - 1]);
  const double k_lo = 0.02 / span, k_hi = std::max(3.0 / spacing, 10 * k_lo);
  double best_cost = std::numeric_limits<double>::infinity();
  double params[3] = {0, 0, 0};
  // For each k, L0 and Linf from the 2 x 2 normal equations of the columns
  // e^{-kt} and 1 - e^{-kt} (weighted): three dot products, no factorization.
  const Eigen::ArrayXd w2 = w.square(), w2y = w2 * y;
  const double sum_w2 = w2.sum(), sum_w2y = w2y.sum();
  for (int g = 0; g < options.rate_grid_size; ++g) {
    const double k = k_lo * std::pow(k_hi / k_lo, static_cast<double>(g) / (options.rate_grid_size - 1));
    const Eigen::ArrayXd e = (-k * t).exp();
    const double ee = (w2 * e * e).sum(), e1 = (w2 * e).sum(), ey = (w2y * e).sum();
    // Columns u = e, v = 1 - e: u'u = ee, u'v = e1 - ee, v'v = sum_w2 - 2 e1 + ee.
    const double uu = ee, uv = e1 - ee, vv = sum_w2 - 2 * e1 + ee, uy = ey, vy = sum_w2y - ey;
    const double det = uu * vv - uv * uv;
    if (!(std::fabs(det) > 1e-14 * uu * vv)) continue;
    const double L0 = (vv * uy - uv * vy) / det, Linf = (uu * vy - uv * uy) / det;
    const double cost = (w2 * (y - L0 * e - Linf * (1 - e)).square()).sum();
    if (cost < best_cost) {
      best_cost = cost;
      params[0] = std::log(k);
      params[1] = L0;
      params[2] = Linf;
    }
  }

  ceres::Problem problem;
  problem.AddResidualBlock(new ChargeCost(t, y, w), nullptr, params);
  // No bounds on log k (they would make Ceres project every step with a
  // line search); a rate at the edge of what the samples resolve is caught below.
  const ceres::Solver::Options solver_options = SmallDenseSolverOptions(options.max_iterations, 1e-14);
  ceres::Solver::Summary solver_summary;
  ceres::Solve(solver_options, &problem, &solver_summary);

  ChargeFitSummary summary;
  summary.rate = std::exp(params[0]);
  summary.L0 = params[1] * scale;
  summary.Linf = params[2] * scale;
  summary.iterations = static_cast<int>(solver_summary.iterations.size());
  // A level that is not reached and a rate at the edge of what the samples
  // resolve mean the curve shows no saturating growth.
  const double edge = std::log(1.05);
  if (params[0] <= std::log(k_lo) + edge || params[0] >= std::log(k_hi) - edge)
    ThrowUserError(where, "", "the curve does not approach a level within its time span (no saturating growth or fall)");

  ceres::Covariance::Options covariance_options;
  covariance_options.algorithm_type = ceres::DENSE_SVD;
  covariance_options.null_space_rank = -1;
  ceres::Covariance covariance(covariance_options);
  std::vector<std::pair<const double*, const double*>> pairs = {{params, params}};
  if (covariance.Compute(pairs, &problem)) {
    double block[9];
    covariance.GetCovarianceBlock(params, params, block);
    const double reduced_chi2 = 2 * solver_summary.final_cost / std::max(1, m - 3);
    summary.rate_stderr = summary.rate * std::sqrt(std::max(0.0, block[0] * reduced_chi2));
    summary.L0_stderr = scale * std::sqrt(std::max(0.0, block[4] * reduced_chi2));
    summary.Linf_stderr = scale * std::sqrt(std::max(0.0, block[8] * reduced_chi2));
  }
  for (int j = 0; j < m; ++j) {
    const double e = std::exp(-summary.rate * t[j]);
    const double r = raw[j] - (summary.L0 * e + summary.Linf * (1 - e));
    summary.rss += r * r;
  }
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

}  // namespace phos
