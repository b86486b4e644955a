#include "phos/fit/state_excitation_fit.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <utility>
#include <memory>

#include <Eigen/Dense>
#include <ceres/ceres.h>

#include "phos/fit/excitation_fit.h"
#include "phos/fit/small_nnls.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "excitation_model.h"
#include "relative_covariance.h"
#include "solver_options.h"

namespace phos {
namespace {

struct FrameResidual {
  FrameResidual(std::vector<double> kr, double charge_s, ExcitationFrame frame, double weight, std::vector<double> r0)
      : kr_(std::move(kr)), charge_s_(charge_s), frame_(frame), weight_(weight), r0_(std::move(r0)) {}
  // Parameters: S (per state), a under this frame's light (per state), B.
  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    T sum = p[2][0];
    for (std::size_t i = 0; i < kr_.size(); ++i)
      sum += p[0][i] * ChargedState(p[1][i], T(kr_[i]), charge_s_, r0_.empty() ? 0.0 : r0_[i]) *
             DecayFactor(T(kr_[i]), frame_.delay_s, frame_.exposure_s);
    residual[0] = weight_ * (sum - frame_.value);
    return true;
  }
  std::vector<double> kr_;
  double charge_s_;
  ExcitationFrame frame_;
  double weight_;
  std::vector<double> r0_;
};

double PeakValue(const std::vector<ExcitationMeasurement>& measurements) {
  double peak = 0;
  for (const auto& m : measurements)
    for (const auto& f : m.frames) peak = std::max(peak, std::fabs(f.value));
  return peak;
}

double FrameWeight(const ExcitationFrame& f, Weighting weighting, double peak) {
  if (weighting == Weighting::kNone) return 1.0 / std::max(peak, 1e-300);
  return PhotonCountingWeight(f.value, std::max(f.exposure_s, 1e-6), 1e-3 * peak);
}

// The linear step: how much of each state one measurement's frames show,
// x_i = S_i r_i(t_c) >= 0, by non-negative least squares on the known D_i.
std::vector<double> SplitIntoStates(const ExcitationMeasurement& m, const std::vector<double>& kr, Weighting weighting,
                                    double peak) {
  const int nc = static_cast<int>(kr.size());
  SmallMatrix G = SmallMatrix::Zero(nc, nc);
  SmallVector b = SmallVector::Zero(nc);
  for (const ExcitationFrame& f : m.frames) {
    const double w = FrameWeight(f, weighting, peak);
    std::vector<double> row(static_cast<std::size_t>(nc));
    for (int i = 0; i < nc; ++i) row[i] = DecayFactor(kr[i], f.delay_s, f.exposure_s);
    for (int i = 0; i < nc; ++i) {
      b(i) += w * w * row[i] * f.value;
      for (int j = 0; j < nc; ++j) G(i, j) += w * w * row[i] * row[j];
    }
  }
  // Fewer frames than states: the split is not determined; the diagonal
  // load keeps the solve defined and the Ceres step does the rest.
  for (int i = 0; i < nc; ++i) G(i, i) += 1e-12 * (G.trace() + 1e-300);
  const SmallNnlsResult solved = SolveSmallNnls(G, b, nc);
  std::vector<double> x(static_cast<std::size_t>(nc), 0.0);
  if (solved.ok)
    for (int i = 0; i < nc; ++i) x[i] = solved.x(i);
  return x;
}

struct Start {
  std::vector<double> S;
  std::map<std::string, std::vector<double>> a;
};

// Per state: the light that charges it most gives S_i and its a; every
// other light is fitted with S_i known (read from its level where its
// charging speed barely differs from kr, the weak spot Sec. 8.4.6 names).
Start StartingPoint(const std::vector<ExcitationMeasurement>& measurements, const StateExcitationOptions& options,
                    const std::string& where, std::vector<std::string>* notes) {
  const int nc = static_cast<int>(options.kr.size());
  const double peak = PeakValue(measurements);
  std::map<std::string, std::vector<std::vector<ExcitationSample>>> series;  // light -> state -> samples
  for (const auto& m : measurements) {
    const std::vector<double> x = SplitIntoStates(m, options.kr, options.weighting, peak);
    auto& per_state = series[m.light];
    per_state.resize(static_cast<std::size_t>(nc));
    for (int i = 0; i < nc; ++i) per_state[i].push_back({m.charge_s, 0.0, 0.0, x[i]});
  }
  Start start;
  start.S.assign(static_cast<std::size_t>(nc), 0.0);
  for (auto& [light, per_state] : series) start.a[light].assign(static_cast<std::size_t>(nc), 0.0);
  for (int i = 0; i < nc; ++i) {
    auto level = [&](const std::vector<ExcitationSample>& samples) {
      double best = 0;
      for (const auto& s : samples) best = std::max(best, s.value);
      return best;
    };
    std::string best;
    for (auto& [light, per_state] : series)
      if (best.empty() || level(per_state[i]) > level(series[best][i])) best = light;
    const double best_level = level(series[best][i]);
    if (!(best_level > 0)) {
      notes->push_back("state " + std::to_string(i + 1) + " (kr " + FormatShort(options.kr[i]) +
                       "/s): no light charged it measurably");
      start.S[i] = 1e-6 * peak;
      continue;
    }
    ExcitationFitOptions single;
    single.kr = options.kr[i];
    try {
      const ExcitationFitSummary fit =
          FitExcitation(series[best][i], single, where + " (" + best + ", state " + std::to_string(i + 1) + ")");
      start.S[i] = fit.scale;
      start.a[best][i] = fit.a;
    } catch (const UserError&) {
      // A charging curve that shows no speed: assume a = kr (rho = 1, the
      // middle of Table 8.1) for the start; the refinement moves it.
      start.a[best][i] = options.kr[i];
      start.S[i] = 2 * best_level;
    }
    for (auto& [light, per_state] : series) {
      if (light == best) continue;
      if (level(per_state[i]) < 1e-4 * best_level) continue;  // a = 0: this light does not reach the state
      single.saturated_signal = start.S[i];
      try {
        start.a[light][i] = FitExcitation(per_state[i], single, where + " (" + light + ")").a;
      } catch (const UserError&) {
        start.a[light][i] = 0;
      }
    }
  }
  return start;
}

// The weighted sum of squares of one light's measurements for rates `a`,
// with S and B held.
double LightCost(const std::vector<const ExcitationMeasurement*>& measurements, const std::vector<double>& S,
                 const std::vector<double>& a, const std::vector<double>& kr, double background, Weighting weighting,
                 double peak) {
  double cost = 0;
  for (const ExcitationMeasurement* m : measurements)
    for (const ExcitationFrame& f : m->frames) {
      const double r = FrameWeight(f, weighting, peak) *
                       (ExcitationFrameSignal(S, a, kr, m->charge_s, f, background, m->start_state) - f.value);
      cost += r * r;
    }
  return cost;
}

// S and B given every a: linear, solved exactly (S >= 0) on all frames.
void SolveSignals(const std::vector<ExcitationMeasurement>& measurements, const StateExcitationOptions& options,
                  const std::map<std::string, std::vector<double>>& a, double peak, std::vector<double>* S,
                  double* background) {
  const int nc = static_cast<int>(options.kr.size()), n = nc + 1;
  SmallMatrix G = SmallMatrix::Zero(n, n);
  SmallVector b = SmallVector::Zero(n);
  std::vector<double> unit(static_cast<std::size_t>(nc), 0.0), row(static_cast<std::size_t>(n), 1.0);
  for (const auto& m : measurements)
    for (const ExcitationFrame& f : m.frames) {
      for (int i = 0; i < nc; ++i) {
        std::fill(unit.begin(), unit.end(), 0.0);
        unit[i] = 1;
        row[i] = ExcitationFrameSignal(unit, a.at(m.light), options.kr, m.charge_s, f, 0.0, m.start_state);
      }
      const double w2 = std::pow(FrameWeight(f, options.weighting, peak), 2);
      for (int i = 0; i < n; ++i) {
        b(i) += w2 * row[i] * f.value;
        for (int j = 0; j < n; ++j) G(i, j) += w2 * row[i] * row[j];
      }
    }
  if (!options.background) {
    G(nc, nc) = 1;
    b(nc) = 0;
    for (int i = 0; i < nc; ++i) G(i, nc) = G(nc, i) = 0;
  }
  const SmallNnlsResult solved = SolveSmallNnls(G, b, nc);
  if (!solved.ok) return;
  for (int i = 0; i < nc; ++i) (*S)[i] = solved.x(i);
  *background = solved.x(nc);
}

// A global search of each light's rates, one light at a time (its rates
// touch only its own frames), on a log grid of a_i / kr_i from 1e-3 to 30
// with S and B held; then S and B anew; three rounds. The charging curves
// of two states whose rates are close, one of them faint, have valleys in
// which a local start stays (a weak state's S and a trade along a << kr).
void SearchRates(const std::vector<ExcitationMeasurement>& measurements, const StateExcitationOptions& options,
                 Start* start, double* background) {
  const int nc = static_cast<int>(options.kr.size());
  const double peak = PeakValue(measurements);
  const int per_axis = nc == 1 ? 96 : nc == 2 ? 40 : nc == 3 ? 16 : 9;
  std::vector<double> ratios = {0.0};
  for (int g = 0; g < per_axis; ++g) ratios.push_back(1e-3 * std::pow(3e4, static_cast<double>(g) / (per_axis - 1)));
  std::map<std::string, std::vector<const ExcitationMeasurement*>> by_light;
  for (const auto& m : measurements) by_light[m.light].push_back(&m);
  for (int round = 0; round < 3; ++round) {
    for (auto& [light, list] : by_light) {
      std::vector<double>& best = start->a[light];
      double best_cost = LightCost(list, start->S, best, options.kr, *background, options.weighting, peak);
      std::vector<int> index(static_cast<std::size_t>(nc), 0);
      std::vector<double> trial(static_cast<std::size_t>(nc));
      const std::size_t combinations = static_cast<std::size_t>(std::pow(ratios.size(), nc));
      for (std::size_t c = 0; c < combinations; ++c) {
        std::size_t rest = c;
        for (int i = 0; i < nc; ++i, rest /= ratios.size()) trial[i] = ratios[rest % ratios.size()] * options.kr[i];
        const double cost = LightCost(list, start->S, trial, options.kr, *background, options.weighting, peak);
        if (cost < best_cost) best_cost = cost, best = trial;
      }
    }
    SolveSignals(measurements, options, start->a, peak, &start->S, background);
  }
}

struct Built {
  ceres::Problem problem;
  std::vector<double*> blocks;  // S first, then a per light in map order (B is not among them)
};

void BuildProblem(Built& built, const std::vector<ExcitationMeasurement>& measurements, const std::vector<double>& kr,
                  Weighting weighting, std::vector<double>& S, std::map<std::string, std::vector<double>>& a,
                  double* background, bool fit_background) {
  const int nc = static_cast<int>(kr.size());
  const double peak = PeakValue(measurements);
  built.blocks.push_back(S.data());
  for (auto& [light, values] : a) built.blocks.push_back(values.data());
  for (const auto& m : measurements)
    for (const ExcitationFrame& f : m.frames) {
      auto* cost = new ceres::DynamicAutoDiffCostFunction<FrameResidual, 8>(
          new FrameResidual(kr, m.charge_s, f, FrameWeight(f, weighting, peak), m.start_state));
      cost->AddParameterBlock(nc);
      cost->AddParameterBlock(nc);
      cost->AddParameterBlock(1);
      cost->SetNumResiduals(1);
      built.problem.AddResidualBlock(cost, nullptr, S.data(), a[m.light].data(), background);
    }
  for (double* block : built.blocks)
    for (int i = 0; i < nc; ++i) built.problem.SetParameterLowerBound(block, i, 0.0);
  if (!fit_background) built.problem.SetParameterBlockConstant(background);
}

}  // namespace

