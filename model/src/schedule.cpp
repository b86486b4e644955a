#include "phos/model/schedule.h"

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

std::vector<double> ExcitationRates(const Material& material, const std::vector<double>& E, const std::string& where,
                                    const std::string& remedy) {
  PHOS_CHECK(static_cast<int>(E.size()) == material.band_count());
  std::vector<double> a(material.states.size(), 0.0);
  for (size_t i = 0; i < material.states.size(); ++i) {
    const ExcitedState& s = material.states[i];
    for (int b = 0; b < material.band_count(); ++b) {
      if (E[b] == 0.0) continue;
      if (!s.ke_known(b))
        ThrowUserError(where, "states[" + std::to_string(i) + "].ke[" + std::to_string(b) + "]",
                       "unknown (not measured) for band " + material.bands.BandName(b) + ": material '" +
                           material.name + "' cannot be charged by irradiance " + FormatDouble(E[b]) +
                           " there; " + remedy);
      a[i] += *s.ke[b] * E[b];
    }
  }
  return a;
}

}  // namespace phos
