// Frames rendered in ranges (phos render --frames / --task, from the states
// of --solve-only --checkpoints; docs/scale.md) equal the same frames of one
// sequential run bit for bit, for the path tracer, with moving light and
// media, and with glow-on-glow; a finished range is not rendered again.

#include <gtest/gtest.h>

#include <map>

#include <nlohmann/json.hpp>

#include "phos/render/renderer.h"
#include "test_util.h"

namespace phos::testing {
namespace {

// The pixels of every frame-NNNN.exr of a folder, by name.
std::map<std::string, LargeTable<float>> Frames(const std::filesystem::path& dir) {
  std::map<std::string, LargeTable<float>> frames;
  for (const auto& entry : std::filesystem::directory_iterator(dir))
    if (entry.path().extension() == ".exr") frames[entry.path().filename().string()] = render::ReadImage(entry.path()).pixels;
  return frames;
}

// One run, then the solver pass and `tasks` ranges into another folder: the
// same frames (the EXRs' pixels; their headers differ only in the date
// OpenImageIO writes).
void ExpectRangesEqualOneRun(const std::string& scene, const std::string& options, int tasks) {
  TempDir whole, ranges, states;
  const CommandResult one = RunPhos("render " + scene + " --out " + whole.path().string() + " " + options);
  ASSERT_EQ(one.exit_code, 0) << one.err;
  const CommandResult solve = RunPhos("render " + scene + " --solve-only --checkpoints " + states.path().string() +
                                      " --tasks " + std::to_string(tasks) + " " + options + " --json");
  ASSERT_EQ(solve.exit_code, 0) << solve.err;
  EXPECT_EQ(nlohmann::json::parse(solve.out)["checkpoints"].size(), static_cast<std::size_t>(tasks));
  // In reverse order: no range leans on another's leftovers.
  for (int i = tasks - 1; i >= 0; --i) {
    const CommandResult r = RunPhos("render " + scene + " --out " + ranges.path().string() + " --task " +
                                    std::to_string(i) + "/" + std::to_string(tasks) + " --checkpoints " +
                                    states.path().string() + " " + options);
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  const auto expected = Frames(whole.path()), got = Frames(ranges.path());
  ASSERT_GE(expected.size(), 3u);
  ASSERT_EQ(got.size(), expected.size());
  for (const auto& [name, pixels] : expected) {
    ASSERT_TRUE(got.count(name)) << name;
    EXPECT_TRUE(got.at(name) == pixels) << scene << ": " << name << " differs";
  }
  // A range in the middle, without states, advanced from the scene's start: the same too.
  TempDir middle;
  const CommandResult m = RunPhos("render " + scene + " --out " + middle.path().string() + " --frames 1:3 " + options);
  ASSERT_EQ(m.exit_code, 0) << m.err;
  for (const auto& [name, pixels] : Frames(middle.path())) EXPECT_TRUE(expected.at(name) == pixels) << name;
}

TEST(RenderRanges, PathTracedCornellBoxAcrossLightsOut) {
  ExpectRangesEqualOneRun(Fixture("scenes/cornell-phosphor.json").string(),
                          "--times 5,20,31,45,60 --width 20 --height 16 --transport path --spp 2", 3);
}

TEST(RenderRanges, PhosphorescentDustSweptByMovingSheets) {
  ExpectRangesEqualOneRun(Fixture("scenes/dust-sheets.json").string(), "--times 1,2,3.6,5 --width 24 --height 18", 2);
}

TEST(RenderRanges, GlowOnGlow) {
  // The Cornell box with phosphor_irradiance: the walls' glow charges the others.
  nlohmann::json scene = nlohmann::json::parse(ReadText(Fixture("scenes/cornell-phosphor.json")));
  scene["render"]["phosphor_irradiance"] = true;
  scene["texel_size_m"] = 0.04;
  for (auto& object : scene["objects"]) {
    object["mesh"] = Fixture("scenes/meshes/cornell.obj").string();
    if (!object.contains("phosphor")) continue;
    object["phosphor"] = (Fixture("scenes") / object["phosphor"].get<std::string>()).string();
    object["unknown_ke"] = "zero";  // the glow reaches bands whose ke the presets leave unmeasured
  }
  TempDir dir;
  WriteText(dir / "glow.json", scene.dump());
  ExpectRangesEqualOneRun((dir / "glow.json").string(), "--times 10,25,35,50 --width 16 --height 12 --transport dss",
                          2);
}

TEST(RenderRanges, EveryFrameHasItsOwnNoise) {
  // Two frames at the same time: the same light, different samples (the seed
  // mixes in the frame), so averaging frames averages noise.
  TempDir dir;
  const CommandResult r = RunPhos("render " + Fixture("scenes/cornell-phosphor.json").string() + " --out " +
                                  dir.path().string() + " --times 40,40 --width 16 --height 16 --transport path --spp 1");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(render::ReadImage(dir / "frame-0000.exr").pixels, render::ReadImage(dir / "frame-0001.exr").pixels);
}

TEST(RenderRanges, AFinishedRangeIsNotRenderedAgain) {
  TempDir dir;
  const std::string base = "render " + Fixture("scenes/cornell-phosphor.json").string() + " --out " +
                           dir.path().string() + " --times 10,40,60 --height 12 --task 1/2";
  const CommandResult first = RunPhos(base);
  ASSERT_EQ(first.exit_code, 0) << first.err;
  const auto done = dir / "done" / "task-1-of-2.json";
  ASSERT_TRUE(std::filesystem::exists(done));
  const auto written = std::filesystem::last_write_time(dir / "frame-0001.exr");
  std::filesystem::remove(dir / "frame-0002.exr");  // would come back if the range ran again
  const CommandResult again = RunPhos(base);
  ASSERT_EQ(again.exit_code, 0) << again.err;
  EXPECT_NE(again.out.find("nothing to do"), std::string::npos) << again.out;
  EXPECT_FALSE(std::filesystem::exists(dir / "frame-0002.exr"));
  EXPECT_EQ(std::filesystem::last_write_time(dir / "frame-0001.exr"), written);
  // Other inputs (another size) are another task: it runs.
  const CommandResult other = RunPhos(base + " --width 10");
  ASSERT_EQ(other.exit_code, 0) << other.err;
  EXPECT_TRUE(std::filesystem::exists(dir / "frame-0002.exr"));
  EXPECT_EQ(render::ReadImage(dir / "frame-0002.exr").width, 10);
}

// The same options on an edited scene, or with an edited material, are
// another range's inputs: it runs (it said "nothing to do" and kept the
// frames of the scene before the edit).
TEST(RenderRanges, AnEditedSceneOrMaterialIsRenderedAgain) {
  TempDir dir, out;
  nlohmann::json scene = nlohmann::json::parse(ReadText(Fixture("scenes/cornell-phosphor.json")));
  // The box's walls are groups of one OBJ (cornell.obj#left, ...), copied here to be edited.
  std::string mesh;
  for (auto& object : scene["objects"])
    if (object.contains("mesh")) {
      mesh = object["mesh"].get<std::string>();
      object["mesh"] = (dir / "box.obj").string();
    }
  ASSERT_FALSE(mesh.empty());
  std::filesystem::copy_file(Fixture("scenes") / mesh, dir / "box.obj");
  std::filesystem::copy_file(Fixture("materials/green.json"), dir / "paint.json");
  for (auto& object : scene["objects"])
    if (object.contains("phosphor")) object["phosphor"] = (dir / "paint.json").string();
  WriteText(dir / "scene.json", scene.dump());
  const std::string command =
      "render " + (dir / "scene.json").string() + " --out " + out.path().string() + " --times 10,40 --height 12 --frames 1:2";
  ASSERT_EQ(RunPhos(command).exit_code, 0);
  const CommandResult again = RunPhos(command);
  EXPECT_NE(again.out.find("nothing to do"), std::string::npos) << again.out;
  // The scene edited: a darker floor.
  for (auto& object : scene["objects"])
    if (!object.contains("phosphor")) object["albedo"] = 0.1;
  WriteText(dir / "scene.json", scene.dump());
  const CommandResult edited = RunPhos(command);
  ASSERT_EQ(edited.exit_code, 0) << edited.err;
  EXPECT_EQ(edited.out.find("nothing to do"), std::string::npos) << edited.out;
  EXPECT_NE(RunPhos(command).out.find("nothing to do"), std::string::npos);
  // The material edited: a slower paint.
  nlohmann::json paint = nlohmann::json::parse(ReadText(dir / "paint.json"));
  paint["states"][0]["kr"] = paint["states"][0]["kr"].get<double>() / 2;
  WriteText(dir / "paint.json", paint.dump());
  const CommandResult repainted = RunPhos(command);
  ASSERT_EQ(repainted.exit_code, 0) << repainted.err;
  EXPECT_EQ(repainted.out.find("nothing to do"), std::string::npos) << repainted.out;
  // The mesh edited (a comment added): its groups' file is read by content too.
  WriteText(dir / "box.obj", ReadText(dir / "box.obj") + "# moved nothing, but the file changed\n");
  const CommandResult remeshed = RunPhos(command);
  ASSERT_EQ(remeshed.exit_code, 0) << remeshed.err;
  EXPECT_EQ(remeshed.out.find("nothing to do"), std::string::npos) << remeshed.out;
}

// RFC 4648 base64 (a glTF data: URI's bytes), for moving a buffer to a file.
std::string Base64Decode(const std::string& text) {
  const std::string alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string bytes;
  unsigned bits = 0;
  int count = 0;
  for (char c : text) {
    const std::size_t v = alphabet.find(c);
    if (v == std::string::npos) break;  // '=' padding ends it
    bits = (bits << 6) | static_cast<unsigned>(v);
    count += 6;
    if (count >= 8) {
      count -= 8;
      bytes.push_back(static_cast<char>((bits >> count) & 0xFF));
    }
  }
  return bytes;
}

// The files a mesh leads to are inputs too: an OBJ's .mtl and a glTF's
// external buffer (.bin), edited between runs, make the range run again.
TEST(RenderRanges, AnEditedMtlOrGltfBufferIsRenderedAgain) {
  TempDir dir, out;
  nlohmann::json scene = nlohmann::json::parse(ReadText(Fixture("scenes/cornell-phosphor.json")));
  // The box's OBJ, copied with a material library.
  for (auto& object : scene["objects"])
    if (object.contains("mesh")) {
      WriteText(dir / "box.obj", "mtllib box.mtl\n" + ReadText(Fixture("scenes") / object["mesh"].get<std::string>()));
      object["mesh"] = (dir / "box.obj").string();
    }
  WriteText(dir / "box.mtl", "newmtl white\nKd 0.8 0.8 0.8\n");
  for (auto& object : scene["objects"])
    if (object.contains("phosphor"))
      object["phosphor"] = (Fixture("scenes") / object["phosphor"].get<std::string>()).string();
  // The still life's pedestal, its buffer moved from a data: URI to a file of its own.
  nlohmann::json gltf = nlohmann::json::parse(ReadText(Fixture("scenes/meshes/pedestal.gltf")));
  const std::string uri = gltf["buffers"][0]["uri"].get<std::string>();
  const std::string prefix = "data:application/octet-stream;base64,";
  ASSERT_EQ(uri.rfind(prefix, 0), 0u);
  WriteText(dir / "pedestal.bin", Base64Decode(uri.substr(prefix.size())));
  gltf["buffers"][0]["uri"] = "pedestal.bin";
  WriteText(dir / "pedestal.gltf", gltf.dump());
  nlohmann::json pedestal = {{"name", "pedestal"}, {"mesh", (dir / "pedestal.gltf").string()}, {"albedo", 0.5}};
  pedestal["transform"] = {{"translate", {0.4, 0.1, 0.2}}, {"scale", 0.1}};
  scene["objects"].push_back(pedestal);
  WriteText(dir / "scene.json", scene.dump());
  const std::string command =
      "render " + (dir / "scene.json").string() + " --out " + out.path().string() + " --times 10,40 --height 12 --frames 1:2";
  const CommandResult first = RunPhos(command);
  ASSERT_EQ(first.exit_code, 0) << first.err;
  EXPECT_NE(RunPhos(command).out.find("nothing to do"), std::string::npos);
  WriteText(dir / "box.mtl", "newmtl white\nKd 0.7 0.7 0.7\n");
  const CommandResult remtl = RunPhos(command);
  ASSERT_EQ(remtl.exit_code, 0) << remtl.err;
  EXPECT_EQ(remtl.out.find("nothing to do"), std::string::npos) << remtl.out;
  EXPECT_NE(RunPhos(command).out.find("nothing to do"), std::string::npos);
  std::string buffer = ReadText(dir / "pedestal.bin");
  buffer[3] = static_cast<char>(buffer[3] ^ 1);  // its first vertex's x: -0.5 to -0.125
  WriteText(dir / "pedestal.bin", buffer);
  const CommandResult rebuffered = RunPhos(command);
  ASSERT_EQ(rebuffered.exit_code, 0) << rebuffered.err;
  EXPECT_EQ(rebuffered.out.find("nothing to do"), std::string::npos) << rebuffered.out;
}

TEST(RenderRanges, BadRangesAndStatesAreOneLineErrors) {
  TempDir dir, states;
  const std::string scene = Fixture("scenes/cornell-phosphor.json").string();
  const std::string out = " --out " + dir.path().string() + " --times 10,40,60 --width 8 --height 8";
  CommandResult r = RunPhos("render " + scene + out + " --frames 2:9");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--frames: expected 0 <= FIRST < END <= 3"), std::string::npos) << r.err;
  r = RunPhos("render " + scene + out + " --task 3/3");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--task: expected i/N"), std::string::npos) << r.err;
  r = RunPhos("render " + scene + " --solve-only --times 10,40,60");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--checkpoints"), std::string::npos) << r.err;
  // A state cut short (a torn copy) is named, not read.
  r = RunPhos("render " + scene + " --solve-only --checkpoints " + states.path().string() +
              " --tasks 2 --times 10,40,60 --width 8 --height 8");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto state = states / "state-000001.bin";
  ASSERT_TRUE(std::filesystem::exists(state)) << r.out;
  // A state of other times is refused.
  r = RunPhos("render " + scene + " --out " + dir.path().string() +
              " --times 10,41,60 --width 8 --height 8 --task 1/2 --checkpoints " + states.path().string());
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("state-000001.bin: time_s: is the state at 40 s, but frame 1"), std::string::npos) << r.err;
  std::filesystem::resize_file(state, std::filesystem::file_size(state) - 4);
  r = RunPhos("render " + scene + out + " --task 1/2 --checkpoints " + states.path().string());
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("state-000001.bin: is shorter than its header says"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace phos::testing
