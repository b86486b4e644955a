#include "phos/fit/schedule_fit.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>

#include <ceres/ceres.h>
#include <Eigen/Dense>

#include "phos/fit/small_nnls.h"
#include "phos/model/closed_form.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "solver_options.h"

namespace phos {
namespace {

// One interval of constant light that ends at a sample or at a switch of
// the light; `sample` is the sample it ends at, or -1.
struct Step {
  double dt = 0;
  bool on = false;
  int sample = -1;
};

// The curve's times as intervals of constant light from a dark start, so
// that a state is carried from sample to sample by the closed form of
// Eq. 8.1 over each interval, exact for any sampling.
struct Timeline {
  std::vector<Step> steps;
  std::vector<char> on;  // per sample: the light is on there (the prompt term)
};

bool LightOnAt(const std::vector<LightWindow>& lights, double t) {
  return std::any_of(lights.begin(), lights.end(), [t](const LightWindow& w) { return w.on_s <= t && t < w.off_s; });
}

Timeline MakeTimeline(const std::vector<double>& t, const std::vector<LightWindow>& lights, double start) {
  std::vector<double> switches;
  for (const LightWindow& w : lights)
    for (double s : {w.on_s, w.off_s})
      if (s > start) switches.push_back(s);
  std::sort(switches.begin(), switches.end());
  Timeline timeline;
  double now = start;
  bool on = LightOnAt(lights, start);
  std::size_t next = 0;
  for (std::size_t j = 0; j < t.size(); ++j) {
    for (; next < switches.size() && switches[next] <= t[j]; ++next) {
      if (switches[next] > now) timeline.steps.push_back({switches[next] - now, on, -1});
      now = switches[next];
      on = LightOnAt(lights, now);
    }
    timeline.steps.push_back({t[j] - now, on, static_cast<int>(j)});
    timeline.on.push_back(on);
    now = t[j];
  }
  return timeline;
}

// Carries n states along the timeline from r = 0 (Eq. 8.1 in closed form,
// model/closed_form.h) and calls at_sample(j, r) at every sample. T: double
// or a ceres::Jet.
template <typename T, typename AtSample>
void Propagate(const Timeline& timeline, const std::vector<T>& kr, const std::vector<T>& a, AtSample at_sample) {
  std::vector<T> r(kr.size(), T(0));
  for (const Step& step : timeline.steps) {
    for (std::size_t i = 0; i < r.size(); ++i)
      r[i] = step.on ? ChargedState(a[i], kr[i], step.dt, r[i]) : r[i] * DecayFactor(kr[i], step.dt);
    if (step.sample >= 0) at_sample(step.sample, r);
  }
}

// Every parameter in the curve's units (times / span, values / the largest
// |value|): rates as logs, S[i * C + c].
struct Params {
  std::vector<double> log_kr, log_a, S, P, B;
  int n() const { return static_cast<int>(log_kr.size()); }
};

struct Data {
  Timeline timeline;
  std::vector<std::vector<double>> y;      // per channel, scaled
  std::vector<std::vector<double>> w, w2;  // per channel: weights and their squares
  int m = 0, C = 0;
  double k_lo = 0, k_hi = 0, a_lo = 0, a_hi = 0;  // the rates the samples resolve
};

// The weighted residual of every sample and channel, w (y - model), at
// residual[c * m + j].
struct ScheduleResidual {
  const Data* data;
  int n;
  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    const int C = data->C, m = data->m;
    std::vector<T> kr(n), a(n);
    for (int i = 0; i < n; ++i) {
      using std::exp;
      kr[i] = exp(p[0][i]);
      a[i] = exp(p[1][i]);
    }
    const T *S = p[2], *P = p[3], *B = p[4];
    Propagate(data->timeline, kr, a, [&](int j, const std::vector<T>& r) {
      for (int c = 0; c < C; ++c) {
        T model = B[c];
        if (data->timeline.on[j]) model += P[c];
        for (int i = 0; i < n; ++i) model += S[i * C + c] * r[i];
        residual[c * m + j] = data->w[c][j] * (data->y[c][j] - model);
      }
    });
    return true;
  }
};

using BoundedVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 64, 1>;

// Least squares with x[k] >= 0 where constrained[k], on the normal
// equations G x = b (a dozen unknowns at most): the unconstrained solution
// on a support that drops the most negative entry until none is, then takes
// back the entry whose gradient asks most (Lawson and Hanson's active set,
// capped at a few rounds: it gives starting values, which Ceres refines
// with bounds).
BoundedVector SolveNonNegativeNormal(const BoundedMatrix& G, const BoundedVector& b,
                                     const std::vector<char>& constrained) {
  const Eigen::Index p = G.rows();
  std::vector<char> in(static_cast<std::size_t>(p), 1);
  BoundedVector x = BoundedVector::Zero(p);
  const double ridge = 1e-12 * std::max(G.diagonal().cwiseAbs().maxCoeff(), 1e-300);
  for (int round = 0; round < 3 * static_cast<int>(p); ++round) {
    std::vector<Eigen::Index> keep;
    for (Eigen::Index k = 0; k < p; ++k)
      if (in[k]) keep.push_back(k);
    const auto q = static_cast<Eigen::Index>(keep.size());
    BoundedMatrix g(q, q);
    BoundedVector rhs(q);
    for (Eigen::Index u = 0; u < q; ++u) {
      for (Eigen::Index v = 0; v < q; ++v) g(u, v) = G(keep[u], keep[v]);
      g(u, u) += ridge;
      rhs(u) = b(keep[u]);
    }
    const BoundedVector z = g.ldlt().solve(rhs);
    x.setZero();
    Eigen::Index worst = -1;
    for (Eigen::Index u = 0; u < q; ++u) {
      x(keep[u]) = z(u);
      if (constrained[keep[u]] && z(u) < 0 && (worst < 0 || z(u) < x(worst))) worst = keep[u];
    }
    if (worst >= 0) {
      in[worst] = 0;
      x(worst) = 0;
      continue;
    }
    const BoundedVector gradient = b - G * x;
    Eigen::Index best = -1;
    for (Eigen::Index k = 0; k < p; ++k)
      if (!in[k] && gradient(k) > 1e-9 * std::sqrt(G(k, k)) && (best < 0 || gradient(k) > gradient(best))) best = k;
    if (best < 0) break;
    in[best] = 1;
  }
  return x;
}

// r of one state at every sample, from the dark start.
std::vector<double> StateColumn(const Data& d, double kr, double a) {
  std::vector<double> column(static_cast<std::size_t>(d.m));
  Propagate<double>(d.timeline, {kr}, {a}, [&](int j, const std::vector<double>& r) { column[j] = r[0]; });
  return column;
}

// sum_j w2_j u_j v_j
double Dot(const std::vector<double>& u, const std::vector<double>& v, const std::vector<double>& w2) {
  double sum = 0;
  for (std::size_t j = 0; j < u.size(); ++j) sum += w2[j] * u[j] * v[j];
  return sum;
}

// The linear part of the model at fixed rates: columns [light on, 1,
// r_1 .. r_n] (P, B, S_1 .. S_n per channel; all but B >= 0), their
// weighted normal matrix and right-hand side per channel, so that a
// candidate state costs one column's dot products.
struct LinearSystem {
  std::vector<std::vector<double>> columns;
  std::vector<BoundedMatrix> G;  // per channel
  std::vector<BoundedVector> b;  // per channel
  std::vector<double> yy;        // per channel

