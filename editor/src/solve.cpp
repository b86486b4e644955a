#include "phos/editor/solve.h"

#include <algorithm>
#include <chrono>
#include <functional>
#include <cmath>
#include <limits>
#include <numeric>
#include <set>
#include <type_traits>

#include <ceres/ceres.h>
#include <nlohmann/json.hpp>

#include "phos/fit/small_nnls.h"
#include "phos/model/closed_form.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"
#include "phos/util/math.h"

namespace phos::editor {
namespace {

// The moments the cost looks at, per point: every target's time and every
// frame start inside a bound's range (and its ends), sorted, with who uses each.
// The irradiance is piecewise constant, and the exact update (Eq. 8.1) over
// an interval of constant irradiance depends on its length only, so runs of
// frames with equal irradiance and no sample inside are one step: a lit
// stretch or a dark stretch costs one exponential, not one per frame.
struct Step {
  int frame = 0;    // a frame of the run (its irradiance holds throughout)
  double h_s = 0;   // the run's length
  int sample = -1;  // the sample that ends the step, or -1
};
struct PointSamples {
  std::vector<double> t;    // sorted, unique
  std::vector<int> frame;   // frame whose irradiance shows at t
  std::vector<Step> steps;  // from t = 0 to the last sample
};

std::vector<Step> MakeSteps(const Point& point, double dt_s, const std::vector<double>& t_samples) {
  std::vector<Step> steps;
  const int frames = static_cast<int>(point.irradiance.size());
  double t = 0;
  int frame = 0;
  for (std::size_t m = 0; m < t_samples.size(); ++m) {
    bool stepped = false;
    while (t < t_samples[m] - 1e-12) {
      const double frame_end = dt_s * (frame + 1);
      const double until = std::min(frame_end, t_samples[m]);
      const int f = std::min(frame, frames - 1);
      const bool ends_sample = until >= t_samples[m] - 1e-12;
      const bool joins =
          !steps.empty() && steps.back().sample < 0 && point.irradiance[steps.back().frame] == point.irradiance[f];
      if (joins) {
        steps.back().h_s += until - t;
      } else {
        steps.push_back({f, until - t, -1});
      }
      if (ends_sample) steps.back().sample = static_cast<int>(m);
      stepped = true;
      t = until;
      if (t >= frame_end - 1e-12) ++frame;
    }
    if (!stepped) steps.push_back({std::min(frame, frames - 1), 0.0, static_cast<int>(m)});  // a sample at t = 0
  }
  return steps;
}
struct Samples {
  std::vector<PointSamples> points;
  std::vector<int> target_sample;               // per constraint (targets): index into its point's t
  std::vector<std::vector<int>> bound_samples;  // per constraint (bounds): indices into its point's t
};

Samples MakeSamples(const Problem& p) {
  Samples s;
  s.points.resize(p.points.size());
  std::vector<std::vector<double>> times(p.points.size());
  for (const Constraint& c : p.constraints) {
    PHOS_CHECK(c.point >= 0 && c.point < static_cast<int>(p.points.size()));
    times[c.point].push_back(c.t_s);
    if (c.kind != Constraint::Kind::kTarget) {
      times[c.point].push_back(c.until_s);
      for (double t = std::ceil(c.t_s / p.dt_s) * p.dt_s; t < c.until_s; t += p.dt_s) times[c.point].push_back(t);
    }
  }
  const int frames = static_cast<int>(p.frames());
  for (std::size_t q = 0; q < p.points.size(); ++q) {
    std::sort(times[q].begin(), times[q].end());
    PointSamples& ps = s.points[q];
    for (double t : times[q])
      if (ps.t.empty() || t > ps.t.back() + 1e-9 * p.dt_s) ps.t.push_back(t);
    for (double t : ps.t)
      ps.frame.push_back(std::clamp(static_cast<int>(std::floor(t / p.dt_s + 1e-9)), 0, frames - 1));
    ps.steps = MakeSteps(p.points[q], p.dt_s, ps.t);
  }
  auto index_of = [&](int q, double t) {
    const std::vector<double>& ts = s.points[q].t;
    return static_cast<int>(std::lower_bound(ts.begin(), ts.end(), t - 1e-9 * p.dt_s) - ts.begin());
  };
  for (const Constraint& c : p.constraints) {
    s.target_sample.push_back(c.kind == Constraint::Kind::kTarget ? index_of(c.point, c.t_s) : -1);
    std::vector<int> range;
    const std::vector<double>& ts = s.points[c.point].t;
    if (c.kind != Constraint::Kind::kTarget)
      for (int k = index_of(c.point, c.t_s); k < static_cast<int>(ts.size()) && ts[k] <= c.until_s + 1e-9 * p.dt_s; ++k)
        range.push_back(k);
    s.bound_samples.push_back(range);
  }
  return s;
}

// r(t) at the samples for decay rate kr and excitation rate a[step] (Eq. 8.1
// with the exact update, irradiance constant over each step: model/'s
// ChargedState, unclamped so the derivatives pass). T: double or a Ceres Jet.
template <typename T>
void StateAtSamples(const PointSamples& s, const std::vector<T>& a, const T& kr, std::vector<T>& r_out) {
  r_out.resize(s.t.size());
  T r(0.0);
  for (std::size_t j = 0; j < s.steps.size(); ++j) {
    r = ChargedState(a[j], kr, s.steps[j].h_s, r);
    if (s.steps[j].sample >= 0) r_out[s.steps[j].sample] = r;
  }
}

// Emitted radiance per point, sample and band.
template <typename T>
using Emitted = std::vector<std::vector<std::vector<T>>>;

// Where a residual reads the radiance, and its slope dr/dL there: w for a
// target, -w (at least) or w (at most) for a violated bound, 0 for a met one.
struct ResidualSite {
  int point = 0, sample = 0, band = 0;
  double slope = 0;
};

// The residuals of Eq. 8.7 given the emitted radiance (reflection added here),
// and, if `sites` is given, where each one reads it.
template <typename T>
void Residuals(const Problem& p, const Samples& s, const Emitted<T>& Lp, T* out, ResidualSite* sites = nullptr) {
  const int nb = p.bands.band_count();
  int k = 0;
  for (std::size_t c = 0; c < p.constraints.size(); ++c) {
    const Constraint& con = p.constraints[c];
    const Point& point = p.points[con.point];
    const PointSamples& ps = s.points[con.point];
    const double w = std::sqrt(con.weight);
    auto L = [&](int sample, int b) {
      return Lp[con.point][sample][b] + point.albedo[b] * point.irradiance[ps.frame[sample]][b] / kPi;
    };
    if (con.kind == Constraint::Kind::kTarget) {
      for (int b = 0; b < nb; ++b) {
        if (sites) sites[k] = {con.point, s.target_sample[c], b, w};
        out[k++] = w * (L(s.target_sample[c], b) - con.radiance[b]);
      }
    } else {
      const bool at_least = con.kind == Constraint::Kind::kAtLeast;
      for (int sample : s.bound_samples[c])
        for (int b = 0; b < nb; ++b) {
          const T miss = at_least ? T(con.radiance[b]) - L(sample, b) : L(sample, b) - T(con.radiance[b]);
          const bool violated = miss > T(0.0);
          if (sites) sites[k] = {con.point, sample, b, violated ? (at_least ? -w : w) : 0.0};
          out[k++] = violated ? T(w) * miss : T(0.0);
        }
    }
  }
}

int ResidualCount(const Problem& p, const Samples& s) {
  int count = 0;
  for (std::size_t c = 0; c < p.constraints.size(); ++c)
    count += p.bands.band_count() *
             (p.constraints[c].kind == Constraint::Kind::kTarget ? 1 : static_cast<int>(s.bound_samples[c].size()));
  return count;
}

// The bands that carry irradiance at some frame (only there is ke meaningful).
std::vector<int> LitBands(const Problem& p) {
  std::vector<int> lit;
  for (int b = 0; b < p.bands.band_count(); ++b) {
    bool any = false;
    for (const Point& point : p.points)
      for (const auto& E : point.irradiance) any = any || E[b] > 0;
    if (any) lit.push_back(b);
  }
  return lit;
}

// Parameters of a candidate: per state kr, ke over the lit bands, Lambda over all bands.
struct Parameters {
  std::vector<double> kr;                   // [nc]
  std::vector<std::vector<double>> ke;      // [nc][lit]
  std::vector<std::vector<double>> Lambda;  // [nc][nb]
};

// ke over `bands` (the lit ones, or all of them for the grid baseline) into a
// material. Where no light reaches any point, every ke looks the same, so the
// constraints say nothing of it: it stays unknown (null in the file), as a
// measurement that never lit a band leaves it, and is never invented.
Material ToMaterial(const Problem& p, const std::vector<int>& bands, const Parameters& x) {
  const std::vector<int> lit = LitBands(p);
  Material m;
  m.name = "edited";
  m.source = "phos edit solve (Sec. 8.6, Eq. 8.7) on " + p.source;
  m.bands = p.bands;
  m.albedo = p.points[0].albedo;
  for (std::size_t i = 0; i < x.kr.size(); ++i) {
    ExcitedState s;
    s.kr = x.kr[i];
    s.ke.assign(p.bands.band_count(), std::nullopt);
    for (std::size_t l = 0; l < bands.size(); ++l)
      if (std::find(lit.begin(), lit.end(), bands[l]) != lit.end()) s.ke[bands[l]] = x.ke[i][l];
    s.Lambda = x.Lambda[i];
    m.states.push_back(s);
  }
  return m;
}

// Excitation rate per step of a state at a point: a = sum_b ke_b E_b.
template <typename T>
void ExcitationPerStep(const Point& point, const PointSamples& s, const std::vector<int>& lit, const T* ke,
                       std::vector<T>& a) {
  a.assign(s.steps.size(), T(0.0));
  for (std::size_t j = 0; j < a.size(); ++j)
    for (std::size_t l = 0; l < lit.size(); ++l) a[j] += ke[l] * point.irradiance[s.steps[j].frame][lit[l]];
}
template <typename T>
std::vector<T> ExcitationPerStep(const Point& point, const PointSamples& s, const std::vector<int>& lit, const T* ke) {
  std::vector<T> a;
  ExcitationPerStep(point, s, lit, ke, a);
  return a;
}

// One state's curve g = kr r(t) at every point's samples ([point][sample]):
// what Lambda multiplies in Eq. 8.2.
template <typename T>
using StateCurve = std::vector<std::vector<T>>;

template <typename T>
StateCurve<T> CurveOf(const Problem& p, const Samples& s, const std::vector<int>& lit, const T& kr, const T* ke) {
  StateCurve<T> g(p.points.size());
  for (std::size_t q = 0; q < p.points.size(); ++q) {
    StateAtSamples(s.points[q], ExcitationPerStep(p.points[q], s.points[q], lit, ke), kr, g[q]);
    for (T& v : g[q]) v *= kr;
  }
  return g;
}

// Lp = sum_i Lambda_i g_i into `Lp` (resized and reused: the beam search calls this thousands of times).
template <typename T>
void EmitInto(const Problem& p, const Samples& s, const std::vector<const StateCurve<T>*>& g,
              const std::vector<std::vector<T>>& Lambda, Emitted<T>& Lp) {
  const int nb = p.bands.band_count();
  Lp.resize(p.points.size());
  for (std::size_t q = 0; q < p.points.size(); ++q) {
    Lp[q].resize(s.points[q].t.size());
    for (std::size_t m = 0; m < s.points[q].t.size(); ++m) {
      Lp[q][m].assign(nb, T(0.0));
      for (std::size_t i = 0; i < g.size(); ++i)
        for (int b = 0; b < nb; ++b) Lp[q][m][b] += Lambda[i][b] * (*g[i])[q][m];
    }
  }
}

// The value of a double or of a Ceres Jet.
inline double ValueOf(double x) { return x; }
template <typename T, int N>
double ValueOf(const ceres::Jet<T, N>& x) {
  return x.a;
}

// Solves G x = b in place for a small symmetric positive definite G (n <= 5,
// by Cholesky), in T, so that a Jet's derivatives follow G's and b's.
template <typename T>
void SolveSpdInPlace(T (&G)[5][5], T (&b)[5], int n) {
  using std::sqrt;
  for (int j = 0; j < n; ++j) {
    for (int k = 0; k < j; ++k) G[j][j] -= G[j][k] * G[j][k];
    G[j][j] = sqrt(G[j][j]);
    for (int i = j + 1; i < n; ++i) {
      for (int k = 0; k < j; ++k) G[i][j] -= G[i][k] * G[j][k];
      G[i][j] /= G[j][j];
    }
  }
  for (int i = 0; i < n; ++i) {
    for (int k = 0; k < i; ++k) b[i] -= G[i][k] * b[k];
    b[i] /= G[i][i];
  }
  for (int i = n - 1; i >= 0; --i) {
    for (int k = i + 1; k < n; ++k) b[i] -= G[k][i] * b[k];
    b[i] /= G[i][i];
  }
}

// The non-negative x minimizing 0.5 x'Gx - rhs'x, G symmetric positive
// definite (lower triangle read), n <= 5. Most often the unconstrained
// optimum is already non-negative, and then it is the answer (the problem is
// convex): one Cholesky solve. Otherwise fit/'s exact subset solver picks the
// support on values, and for a Jet x is solved again on that support in T,
// which is the exact derivative of the projected problem (variable
// projection, Golub and Pereyra 1973).
template <typename T>
void NonNegativeSolve(const T (&G)[5][5], const T (&rhs)[5], int n, T (&x)[5]) {
  T L[5][5];
  for (int i = 0; i < n; ++i) {
    x[i] = rhs[i];
    for (int j = 0; j <= i; ++j) L[i][j] = G[i][j];
  }
  SolveSpdInPlace(L, x, n);
  bool feasible = true;
  for (int i = 0; i < n; ++i) feasible = feasible && ValueOf(x[i]) >= 0;  // also false on NaN
  if (feasible) return;
  if (n == 2) {
    // The optimum is then on an edge, x_j = 0 and x_i = max(0, rhs_i / G_ii):
    // the better edge, in closed form (the beam search's common case).
    const int i = ValueOf(rhs[0] * rhs[0] / G[0][0]) >= ValueOf(rhs[1] * rhs[1] / G[1][1]) ? 0 : 1;
    x[0] = x[1] = T(0.0);
    if (ValueOf(rhs[i]) > 0)
      x[i] = rhs[i] / G[i][i];
    else if (ValueOf(rhs[1 - i]) > 0)
      x[1 - i] = rhs[1 - i] / G[1 - i][1 - i];
    return;
  }
  SmallMatrix G_value(n, n);
  SmallVector rhs_value(n);
  for (int i = 0; i < n; ++i) {
    rhs_value[i] = ValueOf(rhs[i]);
    for (int j = 0; j <= i; ++j) G_value(i, j) = G_value(j, i) = ValueOf(G[i][j]);
  }
  const SmallNnlsResult nnls = SolveSmallNnls(G_value, rhs_value, n);
  int support[5], m = 0;
  for (int i = 0; i < n; ++i) {
    x[i] = T(0.0);
    if (nnls.ok && nnls.x[i] > 0) support[m++] = i;
  }
  T x_support[5];
  for (int i = 0; i < m; ++i) {
    x_support[i] = rhs[support[i]];
    for (int j = 0; j <= i; ++j) L[i][j] = G[support[i]][support[j]];
  }
  SolveSpdInPlace(L, x_support, m);
  for (int i = 0; i < m; ++i) x[support[i]] = x_support[i];
}

// The targets' side of Eq. 8.7 for Lambda: per target its weight and its
// radiance less the reflected light (what the emission must supply), per band.
struct TargetSystem {
  std::vector<int> constraint;         // per target: index into Problem::constraints
  std::vector<double> weight;          // per target
  std::vector<std::vector<double>> y;  // per target, per band
  std::vector<double> wyy;             // per band: sum_targets w y^2
};

TargetSystem MakeTargetSystem(const Problem& p, const Samples& s) {
  TargetSystem t;
  const int nb = p.bands.band_count();
  t.wyy.assign(nb, 0.0);
  for (std::size_t c = 0; c < p.constraints.size(); ++c) {
    const Constraint& con = p.constraints[c];
    if (con.kind != Constraint::Kind::kTarget) continue;
    const int m = s.target_sample[c];
    const Point& point = p.points[con.point];
    std::vector<double> y(nb);
    for (int b = 0; b < nb; ++b) {
      y[b] = con.radiance[b] - point.albedo[b] * point.irradiance[s.points[con.point].frame[m]][b] / kPi;
      t.wyy[b] += con.weight * y[b] * y[b];
    }
    t.constraint.push_back(static_cast<int>(c));
    t.weight.push_back(con.weight);
    t.y.push_back(std::move(y));
  }
  return t;
}

// A state curve at the targets (g_k = kr r at target k), for the normal equations.
template <typename T>
std::vector<T> AtTargets(const Problem& p, const Samples& s, const TargetSystem& t, const StateCurve<T>& g) {
  std::vector<T> out;
  for (int c : t.constraint) out.push_back(g[p.constraints[c].point][s.target_sample[c]]);
  return out;
}

// The normal equations of Lambda_b for curves given at the targets: G_ij =
// sum_k w_k g_i,k g_j,k (shared by all bands; a tiny ridge keeps a state no
// target sees solvable) and rhs_b,i = sum_k w_k g_i,k y_k,b.
template <typename T>
void NormalMatrix(const TargetSystem& t, const std::vector<const std::vector<T>*>& g, T (&G)[5][5]) {
  const int nc = static_cast<int>(g.size());
  PHOS_CHECK(nc <= 5);
  double diagonal_max = 0;
  for (int i = 0; i < nc; ++i)
    for (int j = 0; j <= i; ++j) {
      G[i][j] = T(0.0);
      for (std::size_t k = 0; k < t.weight.size(); ++k) G[i][j] += t.weight[k] * (*g[i])[k] * (*g[j])[k];
      if (i == j) diagonal_max = std::max(diagonal_max, ValueOf(G[i][i]));
    }
  for (int i = 0; i < nc; ++i) G[i][i] += 1e-14 * (diagonal_max + 1e-300);
}

template <typename T>
void NormalRhs(const TargetSystem& t, const std::vector<const std::vector<T>*>& g, int b, T (&rhs)[5]) {
  for (std::size_t i = 0; i < g.size(); ++i) {
    rhs[i] = T(0.0);
    for (std::size_t k = 0; k < t.weight.size(); ++k) rhs[i] += t.weight[k] * (*g[i])[k] * t.y[k][b];
  }
}

// Lambda for given state curves g_i: per band, non-negative least squares on
// the targets (bounds are left to the refinement).
template <typename T>
std::vector<std::vector<T>> BestLambda(const Problem& p, const Samples& s, const TargetSystem& t,
                                       const std::vector<const StateCurve<T>*>& g) {
  const int nc = static_cast<int>(g.size()), nb = p.bands.band_count();
  std::vector<std::vector<T>> at_targets;
  for (const StateCurve<T>* curve : g) at_targets.push_back(AtTargets(p, s, t, *curve));
  std::vector<const std::vector<T>*> g_targets;
  for (const std::vector<T>& v : at_targets) g_targets.push_back(&v);
  T G[5][5], rhs[5], x[5];
  NormalMatrix(t, g_targets, G);
  std::vector<std::vector<T>> Lambda(nc, std::vector<T>(nb, T(0.0)));
  for (int b = 0; b < nb; ++b) {
    NormalRhs(t, g_targets, b, rhs);
    NonNegativeSolve(G, rhs, nc, x);
    for (int i = 0; i < nc; ++i) Lambda[i][b] = x[i];
  }
  return Lambda;
}

// The state curves of log kr and log ke (lit bands), all states: the Ceres parameters.
template <typename T>
std::vector<StateCurve<T>> CurvesOfLogs(const Problem& p, const Samples& s, const std::vector<int>& lit, int nc,
                                        const T* log_kr, const T* log_ke) {
  using std::exp;
  const int n_lit = static_cast<int>(lit.size());
  std::vector<StateCurve<T>> g;
  std::vector<T> ke(n_lit);
  for (int i = 0; i < nc; ++i) {
    for (int l = 0; l < n_lit; ++l) ke[l] = exp(log_ke[i * n_lit + l]);
    g.push_back(CurveOf(p, s, lit, T(exp(log_kr[i])), ke.data()));
  }
  return g;
}

template <typename T>
std::vector<const StateCurve<T>*> Pointers(const std::vector<StateCurve<T>>& g) {
  std::vector<const StateCurve<T>*> out;
  for (const StateCurve<T>& c : g) out.push_back(&c);
  return out;
}

// One state's curve g = kr r(t) at every point's samples, and with `slopes`
// its derivatives with respect to the state's own log kr and log ke (lit
// bands): dg[point][sample * (1 + n_lit) + d], d = 0 for log kr. A state's
// curve depends on its own rates only, so automatic derivatives run over
// 1 + n_lit parameters (in Jets of 8), not over every state's and Lambda.
struct CurveWithSlopes {
  StateCurve<double> g;
  std::vector<std::vector<double>> dg;
};

CurveWithSlopes CurveAndSlopes(const Problem& p, const Samples& s, const std::vector<int>& lit, double log_kr,
                               const double* log_ke, bool slopes) {
  using Jet = ceres::Jet<double, 8>;
  const int n_lit = static_cast<int>(lit.size()), dims = 1 + n_lit;
  CurveWithSlopes c;
  if (!slopes) {
    std::vector<double> ke(n_lit);
    for (int l = 0; l < n_lit; ++l) ke[l] = std::exp(log_ke[l]);
    c.g = CurveOf(p, s, lit, std::exp(log_kr), ke.data());
    return c;
  }
  c.dg.resize(p.points.size());
  for (int first = 0; first < dims; first += 8) {
    // Seeds the parameters [first, first + 8) of this state.
    const auto seeded = [&](double value, int d) {
      return d >= first && d < first + 8 ? Jet(value, d - first) : Jet(value);
    };
    std::vector<Jet> ke(n_lit);
    for (int l = 0; l < n_lit; ++l) ke[l] = exp(seeded(log_ke[l], 1 + l));
    const StateCurve<Jet> g = CurveOf(p, s, lit, Jet(exp(seeded(log_kr, 0))), ke.data());
    if (first == 0) c.g.assign(p.points.size(), {});
    for (std::size_t q = 0; q < g.size(); ++q) {
      c.g[q].resize(g[q].size());
      c.dg[q].resize(g[q].size() * dims);
      for (std::size_t m = 0; m < g[q].size(); ++m) {
        c.g[q][m] = g[q][m].a;
        for (int d = first; d < std::min(dims, first + 8); ++d) c.dg[q][m * dims + d] = g[q][m].v[d - first];
      }
    }
  }
  return c;
}

// The full cost of Eq. 8.7 for Ceres, over log kr (nc), log ke (nc x lit
// bands) and Lambda (nc x bands). L is linear in Lambda, so its derivatives
// are closed-form: dL_b / dLambda_i[b] = g_i and dL_b / dtheta_i =
// Lambda_i[b] dg_i / dtheta_i. Only the curves need automatic derivatives
// (CurveAndSlopes), which makes a bound's every-frame residuals cheap.
class EditCost final : public ceres::CostFunction {
 public:
  EditCost(const Problem& p, const Samples& s, const std::vector<int>& lit, int nc)
      : p_(p), s_(s), lit_(lit), nc_(nc), nb_(p.bands.band_count()), n_lit_(static_cast<int>(lit.size())) {
    *mutable_parameter_block_sizes() = {nc_, nc_ * n_lit_, nc_ * nb_};
    set_num_residuals(ResidualCount(p, s));
  }

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    const bool slopes = jacobians != nullptr;
    std::vector<CurveWithSlopes> curves;
    for (int i = 0; i < nc_; ++i)
      curves.push_back(CurveAndSlopes(p_, s_, lit_, parameters[0][i], parameters[1] + i * n_lit_, slopes));
    std::vector<std::vector<double>> Lambda(nc_);
    for (int i = 0; i < nc_; ++i) Lambda[i].assign(parameters[2] + i * nb_, parameters[2] + (i + 1) * nb_);
    std::vector<const StateCurve<double>*> g;
    for (const CurveWithSlopes& c : curves) g.push_back(&c.g);
    Emitted<double> Lp;
    EmitInto(p_, s_, g, Lambda, Lp);
    std::vector<ResidualSite> sites(num_residuals());
    Residuals(p_, s_, Lp, residuals, sites.data());
    if (!slopes) return true;
    const int sizes[3] = {nc_, nc_ * n_lit_, nc_ * nb_};
    for (int j = 0; j < 3; ++j)
      if (jacobians[j]) std::fill(jacobians[j], jacobians[j] + num_residuals() * sizes[j], 0.0);
    const int dims = 1 + n_lit_;
    for (int k = 0; k < num_residuals(); ++k) {
      const ResidualSite& site = sites[k];
      if (site.slope == 0) continue;
      for (int i = 0; i < nc_; ++i) {
        const double scale = site.slope * Lambda[i][site.band];
        const double* dg = &curves[i].dg[site.point][site.sample * dims];
        if (jacobians[0]) jacobians[0][k * sizes[0] + i] = scale * dg[0];
        if (jacobians[1])
          for (int l = 0; l < n_lit_; ++l) jacobians[1][k * sizes[1] + i * n_lit_ + l] = scale * dg[1 + l];
        if (jacobians[2])
          jacobians[2][k * sizes[2] + i * nb_ + site.band] = site.slope * curves[i].g[site.point][site.sample];
      }
    }
    return true;
  }

