#pragma once
// How a dark scene looks to a dark-adapted eye: the spatial post-process of
// Thompson, Shirley and Ferwerda, "A Spatial Post-Processing Algorithm for
// Images of Night Scenes" (2002). Glowing paint is seen at mesopic and
// scotopic levels, where rods take over: colours fade and shift to blue,
// acuity drops, and the image is grainy.
//
//  - Blue shift: per pixel, the rods' share s (0 photopic .. 1 scotopic) from
//    the photopic luminance in cd/m^2 (mesopic between 0.001 and 3 cd/m^2,
//    linear in log luminance); the rod image is the scotopic luminance V
//    (CIE 1951 V'(lambda), from the bands) drawn in the bluish grey of
//    chromaticity (0.25, 0.25), mixed with the cone image by s.
//  - Loss of acuity: the rod image is blurred by a Gaussian of
//    acuity_sigma_px * s.
//  - Edges: the detail d = blurred - G(blurred) is put back as
//    sign(d) |d|^(1/gamma) (gamma > 1 boosts faint edges, as in the paper).
//  - Noise: zero-mean Gaussian of noise_sigma * sqrt(signal) (display units,
//    like photon noise) on the rod image, seeded: a sequence gets a new
//    pattern per frame from its seed.

#include <cstdint>

#include "phos/model/spectral.h"
#include "phos/render/renderer.h"

namespace phos::render {

struct NightVisionOptions {
  double cd_per_unit = 0.01;  // photopic luminance (cd/m^2) of radiance Y = 1 in the scene's units
  double exposure = 1.0;      // display scale, as for the PNG
  double acuity_sigma_px = 2.0;
  double gamma = 1.6;
  double noise_sigma = 0.05;
  std::uint64_t seed = 1;
};

// CIE 1951 scotopic luminosity V'(lambda), the Gaussian approximation
// 0.992 exp(-321.9 (lambda_um - 0.503)^2); peak 1 near 507 nm.
double ScotopicLuminosity(double wavelength_nm);

// Display-referred linear sRGB (multiply-then-clamp ready) for bands and
// their photopic linear sRGB.
Image NightVision(const Image& bands, const Image& rgb, const SpectralGrid& grid, const NightVisionOptions& options);

}  // namespace phos::render
