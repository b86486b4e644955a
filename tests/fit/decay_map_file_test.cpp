// decay-map.exr's format owner (fit/decay_map_file.h): the channel names in
// the file's order, and the charge a header records, through a real EXR
// written and read by OpenImageIO.

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include <OpenImageIO/imageio.h>

#include "phos/fit/decay_map_file.h"
#include "phos/util/error.h"
#include "test_util.h"

namespace phos::fit {
namespace {

using phos::testing::TempDir;

TEST(DecayMapFile, ChannelNamesAreInTheFilesOrder) {
  EXPECT_EQ(DecayMapChannelNames({"R", "G", "B"}, false),
            (std::vector<std::string>{"kr", "amplitude.R", "amplitude.G", "amplitude.B", "background.R", "background.G",
                                      "background.B", "rms"}));
  EXPECT_EQ(DecayMapChannelNames({"Y"}, true),
            (std::vector<std::string>{"kr", "amplitude.Y", "background.Y", "rms", "kr2", "amplitude2.Y"}));
}

// A 2 x 2 map's header through a file: `annotate` writes into its spec.
OIIO::ImageSpec ThroughAFile(const TempDir& dir, const std::function<void(OIIO::ImageSpec&)>& annotate) {
  const std::string file = (dir / "map.exr").string();
  OIIO::ImageSpec spec(2, 2, 1, OIIO::TypeDesc::FLOAT);
  spec.channelnames = {"kr"};
  annotate(spec);
  const float pixels[4] = {0.1f, 0.2f, 0.3f, 0.4f};
  auto out = OIIO::ImageOutput::create(file);
  EXPECT_TRUE(out && out->open(file, spec) && out->write_image(OIIO::TypeDesc::FLOAT, pixels) && out->close());
  auto in = OIIO::ImageInput::open(file);
  EXPECT_TRUE(in);
  return in ? in->spec() : OIIO::ImageSpec();
}

TEST(DecayMapFile, TheChargeRoundTripsThroughAHeaderAndNoneIsNotRecorded) {
  TempDir dir;
  DecayMapCharge charge;
  charge.charge_s = 1800;
  // Of any number of bands: OpenEXR keeps 2, 3, 4, 9 and 16 floats as a
  // vector or a matrix, one element of that many values.
  for (int bands : {1, 2, 3, 4, 8, 9, 16, 40}) {
    charge.band_irradiance.clear();
    for (int b = 0; b < bands; ++b) charge.band_irradiance.push_back(0.25f * static_cast<float>(b));
    const DecayMapCharge read = DecayMapCharge::FromSpec(
        ThroughAFile(dir, [&](OIIO::ImageSpec& s) { charge.Annotate(s); }), "map.exr", "", "");
    EXPECT_TRUE(read.recorded());
    EXPECT_EQ(read.charge_s, 1800.0f);
    EXPECT_EQ(read.band_irradiance, charge.band_irradiance) << bands << " bands";
  }
  // Not recorded: nothing written, nothing read.
  const OIIO::ImageSpec bare = ThroughAFile(dir, [&](OIIO::ImageSpec& s) { DecayMapCharge().Annotate(s); });
  EXPECT_EQ(bare.find_attribute("phos:charge_s"), nullptr);
  EXPECT_FALSE(DecayMapCharge::FromSpec(bare, "map.exr", "", "").recorded());
}

TEST(DecayMapFile, AChargeThatIsNotFloatsOrNotFiniteAndPositiveIsOneLine) {
  TempDir dir;
  auto error_of = [&](const std::function<void(OIIO::ImageSpec&)>& annotate) {
    const OIIO::ImageSpec spec = ThroughAFile(dir, annotate);
    return phos::testing::ErrorOfType<UserError>(
        [&] { DecayMapCharge::FromSpec(spec, "scene.json", "objects[0].phosphor_map", "map 'm.exr' "); });
  };
  const int ints[2] = {1, 2};
  const std::string not_floats = error_of([&](OIIO::ImageSpec& s) {
    s.attribute("phos:charge_s", 10.0f);
    s.attribute("phos:charge_band_irradiance", OIIO::TypeDesc(OIIO::TypeDesc::INT, 2), ints);
  });
  EXPECT_NE(not_floats.find("scene.json: objects[0].phosphor_map: map 'm.exr' has a phos:charge_band_irradiance "
                            "that is not floats"),
            std::string::npos)
      << not_floats;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  struct Bad {
    float charge_s;
    float irradiance;
  };
  for (const Bad bad : {Bad{10, -1}, Bad{10, nan}, Bad{0, 1}, Bad{-5, 1}, Bad{nan, 1}}) {
    const std::string error = error_of([&](OIIO::ImageSpec& s) {
      DecayMapCharge charge;
      charge.charge_s = bad.charge_s;
      charge.band_irradiance = {1, bad.irradiance};
      charge.Annotate(s);
    });
    EXPECT_NE(error.find("map 'm.exr' records a charge that is not finite and positive"), std::string::npos)
        << bad.charge_s << " " << bad.irradiance << ": " << error;
    EXPECT_EQ(error.find('\n'), std::string::npos);
  }
}

}  // namespace
}  // namespace phos::fit