  LinearSystem(const Data& d, const std::vector<std::vector<double>>& states) {
    std::vector<double> on(d.timeline.on.begin(), d.timeline.on.end()), one(static_cast<std::size_t>(d.m), 1.0);
    columns = {on, one};
    columns.insert(columns.end(), states.begin(), states.end());
    const auto q = static_cast<Eigen::Index>(columns.size());
    for (int c = 0; c < d.C; ++c) {
      const std::vector<double>& w2 = d.w2[c];
      G.emplace_back(q, q);
      b.emplace_back(q);
      for (Eigen::Index u = 0; u < q; ++u) {
        for (Eigen::Index v = 0; v <= u; ++v) G.back()(u, v) = G.back()(v, u) = Dot(columns[u], columns[v], w2);
        b.back()(u) = Dot(columns[u], d.y[c], w2);
      }
      yy.push_back(Dot(d.y[c], d.y[c], w2));
    }
  }

  // The weighted least-squares cost (every channel) with one more state
  // column (none if empty), and the linear parameters per channel.
  double Solve(const Data& d, const std::vector<double>& extra, std::vector<BoundedVector>* x) const {
    const Eigen::Index q0 = static_cast<Eigen::Index>(columns.size()), q = q0 + (extra.empty() ? 0 : 1);
    std::vector<char> constrained(static_cast<std::size_t>(q), 1);
    constrained[1] = 0;  // the background
    double cost = 0;
    x->clear();
    for (int c = 0; c < d.C; ++c) {
      BoundedMatrix g(q, q);
      BoundedVector rhs(q);
      g.topLeftCorner(q0, q0) = G[c];
      rhs.head(q0) = b[c];
      if (q > q0) {
        for (Eigen::Index u = 0; u < q0; ++u) g(u, q0) = g(q0, u) = Dot(columns[u], extra, d.w2[c]);
        g(q0, q0) = Dot(extra, extra, d.w2[c]);
        rhs(q0) = Dot(extra, d.y[c], d.w2[c]);
      }
      x->push_back(SolveNonNegativeNormal(g, rhs, constrained));
      cost += std::max(0.0, yy[c] - 2 * x->back().dot(rhs) + x->back().dot(g * x->back()));
    }
    return cost;
  }
};

// Sets S, P and B of `p` from the linear solution (columns as LinearSystem's).
void SetLinear(const std::vector<BoundedVector>& x, int C, Params* p) {
  const int n = p->n();
  p->S.assign(static_cast<std::size_t>(n * C), 0.0);
  p->P.assign(static_cast<std::size_t>(C), 0.0);
  p->B.assign(static_cast<std::size_t>(C), 0.0);
  for (int c = 0; c < C; ++c) {
    p->P[c] = x[c](0);
    p->B[c] = x[c](1);
    for (int i = 0; i < n; ++i) p->S[i * C + c] = x[c](2 + i);
  }
}

std::vector<double> LogGrid(double lo, double hi, int count) {
  std::vector<double> grid;
  for (int g = 0; g < count; ++g) grid.push_back(lo * std::pow(hi / lo, static_cast<double>(g) / (count - 1)));
  return grid;
}

// The states of `held` and one more, its (kr, a) the best of a log grid of
// both with the others held and S, P, B solved exactly (variable projection,
// as the decay fits add components).
Params AddState(const Data& d, const Params& held, const ScheduleFitOptions& options) {
  std::vector<std::vector<double>> columns;
  for (int i = 0; i < held.n(); ++i)
    columns.push_back(StateColumn(d, std::exp(held.log_kr[i]), std::exp(held.log_a[i])));
  const LinearSystem system(d, columns);
  double best_cost = std::numeric_limits<double>::infinity();
  Params best = held;
  std::vector<BoundedVector> x;
  for (double kr : LogGrid(d.k_lo, d.k_hi, options.rate_grid_size))
    for (double a : LogGrid(d.a_lo, d.a_hi, options.charge_grid_size)) {
      const double cost = system.Solve(d, StateColumn(d, kr, a), &x);
      if (!(cost < best_cost)) continue;
      best_cost = cost;
      best = held;
      best.log_kr.push_back(std::log(kr));
      best.log_a.push_back(std::log(a));
      SetLinear(x, d.C, &best);
    }
  return best;
}

// One number of states, refined.
struct Stage {
  Params p;
  double cost = 0;  // sum of squares, scaled units
  bool usable = false, converged = false;
  int iterations = 0;
  std::vector<double> var_log_kr, var_log_a, var_S, var_P, var_B;  // variances, scaled units (0 if unknown)
};

// The diagonal of the covariance of each block, scaled by the reduced
// chi-square; zeros if Ceres cannot compute it.
void Variances(ceres::Problem& problem, Params& p, double chi2, Stage* stage) {
  std::vector<std::vector<double>*> blocks = {&p.log_kr, &p.log_a, &p.S, &p.P, &p.B};
  std::vector<std::vector<double>*> out = {&stage->var_log_kr, &stage->var_log_a, &stage->var_S, &stage->var_P,
                                           &stage->var_B};
  std::vector<std::pair<const double*, const double*>> pairs;
  for (auto* block : blocks) pairs.emplace_back(block->data(), block->data());
  for (std::size_t k = 0; k < blocks.size(); ++k) out[k]->assign(blocks[k]->size(), 0.0);
  ceres::Covariance covariance(SmallDenseCovarianceOptions());
  if (!covariance.Compute(pairs, &problem)) return;
  for (std::size_t k = 0; k < blocks.size(); ++k) {
    const std::size_t size = blocks[k]->size();
    std::vector<double> block(size * size);
    covariance.GetCovarianceBlock(blocks[k]->data(), blocks[k]->data(), block.data());
    for (std::size_t i = 0; i < size; ++i) (*out[k])[i] = std::max(0.0, block[i * size + i]) * chi2;
  }
}

// Every parameter at once, by Ceres (automatic differentiation through the
// closed form), rates bounded to a decade beyond what the samples resolve.
Stage Refine(const Data& d, Params p, const ScheduleFitOptions& options) {
  const int n = p.n(), C = d.C;
  ceres::Problem problem;
  auto* cost = new ceres::DynamicAutoDiffCostFunction<ScheduleResidual, 8>(new ScheduleResidual{&d, n});
  for (int size : {n, n, n * C, C, C}) cost->AddParameterBlock(size);
  cost->SetNumResiduals(d.m * C);
  problem.AddResidualBlock(cost, nullptr, p.log_kr.data(), p.log_a.data(), p.S.data(), p.P.data(), p.B.data());
  for (int i = 0; i < n; ++i) {
    problem.SetParameterLowerBound(p.log_kr.data(), i, std::log(d.k_lo / 10));
    problem.SetParameterUpperBound(p.log_kr.data(), i, std::log(d.k_hi * 10));
    problem.SetParameterLowerBound(p.log_a.data(), i, std::log(d.a_lo / 10));
    problem.SetParameterUpperBound(p.log_a.data(), i, std::log(d.a_hi * 10));
  }
  for (int k = 0; k < n * C; ++k) problem.SetParameterLowerBound(p.S.data(), k, 0.0);
  for (int c = 0; c < C; ++c) problem.SetParameterLowerBound(p.P.data(), c, 0.0);
  ceres::Solver::Summary summary;
  ceres::Solve(SmallDenseSolverOptions(options.max_iterations, 1e-10), &problem, &summary);
  Stage stage;
  stage.usable = summary.IsSolutionUsable();
  stage.converged = stage.usable && summary.termination_type == ceres::CONVERGENCE;
  stage.iterations = static_cast<int>(summary.iterations.size());
  stage.cost = 2 * summary.final_cost;
  const int parameters = 2 * n + n * C + 2 * C;
  if (stage.usable) Variances(problem, p, stage.cost / std::max(1, d.m * C - parameters), &stage);
  stage.p = std::move(p);
  return stage;
}

// Why a refined stage cannot count (empty if it can): every state present
// (some S > 0), rates inside the resolvable range and more than 2% apart.
std::string WhyInvalid(const Data& d, const Stage& stage, bool keep_unconverged) {
  if (!stage.usable) return "the solve failed";
  if (!stage.converged && !keep_unconverged) return "the solve did not converge within the iteration limit";
  const Params& p = stage.p;
  std::vector<double> kr;
  for (int i = 0; i < p.n(); ++i) {
    double signal = 0;
    for (int c = 0; c < d.C; ++c) signal += p.S[i * d.C + c];
    if (!(signal > 1e-9)) return "a state has no signal";
    kr.push_back(std::exp(p.log_kr[i]));
    if (kr.back() < d.k_lo / 2 || kr.back() > d.k_hi * 2) return "a rate is outside what the samples resolve";
  }
  std::sort(kr.begin(), kr.end());
  for (std::size_t i = 1; i < kr.size(); ++i)
    if (kr[i] < 1.02 * kr[i - 1]) return "two rates are within 2%";
  return "";
}

int ParameterCount(int n, int C) { return 2 * n + n * C + 2 * C; }

// The stages 1..max_n, each from the one before plus a state, refined; a
// stage whose parameters outnumber the samples is not tried.
std::vector<Stage> FitStages(const Data& d, int max_n, const ScheduleFitOptions& options) {
  std::vector<Stage> stages;
  Params held;
  for (int n = 1; n <= max_n; ++n) {
    if (ParameterCount(n, d.C) + 1 > d.m * d.C) break;
    stages.push_back(Refine(d, AddState(d, held, options), options));
    held = stages.back().p;
  }
  return stages;
}

// The scaled data and the rates its samples resolve: kr from a fiftieth of
// one per span to three per smallest step (as the decay fits scan), a from a
// thirtieth of one per longest light to three per smallest step.
Data MakeData(const Curve& scaled, const std::vector<LightWindow>& lights, Weighting weighting) {
  Data d;
  d.m = static_cast<int>(scaled.size());
  d.C = scaled.channel_count();
  d.y = scaled.channels;
  for (const std::vector<double>& y : d.y) {
    d.w.push_back(SampleWeights(y, weighting));
    d.w2.push_back(d.w.back());
    for (double& w2 : d.w2.back()) w2 *= w2;
  }
  d.timeline = MakeTimeline(scaled.t_s, lights, scaled.t_s.front());
  const double span = scaled.t_s.back() - scaled.t_s.front(), step = SmallestTimeStep(scaled);
  double longest = 0;
  for (const LightWindow& w : lights) longest = std::max(longest, w.off_s - w.on_s);
  d.k_lo = 0.02 / span;
  d.k_hi = std::max(3 / step, 10 * d.k_lo);
  d.a_lo = 0.03 / longest;
  d.a_hi = std::max(3 / step, 10 * d.a_lo);
  return d;
}

struct Choice {
  int index = -1;  // into the stages
  std::string text;
  std::vector<double> bic;
  std::vector<std::string> warnings;
};

// BIC = N ln(RSS / N) + P ln N of every valid stage (in the data's units:
// the log of the value unit, squared, added per residual, which leaves the
// choice as it is); the fewest states within 2 of the lowest (Kass and
// Raftery's "not worth more than a bare mention"), or the count asked for,
// or fewer when the curve cannot support it.
Choice ChooseStates(const Data& d, const std::vector<Stage>& stages, int fixed, double log_unit,
                    bool keep_unconverged) {
  Choice choice;
  const double N = static_cast<double>(d.m) * d.C;
  std::vector<std::string> why;
  for (std::size_t k = 0; k < stages.size(); ++k) {
    why.push_back(WhyInvalid(d, stages[k], keep_unconverged));
    const double rss = std::max(stages[k].cost, 1e-300 * N);
    const double bic =
        N * std::log(rss / N) + ParameterCount(static_cast<int>(k) + 1, d.C) * std::log(N) + N * log_unit;
    choice.bic.push_back(why.back().empty() ? bic : std::numeric_limits<double>::quiet_NaN());
  }
  int lowest = -1;
  for (std::size_t k = 0; k < stages.size(); ++k)
    if (why[k].empty() && (lowest < 0 || choice.bic[k] < choice.bic[lowest])) lowest = static_cast<int>(k);
  if (lowest < 0) return choice;
  if (fixed > 0) {
    for (int k = std::min<int>(fixed, static_cast<int>(stages.size())) - 1; k >= 0 && choice.index < 0; --k)
      if (why[k].empty()) choice.index = k;
    choice.text = "fixed";
    if (choice.index + 1 < fixed) {
      const std::string reason =
          fixed <= static_cast<int>(stages.size()) ? why[fixed - 1] : "more parameters than samples";
      choice.text = "fixed at " + std::to_string(fixed) + ", fewer fitted";
      choice.warnings.push_back("the curve supports only " + std::to_string(choice.index + 1) + " state(s), not " +
                                std::to_string(fixed) + " (with " + std::to_string(fixed) + ": " + reason +
                                "); fitted " + std::to_string(choice.index + 1));
    }
    return choice;
  }
  for (int k = 0; k <= lowest && choice.index < 0; ++k)
    if (why[k].empty() && choice.bic[k] <= choice.bic[lowest] + 2) choice.index = k;
  choice.text = "BIC over 1.." + std::to_string(stages.size()) + " states: the fewest within 2 of the lowest";
  return choice;
}

// The stage in the data's units, fastest state first.
ScheduleFitSummary Unscale(const Data& d, const Stage& stage, const CurveScale& units) {
  ScheduleFitSummary fit;
  const Params& p = stage.p;
  const int C = d.C;
  for (int i = 0; i < p.n(); ++i) {
    ScheduleState state;
    state.kr = std::exp(p.log_kr[i]) / units.time_s;
    state.kr_stderr = state.kr * std::sqrt(stage.var_log_kr[i]);
    state.charge_rate = std::exp(p.log_a[i]) / units.time_s;
    state.charge_rate_stderr = state.charge_rate * std::sqrt(stage.var_log_a[i]);
    // At a bound (within 10%) the covariance means nothing: the rate is
    // only known to be beyond what the samples resolve.
    if (p.log_a[i] < std::log(d.a_lo / 10) + 0.1 || p.log_a[i] > std::log(d.a_hi * 10) - 0.1)
      state.charge_rate_stderr = std::numeric_limits<double>::infinity();
    for (int c = 0; c < C; ++c) {
      state.emission.push_back(p.S[i * C + c] * units.value);
      state.emission_stderr.push_back(std::sqrt(stage.var_S[i * C + c]) * units.value);
    }
    fit.states.push_back(std::move(state));
  }
  std::sort(fit.states.begin(), fit.states.end(), [](const auto& x, const auto& y) { return x.kr > y.kr; });
  for (int c = 0; c < C; ++c) {
    fit.prompt.push_back(p.P[c] * units.value);
    fit.prompt_stderr.push_back(std::sqrt(stage.var_P[c]) * units.value);
    fit.background.push_back(p.B[c] * units.value);
    fit.background_stderr.push_back(std::sqrt(stage.var_B[c]) * units.value);
  }
  fit.n_states = p.n();
  fit.converged = stage.converged;
  return fit;
}

// The residual per decade of time after each light's switch-off, up to the
// next light or the end: rms of the residual over rms of the fitted signal,
// every channel together. A sample at the switch-off itself counts in the
// first decade.
std::vector<DecadeResidual> ResidualByDecade(const Curve& curve, const std::vector<LightWindow>& lights,
                                             const ScheduleFitSummary& fit) {
  const std::vector<std::vector<double>> model = EvaluateSchedule(fit, lights, curve.t_s.front(), curve.t_s);
  std::vector<DecadeResidual> decades;
  for (std::size_t w = 0; w < lights.size(); ++w) {
    const double off = lights[w].off_s, end = w + 1 < lights.size() ? lights[w + 1].on_s : HUGE_VAL;
    std::map<int, std::pair<double, double>> sums;  // decade -> (residual^2, model^2)
    std::map<int, std::size_t> counts;
    int first = std::numeric_limits<int>::max();
    for (std::size_t j = 0; j < curve.size(); ++j)
      if (curve.t_s[j] > off && curve.t_s[j] < end)
        first = std::min(first, static_cast<int>(std::floor(std::log10(curve.t_s[j] - off))));
    for (std::size_t j = 0; j < curve.size(); ++j) {
      if (curve.t_s[j] < off || curve.t_s[j] >= end) continue;
      const double after = curve.t_s[j] - off;
      const int decade = after > 0 ? static_cast<int>(std::floor(std::log10(after))) : first;
      for (int c = 0; c < curve.channel_count(); ++c) {
        const double residual = curve.channels[c][j] - model[c][j];
        sums[decade].first += residual * residual;
        sums[decade].second += model[c][j] * model[c][j];
      }
      ++counts[decade];
    }
    for (const auto& [decade, sum] : sums)
      decades.push_back({static_cast<int>(w), std::pow(10.0, decade), std::pow(10.0, decade + 1), counts[decade],
                         sum.second > 0 ? std::sqrt(sum.first / sum.second) : 0.0});
  }
  return decades;
}

// Whether the samples before the first light fall clearly: the sample was
// still glowing from an earlier charge, against the fit's dark start. The
// sum over channels, the mean of the first third of those samples against
// the last third's, more than 5 standard errors apart (the noise from the
// median step between neighbours) and more than 1% of the curve's peak.
std::string DecayBeforeTheFirstLight(const Curve& curve, double first_on_s) {
  std::vector<double> sum;
  double peak = 0;
  for (std::size_t j = 0; j < curve.size(); ++j) {
    double value = 0;
    for (const auto& channel : curve.channels) value += channel[j];
    peak = std::max(peak, std::fabs(value));
    if (curve.t_s[j] < first_on_s) sum.push_back(value);
  }
  const std::size_t third = sum.size() / 3;
  if (third < 3) return "";
  std::vector<double> steps;
  for (std::size_t j = 1; j < sum.size(); ++j) steps.push_back(std::fabs(sum[j] - sum[j - 1]));
  std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
  const double sigma = steps[steps.size() / 2] / (0.6745 * std::sqrt(2.0));  // a step's median |N(0, 2 s^2)|
  const double early = std::accumulate(sum.begin(), sum.begin() + third, 0.0) / third;
  const double late = std::accumulate(sum.end() - third, sum.end(), 0.0) / third;
  if (early - late > 5 * sigma * std::sqrt(2.0 / third) && early - late > 0.01 * peak)
    return "the curve falls before the first light (from " + FormatShort(early, 4) + " to " + FormatShort(late, 4) +
           "): the sample was not dark at the start, as the fit assumes (r = 0 at the first sample)";
  return "";
}

}  // namespace

