// `phos render` as users and checks call it (docs/formats.md): the JSON
// keys, the files it writes, --no-phosphorescence, and one-line errors with
// exit code 2 for bad scenes and options.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <thread>
#include <chrono>
#include <functional>
#include <filesystem>
#include <fstream>

#include <OpenImageIO/imageio.h>
#include <csignal>
#include <sys/wait.h>
#include <unistd.h>
#include <nlohmann/json.hpp>

#include "phos/render/exposure.h"
#include "phos/render/renderer.h"
#include "phos/util/colour.h"
#include "test_util.h"

namespace phos::testing {
namespace {

const std::string kCornell = Fixture("scenes/cornell-phosphor.json").string();

TEST(RenderCommand, JsonFramesFollowTheContract) {
  TempDir dir;
  const CommandResult r =
      RunPhos("render " + kCornell + " --out " + dir.path().string() + " --times 20,40 --width 40 --height 30 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json json = nlohmann::json::parse(r.out);
  ASSERT_EQ(json["frames"].size(), 2u);
  EXPECT_EQ(json["frames"][0]["t"].get<double>(), 20.0);  // in the order given
  for (const auto& frame : json["frames"]) {
    EXPECT_GT(frame["seconds"].get<double>(), 0.0);
    // The set-up is part of the frame's render time, which is part of its time.
    EXPECT_GT(frame["setup_seconds"].get<double>(), 0.0);
    EXPECT_LE(frame["setup_seconds"].get<double>(), frame["render_seconds"].get<double>());
    EXPECT_LE(frame["render_seconds"].get<double>(), frame["seconds"].get<double>());
    const render::Image exr = render::ReadImage(frame["exr"].get<std::string>());
    EXPECT_EQ(exr.width, 40);
    EXPECT_EQ(exr.height, 30);
    EXPECT_EQ(exr.channels, 3 + 8);  // R, G, B and the 8 bands
    EXPECT_EQ(render::ReadImage(frame["png"].get<std::string>()).channels, 3);
  }
  EXPECT_EQ(json["transport"], "direct");
  EXPECT_GT(json["solver"]["texels"].get<int>(), 1000);
}

double ImageSum(const std::string& path) {
  const render::Image image = render::ReadImage(path);
  double sum = 0;
  for (float v : image.pixels) sum += v;
  return sum;
}

// --material can make a plain object a phosphor: its texels are counted
// before --check says the run would go (it passed, and the run then refused).
TEST(RenderCommand, AnObjectMadeAPhosphorByMaterialIsCountedByCheck) {
  testing::TempDir dir;
  nlohmann::json scene = nlohmann::json::parse(ReadText(Fixture("scenes/cornell-phosphor.json")));
  scene["texel_size_m"] = 1e-3;
  scene["objects"].push_back(
      {{"name", "plain quad"}, {"shape", {{"type", "quad"}, {"size", {1e6, 1e6}}}}, {"albedo", 0.5}});
  for (nlohmann::json& object : scene["objects"])
    if (object.contains("mesh")) object["mesh"] = Fixture("scenes/" + object["mesh"].get<std::string>()).string();
  for (nlohmann::json& object : scene["objects"])
    if (object.contains("phosphor"))
      object["phosphor"] = Fixture("scenes/" + object["phosphor"].get<std::string>()).string();
  WriteText(dir / "big.json", scene.dump());
  const std::string run = "render " + (dir / "big.json").string() + " --out " + (dir / "out").string() + " --check";
  EXPECT_EQ(RunPhos(run).exit_code, 0);
  const auto refused = RunPhos(run + " --material 'plain quad=" + Fixture("materials/green.json").string() + "'");
  EXPECT_TRUE(IsOneLineUserError(refused, "texels ('plain quad'")) << refused.err;
  EXPECT_FALSE(std::filesystem::exists(dir / "out"));
}

TEST(RenderCommand, NoPhosphorescenceLeavesTheDarkBoxBlack) {
  TempDir with, without;
  const std::string common = " --times 40 --width 24 --height 24 --json --out ";
  const CommandResult a = RunPhos("render " + kCornell + common + with.path().string());
  const CommandResult b = RunPhos("render " + kCornell + common + without.path().string() + " --no-phosphorescence");
  ASSERT_EQ(a.exit_code, 0) << a.err;
  ASSERT_EQ(b.exit_code, 0) << b.err;
  EXPECT_GT(ImageSum((with / "frame-0000.exr").string()), 0.0);
  EXPECT_EQ(ImageSum((without / "frame-0000.exr").string()), 0.0);  // lights off, nothing glows
  EXPECT_FALSE(nlohmann::json::parse(b.out)["phosphorescence"].get<bool>());
}

TEST(RenderCommand, ExrCompressionIsTheOneAskedForAndLosslessOnesKeepEveryFloat) {
  TempDir dir;
  auto render = [&](const std::string& compression) {
    const std::string out = (dir / compression).string();
    const CommandResult r =
        RunPhos("render " + kCornell + " --times 20 --width 32 --height 24 --transport path --spp 1" +
                " --exr-compression " + compression + " --out " + out);
    EXPECT_EQ(r.exit_code, 0) << r.err;
    auto in = OIIO::ImageInput::open(out + "/frame-0000.exr");
    EXPECT_TRUE(in) << compression;
    if (!in) return std::make_pair(std::string(), std::vector<float>());
    const OIIO::ImageSpec& spec = in->spec();
    std::vector<float> pixels(static_cast<std::size_t>(spec.width) * spec.height * spec.nchannels);
    in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, pixels.data());
    return std::make_pair(std::string(spec.get_string_attribute("compression")), pixels);
  };
  const auto zip = render("zip");
  EXPECT_EQ(zip.first, "zip");
  for (const char* lossless : {"none", "piz", "rle", "zips"}) {
    const auto other = render(lossless);
    EXPECT_EQ(other.first, lossless);
    EXPECT_TRUE(other.second == zip.second) << lossless;  // bit for bit
  }
  const auto pxr24 = render("pxr24");
  EXPECT_EQ(pxr24.first, "pxr24");
  ASSERT_EQ(pxr24.second.size(), zip.second.size());
  for (std::size_t i = 0; i < zip.second.size(); ++i)  // floats rounded to 24 bits: a relative 2^-15 at most
    EXPECT_NEAR(pxr24.second[i], zip.second[i], 1e-4 * std::fabs(zip.second[i]) + 1e-30) << i;
  // dwaa: lossy on R, G, B only; every band channel as written.
  const auto dwaa = render("dwaa");
  EXPECT_EQ(dwaa.first, "dwaa");
  ASSERT_EQ(dwaa.second.size(), zip.second.size());
  const std::size_t channels = zip.second.size() / (32 * 24);
  for (std::size_t i = 0; i < zip.second.size(); ++i)
    if (i % channels >= 3) {
      ASSERT_EQ(dwaa.second[i], zip.second[i]) << i;
    }
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + kCornell + " --exr-compression b44 --out " + (dir / "x").string()),
                                 "--exr-compression"));
  // A range rendered with zip is rendered again with another compression (its done record names it), once.
  const std::string range =
      "render " + kCornell + " --times 20 --width 16 --height 12 --task 0/1 --out " + (dir / "range").string();
  ASSERT_EQ(RunPhos(range).exit_code, 0);
  EXPECT_NE(RunPhos(range).out.find("nothing to do"), std::string::npos);
  const CommandResult other = RunPhos(range + " --exr-compression none");
  ASSERT_EQ(other.exit_code, 0) << other.err;
  EXPECT_EQ(other.out.find("nothing to do"), std::string::npos) << other.out;
  EXPECT_NE(RunPhos(range + " --exr-compression none").out.find("nothing to do"), std::string::npos);
}

