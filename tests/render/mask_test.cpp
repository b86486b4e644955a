// Phosphors that vary across a surface.
// Masks (glow paint on a base): a mask's bare texels carry no state, and the
// painted ones glow by their share of paint, in the direct and the path
// transports. The mask is a PNG written here with a random pattern of bare,
// partly and fully painted cells, one per texel of a quad whose UV map spans
// it; the counts and the glow are worked out from the pattern, not from phos.
// Maps (a `phos fit map` EXR as the phosphor): each texel decays at its
// pixel's rate and glows by its pixel's amplitude over the map's median; the
// map is written here at random, the expectations worked out from it.

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <random>

#include <OpenImageIO/imagebuf.h>

#include <OpenImageIO/imageio.h>
#include <nlohmann/json.hpp>

#include "phos/render/geometry.h"
#include "phos/render/phosphor_map.h"
#include "phos/render/renderer.h"
#include "phos/render/scene.h"
#include "phos/render/solver.h"
#include "phos/util/error.h"
#include "phos/util/json.h"
#include "render/scene_util.h"
#include "test_util.h"

namespace phos::render {
namespace {

using phos::testing::EmptyScene;
using phos::testing::MakeObject;
using phos::testing::UniformPhosphor;

constexpr int kCells = 16;

struct MaskedQuad {
  std::filesystem::path dir, obj, png;
  std::vector<std::uint8_t> pixels;  // [row * kCells + column], the image's rows from the top
  int bare = 0;
};

// A unit quad in y = 0 facing +y, its UV (u, v) = (x, z), as an OBJ (whose
// v = 0 is the image's bottom row), and a kCells^2 mask with 40% bare cells.
MaskedQuad WriteMaskedQuad(const std::string& name, bool all_bare = false) {
  MaskedQuad quad;
  quad.dir = std::filesystem::path(::testing::TempDir()) / name;
  std::filesystem::create_directories(quad.dir);
  quad.obj = quad.dir / "quad.obj";
  std::ofstream(quad.obj) << "v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\n"
                             "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                             "f 1/1 4/4 3/3\nf 1/1 3/3 2/2\n";
  std::mt19937 random(5);
  std::uniform_real_distribution<double> uniform;
  const std::uint8_t levels[] = {64, 128, 255};
  for (int i = 0; i < kCells * kCells; ++i) {
    const bool bare = all_bare || uniform(random) < 0.4;
    quad.pixels.push_back(bare ? 0 : levels[static_cast<int>(uniform(random) * 3) % 3]);
    quad.bare += bare;
  }
  quad.png = quad.dir / "mask.png";
  auto out = OIIO::ImageOutput::create(quad.png.string());
  OIIO::ImageSpec spec(kCells, kCells, 1, OIIO::TypeDesc::UINT8);
  EXPECT_TRUE(out->open(quad.png.string(), spec));
  EXPECT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, quad.pixels.data()));
  out->close();
  return quad;
}

// The mask's value at UV (u, v): the OBJ's v runs up from the bottom row.
float MaskAt(const MaskedQuad& quad, float u, float v) {
  const int column = std::clamp(static_cast<int>(u * kCells), 0, kCells - 1);
  const int row = kCells - 1 - std::clamp(static_cast<int>(v * kCells), 0, kCells - 1);
  return quad.pixels[row * kCells + column] / 255.0f;
}

// The quad with `material` in states r0 over its kCells^2 UV texels, seen
// from above by a 64 x 64 camera that sees only it.
Scene QuadScene(const MaskedQuad& quad, std::shared_ptr<const Material> material, double r0) {
  Scene scene = EmptyScene(64, 64);
  scene.camera.keys = {{0, Vec3(0.5, 2, 0.501), Vec3(0.5, 0, 0.5)}};
  scene.camera.fov_deg = 24;
  Object object = MakeObject("sign", LoadMesh(quad.obj, "", "test"), 0.5, std::move(material));
  object.texels = "uv";
  object.uv_resolution = kCells;
  object.initial = {InitialState::Kind::kUniform, r0};
  scene.objects.push_back(object);
  return scene;
}

Scene MaskedScene(const MaskedQuad& quad, double kr, double r0) {
  Scene scene = QuadScene(quad, UniformPhosphor(kr, std::vector<double>(8, 0.1), {0, 0, 1, 2, 1, 0, 0, 0}), r0);
  scene.objects[0].phosphor_mask = quad.png;
  return scene;
}

