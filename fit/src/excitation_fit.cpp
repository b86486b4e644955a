#include "phos/fit/excitation_fit.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include <Eigen/Dense>
#include <ceres/ceres.h>

#include "phos/fit/small_nnls.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "excitation_model.h"
#include "solver_options.h"

namespace phos {
namespace {

struct ExcitationResidual {
  ExcitationResidual(const ExcitationSample& sample, double kr, double weight)
      : sample_(sample), kr_(kr), weight_(weight) {}
  // Parameters: log a, S.
  template <typename T>
  bool operator()(const T* log_a, const T* S, T* residual) const {
    using std::exp;
    const T a = exp(log_a[0]);
    const T kr(kr_);
    residual[0] = weight_ * (sample_.value - S[0] * ChargedState(a, kr, sample_.charge_s) *
                                                 DecayFactor(kr, sample_.delay_s, sample_.exposure_s));
    return true;
  }
  ExcitationSample sample_;
  double kr_, weight_;
};

struct Solved {
  double log_a, S, log_a_var, S_var, rss;
};

// Fits log a (and S unless fixed) to `samples`; `speed_only` divides out
// the level so only the shape of the charging curve counts.
Solved Solve(const std::vector<ExcitationSample>& samples, const ExcitationFitOptions& options, double log_a0,
             double S0, bool fix_S) {
  std::vector<double> values;
  for (const ExcitationSample& s : samples) values.push_back(s.value);
  const std::vector<double> weights = SampleWeights(values, options.weighting);
  double log_a = log_a0, S = S0;
  ceres::Problem problem;
  for (std::size_t j = 0; j < samples.size(); ++j)
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<ExcitationResidual, 1, 1, 1>(
                                 new ExcitationResidual(samples[j], options.kr, weights[j])),
                             nullptr, &log_a, &S);
  if (fix_S) problem.SetParameterBlockConstant(&S);
  const ceres::Solver::Options solver_options = SmallDenseSolverOptions(options.max_iterations, 1e-12);
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);

  Solved solved{log_a, S, 0, 0, 0};
  const double dof = std::max(1.0, static_cast<double>(samples.size()) - (fix_S ? 1 : 2));
  const double reduced_chi2 = 2 * summary.final_cost / dof;
  ceres::Covariance::Options covariance_options;
  covariance_options.algorithm_type = ceres::DENSE_SVD;
  covariance_options.null_space_rank = -1;
  ceres::Covariance covariance(covariance_options);
  std::vector<std::pair<const double*, const double*>> pairs = {{&log_a, &log_a}};
  if (!fix_S) pairs.push_back({&S, &S});
  if (covariance.Compute(pairs, &problem)) {
    covariance.GetCovarianceBlock(&log_a, &log_a, &solved.log_a_var);
    solved.log_a_var *= reduced_chi2;
    if (!fix_S) {
      covariance.GetCovarianceBlock(&S, &S, &solved.S_var);
      solved.S_var *= reduced_chi2;
    }
  }
  for (const ExcitationSample& s : samples) {
    const double r = s.value - ExcitationSignal(std::exp(log_a), options.kr, S, s);
    solved.rss += r * r;
  }
  return solved;
}

}  // namespace

double ExcitationSignal(double a, double kr, double S, const ExcitationSample& sample) {
  return S * ChargedState(a, kr, sample.charge_s) * DecayFactor(kr, sample.delay_s, sample.exposure_s);
}

