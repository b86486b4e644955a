#pragma once
// A light of a physical scene ("units": "physical", docs/formats.md) given
// in radiometric (W) or photometric (lm, cd, lx) terms, converted through
// its spectrum onto the scene's bands (docs/render.md, "Physical units").
//
// Radiometric: the value is the integral of the spectrum over all
// wavelengths, so the bands hold value * (band integral / total); light
// outside the grid's bands is lost, as a band radiance cannot hold it.
// Photometric: the bands are scaled so that sum_b w_b X_b equals the value,
// w_b = PhotopicBandEfficacy (phos/model/photometry.h: K_m = 683 lm/W times
// the band mean of the CIE 1931 V). A render's Y, the same band sum
// (renderer.h, WriteExr), then reads a light's own value back exactly; the
// exact spectral integral K_m ∫ S V differs by the band approximation
// (998.9 lx for 1000 lx of D65 on the paper's 8-band grid, 971 for F11,
// about 5x for a 405 nm LED), which a render could not show anyway.

#include <string>
#include <vector>

#include "phos/model/spectral.h"
#include "phos/render/scene.h"
#include "phos/util/json.h"

namespace phos::render {

// What a light's value measures: a point or spot light's intensity
// (W/sr, cd), a directional or sheet light's irradiance at normal incidence
// (W/m², lx), an area light's or the sky's radiance (W/(sr m²), cd/m²).
enum class LightQuantity { kIntensity, kIrradiance, kRadiance };
LightQuantity QuantityOf(Light::Kind kind);

// A light's spectrum on the bands (any scale) and its integral over all
// wavelengths (1 for the normalized shapes; the band sum for "bands").
struct LightSpectrum {
  std::vector<double> bands;
  double total = 1.0;
};

// The one physical value a light entry gives: `key` as written, the value
// in its own unit, and the factor to the quantity (a point light's power_w
// or flux_lm: 1 / (4 pi), isotropic).
struct PhysicalValue {
  std::string key;
  double value = 0;
  bool photometric = false;
  double to_quantity = 1.0;
};

// Every key that gives a light in physical units, for RejectUnknownKeys
// lists and for refusing them in a relative scene.
#define PHOS_PHYSICAL_LIGHT_KEYS                                                                                    \
  "intensity_w_sr", "intensity_cd", "power_w", "flux_lm", "irradiance_w_m2", "illuminance_lux", "radiance_w_sr_m2", \
      "luminance_cd_m2"

// In a relative scene: a physical key in `l` fails at that key, saying the
// scene is relative. In a physical scene: "intensity" (`relative_key`) fails.
void RequireUnitsOfScene(const JsonField& l, Units scene_units, const char* relative_key);

// The value of entry `l` for a light of `quantity` (`point`: a point light,
// which may give power_w or flux_lm): exactly one of its keys, positive and
// finite; none, two, or a key of another quantity fail at the field.
PhysicalValue ReadPhysicalValue(const JsonField& l, LightQuantity quantity, bool point);

// The band values (W/sr, W/m² or W/(sr m²) per band) of `value` through
// `spectrum` on `grid`. A photometric value of a spectrum V does not see,
// or bands past kMaxIrradiance, fail at l[value.key].
std::vector<double> PhysicalBands(const JsonField& l, const PhysicalValue& value, const LightSpectrum& spectrum,
                                  const SpectralGrid& grid);

}  // namespace phos::render
