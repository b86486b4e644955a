#include "phos/model/state_reduction.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "phos/model/closed_form.h"
#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos {
namespace {

// The light at the point as phases: start times and irradiance, the last
// phase dark and endless (the scene goes on after the schedule ends).
struct Lighting {
  std::vector<double> start_s;
  std::vector<std::vector<double>> E;
};

Lighting LightingOf(const IrradianceSchedule& schedule, int bands) {
  Lighting light;
  double t = 0;
  for (const IrradiancePhase& phase : schedule.phases()) {
    light.start_s.push_back(t);
    light.E.push_back(phase.E);
    t += phase.duration_s;
  }
  light.start_s.push_back(t);
  light.E.emplace_back(static_cast<std::size_t>(bands), 0.0);
  return light;
}

// One state as the search sees it: the state itself, its excitation rate a
// per phase (Eq. 8.1: a = sum_b ke[b] E[b]) and its glow kr r(t) at the grid's
// times, so that its radiance in band b is glow(t) Lambda[b] (Eq. 8.2).
struct Term {
  ExcitedState state;
  std::vector<double> a;
  std::vector<double> glow;
};

// kr r(t) at the (sorted) times, from r = 0 at t = 0, phase by phase with the
// one closed form (ChargedState: exact under constant light, a = 0 in the dark).
std::vector<double> Glow(double kr, const std::vector<double>& a, const Lighting& light,
                         const std::vector<double>& times_s) {
  std::vector<double> glow;
  glow.reserve(times_s.size());
  std::size_t p = 0;
  double r_start = 0;  // r at the start of phase p
  for (double t : times_s) {
    while (p + 1 < light.start_s.size() && t >= light.start_s[p + 1]) {
      r_start = ChargedState(a[p], kr, light.start_s[p + 1] - light.start_s[p], r_start);
      ++p;
    }
    glow.push_back(kr * ChargedState(a[p], kr, t - light.start_s[p], r_start));
  }
  return glow;
}

std::vector<Term> TermsOf(const Material& material, const Lighting& light, const std::vector<double>& times_s,
                          const std::string& where) {
  std::vector<Term> terms(material.states.size());
  for (std::size_t p = 0; p < light.E.size(); ++p) {
    const std::vector<double> a = ExcitationRates(material, light.E[p], where);
    for (std::size_t i = 0; i < terms.size(); ++i) terms[i].a.push_back(a[i]);
  }
  for (std::size_t i = 0; i < terms.size(); ++i) {
    terms[i].state = material.states[i];
    terms[i].glow = Glow(material.states[i].kr, terms[i].a, light, times_s);
  }
  return terms;
}

// Radiance per time and band (Eq. 8.2), [t * bands + b].
std::vector<double> Radiance(const std::vector<Term>& terms, std::size_t times, int bands) {
  std::vector<double> L(times * bands, 0.0);
  for (const Term& term : terms)
    for (std::size_t t = 0; t < times; ++t)
      for (int b = 0; b < bands; ++b) L[t * bands + b] += term.glow[t] * term.state.Lambda[b];
  return L;
}

// The header's e(t), maxed over the times: L against the full L_full.
double MaxError(const std::vector<double>& L, const std::vector<double>& L_full, int bands) {
  double worst = 0;
  for (std::size_t t = 0; t * bands < L.size(); ++t) {
    double total = 0, band_error = 0;
    for (int b = 0; b < bands; ++b) {
      total += L_full[t * bands + b];
      band_error = std::max(band_error, std::fabs(L[t * bands + b] - L_full[t * bands + b]));
    }
    if (total > 0) worst = std::max(worst, band_error / total);
    if (std::isnan(band_error)) return std::numeric_limits<double>::infinity();
  }
  return worst;
}

// Times relative to every switch (the schedule's phase starts within the
// span): s + dt 10^((j + offset) / per_decade) for j = 0, 1, ... up to the
// span, and the span's end. A glow changes on the scale of the time since
// its last switch, so a log grid from each switch resolves every kr alike.
std::vector<double> SwitchGrid(const Lighting& light, double span_s, double dt_s, int per_decade, double offset) {
  std::vector<double> times{span_s};
  for (double s : light.start_s) {
    if (s >= span_s) break;
    for (int j = 0;; ++j) {
      const double t = s + dt_s * std::pow(10.0, (j + offset) / per_decade);
      if (t > span_s) break;
      times.push_back(t);
    }
  }
  std::sort(times.begin(), times.end());
  times.erase(std::unique(times.begin(), times.end()), times.end());
  return times;
}

// What the greedy search holds fixed: the grid, the lights, the full
// material's radiance there and each time's weight in the fit of a merged
// state's Lambda.
struct Search {
  Lighting light;
  std::vector<double> times;
  int bands = 0;
  std::vector<double> L_full;     // [t * bands + b]
  std::vector<double> inv_total;  // 1 / sum_b L_full,b, 0 where that is 0 or too small to invert
};

// Two adjacent states as one at rate kr. Its ke is the sum of theirs (their
// charge rates add in Eq. 8.1; unknown where either is unknown). Eq. 8.2 is
// linear in Lambda, so each band's Lambda is the least-squares fit of the
// merged glow to what the two emitted, relative to the full radiance: never
// negative, since both glows are not.
Term Merge(const Term& x, const Term& y, double kr, const Search& s) {
  Term m;
  m.state.kr = kr;
  for (std::size_t b = 0; b < x.state.ke.size(); ++b)
    m.state.ke.push_back(x.state.ke[b] && y.state.ke[b] ? std::optional(*x.state.ke[b] + *y.state.ke[b])
                                                        : std::nullopt);
  for (std::size_t p = 0; p < x.a.size(); ++p) m.a.push_back(x.a[p] + y.a[p]);
  m.glow = Glow(kr, m.a, s.light, s.times);
  // Relative to the full radiance, so every time counts alike; a time whose
  // scaled glow overflows (the full glow all but gone) is left out of the fit.
  std::vector<double> f(s.times.size());
  double ff = 0;
  for (std::size_t t = 0; t < s.times.size(); ++t) {
    f[t] = m.glow[t] * s.inv_total[t];
    if (!std::isfinite(f[t] * f[t])) f[t] = 0;
    ff += f[t] * f[t];
  }
  for (int b = 0; b < s.bands; ++b) {
    double fR = 0;
    for (std::size_t t = 0; t < s.times.size(); ++t)
      if (f[t] > 0) fR += f[t] * (x.glow[t] * x.state.Lambda[b] + y.glow[t] * y.state.Lambda[b]) * s.inv_total[t];
    m.state.Lambda.push_back(ff > 0 && std::isfinite(fR) ? fR / ff : 0.0);
  }
  return m;
}

// The rates a merge of x and y tries: their emission-weighted log mean (each
// weighted by the energy it releases after its fullest, r_peak sum_b Lambda,
// Eq. 8.2 integrated) and 8 rates log-spaced from one kr to the other.
std::vector<double> MergeRates(const Term& x, const Term& y) {
  auto energy = [](const Term& term) {
    double lambda = 0;
    for (double l : term.state.Lambda) lambda += l;
    return *std::max_element(term.glow.begin(), term.glow.end()) / term.state.kr * lambda;
  };
  const double wx = energy(x), wy = energy(y);
  const double lx = std::log(x.state.kr), ly = std::log(y.state.kr);
  std::vector<double> rates;
  if (wx + wy > 0) rates.push_back(std::exp((wx * lx + wy * ly) / (wx + wy)));
  rates.push_back(x.state.kr);
  for (int q = 1; q < 7; ++q) rates.push_back(std::exp(lx + (ly - lx) * q / 7.0));
  rates.push_back(y.state.kr);
  return rates;
}

// The error after replacing terms[i] (and terms[i + 1] when merged) by
// `added` (none for a drop), from the current radiance L.
double CandidateError(const Search& s, const std::vector<double>& L, const std::vector<Term>& terms, std::size_t i,
                      bool merged, const Term* added) {
  std::vector<double> candidate = L;
  for (std::size_t t = 0; t < s.times.size(); ++t)
    for (int b = 0; b < s.bands; ++b) {
      double& c = candidate[t * s.bands + b];
      c -= terms[i].glow[t] * terms[i].state.Lambda[b];
      if (merged) c -= terms[i + 1].glow[t] * terms[i + 1].state.Lambda[b];
      if (added) c += added->glow[t] * added->state.Lambda[b];
    }
  return MaxError(candidate, s.L_full, s.bands);
}

// One greedy round: the best of every drop and every merge of neighbours in kr.
std::vector<Term> BestNext(const Search& s, const std::vector<Term>& terms, double& error) {
  const std::vector<double> L = Radiance(terms, s.times.size(), s.bands);
  error = std::numeric_limits<double>::infinity();
  std::vector<Term> best;
  auto consider = [&](std::size_t i, bool merged, const Term* added) {
    const double e = CandidateError(s, L, terms, i, merged, added);
    if (!(e < error)) return;
    error = e;
    best.assign(terms.begin(), terms.begin() + static_cast<std::ptrdiff_t>(i));
    if (added) best.push_back(*added);
    best.insert(best.end(), terms.begin() + static_cast<std::ptrdiff_t>(i + (merged ? 2 : 1)), terms.end());
  };
  for (std::size_t i = 0; i < terms.size(); ++i) {
    consider(i, false, nullptr);
    if (i + 1 == terms.size() || !(terms[i].state.kr > 0 && terms[i + 1].state.kr > 0)) continue;
    for (double kr : MergeRates(terms[i], terms[i + 1])) {
      const Term m = Merge(terms[i], terms[i + 1], kr, s);
      consider(i, true, &m);
    }
  }
  return best;
}

}  // namespace

