#pragma once
// RGB albedo (glTF baseColorFactor and baseColorTexture, OBJ/MTL Kd and
// map_Kd) to the scene's bands. Sec. 8.5 keeps the parameters "per material
// or, if spatial variation is desired, in textures"; textures are RGB, the
// renderer spectral, so each texel needs a reflectance spectrum.
//
// The upsampling is linear: albedo_b = sum_c basis_{b,c} rgb_c with basis
// spectra that are non-negative and sum to 1 at every wavelength (a
// partition of unity). A primary's basis at a wavelength is its share of the
// clipped linear-sRGB colour matching functions there (the CIE 1931
// functions of util/colour.h through the XYZ to sRGB matrix, negative lobes
// cut), averaged over the band. So, by construction: white (1, 1, 1) is 1 in
// every band, every band lies between the smallest and the largest of r, g,
// b (so in [0, 1]), and upsampling commutes with the texture filter (it is
// linear), so a mip-mapped RGB texture needs no spectral copy. docs/render.md
// ("Textures") compares it with Jakob and Hanika 2019 and Smits 1999.

#include <array>
#include <cmath>
#include <vector>

#include "phos/model/spectral.h"

namespace phos::render {

class RgbToBands {
 public:
  explicit RgbToBands(const SpectralGrid& bands);
  int band_count() const { return static_cast<int>(red_.size()); }
  // Linear RGB in [0, 1] (clamped) to albedo per band, written to bands[0, band_count).
  void Albedo(const float rgb[3], float* bands) const;
  std::vector<double> Albedo(const std::array<double, 3>& rgb) const;

 private:
  std::vector<float> red_, blue_;  // per band; green is the rest
};

// The sRGB transfer function's inverse (IEC 61966-2-1): an 8-bit texture's
// encoded value in [0, 1] to linear.
inline float SrgbToLinear(float encoded) {
  return encoded <= 0.04045f ? encoded / 12.92f : std::pow((encoded + 0.055f) / 1.055f, 2.4f);
}

}  // namespace phos::render
