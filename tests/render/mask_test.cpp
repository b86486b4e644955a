// Phosphor masks (glow paint on a base): a mask's bare texels carry no
// state, and the painted ones glow by their share of paint, in the direct
// and the path transports. The mask is a PNG written here with a random
// pattern of bare, partly and fully painted cells, one per texel of a quad
// whose UV map spans it; the counts and the glow are worked out from the
// pattern, not from phos.

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

#include <OpenImageIO/imageio.h>
#include <nlohmann/json.hpp>

#include "phos/render/geometry.h"
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

Scene MaskedScene(const MaskedQuad& quad, double kr, double r0) {
  Scene scene = EmptyScene(64, 64);
  scene.camera.keys = {{0, Vec3(0.5, 2, 0.501), Vec3(0.5, 0, 0.5)}};
  scene.camera.fov_deg = 24;  // sees only the quad
  Object object = MakeObject("sign", LoadMesh(quad.obj, "", "test"), 0.5,
                             UniformPhosphor(kr, std::vector<double>(8, 0.1), {0, 0, 1, 2, 1, 0, 0, 0}));
  object.phosphor_mask = quad.png;
  object.texels = "uv";
  object.uv_resolution = kCells;
  object.initial = {InitialState::Kind::kUniform, r0};
  scene.objects.push_back(object);
  return scene;
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
  const CameraRays camera(scene, 0);
  const Mesh& mesh = *scene.objects[0].mesh;
  int checked_bare = 0, checked_painted = 0;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      const Hit hit = geometry.Intersect(camera.origin(), camera.Direction(x + 0.5f, y + 0.5f));
      ASSERT_TRUE(hit);
      const Eigen::Vector3i& t = mesh.uv_triangles[hit.triangle];
      const Eigen::Vector2f uv =
          (1 - hit.b1 - hit.b2) * mesh.uvs[t[0]] + hit.b1 * mesh.uvs[t[1]] + hit.b2 * mesh.uvs[t[2]];
      // Pixels whose footprint could straddle two cells are left out.
      const Eigen::Vector2f in_cell = uv * kCells - (uv * kCells).array().floor().matrix();
      if ((in_cell.array() < 0.25f).any() || (in_cell.array() > 0.75f).any()) continue;
      const double expected = MaskAt(quad, uv.x(), uv.y()) * Lp3;
      ASSERT_NEAR(d.at(x, y)[3], expected, 1e-5) << x << "," << y;
      ASSERT_NEAR(p.at(x, y)[3], expected, 1e-5) << x << "," << y;
      (expected == 0 ? checked_bare : checked_painted)++;
    }
  EXPECT_GT(checked_bare, 100);
  EXPECT_GT(checked_painted, 100);
}

TEST(PhosphorMask, BadMasksAreOneLine) {
  const MaskedQuad quad = WriteMaskedQuad("mask_bad");
  nlohmann::json json = ReadJsonFile(phos::testing::Fixture("scenes/cornell-phosphor.json"));
  for (auto& object : json["objects"])
    for (const char* key : {"mesh", "phosphor"})
      if (object.contains(key))
        object[key] = (std::filesystem::path(phos::testing::Fixture("scenes")) / object[key].get<std::string>()).string();
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

}  // namespace
}  // namespace phos::render