// Calls f(x, y, uv) for each pixel of QuadScene's view at time t whose ray
// meets the quad well inside one cell: a pixel whose footprint could
// straddle two cells is left out.
template <typename F>
void ForEachPixelInsideACell(const Scene& scene, const SceneGeometry& geometry, double t, F&& f) {
  const CameraRays camera(scene, t);
  const Mesh& mesh = *scene.objects[0].mesh;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      const Hit hit = geometry.Intersect(camera.origin(), camera.Direction(x + 0.5f, y + 0.5f));
      ASSERT_TRUE(hit);
      const Eigen::Vector3i& tri = mesh.uv_triangles[hit.triangle];
      const Eigen::Vector2f uv =
          (1 - hit.b1 - hit.b2) * mesh.uvs[tri[0]] + hit.b1 * mesh.uvs[tri[1]] + hit.b2 * mesh.uvs[tri[2]];
      const Eigen::Vector2f in_cell = uv * kCells - (uv * kCells).array().floor().matrix();
      if ((in_cell.array() < 0.25f).any() || (in_cell.array() > 0.75f).any()) continue;
      f(x, y, uv);
    }
}

TEST(PhosphorMask, BareTexelsCarryNoStateAndPaintedOnesGlowByTheirShare) {
  const MaskedQuad quad = WriteMaskedQuad("mask_glow");
  const double kr = 0.2, r0 = 0.5, Lp3 = 2 * kr * r0;  // Eq. 8.2, band 3 of Lambda
  const Scene scene = MaskedScene(quad, kr, r0);
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  const TexelAtlas::ObjectTexels& texels = solver.atlas().objects()[0];
  EXPECT_GT(quad.bare, 50);
  EXPECT_EQ(texels.masked_out, static_cast<std::size_t>(quad.bare));
  EXPECT_EQ(texels.count, static_cast<std::size_t>(kCells * kCells - quad.bare));
  EXPECT_EQ(solver.atlas().total_texels(), texels.count);

  FrameOptions direct;
  FrameOptions path;
  path.transport = Transport::kPath;
  path.spp = 4;
  const Image d = RenderBands(geometry, &solver, direct);
  const Image p = RenderBands(geometry, &solver, path);
  int checked_bare = 0, checked_painted = 0;
  ForEachPixelInsideACell(scene, geometry, 0, [&](int x, int y, const Eigen::Vector2f& uv) {
    const double expected = MaskAt(quad, uv.x(), uv.y()) * Lp3;
    ASSERT_NEAR(d.at(x, y)[3], expected, 1e-5) << x << "," << y;
    ASSERT_NEAR(p.at(x, y)[3], expected, 1e-5) << x << "," << y;
    (expected == 0 ? checked_bare : checked_painted)++;
  });
  EXPECT_GT(checked_bare, 100);
  EXPECT_GT(checked_painted, 100);
}