 private:
  const Problem& p_;
  const Samples& s_;
  const std::vector<int>& lit_;
  const int nc_, nb_, n_lit_;
};

// Ceres functor over log kr and log ke only, Lambda projected out (BestLambda).
struct ProjectedEditCost {
  const Problem* p;
  const Samples* s;
  const TargetSystem* t;
  const std::vector<int>* lit;
  int nc;
  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    const std::vector<StateCurve<T>> g = CurvesOfLogs(*p, *s, *lit, nc, parameters[0], parameters[1]);
    const std::vector<const StateCurve<T>*> curves = Pointers(g);
    Emitted<T> Lp;
    EmitInto(*p, *s, curves, BestLambda(*p, *s, *t, curves), Lp);
    Residuals(*p, *s, Lp, residuals);
    return true;
  }
};

// The cost of Eq. 8.7 from the emitted radiance; `residuals` is scratch.
double CostOf(const Problem& p, const Samples& s, const Emitted<double>& Lp, std::vector<double>& residuals) {
  residuals.resize(ResidualCount(p, s));
  Residuals(p, s, Lp, residuals.data());
  double cost = 0;
  for (double r : residuals) cost += r * r;
  return cost;
}

double CostOf(const Problem& p, const Samples& s, const Emitted<double>& Lp) {
  std::vector<double> residuals;
  return CostOf(p, s, Lp, residuals);
}