TEST(RenderCommand, PathTransportRenders) {
  TempDir dir;
  const CommandResult r = RunPhos("render " + kCornell + " --out " + dir.path().string() +
                                  " --times 40 --width 16 --height 16 --spp 4 --transport path --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out)["transport"], "path");
  EXPECT_GT(ImageSum((dir / "frame-0000.exr").string()), 0.0);
}

TEST(RenderCommand, ABudgetPicksTheBestTransportThatFits) {
  TempDir dir;
  auto run = [&](const std::string& extra) {
    const CommandResult r = RunPhos("render " + kCornell + " --out " + dir.path().string() +
                                    " --times 40 --width 10 --height 10 --json " + extra);
    EXPECT_EQ(r.exit_code, 0) << r.err;
    return nlohmann::json::parse(r.out);
  };
  // Nothing fits a nanosecond: the fastest (direct), said so.
  const nlohmann::json tiny = run("--budget-s 1e-9");
  EXPECT_EQ(tiny["transport"], "direct");
  EXPECT_FALSE(tiny["transport_choice"]["fits"].get<bool>());
  // An hour fits everything: the best expected quality.
  const nlohmann::json hour = run("--budget-s 3600");
  EXPECT_EQ(hour["transport_choice"]["chosen"], "path 1024 spp");
  EXPECT_EQ(hour["transport"], "path");
  // In between, the choice fits its budget and nothing that fits (by that
  // run's own timings: the machine's noise moves them) looks better.
  const double dss_s = hour["transport_choice"]["candidates"][1]["estimated_s"].get<double>();
  const double budget = dss_s * 1.5;
  const nlohmann::json mid = run("--budget-s " + std::to_string(budget))["transport_choice"];
  if (mid["fits"].get<bool>()) {
    EXPECT_LE(mid["estimated_s"].get<double>(), budget);
  }
  for (const auto& candidate : mid["candidates"]) {
    if (candidate["estimated_s"].get<double>() <= budget) {
      EXPECT_LE(candidate["expected_ssim"].get<double>(), mid["expected_ssim"].get<double>()) << candidate["transport"];
    }
  }
  // A quality asks for the cheapest transport that reaches it.
  const nlohmann::json good = run("--quality 0.95");
  EXPECT_GE(good["transport_choice"]["expected_ssim"].get<double>(), 0.95);
  EXPECT_EQ(good["transport"], "path");
}

TEST(RenderCommand, TimesPastTheScenesEndAreRenderedWithAWarning) {
  TempDir dir;
  // The scene ends at 90 s. At auto: at its exposure 1 the glow after dark is nearly black, and said.
  const CommandResult r = RunPhos("render " + kCornell + " --out " + dir.path().string() +
                                  " --times 40,3600 --width 8 --height 8 --exposure auto --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out)["frames"].size(), 2u);
  EXPECT_EQ(r.err, "phos render: warning: --times: 3600 s is past the scene's end (90 s); rendered all the same\n");
}

// A phosphor tile under a lamp that is on for 10 s: facing it, wound the
// other way round (its back towards the lamp), or under a roof. Only the
// first charges; the others are named, once each, with the reason.
// A 16 x 16 scene of `objects` under a violet lamp 1 m above the origin,
// on for the first 10 of its 20 s, seen from `camera` looking at the origin.
nlohmann::json LampLitScene(const std::string& name, const nlohmann::json& objects, const nlohmann::json& camera) {
  return {{"schema", "phos.scene/1"},
          {"name", name},
          {"time", {{"start_s", 0}, {"end_s", 20}, {"fps", 0.1}}},
          {"texel_size_m", 0.1},
          {"camera", {{"position", camera}, {"look_at", {0, 0, 0}}, {"fov_deg", 60}, {"width", 16}, {"height", 16}}},
          {"objects", objects},
          {"lights",
           {{{"name", "lamp"},
             {"type", "point"},
             {"position", {0, 1, 0}},
             {"intensity", 0.5},
             {"spectrum", {{"type", "led"}, {"center_nm", 405}, {"fwhm_nm", 15}}},
             {"schedule", {{{"t_s", 0}, {"level", 1}}, {{"t_s", 10}, {"level", 0}}}}}}}};
}

CommandResult RenderTile(const TempDir& dir, bool flipped, bool roof, bool two_sided = false) {
  nlohmann::json tile = {{"name", "sign"},
                         {"shape", {{"type", "quad"}, {"size", {1, 1}}}},
                         {"phosphor", Fixture("materials/blue.json").string()},
                         {"albedo", 0.8}};
  if (flipped) tile["transform"] = {{"rotate", {{"axis", {1, 0, 0}}, {"deg", 180}}}};
  if (two_sided) tile["two_sided"] = true;
  nlohmann::json objects = nlohmann::json::array({tile});
  if (roof)
    objects.push_back({{"name", "roof"},
                       {"shape", {{"type", "box"}, {"size", {3, 0.05, 3}}}},
                       {"transform", {{"translate", {0, 0.5, 0}}}},
                       {"albedo", 0.5}});
  const nlohmann::json scene = LampLitScene("tile", objects, {0, 0.3, 2});
  const std::filesystem::path path = dir / (std::string(flipped ? "flipped" : "facing") + (roof ? "-roof" : "") +
                                            (two_sided ? "-two-sided" : "") + ".json");
  WriteText(path, scene.dump());
  // At an exposure that shows the glow after dark (at 1 it is nearly black, and said).
  return RunPhos("render " + path.string() + " --out " + (dir / path.stem()).string() +
                 " --times 5,15 --exposure 1000 --json");
}

// A glTF whose material has a normal map and emission: the render draws it
// without them and says so, one line naming the object, its file and the
// fields, and the same under "unread_material" in --json; a scene whose
// meshes have nothing unread gets no line and an empty object.
TEST(RenderCommand, GltfMaterialPartsNotDrawnAreNamedOnce) {
  TempDir dir;
  std::filesystem::copy_file(Fixture("scenes/textured/checker.png"), dir / "checker.png");
  nlohmann::json gltf = nlohmann::json::parse(ReadText(Fixture("scenes/textured/plane.gltf")));
  gltf["materials"][0]["normalTexture"] = {{"index", 0}};
  gltf["materials"][0]["emissiveFactor"] = {1, 1, 1};
  WriteText(dir / "board.gltf", gltf.dump());
  const nlohmann::json scene = LampLitScene(
      "board", {{{"name", "board"}, {"mesh", "board.gltf"}, {"phosphor", Fixture("materials/blue.json").string()}}},
      {0, 2, 0.01});
  WriteText(dir / "board.json", scene.dump());
  const CommandResult r = RunPhos("render " + (dir / "board.json").string() + " --out " + (dir / "out").string() +
                                  " --times 5,15 --exposure auto --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;  // once, for two frames
  EXPECT_NE(r.err.find("warning: 'board' ("), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("board.gltf): not drawn: materials[0].normalTexture, materials[0].emissiveFactor"),
            std::string::npos)
      << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out)["unread_material"],
            nlohmann::json({{"board", {"materials[0].normalTexture", "materials[0].emissiveFactor"}}}));
  // The cluster's solve pass, which renders nothing, says it as well.
  const CommandResult solve = RunPhos("render " + (dir / "board.json").string() + " --times 5,15 --solve-only" +
                                      " --checkpoints " + (dir / "states").string());
  ASSERT_EQ(solve.exit_code, 0) << solve.err;
  EXPECT_EQ(std::count(solve.err.begin(), solve.err.end(), '\n'), 1) << solve.err;
  EXPECT_NE(solve.err.find("board.gltf): not drawn: materials[0].normalTexture"), std::string::npos) << solve.err;

  const CommandResult cornell = RunPhos("render " + kCornell + " --out " + (dir / "cornell").string() +
                                        " --times 40 --width 16 --height 16 --exposure auto --json");
  ASSERT_EQ(cornell.exit_code, 0) << cornell.err;
  EXPECT_EQ(cornell.err, "");
  EXPECT_EQ(nlohmann::json::parse(cornell.out)["unread_material"], nlohmann::json::object());
}

TEST(RenderCommand, APhosphorThatNoLightChargesIsNamedOnceWithTheReason) {
  TempDir dir;
  const CommandResult facing = RenderTile(dir, false, false);
  ASSERT_EQ(facing.exit_code, 0) << facing.err;
  EXPECT_EQ(facing.err, "");
  EXPECT_EQ(nlohmann::json::parse(facing.out)["solver"]["never_charged"], nlohmann::json::array());

  const CommandResult flipped = RenderTile(dir, true, false);
  ASSERT_EQ(flipped.exit_code, 0) << flipped.err;
  EXPECT_EQ(nlohmann::json::parse(flipped.out)["solver"]["never_charged"], nlohmann::json::array({"sign"}));
  EXPECT_EQ(std::count(flipped.err.begin(), flipped.err.end(), '\n'), 1) << flipped.err;  // once, for two frames
  EXPECT_NE(flipped.err.find("'sign' receives no irradiance in a lit scene"), std::string::npos) << flipped.err;
  EXPECT_NE(flipped.err.find("the light reaches its back"), std::string::npos) << flipped.err;

  const CommandResult roofed = RenderTile(dir, false, true);
  ASSERT_EQ(roofed.exit_code, 0) << roofed.err;
  EXPECT_EQ(nlohmann::json::parse(roofed.out)["solver"]["never_charged"], nlohmann::json::array({"sign"}));
  EXPECT_NE(roofed.err.find("no light reaches its front"), std::string::npos) << roofed.err;
}

// The tile turned over and two-sided: lit on its back and seen from it, it
// charges and glows as the tile facing the lamp does (the quad and the lamp
// are symmetric under the turn, up to where its texels fall), with no warning.
TEST(RenderCommand, ATwoSidedPhosphorLitFromBehindChargesAndGlows) {
  TempDir dir;
  const CommandResult facing = RenderTile(dir, false, false);
  ASSERT_EQ(facing.exit_code, 0) << facing.err;
  const CommandResult sheet = RenderTile(dir, true, false, true);
  ASSERT_EQ(sheet.exit_code, 0) << sheet.err;
  EXPECT_EQ(sheet.err, "");
  EXPECT_EQ(nlohmann::json::parse(sheet.out)["solver"]["never_charged"], nlohmann::json::array());
  for (const char* frame : {"frame-0000.exr", "frame-0001.exr"}) {  // lit (5 s), then after dark (15 s)
    const double expected = ImageSum((dir / "facing" / frame).string());
    ASSERT_GT(expected, 0.0) << frame;
    EXPECT_NEAR(ImageSum((dir / "flipped-two-sided" / frame).string()), expected, 0.01 * expected) << frame;
  }
}

TEST(RenderCommand, BadInputIsOneLineAndExitTwo) {
  TempDir dir;
  const std::string out = " --out " + dir.path().string();
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render /nonexistent/scene.json" + out), "scene.json"));
  EXPECT_TRUE(
      IsOneLineUserError(RunPhos("render " + kCornell + out + " --transport magic"), "unknown transport 'magic'"));
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + kCornell + out + " --times 5,x"), "--times"));
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + kCornell + out + " --times -1"), "before the scene's start"));
  // Given empty (a script's unset variable), not every frame of the scene.
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + kCornell + out + " --times \"\""),
                                 "--times: expected a comma-separated list of seconds, got nothing"));
  // Out of order is refused, not re-sorted (frames are numbered as given).
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + kCornell + out + " --times 30,0"),
                                 "--times: expected times in increasing order, got 0 after 30"));
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + kCornell + out + " --spp 0"), "--spp"));
  // Each within its own range, together over the scene file's pixel limit (it took 12.7 GB).
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + kCornell + out + " --width 16384 --height 16384"),
                                 "--width: 16384 x 16384 pixels is more than the limit"));
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + kCornell + out + " --budget-s 1 --transport dss"), "--budget-s"));
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + kCornell + out + " --budget-s 1 --quality 0.5"), "not both"));
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + kCornell + out + " --quality 2"), "--quality"));
  // Bounds said as a person would (CLI11's own said "Value 0 not in range
  // 0.000000 to 1.000000", and DBL_MAX in 309 digits for a positive number).
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + kCornell + out + " --quality 0"),
                                 "--quality: expected a number above 0 and at most 1, got 0"));
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + kCornell + out + " --budget-s 0"),
                                 "--budget-s: expected a number > 0, got 0"));
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + kCornell + out + " --night-vision -1"),
                                 "--night-vision: expected a number > 0, got -1"));
  // --help lists each check once.
  EXPECT_EQ(RunPhos("render --help").out.find("FINITE:FINITE"), std::string::npos);
  WriteText(dir / "bad.json", R"({"schema": "phos.scene/1", "camera": {"position": [0,0,0], "look_at": [0,0,1]},
    "objects": [{"shape": {"type": "cone"}, "albedo": 0.5}], "lights": []})");
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + (dir / "bad.json").string() + out), "objects[0].shape.type"));
  WriteText(dir / "broken.json", "{\"schema\": ");
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + (dir / "broken.json").string() + out), "broken.json"));
  // Nothing was written by the failed runs.
  EXPECT_FALSE(std::filesystem::exists(dir / "frame-0000.exr"));
}

