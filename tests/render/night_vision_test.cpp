// The night-vision post-process (Thompson et al. 2002): what it must keep and
// what it must change.

#include <gtest/gtest.h>

#include <cmath>

#include "phos/render/night_vision.h"

namespace phos::render {
namespace {

// A flat-spectrum image: value v in every band, its linear sRGB from the renderer's own conversion.
struct Pair {
  Image bands, rgb;
};
Pair Flat(int w, int h, float v, bool step_edge = false) {
  Pair p{Image(w, h, 8), Image()};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int b = 0; b < 8; ++b) p.bands.at(x, y)[b] = (step_edge && x >= w / 2) ? 2 * v : v;
  p.rgb = BandsToLinearSrgb(p.bands, SpectralGrid::Paper());
  return p;
}

TEST(NightVision, ScotopicLuminosityPeaksNear507nm) {
  EXPECT_NEAR(ScotopicLuminosity(503), 0.992, 1e-12);
  EXPECT_GT(ScotopicLuminosity(507), 0.98);
  EXPECT_LT(ScotopicLuminosity(650), 0.05);  // rods are blind to red
  EXPECT_LT(ScotopicLuminosity(400), ScotopicLuminosity(450));
}

TEST(NightVision, BrightScenesAreLeftAsTheyAre) {
  const Pair p = Flat(16, 16, 1.0f, true);
  NightVisionOptions options;
  options.cd_per_unit = 100;  // Y = 1 is 100 cd/m^2: photopic everywhere
  const Image out = NightVision(p.bands, p.rgb, SpectralGrid::Paper(), options);
  for (std::size_t i = 0; i < out.pixels.size(); ++i) EXPECT_FLOAT_EQ(out.pixels[i], p.rgb.pixels[i]);
}

TEST(NightVision, DarkScenesTurnBlueGreyAndKeepTheirMeanBrightness) {
  const Pair p = Flat(32, 32, 0.5f);
  NightVisionOptions options;
  options.cd_per_unit = 1e-4;  // fully scotopic
  options.noise_sigma = 0;
  const Image out = NightVision(p.bands, p.rgb, SpectralGrid::Paper(), options);
  double r = 0, b = 0, Y = 0;
  for (std::size_t q = 0; q < out.pixels.size() / 3; ++q) {
    r += out.pixels[3 * q];
    b += out.pixels[3 * q + 2];
    Y += 0.2126 * out.pixels[3 * q] + 0.7152 * out.pixels[3 * q + 1] + 0.0722 * out.pixels[3 * q + 2];
  }
  EXPECT_GT(b, 1.5 * r);                  // blue shift
  EXPECT_NEAR(Y / (32 * 32), 0.5, 0.02);  // a flat spectrum has V = Y
}

TEST(NightVision, EdgeTermBoostsFaintEdgesAndNoiseIsSeeded) {
  const Pair p = Flat(32, 8, 0.05f, true);  // a faint step: detail well below 1
  NightVisionOptions options;
  options.cd_per_unit = 1e-4;
  options.noise_sigma = 0;
  options.acuity_sigma_px = 0;  // isolate the edge term
  options.gamma = 1.0;
  const Image linear = NightVision(p.bands, p.rgb, SpectralGrid::Paper(), options);
  options.gamma = 2.0;
  const Image boosted = NightVision(p.bands, p.rgb, SpectralGrid::Paper(), options);
  // Across the step, sign(d)|d|^(1/2) > |d| for |d| < 1: a higher contrast.
  const double contrast_linear = linear.at(17, 4)[1] - linear.at(14, 4)[1];
  const double contrast_boosted = boosted.at(17, 4)[1] - boosted.at(14, 4)[1];
  EXPECT_GT(contrast_linear, 0);
  EXPECT_GT(contrast_boosted, 1.5 * contrast_linear);
  // Far from the edge the detail vanishes and gamma changes nothing.
  EXPECT_NEAR(boosted.at(1, 4)[1], linear.at(1, 4)[1], 1e-3);

  options.noise_sigma = 0.05;
  options.seed = 9;
  const Image a = NightVision(p.bands, p.rgb, SpectralGrid::Paper(), options);
  const Image b = NightVision(p.bands, p.rgb, SpectralGrid::Paper(), options);
  options.seed = 10;
  const Image c = NightVision(p.bands, p.rgb, SpectralGrid::Paper(), options);
  EXPECT_EQ(a.pixels, b.pixels);
  EXPECT_NE(a.pixels, c.pixels);
}

}  // namespace
}  // namespace phos::render