Emitted<double> EmittedAtSamples(const Problem& p, const Samples& s, const std::vector<int>& lit, const Parameters& x) {
  std::vector<StateCurve<double>> g;
  for (std::size_t i = 0; i < x.kr.size(); ++i) g.push_back(CurveOf(p, s, lit, x.kr[i], x.ke[i].data()));
  Emitted<double> Lp;
  EmitInto(p, s, Pointers(g), x.Lambda, Lp);
  return Lp;
}

std::vector<double> LogSpace(double lo, double hi, int n) {
  std::vector<double> v(n);
  for (int k = 0; k < n; ++k) v[k] = lo * std::pow(hi / lo, n == 1 ? 0.0 : double(k) / (n - 1));
  return v;
}

// What the solution cannot do, in words: constraints it misses, and pairs of
// targets no phosphor can meet (the glow can only fade in the dark).
std::vector<std::string> Feedback(const Problem& p, const Samples& s, const std::vector<ConstraintResult>& results) {
  std::vector<std::string> notes;
  const int nb = p.bands.band_count();
  for (std::size_t c = 0; c < p.constraints.size(); ++c) {
    const Constraint& con = p.constraints[c];
    double scale = 0;
    for (double v : con.radiance) scale = std::max(scale, std::abs(v));
    if (results[c].residual > 0.1 * scale + 1e-12)
      notes.push_back(con.label + " (t = " + FormatDouble(con.t_s) + " s) is missed by " +
                      FormatShort(results[c].residual, 3) + " (" +
                      FormatShort(100 * results[c].residual / std::max(scale, 1e-300), 3) + "% of its largest band)");
    if (con.kind == Constraint::Kind::kTarget) {
      const Point& point = p.points[con.point];
      const int frame = s.points[con.point].frame[s.target_sample[c]];
      for (int b = 0; b < nb; ++b) {
        const double reflected = point.albedo[b] * point.irradiance[frame][b] / kPi;
        if (con.radiance[b] < reflected * (1 - 1e-9))
          notes.push_back(con.label + ": band " + p.bands.BandName(b) + " asks for " + FormatShort(con.radiance[b], 3) +
                          " but the reflected light alone is " + FormatShort(reflected, 3));
      }
    }
  }
  // Targets t1 < t2 with darkness between them: the glow (target minus
  // reflection) cannot grow.
  for (std::size_t i = 0; i < p.constraints.size(); ++i)
    for (std::size_t j = 0; j < p.constraints.size(); ++j) {
      const Constraint &a = p.constraints[i], &b = p.constraints[j];
      if (a.kind != Constraint::Kind::kTarget || b.kind != Constraint::Kind::kTarget || !(a.t_s < b.t_s) ||
          a.point != b.point)
        continue;
      const PointSamples& ps = s.points[a.point];
      const int f0 = ps.frame[s.target_sample[i]], f1 = ps.frame[s.target_sample[j]];
      bool dark = true;
      for (int f = f0; f <= f1 && dark; ++f)
        for (double e : p.points[a.point].irradiance[f]) dark = dark && e == 0;
      if (!dark) continue;
      for (int band = 0; band < nb; ++band)
        if (b.radiance[band] > a.radiance[band] * (1 + 1e-6) + 1e-12) {
          notes.push_back(a.label + " and " + b.label + " contradict: it is dark from " + FormatDouble(a.t_s) +
                          " s to " + FormatDouble(b.t_s) + " s, where a glow can only fade, but band " +
                          p.bands.BandName(band) + " rises from " + FormatShort(a.radiance[band], 3) + " to " +
                          FormatShort(b.radiance[band], 3));
          break;
        }
    }
  return notes;
}