// --exposure auto, worked out here from the EXRs: each frame's nearest-rank
// median of its glowing pixels' luminance; the largest shown as mid-grey.
double MidGreyExposureOf(const std::vector<std::string>& exrs) {
  double brightest = 0;
  for (const std::string& exr : exrs) {
    const render::Image image = render::ReadImage(exr);
    std::vector<float> glowing;
    for (std::size_t p = 0; p < image.pixels.size() / image.channels; ++p) {
      const float* c = &image.pixels[p * image.channels];
      const double Y = LinearSrgbLuminance(c[0], c[1], c[2]);
      if (Y > 0) glowing.push_back(static_cast<float>(Y));
    }
    if (glowing.empty()) continue;
    std::sort(glowing.begin(), glowing.end());
    brightest = std::max(brightest, static_cast<double>(glowing[(glowing.size() + 1) / 2 - 1]));
  }
  EXPECT_GT(brightest, 0.0);
  return 0.18 / (1 - 0.18) / brightest;
}

// The frame's PNG is its EXR's R, G, B through ToneMap at `exposure`, to the 8-bit rounding.
::testing::AssertionResult PngShowsExrAt(const nlohmann::json& frame, double exposure) {
  const render::Image exr = render::ReadImage(frame["exr"].get<std::string>());
  render::Image rgb(exr.width, exr.height, 3);
  for (std::size_t p = 0; p < rgb.pixels.size() / 3; ++p)
    std::copy_n(&exr.pixels[p * exr.channels], 3, &rgb.pixels[3 * p]);
  const render::Image expected = render::ToneMap(rgb, exposure);
  const render::Image png = render::ReadImage(frame["png"].get<std::string>());
  for (std::size_t i = 0; i < png.pixels.size(); ++i)
    if (std::lround(png.pixels[i] * 255) != std::lround(expected.pixels[i] * 255))
      return ::testing::AssertionFailure() << frame["png"] << " value " << i << ": " << png.pixels[i] * 255
                                           << " against " << expected.pixels[i] * 255 << " at exposure " << exposure;
  return ::testing::AssertionSuccess();
}

