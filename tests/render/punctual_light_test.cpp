// Spot lights and glTF's KHR_lights_punctual:
//  - a spot's irradiance on a floor is I cos / d^2 times the glTF falloff
//    (the square of the cosine to the axis mapped from the outer cone to the
//    inner), worked out here from the angles;
//  - a glTF's point, spot and directional lights land where their nodes
//    (with a parent's transform) put them, pointing down their -z axes,
//    with the scene's spectrum times glTF intensity times the scale times
//    the colour;
//  - a glTF that requires an extension phos does not read is refused in
//    one line naming the file, the field and the extension.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "phos/render/geometry.h"
#include "phos/render/scene.h"
#include "phos/render/spectral_upsampling.h"
#include "phos/util/error.h"
#include "phos/util/json.h"
#include "render/scene_util.h"
#include "test_util.h"

namespace phos::render {
namespace {

using phos::testing::EmptyScene;
using phos::testing::MakeObject;

TEST(SpotLight, IrradianceIsInverseSquareTimesTheGltfFalloff) {
  Scene scene = EmptyScene();
  scene.objects.push_back(MakeObject("floor", MakeQuad(10, 10), 0.5));
  Light spot;
  spot.kind = Light::Kind::kSpot;
  spot.position = Vec3(0, 1, 0);
  spot.direction = Vec3(0, -1, 0);
  spot.inner_cone_deg = 20;
  spot.outer_cone_deg = 40;
  spot.E_per_band.assign(8, 1.0);
  SceneGeometry geometry(scene);
  const LightPose pose = PoseAt(spot, 0);
  const double cos_inner = std::cos(20 * M_PI / 180), cos_outer = std::cos(40 * M_PI / 180);
  int inside = 0, between = 0, outside = 0;
  for (double angle_deg = 0; angle_deg < 60; angle_deg += 1.5) {
    const double x = std::tan(angle_deg * M_PI / 180);  // the floor point seen at that angle from the axis
    const double c = std::cos(angle_deg * M_PI / 180), d2 = 1 + x * x;
    double share = std::clamp((c - cos_outer) / (cos_inner - cos_outer), 0.0, 1.0);
    share *= share;
    const double expected = share * c / d2;
    const float got = UnitIrradiance(geometry, pose, Vec3f(float(x), 0, 0), Vec3f(0, 1, 0));
    EXPECT_NEAR(got, expected, 1e-5 + 1e-5 * expected) << angle_deg << " deg";
    (share == 1 ? inside : share == 0 ? outside : between)++;
  }
  EXPECT_GT(inside, 5);
  EXPECT_GT(between, 5);
  EXPECT_GT(outside, 5);
}

// A glTF with three lights: a red point at (1, 2, 3) under a parent moved
// by (0, 1, 0); a spot turned to point down (-90 deg about x); a
// directional turned about y by 90 deg (its -z becomes -x).
std::filesystem::path WriteLightsGltf(const std::filesystem::path& dir, nlohmann::json extra = {}) {
  const double s = std::sqrt(0.5);
  nlohmann::json gltf = {
      {"asset", {{"version", "2.0"}}},
      {"extensionsUsed", {"KHR_lights_punctual"}},
      {"extensions",
       {{"KHR_lights_punctual",
         {{"lights",
           {{{"name", "bulb"}, {"type", "point"}, {"intensity", 40}, {"color", {1, 0, 0}}},
            {{"name", "torch"},
             {"type", "spot"},
             {"intensity", 100},
             {"spot", {{"innerConeAngle", 0.2}, {"outerConeAngle", 0.5}}}},
            {{"name", "sun"}, {"type", "directional"}, {"intensity", 3}}}}}}}},
      {"scene", 0},
      {"scenes", {{{"nodes", {0, 2, 3}}}}},
      {"nodes",
       {{{"name", "parent"}, {"translation", {0, 1, 0}}, {"children", {1}}},
        {{"name", "bulb node"}, {"translation", {1, 2, 3}}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}},
        {{"name", "torch node"},
         {"translation", {0, 4, 0}},
         {"rotation", {-s, 0, 0, s}},
         {"extensions", {{"KHR_lights_punctual", {{"light", 1}}}}}},
        {{"name", "sun node"},
         {"rotation", {0, s, 0, s}},
         {"extensions", {{"KHR_lights_punctual", {{"light", 2}}}}}}}}};
  if (extra.is_object()) gltf.update(extra);
  std::filesystem::create_directories(dir);
  const std::filesystem::path file = dir / "lights.gltf";
  std::ofstream(file) << gltf.dump();
  return file;
}

TEST(GltfLights, PlacedByTheirNodesWithTheScenesSpectrumScaleAndColour) {
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "gltf_lights";
  WriteLightsGltf(dir);
  nlohmann::json json = ReadJsonFile(phos::testing::Fixture("scenes/cornell-phosphor.json"));
  json["lights"] = {{{"type", "gltf"},
                     {"file", "lights.gltf"},
                     {"spectrum", {{"type", "led"}, {"center_nm", 405}, {"fwhm_nm", 15}}},
                     {"intensity_scale", 0.01},
                     {"schedule", {{{"t_s", 0}, {"level", 1}}, {{"t_s", 5}, {"level", 0}}}}}};
  // Materials are found from the fixture's folder: point the scene's paths there.
  for (auto& object : json["objects"])
    for (const char* key : {"mesh", "phosphor"})
      if (object.contains(key))
        object[key] =
            (std::filesystem::path(phos::testing::Fixture("scenes")) / object[key].get<std::string>()).string();
  const Scene scene = SceneFromJson(json, dir, "lights.json");
  ASSERT_EQ(scene.lights.size(), 3u);
  const Light& bulb = scene.lights[0];
  const Light& torch = scene.lights[1];
  const Light& sun = scene.lights[2];
  EXPECT_EQ(bulb.name, "bulb");
  EXPECT_EQ(bulb.kind, Light::Kind::kPoint);
  EXPECT_TRUE(bulb.position.isApprox(Vec3(1, 3, 3), 1e-12));
  EXPECT_EQ(torch.kind, Light::Kind::kSpot);
  EXPECT_TRUE(torch.position.isApprox(Vec3(0, 4, 0), 1e-12));
  EXPECT_TRUE(torch.direction.isApprox(Vec3(0, -1, 0), 1e-9)) << torch.direction.transpose();
  EXPECT_NEAR(torch.inner_cone_deg, 0.2 * 180 / M_PI, 1e-9);
  EXPECT_NEAR(torch.outer_cone_deg, 0.5 * 180 / M_PI, 1e-9);
  EXPECT_EQ(sun.kind, Light::Kind::kDirectional);
  EXPECT_TRUE(sun.direction.isApprox(Vec3(-1, 0, 0), 1e-9)) << sun.direction.transpose();
  EXPECT_EQ(sun.schedule.LevelAt(6), 0.0);
  // Spectrum x intensity x scale x colour: the torch is white (1 in every
  // band), the bulb red.
  nlohmann::json point = {{"type", "point"},
                          {"position", {0, 1, 0}},
                          {"intensity", 1},
                          {"spectrum", {{"type", "led"}, {"center_nm", 405}, {"fwhm_nm", 15}}}};
  json["lights"] = {point};
  const Scene reference = SceneFromJson(json, dir, "reference.json");
  const std::vector<double> red = RgbToBands(scene.bands).Albedo({1, 0, 0});
  double total = 0;
  for (int b = 0; b < scene.bands.band_count(); ++b) {
    const double spectrum = reference.lights[0].E_per_band[b];
    total += spectrum;
    EXPECT_NEAR(torch.E_per_band[b], spectrum * 100 * 0.01, 1e-12 * (1 + spectrum));
    EXPECT_NEAR(sun.E_per_band[b], spectrum * 3 * 0.01, 1e-12 * (1 + spectrum));
    EXPECT_NEAR(bulb.E_per_band[b], spectrum * 40 * 0.01 * red[b], 1e-12 * (1 + spectrum));
  }
  EXPECT_GT(total, 0.5);  // the LED's bands are on the grid
  // intensity_scale is optional, 1 by default (docs/formats.md): an entry
  // without it was refused ("intensity_scale: missing (required)").
  json["lights"] = {{{"type", "gltf"},
                     {"file", "lights.gltf"},
                     {"spectrum", {{"type", "led"}, {"center_nm", 405}, {"fwhm_nm", 15}}}}};
  const Scene unscaled = SceneFromJson(json, dir, "unscaled.json");
  ASSERT_EQ(unscaled.lights.size(), 3u);
  for (int b = 0; b < scene.bands.band_count(); ++b)
    EXPECT_NEAR(unscaled.lights[1].E_per_band[b], reference.lights[0].E_per_band[b] * 100, 1e-10);
}

TEST(GltfLights, ARequiredExtensionPhosDoesNotReadIsOneLine) {
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "gltf_required";
  const std::filesystem::path file =
      WriteLightsGltf(dir, {{"extensionsUsed", {"KHR_lights_punctual", "KHR_materials_transmission"}},
                            {"extensionsRequired", {"KHR_materials_transmission"}}});
  for (int as_mesh = 0; as_mesh < 2; ++as_mesh) {
    std::string message = "accepted";
    try {
      if (as_mesh)
        LoadMesh(file, "", "scene.json: objects[0].mesh");
      else
        LoadGltfLights(file, "scene.json: lights[0].file");
    } catch (const UserError& e) {
      message = e.what();
    }
    EXPECT_NE(message.find("extensionsRequired"), std::string::npos) << message;
    EXPECT_NE(message.find("KHR_materials_transmission"), std::string::npos) << message;
    EXPECT_NE(message.find("lights.gltf"), std::string::npos) << message;
    EXPECT_EQ(message.find('\n'), std::string::npos) << message;
  }
  // Required and read: accepted.
  const std::filesystem::path ok = WriteLightsGltf(dir / "ok", {{"extensionsRequired", {"KHR_lights_punctual"}}});
  EXPECT_EQ(LoadGltfLights(ok, "here").size(), 3u);
}

TEST(SpotLight, SceneKeysAndBadCones) {
  nlohmann::json json = ReadJsonFile(phos::testing::Fixture("scenes/cornell-phosphor.json"));
  auto load = [&](nlohmann::json light) {
    json["lights"] = {light};
    try {
      SceneFromJson(json, phos::testing::Fixture("scenes"), "cornell-phosphor.json");
    } catch (const UserError& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  nlohmann::json spot = {{"type", "spot"},
                         {"position", {0, 1, 0}},
                         {"direction", {0, -1, 0}},
                         {"inner_cone_deg", 10},
                         {"outer_cone_deg", 30},
                         {"intensity", 1},
                         {"spectrum", {{"type", "white_led"}}}};
  EXPECT_EQ(load(spot), "accepted");
  spot["outer_cone_deg"] = 5;
  EXPECT_NE(load(spot).find("outer_cone_deg"), std::string::npos) << load(spot);
  nlohmann::json point = {{"type", "point"},
                          {"position", {0, 1, 0}},
                          {"inner_cone_deg", 10},
                          {"intensity", 1},
                          {"spectrum", {{"type", "white_led"}}}};
  EXPECT_NE(load(point).find("only a spot"), std::string::npos) << load(point);
}

}  // namespace
}  // namespace phos::render