Solution Finish(const Problem& p, const Samples& s, const std::vector<int>& lit, const Parameters& x,
                std::chrono::steady_clock::time_point start, int evaluations) {
  Solution solution;
  solution.material = ToMaterial(p, lit, x);
  const Emitted<double> Lp = EmittedAtSamples(p, s, lit, x);
  solution.cost = CostOf(p, s, Lp);
  const int nb = p.bands.band_count();
  for (std::size_t c = 0; c < p.constraints.size(); ++c) {
    const Constraint& con = p.constraints[c];
    const Point& point = p.points[con.point];
    ConstraintResult result;
    result.label = con.label;
    auto L = [&](int m, int b) {
      return Lp[con.point][m][b] + point.albedo[b] * point.irradiance[s.points[con.point].frame[m]][b] / kPi;
    };
    if (con.kind == Constraint::Kind::kTarget) {
      const int m = s.target_sample[c];
      double sum = 0;
      for (int b = 0; b < nb; ++b) {
        result.predicted.push_back(L(m, b));
        sum += std::pow(L(m, b) - con.radiance[b], 2);
      }
      result.residual = std::sqrt(sum);
    } else {
      for (int b = 0; b < nb; ++b) result.predicted.push_back(L(s.bound_samples[c].front(), b));
      for (int m : s.bound_samples[c])
        for (int b = 0; b < nb; ++b)
          result.residual =
              std::max(result.residual,
                       con.kind == Constraint::Kind::kAtLeast ? con.radiance[b] - L(m, b) : L(m, b) - con.radiance[b]);
    }
    solution.constraints.push_back(result);
  }
  solution.feedback = Feedback(p, s, solution.constraints);
  solution.evaluations = evaluations;
  solution.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return solution;
}

