#include "phos/editor/solve.h"

#include <algorithm>
#include <chrono>
#include <functional>
#include <cmath>
#include <limits>
#include <numeric>

#include <ceres/ceres.h>
#include <nlohmann/json.hpp>

#include "phos/fit/small_nnls.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"

namespace phos::editor {
namespace {

constexpr double kPi = 3.14159265358979323846;

// The moments the cost looks at, per point: every target's time and every
// frame start inside a bound's range (and its ends), sorted, with who uses each.
struct PointSamples {
  std::vector<double> t;    // sorted, unique
  std::vector<int> frame;   // frame whose irradiance shows at t
};
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
    for (double t : ps.t) ps.frame.push_back(std::clamp(static_cast<int>(std::floor(t / p.dt_s + 1e-9)), 0, frames - 1));
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

// r(t) at the samples for decay rate kr and excitation rate a[frame] (Eq. 8.1
// with the exact update, irradiance constant over each frame). T: double or a Ceres Jet.
template <typename T>
void StateAtSamples(const PointSamples& s, double dt_s, const std::vector<T>& a, const T& kr, std::vector<T>& r_out) {
  using std::exp;
  using std::expm1;
  r_out.resize(s.t.size());
  T r(0.0);
  double t = 0;
  int frame = 0;
  auto step = [&](const T& a_frame, double h) {
    const T k = a_frame + kr;
    const T rise = -expm1(-k * h);
    r = r * (T(1.0) - rise) + a_frame / k * rise;
  };
  for (std::size_t m = 0; m < s.t.size(); ++m) {
    while (t < s.t[m] - 1e-12) {
      const double frame_end = dt_s * (frame + 1);
      const double until = std::min(frame_end, s.t[m]);
      step(a[std::min<std::size_t>(frame, a.size() - 1)], until - t);
      t = until;
      if (t >= frame_end - 1e-12) ++frame;
    }
    r_out[m] = r;
  }
}

// Emitted radiance per point, sample and band.
template <typename T>
using Emitted = std::vector<std::vector<std::vector<T>>>;

// The residuals of Eq. 8.7 given the emitted radiance (reflection added here).
template <typename T>
void Residuals(const Problem& p, const Samples& s, const Emitted<T>& Lp, T* out) {
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
      for (int b = 0; b < nb; ++b) out[k++] = w * (L(s.target_sample[c], b) - con.radiance[b]);
    } else {
      for (int sample : s.bound_samples[c])
        for (int b = 0; b < nb; ++b) {
          const T miss = con.kind == Constraint::Kind::kAtLeast ? T(con.radiance[b]) - L(sample, b)
                                                                : L(sample, b) - T(con.radiance[b]);
          out[k++] = miss > T(0.0) ? T(w) * miss : T(0.0);
        }
    }
  }
}

int ResidualCount(const Problem& p, const Samples& s) {
  int count = 0;
  for (std::size_t c = 0; c < p.constraints.size(); ++c)
    count += p.bands.band_count() * (p.constraints[c].kind == Constraint::Kind::kTarget
                                         ? 1 : static_cast<int>(s.bound_samples[c].size()));
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
  std::vector<double> kr;                  // [nc]
  std::vector<std::vector<double>> ke;     // [nc][lit]
  std::vector<std::vector<double>> Lambda; // [nc][nb]
};

Material ToMaterial(const Problem& p, const std::vector<int>& lit, const Parameters& x) {
  Material m;
  m.name = "edited";
  m.source = "phos edit solve (Sec. 8.6, Eq. 8.7) on " + p.source;
  m.bands = p.bands;
  m.albedo = p.points[0].albedo;
  for (std::size_t i = 0; i < x.kr.size(); ++i) {
    ExcitedState s;
    s.kr = x.kr[i];
    s.ke.assign(p.bands.band_count(), 0.0);  // no light there: any ke looks the same; 0 is the honest minimum
    for (std::size_t l = 0; l < lit.size(); ++l) s.ke[lit[l]] = x.ke[i][l];
    s.Lambda = x.Lambda[i];
    m.states.push_back(s);
  }
  return m;
}

