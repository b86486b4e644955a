// "exposure": "auto" (render/exposure.h): the median glowing pixel of the
// metered frames is shown as mid-grey through the PNG's own tone map, black
// pixels are not counted, nothing glowing keeps exposure 1; the scene's
// camera.exposure takes "auto" or a number, and the frames after dark are
// those where no light and no sky is on.

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include <nlohmann/json.hpp>

#include "phos/render/exposure.h"
#include "phos/render/renderer.h"
#include "phos/render/scene.h"
#include "phos/util/error.h"
#include "phos/util/json.h"
#include "test_util.h"

namespace phos::render {
namespace {

using phos::testing::ErrorOfType;
using phos::testing::Fixture;

// A grey image (r = g = b = v, so luminance v) of the given pixel values, one row.
Image Grey(const std::vector<float>& values) {
  Image image(static_cast<int>(values.size()), 1, 3);
  for (std::size_t p = 0; p < values.size(); ++p)
    for (int k = 0; k < 3; ++k) image.pixels[3 * p + k] = values[p];
  return image;
}

double SrgbToLinear(double v) { return v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4); }

// The display luminance ToneMap gives a grey pixel of luminance v at `exposure`.
double DisplayLuminance(float v, double exposure) {
  const Image display = ToneMap(Grey({v}), exposure);
  return SrgbToLinear(display.pixels[0]);  // grey in, grey out: any channel
}

TEST(AutoExposure, ReinhardShowsTheLuminanceAsTheAskedDisplayLuminance) {
  for (double Y : {1e-9, 1e-4, 0.37, 250.0})
    for (double D : {0.05, 0.18, 0.9}) {
      const double e = ExposureShowingLuminanceAs(Y, D);
      EXPECT_NEAR(e * Y / (1 + e * Y), D, 1e-12 * D);
    }
}

TEST(AutoExposure, TheMedianGlowingPixelIsShownAsMidGrey) {
  // Nine glowing pixels 1..9 (median 5) among black ones, a NaN and an inf,
  // which say nothing about the glow and are not counted.
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  ExposureMeter meter;
  meter.Add(Grey({0, 3, 9, 0, 1, 7, nan, 5, 0, 2, 8, inf, 4, 6, 0}));
  const AutoExposure chosen = meter.Choose();
  EXPECT_EQ(chosen.glowing_pixels, 9u);
  EXPECT_EQ(chosen.metered_frames, 1u);
  EXPECT_FLOAT_EQ(chosen.metered_luminance, 5.0f);
  EXPECT_NEAR(chosen.exposure, 0.18 / 0.82 / 5, 1e-12);
  // Through the PNG's own tone map, to the float's rounding: mid-grey.
  EXPECT_NEAR(DisplayLuminance(5.0f, chosen.exposure), kMeteredDisplayLuminance, 1e-6);
  EXPECT_LT(DisplayLuminance(4.0f, chosen.exposure), kMeteredDisplayLuminance);
  EXPECT_GT(DisplayLuminance(6.0f, chosen.exposure), kMeteredDisplayLuminance);
}

TEST(AutoExposure, TheBrightestFramesMedianSetsTheSequencesExposure) {
  // A bright frame and a dim one (a glow fading): medians 0.02 (of 3
  // glowing pixels) and 0.002 (of 4: the nearest rank ceil(4 / 2) = 2nd,
  // beside a 0.1 that a pooled median would have let in), in either order.
  for (bool bright_first : {true, false}) {
    ExposureMeter meter;
    const Image bright = Grey({0.04f, 0.02f, 0.01f, 0}), dim = Grey({0.003f, 0.001f, 0.002f, 0.1f});
    meter.Add(bright_first ? bright : dim);
    meter.Add(bright_first ? dim : bright);
    const AutoExposure chosen = meter.Choose();
    EXPECT_EQ(chosen.metered_frames, 2u);
    EXPECT_EQ(chosen.glowing_pixels, 7u);
    EXPECT_FLOAT_EQ(chosen.metered_luminance, 0.02f);
    EXPECT_NEAR(DisplayLuminance(0.02f, chosen.exposure), 0.18, 1e-6);
  }
}

TEST(AutoExposure, OneMorePixelInTheDimFrameDoesNotMoveTheExposure) {
  // 500 pixels of a bright frame (0.9 to 1.1) and 499 or 501 of a dim one
  // (0.009 to 0.011): a median of the pixels pooled is a bright one in the
  // first case and a dim one in the second, 100x apart (the meter before).
  auto frame = [](int n, float level) {
    std::vector<float> values;
    for (int i = 0; i < n; ++i) values.push_back(level * (0.9f + 0.2f * static_cast<float>(i) / static_cast<float>(n)));
    return Grey(values);
  };
  ExposureMeter fewer, more;
  fewer.Add(frame(500, 1.0f));
  fewer.Add(frame(499, 0.01f));
  more.Add(frame(500, 1.0f));
  more.Add(frame(501, 0.01f));
  EXPECT_EQ(fewer.Choose().metered_luminance, more.Choose().metered_luminance);
  EXPECT_NEAR(fewer.Choose().metered_luminance, 1.0, 0.01);
}

TEST(AutoExposure, NothingGlowingKeepsExposureOne) {
  ExposureMeter meter;
  meter.Add(Grey({0, 0, 0}));
  meter.Add(Grey({0, -1e-3f, 0}));  // negative luminance is not a glow either
  const AutoExposure chosen = meter.Choose();
  EXPECT_EQ(chosen.exposure, 1.0);
  EXPECT_EQ(chosen.glowing_pixels, 0u);
  EXPECT_EQ(chosen.metered_luminance, 0.0);
  EXPECT_TRUE(std::isfinite(chosen.exposure));
  EXPECT_EQ(ExposureMeter().Choose().exposure, 1.0);  // no frame at all
}

// The Cornell fixture (its LED on from 0 to 30 s) with one change to its camera.
Scene CornellWith(const std::function<void(nlohmann::json&)>& edit) {
  nlohmann::json json = ReadJsonFile(Fixture("scenes/cornell-phosphor.json"));
  edit(json);
  return SceneFromJson(json, Fixture("scenes"), "cornell-phosphor.json");
}

TEST(AutoExposure, TheCameraTakesAutoOrANumberAndNamesTheFieldOtherwise) {
  const Scene numeric = CornellWith([](nlohmann::json& j) { j["camera"]["exposure"] = 2.5; });
  EXPECT_FALSE(numeric.camera.exposure_auto);
  EXPECT_EQ(numeric.camera.exposure, 2.5);
  const Scene automatic = CornellWith([](nlohmann::json& j) { j["camera"]["exposure"] = "auto"; });
  EXPECT_TRUE(automatic.camera.exposure_auto);
  for (const nlohmann::json& bad : {nlohmann::json("autox"), nlohmann::json(-1), nlohmann::json(2e9),
                                    nlohmann::json(true), nlohmann::json::array()}) {
    const std::string error =
        ErrorOfType<UserError>([&] { CornellWith([&](nlohmann::json& j) { j["camera"]["exposure"] = bad; }); });
    EXPECT_NE(error.find("cornell-phosphor.json: camera.exposure: expected \"auto\" or a number in [0, 1e9]"),
              std::string::npos)
        << error;
  }
}

TEST(AutoExposure, AfterDarkIsWhereNoLightAndNoSkyIsOn) {
  const Scene cornell = CornellWith([](nlohmann::json&) {});
  EXPECT_TRUE(cornell.AnyLightOnAt(0));
  EXPECT_TRUE(cornell.AnyLightOnAt(29.9));
  EXPECT_FALSE(cornell.AnyLightOnAt(30));  // the LED's off key
  EXPECT_FALSE(cornell.AnyLightOnAt(3600));
  const Scene dusk = LoadScene(Fixture("scenes/dusk-sign.json"));  // no lights, a sky dark from 60 s
  EXPECT_TRUE(dusk.AnyLightOnAt(55));                              // level 0.08: dim, but on
  EXPECT_FALSE(dusk.AnyLightOnAt(60));
}

}  // namespace
}  // namespace phos::render