// The excitation direction: ke = kappa * e, e the mean irradiance over the
// lit frames scaled so that e . E_mean = 1 (kappa: the rate under the mean light).
std::vector<double> ExcitationDirection(const Problem& p, const std::vector<int>& lit) {
  const int n_lit = static_cast<int>(lit.size());
  std::vector<double> mean(n_lit, 0.0), direction(n_lit, 0.0);
  int lit_frames = 0;
  for (const Point& point : p.points)
    for (const auto& E : point.irradiance) {
      double sum = 0;
      for (int l = 0; l < n_lit; ++l) sum += E[lit[l]];
      if (sum <= 0) continue;
      ++lit_frames;
      for (int l = 0; l < n_lit; ++l) mean[l] += E[lit[l]];
    }
  double norm2 = 0;
  for (int l = 0; l < n_lit; ++l) {
    mean[l] /= std::max(lit_frames, 1);
    norm2 += mean[l] * mean[l];
  }
  for (int l = 0; l < n_lit; ++l) direction[l] = norm2 > 0 ? mean[l] / norm2 : 0.0;
  return direction;
}

// A curve of the library: one state with kr and ke = kappa e.
struct LibraryCurve {
  double kr, kappa;
  StateCurve<double> g;
  std::vector<double> at_targets;  // g at the targets (TargetSystem's order)
};

// Whether two curves have one shape (one is a multiple of the other, to
// about 1e-3 relative: 1 - cos^2 below 1e-6): Lambda scales them alike, so
// they look the same.
bool SameShape(const StateCurve<double>& a, const StateCurve<double>& b) {
  double ab = 0, aa = 0, bb = 0;
  for (std::size_t q = 0; q < a.size(); ++q)
    for (std::size_t m = 0; m < a[q].size(); ++m) {
      ab += a[q][m] * b[q][m];
      aa += a[q][m] * a[q][m];
      bb += b[q][m] * b[q][m];
    }
  return ab * ab >= (1 - 1e-6) * aa * bb;
}

// The curve whose kappa is nearest `kappa` (in log).
int NearestKappa(const std::vector<LibraryCurve>& row, double kappa) {
  int best = 0;
  for (int k = 1; k < static_cast<int>(row.size()); ++k)
    if (std::abs(std::log(row[k].kappa / kappa)) < std::abs(std::log(row[best].kappa / kappa))) best = k;
  return best;
}

// The curves of one kr worth keeping, kappa ascending. Under weak light
// (a << kr, a t << 1) r grows in proportion to ke, so every small kappa gives
// one shape; past saturation r is full before the first target and every
// large kappa gives another. Such a run is one curve, and the one kept is at
// its end nearest the informative middle: a start deep inside a plateau
// cannot be refined (its look does not change with ke, so neither does the
// cost) while a start at its edge can. When every kappa gives one shape (a
// fast state, full before the first target whatever the light), the one kept
// has a = kr, where r_inf = a / (a + kr) still moves with both.
std::vector<int> DistinctShapes(const std::vector<LibraryCurve>& row) {
  const int n = static_cast<int>(row.size());
  std::vector<int> keep;
  for (int start = 0; start < n;) {
    int end = start;
    while (end + 1 < n && SameShape(row[end].g, row[end + 1].g)) ++end;
    if (start == end)
      keep.push_back(start);
    else if (start == 0 && end == n - 1)
      keep.push_back(NearestKappa(row, row[0].kr));  // one shape for every kappa
    else if (start == 0)
      keep.push_back(end);  // the weak-light plateau: its strongest
    else if (end == n - 1)
      keep.push_back(start);  // the saturated plateau: its weakest
    else
      for (int k = start; k <= end; ++k) keep.push_back(k);
    start = end + 1;
  }
  return keep;
}

// The constraints' energy, sum w |T|^2: the cost of emitting nothing at the
// targets, the scale of every tolerance on the cost.
double TargetEnergy(const Problem& p) {
  double energy = 0;
  for (const Constraint& c : p.constraints)
    for (double v : c.radiance) energy += c.weight * v * v;
  return energy;
}

// The cost within which two solutions make the same look: a millionth of
// the cost (rounding), plus 1e-12 of the targets' energy (a relative error of
// 1e-6 at every target).
double SameLookTolerance(const Problem& p, double cost) { return cost * 1e-6 + 1e-12 * TargetEnergy(p); }

double SumOfLambda(const std::vector<std::vector<double>>& Lambda) {
  double sum = 0;
  for (const auto& per_band : Lambda)
    for (double v : per_band) sum += v;
  return sum;
}

bool HasBounds(const Problem& p) {
  for (const Constraint& c : p.constraints)
    if (c.kind != Constraint::Kind::kTarget) return true;
  return false;
}

// The full cost (Eq. 8.7) of a combination of library curves with its
// closed-form Lambda. Without bounds it comes from the normal equations
// alone, sum_b (sum w y_b^2 - 2 rhs_b . x_b + x_b' G x_b): no radiance to
// assemble, thousands of combinations in a millisecond. Holds its scratch.
class CombinationCost {
 public:
  CombinationCost(const Problem& p, const Samples& s, const TargetSystem& t, const std::vector<LibraryCurve>& library)
      : p_(p), s_(s), t_(t), library_(library), bounds_(HasBounds(p)) {}
  double operator()(const std::vector<int>& combination) {
    const int n = static_cast<int>(combination.size()), nb = p_.bands.band_count();
    g_targets_.clear();
    for (int k : combination) g_targets_.push_back(&library_[k].at_targets);
    double G[5][5], rhs[5], x[5];
    NormalMatrix(t_, g_targets_, G);
    Lambda_.resize(n);
    double cost = 0;
    for (int b = 0; b < nb; ++b) {
      NormalRhs(t_, g_targets_, b, rhs);
      NonNegativeSolve(G, rhs, n, x);
      cost += t_.wyy[b];
      for (int i = 0; i < n; ++i) {
        Lambda_[i].resize(nb);
        Lambda_[i][b] = x[i];
        cost -= 2 * rhs[i] * x[i];
        for (int j = 0; j < n; ++j) cost += x[i] * (i >= j ? G[i][j] : G[j][i]) * x[j];
      }
    }
    if (!bounds_) return std::max(cost, 0.0);
    g_.clear();
    for (int k : combination) g_.push_back(&library_[k].g);
    EmitInto(p_, s_, g_, Lambda_, Lp_);
    return CostOf(p_, s_, Lp_, residuals_);
  }
  // The emitting centres, sum of Lambda over states and bands, of the last
  // combination costed (the tie-break of LeastLambdaFirst).
  double LambdaSum() const { return SumOfLambda(Lambda_); }

 private:
  const Problem& p_;
  const Samples& s_;
  const TargetSystem& t_;
  const std::vector<LibraryCurve>& library_;
  const bool bounds_;
  Emitted<double> Lp_;  // scratch, reused
  std::vector<double> residuals_;
  std::vector<const std::vector<double>*> g_targets_;
  std::vector<const StateCurve<double>*> g_;
  std::vector<std::vector<double>> Lambda_;
};

// A candidate: its cost, its emitting centres (sum of Lambda) and its
// library curves.
struct Candidate {
  double cost = 0;
  double Lambda_sum = 0;
  std::vector<int> combination;
};