// Excitation rate per frame of a state at a point: a = sum_b ke_b E_b.
template <typename T>
std::vector<T> ExcitationPerFrame(const Point& point, const std::vector<int>& lit, const T* ke) {
  std::vector<T> a(point.irradiance.size(), T(0.0));
  for (std::size_t f = 0; f < a.size(); ++f)
    for (std::size_t l = 0; l < lit.size(); ++l) a[f] += ke[l] * point.irradiance[f][lit[l]];
  return a;
}

// Ceres functor over log kr, log ke (lit bands), Lambda (all bands), all states.
struct EditCost {
  const Problem* p;
  const Samples* s;
  const std::vector<int>* lit;
  int nc, nb;
  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    using std::exp;
    const T* log_kr = parameters[0];
    const T* log_ke = parameters[1];
    const T* Lambda = parameters[2];
    Emitted<T> Lp(p->points.size());
    for (std::size_t q = 0; q < p->points.size(); ++q)
      Lp[q].assign(s->points[q].t.size(), std::vector<T>(nb, T(0.0)));
    std::vector<T> r;
    const int n_lit = static_cast<int>(lit->size());
    for (int i = 0; i < nc; ++i) {
      std::vector<T> ke(n_lit);
      for (int l = 0; l < n_lit; ++l) ke[l] = exp(log_ke[i * n_lit + l]);
      const T kr = exp(log_kr[i]);
      for (std::size_t q = 0; q < p->points.size(); ++q) {
        StateAtSamples(s->points[q], p->dt_s, ExcitationPerFrame(p->points[q], *lit, ke.data()), kr, r);
        for (std::size_t m = 0; m < r.size(); ++m)
          for (int b = 0; b < nb; ++b) Lp[q][m][b] += Lambda[i * nb + b] * kr * r[m];
      }
    }
    Residuals(*p, *s, Lp, residuals);
    return true;
  }
};

double CostOf(const Problem& p, const Samples& s, const Emitted<double>& Lp) {
  std::vector<double> residuals(ResidualCount(p, s));
  Residuals(p, s, Lp, residuals.data());
  double cost = 0;
  for (double r : residuals) cost += r * r;
  return cost;
}

Emitted<double> EmittedAtSamples(const Problem& p, const Samples& s, const std::vector<int>& lit, const Parameters& x) {
  const int nb = p.bands.band_count();
  Emitted<double> Lp(p.points.size());
  std::vector<double> r;
  for (std::size_t q = 0; q < p.points.size(); ++q) {
    Lp[q].assign(s.points[q].t.size(), std::vector<double>(nb, 0.0));
    for (std::size_t i = 0; i < x.kr.size(); ++i) {
      StateAtSamples(s.points[q], p.dt_s, ExcitationPerFrame(p.points[q], lit, x.ke[i].data()), x.kr[i], r);
      for (std::size_t m = 0; m < r.size(); ++m)
        for (int b = 0; b < nb; ++b) Lp[q][m][b] += x.Lambda[i][b] * x.kr[i] * r[m];
    }
  }
  return Lp;
}

std::vector<double> LogSpace(double lo, double hi, int n) {
  std::vector<double> v(n);
  for (int k = 0; k < n; ++k) v[k] = lo * std::pow(hi / lo, n == 1 ? 0.0 : double(k) / (n - 1));
  return v;
}