// The Cornell fixture changed by `edit`, written into `dir` (its meshes' and
// materials' paths made absolute, so the copy finds them).
std::string CornellEdited(const TempDir& dir, const std::string& name,
                          const std::function<void(nlohmann::json&)>& edit) {
  nlohmann::json scene = nlohmann::json::parse(ReadText(kCornell));
  edit(scene);
  for (auto& object : scene["objects"])
    for (const char* key : {"mesh", "phosphor"})
      if (object.contains(key))
        object[key] = (Fixture("scenes") / object[key].get<std::string>()).lexically_normal().string();
  const std::filesystem::path path = dir / (name + ".json");
  WriteText(path, scene.dump());
  return path.string();
}
// The Cornell fixture with another camera.exposure.
std::string CornellWithExposure(const TempDir& dir, const std::string& name, const nlohmann::json& exposure) {
  return CornellEdited(dir, name, [&](nlohmann::json& scene) { scene["camera"]["exposure"] = exposure; });
}

// A killed run leaves the temporary of the frame it was writing; the next
// run of those frames removes it (it stayed, 82 MB, after a timeout).
TEST(RenderCommand, ARunRemovesTheTemporariesAKilledRunLeft) {
  TempDir dir;
  WriteText(dir / "frame-0000.exr.tmp.4242.exr", "half a frame");
  WriteText(dir / "other.exr.tmp.4242.exr", "not ours");
  const CommandResult r =
      RunPhos("render " + kCornell + " --out " + dir.path().string() + " --times 40 --width 8 --height 6");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir / "frame-0000.exr.tmp.4242.exr"));
  EXPECT_TRUE(std::filesystem::exists(dir / "other.exr.tmp.4242.exr"));  // not a file this run writes
  EXPECT_TRUE(std::filesystem::exists(dir / "frame-0000.exr"));
}