TEST(PhosphorMask, BadMasksAreOneLine) {
  const MaskedQuad quad = WriteMaskedQuad("mask_bad");
  nlohmann::json json = ReadJsonFile(phos::testing::Fixture("scenes/cornell-phosphor.json"));
  for (auto& object : json["objects"])
    for (const char* key : {"mesh", "phosphor"})
      if (object.contains(key))
        object[key] =
            (std::filesystem::path(phos::testing::Fixture("scenes")) / object[key].get<std::string>()).string();
  auto error = [&](const std::function<void(nlohmann::json&)>& edit) {
    nlohmann::json edited = json;
    edit(edited);
    try {
      const Scene scene = SceneFromJson(edited, quad.dir, "sign.json");
      SceneGeometry geometry(scene);
      CoupledSolver solver(scene, geometry);
    } catch (const UserError& e) {
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  // The Cornell walls have no UV map.
  int phosphor = -1;
  for (std::size_t i = 0; i < json["objects"].size(); ++i)
    if (json["objects"][i].contains("phosphor")) phosphor = static_cast<int>(i);
  ASSERT_GE(phosphor, 0);
  EXPECT_NE(error([&](nlohmann::json& j) { j["objects"][phosphor]["phosphor_mask"] = "mask.png"; }).find("UV map"),
            std::string::npos);
  nlohmann::json sign = {{"name", "sign"},
                         {"mesh", quad.obj.string()},
                         {"albedo", 0.5},
                         {"phosphor", json["objects"][phosphor]["phosphor"]},
                         {"phosphor_mask", "mask.png"}};
  EXPECT_EQ(error([&](nlohmann::json& j) { j["objects"].push_back(sign); }), "accepted");
  EXPECT_NE(error([&](nlohmann::json& j) {
              j["objects"].push_back(sign);
              j["objects"].back()["phosphor_mask"] = "missing.png";
            }).find("missing.png"),
            std::string::npos);
  EXPECT_NE(error([&](nlohmann::json& j) {
              j["objects"].push_back(sign);
              j["objects"].back().erase("phosphor");
            }).find("only a phosphor"),
            std::string::npos);
  EXPECT_NE(error([&](nlohmann::json& j) {
              j["objects"].push_back(sign);
              j["objects"].back()["texels"] = "auto";
            }).find("uv"),
            std::string::npos);
  const MaskedQuad bare = WriteMaskedQuad("mask_all_bare", /*all_bare=*/true);
  EXPECT_NE(error([&](nlohmann::json& j) {
              j["objects"].push_back(sign);
              j["objects"].back()["phosphor_mask"] = bare.png.string();
            }).find("is 0 wherever"),
            std::string::npos);
  std::ofstream(quad.dir / "not-an-image.png") << "text";
  EXPECT_NE(error([&](nlohmann::json& j) {
              j["objects"].push_back(sign);
              j["objects"].back()["phosphor_mask"] = "not-an-image.png";
            }).find("not an image"),
            std::string::npos);
}

// Glow on glow (phosphor_irradiance): a masked phosphor lights another by
// the paint it has, not as if painted whole. Over the same quad, a uniform
// half coverage (every cell 128 of 255) puts 128/255 of the unmasked quad's
// glow on a small phosphor above its middle, and paint on the left 7 of 16
// columns puts what the integral of cos cos / d^2 over those columns says.
// The old patch mean (over the painted texels only, whole) gave all of it
// for the first and the left half's share (8 columns) for the second.
void WriteMaskPng(const std::filesystem::path& png, const std::function<std::uint8_t(int, int)>& value) {
  std::vector<std::uint8_t> pixels;
  for (int row = 0; row < kCells; ++row)
    for (int column = 0; column < kCells; ++column) pixels.push_back(value(row, column));
  auto out = OIIO::ImageOutput::create(png.string());
  OIIO::ImageSpec spec(kCells, kCells, 1, OIIO::TypeDesc::UINT8);
  ASSERT_TRUE(out && out->open(png.string(), spec) && out->write_image(OIIO::TypeDesc::UINT8, pixels.data()));
  out->close();
}

TEST(PhosphorMask, AMaskedPhosphorLightsOthersByItsShareOfPaint) {
  const MaskedQuad quad = WriteMaskedQuad("mask_glow_on_glow");
  WriteMaskPng(quad.dir / "half.png", [](int, int) { return std::uint8_t{128}; });
  WriteMaskPng(quad.dir / "left.png", [](int, int column) { return std::uint8_t(column < 7 ? 255 : 0); });
  auto glow_on_receiver = [&](const std::optional<std::filesystem::path>& mask) {
    Scene scene = MaskedScene(quad, 0.2, 0.5);
    scene.settings.phosphor_irradiance = true;
    scene.objects[0].phosphor_mask = mask;
    Mesh receiver = phos::testing::DiskFacingDown(0.05f, 0.8f, 12);
    for (Eigen::Vector3f& p : receiver.positions) p += Eigen::Vector3f(0.5f, 0, 0.5f);
    Object disk = MakeObject("receiver", receiver, 0.5, scene.objects[0].phosphor);
    disk.texels = "auto";
    scene.objects.push_back(disk);
    SceneGeometry geometry(scene);
    CoupledSolver solver(scene, geometry);
    double E = 0;
    const std::size_t n = solver.atlas().objects()[1].count;
    for (std::size_t k = 0; k < n; ++k) E += solver.TexelGlowIrradiance(1, k)[3];
    return E / static_cast<double>(n);
  };
  const double whole = glow_on_receiver(std::nullopt);
  ASSERT_GT(whole, 0.0);
  EXPECT_NEAR(glow_on_receiver(quad.dir / "half.png") / whole, 128.0 / 255.0, 1e-4);
  // The receiver's middle, (0.5, 0.8, 0.5) facing down, sees the quad's
  // point (x, 0, z) with cos cos / d^2 = 0.8^2 / d^4: summed over x < 7/16 and over all.
  double left = 0, all = 0;
  constexpr int kSteps = 800;
  for (int i = 0; i < kSteps; ++i)
    for (int k = 0; k < kSteps; ++k) {
      const double x = (i + 0.5) / kSteps, z = (k + 0.5) / kSteps;
      const double d2 = (x - 0.5) * (x - 0.5) + 0.64 + (z - 0.5) * (z - 0.5);
      all += 0.64 / (d2 * d2);
      if (x < 7.0 / 16) left += 0.64 / (d2 * d2);
    }
  EXPECT_NEAR(glow_on_receiver(quad.dir / "left.png") / whole, left / all, 0.01);
}

// A random decay map of kCells^2 pixels as `phos fit map` writes it: kr,
// amplitude.R/G/B, background.R/G/B, rms, and with two states kr2 and
// amplitude2.R/G/B. About 20% of the pixels have no decay (kr NaN), one has
// a finite kr but no amplitude, and with two states a third keep one state
// (kr2 NaN, amplitude2 0).
struct RandomMap {
  std::filesystem::path exr;
  int states = 1;
  std::vector<float> kr[2], amplitude[2];  // per pixel, the image's rows from the top; amplitude: sum over channels
  int no_decay = 0;
};

RandomMap WriteRandomMap(const std::filesystem::path& dir, int states, unsigned seed, bool tile = false) {
  RandomMap map;
  map.states = states;
  map.exr = dir / ("map-" + std::to_string(states) + (tile ? "-tile" : "") + ".exr");
  std::vector<std::string> names = {"kr",           "amplitude.R",  "amplitude.G",  "amplitude.B",
                                    "background.R", "background.G", "background.B", "rms"};
  if (states == 2) names.insert(names.end(), {"kr2", "amplitude2.R", "amplitude2.G", "amplitude2.B"});
  const int nch = static_cast<int>(names.size()), n = kCells * kCells;
  std::mt19937 random(seed);
  std::uniform_real_distribution<float> uniform;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::vector<float> pixels(static_cast<std::size_t>(n) * nch, 0.0f);
  for (int i = 0; i < 2; ++i) {
    map.kr[i].assign(n, nan);
    map.amplitude[i].assign(n, 0.0f);
  }
  for (int p = 0; p < n; ++p) {
    float* px = &pixels[static_cast<std::size_t>(p) * nch];
    const bool decays = uniform(random) >= 0.2f;
    px[0] = decays ? std::exp(std::log(0.01f) + uniform(random) * std::log(100.0f)) : nan;  // 0.01 to 1 /s
    for (int c = 0; c < 3; ++c) px[1 + c] = decays ? 50 + 400 * uniform(random) : 0.0f;
    if (p == 7) {  // a finite rate with nothing emitted: no decay either
      px[0] = 0.1f;
      px[1] = px[2] = px[3] = 0;
    }
    px[7] = 1;
    if (decays && p != 7) {
      map.kr[0][p] = px[0];
      map.amplitude[0][p] = px[1] + px[2] + px[3];
    } else {
      ++map.no_decay;
    }
    if (states == 2) {
      const bool two = decays && p != 7 && uniform(random) >= 0.3f;
      px[8] = two ? px[0] * (2 + 20 * uniform(random)) : nan;
      for (int c = 0; c < 3; ++c) px[9 + c] = two ? 100 * uniform(random) : 0.0f;
      if (two) {
        map.kr[1][p] = px[8];
        map.amplitude[1][p] = px[9] + px[10] + px[11];
      }
    }
  }
  OIIO::ImageSpec spec(kCells, kCells, nch, OIIO::TypeDesc::FLOAT);
  spec.channelnames = names;
  if (tile) spec.attribute("phos:first_row", 0);
  auto out = OIIO::ImageOutput::create(map.exr.string());
  EXPECT_TRUE(out->open(map.exr.string(), spec));
  EXPECT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, pixels.data()));
  out->close();
  return map;
}