bool ScheduleFitOptions::IsValid(std::string* error) const {
  if (lights.empty()) return *error = "needs at least one light window", false;
  if (states < 0 || states > 8) return *error = "states must be 1 to 8 (or 0 to choose)", false;
  if (states == 0 && (max_states < 1 || max_states > 8)) return *error = "max states must be 1 to 8", false;
  if (rate_grid_size < 2 || charge_grid_size < 2 || max_iterations < 1)
    return *error = "grid sizes must be >= 2 and max_iterations >= 1", false;
  return true;
}

void ValidateSchedule(const Curve& curve, const std::vector<LightWindow>& lights, const std::string& where,
                      const std::string& option) {
  if (lights.empty()) ThrowUserError(where, option, "no light window given (T0:T1, seconds)");
  const double first = curve.t_s.front(), last = curve.t_s.back();
  auto name = [](const LightWindow& w) { return FormatShort(w.on_s, 6) + ":" + FormatShort(w.off_s, 6); };
  for (std::size_t w = 0; w < lights.size(); ++w) {
    const LightWindow& light = lights[w];
    if (!(light.on_s < light.off_s))
      ThrowUserError(where, option, name(light) + ": the light must go off after it goes on");
    if (light.on_s < first || light.off_s >= last)
      ThrowUserError(where, option,
                     name(light) + " is outside the curve's time range (" + FormatShort(first, 6) + " to " +
                         FormatShort(last, 6) + " s, with dark samples after the light)");
    if (w > 0 && light.on_s < lights[w - 1].off_s)
      ThrowUserError(where, option,
                     name(light) + " overlaps the light before it, or comes before it (give them in time order)");
  }
  for (std::size_t w = 0; w < lights.size(); ++w) {
    const double off = lights[w].off_s, dark_end = w + 1 < lights.size() ? lights[w + 1].on_s : HUGE_VAL;
    const auto dark =
        std::count_if(curve.t_s.begin(), curve.t_s.end(), [&](double t) { return t >= off && t < dark_end; });
    if (dark < 3)
      ThrowUserError(where, option,
                     name(lights[w]) + ": the curve has " + std::to_string(dark) +
                         " sample(s) in the dark after this light (at least 3 are needed to see a decay)");
  }
}