// Ctrl-C (or a Slurm cancel's SIGTERM) mid-render: one line says what is
// left, with the usual exit code (it ended with 130 and no word).
TEST(RenderCommand, AnInterruptedRenderSaysWhatIsLeft) {
  TempDir dir;
  const std::string command = "timeout --preserve-status -s INT 5 " + std::string(PHOS_BINARY) + " render " + kCornell +
                              " --out " + dir.path().string() +
                              " --transport path --spp 1024 --width 256 --height 256 --times 40,41,42,43 >" +
                              (dir / "out.txt").string() + " 2>" + (dir / "err.txt").string();
  const int status = std::system(command.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 130);
  const std::string err = ReadText(dir / "err.txt");
  EXPECT_NE(err.find("phos render: interrupted (SIGINT): every frame written is whole"), std::string::npos) << err;
}

// With a fixed exposure each frame's line is printed, and flushed, as soon
// as the frame's files are written: a run cut short (a cluster job out of
// time, Ctrl-C) has its header and a line for each frame on disk in its
// log. They used to be printed at the end only, so such a log was empty.
TEST(RenderCommand, EachFramesLineIsInTheLogAsSoonAsTheFrameIsWritten) {
  // The property, without a bound on speed (a 4 s cut failed on a busy
  // machine under ASan): frame f's line is printed and flushed before frame
  // f + 1 is rendered, so once frame f + 1's file exists the log must name
  // frame f. The render runs until frame 2 is written, then is interrupted;
  // the 10 minutes are only a guard against a hang.
  TempDir dir;
  std::string times;
  for (int t = 40; t < 140; ++t) {
    if (!times.empty()) times += ',';
    times += std::to_string(t);
  }
  const std::string command = "exec " + std::string(PHOS_BINARY) + " render " + kCornell + " --out " +
                              dir.path().string() + " --transport path --spp 16 --width 96 --height 96 --times " +
                              times + " >" + (dir / "out.txt").string() + " 2>" + (dir / "err.txt").string();
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::execl("/bin/sh", "sh", "-c", command.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ASSERT_GT(pid, 0);
  auto png = [&](int f) {
    char name[32];
    std::snprintf(name, sizeof name, "frame-%04d.png", f);
    return (dir / name).string();
  };
  int status = 0;
  bool ended = false;
  const auto guard = std::chrono::steady_clock::now() + std::chrono::minutes(10);
  while (!std::filesystem::exists(png(2)) && std::chrono::steady_clock::now() < guard) {
    if (::waitpid(pid, &status, WNOHANG) == pid) {
      ended = true;
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  const bool third_written = std::filesystem::exists(png(2));
  const std::string log_then = ReadText(dir / "out.txt");  // read after frame 2's file was seen
  if (!ended) {
    ::kill(pid, SIGINT);
    ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  }
  ASSERT_TRUE(third_written) << "frame 2 was never written: " << ReadText(dir / "err.txt");
  EXPECT_EQ(log_then.rfind("cornell-phosphor: 100 frame(s), 96x96, transport path, ", 0), 0u) << log_then;
  for (int f = 0; f < 2; ++f) EXPECT_NE(log_then.find(png(f) + "\n"), std::string::npos) << f << "\n" << log_then;
  // Interrupted: exit 130, and every line names a frame that was written;
  // every frame before the last one written has its line.
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 130) << ReadText(dir / "err.txt");
  const std::string out = ReadText(dir / "out.txt");
  for (int f = 0; f < 100; ++f) {
    const bool said = out.find(png(f) + "\n") != std::string::npos;
    if (said) EXPECT_TRUE(std::filesystem::exists(png(f))) << png(f) << " said but not written";
    if (std::filesystem::exists(png(f + 1))) EXPECT_TRUE(said) << png(f) << " written before the next, not said";
  }
}

// What would render black without a word is said: a light whose spectrum
// misses the scene's bands, a scene with nothing to charge or show its
// phosphors; and a scene whose objects share a name, which --material gave
// to both silently, is refused.
TEST(RenderCommand, ADarkSceneIsWarnedAboutAndAnAmbiguousMaterialRefused) {
  TempDir dir;
  const std::string out = " --out " + dir.path().string() + " --times 40 --width 16 --height 12";
  const std::string infrared = CornellEdited(dir, "infrared", [](nlohmann::json& s) {
    s["lights"][0]["spectrum"]["center_nm"] = 1000;  // the scene's bands end at 700 nm
  });
  CommandResult r = RunPhos("render " + infrared + out);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err,
            "phos render: warning: light 'uv led' puts nothing in the scene's bands (400-700 nm): its "
            "spectrum lies outside them, so it lights nothing\n");
  const std::string unlit =
      CornellEdited(dir, "unlit", [](nlohmann::json& s) { s["lights"] = nlohmann::json::array(); });
  r = RunPhos("render " + unlit + out);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("the scene has no light and no sky, and no phosphor starts charged"), std::string::npos)
      << r.err;
  // Charged from the start, it glows without a light: nothing to warn of.
  const std::string precharged = CornellEdited(dir, "precharged", [](nlohmann::json& s) {
    s["lights"] = nlohmann::json::array();
    for (auto& object : s["objects"])
      if (object.contains("phosphor")) object["initial"] = 0.3;
  });
  // (At auto: at the scene's exposure 1 the glow would be nearly black, and said.)
  r = RunPhos("render " + precharged + out + " --exposure auto");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");
  r = RunPhos("render " + kCornell + out + " --exposure auto");
  EXPECT_EQ(r.err, "");
  const std::string twins =
      CornellEdited(dir, "twins", [](nlohmann::json& s) { s["objects"][1]["name"] = s["objects"][0]["name"]; });
  const std::string name = nlohmann::json::parse(ReadText(kCornell))["objects"][0]["name"];
  EXPECT_TRUE(IsOneLineUserError(
      RunPhos("render " + twins + out + " --material \"" + name + "=" + Fixture("materials/orange.json").string() +
              "\""),
      "objects[1].name: '" + name + "' is the name of objects[0] too; give each object a name of its own"));
}

