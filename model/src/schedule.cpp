#include "phos/model/schedule.h"

#include <algorithm>
#include <cmath>

#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos {

bool IrradiancePhase::dark() const {
  for (double e : E)
    if (e != 0.0) return false;
  return true;
}

IrradianceSchedule IrradianceSchedule::ChargeThenDecay(const std::vector<double>& E, double charge_s, double decay_s) {
  IrradianceSchedule schedule;
  if (charge_s > 0) schedule.Add(charge_s, E, "charge");
  if (decay_s > 0) schedule.Add(decay_s, std::vector<double>(E.size(), 0.0), "dark");
  return schedule;
}

void IrradianceSchedule::Add(double duration_s, std::vector<double> E, std::string label) {
  PHOS_CHECK(duration_s >= 0);
  phases_.push_back({duration_s, std::move(E), std::move(label)});
}

double IrradianceSchedule::total_s() const {
  double total = 0;
  for (const IrradiancePhase& p : phases_) total += p.duration_s;
  return total;
}

namespace {
// t / dt_s in frames, snapped to the grid within 1e-9 of it.
double FramesOf(double t_s, double dt_s) {
  const double frames = t_s / dt_s;
  const double nearest = std::round(frames);
  return std::fabs(frames - nearest) <= 1e-9 * std::max(1.0, nearest) ? nearest : frames;
}
}  // namespace

std::optional<long long> WholeFrames(double total_s, double dt_s) {
  const double frames = FramesOf(total_s, dt_s);
  if (frames != std::round(frames) || !(frames < 9e18)) return std::nullopt;
  return static_cast<long long>(frames);
}

std::vector<std::vector<double>> FrameIrradiance(const IrradianceSchedule& schedule, double dt_s) {
  PHOS_CHECK(dt_s > 0 && !schedule.phases().empty());
  const std::optional<long long> frames = WholeFrames(schedule.total_s(), dt_s);
  PHOS_CHECK(frames && *frames > 0);
  const std::size_t bands = schedule.phases().front().E.size();
  std::vector<std::vector<double>> E(static_cast<std::size_t>(*frames), std::vector<double>(bands, 0.0));
  double elapsed_s = 0;
  for (const IrradiancePhase& phase : schedule.phases()) {
    PHOS_CHECK(phase.E.size() == bands);
    const double begin = FramesOf(elapsed_s, dt_s);
    elapsed_s += phase.duration_s;
    const double end = std::min(FramesOf(elapsed_s, dt_s), static_cast<double>(*frames));
    if (phase.dark()) continue;
    for (auto f = static_cast<long long>(std::floor(begin)); f < *frames && static_cast<double>(f) < end; ++f) {
      // The share of frame f that this phase covers.
      const double share = std::min(end, f + 1.0) - std::max(begin, static_cast<double>(f));
      if (share <= 0) continue;
      for (std::size_t b = 0; b < bands; ++b) E[static_cast<std::size_t>(f)][b] += share * phase.E[b];
    }
  }
  return E;
}

std::vector<double> ExcitationRates(const Material& material, const std::vector<double>& E, const std::string& where,
                                    const std::string& remedy, const std::function<std::string(int band)>& charged_by) {
  PHOS_CHECK(static_cast<int>(E.size()) == material.band_count());
  std::vector<double> a(material.states.size(), 0.0);
  for (size_t i = 0; i < material.states.size(); ++i) {
    const ExcitedState& s = material.states[i];
    for (int b = 0; b < material.band_count(); ++b) {
      if (E[b] == 0.0) continue;
      if (!s.ke_known(b))
        ThrowUserError(where, "states[" + std::to_string(i) + "].ke[" + std::to_string(b) + "]",
                       "unknown (not measured) for band " + material.bands.BandName(b) + ": material '" +
                           material.name + "' cannot be charged by " +
                           (charged_by ? charged_by(b) : "irradiance " + FormatDouble(E[b])) + " there; " + remedy);
      a[i] += *s.ke[b] * E[b];
    }
  }
  return a;
}

}  // namespace phos