bool StateExcitationOptions::IsValid(std::string* error) const {
  if (kr.empty() || kr.size() > 4) return *error = "needs 1 to 4 decay rates", false;
  for (double k : kr)
    if (!(k > 0) || !std::isfinite(k)) return *error = "every kr must be a finite number > 0", false;
  if (max_iterations < 1) return *error = "max_iterations must be >= 1", false;
  return true;
}

double ExcitationFrameSignal(const std::vector<double>& S, const std::vector<double>& a, const std::vector<double>& kr,
                             double charge_s, const ExcitationFrame& frame, double background,
                             const std::vector<double>& start_state) {
  double sum = background;
  for (std::size_t i = 0; i < kr.size(); ++i)
    sum += S[i] * ChargedState(a[i], kr[i], charge_s, start_state.empty() ? 0.0 : start_state[i]) *
           DecayFactor(kr[i], frame.delay_s, frame.exposure_s);
  return sum;
}

void CarryOverStartStates(std::vector<ExcitationMeasurement>& measurements,
                          const std::map<std::string, std::vector<double>>& a, const std::vector<double>& kr) {
  std::vector<ExcitationMeasurement*> order;
  for (ExcitationMeasurement& m : measurements) {
    m.start_state.clear();
    if (std::isfinite(m.light_off_s)) order.push_back(&m);
  }
  std::sort(order.begin(), order.end(), [](const ExcitationMeasurement* x, const ExcitationMeasurement* y) {
    return std::pair(x->run, x->light_off_s) < std::pair(y->run, y->light_off_s);
  });
  for (std::size_t k = 1; k < order.size(); ++k) {
    const ExcitationMeasurement& before = *order[k - 1];
    ExcitationMeasurement& m = *order[k];
    if (before.run != m.run) continue;  // times of another clock: nothing carried over
    const auto rates = a.find(before.light);
    if (rates == a.end()) continue;
    const double dark_s = m.light_off_s - m.charge_s - before.light_off_s;
    if (!(dark_s >= 0)) continue;
    m.start_state.resize(kr.size());
    for (std::size_t i = 0; i < kr.size(); ++i) {
      const double r_off = ChargedState(rates->second[i], kr[i], before.charge_s,
                                        before.start_state.empty() ? 0.0 : before.start_state[i]);
      m.start_state[i] = r_off * DecayFactor(kr[i], dark_s);
    }
  }
}