TEST(RenderCommand, AutoExposureMetersTheFramesAfterDark) {
  // The LED is on until 30 s: 20 s is lit, 40 and 60 s are after dark.
  TempDir dir;
  const CommandResult r =
      RunPhos("render " + kCornell + " --out " + dir.path().string() + " --times 20,40,60 --width 24 --height 24" +
              " --exposure auto --night-vision 0.05 --contact-sheet " + (dir / "sheet.png").string() + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");
  const nlohmann::json json = nlohmann::json::parse(r.out);
  const nlohmann::json& metering = json["exposure_auto"];
  EXPECT_EQ(metering["metered"], "after dark");
  EXPECT_EQ(metering["metered_frames"].get<int>(), 2);
  EXPECT_EQ(metering["display_luminance"].get<double>(), 0.18);
  const double exposure = json["exposure"].get<double>();
  const double expected = MidGreyExposureOf({json["frames"][1]["exr"], json["frames"][2]["exr"]});
  EXPECT_NEAR(exposure, expected, 1e-9 * expected);
  EXPECT_GT(exposure, 10.0);  // the glow is far dimmer than the camera's exposure 1 shows
  // Every view of every frame, the lit one too, is at that one exposure.
  for (const auto& frame : json["frames"]) {
    EXPECT_TRUE(PngShowsExrAt(frame, exposure));
    EXPECT_TRUE(std::filesystem::exists(frame["night_png"].get<std::string>()));
  }
  EXPECT_TRUE(std::filesystem::exists(dir / "sheet.png"));

  const CommandResult text = RunPhos("render " + kCornell + " --out " + dir.path().string() +
                                     " --times 20,40,60 --width 24 --height 24 --exposure auto");
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_NE(text.out.find("  exposure auto: "), std::string::npos) << text.out;
  EXPECT_NE(text.out.find("metered on 2 frame(s) after dark"), std::string::npos) << text.out;
}

// Under path and dss transport, "auto" meters the direct transport's frames
// of the same moments: the glow itself, not the light it throws on the
// rest (the path tracer's indirect light set the median before). So every
// transport gets the direct run's exposure, and its PNGs show its own EXRs
// at that exposure.
TEST(RenderCommand, AutoExposureUnderPathAndDssIsMeteredOnTheDirectFrames) {
  TempDir dir;
  auto run = [&](const std::string& transport) {
    const CommandResult r =
        RunPhos("render " + kCornell + " --out " + (dir / transport).string() +
                " --times 40,60 --width 24 --height 24 --spp 4 --exposure auto --json" + " --transport " + transport);
    EXPECT_EQ(r.exit_code, 0) << r.err;
    return nlohmann::json::parse(r.out);
  };
  const nlohmann::json direct = run("direct");
  const double exposure = direct["exposure"].get<double>();
  EXPECT_NEAR(exposure, MidGreyExposureOf({direct["frames"][0]["exr"], direct["frames"][1]["exr"]}), 1e-9 * exposure);
  for (const std::string transport : {"path", "dss"}) {
    const nlohmann::json json = run(transport);
    EXPECT_EQ(json["exposure_auto"]["metered_transport"], "direct");
    EXPECT_EQ(json["exposure"].get<double>(), exposure) << transport;
    // Its own frames' median would differ: their indirect light glows too.
    const double own = MidGreyExposureOf({json["frames"][0]["exr"], json["frames"][1]["exr"]});
    EXPECT_GT(std::abs(own - exposure), 0.01 * exposure) << transport;
    for (const auto& frame : json["frames"]) EXPECT_TRUE(PngShowsExrAt(frame, exposure)) << transport;
  }
}

TEST(RenderCommand, ANumericExposureIsUsedAsItIs) {
  TempDir dir;
  const std::string common = " --out " + dir.path().string() + " --times 40 --width 16 --height 16 --json";
  const nlohmann::json by_scene = nlohmann::json::parse(RunPhos("render " + kCornell + common).out);
  EXPECT_EQ(by_scene["exposure"].get<double>(), 1.0);  // the fixture's camera.exposure
  EXPECT_FALSE(by_scene.contains("exposure_auto"));
  EXPECT_TRUE(PngShowsExrAt(by_scene["frames"][0], 1.0));
  const nlohmann::json given = nlohmann::json::parse(RunPhos("render " + kCornell + common + " --exposure 3").out);
  EXPECT_EQ(given["exposure"].get<double>(), 3.0);
  EXPECT_TRUE(PngShowsExrAt(given["frames"][0], 3.0));
  // A number on the command line wins over a scene's "auto".
  const std::string auto_scene = CornellWithExposure(dir, "auto", "auto");
  const nlohmann::json overridden =
      nlohmann::json::parse(RunPhos("render " + auto_scene + common + " --exposure 3").out);
  EXPECT_EQ(overridden["exposure"].get<double>(), 3.0);
  EXPECT_FALSE(overridden.contains("exposure_auto"));
  const nlohmann::json from_scene = nlohmann::json::parse(RunPhos("render " + auto_scene + common).out);
  EXPECT_EQ(from_scene["exposure_auto"]["metered"], "after dark");
}

TEST(RenderCommand, AutoExposureWithNoFrameAfterDarkMetersEveryFrame) {
  TempDir dir;
  const CommandResult r = RunPhos("render " + kCornell + " --out " + dir.path().string() +
                                  " --times 5,10 --width 16 --height 16 --exposure auto --json");  // LED on
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");
  const nlohmann::json json = nlohmann::json::parse(r.out);
  EXPECT_EQ(json["exposure_auto"]["metered"], "all frames");
  EXPECT_EQ(json["exposure_auto"]["metered_frames"].get<int>(), 2);
  const double expected = MidGreyExposureOf({json["frames"][0]["exr"], json["frames"][1]["exr"]});
  EXPECT_NEAR(json["exposure"].get<double>(), expected, 1e-9 * expected);
}

TEST(RenderCommand, AutoExposureOfBlackFramesAfterDarkIsOneAndSaidOnce) {
  TempDir dir;
  const CommandResult r =
      RunPhos("render " + kCornell + " --out " + dir.path().string() +
              " --times 20,40,60 --width 16 --height 16 --exposure auto --no-phosphorescence --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err,
            "phos render: warning: exposure auto: the 2 frame(s) after dark are black (no pixel glows): "
            "exposure 1\n");
  const nlohmann::json json = nlohmann::json::parse(r.out);
  ASSERT_TRUE(json["exposure"].is_number());  // not null (NaN) nor inf
  EXPECT_EQ(json["exposure"].get<double>(), 1.0);
  EXPECT_EQ(json["exposure_auto"]["glowing_pixels"].get<int>(), 0);
  for (const auto& frame : json["frames"]) EXPECT_TRUE(PngShowsExrAt(frame, 1.0));
}

TEST(RenderCommand, BadExposuresAreOneLineAndExitTwo) {
  TempDir dir;
  const std::string out = " --out " + dir.path().string() + " --times 40 --width 8 --height 8";
  for (const std::string bad : {"autox", "-1", "nan", "inf", "0", "1e400", ""})
    EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + kCornell + out + " --exposure '" + bad + "'"),
                                   "--exposure: expected \"auto\", ev100:N or a positive number, got \"" + bad + "\""));
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + CornellWithExposure(dir, "autox", "autox") + out),
                                 "autox.json: camera.exposure: expected \"auto\" or a number in [0, 1e9], got "));
  // A range of frames cannot see the others' frames after dark.
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + kCornell + out + " --exposure auto --task 0/2"),
                                 "--exposure: \"auto\" meters every frame after dark: not with --frames or --task"));
  EXPECT_TRUE(IsOneLineUserError(RunPhos("render " + CornellWithExposure(dir, "auto", "auto") + out + " --frames 0:1"),
                                 "auto.json: camera.exposure: \"auto\" meters every frame after dark"));
  EXPECT_FALSE(std::filesystem::exists(dir / "frame-0000.exr"));
}

}  // namespace
}  // namespace phos::testing

