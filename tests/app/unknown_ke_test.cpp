// A phosphor whose ke was not measured in a band a light reaches (every
// Table 8.1 preset under white light, a fitted material in the bands no LED
// of the lab reached): refused, naming the light and its own value in that
// band and the ways out; `phos render --unknown-ke zero` takes every such ke
// as 0, says which, and renders what "unknown_ke": "zero" on the object does.

#include <filesystem>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <string>

#include "test_util.h"

namespace phos {
namespace {

using testing::RunPhos;

// A plate of Table 8.1's green (ke measured in bands 1-3 only) under a
// directional light of irradiance 2 x values in every band, off at 5 s.
std::string WriteScene(const testing::TempDir& dir, const std::string& name, bool unknown_ke_zero) {
  nlohmann::json plate = {{"name", "plate"},
                          {"shape", {{"type", "quad"}, {"size", {1, 1}}}},
                          {"albedo", 0.5},
                          {"phosphor", testing::Fixture("materials/green.json").string()}};
  if (unknown_ke_zero) plate["unknown_ke"] = "zero";
  const nlohmann::json scene = {
      {"schema", "phos.scene/1"},
      {"name", "white-lit"},
      {"time", {{"start_s", 0}, {"end_s", 10}, {"fps", 1}}},
      {"camera", {{"position", {0, 2, 0.01}}, {"look_at", {0, 0, 0}}, {"fov_deg", 40}, {"width", 16}, {"height", 16}}},
      {"objects", {plate}},
      {"lights",
       {{{"name", "white lamp"},
         {"type", "directional"},
         {"direction", {0, -1, 0}},
         {"intensity", 2},
         {"spectrum", {{"type", "bands"}, {"values", {0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8}}}},
         {"schedule", {{{"t_s", 0}, {"level", 1}}, {{"t_s", 5}, {"level", 0}}}}}}}};
  testing::WriteText(dir / name, scene.dump());
  return (dir / name).string();
}

TEST(UnknownKe, IsRefusedNamingTheLightsValueThereAndTheOption) {
  testing::TempDir dir;
  const std::string scene = WriteScene(dir, "scene.json", false);
  const auto refused = RunPhos("render " + scene + " --out " + (dir / "out").string() + " --times 6");
  EXPECT_TRUE(testing::IsOneLineUserError(
      refused,
      "states[0].ke[3]: unknown (not measured) for band 512.5-550 nm: material 'green' cannot be charged by light "
      "'white lamp' (irradiance 0.8 in that band) there; measure ke there, or take it as not charging there: phos "
      "render --unknown-ke zero"));
  EXPECT_FALSE(std::filesystem::exists(dir / "out"));
}

TEST(UnknownKe, ZeroTakesEveryUnknownKeAsZeroAndSaysWhichAsTheSceneWould) {
  testing::TempDir dir;
  const std::string scene = WriteScene(dir, "scene.json", false);
  const auto zero = RunPhos("render " + scene + " --out " + (dir / "a").string() +
                            " --times 2,6 --exposure auto --unknown-ke zero --json");
  ASSERT_EQ(zero.exit_code, 0) << zero.err;
  EXPECT_EQ(zero.err, "phos render: warning: --unknown-ke zero: ke not measured taken as 0 (not charging): 'green' (" +
                          testing::Fixture("materials/green.json").string() +
                          ") in 512.5-550 nm, 550-587.5 nm, 587.5-625 nm, 625-662.5 nm, 662.5-700 nm\n");
  // The same frames as the scene that says so on its object, which is not said again.
  const auto stated = RunPhos("render " + WriteScene(dir, "stated.json", true) + " --out " + (dir / "b").string() +
                              " --times 2,6 --exposure auto --unknown-ke zero --json");
  ASSERT_EQ(stated.exit_code, 0) << stated.err;
  EXPECT_EQ(stated.err, "");
  for (const char* frame : {"frame-0000.png", "frame-0001.png"})
    EXPECT_EQ(testing::ReadText(dir / "a" / frame), testing::ReadText(dir / "b" / frame)) << frame;
  // It glows after dark (auto found glowing pixels): charged in the bands that were measured.
  const nlohmann::json a = nlohmann::json::parse(zero.out), b = nlohmann::json::parse(stated.out);
  EXPECT_GT(a["exposure_auto"]["glowing_pixels"].get<int>(), 0);
  EXPECT_EQ(a["exposure"], b["exposure"]);
  EXPECT_TRUE(testing::IsOneLineUserError(
      RunPhos("render " + scene + " --out " + (dir / "c").string() + " --unknown-ke guess"), "--unknown-ke"));
}

}  // namespace
}  // namespace phos
