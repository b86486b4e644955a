#include "phos/fit/decay_map_file.h"

#include <algorithm>
#include <cmath>

#include "phos/util/error.h"

namespace phos::fit {

std::vector<std::string> DecayMapChannelNames(const std::vector<std::string>& camera_channels, bool two_states) {
  std::vector<std::string> names = {kDecayMapKr};
  for (const std::string& c : camera_channels) names.push_back(kDecayMapAmplitude + c);
  for (const std::string& c : camera_channels) names.push_back(kDecayMapBackground + c);
  names.push_back(kDecayMapRms);
  if (two_states) {
    names.push_back(kDecayMapKr2);
    for (const std::string& c : camera_channels) names.push_back(kDecayMapAmplitude2 + c);
  }
  return names;
}

void DecayMapCharge::Annotate(OIIO::ImageSpec& spec) const {
  if (!recorded()) return;
  spec.attribute("phos:charge_s", charge_s);
  spec.attribute("phos:charge_band_irradiance",
                 OIIO::TypeDesc(OIIO::TypeDesc::FLOAT, static_cast<int>(band_irradiance.size())),
                 band_irradiance.data());
}

DecayMapCharge DecayMapCharge::FromSpec(const OIIO::ImageSpec& spec, const std::string& where, const std::string& field,
                                        const std::string& subject) {
  DecayMapCharge charge;
  const OIIO::ParamValue* irradiance = spec.find_attribute("phos:charge_band_irradiance");
  if (!irradiance) return charge;
  if (irradiance->type().basetype != OIIO::TypeDesc::FLOAT)
    ThrowUserError(where, field, subject + "has a phos:charge_band_irradiance that is not floats");
  const float* values = static_cast<const float*>(irradiance->data());
  // All its floats: OpenEXR keeps an array of 2, 3 (or 4, 9, 16) floats as
  // one vector (or matrix), of one element of that many values.
  charge.band_irradiance.assign(values, values + irradiance->type().basevalues());
  charge.charge_s = spec.get_float_attribute("phos:charge_s", 0.0f);
  const bool valid = std::all_of(charge.band_irradiance.begin(), charge.band_irradiance.end(),
                                 [](float E) { return std::isfinite(E) && E >= 0; });
  if (!valid || !(charge.charge_s > 0) || !std::isfinite(charge.charge_s))
    ThrowUserError(where, field,
                   subject +
                       "records a charge that is not finite and positive (phos:charge_s, "
                       "phos:charge_band_irradiance)");
  return charge;
}

}  // namespace phos::fit