// Lambda for given state curves g_i(sample) = kr_i r_i: per band, non-negative
// least squares on the targets (bounds are left to the refinement).
std::vector<std::vector<double>> BestLambda(const Problem& p, const Samples& s,
                                            const std::vector<const std::vector<std::vector<double>>*>& g) {
  const int nc = static_cast<int>(g.size()), nb = p.bands.band_count();
  std::vector<std::vector<double>> Lambda(nc, std::vector<double>(nb, 0.0));
  for (int b = 0; b < nb; ++b) {
    SmallMatrix G = SmallMatrix::Zero(nc, nc);
    SmallVector rhs = SmallVector::Zero(nc);
    for (std::size_t c = 0; c < p.constraints.size(); ++c) {
      const Constraint& con = p.constraints[c];
      if (con.kind != Constraint::Kind::kTarget) continue;
      const int m = s.target_sample[c], q = con.point;
      const Point& point = p.points[q];
      const double y = con.radiance[b] - point.albedo[b] * point.irradiance[s.points[q].frame[m]][b] / kPi;
      for (int i = 0; i < nc; ++i) {
        const double gi = (*g[i])[q][m];
        rhs[i] += con.weight * gi * y;
        for (int j = 0; j < nc; ++j) G(i, j) += con.weight * gi * (*g[j])[q][m];
      }
    }
    G.diagonal().array() += 1e-14 * (G.diagonal().maxCoeff() + 1e-300);  // a state unseen by any target
    const SmallNnlsResult x = SolveSmallNnls(G, rhs, nc);
    for (int i = 0; i < nc; ++i) Lambda[i][b] = x.ok ? std::max(0.0, x.x[i]) : 0.0;
  }
  return Lambda;
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
                      FormatShort(results[c].residual, 3) + " (" + FormatShort(100 * results[c].residual / std::max(scale, 1e-300), 3) +
                      "% of its largest band)");
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
          notes.push_back(a.label + " and " + b.label + " contradict: it is dark from " + FormatDouble(a.t_s) + " s to " +
                          FormatDouble(b.t_s) + " s, where a glow can only fade, but band " + p.bands.BandName(band) +
                          " rises from " + FormatShort(a.radiance[band], 3) + " to " + FormatShort(b.radiance[band], 3));
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
          result.residual = std::max(result.residual, con.kind == Constraint::Kind::kAtLeast ? con.radiance[b] - L(m, b)
                                                                                          : L(m, b) - con.radiance[b]);
    }
    solution.constraints.push_back(result);
  }
  solution.feedback = Feedback(p, s, solution.constraints);
  solution.evaluations = evaluations;
  solution.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return solution;
}

}  // namespace