ExcitationFitSummary FitExcitation(const std::vector<ExcitationSample>& samples, const ExcitationFitOptions& options,
                                   const std::string& where) {
  const auto start = std::chrono::steady_clock::now();
  if (!(options.kr > 0) || !std::isfinite(options.kr))
    ThrowUserError(where, "kr", "expected the decay rate from a decay fit (> 0), got " + FormatDouble(options.kr));
  if (samples.size() < 3)
    ThrowUserError(
        where, "",
        "has " + std::to_string(samples.size()) + " experiments; an excitation fit needs at least 3 charge times");
  double longest = 0, shortest = std::numeric_limits<double>::infinity(), peak = 0;
  for (std::size_t j = 0; j < samples.size(); ++j) {
    const ExcitationSample& s = samples[j];
    if (!(s.charge_s > 0) || !(s.delay_s >= 0) || !(s.exposure_s >= 0) || !std::isfinite(s.value) ||
        !std::isfinite(s.charge_s) || !std::isfinite(s.delay_s) || !std::isfinite(s.exposure_s))
      ThrowUserError(where, "experiment " + std::to_string(j + 1),
                     "needs a charge time > 0, a delay and an exposure >= 0, and a finite value");
    longest = std::max(longest, s.charge_s);
    shortest = std::min(shortest, s.charge_s);
    peak = std::max(peak, s.value);
  }
  if (!(peak > 0)) ThrowUserError(where, "", "no experiment shows any glow: nothing to fit");
  if (!(longest > shortest))
    ThrowUserError(where, "", "every experiment has the same charge time: the charging speed is unknown");

  // Start: a from a rate scan with S solved linearly (the signal is linear in S).
  double best_cost = std::numeric_limits<double>::infinity(), log_a0 = 0, S0 = 0;
  const double a_lo = 1e-3 / longest, a_hi = 1e3 / shortest;
  for (int g = 0; g < 64; ++g) {
    const double a = a_lo * std::pow(a_hi / a_lo, g / 63.0);
    double num = 0, den = 0;
    for (const ExcitationSample& s : samples) {
      const double unit = ExcitationSignal(a, options.kr, 1.0, s);
      num += unit * s.value;
      den += unit * unit;
    }
    const double S = options.saturated_signal ? *options.saturated_signal : (den > 0 ? num / den : 0);
    double cost = 0;
    for (const ExcitationSample& s : samples) cost += std::pow(s.value - ExcitationSignal(a, options.kr, S, s), 2);
    if (cost < best_cost) {
      best_cost = cost;
      log_a0 = std::log(a);
      S0 = S;
    }
  }

  ExcitationFitSummary summary;
  const bool known_S = options.saturated_signal.has_value();
  Solved joint = Solve(samples, options, log_a0, S0, known_S);
  summary.a = std::exp(joint.log_a);
  summary.a_stderr = summary.a * std::sqrt(std::max(0.0, joint.log_a_var));
  summary.scale = joint.S;
  summary.scale_stderr = std::sqrt(std::max(0.0, joint.S_var));
  summary.rss = joint.rss;

  if (known_S) {
    // Speed alone: S free, so only the shape of the curve over charge time
    // constrains a. Level alone: the longest charges, where the curve has
    // flattened, against the known S.
    Solved speed = Solve(samples, options, joint.log_a, joint.S, false);
    summary.a_from_speed = std::exp(speed.log_a);
    std::vector<ExcitationSample> late;
    for (const ExcitationSample& s : samples)
      if (s.charge_s * (summary.a + options.kr) >= 3) late.push_back(s);  // 95% of the way to equilibrium
    if (!late.empty()) {
      Solved level = Solve(late, options, joint.log_a, *options.saturated_signal, true);
      summary.a_from_level = std::exp(level.log_a);
      const double sigma = std::hypot(*summary.a_from_speed * std::sqrt(std::max(0.0, speed.log_a_var)),
                                      *summary.a_from_level * std::sqrt(std::max(0.0, level.log_a_var)));
      summary.level_and_speed_disagree =
          std::fabs(*summary.a_from_level - *summary.a_from_speed) > 3 * sigma && sigma > 0;
      if (summary.level_and_speed_disagree)
        summary.note = "the equilibrium level gives a = " + FormatShort(*summary.a_from_level) +
                       "/s but the charging speed gives a = " + FormatShort(*summary.a_from_speed) +
                       "/s (more than 3 sigma apart): check the saturated signal, the delay, or a second state";
    } else {
      summary.note = "no charge long enough to reach equilibrium: the level could not be checked against the speed";
    }
  }
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

namespace {
struct KeResidual {
  KeResidual(std::vector<double> E, double a, double scale) : E_(std::move(E)), a_(a), scale_(scale) {}
  template <typename T>
  bool operator()(T const* const* ke, T* residual) const {
    T sum(0);
    for (std::size_t b = 0; b < E_.size(); ++b) sum += ke[0][b] * E_[b];
    residual[0] = (sum - a_) / scale_;  // relative: each light counts the same
    return true;
  }
  std::vector<double> E_;
  double a_, scale_;
};
}  // namespace

std::vector<std::optional<double>> KeFromExcitationRates(const std::vector<std::vector<double>>& E_per_light,
                                                         const std::vector<double>& a_per_light,
                                                         const std::string& where) {
  if (E_per_light.empty() || E_per_light.size() != a_per_light.size())
    ThrowUserError(where, "", "needs one excitation rate per light");
  const std::size_t bands = E_per_light[0].size();
  for (std::size_t l = 0; l < E_per_light.size(); ++l) {
    if (E_per_light[l].size() != bands) ThrowUserError(where, "light " + std::to_string(l + 1), "band count differs");
    // 0 is a measurement too: that light does not excite the sample.
    if (!(a_per_light[l] >= 0)) ThrowUserError(where, "light " + std::to_string(l + 1), "excitation rate must be >= 0");
  }
  // Only the bands some light reaches are parameters.
  std::vector<int> lit;
  for (std::size_t b = 0; b < bands; ++b) {
    bool reached = false;
    for (const auto& E : E_per_light) reached = reached || E[b] > 0;
    if (reached) lit.push_back(static_cast<int>(b));
  }
  if (lit.empty()) ThrowUserError(where, "", "no light reaches any band: ke cannot be measured");
  // Start: every lit band equally responsible for the mean rate.
  double mean_ratio = 0;
  for (std::size_t l = 0; l < E_per_light.size(); ++l) {
    double total = 0;
    for (int b : lit) total += E_per_light[l][b];
    if (total > 0) mean_ratio += a_per_light[l] / total / static_cast<double>(E_per_light.size());
  }
  mean_ratio = std::max(mean_ratio, 1e-12);  // a start inside the bounds, even when no light excites
  std::vector<double> ke(lit.size(), mean_ratio);
  ceres::Problem problem;
  for (std::size_t l = 0; l < E_per_light.size(); ++l) {
    std::vector<double> E;
    for (int b : lit) E.push_back(E_per_light[l][b]);
    // Relative to the light's own rate; a light that does not excite (a = 0)
    // is held to 0.1% of the strongest, the resolution the rates have.
    const double strongest = *std::max_element(a_per_light.begin(), a_per_light.end());
    const double scale = std::max(a_per_light[l], strongest > 0 ? 1e-3 * strongest : 1.0);
    auto* cost = new ceres::DynamicAutoDiffCostFunction<KeResidual>(new KeResidual(E, a_per_light[l], scale));
    cost->AddParameterBlock(static_cast<int>(lit.size()));
    cost->SetNumResiduals(1);
    problem.AddResidualBlock(cost, nullptr, ke.data());
  }
  for (std::size_t b = 0; b < lit.size(); ++b) problem.SetParameterLowerBound(ke.data(), static_cast<int>(b), 0.0);
  ceres::Solver::Options options = SmallDenseSolverOptions(200, 1e-14);
  options.parameter_tolerance = 1e-14;
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  std::vector<std::optional<double>> result(bands);
  for (std::size_t i = 0; i < lit.size(); ++i) result[lit[i]] = ke[i];
  return result;
}

KeEstimate KeWithUncertainty(const std::vector<std::vector<double>>& E_per_light,
                             const std::vector<double>& a_per_light, const std::vector<double>& a_stderr_per_light,
                             const std::string& where) {
  KeEstimate estimate;
  estimate.ke = KeFromExcitationRates(E_per_light, a_per_light, where);
  const std::size_t bands = estimate.ke.size();
  estimate.ke_stderr.assign(bands, std::nullopt);
  if (a_stderr_per_light.size() != a_per_light.size()) return estimate;
  const double strongest = *std::max_element(a_per_light.begin(), a_per_light.end());
  std::vector<int> free_bands;
  for (std::size_t b = 0; b < bands; ++b)
    if (estimate.ke[b] && *estimate.ke[b] > 1e-9 * std::max(strongest, 1e-300))
      free_bands.push_back(static_cast<int>(b));
  if (free_bands.empty()) return estimate;
  if (free_bands.size() > 64) return estimate;
  BoundedMatrix normal =
      BoundedMatrix::Zero(static_cast<Eigen::Index>(free_bands.size()), static_cast<Eigen::Index>(free_bands.size()));
  for (std::size_t l = 0; l < E_per_light.size(); ++l) {
    const double sigma = a_stderr_per_light[l];
    if (!(sigma > 0)) return estimate;  // an exact rate: no uncertainty to carry
    for (std::size_t i = 0; i < free_bands.size(); ++i)
      for (std::size_t j = 0; j < free_bands.size(); ++j)
        normal(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) +=
            E_per_light[l][free_bands[i]] * E_per_light[l][free_bands[j]] / (sigma * sigma);
  }
  const Eigen::FullPivLU<BoundedMatrix> lu(normal);
  if (!lu.isInvertible()) return estimate;
  const BoundedMatrix covariance = lu.inverse();
  for (std::size_t i = 0; i < free_bands.size(); ++i)
    estimate.ke_stderr[free_bands[i]] =
        std::sqrt(std::max(0.0, covariance(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(i))));
  return estimate;
}

}  // namespace phos
