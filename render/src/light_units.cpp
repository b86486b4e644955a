#include "phos/render/light_units.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "phos/model/material.h"
#include "phos/model/photometry.h"
#include "phos/util/format.h"
#include "phos/util/math.h"

namespace phos::render {
namespace {

// The keys of a quantity: radiometric first, then photometric.
struct QuantityKeys {
  const char* radiometric;
  const char* photometric;
  const char* what;
};
QuantityKeys KeysOf(LightQuantity quantity) {
  switch (quantity) {
    case LightQuantity::kIntensity: return {"intensity_w_sr", "intensity_cd", "an intensity"};
    case LightQuantity::kIrradiance: return {"irradiance_w_m2", "illuminance_lux", "an irradiance"};
    case LightQuantity::kRadiance: break;
  }
  return {"radiance_w_sr_m2", "luminance_cd_m2", "a radiance"};
}

constexpr const char* kPhysicalKeys[] = {PHOS_PHYSICAL_LIGHT_KEYS};

}  // namespace

LightQuantity QuantityOf(Light::Kind kind) {
  switch (kind) {
    case Light::Kind::kPoint:
    case Light::Kind::kSpot: return LightQuantity::kIntensity;
    case Light::Kind::kDirectional:
    case Light::Kind::kSheet: return LightQuantity::kIrradiance;
    case Light::Kind::kQuad:
    case Light::Kind::kDisk:
    case Light::Kind::kMesh: break;
  }
  return LightQuantity::kRadiance;
}

void RequireUnitsOfScene(const JsonField& l, Units scene_units, const char* relative_key) {
  if (scene_units == Units::kPhysical) {
    if (l.Has(relative_key))
      l[relative_key].Fail(
          "the scene is physical (\"units\": \"physical\"): give the light in W or in lm, cd, lx (docs/render.md, "
          "\"Physical units\"), not a relative '" +
          std::string(relative_key) + "'");
    return;
  }
  for (const char* key : kPhysicalKeys)
    if (l.Has(key))
      l[key].Fail("the scene is relative: a light in W or in lm, cd, lx needs \"units\": \"physical\" in the scene");
}

PhysicalValue ReadPhysicalValue(const JsonField& l, LightQuantity quantity, bool point) {
  const QuantityKeys keys = KeysOf(quantity);
  std::vector<PhysicalValue> given;
  auto take = [&](const char* key, bool photometric, double to_quantity) {
    if (!l.Has(key)) return;
    const JsonField f = l[key];
    const double value = f.Number();
    if (!(value > 0 && std::isfinite(value)))
      f.Fail("expected a positive finite number, got " + DescribeJson(f.value()));
    given.push_back({key, value, photometric, to_quantity});
  };
  take(keys.radiometric, false, 1.0);
  take(keys.photometric, true, 1.0);
  if (point) {
    // An isotropic point light of power P has intensity P / (4 pi) in every direction.
    take("power_w", false, 1 / (4 * kPi));
    take("flux_lm", true, 1 / (4 * kPi));
  }
  const std::string choices =
      std::string(keys.radiometric) + " or " + keys.photometric + (point ? " (or power_w or flux_lm)" : "");
  for (const char* key : kPhysicalKeys)
    if (l.Has(key) && std::none_of(given.begin(), given.end(), [&](const PhysicalValue& v) { return v.key == key; }))
      l[key].Fail("this light gives " + std::string(keys.what) + ": " + choices);
  if (given.empty()) l.Fail("a light of a physical scene gives " + std::string(keys.what) + ": " + choices);
  if (given.size() > 1) l[given[1].key].Fail("give one of " + choices + ", not both '" + given[0].key + "' and it");
  return given.front();
}

std::vector<double> PhysicalBands(const JsonField& l, const PhysicalValue& value, const LightSpectrum& spectrum,
                                  const SpectralGrid& grid) {
  const JsonField f = l[value.key];
  double per_unit_spectrum = spectrum.total;  // what one unit of the spectrum measures
  if (value.photometric) {
    const std::vector<double> w = PhotopicBandEfficacy(grid);
    per_unit_spectrum = std::inner_product(w.begin(), w.end(), spectrum.bands.begin(), 0.0);
    if (!(per_unit_spectrum > 0))
      f.Fail(
          "the light's spectrum has no light the eye sees (V(lambda) is 0 in its bands): a photometric value "
          "cannot set it; give it in W");
  }
  if (!(per_unit_spectrum > 0)) f.Fail("the light's spectrum is zero: it gives no light");
  std::vector<double> bands = spectrum.bands;
  const double scale = value.value * value.to_quantity / per_unit_spectrum;
  for (double& x : bands) {
    x *= scale;
    if (!(x <= kMaxIrradiance))
      f.Fail("gives " + FormatDouble(x) + " in a band, more than the limit of " + FormatDouble(kMaxIrradiance));
  }
  return bands;
}

}  // namespace phos::render