Solution Solve(const Problem& p, const SolveOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const Samples s = MakeSamples(p);
  const std::vector<int> lit = LitBands(p);
  const int nb = p.bands.band_count(), nc = p.states, n_lit = static_cast<int>(lit.size());
  int evaluations = 0;

  // The excitation direction: ke = kappa * e, e the mean irradiance over the
  // lit frames scaled so that e . E_mean = 1 (kappa: the rate under the mean light).
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

  // 1. The curve library: g = kr r(t) at the samples for a log grid of (kr, kappa).
  struct Curve {
    double kr, kappa;
    std::vector<std::vector<double>> g;  // [point][sample]
  };
  std::vector<Curve> library;
  const std::vector<double> kr_grid = LogSpace(1e-3, 10.0, options.library_kr);
  const std::vector<double> kappa_grid = LogSpace(1e-4, 1e2, options.library_excitation);
  std::vector<double> r;
  for (double kappa : kappa_grid) {
    std::vector<double> ke(n_lit);
    for (int l = 0; l < n_lit; ++l) ke[l] = kappa * direction[l];
    std::vector<std::vector<double>> a;
    for (const Point& point : p.points) a.push_back(ExcitationPerFrame(point, lit, ke.data()));
    for (double kr : kr_grid) {
      Curve curve{kr, kappa, {}};
      for (std::size_t q = 0; q < p.points.size(); ++q) {
        StateAtSamples(s.points[q], p.dt_s, a[q], kr, r);
        for (double& v : r) v *= kr;
        curve.g.push_back(r);
      }
      library.push_back(std::move(curve));
      ++evaluations;
    }
  }
  // 2. Candidates: single curves (nc = 1) or combinations of the best singles,
  // each with its closed-form Lambda, ranked by the full cost.
  auto params_of = [&](const std::vector<const Curve*>& curves) {
    std::vector<const std::vector<std::vector<double>>*> g;
    for (const Curve* c : curves) g.push_back(&c->g);
    Parameters x;
    x.Lambda = BestLambda(p, s, g);
    for (const Curve* c : curves) {
      x.kr.push_back(c->kr);
      std::vector<double> ke(n_lit);
      for (int l = 0; l < n_lit; ++l) ke[l] = c->kappa * direction[l];
      x.ke.push_back(ke);
    }
    return x;
  };
  std::vector<std::pair<double, Parameters>> ranked;
  auto evaluate = [&](const std::vector<const Curve*>& curves) {
    Parameters x = params_of(curves);
    Emitted<double> Lp(p.points.size());
    for (std::size_t q = 0; q < p.points.size(); ++q) {
      Lp[q].assign(s.points[q].t.size(), std::vector<double>(nb, 0.0));
      for (std::size_t i = 0; i < curves.size(); ++i)
        for (std::size_t m = 0; m < s.points[q].t.size(); ++m)
          for (int b = 0; b < nb; ++b) Lp[q][m][b] += x.Lambda[i][b] * curves[i]->g[q][m];
    }
    ranked.emplace_back(CostOf(p, s, Lp), std::move(x));
  };
  std::vector<std::pair<double, int>> singles;
  for (std::size_t k = 0; k < library.size(); ++k) {
    evaluate({&library[k]});
    singles.emplace_back(ranked.back().first, static_cast<int>(k));
  }
  if (nc > 1) {
    // Beam search: the best `beam` combinations of k curves, each extended by
    // every curve of the library. A slow state that looks poor on its own
    // (its singles rank low) is still found as the partner of a fast one.
    const int beam = 16;
    std::sort(singles.begin(), singles.end());
    std::vector<std::vector<int>> combinations;
    for (int k = 0; k < std::min<int>(beam, static_cast<int>(singles.size())); ++k) combinations.push_back({singles[k].second});
    for (int depth = 2; depth <= nc; ++depth) {
      ranked.clear();
      std::vector<std::pair<double, std::vector<int>>> next;
      for (const std::vector<int>& combination : combinations)
        for (int k = 0; k < static_cast<int>(library.size()); ++k) {
          if (std::find(combination.begin(), combination.end(), k) != combination.end()) continue;
          std::vector<int> extended = combination;
          extended.push_back(k);
          std::sort(extended.begin(), extended.end());
          std::vector<const Curve*> curves;
          for (int q : extended) curves.push_back(&library[q]);
          evaluate(curves);
          next.emplace_back(ranked.back().first, extended);
        }
      std::sort(next.begin(), next.end());
      next.erase(std::unique(next.begin(), next.end(), [](const auto& a, const auto& b) { return a.second == b.second; }),
                 next.end());
      combinations.clear();
      for (int k = 0; k < std::min<int>(beam, static_cast<int>(next.size())); ++k) combinations.push_back(next[k].second);
    }
  }
  std::sort(ranked.begin(), ranked.end(), [](const auto& a, const auto& b) { return a.first < b.first; });

  // 3. Refine the best candidates with Ceres over every parameter.
  Parameters best = ranked.front().second;
  double best_cost = ranked.front().first;
  if (options.refine && n_lit > 0) {
    const int residuals = ResidualCount(p, s);
    for (int k = 0; k < std::min<int>(options.refine_starts, static_cast<int>(ranked.size())); ++k) {
      const Parameters& x0 = ranked[k].second;
      std::vector<double> log_kr(nc), log_ke(nc * n_lit), Lambda(nc * nb);
      for (int i = 0; i < nc; ++i) {
        log_kr[i] = std::log(x0.kr[i]);
        for (int l = 0; l < n_lit; ++l) log_ke[i * n_lit + l] = std::log(std::max(x0.ke[i][l], 1e-12));
        for (int b = 0; b < nb; ++b) Lambda[i * nb + b] = x0.Lambda[i][b];
      }
      auto* cost = new ceres::DynamicAutoDiffCostFunction<EditCost, 8>(new EditCost{&p, &s, &lit, nc, nb});
      cost->AddParameterBlock(nc);
      cost->AddParameterBlock(nc * n_lit);
      cost->AddParameterBlock(nc * nb);
      cost->SetNumResiduals(residuals);
      ceres::Problem problem;
      problem.AddResidualBlock(cost, nullptr, {log_kr.data(), log_ke.data(), Lambda.data()});
      for (int q = 0; q < nc * nb; ++q) problem.SetParameterLowerBound(Lambda.data(), q, 0.0);
      for (int i = 0; i < nc; ++i) {  // kr and ke within the library's range, widened
        problem.SetParameterLowerBound(log_kr.data(), i, std::log(1e-5));
        problem.SetParameterUpperBound(log_kr.data(), i, std::log(1e3));
      }
      for (int q = 0; q < nc * n_lit; ++q) {
        problem.SetParameterLowerBound(log_ke.data(), q, std::log(1e-12));
        problem.SetParameterUpperBound(log_ke.data(), q, std::log(1e6));
      }
      ceres::Solver::Options solver;
      solver.linear_solver_type = ceres::DENSE_QR;
      solver.max_num_iterations = 60;
      solver.function_tolerance = 1e-12;
      solver.logging_type = ceres::SILENT;
      ceres::Solver::Summary summary;
      ceres::Solve(solver, &problem, &summary);
      evaluations += summary.num_residual_evaluations + summary.num_jacobian_evaluations;
      Parameters x;
      for (int i = 0; i < nc; ++i) {
        x.kr.push_back(std::exp(log_kr[i]));
        x.ke.emplace_back();
        for (int l = 0; l < n_lit; ++l) x.ke[i].push_back(std::exp(log_ke[i * n_lit + l]));
        x.Lambda.emplace_back(Lambda.begin() + i * nb, Lambda.begin() + (i + 1) * nb);
      }
      const double c = CostOf(p, s, EmittedAtSamples(p, s, lit, x));
      if (c < best_cost) {
        best_cost = c;
        best = x;
      }
    }
  }
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
  const int ke_combinations = static_cast<int>(std::pow(10, nb));
  for (double kr : kr_grid)
    for (int combination = 0; combination < ke_combinations; ++combination) {
      std::vector<double> ke(nb);
      for (int b = 0, rest = combination; b < nb; ++b, rest /= 10) ke[b] = ke_grid[rest % 10];
      for (std::size_t q = 0; q < p.points.size(); ++q)
        StateAtSamples(s.points[q], p.dt_s, ExcitationPerFrame(p.points[q], all_bands, ke.data()), kr, r[q]);
      ++evaluations;
      // The cost separates over bands, and Lambda_b enters band b only: the
      // best Lambda grid point per band gives the grid's best over all 10^3.
      Parameters x{{kr}, {ke}, {std::vector<double>(nb, 0.0)}};
      double cost = 0;
      for (int b = 0; b < nb; ++b) {
        double best_band = std::numeric_limits<double>::infinity();
        for (double Lambda : Lambda_grid) {
          double c = 0;
          for (std::size_t k = 0; k < p.constraints.size(); ++k) {
            const Constraint& con = p.constraints[k];
            const Point& point = p.points[con.point];
            auto L = [&](int m) {
              return Lambda * kr * r[con.point][m] + point.albedo[b] * point.irradiance[s.points[con.point].frame[m]][b] / kPi;
            };
            if (con.kind == Constraint::Kind::kTarget) {
              c += con.weight * std::pow(L(s.target_sample[k]) - con.radiance[b], 2);
            } else {
              for (int m : s.bound_samples[k]) {
                const double miss = con.kind == Constraint::Kind::kAtLeast ? con.radiance[b] - L(m) : L(m) - con.radiance[b];
                if (miss > 0) c += con.weight * miss * miss;
              }
            }
          }
          if (c < best_band) {
            best_band = c;
            x.Lambda[0][b] = Lambda;
          }
        }
        cost += best_band;
      }
      if (cost < best_cost) {
        best_cost = cost;
        best = x;
      }
    }
  return Finish(p, s, all_bands, best, start, evaluations);
}

namespace {

// A material as the solver's parameters (ke on the lit bands; unknown as 0).
Parameters ParametersOf(const Material& material, const std::vector<int>& lit) {
  Parameters x;
  for (const ExcitedState& state : material.states) {
    x.kr.push_back(state.kr);
    std::vector<double> ke;
    for (int b : lit) ke.push_back(state.ke[b].value_or(0.0));
    x.ke.push_back(ke);
    x.Lambda.push_back(state.Lambda);
  }
  return x;
}

}  // namespace

double Cost(const Problem& p, const Material& material) {
  const Samples s = MakeSamples(p);
  const std::vector<int> lit = LitBands(p);
  const Parameters x = ParametersOf(material, lit);
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
  const Parameters x = ParametersOf(material, lit);
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
  return {{"material", MaterialToJson(solution.material)}, {"cost", solution.cost}, {"residuals", residuals},
          {"constraints", constraints}, {"feedback", solution.feedback}, {"seconds", solution.seconds},
          {"evaluations", solution.evaluations}};
}

}  // namespace phos::editor