std::vector<std::vector<double>> EvaluateSchedule(const ScheduleFitSummary& fit, const std::vector<LightWindow>& lights,
                                                  double start_s, const std::vector<double>& t_s) {
  const int C = static_cast<int>(fit.background.size());
  std::vector<double> kr, a;
  for (const ScheduleState& state : fit.states) {
    kr.push_back(state.kr);
    a.push_back(state.charge_rate);
  }
  const Timeline timeline = MakeTimeline(t_s, lights, start_s);
  std::vector<std::vector<double>> values(static_cast<std::size_t>(C), std::vector<double>(t_s.size()));
  Propagate<double>(timeline, kr, a, [&](int j, const std::vector<double>& r) {
    for (int c = 0; c < C; ++c) {
      double model = fit.background[c] + (timeline.on[j] ? fit.prompt[c] : 0.0);
      for (std::size_t i = 0; i < r.size(); ++i) model += fit.states[i].emission[c] * r[i];
      values[c][j] = model;
    }
  });
  return values;
}

ScheduleFitSummary FitSchedule(const Curve& curve, const ScheduleFitOptions& options, const std::string& where) {
  const auto start = std::chrono::steady_clock::now();
  std::string error;
  if (!options.IsValid(&error)) ThrowUserError(where, "options", error);
  ValidateCurve(curve, 4, where);
  ValidateSchedule(curve, options.lights, where, "lights");
  // Solved in the curve's own units (curve.h: CurveScale): nothing below
  // depends on the units of the data or of the time.
  const CurveScale units = ScaleOfCurve(curve, where);
  std::vector<LightWindow> scaled_lights;
  for (const LightWindow& w : options.lights) scaled_lights.push_back({w.on_s / units.time_s, w.off_s / units.time_s});
  const Data d = MakeData(ScaledCurve(curve, units), scaled_lights, options.weighting);
  const int max_n = options.states > 0 ? options.states : options.max_states;
  const std::vector<Stage> stages = FitStages(d, max_n, options);
  // A weighted squared residual of the scaled curve in the data's units, as
  // its log: value^2 unweighted, value with Poisson weights 1 / sqrt(value).
  const double log_unit = (options.weighting == Weighting::kNone ? 2 : 1) * std::log(units.value);
  Choice choice = ChooseStates(d, stages, options.states, log_unit, options.keep_unconverged);
  if (choice.index < 0)
    ThrowUserError(where, "",
                   stages.empty() ? "too few samples for one state"
                                  : "no number of states fits the curve (1 state: " +
                                        WhyInvalid(d, stages[0], options.keep_unconverged) +
                                        "); nothing reported (raise --max-iterations, or give --keep-unconverged to "
                                        "see an unconverged fit)");
  ScheduleFitSummary fit = Unscale(d, stages[choice.index], units);
  fit.bic = choice.bic;
  fit.choice = choice.text;
  fit.warnings = choice.warnings;
  if (std::string glowing = DecayBeforeTheFirstLight(curve, options.lights.front().on_s); !glowing.empty())
    fit.warnings.push_back(std::move(glowing));
  for (const Stage& stage : stages) fit.iterations += stage.iterations;
  fit.weighted_rss = stages[choice.index].cost * std::exp(log_unit);
  const std::vector<std::vector<double>> model = EvaluateSchedule(fit, options.lights, curve.t_s.front(), curve.t_s);
  for (int c = 0; c < curve.channel_count(); ++c)
    for (std::size_t j = 0; j < curve.size(); ++j)
      fit.rss += (curve.channels[c][j] - model[c][j]) * (curve.channels[c][j] - model[c][j]);
  fit.residual_by_decade = ResidualByDecade(curve, options.lights, fit);
  fit.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return fit;
}

}  // namespace phos