// Best cost first; among the candidates that make the same look as the best
// (within SameLookTolerance), the fewest emitting centres first. Few
// constraints leave many curves that meet them exactly (one target in the dark
// is met by any kr, with Lambda scaled to it), and the cost alone would pick
// among them by rounding: a fast decay with Lambda ~1e11, glowing 1e11 times
// brighter while lit, under one build, a plausible one under another. The
// least Lambda that makes the look is the material with the least phosphor:
// for one dark target tau after the light, the kr whose glow there is most
// efficient (about 1 / tau when saturated), and past kMaxLambda never.
void LeastLambdaFirst(const Problem& p, std::vector<Candidate>& ranked) {
  std::sort(ranked.begin(), ranked.end(), [](const Candidate& a, const Candidate& b) {
    const bool a_ok = a.Lambda_sum <= kMaxLambda, b_ok = b.Lambda_sum <= kMaxLambda;
    if (a_ok != b_ok) return a_ok;
    return a.cost < b.cost || (a.cost == b.cost && a.combination < b.combination);
  });
  if (ranked.empty()) return;
  const double same = ranked.front().cost + SameLookTolerance(p, ranked.front().cost);
  const auto ties = std::find_if(ranked.begin(), ranked.end(),
                                 [&](const Candidate& c) { return c.cost > same || c.Lambda_sum > kMaxLambda; });
  std::stable_sort(ranked.begin(), ties,
                   [](const Candidate& a, const Candidate& b) { return a.Lambda_sum < b.Lambda_sum; });
}

// Candidates for the refinement: combinations of nc library curves (indices),
// in LeastLambdaFirst's order. nc = 1: every curve. nc > 1: a beam search,
// the best `beam` combinations of k curves each extended by every curve of
// the library, so that a slow state that looks poor on its own (its singles
// rank low) is still found as the partner of a fast one.
std::vector<Candidate> RankCombinations(const Problem& p, const std::vector<LibraryCurve>& library, int nc,
                                        CombinationCost& cost_of) {
  std::vector<Candidate> ranked;
  for (int k = 0; k < static_cast<int>(library.size()); ++k) {
    const double cost = cost_of({k});
    ranked.push_back({cost, cost_of.LambdaSum(), {k}});
  }
  LeastLambdaFirst(p, ranked);
  const int beam = 16;
  for (int depth = 2; depth <= nc; ++depth) {
    std::vector<Candidate> next;
    std::set<std::vector<int>> seen;
    for (int c = 0; c < std::min<int>(beam, static_cast<int>(ranked.size())); ++c)
      for (int k = 0; k < static_cast<int>(library.size()); ++k) {
        const std::vector<int>& combination = ranked[c].combination;
        if (std::find(combination.begin(), combination.end(), k) != combination.end()) continue;
        std::vector<int> extended = combination;
        extended.push_back(k);
        std::sort(extended.begin(), extended.end());
        if (!seen.insert(extended).second) continue;
        const double cost = cost_of(extended);
        next.push_back({cost, cost_of.LambdaSum(), std::move(extended)});
      }
    LeastLambdaFirst(p, next);
    ranked = std::move(next);
  }
  return ranked;
}

// Bounds on the refinement's log parameters: kr and ke within the library's
// range, widened. Above, a state lit with ke_b E_b >= 1e3 /s in a band fills
// within a millisecond of the light: saturated, it looks the same for any
// larger ke, and a fit that wants saturation would otherwise push ke_b to
// whatever bound there is.
std::vector<double> KeUpperBounds(const Problem& p, const std::vector<int>& lit) {
  std::vector<double> E_max(lit.size(), 0.0);
  for (const Point& point : p.points)
    for (const auto& E : point.irradiance)
      for (std::size_t l = 0; l < lit.size(); ++l) E_max[l] = std::max(E_max[l], E[lit[l]]);
  std::vector<double> upper;
  for (double E : E_max) upper.push_back(1e3 / E);
  return upper;
}

void BoundLogRates(const std::vector<double>& ke_upper, ceres::Problem& problem, std::vector<double>& log_kr,
                   std::vector<double>& log_ke) {
  const int n_lit = static_cast<int>(ke_upper.size());
  for (std::size_t i = 0; i < log_kr.size(); ++i) {
    problem.SetParameterLowerBound(log_kr.data(), static_cast<int>(i), std::log(1e-5));
    problem.SetParameterUpperBound(log_kr.data(), static_cast<int>(i), std::log(1e3));
  }
  for (std::size_t q = 0; q < log_ke.size(); ++q) {
    problem.SetParameterLowerBound(log_ke.data(), static_cast<int>(q), std::log(1e-12));
    problem.SetParameterUpperBound(log_ke.data(), static_cast<int>(q), std::log(ke_upper[q % n_lit]));
  }
}

// The cost as Ceres sees it, divided by the constraints' energy (sum w |T|^2):
// Ceres' tolerances are absolute, and a faint glow's cost and gradient are
// tiny, so unscaled the refinement would stop far from the targets.
ceres::LossFunction* ScaleToTargets(const Problem& p) {
  const double energy = TargetEnergy(p);
  return new ceres::ScaledLoss(nullptr, energy > 0 ? 1 / energy : 1.0, ceres::TAKE_OWNERSHIP);
}

// Refines one candidate with Ceres. First over log kr and log ke with Lambda
// projected out (ProjectedEditCost: fewer parameters, and Lambda is optimal at
// every step, so a few iterations reach what the full problem reaches). That
// optimum is a stationary point of the full cost when only targets count;
// bounds also pull on Lambda, so then every parameter is refined after it.
Parameters Refine(const Problem& p, const Samples& s, const TargetSystem& t, const std::vector<int>& lit,
                  const Parameters& x0, int* evaluations) {
  const int nc = static_cast<int>(x0.kr.size()), nb = p.bands.band_count(), n_lit = static_cast<int>(lit.size());
  const int residuals = ResidualCount(p, s);
  const std::vector<double> ke_upper = KeUpperBounds(p, lit);
  std::vector<double> log_kr(nc), log_ke(nc * n_lit), Lambda(nc * nb);
  for (int i = 0; i < nc; ++i) {
    log_kr[i] = std::log(x0.kr[i]);
    for (int l = 0; l < n_lit; ++l) log_ke[i * n_lit + l] = std::log(std::clamp(x0.ke[i][l], 1e-12, ke_upper[l]));
  }
  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::DENSE_QR;
  solver.max_num_iterations = 60;
  solver.function_tolerance = 1e-12;
  solver.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  {
    auto* cost =
        new ceres::DynamicAutoDiffCostFunction<ProjectedEditCost, 8>(new ProjectedEditCost{&p, &s, &t, &lit, nc});
    cost->AddParameterBlock(nc);
    cost->AddParameterBlock(nc * n_lit);
    cost->SetNumResiduals(residuals);
    ceres::Problem problem;
    problem.AddResidualBlock(cost, ScaleToTargets(p), {log_kr.data(), log_ke.data()});
    BoundLogRates(ke_upper, problem, log_kr, log_ke);
    ceres::Solve(solver, &problem, &summary);
    *evaluations += summary.num_residual_evaluations + summary.num_jacobian_evaluations;
  }
  Parameters x;
  for (int i = 0; i < nc; ++i) {
    x.kr.push_back(std::exp(log_kr[i]));
    x.ke.emplace_back();
    for (int l = 0; l < n_lit; ++l) x.ke[i].push_back(std::exp(log_ke[i * n_lit + l]));
  }
  std::vector<StateCurve<double>> g;
  for (int i = 0; i < nc; ++i) g.push_back(CurveOf(p, s, lit, x.kr[i], x.ke[i].data()));
  x.Lambda = BestLambda(p, s, t, Pointers(g));
  if (!HasBounds(p)) return x;

  for (int i = 0; i < nc; ++i)
    for (int b = 0; b < nb; ++b) Lambda[i * nb + b] = x.Lambda[i][b];
  ceres::Problem problem;
  problem.AddResidualBlock(new EditCost(p, s, lit, nc), ScaleToTargets(p),
                           {log_kr.data(), log_ke.data(), Lambda.data()});
  for (int q = 0; q < nc * nb; ++q) problem.SetParameterLowerBound(Lambda.data(), q, 0.0);
  BoundLogRates(ke_upper, problem, log_kr, log_ke);
  ceres::Solve(solver, &problem, &summary);
  *evaluations += summary.num_residual_evaluations + summary.num_jacobian_evaluations;
  for (int i = 0; i < nc; ++i) {
    x.kr[i] = std::exp(log_kr[i]);
    for (int l = 0; l < n_lit; ++l) x.ke[i][l] = std::exp(log_ke[i * n_lit + l]);
    x.Lambda[i].assign(Lambda.begin() + i * nb, Lambda.begin() + (i + 1) * nb);
  }
  return x;
}

