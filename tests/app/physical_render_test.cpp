// A scene in physical units ("units": "physical", docs/render.md,
// "Physical units"), rendered by the real renderer:
//  - a white Lambertian floor (albedo 0.8) 2 m below a 100 cd point light
//    reads Y = 0.8 x 25 / pi cd/m² under the light in the EXR's Y channel,
//    given in the scene or by a glTF KHR_lights_punctual light of
//    intensity 100 (whose range window cuts it as the extension says);
//  - random lights, places and albedos against the analytic irradiance
//    (inverse square times the cosine; a directional light's E lux gives
//    albedo E / pi; a sky of L cd/m² gives albedo L);
//  - mixing units, a light in two units, a physical key in a relative
//    scene, a value that is not positive, ev100 on a relative scene: one
//    line naming the file and the field, exit 2.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numeric>
#include <random>

#include <nlohmann/json.hpp>

#include "phos/model/photometry.h"
#include "phos/render/geometry.h"
#include "phos/render/renderer.h"
#include "phos/render/scene.h"
#include "phos/util/error.h"
#include "test_util.h"

namespace phos::testing {
namespace {

constexpr double kPi = 3.14159265358979323846;

// A floor of `albedo` (20 m square at y = 0) seen by a camera `height_m`
// above `target`, looking straight down, through a 3 x 3 image of 1 degree:
// the centre pixel sees the target.
nlohmann::json FloorScene(double albedo, const Eigen::Vector3d& target = Eigen::Vector3d::Zero(),
                          double height_m = 1.0) {
  return {{"schema", "phos.scene/1"},
          {"units", "physical"},
          {"time", {{"start_s", 0}, {"end_s", 0}}},
          {"camera",
           {{"position", {target.x(), height_m, target.z()}},
            {"look_at", {target.x(), 0, target.z()}},
            {"up", {0, 0, -1}},
            {"fov_deg", 1},
            {"width", 3},
            {"height", 3}}},
          {"objects", {{{"name", "floor"}, {"shape", {{"type", "quad"}, {"size", {20, 20}}}}, {"albedo", albedo}}}},
          {"lights", nlohmann::json::array()}};
}

// The centre pixel's band radiances, rendered by the direct transport.
std::vector<double> CentreBands(const nlohmann::json& json, const std::filesystem::path& dir) {
  const render::Scene scene = render::SceneFromJson(json, dir, "random.json");
  render::SceneGeometry geometry(scene);
  const render::Image image = render::RenderBands(geometry, nullptr, render::FrameOptions{});
  const float* p = image.at(1, 1);
  return std::vector<double>(p, p + image.channels);
}

double Y(const std::vector<double>& bands) {
  const std::vector<double> w = PhotopicBandEfficacy(SpectralGrid::Paper());
  return std::inner_product(w.begin(), w.end(), bands.begin(), 0.0);
}

// phos render --json on `scene` (a file); the EXR's Y channel at the centre pixel.
double RenderedY(const std::filesystem::path& scene, const std::filesystem::path& out, nlohmann::json* result) {
  const CommandResult r = RunPhos("render " + scene.string() + " --out " + out.string() + " --json");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  if (r.exit_code != 0) return NAN;
  *result = nlohmann::json::parse(r.out);
  const std::string exr = (*result)["frames"][0]["exr"].get<std::string>();
  EXPECT_EQ(render::ReadImage(exr).channels, 3 + 8 + 1);  // R, G, B, 8 bands, Y
  return render::ReadImageChannels(exr, {"Y"}).at(1, 1)[0];
}

const double kDoneWhenY = 0.8 * 25 / kPi;  // 0.8 x (100 cd / (2 m)^2) / pi = 6.366 cd/m²

// The floor of albedo 0.8 with a white LED lamp of 100 cd 2 m above it.
nlohmann::json LampScene() {
  nlohmann::json scene = FloorScene(0.8);
  scene["lights"].push_back(
      {{"type", "point"}, {"position", {0, 2, 0}}, {"intensity_cd", 100}, {"spectrum", {{"type", "white_led"}}}});
  return scene;
}

TEST(PhysicalRender, A100cdLamp2mAboveAWhiteFloorReads6_37cdPerM2) {
  TempDir dir;
  WriteText(dir / "lamp.json", LampScene().dump());
  nlohmann::json result;
  const double y = RenderedY(dir / "lamp.json", dir / "out", &result);
  EXPECT_NEAR(y, kDoneWhenY, 0.01 * kDoneWhenY);
  EXPECT_EQ(result["units"]["scene"], "physical");
  EXPECT_EQ(result["units"]["Y"], "cd/m2");
}

// A glTF whose one node, at (0, 2, 0), holds a KHR_lights_punctual point
// light of `intensity` (and `range`, when > 0).
void WriteLampGltf(const std::filesystem::path& path, double intensity, double range = 0) {
  nlohmann::json light = {{"type", "point"}, {"intensity", intensity}};
  if (range > 0) light["range"] = range;
  const nlohmann::json gltf = {
      {"asset", {{"version", "2.0"}}},
      {"extensionsUsed", {"KHR_lights_punctual"}},
      {"extensions", {{"KHR_lights_punctual", {{"lights", {light}}}}}},
      {"scene", 0},
      {"scenes", {{{"nodes", {0}}}}},
      {"nodes",
       {{{"name", "lamp"}, {"translation", {0, 2, 0}}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}}}}};
  WriteText(path, gltf.dump());
}

TEST(PhysicalRender, AGltfLampOf100ReadsInCandela) {
  TempDir dir;
  WriteLampGltf(dir / "lamp.gltf", 100);
  nlohmann::json scene = FloorScene(0.8);
  scene["lights"].push_back(
      {{"type", "gltf"}, {"file", "lamp.gltf"}, {"spectrum", {{"type", "blackbody"}, {"temperature_k", 2856}}}});
  WriteText(dir / "gltf-lamp.json", scene.dump());
  nlohmann::json result;
  EXPECT_NEAR(RenderedY(dir / "gltf-lamp.json", dir / "out", &result), kDoneWhenY, 0.01 * kDoneWhenY);
}

// A directional glTF light is in lux, down its node's -z axis (here turned
// 30 degrees from straight down); a coloured one shows its intensity times
// the colour's Rec. 709 luminance (a red point light of 100 cd as 21.26 cd).
TEST(PhysicalRender, GltfLightsAreInLuxAndTheirColoursLuminance) {
  TempDir dir;
  for (const bool directional : {true, false}) {
    nlohmann::json light = {{"type", directional ? "directional" : "point"}, {"intensity", directional ? 500 : 100}};
    if (!directional) light["color"] = {1, 0, 0};
    nlohmann::json node = {{"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}};
    if (directional)  // -90 degrees about x points -z down; 30 more tilt it
      node["rotation"] = {-std::sin(kPi / 4 + kPi / 12), 0, 0, std::cos(kPi / 4 + kPi / 12)};
    else
      node["translation"] = {0, 2, 0};
    const nlohmann::json gltf = {{"asset", {{"version", "2.0"}}},
                                 {"extensionsUsed", {"KHR_lights_punctual"}},
                                 {"extensions", {{"KHR_lights_punctual", {{"lights", {light}}}}}},
                                 {"scene", 0},
                                 {"scenes", {{{"nodes", {0}}}}},
                                 {"nodes", {node}}};
    WriteText(dir / "light.gltf", gltf.dump());
    nlohmann::json scene = FloorScene(0.8);
    scene["lights"].push_back({{"type", "gltf"}, {"file", "light.gltf"}, {"spectrum", {{"type", "white_led"}}}});
    const double expected = directional ? 0.8 * 500 * std::cos(kPi / 6) / kPi : 0.2126 * kDoneWhenY;
    EXPECT_NEAR(Y(CentreBands(scene, dir.path())), expected, 1e-3 * expected) << (directional ? "lux" : "red");
  }
}

// KHR_lights_punctual's range: the inverse square times
// clamp(1 - (d / range)^4, 0, 1); past the range, nothing.
TEST(PhysicalRender, AGltfLampsRangeWindowsItsFalloff) {
  TempDir dir;
  for (const double range : {2.5, 1.9}) {
    WriteLampGltf(dir / "lamp.gltf", 100, range);
    nlohmann::json scene = FloorScene(0.8);
    scene["lights"].push_back({{"type", "gltf"}, {"file", "lamp.gltf"}, {"spectrum", {{"type", "white_led"}}}});
    const double window = std::clamp(1 - std::pow(2 / range, 4), 0.0, 1.0);
    EXPECT_NEAR(Y(CentreBands(scene, dir.path())), kDoneWhenY * window, 1e-3 * kDoneWhenY) << range;
  }
}

// Random point and spot-free lights in cd, W/sr, lm and W, directional
// lights in lx and W/m², skies in cd/m²: the floor's Y (or its band sum,
// for a radiometric value of an LED inside the grid) is the albedo over pi
// times the analytic irradiance.
TEST(PhysicalRender, RandomLightsMatchTheAnalyticIrradiance) {
  TempDir dir;
  std::mt19937_64 random(45);
  std::uniform_real_distribution<double> u(0, 1);
  for (int trial = 0; trial < 24; ++trial) {
    const double albedo = 0.1 + 0.9 * u(random), value = std::exp(std::log(1000.0) * u(random));
    const Eigen::Vector3d target(2 * u(random) - 1, 0, 2 * u(random) - 1);
    nlohmann::json scene = FloorScene(albedo, target, 0.1);
    const nlohmann::json led = {{"type", "led"}, {"center_nm", 450 + 200 * u(random)}, {"fwhm_nm", 20}};
    double irradiance = 0;       // lx, or W/m² for a radiometric value
    const int kind = trial % 6;  // cd, W/sr, lm, W; directional in lx or W/m²; sky
    const bool radiometric = kind == 1 || kind == 3 || (kind == 4 && trial % 12 == 10);
    if (kind <= 3) {
      const Eigen::Vector3d light(2 * u(random) - 1, 0.5 + 2.5 * u(random), 2 * u(random) - 1);
      const double d = (light - target).norm(), cosine = light.y() / d;
      const char* keys[] = {"intensity_cd", "intensity_w_sr", "flux_lm", "power_w"};
      const char* key = keys[kind];
      const double intensity = kind >= 2 ? value / (4 * kPi) : value;  // isotropic: I = power / (4 pi)
      scene["lights"].push_back(
          {{"type", "point"}, {"position", {light.x(), light.y(), light.z()}}, {key, value}, {"spectrum", led}});
      irradiance = intensity * cosine / (d * d);
    } else if (kind <= 4) {
      const Eigen::Vector3d travel = Eigen::Vector3d(u(random) - 0.5, -1, u(random) - 0.5).normalized();
      scene["lights"].push_back({{"type", "directional"},
                                 {"direction", {travel.x(), travel.y(), travel.z()}},
                                 {radiometric ? "irradiance_w_m2" : "illuminance_lux", value},
                                 {"spectrum", led}});
      irradiance = value * -travel.y();
    } else {
      scene["environment"] = {{"spectrum", {{"type", "sun"}}}, {"luminance_cd_m2", value}};
      irradiance = kPi * value;  // an unoccluded floor under a uniform sky
    }
    const std::vector<double> bands = CentreBands(scene, dir.path());
    const double got = radiometric ? std::accumulate(bands.begin(), bands.end(), 0.0) : Y(bands);
    const double expected = albedo * irradiance / kPi;
    EXPECT_NEAR(got, expected, 5e-3 * expected) << "trial " << trial << ": " << scene.dump();
  }
}

// A quad or disk of luminance L (or radiance R) filling nearly the whole
// sky above the floor gives it pi L (Lambert's formula: the configuration
// factor of a 2 km light 1 m up is 1 - 3e-4), so the floor reads albedo L.
TEST(PhysicalRender, AnAreaLightOverTheFloorGivesAlbedoTimesItsLuminance) {
  TempDir dir;
  for (const char* type : {"quad", "disk"})
    for (const bool radiometric : {false, true}) {
      nlohmann::json scene = FloorScene(0.5, Eigen::Vector3d::Zero(), 0.1);
      nlohmann::json light = {{"type", type},
                              {"position", {0, 1, 0}},
                              {"normal", {0, -1, 0}},
                              {radiometric ? "radiance_w_sr_m2" : "luminance_cd_m2", 40},
                              {"spectrum", {{"type", "led"}, {"center_nm", 530}, {"fwhm_nm", 20}}}};
      light[std::string(type) == "quad" ? "size_m" : "radius_m"] =
          std::string(type) == "quad" ? nlohmann::json{2000, 2000} : nlohmann::json(1000);
      scene["lights"].push_back(light);
      const std::vector<double> bands = CentreBands(scene, dir.path());
      const double got = radiometric ? std::accumulate(bands.begin(), bands.end(), 0.0) : Y(bands);
      EXPECT_NEAR(got, 0.5 * 40, 2e-3 * 0.5 * 40) << type << (radiometric ? " W/(sr m2)" : " cd/m2");
    }
}

// What `phos render` says of a scene: exit code and stderr.
CommandResult RenderScene(const std::filesystem::path& dir, const nlohmann::json& scene,
                          const std::string& options = "") {
  WriteText(dir / "bad.json", scene.dump());
  return RunPhos("render " + (dir / "bad.json").string() + " --out " + (dir / "out").string() + " " + options);
}

void ExpectOneLine(const CommandResult& r, const std::vector<std::string>& words) {
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  for (const std::string& word : words) EXPECT_NE(r.err.find(word), std::string::npos) << word << " in " << r.err;
}

TEST(PhysicalRender, BadInputIsOneLineNamingTheFileAndField) {
  TempDir dir;
  nlohmann::json physical = LampScene();
  physical["bands_nm"] = {300.0, 350.0, 400.0, 437.5, 475.0, 512.5, 550.0, 587.5, 625.0, 662.5, 700.0};
  {  // a physical scene, a relative material
    nlohmann::json scene = physical;
    scene.erase("bands_nm");
    scene["objects"][0]["phosphor"] = Fixture("materials/green.json").string();
    ExpectOneLine(RenderScene(dir.path(), scene),
                  {"bad.json", "objects[0].phosphor", "'floor'", "green.json", "relative"});
  }
  {  // a relative scene, a physical material
    nlohmann::json scene = physical;
    scene.erase("units");
    scene["lights"][0].erase("intensity_cd");
    scene["lights"][0]["intensity"] = 1;
    scene["objects"][0]["phosphor"] = Fixture("materials/physical/sign-paint.json").string();
    ExpectOneLine(RenderScene(dir.path(), scene),
                  {"bad.json", "objects[0].phosphor", "'floor'", "sign-paint.json", "physical"});
  }
  {  // a light in both units
    nlohmann::json scene = physical;
    scene["lights"][0]["intensity_w_sr"] = 0.1;
    ExpectOneLine(RenderScene(dir.path(), scene), {"bad.json", "lights[0]", "intensity_cd", "intensity_w_sr"});
  }
  {  // a physical key in a relative scene
    nlohmann::json scene = physical;
    scene.erase("units");
    ExpectOneLine(RenderScene(dir.path(), scene), {"bad.json", "lights[0].intensity_cd", "relative"});
  }
  {  // a relative intensity in a physical scene
    nlohmann::json scene = physical;
    scene["lights"][0].erase("intensity_cd");
    scene["lights"][0]["intensity"] = 1;
    ExpectOneLine(RenderScene(dir.path(), scene), {"bad.json", "lights[0].intensity", "physical"});
  }
  for (const double bad : {0.0, -3.0}) {  // not positive
    nlohmann::json scene = physical;
    scene["lights"][0]["intensity_cd"] = bad;
    ExpectOneLine(RenderScene(dir.path(), scene), {"bad.json", "lights[0].intensity_cd", "positive"});
  }
  {  // a key of another quantity
    nlohmann::json scene = physical;
    scene["lights"][0].erase("intensity_cd");
    scene["lights"][0]["illuminance_lux"] = 10;
    ExpectOneLine(RenderScene(dir.path(), scene), {"bad.json", "lights[0].illuminance_lux", "intensity_cd"});
  }
  {  // no value at all
    nlohmann::json scene = physical;
    scene["lights"][0].erase("intensity_cd");
    ExpectOneLine(RenderScene(dir.path(), scene), {"bad.json", "lights[0]", "intensity_w_sr or intensity_cd"});
  }
  {  // unknown units
    nlohmann::json scene = physical;
    scene["units"] = "imperial";
    ExpectOneLine(RenderScene(dir.path(), scene), {"bad.json", "units", "imperial"});
  }
  for (const std::string bad : {"ev100:", "ev100:x", "ev100:nan", "ev100:100"}) {  // not an EV100
    WriteText(dir / "lamp.json", physical.dump());
    const CommandResult r =
        RunPhos("render " + (dir / "lamp.json").string() + " --out " + (dir / "out").string() + " --exposure " + bad);
    ExpectOneLine(r, {"--exposure", "ev100:N", bad});
  }
  {  // --material: a physical material into a relative scene
    nlohmann::json scene = physical;
    scene.erase("units");
    scene["lights"][0].erase("intensity_cd");
    scene["lights"][0]["intensity"] = 1;
    ExpectOneLine(
        RenderScene(dir.path(), scene, "--material floor=" + Fixture("materials/physical/sign-paint.json").string()),
        {"--material", "'floor'", "sign-paint.json", "physical"});
  }
  {  // ev100 on a relative scene
    const std::string cornell = Fixture("scenes/cornell-phosphor.json").string();
    const CommandResult r = RunPhos("render " + cornell + " --out " + (dir / "out").string() +
                                    " --times 1 --width 8 --height 8 --exposure ev100:3");
    ExpectOneLine(r, {"--exposure", "ev100", "relative"});
  }
}

// --exposure ev100:N shows 1.2 x 2^N cd/m² as 1 before the tone map: the
// lamp's floor (6.37 cd/m²) at EV100 log2(6.37 / 1.2) is Reinhard's 1 / 2,
// sRGB-encoded; two stops brighter it is 4 / 5.
TEST(PhysicalRender, Ev100ExposesTheLuminanceThatSaturatesTheSensorAsOne) {
  TempDir dir;
  WriteText(dir / "lamp.json", LampScene().dump());
  const double ev100 = std::log2(kDoneWhenY / 1.2);
  for (const auto& [stops, shown] : {std::pair{0.0, 0.5}, std::pair{-2.0, 0.8}}) {
    const std::string out = (dir / ("out" + std::to_string(int(-stops)))).string();
    const CommandResult r = RunPhos("render " + (dir / "lamp.json").string() + " --out " + out +
                                    " --json --exposure ev100:" + std::to_string(ev100 + stops));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const nlohmann::json result = nlohmann::json::parse(r.out);
    EXPECT_NEAR(result["exposure_ev100"].get<double>(), ev100 + stops, 1e-5);
    const std::string exr_path = result["frames"][0]["exr"].get<std::string>();
    const render::Image exr = render::ReadImageChannels(exr_path, {"R", "G", "B", "Y"});
    const render::Image png = render::ReadImage(result["frames"][0]["png"].get<std::string>());
    // The PNG's luminance, decoded from sRGB, against Reinhard's Y / (1 + Y)
    // of the exposed luminance; the white LED's rgb is not grey, so the
    // colour's own luminance is compared.
    const float* rgb = exr.at(1, 1);
    const double exr_y = 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
    const double exposure = result["exposure"].get<double>();
    const double exposed = exposure * exr_y;
    EXPECT_NEAR(exposed * 1.2 * std::exp2(ev100 + stops) / exr.at(1, 1)[3], 1.0, 0.05);
    EXPECT_NEAR(exposed / (1 + exposed), shown, 0.03);
    EXPECT_EQ(png.channels, 3);
  }
}

// "auto" writes the PNGs after the last frame from the EXRs read back: a
// physical frame's, whose "Y" the file keeps before "band0", shows as the
// same frame at the chosen exposure given as a number does, its night view
// (made of the bands) too.
TEST(PhysicalRender, AutoExposureReadsAPhysicalFrameBackByName) {
  TempDir dir;
  nlohmann::json scene = FloorScene(0.8);
  scene["camera"]["fov_deg"] = 60;
  scene["camera"]["width"] = scene["camera"]["height"] = 8;
  scene["lights"].push_back({{"type", "point"},
                             {"position", {0, 2, 0}},
                             {"intensity_cd", 100},
                             {"spectrum", {{"type", "led"}, {"center_nm", 620}, {"fwhm_nm", 20}}}});
  WriteText(dir / "lamp.json", scene.dump());
  const std::string render = "render " + (dir / "lamp.json").string() + " --night-vision 0.1 --json --out ";
  const CommandResult automatic = RunPhos(render + (dir / "auto").string() + " --exposure auto");
  ASSERT_EQ(automatic.exit_code, 0) << automatic.err;
  const double exposure = nlohmann::json::parse(automatic.out)["exposure"].get<double>();
  char number[64];
  std::snprintf(number, sizeof number, "%.17g", exposure);
  const CommandResult fixed = RunPhos(render + (dir / "fixed").string() + " --exposure " + number);
  ASSERT_EQ(fixed.exit_code, 0) << fixed.err;
  for (const char* view : {"frame-0000.png", "frame-0000-night.png"})  // the night view is made of the bands
    EXPECT_EQ(render::ReadImage(dir / "auto" / view).pixels, render::ReadImage(dir / "fixed" / view).pixels) << view;
}

}  // namespace
}  // namespace phos::testing