StateExcitationFit FitStateExcitation(const std::vector<ExcitationMeasurement>& measurements,
                                      const StateExcitationOptions& options, const std::string& where) {
  const auto started = std::chrono::steady_clock::now();
  std::string error;
  if (!options.IsValid(&error)) ThrowUserError(where, "excitation", error);
  if (measurements.empty()) ThrowUserError(where, "excitation", "no measurement to fit");
  for (const auto& m : measurements) {
    if (m.frames.empty()) ThrowUserError(where, "excitation", "a measurement of '" + m.light + "' has no frame");
    if (!(m.charge_s > 0) || !std::isfinite(m.charge_s))
      ThrowUserError(where, "excitation", "charge times must be finite and > 0");
    for (const auto& f : m.frames)
      if (!std::isfinite(f.value) || !(f.delay_s >= 0) || !(f.exposure_s >= 0) || !std::isfinite(f.exposure_s) ||
          !std::isfinite(f.delay_s))
        ThrowUserError(where, "excitation",
                       "frame values, delays and exposures must be finite (delays, exposures >= 0)");
  }
  if (!(PeakValue(measurements) > 0)) ThrowUserError(where, "excitation", "no frame shows any signal");
  StateExcitationFit fit;
  const int nc = static_cast<int>(options.kr.size());
  Start start = StartingPoint(measurements, options, where, &fit.notes);
  SearchRates(measurements, options, &start, &fit.background);
  fit.S = start.S;
  fit.a = start.a;
  // Twice: then with every charge's start carried over from the one before.
  std::vector<ExcitationMeasurement> carried = measurements;
  ceres::Solver::Summary summary;
  std::unique_ptr<Built> built;
  for (int pass = 0; pass < 2; ++pass) {
    if (pass == 1) CarryOverStartStates(carried, fit.a, options.kr);
    built = std::make_unique<Built>();
    BuildProblem(*built, carried, options.kr, options.weighting, fit.S, fit.a, &fit.background, options.background);
    ceres::Solver::Options solver = SmallDenseSolverOptions(options.max_iterations, 1e-12);
    ceres::Solve(solver, &built->problem, &summary);
    fit.iterations += static_cast<int>(summary.iterations.size());
  }
  fit.fitted_measurements = carried;
  fit.converged = summary.IsSolutionUsable() && summary.termination_type == ceres::CONVERGENCE;
  if (!fit.converged) {
    fit.termination = summary.message;
    fit.notes.push_back("the excitation fit did not converge: " + summary.message);
  }
  fit.weighted_rss = 2 * summary.final_cost;
  for (const auto& m : carried)
    for (const ExcitationFrame& f : m.frames) {
      const double r =
          ExcitationFrameSignal(fit.S, fit.a[m.light], options.kr, m.charge_s, f, fit.background, m.start_state) -
          f.value;
      fit.rss += r * r;
      ++fit.frames;
    }
  fit.S_stderr.assign(static_cast<std::size_t>(nc), 0.0);
  for (auto& [light, values] : fit.a) fit.a_stderr[light].assign(static_cast<std::size_t>(nc), 0.0);
  const int parameters = static_cast<int>(built->blocks.size()) * nc + (options.background ? 1 : 0);
  std::vector<CovarianceBlock> blocks;
  for (double* block : built->blocks) blocks.push_back({block, nc, nc});
  if (options.background) blocks.push_back({&fit.background, 1, 0});
  const double chi2 =
      fit.frames > parameters ? fit.weighted_rss / (fit.frames - parameters) : 1.0;  // reduced chi-square
  const RelativeCovariance covariance = ComputeRelativeCovariance(built->problem, blocks, chi2);
  fit.condition_number = covariance.condition_number;
  if (options.compute_uncertainties && fit.frames > parameters) {
    if (covariance.ok) {
      fit.S_stderr = covariance.stderr_per_block[0];
      std::size_t k = 1;
      for (auto& [light, values] : fit.a) fit.a_stderr[light] = covariance.stderr_per_block[k++];
    } else {
      fit.notes.push_back(
          "the excitation's covariance could not be computed (a direction the data do not pin): no "
          "uncertainties");
    }
  }
  fit.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  return fit;
}