// A saturated state (full soon after the light comes on) looks the same for
// any larger ke, so the refinement leaves its ke wherever it stopped, up to
// the bound. Each state's ke is halved while the cost stays within 1e-6 of
// its own (plus 1e-12 of the targets' energy): the weakest excitation that
// makes the look, rather than an arbitrary point of the plateau (and its
// Lambda with it, re-solved when only targets count). Only while the state
// stays saturated: once halving ke lowers its peak by more than a quarter,
// it is on the weak-light line, where r grows in proportion to ke and Lambda
// takes the other factor, so the look holds for every further halving and ke
// would fall (and Lambda rise) 2^60-fold, past what a material file holds.
// There the knee is kept.
Parameters WeakestExcitation(const Problem& p, const Samples& s, const TargetSystem& t, const std::vector<int>& lit,
                             Parameters x) {
  const double cost = CostOf(p, s, EmittedAtSamples(p, s, lit, x));
  const double allowed = cost + SameLookTolerance(p, cost);
  for (std::size_t i = 0; i < x.kr.size(); ++i)
    for (int halving = 0; halving < 60; ++halving) {
      Parameters weaker = x;
      for (double& ke : weaker.ke[i]) ke /= 2;
      const auto peak = [&](const Parameters& q) {
        double top = 0;
        for (const auto& at_point : CurveOf(p, s, lit, q.kr[i], q.ke[i].data()))
          for (double v : at_point) top = std::max(top, v);
        return top;
      };
      if (peak(weaker) < 0.75 * peak(x)) break;
      if (!HasBounds(p)) {  // Lambda follows (r_inf = a / (a + kr) drops a little); bounds would pull on it too
        std::vector<StateCurve<double>> g;
        for (std::size_t j = 0; j < x.kr.size(); ++j)
          g.push_back(CurveOf(p, s, lit, weaker.kr[j], weaker.ke[j].data()));
        weaker.Lambda = BestLambda(p, s, t, Pointers(g));
      }
      bool representable = true;
      for (const auto& Lambda : weaker.Lambda)
        for (double v : Lambda) representable = representable && v <= kMaxLambda;
      if (!representable || CostOf(p, s, EmittedAtSamples(p, s, lit, weaker)) > allowed) break;
      x = std::move(weaker);
    }
  return x;
}

// A material as the solver's parameters (ke on the lit bands). An unknown ke
// in a lit band has no value to simulate with: the caller states an
// assumption (AssumeUnknownKeZero) or gets a UserError, as the simulator does.
Parameters ParametersOf(const Problem& p, const Material& material, const std::vector<int>& lit) {
  Parameters x;
  for (std::size_t i = 0; i < material.states.size(); ++i) {
    const ExcitedState& state = material.states[i];
    x.kr.push_back(state.kr);
    std::vector<double> ke;
    for (int b : lit) {
      if (!state.ke[b])
        ThrowUserError(material.name, "states[" + std::to_string(i) + "].ke[" + std::to_string(b) + "]",
                       "unknown (not measured) for band " + p.bands.BandName(b) + ", which " + p.source + " lights");
      ke.push_back(*state.ke[b]);
    }
    x.ke.push_back(ke);
    x.Lambda.push_back(state.Lambda);
  }
  return x;
}

// The start material's parameters (Problem::start), or nullopt when it has
// another number of states.
std::optional<Parameters> StartParameters(const Problem& p, const std::vector<int>& lit) {
  if (!p.start || p.start->state_count() != p.states) return std::nullopt;
  Material known = *p.start;
  AssumeUnknownKeZero(known);
  return ParametersOf(p, known, lit);
}

}  // namespace

Solution Solve(const Problem& p, const SolveOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const Samples s = MakeSamples(p);
  const std::vector<int> lit = LitBands(p);
  const int nc = p.states, n_lit = static_cast<int>(lit.size());
  int evaluations = 0;
  const std::vector<double> direction = ExcitationDirection(p, lit);
  const TargetSystem t = MakeTargetSystem(p, s);
  // 0. What the points wear now: kept whole when it already meets the
  // constraints to the tolerance that calls two looks the same.
  const std::optional<Parameters> from_start = StartParameters(p, lit);
  if (from_start && CostOf(p, s, EmittedAtSamples(p, s, lit, *from_start)) <= SameLookTolerance(p, 0)) {
    Solution kept = Finish(p, s, lit, *from_start, start, evaluations + 1);
    kept.material = *p.start;
    kept.kept_start = true;
    return kept;
  }

  // 1. The curve library: g = kr r(t) at the samples for a log grid of (kr, kappa).
  std::vector<LibraryCurve> library;
  for (double kr : LogSpace(1e-3, 10.0, options.library_kr)) {
    std::vector<LibraryCurve> row;
    for (double kappa : LogSpace(1e-4, 1e2, options.library_excitation)) {
      std::vector<double> ke(n_lit);
      for (int l = 0; l < n_lit; ++l) ke[l] = kappa * direction[l];
      StateCurve<double> g = CurveOf(p, s, lit, kr, ke.data());
      std::vector<double> at_targets = AtTargets(p, s, t, g);
      row.push_back({kr, kappa, std::move(g), std::move(at_targets)});
      ++evaluations;
    }
    for (int k : DistinctShapes(row)) library.push_back(std::move(row[k]));
  }
  // 2. Candidates, ranked by the full cost with the closed-form Lambda.
  CombinationCost cost_of(p, s, t, library);
  const std::vector<Candidate> ranked = RankCombinations(p, library, nc, cost_of);
  evaluations += static_cast<int>(ranked.size());
  auto params_of = [&](const std::vector<int>& combination) {
    Parameters x;
    std::vector<const StateCurve<double>*> g;
    for (int k : combination) {
      g.push_back(&library[k].g);
      x.kr.push_back(library[k].kr);
      std::vector<double> ke(n_lit);
      for (int l = 0; l < n_lit; ++l) ke[l] = library[k].kappa * direction[l];
      x.ke.push_back(ke);
    }
    x.Lambda = BestLambda(p, s, t, g);
    return x;
  };

  // 3. Refine the best candidates with Ceres; the best result wins, and of
  // results that make the same look, the one with the least Lambda (as in
  // LeastLambdaFirst). Starts differ in their set of kr: curves that differ
  // only in kappa past saturation look the same, and would start the
  // refinement from one place.
  Parameters best = params_of(ranked.front().combination);
  double best_cost = CostOf(p, s, EmittedAtSamples(p, s, lit, best));
  const auto better = [&](const Parameters& x, double c) {
    const double Lambda = SumOfLambda(x.Lambda), best_Lambda = SumOfLambda(best.Lambda);
    if ((Lambda <= kMaxLambda) != (best_Lambda <= kMaxLambda)) return Lambda <= kMaxLambda;
    const double same = SameLookTolerance(p, std::min(c, best_cost));
    if (c < best_cost - same) return true;
    return c <= best_cost + same && Lambda < best_Lambda;
  };
  if (from_start) {
    const double c = CostOf(p, s, EmittedAtSamples(p, s, lit, *from_start));
    if (better(*from_start, c)) best_cost = c, best = *from_start;
  }
  if (options.refine && n_lit > 0 && from_start) {
    const Parameters x = Refine(p, s, t, lit, *from_start, &evaluations);
    const double c = CostOf(p, s, EmittedAtSamples(p, s, lit, x));
    if (better(x, c)) best_cost = c, best = x;
  }
  if (options.refine && n_lit > 0) {
    std::vector<std::vector<double>> kr_sets;
    for (std::size_t k = 0; k < ranked.size() && static_cast<int>(kr_sets.size()) < options.refine_starts; ++k) {
      const Parameters x0 = params_of(ranked[k].combination);
      std::vector<double> kr_set = x0.kr;
      std::sort(kr_set.begin(), kr_set.end());
      if (std::find(kr_sets.begin(), kr_sets.end(), kr_set) != kr_sets.end()) continue;
      kr_sets.push_back(kr_set);
      const Parameters x = Refine(p, s, t, lit, x0, &evaluations);
      const double c = CostOf(p, s, EmittedAtSamples(p, s, lit, x));
      if (better(x, c)) {
        best_cost = c;
        best = x;
      }
    }
  }
  best = WeakestExcitation(p, s, t, lit, best);
  // States sorted by rate, as everywhere in phos.
  std::vector<int> order(nc);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) { return best.kr[a] > best.kr[b]; });
  Parameters sorted;
  for (int i : order) {
    sorted.kr.push_back(best.kr[i]);
    sorted.ke.push_back(best.ke[i]);
    sorted.Lambda.push_back(best.Lambda[i]);
  }
  return Finish(p, s, lit, sorted, start, evaluations);
}

