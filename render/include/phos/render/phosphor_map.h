#pragma once
// A phosphor that varies across a surface as it was measured (Sec. 8.5:
// parameters "per material or, if spatial variation is desired, in
// textures"): the decay map `phos fit map` writes (decay-map.exr, channels
// kr, amplitude.<channel>, and with --states 2 kr2, amplitude2.<channel>)
// laid over an object's UV map (Object::phosphor_map).
//
// A decay map measures what a decay after the lab's charge shows: per pixel,
// each state's rate kr_i and its amplitude a_i, the emitted radiance at
// light-off, Lambda_i kr_i r_i (Eq. 8.2) seen through the camera, where r_i
// is the level the lab's charge left (Eq. 8.1 from r = 0 under the charge
// light for charge_s: r_i = a / (a + kr_i) (1 - e^{-(a + kr_i) charge_s}),
// a = sum_b ke_i[b] E_b). It does not measure the charge rates ke or the
// emission spectra, and its amplitudes are in camera DN/s, not radiance.
// So the object's material gives those, and its level: texel j's state i
// decays at the map's kr_i and emits the material's Lambda_i[b] kr_i times
//     s_i(j) = (a_i(j) / r_i(j)) / median over the map's pixels of (a_i / r_i),
// its glow at a full charge relative to the map's typical pixel, r_i(j)
// from the map's own kr_i(j) with the material's ke. A map that records no
// charge (phos:charge_band_irradiance) is taken as charged to r = 1. A map
// that is the same everywhere, at the material's rates, renders as the
// material does.

#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

#include "phos/model/batch.h"

namespace phos::render {

struct PhosphorMap {
  std::filesystem::path file;
  int width = 0, height = 0;
  int states = 1;  // 1, or 2 for a map with kr2 (then state 0 is the slow one, `kr`)
  // Per state and pixel, [i * width * height + y * width + x], y from the
  // image's top row: the state's rate (1/s; NaN where it does not decay:
  // a pixel without a decay, or one where one state sufficed for state 1)
  // and its amplitude, summed over the camera's channels (0 where NaN).
  std::vector<float> kr_per_s, amplitude_dn_per_s;
  std::size_t pixels_with_decay = 0;
  // The session's charge (phos:charge_s, phos:charge_band_irradiance): the
  // charge light's band irradiance in the material's units. Empty: none recorded.
  double charge_s = 0;
  std::vector<double> charge_band_irradiance;

  std::size_t pixel_count() const { return static_cast<std::size_t>(width) * height; }
  bool Decays(std::size_t pixel) const { return kr_per_s[pixel] == kr_per_s[pixel]; }  // not NaN
  // The pixel under UV point (u, v) (clamped to the image); v_up: the mesh's
  // v = 0 is the image's bottom row (OBJ), else its top row (glTF).
  std::size_t PixelAt(float u, float v, bool v_up) const;
};

// Reads a decay map. A file OpenImageIO cannot read, a map without kr or
// amplitude channels, a tile of one (`phos fit map --tile`: merge it first)
// or a map where no pixel decays is a UserError naming `where` and `field`.
PhosphorMap ReadPhosphorMap(const std::filesystem::path& file, const std::string& where, const std::string& field);

// The per-point parameters of texels over map pixels `pixels` (one per
// texel): c, compiled from the object's `material` (its unknown ke already
// settled by the scene's policy), gains kr_per_point and emission_scale, the
// s_i(j) above. The material's states are matched to the map's by rate, the
// slower to `kr`; a state the map leaves NaN at a pixel (the fast one where
// one state sufficed) keeps the material's kr and emits nothing there. A
// charge the material cannot take (an unknown ke in a band the charge light
// reaches, no excitation at all, another band count) is a UserError naming `where`.
void ApplyPhosphorMap(const PhosphorMap& map, const Material& material, const std::vector<std::uint32_t>& pixels,
                      BatchCoefficients<float>& c, const std::string& where);

}  // namespace phos::render