namespace phos::testing {
namespace {

// The textured-plane fixture's glTF with its image replaced by `image_uri`.
std::string TexturedPlaneScene(const phos::testing::TempDir& dir, const std::string& image_uri) {
  std::string gltf = phos::testing::ReadText(phos::testing::Fixture("scenes/textured/plane.gltf"));
  const std::string uri = "\"uri\": \"checker.png\"";
  gltf.replace(gltf.find(uri), uri.size(), "\"uri\": \"" + image_uri + "\"");
  std::ofstream(dir / "plane.gltf") << gltf;
  std::ofstream(dir / "scene.json") << R"({"schema": "phos.scene/1", "time": {"start_s": 0, "end_s": 1, "fps": 1},
    "camera": {"position": [0, 2, 0], "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 8, "height": 8},
    "objects": [{"name": "plane", "mesh": "plane.gltf"}], "lights": []})";
  return (dir / "scene.json").string();
}

TEST(RenderCommand, ABadTextureIsOneLineAndExitTwo) {
  phos::testing::TempDir dir;
  const std::string out = " --out " + (dir / "out").string();
  EXPECT_TRUE(phos::testing::IsOneLineUserError(RunPhos("render " + TexturedPlaneScene(dir, "gone.png") + out),
                                                "images[0].uri: texture file"));
  std::ofstream(dir / "notes.png") << "these are not pixels\n";
  EXPECT_TRUE(phos::testing::IsOneLineUserError(RunPhos("render " + TexturedPlaneScene(dir, "notes.png") + out),
                                                "baseColorTexture: texture file"));
}

// A unit quad in y = 0 facing +y, UV (u, v) = (x, z), and a scene that looks
// straight down on it, lit by a 405 nm point light until 10 s. `object_extra`
// goes into the quad's object (a phosphor map, initial states).
std::string MappedQuadScene(const phos::testing::TempDir& dir, const std::string& name, const std::string& material,
                            const std::string& object_extra, bool lit) {
  std::ofstream(dir / "quad.obj") << "v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                                     "f 1/1 4/4 3/3\nf 1/1 3/3 2/2\n";
  const std::string light = R"({"name": "uv", "type": "point", "position": [0.5, 1.5, 0.5], "intensity": 0.5,
      "spectrum": {"type": "led", "center_nm": 405, "fwhm_nm": 15}, "schedule": [{"t_s": 0, "level": 1}, {"t_s": 10, "level": 0}]})";
  std::ofstream(dir / (name + ".json")) << R"({"schema": "phos.scene/1", "name": ")" << name
                                        << R"(", "time": {"start_s": 0, "end_s": 30, "fps": 1},
    "camera": {"position": [0.5, 2, 0.5], "look_at": [0.5, 0, 0.5], "up": [0, 0, 1], "fov_deg": 24, "width": 32, "height": 32},
    "objects": [{"name": "sample", "mesh": "quad.obj", "albedo": 0.5, "phosphor": ")"
                                        << material << R"(", "uv_resolution": 16)" << object_extra << R"(}],
    "lights": [)" << (lit ? light : "") << "]}";
  return (dir / (name + ".json")).string();
}