DesignInformation ExcitationDesignInformation(const std::vector<ExcitationMeasurement>& design,
                                              const std::vector<double>& S,
                                              const std::map<std::string, std::vector<double>>& a,
                                              const std::vector<double>& kr) {
  std::vector<double> s = S;
  std::map<std::string, std::vector<double>> rates = a;
  // Noise-free data from the parameters themselves: the Jacobian at the truth.
  std::vector<ExcitationMeasurement> exact = design;
  for (auto& m : exact)
    for (auto& f : m.frames) f.value = ExcitationFrameSignal(S, a.at(m.light), kr, m.charge_s, f);
  Built built;
  double background = 0;
  BuildProblem(built, exact, kr, Weighting::kPoisson, s, rates, &background, false);
  const int nc = static_cast<int>(kr.size());
  std::vector<CovarianceBlock> blocks;
  for (double* block : built.blocks) blocks.push_back({block, nc, nc});
  // FrameWeight's floor aside, its weights are 1/sigma for one electron per unit: chi2 = 1.
  const RelativeCovariance covariance = ComputeRelativeCovariance(built.problem, blocks, 1.0);
  DesignInformation information;
  information.condition_number = covariance.condition_number;
  std::size_t k = 1;
  for (auto& [light, values] : rates) {
    std::vector<double>& relative = information.a_relative_stderr[light];
    for (int i = 0; i < nc; ++i) {
      relative.push_back(covariance.ok && values[i] > 0 ? covariance.stderr_per_block[k][i] / values[i]
                                                        : std::numeric_limits<double>::infinity());
      information.worst_a_relative_stderr = std::max(information.worst_a_relative_stderr, relative.back());
    }
    ++k;
  }
  return information;
}

}  // namespace phos
