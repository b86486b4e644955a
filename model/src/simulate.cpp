#include "phos/model/simulate.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos {

bool SameTime(double x, double y) {
  return std::fabs(x - y) <= 64 * std::numeric_limits<double>::epsilon() * std::max(std::fabs(x), std::fabs(y));
}

std::vector<double> EmittedRadiance(const Material& material, const double* r) {
  std::vector<double> L(static_cast<std::size_t>(material.band_count()), 0.0);
  for (int i = 0; i < material.state_count(); ++i) {
    const ExcitedState& s = material.states[i];
    for (int b = 0; b < material.band_count(); ++b) L[b] += s.Lambda[b] * s.kr * r[i];  // Eq. 8.2
  }
  return L;
}

namespace {

// Checks an explicit integrator against its limits for the largest step it
// will take in each phase; the paper's Euler is kept, but never silently wrong.
void CheckStability(const Material& material, const IrradianceSchedule& schedule,
                    const std::vector<std::vector<double>>& rates, const SimulationOptions& options,
                    std::vector<std::string>* warnings) {
  const Integrator integrator = options.integrator;
  const double stable = StabilityLimitHk(integrator), monotone = MonotoneLimitHk(integrator);
  if (!std::isfinite(stable)) return;
  for (std::size_t p = 0; p < schedule.phases().size(); ++p) {
    const IrradiancePhase& phase = schedule.phases()[p];
    const double h = std::min(options.dt_s, phase.duration_s);
    for (int i = 0; i < material.state_count(); ++i) {
      const double k = rates[p][i] + material.states[i].kr;
      const double hk = h * k;
      if (hk <= monotone) continue;
      const std::string what = std::string(IntegratorName(integrator)) + " with --dt " + FormatDouble(options.dt_s) +
                               ": h*k = " + FormatShort(hk) + " for state " + std::to_string(i + 1) + " during '" +
                               phase.label + "' (k = " + FormatShort(k) + "/s)";
      const std::string fix = "use --integrator exact, or --dt <= " + FormatDouble(RoundDownSignificant(monotone / k));
      if (hk > stable) {
        std::string message =
            what + " exceeds the stability limit " + FormatShort(stable) + ": the result diverges; " + fix;
        if (!options.allow_unstable) ThrowUserError("", "--dt", message);
        warnings->push_back("unstable: " + message);
      } else {
        warnings->push_back("not monotone: " + what + " exceeds " + FormatShort(monotone) +
                            ": the state oscillates around equilibrium and may leave [0, 1]; " + fix);
      }
    }
  }
}

}  // namespace

SimulationResult Simulate(const Material& material, const IrradianceSchedule& schedule,
                          const SimulationOptions& options, const std::string& where) {
  if (!(options.dt_s > 0) || !std::isfinite(options.dt_s))
    ThrowUserError("", "--dt", "expected a step > 0 seconds, got " + FormatDouble(options.dt_s));
  const int nc = material.state_count(), nb = material.band_count();
  for (const IrradiancePhase& phase : schedule.phases()) {
    PHOS_CHECK(static_cast<int>(phase.E.size()) == nb);
    for (double e : phase.E)
      if (!(e >= 0) || !std::isfinite(e))
        ThrowUserError("", "--irradiance", "expected finite values >= 0, got " + FormatDouble(e));
  }
  const double total = schedule.total_s();
  const double sample_count_real = std::floor(total / options.dt_s * (1 + 1e-12)) + 1;
  if (sample_count_real > static_cast<double>(options.max_samples))
    ThrowUserError("", "--dt",
                   FormatDouble(options.dt_s) + " s over " + FormatDouble(total) + " s gives " +
                       FormatDouble(sample_count_real) + " samples, more than the limit of " +
                       std::to_string(options.max_samples) + "; choose a larger --dt");
  const auto samples = static_cast<std::size_t>(sample_count_real);

  // a_i per phase (UserError if a lit band has unknown ke).
  std::vector<std::vector<double>> rates;
  for (const IrradiancePhase& phase : schedule.phases()) rates.push_back(ExcitationRates(material, phase.E, where));

  SimulationResult result;
  result.nc = nc;
  result.nb = nb;
  CheckStability(material, schedule, rates, options, &result.warnings);

  std::vector<double> r(static_cast<std::size_t>(nc), 0.0);
  if (!options.r0.empty()) {
    PHOS_CHECK(static_cast<int>(options.r0.size()) == nc);
    r = options.r0;
  }
  std::vector<long double> r_long(r.begin(), r.end());  // the reference keeps its extra digits between steps

  result.t_s.reserve(samples);
  result.r.reserve(samples * nc);
  result.L.reserve(samples * nb);
  auto record = [&](double t) {
    result.t_s.push_back(t);
    result.r.insert(result.r.end(), r.begin(), r.end());
    std::vector<double> L = EmittedRadiance(material, r.data());
    result.L.insert(result.L.end(), L.begin(), L.end());
  };

  // Phase boundaries in absolute time.
  std::vector<double> phase_end;
  double acc = 0;
  for (const IrradiancePhase& phase : schedule.phases()) phase_end.push_back(acc += phase.duration_s);

  record(0.0);
  double t = 0.0;
  std::size_t phase = 0;
  ReferenceStats reference_stats;
  for (std::size_t m = 1; m < samples; ++m) {
    const double target = static_cast<double>(m) * options.dt_s;
    while (t < target) {
      // A phase is over when t has reached its end; a boundary within
      // rounding of a sample is the sample (SameTime), so no step of a few
      // ulps is taken. Only rounding: a phase far shorter than --dt (a
      // nanosecond flash) is stepped through whole, however short.
      while (phase + 1 < phase_end.size() && (phase_end[phase] <= t || SameTime(phase_end[phase], t))) ++phase;
      double end = target;
      // Split at the light switch. The last phase runs on to the last
      // sample, which may lie a little past the schedule's sum.
      if (phase + 1 < phase_end.size() && phase_end[phase] < target && !SameTime(phase_end[phase], target))
        end = phase_end[phase];
      const double h = end - t;
      for (int i = 0; i < nc; ++i) {
        const double a = rates[phase][i], kr = material.states[i].kr;
        switch (options.integrator) {
          case Integrator::kExact: r[i] = ExactStep(r[i], a, kr, h); break;
          case Integrator::kEuler: r[i] = EulerStep(r[i], a, kr, h); break;
          case Integrator::kRk4: r[i] = Rk4Step(r[i], a, kr, h); break;
          case Integrator::kReference:
            r_long[i] = ReferenceAdvance(r_long[i], a, kr, h, options.reference, &reference_stats);
            r[i] = static_cast<double>(r_long[i]);
            break;
        }
      }
      ++result.steps;
      t = end;
    }
    t = target;
    record(t);
  }
  if (options.integrator == Integrator::kReference) result.steps = reference_stats.accepted;
  return result;
}

}  // namespace phos