std::optional<Solution> SolveGridBaseline(const Problem& p, std::string* why) {
  const auto start = std::chrono::steady_clock::now();
  const int nb = p.bands.band_count();
  if (p.states != 1 || nb > 3) {
    if (why) *why = "the paper's grid (Table 8.2) is defined for nc = 1 in three bands (RGB)";
    return std::nullopt;
  }
  const Samples s = MakeSamples(p);
  // Table 8.2: a * 2^b, b equidistant in [b_min, b_max], 10 values per dimension.
  auto grid = [](double a, double b_max) {
    std::vector<double> v;
    for (int k = 0; k < 10; ++k) v.push_back(a * std::pow(2.0, b_max * k / 9.0));
    return v;
  };
  const std::vector<double> kr_grid = grid(0.001, 5.0), ke_grid = grid(0.001, 12.0), Lambda_grid = grid(0.1, 9.0);
  std::vector<int> all_bands(nb);
  std::iota(all_bands.begin(), all_bands.end(), 0);
  Parameters best;
  double best_cost = std::numeric_limits<double>::infinity();
  int evaluations = 0;
  std::vector<std::vector<double>> r(p.points.size());
  // Every sample the cost reads, flattened once: which state value it takes,
  // and per band its reflected light, target and weight. The loops below then
  // do the same arithmetic in the same order as on the constraints
  // themselves (the grid's 10^4 x 3 x 10 cost evaluations were mostly
  // lookups through them), so the grid finds the same point.
  struct Term {
    int point = 0, sample = 0;
    Constraint::Kind kind = Constraint::Kind::kTarget;
    double weight = 0;
    std::vector<double> reflected, radiance;  // per band
  };
  std::vector<Term> terms;
  for (std::size_t k = 0; k < p.constraints.size(); ++k) {
    const Constraint& con = p.constraints[k];
    const Point& point = p.points[con.point];
    const std::vector<int> samples =
        con.kind == Constraint::Kind::kTarget ? std::vector<int>{s.target_sample[k]} : s.bound_samples[k];
    for (int m : samples) {
      Term term{con.point, m, con.kind, con.weight, {}, con.radiance};
      for (int b = 0; b < nb; ++b)
        term.reflected.push_back(point.albedo[b] * point.irradiance[s.points[con.point].frame[m]][b] / kPi);
      terms.push_back(std::move(term));
    }
  }
  std::vector<double> state(terms.size());                     // r at each term's sample
  std::vector<double> ke(nb), Lambda_of_band(nb), excitation;  // reused: no allocation per grid point
  const int ke_combinations = static_cast<int>(std::pow(10, nb));
  for (double kr : kr_grid)
    for (int combination = 0; combination < ke_combinations; ++combination) {
      for (int b = 0, rest = combination; b < nb; ++b, rest /= 10) ke[b] = ke_grid[rest % 10];
      for (std::size_t q = 0; q < p.points.size(); ++q) {
        ExcitationPerStep(p.points[q], s.points[q], all_bands, ke.data(), excitation);
        StateAtSamples(s.points[q], excitation, kr, r[q]);
      }
      ++evaluations;
      for (std::size_t j = 0; j < terms.size(); ++j) state[j] = r[terms[j].point][terms[j].sample];
      // The cost separates over bands, and Lambda_b enters band b only: the
      // best Lambda grid point per band gives the grid's best over all 10^3.
      std::fill(Lambda_of_band.begin(), Lambda_of_band.end(), 0.0);
      double cost = 0;
      for (int b = 0; b < nb; ++b) {
        double best_band = std::numeric_limits<double>::infinity();
        for (double Lambda : Lambda_grid) {
          const double Lambda_kr = Lambda * kr;
          double c = 0;
          for (std::size_t j = 0; j < terms.size(); ++j) {
            const Term& term = terms[j];
            const double L = Lambda_kr * state[j] + term.reflected[b];
            if (term.kind == Constraint::Kind::kTarget) {
              c += term.weight * std::pow(L - term.radiance[b], 2);
            } else {
              const double miss = term.kind == Constraint::Kind::kAtLeast ? term.radiance[b] - L : L - term.radiance[b];
              if (miss > 0) c += term.weight * miss * miss;
            }
          }
          if (c < best_band) {
            best_band = c;
            Lambda_of_band[b] = Lambda;
          }
        }
        cost += best_band;
      }
      if (cost < best_cost) {
        best_cost = cost;
        best = Parameters{{kr}, {ke}, {Lambda_of_band}};
      }
    }
  return Finish(p, s, all_bands, best, start, evaluations);
}

double Cost(const Problem& p, const Material& material) {
  const Samples s = MakeSamples(p);
  const std::vector<int> lit = LitBands(p);
  const Parameters x = ParametersOf(p, material, lit);
  return CostOf(p, s, EmittedAtSamples(p, s, lit, x));
}

std::vector<std::vector<double>> PredictRadiance(const Problem& p, const Material& material,
                                                 const std::vector<double>& times_s, int point) {
  Problem probe = p;
  probe.constraints.clear();
  for (double t : times_s) {
    Constraint c;
    c.point = point;
    c.t_s = c.until_s = t;
    c.radiance.assign(p.bands.band_count(), 0.0);
    probe.constraints.push_back(c);
  }
  const Samples s = MakeSamples(probe);
  const std::vector<int> lit = LitBands(p);
  const Parameters x = ParametersOf(p, material, lit);
  const Emitted<double> Lp = EmittedAtSamples(probe, s, lit, x);
  const Point& at = p.points[point];
  std::vector<std::vector<double>> out;
  for (std::size_t c = 0; c < times_s.size(); ++c) {
    const int m = s.target_sample[c];
    std::vector<double> L(p.bands.band_count());
    for (int b = 0; b < p.bands.band_count(); ++b)
      L[b] = Lp[point][m][b] + at.albedo[b] * at.irradiance[s.points[point].frame[m]][b] / kPi;
    out.push_back(L);
  }
  return out;
}

nlohmann::json SolutionToJson(const Solution& solution) {
  nlohmann::json residuals = nlohmann::json::array(), constraints = nlohmann::json::array();
  for (const ConstraintResult& c : solution.constraints) {
    residuals.push_back(c.residual);
    constraints.push_back({{"label", c.label}, {"residual", c.residual}, {"predicted", c.predicted}});
  }
  return {{"material", MaterialToJson(solution.material)},
          {"cost", solution.cost},
          {"residuals", residuals},
          {"constraints", constraints},
          {"feedback", solution.feedback},
          {"seconds", solution.seconds},
          {"evaluations", solution.evaluations}};
}

}  // namespace phos::editor