float MedianOf(std::vector<float> values) {
  std::vector<float> finite;
  for (float v : values)
    if (v > 0) finite.push_back(v);
  std::sort(finite.begin(), finite.end());
  return finite[finite.size() / 2];
}

TEST(PhosphorMap, EachTexelDecaysAtItsPixelsRateAndGlowsByItsAmplitude) {
  const MaskedQuad quad = WriteMaskedQuad("map_glow");
  for (int states : {1, 2}) {
    SCOPED_TRACE(states);
    const RandomMap map = WriteRandomMap(quad.dir, states, 11 + states);
    // The material: Lambda_i kr_i gives the level, its kr are replaced by the map's.
    auto material = phos::testing::UniformPhosphor(0.2, std::vector<double>(8, 0.1), {0, 0, 1, 2, 1, 0, 0, 0});
    if (states == 2) {
      ExcitedState fast = material->states[0];
      fast.kr = 3.0;  // listed first: states are matched by rate, not by order
      fast.Lambda = {0, 0, 0.5, 0.25, 0, 0, 0, 0};
      material->states.insert(material->states.begin(), fast);
    }
    const double r0 = 0.5, t = 2.5;
    Scene scene = QuadScene(quad, material, r0);
    scene.objects[0].phosphor_map = std::make_shared<PhosphorMap>(ReadPhosphorMap(map.exr, "test", "phosphor_map"));
    SceneGeometry geometry(scene);
    CoupledSolver solver(scene, geometry);
    const TexelAtlas::ObjectTexels& texels = solver.atlas().objects()[0];
    // Model only what the scene requires: pixels without a decay carry no state.
    EXPECT_GT(map.no_decay, 20);
    EXPECT_EQ(texels.masked_out, static_cast<std::size_t>(map.no_decay));
    EXPECT_EQ(texels.count, static_cast<std::size_t>(kCells * kCells - map.no_decay));
    solver.AdvanceTo(t);  // no light: each state decays at its texel's rate
    if (states == 2) {
      // Over a pixel where one state sufficed, the fast state keeps the
      // material's rate (3 /s) and glows not at all.
      int checked = 0;
      for (std::size_t k = 0; k < texels.count; ++k) {
        const std::uint32_t pixel = texels.map_pixel[k];
        if (map.kr[1][pixel] > 0) continue;
        EXPECT_NEAR(solver.State(0, 0, k), r0 * std::exp(-3.0 * t), 1e-6);
        ++checked;
      }
      EXPECT_GT(checked, 20);
    }

    const float median[2] = {MedianOf(map.amplitude[0]), states == 2 ? MedianOf(map.amplitude[1]) : 1.0f};
    const ExcitedState& slow = material->states[states == 2 ? 1 : 0];
    auto expected_Lp3 = [&](int pixel) {
      if (!(map.kr[0][pixel] > 0)) return 0.0;
      double L = slow.Lambda[3] * slow.kr * map.amplitude[0][pixel] / median[0] * r0 * std::exp(-map.kr[0][pixel] * t);
      if (states == 2 && map.kr[1][pixel] > 0) {
        const ExcitedState& fast = material->states[0];
        L += fast.Lambda[3] * fast.kr * map.amplitude[1][pixel] / median[1] * r0 * std::exp(-map.kr[1][pixel] * t);
      }
      return L;
    };
    FrameOptions direct;
    FrameOptions path;
    path.transport = Transport::kPath;
    path.spp = 2;
    const Image d = RenderBands(geometry, &solver, direct);
    const Image p = RenderBands(geometry, &solver, path);
    int dark = 0, glowing = 0;
    ForEachPixelInsideACell(scene, geometry, t, [&](int x, int y, const Eigen::Vector2f& uv) {
      // The OBJ's v runs up from the image's bottom row.
      const int column = std::clamp(static_cast<int>(uv.x() * kCells), 0, kCells - 1);
      const int row = kCells - 1 - std::clamp(static_cast<int>(uv.y() * kCells), 0, kCells - 1);
      const double expected = expected_Lp3(row * kCells + column);
      ASSERT_NEAR(d.at(x, y)[3], expected, 1e-6 + 2e-6 * expected) << x << "," << y;
      ASSERT_NEAR(p.at(x, y)[3], expected, 1e-6 + 2e-6 * expected) << x << "," << y;
      (expected == 0 ? dark : glowing)++;
    });
    EXPECT_GT(dark, 100);
    EXPECT_GT(glowing, 400);
  }
}