double MaxRadianceError(const Material& full, const Material& reduced, const IrradianceSchedule& schedule,
                        const std::vector<double>& times_s, const std::string& where) {
  std::vector<double> times = times_s;
  std::sort(times.begin(), times.end());
  const Lighting light = LightingOf(schedule, full.band_count());
  const int bands = full.band_count();
  return MaxError(Radiance(TermsOf(reduced, light, times, where), times.size(), bands),
                  Radiance(TermsOf(full, light, times, where), times.size(), bands), bands);
}

}  // namespace phos

namespace phos {
namespace {

void CheckOptions(const StateReductionOptions& o, const std::string& where) {
  auto positive = [&](double value, const char* name) {
    if (!(std::isfinite(value) && value > 0))
      ThrowUserError(where, name, "expected a finite number > 0, got " + FormatDouble(value));
  };
  positive(o.span_s, "span_s");
  positive(o.dt_s, "dt_s");
  positive(o.tolerance, "tolerance");
  if (!(o.margin > 0 && o.margin <= 1))
    ThrowUserError(where, "margin", "expected a number in (0, 1], got " + FormatDouble(o.margin));
  if (o.states && *o.states < 1)
    ThrowUserError(where, "states", "expected 1 or more, got " + std::to_string(*o.states));
  if (o.points_per_decade < 1) ThrowUserError(where, "points_per_decade", "expected 1 or more");
}

Search MakeSearch(const Material& material, const IrradianceSchedule& schedule, std::vector<double> times,
                  const std::string& where) {
  Search s;
  s.light = LightingOf(schedule, material.band_count());
  s.times = std::move(times);
  s.bands = material.band_count();
  s.L_full = Radiance(TermsOf(material, s.light, s.times, where), s.times.size(), s.bands);
  for (std::size_t t = 0; t < s.times.size(); ++t) {
    double total = 0;
    for (int b = 0; b < s.bands; ++b) total += s.L_full[t * s.bands + b];
    const double inv = total > 0 ? 1 / total : 0.0;
    s.inv_total.push_back(std::isfinite(inv) ? inv : 0.0);
  }
  return s;
}

Material WithStates(const Material& material, const std::vector<Term>& terms) {
  Material reduced = material;
  reduced.states.clear();
  for (const Term& term : terms) reduced.states.push_back(term.state);
  return reduced;
}

}  // namespace

// Why this method. Eq. 8.2 makes the radiance a sum over states of
// kr_i r_i(t) Lambda_i, and Eq. 8.1 gives each r_i(t) in closed form under
// piecewise-constant light, so any candidate material is scored exactly at
// any time without integrating. Two states close in kr glow alike over a
// span they both outlast or that outlasts both, so merging neighbours in kr
// loses little; a state that decays within a frame, or emits little, can go
// when its share is below the tolerance. Greedy is not optimal, but each
// round keeps the best candidate, and the whole path (n - 1 rounds) costs
// about n^2 candidate scorings on a grid of a few hundred times.
StateReduction ReduceStates(const Material& material, const IrradianceSchedule& schedule,
                            const StateReductionOptions& options, const std::string& where) {
  CheckOptions(options, where);
  const Search search = MakeSearch(material, schedule,
                                   SwitchGrid(LightingOf(schedule, material.band_count()), options.span_s, options.dt_s,
                                              options.points_per_decade, 0.0),
                                   where);
  const Search check =
      MakeSearch(material, schedule,
                 SwitchGrid(search.light, options.span_s, options.dt_s, 3 * options.points_per_decade, 0.5), where);
  std::vector<Term> terms = TermsOf(material, search.light, search.times, where);
  std::stable_sort(terms.begin(), terms.end(), [](const Term& x, const Term& y) { return x.state.kr < y.state.kr; });

  // The greedy path: path[k - 1] has k states.
  const int n = material.state_count();
  const int last = options.states ? std::min(*options.states, n) : 1;
  std::vector<std::vector<Term>> path(static_cast<std::size_t>(n));
  path[n - 1] = terms;
  for (int k = n - 1; k >= last; --k) {
    double error = 0;
    path[k - 1] = BestNext(search, path[k], error);
  }
  auto result = [&](int k) {
    const Material reduced = WithStates(material, path[k - 1]);
    const std::vector<Term> on_check = TermsOf(reduced, check.light, check.times, where);
    const double error =
        std::max(MaxError(Radiance(path[k - 1], search.times.size(), search.bands), search.L_full, search.bands),
                 MaxError(Radiance(on_check, check.times.size(), check.bands), check.L_full, check.bands));
    return StateReduction{reduced, n, k, error};
  };
  if (options.states) return result(last);
  for (int k = 1; k < n; ++k) {
    StateReduction r = result(k);
    if (r.max_error <= options.margin * options.tolerance) return r;
  }
  return StateReduction{material, n, n, 0.0};
}

}  // namespace phos