// A decay map as `phos fit map` writes it (kr, amplitude.R/G/B), the same at every pixel.
void WriteUniformMap(const std::filesystem::path& exr, float kr_per_s, float amplitude) {
  const int side = 16, channels = 4;
  std::vector<float> pixels(side * side * channels, amplitude);
  for (int p = 0; p < side * side; ++p) pixels[p * channels] = kr_per_s;
  OIIO::ImageSpec spec(side, side, channels, OIIO::TypeDesc::FLOAT);
  spec.channelnames = {"kr", "amplitude.R", "amplitude.G", "amplitude.B"};
  auto out = OIIO::ImageOutput::create(exr.string());
  ASSERT_TRUE(out && out->open(exr.string(), spec) && out->write_image(OIIO::TypeDesc::FLOAT, pixels.data()));
  out->close();
}

// An object driven by a uniform map renders the same frames as the uniform
// material (as oiiotool --diff would see), lit and ten seconds after dark.
TEST(RenderCommand, AUniformMapRendersAsTheUniformMaterial) {
  TempDir dir;
  const std::string green = Fixture("materials/green.json").string();
  WriteUniformMap(dir / "uniform.exr", 0.227f, 300.0f);  // green's kr
  const std::string mapped = MappedQuadScene(dir, "mapped", green, R"(, "phosphor_map": "uniform.exr")", true);
  const std::string plain = MappedQuadScene(dir, "plain", green, "", true);
  for (const auto& [scene, out] : {std::pair{mapped, "mapped-out"}, std::pair{plain, "plain-out"}}) {
    const CommandResult r = RunPhos("render " + scene + " --times 5,20 --out " + (dir / out).string());
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  EXPECT_GT(ImageSum((dir / "plain-out/frame-0001.exr").string()), 0.0);  // it glows after dark
  for (const char* frame : {"frame-0000.exr", "frame-0001.exr"}) {
    const std::string a = (dir / "mapped-out" / frame).string(), b = (dir / "plain-out" / frame).string();
    const int status = std::system(("oiiotool --diff " + a + " " + b + " >/dev/null 2>&1").c_str());
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "oiiotool --diff " << a << " " << b;
  }
}

// The whole path of a measured map: a simulated sample whose centre is
// another phosphor (4x the rate, half the re-radiation, the same charge
// rates: twice the glow at a full charge, but the lab's charge leaves it at a
// lower level) is captured, fitted per pixel, and worn by a quad. Its glow
// 2 s into the dark, from states of 1, is in the ratio the two materials
// say, 2 e^{-(4 - 1) kr 2 s}: the map's amplitudes are read through the
// levels its session's charge left (phos:charge_s), not taken as they are.
TEST(RenderCommand, ASimulatedSampleRendersAsItWasMeasured) {
  TempDir dir;
  nlohmann::json inset = nlohmann::json::parse(ReadText(Fixture("materials/green.json")));
  inset["name"] = "green, 4x as fast";
  const double kr = inset["states"][0]["kr"].get<double>();
  for (auto& state : inset["states"]) {
    state["kr"] = 4 * state["kr"].get<double>();
    for (auto& Lambda : state["Lambda"]) Lambda = 0.5 * Lambda.get<double>();
  }
  std::ofstream(dir / "inset.json") << inset.dump();
  const std::string green = Fixture("materials/green.json").string();
  const CommandResult capture =
      RunPhos("capture decay --sim-material " + green + " --sim-inset " + (dir / "inset.json").string() +
              " --sim-size 32x32 --charge-s 1800 --duration-s 60 --out " + (dir / "session").string());
  ASSERT_EQ(capture.exit_code, 0) << capture.err;
  const CommandResult map = RunPhos("fit map " + (dir / "session").string() + " --out " + (dir / "map").string());
  ASSERT_EQ(map.exit_code, 0) << map.err;
  const std::string scene =
      MappedQuadScene(dir, "sample", green, R"(, "phosphor_map": "map/decay-map.exr", "initial": 1)", false);
  const CommandResult render = RunPhos("render " + scene + " --times 2 --out " + (dir / "render").string());
  ASSERT_EQ(render.exit_code, 0) << render.err;
  const render::Image image = render::ReadImage((dir / "render/frame-0000.exr").string());
  const int band = 3 + 3;  // R, G, B, then band 3 (green's peak)
  auto glow = [&](int x, int y) { return image.at(x, y)[band]; };
  // The disk fills the middle (radius a quarter of the side); the corners are the base.
  const double inside = (glow(15, 15) + glow(16, 16) + glow(15, 16) + glow(16, 15)) / 4;
  const double outside = (glow(3, 3) + glow(28, 3) + glow(3, 28) + glow(28, 28)) / 4;
  ASSERT_GT(outside, 0.0);
  const double expected = 2 * std::exp(-3 * kr * 2);
  EXPECT_NEAR(inside / outside, expected, 0.05 * expected);
}

TEST(RenderCommand, AMapOfAnotherStateCountIsOneLineAndExitTwo) {
  TempDir dir;
  WriteUniformMap(dir / "uniform.exr", 0.227f, 300.0f);
  const std::string two_states = Fixture("materials/two-state-ratio20.json").string();
  const std::string scene = MappedQuadScene(dir, "mapped", two_states, R"(, "phosphor_map": "uniform.exr")", true);
  EXPECT_TRUE(
      IsOneLineUserError(RunPhos("render " + scene + " --out " + (dir / "out").string()), "phosphor_map: the map"));
  // The same, with the material swapped in from the command line after the scene was read.
  const std::string one_state =
      MappedQuadScene(dir, "one", Fixture("materials/green.json").string(), R"(, "phosphor_map": "uniform.exr")", true);
  EXPECT_TRUE(IsOneLineUserError(
      RunPhos("render " + one_state + " --material sample=" + two_states + " --out " + (dir / "out2").string()),
      "phosphor_map: the map has 1 state(s)"));
}

}  // namespace
}  // namespace phos::testing