TEST(PhosphorMap, BadMapsAreOneLine) {
  const MaskedQuad quad = WriteMaskedQuad("map_bad");
  WriteRandomMap(quad.dir, 1, 3);
  WriteRandomMap(quad.dir, 2, 4);
  WriteRandomMap(quad.dir, 1, 5, /*tile=*/true);
  const std::filesystem::path material = phos::testing::Fixture("materials/green.json");
  auto error = [&](const std::function<void(nlohmann::json&)>& edit) {
    nlohmann::json scene = {
        {"schema", "phos.scene/1"},
        {"name", "mapped"},
        {"camera", {{"position", {0.5, 2, 0.5}}, {"look_at", {0.5, 0, 0.5}}, {"width", 8}, {"height", 8}}},
        {"time", {{"start_s", 0}, {"end_s", 1}, {"fps", 1}}},
        {"lights", nlohmann::json::array()},
        {"objects",
         {{{"name", "sample"},
           {"mesh", quad.obj.string()},
           {"albedo", 0.5},
           {"phosphor", material.string()},
           {"phosphor_map", "map-1.exr"}}}}};
    edit(scene["objects"][0]);
    try {
      const Scene loaded = SceneFromJson(scene, quad.dir, "mapped.json");
      SceneGeometry geometry(loaded);
      CoupledSolver solver(loaded, geometry);
      EXPECT_EQ(solver.atlas().objects()[0].uv_resolution, loaded.objects[0].uv_resolution);
    } catch (const UserError& e) {
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("phosphor_map"), std::string::npos) << e.what();
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  auto fails_with = [&](const std::function<void(nlohmann::json&)>& edit, const std::string& part) {
    const std::string message = error(edit);
    EXPECT_NE(message.find(part), std::string::npos) << message;
  };
  EXPECT_EQ(error([](nlohmann::json&) {}), "accepted");
  fails_with([](nlohmann::json& o) { o["phosphor_map"] = "missing.exr"; }, "missing.exr");
  fails_with([](nlohmann::json& o) { o["phosphor_map"] = "mask.png"; }, "no 'kr'");
  fails_with([](nlohmann::json& o) { o["phosphor_map"] = "map-1-tile.exr"; }, "--merge");
  fails_with([](nlohmann::json& o) { o["phosphor_map"] = "map-2.exr"; }, "2 state(s) (kr2)");
  fails_with([](nlohmann::json& o) { o["uv_resolution"] = kCells + 1; }, "finer than the map's 16 x 16");
  fails_with([](nlohmann::json& o) { o.erase("phosphor"); }, "give the material");
  fails_with([](nlohmann::json& o) { o["texels"] = "auto"; }, "\"uv\"");
  // One decaying pixel's number out of range (the channels as written:
  // kr, amplitude.R, .G, .B): refused naming the pixel, never rendered NaN.
  auto with_pixel = [&](const std::string& name, int channel, float value) {
    auto in = OIIO::ImageInput::open((quad.dir / "map-1.exr").string());
    OIIO::ImageSpec spec = in->spec();
    std::vector<float> px(static_cast<std::size_t>(spec.width) * spec.height * spec.nchannels);
    in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, px.data());
    in->close();
    int p = 0;
    while (!(px[p * spec.nchannels + spec.channelindex("kr")] > 0)) ++p;
    px[p * spec.nchannels + spec.channelindex(channel == 0 ? "kr" : "amplitude.G")] = value;
    auto out = OIIO::ImageOutput::create((quad.dir / name).string());
    out->open((quad.dir / name).string(), spec);
    out->write_image(OIIO::TypeDesc::FLOAT, px.data());
    out->close();
    return "pixel (" + std::to_string(p % spec.width) + ", " + std::to_string(p / spec.width) + ")";
  };
  const float inf = std::numeric_limits<float>::infinity();
  std::string at = with_pixel("kr-1e30.exr", 0, 1e30f);
  fails_with([](nlohmann::json& o) { o["phosphor_map"] = "kr-1e30.exr"; }, at + ": kr 1e+30 /s is above");
  with_pixel("kr-inf.exr", 0, inf);
  fails_with([](nlohmann::json& o) { o["phosphor_map"] = "kr-inf.exr"; }, "is above the largest rate");
  at = with_pixel("amplitude-inf.exr", 1, inf);
  fails_with([](nlohmann::json& o) { o["phosphor_map"] = "amplitude-inf.exr"; }, at + ": amplitude.G is inf");
  with_pixel("amplitude-3e38.exr", 1, 3e38f);
  fails_with([](nlohmann::json& o) { o["phosphor_map"] = "amplitude-3e38.exr"; }, "times the map's typical pixel");
  with_pixel("amplitude-huge-sum.exr", 1, 3.4e38f);
  EXPECT_NE(error([](nlohmann::json& o) { o["phosphor_map"] = "amplitude-huge-sum.exr"; }), "accepted");
  std::ofstream(quad.dir / "not-an-image.exr") << "text";
  fails_with([](nlohmann::json& o) { o["phosphor_map"] = "not-an-image.exr"; }, "not an image");
}

}  // namespace
}  // namespace phos::render
