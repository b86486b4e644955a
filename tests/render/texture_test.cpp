// Albedo textures (docs/render.md, "Textures") against closed forms:
//  - the spectral upsampling: white is 1 in every band, every band lies
//    between the smallest and largest of r, g, b;
//  - the textured-plane fixture (a 2 x 2 checker of known sRGB colours,
//    scripts/make_textured_fixture.py) under a point light: each quadrant's
//    centre is albedo(u, v) E / pi in the direct, path and dss transports,
//    and an OBJ/MTL map_Kd of the same checker (v up) renders the same;
//  - a glTF metallicRoughnessTexture: each half of a two-valued texture
//    renders as a plane of that half's constant gloss (direct and path), and
//    the scene's factors multiply it;
//  - bad input names the file and the field.

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <map>
#include <optional>
#include <random>
#include <set>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>
#include <nlohmann/json.hpp>

#include "phos/render/surface_textures.h"
#include "phos/render/geometry.h"
#include "phos/render/renderer.h"
#include "phos/render/spectral_upsampling.h"
#include "phos/util/error.h"
#include "phos/util/json.h"
#include "render/scene_util.h"
#include "test_util.h"

namespace phos::render {
namespace {

using phos::testing::Fixture;
using phos::testing::ReadText;
using phos::testing::TempDir;

// The decode against IEC 61966-2-1's formula in double, at every 8-bit code
// and between them.
TEST(SpectralUpsampling, SrgbToLinearIsTheStandardsCurve) {
  for (int i = 0; i <= 255 * 16; ++i) {
    const double encoded = i / (255.0 * 16);
    const double exact = encoded <= 0.04045 ? encoded / 12.92 : std::pow((encoded + 0.055) / 1.055, 2.4);
    EXPECT_NEAR(SrgbToLinear(static_cast<float>(encoded)), exact, 2e-5 * exact + 1e-9) << encoded;
  }
  EXPECT_EQ(SrgbToLinear(0), 0);
  EXPECT_NEAR(SrgbToLinear(1), 1, 2e-5);
}

TEST(SpectralUpsampling, WhiteIsOneInEveryBandAndGreyItself) {
  for (const SpectralGrid& grid : {SpectralGrid::Paper(), SpectralGrid::Uniform(360, 830, 470)}) {
    const RgbToBands to_bands(grid);
    const std::vector<double> white = to_bands.Albedo({1, 1, 1});
    for (double v : white) EXPECT_EQ(v, 1.0);
    for (double v : to_bands.Albedo({0.3, 0.3, 0.3})) EXPECT_FLOAT_EQ(v, 0.3f);
    for (double v : to_bands.Albedo({0, 0, 0})) EXPECT_EQ(v, 0.0);
  }
}

TEST(SpectralUpsampling, EveryBandLiesBetweenTheSmallestAndLargestPrimary) {
  const RgbToBands to_bands(SpectralGrid::Uniform(380, 780, 40));
  std::mt19937 random(3);
  std::uniform_real_distribution<double> unit(0, 1);
  for (int i = 0; i < 1000; ++i) {
    const std::array<double, 3> rgb = {unit(random), unit(random), unit(random)};
    const double lo = std::min({rgb[0], rgb[1], rgb[2]}), hi = std::max({rgb[0], rgb[1], rgb[2]});
    for (double v : to_bands.Albedo(rgb)) {
      EXPECT_GE(v, lo - 1e-6);
      EXPECT_LE(v, hi + 1e-6);
    }
  }
  // Out of range input is clamped, never out of [0, 1].
  for (double v : to_bands.Albedo({2, -1, 0.5})) {
    EXPECT_GE(v, 0.0);
    EXPECT_LE(v, 1.0);
  }
  // Red is long waves, blue short: the basis follows the primaries.
  const std::vector<double> red = to_bands.Albedo({1, 0, 0}), blue = to_bands.Albedo({0, 0, 1});
  EXPECT_GT(red.back(), 0.9);
  EXPECT_LT(red.front(), 0.2);  // sRGB's red matching function has a violet lobe
  EXPECT_GT(blue.front(), 0.8);
  EXPECT_LT(blue.back(), 0.1);
}

// The fixture's quadrant colours (scripts/make_textured_fixture.py), by
// (u < 0.5 ? 0 : 1, v < 0.5 ? 0 : 1) with glTF's v = 0 at the image's top.
std::array<float, 3> QuadrantSrgb(int u_half, int v_half) {
  static const int colours[2][2][3] = {{{230, 60, 40}, {40, 180, 70}}, {{50, 80, 220}, {250, 250, 250}}};
  const int* c = colours[v_half][u_half];
  return {c[0] / 255.0f, c[1] / 255.0f, c[2] / 255.0f};
}

// albedo E / pi at the pixel seeing the centre of each quadrant of the
// plane, E from the point light (1 m above the plane's centre), for every band.
// `shown` (u_half, v_half) -> the texture's quadrant seen there; none: the same.
using QuadrantMap = std::function<std::array<int, 2>(int, int)>;
void ExpectQuadrantsAreAlbedoTimesEOverPi(const Scene& scene, const Image& image, const std::string& what,
                                          const QuadrantMap& shown = nullptr) {
  const CameraRays camera(scene, 0);
  const RgbToBands to_bands(scene.bands);
  const int nb = scene.bands.band_count();
  int checked = 0;
  for (int u_half = 0; u_half < 2; ++u_half)
    for (int v_half = 0; v_half < 2; ++v_half) {
      // u = x + 0.5, v = z + 0.5 on the plane.
      const Vec3f centre(u_half ? 0.25f : -0.25f, 0, v_half ? 0.25f : -0.25f);
      float px, py, depth;
      ASSERT_TRUE(camera.Project(centre, &px, &py, &depth));
      const int x = static_cast<int>(px), y = static_cast<int>(py);
      // Where the pixel's centre ray meets the plane, and its irradiance.
      const Vec3f d = camera.Direction(x + 0.5f, y + 0.5f);
      const Vec3f p = camera.origin() + d * (-camera.origin().y() / d.y());
      ASSERT_LT((p - centre).norm(), 0.05f);  // well inside the quadrant (0.25 m from its edges)
      const Vec3f to_light = Vec3f(0, 1, 0) - p;
      const double unit = 1.0 / to_light.norm() / to_light.squaredNorm();  // cos / d^2, cos = 1 / d
      const std::array<int, 2> seen = shown ? shown(u_half, v_half) : std::array<int, 2>{u_half, v_half};
      const std::array<float, 3> srgb = QuadrantSrgb(seen[0], seen[1]);
      const float linear[3] = {SrgbToLinear(srgb[0]), SrgbToLinear(srgb[1]), SrgbToLinear(srgb[2])};
      std::vector<float> albedo(nb);
      to_bands.Albedo(linear, albedo.data());
      for (int b = 0; b < nb; ++b) {
        const double expected = albedo[b] * scene.lights[0].E_per_band[b] * unit / M_PI;
        EXPECT_NEAR(image.at(x, y)[b], expected, 1e-4 * expected + 1e-9)
            << what << ", quadrant " << u_half << v_half << " showing " << seen[0] << seen[1] << ", band " << b;
      }
      ++checked;
    }
  EXPECT_EQ(checked, 4);
}

Scene TexturedPlane() {
  Scene scene = LoadScene(Fixture("scenes/textured-plane.json"));
  scene.camera.width = 160;  // texels magnified: a pixel covers under half a texel
  scene.camera.height = 120;
  return scene;
}

TEST(AlbedoTexture, TheFixtureIsATexturedPlaneWithItsFactor) {
  const Scene scene = TexturedPlane();
  ASSERT_TRUE(scene.objects[0].albedo_texture);
  EXPECT_EQ(scene.objects[0].albedo_texture->texture.filename(), "checker.png");
  for (double v : scene.objects[0].albedo) EXPECT_EQ(v, 1.0);  // baseColorFactor [1, 1, 1, 1]
}

TEST(AlbedoTexture, TexturedPlaneUnderAPointLightIsAlbedoTimesEOverPiInEveryTransport) {
  const Scene scene = TexturedPlane();
  SceneGeometry geometry(scene);
  ASSERT_NE(geometry.surface_textures(), nullptr);
  for (Transport transport : {Transport::kDirect, Transport::kPath, Transport::kDss}) {
    FrameOptions options = DefaultFrameOptions(scene, transport);
    options.spp = 1;  // centred: the path tracer's camera ray is the direct one, and nothing bounces back
    options.direct_spp = 1;
    ExpectQuadrantsAreAlbedoTimesEOverPi(scene, RenderBands(geometry, nullptr, options), TransportName(transport));
  }
}

TEST(AlbedoTexture, ObjMapKdWithVUpRendersAsTheGltf) {
  TempDir dir;
  std::filesystem::copy_file(Fixture("scenes/textured/checker.png"), dir / "checker.png");
  // The glTF's quad, its v turned up (OBJ's v = 0 is the image's bottom row).
  std::ofstream(dir / "plane.obj") << "mtllib plane.mtl\n"
                                      "v -0.5 0 -0.5\nv 0.5 0 -0.5\nv 0.5 0 0.5\nv -0.5 0 0.5\n"
                                      "vt 0 1\nvt 1 1\nvt 1 0\nvt 0 0\n"
                                      "usemtl checker\nf 1/1 3/3 2/2\nf 1/1 4/4 3/3\n";
  std::ofstream(dir / "plane.mtl") << "newmtl checker\nKd 1 1 1\nmap_Kd checker.png\n";
  Scene gltf = TexturedPlane();
  Scene obj = gltf;
  obj.objects[0].mesh = std::make_shared<Mesh>(LoadMesh(dir / "plane.obj", "", "test"));
  ASSERT_TRUE(obj.objects[0].mesh->base_colour);
  obj.objects[0].albedo_texture = obj.objects[0].mesh->base_colour;
  EXPECT_TRUE(obj.objects[0].albedo_texture->v_up);
  SceneGeometry gltf_geometry(gltf), obj_geometry(obj);
  const FrameOptions options = DefaultFrameOptions(gltf, Transport::kDirect);
  const Image a = RenderBands(gltf_geometry, nullptr, options), b = RenderBands(obj_geometry, nullptr, options);
  ExpectQuadrantsAreAlbedoTimesEOverPi(obj, b, "obj");
  double largest = 0;
  for (std::size_t i = 0; i < a.pixels.size(); ++i) largest = std::max<double>(largest, std::abs(a.pixels[i] - b.pixels[i]));
  EXPECT_LT(largest, 1e-5);
}

// The footprint reaches the filter: a checker of single black and white
// texels (a binary PPM, which OpenImageIO reads), seen so small that a pixel
// covers about six texels a side, must come out grey, the filtered mean (0.5
// encoded, 0.214 linear, since the decode follows the filter); a point
// lookup would give 0 or 1 per pixel.
TEST(AlbedoTexture, APixelCoveringManyTexelsSeesTheirFilteredMean) {
  TempDir dir;
  {
    std::ofstream ppm(dir / "fine.ppm", std::ios::binary);
    ppm << "P6\n64 64\n255\n";
    for (int y = 0; y < 64; ++y)
      for (int x = 0; x < 64; ++x)
        for (int c = 0; c < 3; ++c) ppm.put(static_cast<char>((x + y) % 2 ? 255 : 0));
  }
  Scene scene = TexturedPlane();
  scene.camera.width = 16;
  scene.camera.height = 12;
  BaseColour fine = *scene.objects[0].albedo_texture;
  fine.texture = dir / "fine.ppm";
  scene.objects[0].albedo_texture = fine;
  SceneGeometry geometry(scene);
  const Image image = RenderBands(geometry, nullptr, DefaultFrameOptions(scene, Transport::kDirect));
  const CameraRays camera(scene, 0);
  for (int y = 4; y < 8; ++y)
    for (int x = 6; x < 10; ++x) {
      const Vec3f d = camera.Direction(x + 0.5f, y + 0.5f);
      const Vec3f p = camera.origin() + d * (-camera.origin().y() / d.y());
      const Vec3f to_light = Vec3f(0, 1, 0) - p;
      const double unit = 1.0 / to_light.norm() / to_light.squaredNorm();
      const double albedo = image.at(x, y)[4] / (scene.lights[0].E_per_band[4] * unit / M_PI);
      EXPECT_NEAR(albedo, SrgbToLinear(0.5f), 0.05) << x << "," << y;
    }
}

TEST(AlbedoTexture, TheScenesAlbedoOverridesTheMeshsBaseColour) {
  TempDir dir;
  std::filesystem::copy_file(Fixture("scenes/textured/checker.png"), dir / "checker.png");
  std::filesystem::copy_file(Fixture("scenes/textured/plane.gltf"), dir / "plane.gltf");
  std::ofstream(dir / "scene.json") << R"({"schema": "phos.scene/1", "time": {"start_s": 0, "end_s": 1, "fps": 1},
    "camera": {"position": [0, 2, 0], "look_at": [0, 0, 0], "up": [0, 0, 1]},
    "objects": [{"mesh": "plane.gltf", "albedo": 0.4}], "lights": []})";
  const Scene scene = LoadScene(dir / "scene.json");
  EXPECT_FALSE(scene.objects[0].albedo_texture);
  for (double v : scene.objects[0].albedo) EXPECT_EQ(v, 0.4);
}

// The textured-plane fixture's scene at 160 x 120 with `mesh` (a file in
// dir) as its plane.
std::filesystem::path PlaneScene(const TempDir& dir, const std::string& mesh) {
  nlohmann::json scene = nlohmann::json::parse(ReadText(Fixture("scenes/textured-plane.json")));
  scene["objects"][0]["mesh"] = mesh;
  scene["objects"][0]["phosphor"] = Fixture("materials/green.json").string();
  scene["camera"]["width"] = 160;
  scene["camera"]["height"] = 120;
  std::ofstream(dir / "scene.json", std::ios::trunc) << scene.dump();
  return dir / "scene.json";
}

// The fixture's glTF, `edit` applied, as plane.gltf beside checker.png in dir.
std::filesystem::path EditedPlane(const TempDir& dir, const std::function<void(nlohmann::json&)>& edit) {
  std::filesystem::copy_file(Fixture("scenes/textured/checker.png"), dir / "checker.png",
                             std::filesystem::copy_options::overwrite_existing);
  nlohmann::json gltf = nlohmann::json::parse(ReadText(Fixture("scenes/textured/plane.gltf")));
  edit(gltf);
  std::ofstream(dir / "plane.gltf", std::ios::trunc) << gltf.dump();
  return PlaneScene(dir, "plane.gltf");
}

std::string UserErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const UserError& e) {
    return e.what();
  }
  return "(no error)";
}

// An MTL Kd alone is a constant albedo (no lookup); parts with different
// materials give no single base colour, which the scene must settle.
TEST(AlbedoTexture, KdAloneIsAConstantAlbedoAndDifferingPartsNeedTheScenesWord) {
  TempDir dir;
  std::ofstream(dir / "two.obj") << "mtllib two.mtl\nv 0 0 0\nv 1 0 0\nv 0 0 1\nv 1 0 1\n"
                                    "usemtl grey\nf 1 3 2\nusemtl red\nf 2 3 4\n";
  std::ofstream(dir / "two.mtl") << "newmtl grey\nKd 0.5 0.5 0.5\nnewmtl red\nKd 0.8 0.1 0.1\n";
  auto scene_json = [&](const std::string& object) {
    std::ofstream(dir / "scene.json", std::ios::trunc)
        << R"({"schema": "phos.scene/1", "time": {"start_s": 0, "end_s": 1, "fps": 1},
    "camera": {"position": [0, 2, 0], "look_at": [0, 0, 0], "up": [0, 0, 1]}, "objects": [)" + object +
               R"(], "lights": []})";
    return dir / "scene.json";
  };
  const std::string differ = UserErrorOf([&] { LoadScene(scene_json(R"({"mesh": "two.obj"})")); });
  EXPECT_NE(differ.find("no single base colour"), std::string::npos) << differ;
  EXPECT_NE(differ.find("newmtl grey"), std::string::npos) << differ;
  const Scene given = LoadScene(scene_json(R"({"mesh": "two.obj", "albedo": 0.3})"));
  for (double v : given.objects[0].albedo) EXPECT_EQ(v, 0.3);
  std::ofstream(dir / "two.mtl", std::ios::trunc) << "newmtl grey\nKd 0.5 0.5 0.5\nnewmtl red\nKd 0.5 0.5 0.5\n";
  const Scene grey = LoadScene(scene_json(R"({"mesh": "two.obj"})"));
  EXPECT_FALSE(grey.objects[0].albedo_texture);
  for (double v : grey.objects[0].albedo) EXPECT_FLOAT_EQ(v, 0.5f);
}

TEST(AlbedoTexture, AMissingTextureNamesTheFileAndTheField) {
  TempDir dir;
  const std::string message =
      UserErrorOf([&] { LoadScene(EditedPlane(dir, [](nlohmann::json& g) { g["images"][0]["uri"] = "gone.png"; })); });
  EXPECT_NE(message.find("plane.gltf"), std::string::npos) << message;
  EXPECT_NE(message.find("images[0].uri"), std::string::npos) << message;
  EXPECT_NE(message.find("gone.png' does not exist"), std::string::npos) << message;
  EXPECT_EQ(message.find('\n'), std::string::npos) << message;
}

TEST(AlbedoTexture, ATextureThatIsNotAnImageNamesTheFileAndTheField) {
  TempDir dir;
  std::ofstream(dir / "notes.png") << "these are not pixels\n";
  const Scene scene = LoadScene(EditedPlane(dir, [](nlohmann::json& g) {
    g["images"][0]["uri"] = "notes.png";
  }));  // a regular file: read when rendering starts
  const std::string message = UserErrorOf([&] { SceneGeometry geometry(scene); });
  EXPECT_NE(message.find("plane.gltf"), std::string::npos) << message;
  EXPECT_NE(message.find("baseColorTexture"), std::string::npos) << message;
  EXPECT_NE(message.find("notes.png' is not an image"), std::string::npos) << message;
  EXPECT_EQ(message.find('\n'), std::string::npos) << message;
}

TEST(AlbedoTexture, MeshesWithoutUvsAndMissingMtlTexturesAreRefused) {
  TempDir dir;
  std::filesystem::copy_file(Fixture("scenes/textured/checker.png"), dir / "checker.png");
  std::ofstream(dir / "plane.obj") << "mtllib plane.mtl\nv 0 0 0\nv 1 0 0\nv 0 0 1\nusemtl m\nf 1 3 2\n";
  std::ofstream(dir / "plane.mtl") << "newmtl m\nmap_Kd checker.png\n";
  std::ofstream(dir / "obj.json") << R"({"schema": "phos.scene/1", "time": {"start_s": 0, "end_s": 1, "fps": 1},
    "camera": {"position": [0, 2, 0], "look_at": [0, 0, 0], "up": [0, 0, 1]},
    "objects": [{"mesh": "plane.obj"}], "lights": []})";
  const std::string no_uvs = UserErrorOf([&] { LoadScene(dir / "obj.json"); });
  EXPECT_NE(no_uvs.find("newmtl m: map_Kd) but no UV map"), std::string::npos) << no_uvs;
  std::ofstream(dir / "plane.mtl", std::ios::trunc) << "newmtl m\nmap_Kd missing.png\n";
  const std::string missing = UserErrorOf([&] { LoadScene(dir / "obj.json"); });
  EXPECT_NE(missing.find("plane.mtl): newmtl m: map_Kd: texture file"), std::string::npos) << missing;
}

// A glossy grey plane under a point light, seen from above; its glTF
// material has metallicFactor and roughnessFactor `factors` and, if `png`
// is given, that metallicRoughnessTexture. `scene_factors`: the scene's
// "metallic" and "roughness" keys, if any.
Scene GlossPlane(const TempDir& dir, const std::string& name, Gloss factors, const std::string& png,
                 const std::string& scene_factors = "") {
  nlohmann::json gltf = ReadJsonFile(Fixture("scenes/textured/plane.gltf"));
  nlohmann::json& pbr = gltf["materials"][0]["pbrMetallicRoughness"];
  pbr.erase("baseColorTexture");
  pbr["baseColorFactor"] = {0.6, 0.6, 0.6, 1};
  pbr["metallicFactor"] = factors.metallic;
  pbr["roughnessFactor"] = factors.roughness;
  if (png.empty()) {
    gltf.erase("textures");
    gltf.erase("images");
  } else {
    pbr["metallicRoughnessTexture"] = {{"index", 0}};
    gltf["images"][0]["uri"] = png;
  }
  std::ofstream(dir / (name + ".gltf")) << gltf.dump();
  std::ofstream(dir / (name + ".json")) << R"({"schema": "phos.scene/1", "time": {"start_s": 0, "end_s": 1, "fps": 1},
    "camera": {"position": [0, 1.6, 0.001], "look_at": [0, 0, 0], "up": [0, 1, 0], "fov_deg": 40,
               "width": 160, "height": 120},
    "objects": [{"name": "plane", "mesh": ")" + name + R"(.gltf")" + scene_factors + R"(}],
    "lights": [{"type": "point", "position": [0, 1, 0], "intensity": 1, "spectrum": {"type": "white_led"}}]})";
  return LoadScene(dir / (name + ".json"));
}

// An 8 x 8 RGB metallicRoughnessTexture: rows 0-3 (glTF's v < 0.5, the
// plane's z < 0) hold `top` as (roughness in G, metallic in B), rows 4-7
// `bottom`; R holds noise, which glTF leaves unused.
void WriteGlossPng(const std::filesystem::path& file, std::array<int, 2> top, std::array<int, 2> bottom) {
  std::vector<std::uint8_t> pixels;
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x) {
      const std::array<int, 2>& half = y < 4 ? top : bottom;
      pixels.insert(pixels.end(), {static_cast<std::uint8_t>(37 * (x + y) % 256), static_cast<std::uint8_t>(half[0]),
                                   static_cast<std::uint8_t>(half[1])});
    }
  auto out = OIIO::ImageOutput::create(file.string());
  ASSERT_TRUE(out);
  ASSERT_TRUE(out->open(file.string(), OIIO::ImageSpec(8, 8, 3, OIIO::TypeDesc::UINT8)));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, pixels.data()));
  out->close();
}

// The pixels within 4 of the one seeing the plane's point (0, 0, z).
std::vector<std::array<int, 2>> PixelsAround(const Scene& scene, float z) {
  const CameraRays camera(scene, 0);
  float px, py, depth;
  EXPECT_TRUE(camera.Project(Vec3f(0, 0, z), &px, &py, &depth));
  std::vector<std::array<int, 2>> pixels;
  for (int dy = -4; dy <= 4; ++dy)
    for (int dx = -4; dx <= 4; ++dx) pixels.push_back({static_cast<int>(px) + dx, static_cast<int>(py) + dy});
  return pixels;
}

// The largest relative difference of two frames over `pixels`, every band.
double LargestDifference(const Image& a, const Image& b, const std::vector<std::array<int, 2>>& pixels) {
  double largest = 0;
  for (const auto& [x, y] : pixels)
    for (int c = 0; c < a.channels; ++c) {
      const double u = a.at(x, y)[c], v = b.at(x, y)[c];
      largest = std::max(largest, std::abs(u - v) / std::max({std::abs(u), std::abs(v), 1e-12}));
    }
  return largest;
}

TEST(GlossTexture, EachHalfRendersAsItsConstantGlossAndTheScenesFactorsMultiplyIt) {
  TempDir dir;
  // Top: roughness 0.2, metallic 1 (a smooth metal); bottom: roughness 0.8,
  // metallic 0 (a rough dielectric).
  WriteGlossPng(dir / "mr.png", {51, 255}, {204, 0});
  const Scene textured = GlossPlane(dir, "textured", {1, 1}, "mr.png");
  ASSERT_TRUE(textured.objects[0].gloss_texture);
  EXPECT_NE(textured.objects[0].gloss_texture->field.find("metallicRoughnessTexture"), std::string::npos);
  const Scene top = GlossPlane(dir, "top", {1, 0.2f}, "");
  const Scene bottom = GlossPlane(dir, "bottom", {0, 0.8f}, "");
  // The scene's factors over the glTF's, times the texture: roughness 0.5 x
  // 0.2 and metallic 0.5 x 1 at the top.
  const Scene halved = GlossPlane(dir, "halved", {1, 1}, "mr.png", R"(, "metallic": 0.5, "roughness": 0.5)");
  const Scene halved_top = GlossPlane(dir, "halved_top", {0.5f, 0.1f}, "");
  const auto top_pixels = PixelsAround(textured, -0.25f), bottom_pixels = PixelsAround(textured, 0.25f);
  for (Transport transport : {Transport::kDirect, Transport::kPath}) {
    FrameOptions options = DefaultFrameOptions(textured, transport);
    options.spp = 1;  // centred: the camera ray is the direct one, and a lone plane bounces nothing back
    options.max_depth = 2;
    auto render = [&](const Scene& scene) {
      SceneGeometry geometry(scene);
      return RenderBands(geometry, nullptr, options);
    };
    const Image mixed = render(textured), smooth = render(top), rough = render(bottom);
    const std::string what = TransportName(transport);
    EXPECT_LT(LargestDifference(mixed, smooth, top_pixels), 1e-4) << what;
    EXPECT_LT(LargestDifference(mixed, rough, bottom_pixels), 1e-4) << what;
    // The two glosses look different where they are checked: a texture read
    // upside down, or its channels swapped, would fail above.
    EXPECT_GT(LargestDifference(smooth, rough, top_pixels), 0.2) << what;
    EXPECT_GT(LargestDifference(smooth, rough, bottom_pixels), 0.2) << what;
    EXPECT_LT(LargestDifference(render(halved), render(halved_top), top_pixels), 1e-4) << what;
  }
}

TEST(GlossTexture, AMissingOrUnreadableGlossTextureNamesTheField) {
  TempDir dir;
  const std::string missing = UserErrorOf([&] { GlossPlane(dir, "missing", {1, 1}, "gone.png"); });
  EXPECT_NE(missing.find("gone.png' does not exist"), std::string::npos) << missing;
  std::ofstream(dir / "notes.png") << "these are not pixels\n";
  const Scene scene = GlossPlane(dir, "notes", {1, 1}, "notes.png");
  const std::string unreadable = UserErrorOf([&] { SceneGeometry geometry(scene); });
  EXPECT_NE(unreadable.find("metallicRoughnessTexture"), std::string::npos) << unreadable;
  EXPECT_NE(unreadable.find("notes.png' is not an image"), std::string::npos) << unreadable;
  EXPECT_EQ(unreadable.find('\n'), std::string::npos) << unreadable;
}

// A 1 m plane facing +y whose UVs run 0 to 2 (so past the texture's
// square), wearing a 16 x 1 grey ramp through a glTF sampler with wrapS =
// `wrap_s` (glTF's numbers), as plane.gltf, plane.bin and ramp.png in dir.
std::filesystem::path WrappedRampPlane(const TempDir& dir, int wrap_s) {
  const float data[] = {-0.5f, 0, -0.5f, 0.5f, 0, -0.5f, 0.5f, 0, 0.5f, -0.5f, 0, 0.5f,  // POSITION
                        0,     0, 2,     0,    2, 2,     0,    2};                       // TEXCOORD_0 = 2 (x, z) + 1
  const std::uint16_t indices[] = {0, 3, 2, 0, 2, 1};  // counter-clockwise seen from +y
  std::ofstream bin(dir / "plane.bin", std::ios::binary);
  bin.write(reinterpret_cast<const char*>(data), sizeof(data));
  bin.write(reinterpret_cast<const char*>(indices), sizeof(indices));
  bin.close();
  std::uint8_t ramp[16 * 3];
  for (int x = 0; x < 16; ++x) ramp[3 * x] = ramp[3 * x + 1] = ramp[3 * x + 2] = static_cast<std::uint8_t>(8 + 16 * x);
  auto out = OIIO::ImageOutput::create((dir / "ramp.png").string());
  EXPECT_TRUE(out && out->open((dir / "ramp.png").string(), OIIO::ImageSpec(16, 1, 3, OIIO::TypeDesc::UINT8)) &&
              out->write_image(OIIO::TypeDesc::UINT8, ramp) && out->close());
  nlohmann::json gltf = {
      {"asset", {{"version", "2.0"}}},
      {"scenes", {{{"nodes", {0}}}}},
      {"nodes", {{{"mesh", 0}}}},
      {"meshes", {{{"primitives", {{{"attributes", {{"POSITION", 0}, {"TEXCOORD_0", 1}}}, {"indices", 2},
                                     {"material", 0}}}}}}},
      {"materials", {{{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}}}},
      {"textures", {{{"source", 0}, {"sampler", 0}}}},
      {"samplers", {{{"wrapS", wrap_s}, {"wrapT", 10497}}}},
      {"images", {{{"uri", "ramp.png"}}}},
      {"accessors",
       {{{"bufferView", 0}, {"componentType", 5126}, {"count", 4}, {"type", "VEC3"},
         {"min", {-0.5, 0, -0.5}}, {"max", {0.5, 0, 0.5}}},
        {{"bufferView", 1}, {"componentType", 5126}, {"count", 4}, {"type", "VEC2"}},
        {{"bufferView", 2}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}}}},
      {"bufferViews",
       {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 48}},
        {{"buffer", 0}, {"byteOffset", 48}, {"byteLength", 32}},
        {{"buffer", 0}, {"byteOffset", 80}, {"byteLength", 12}}}},
      {"buffers", {{{"uri", "plane.bin"}, {"byteLength", 92}}}}};
  std::ofstream(dir / "plane.gltf") << gltf.dump();
  const std::filesystem::path scene = dir / "scene.json";
  std::ofstream(scene) << R"({"schema": "phos.scene/1", "camera": {"position": [0, 2, 0.001], "look_at": [0, 0, 0]},
    "objects": [{"name": "plane", "mesh": "plane.gltf"}], "lights": []})";
  return scene;
}

// The albedo (band 4) a point lookup finds at u, v = 1.95 on the plane.
float AlbedoAtU(const SceneGeometry& geometry, float u) {
  // On triangle (0, 3, 2), uv = (2 b2, 2 (b1 + b2)).
  Hit hit;
  hit.object = 0;
  hit.triangle = 0;
  hit.b2 = u / 2;
  hit.b1 = 0.975f - hit.b2;  // v = 1.95
  const SurfaceTextures& textures = *geometry.surface_textures();
  std::vector<float> bands(static_cast<std::size_t>(geometry.scene().bands.band_count()));
  textures.Albedo(0, textures.Footprint(geometry, hit, Vec3f::Zero(), Vec3f::Zero()), bands.data());
  return bands[4];
}

TEST(AlbedoTexture, TheGltfSamplersWrapSaysHowTheTextureReadsPastItsSquare) {
  // At u = 1.265625 (a texel's centre past the square): REPEAT reads
  // u - 1, MIRRORED_REPEAT 2 - u, CLAMP_TO_EDGE the last column, as at 1.9.
  const float u = 1.265625f;
  std::map<int, std::pair<float, float>> expected;  // wrapS: (the lookup's partner u, its reading at u)
  for (int wrap : {10497, 33648, 33071}) {
    TempDir dir;
    const Scene scene = LoadScene(WrappedRampPlane(dir, wrap));
    EXPECT_EQ(scene.objects[0].albedo_texture->wraps.s,
              wrap == 10497 ? TextureWrap::kRepeat
                            : wrap == 33648 ? TextureWrap::kMirroredRepeat : TextureWrap::kClampToEdge);
    const SceneGeometry geometry(scene);
    const float at = AlbedoAtU(geometry, u);
    const float partner = AlbedoAtU(geometry, wrap == 10497 ? u - 1 : wrap == 33648 ? 2 - u : 1.9f);
    EXPECT_NEAR(at, partner, 1e-6f) << wrap;
    expected[wrap] = {partner, at};
  }
  // And the three differ (the ramp rises along u).
  EXPECT_GT(std::abs(expected[10497].second - expected[33648].second), 0.05f);
  EXPECT_GT(std::abs(expected[33648].second - expected[33071].second), 0.05f);
  // A wrap glTF does not have is one line naming the sampler's field.
  TempDir dir;
  const std::string message = UserErrorOf([&] { LoadScene(WrappedRampPlane(dir, 12345)); });
  EXPECT_NE(message.find("samplers[0].wrapS"), std::string::npos) << message;
}

// The textured plane with KHR_texture_transform on its base colour texture,
// `transform` the extension's object.
std::filesystem::path TransformedPlane(const TempDir& dir, const nlohmann::json& transform) {
  return EditedPlane(dir, [&](nlohmann::json& gltf) {
    gltf["extensionsUsed"] = {"KHR_texture_transform"};
    gltf["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"]["KHR_texture_transform"] =
        transform;
  });
}

// Random offsets, rotations and scales: each quadrant's centre shows the
// quadrant of the texture that the extension's matrix T R S sends it to,
// written out here as Khronos's sample renderer builds it (its
// material.js, gl-matrix column by column: rotation [c, -s, 0, s, c, 0, 0,
// 0, 1]): u' = sx cos u + sy sin v + ox, v' = -sx sin u + sy cos v + oy,
// then REPEAT. (The GLSL listing in the extension's README turns the other
// way; glTF issue 1563 says the implementations and the sample model agree
// with the renderer.)
TEST(AlbedoTexture, KhrTextureTransformMovesTheTextureAsTheExtensionsMatrixSays) {
  std::mt19937_64 random(20261206);
  std::uniform_real_distribution<double> offset(-1.5, 1.5), angle(-2 * M_PI, 2 * M_PI), scale(0.5, 1.5);
  auto half = [](double x) { return x - std::floor(x) >= 0.5 ? 1 : 0; };
  // Away from the texture's quadrant edges by more than the pixel's offset
  // from the centre (0.05 m, times the scale) and a texel or two of filter.
  auto clear = [](double x) {
    const double f = x - std::floor(x);
    return std::min({std::abs(f), std::abs(f - 0.5), std::abs(f - 1)}) > 0.1;
  };
  int rendered = 0, rotated_half_turn = 0;
  for (int draw = 0; draw < 5000 && rendered < 6; ++draw) {
    const double ox = offset(random), oy = offset(random), r = angle(random);
    const double sx = scale(random) * (random() % 2 ? -1 : 1), sy = scale(random);
    auto sent = [&](int u_half, int v_half) {
      const double u = u_half ? 0.75 : 0.25, v = v_half ? 0.75 : 0.25;
      return std::array<double, 2>{sx * std::cos(r) * u + sy * std::sin(r) * v + ox,
                                   -sx * std::sin(r) * u + sy * std::cos(r) * v + oy};
    };
    bool usable = true;
    for (int u_half = 0; u_half < 2; ++u_half)
      for (int v_half = 0; v_half < 2; ++v_half)
        usable = usable && clear(sent(u_half, v_half)[0]) && clear(sent(u_half, v_half)[1]);
    if (!usable) continue;
    TempDir dir;
    const Scene scene = LoadScene(TransformedPlane(
        dir, {{"offset", {ox, oy}}, {"rotation", r}, {"scale", {sx, sy}}}));
    SceneGeometry geometry(scene);
    FrameOptions options = DefaultFrameOptions(scene, Transport::kDirect);
    options.direct_spp = 1;
    ExpectQuadrantsAreAlbedoTimesEOverPi(scene, RenderBands(geometry, nullptr, options),
                                         "offset " + std::to_string(ox) + ", " + std::to_string(oy) + ", rotation " +
                                             std::to_string(r) + ", scale " + std::to_string(sx) + ", " +
                                             std::to_string(sy),
                                         [&](int u_half, int v_half) {
                                           const std::array<double, 2> uv = sent(u_half, v_half);
                                           return std::array<int, 2>{half(uv[0]), half(uv[1])};
                                         });
    rotated_half_turn += std::abs(std::remainder(r, 2 * M_PI)) > M_PI / 2;
    ++rendered;
  }
  EXPECT_EQ(rendered, 6);
  EXPECT_GE(rotated_half_turn, 1);  // the draws turn the texture past a quarter turn, where a sign error shows
}

TEST(AlbedoTexture, AKhrTextureTransformPhosCannotFollowIsOneLineNamingItsField) {
  TempDir dir;
  std::string message = UserErrorOf([&] { LoadScene(TransformedPlane(dir, {{"texCoord", 1}})); });
  EXPECT_NE(message.find("baseColorTexture.extensions.KHR_texture_transform.texCoord"), std::string::npos) << message;
  message = UserErrorOf([&] { LoadScene(TransformedPlane(dir, {{"scale", {1, 2, 3}}})); });
  EXPECT_NE(message.find("KHR_texture_transform.scale: expected 2 numbers"), std::string::npos) << message;
  message = UserErrorOf([&] { LoadScene(TransformedPlane(dir, {{"rotation", "a quarter turn"}})); });
  EXPECT_NE(message.find("KHR_texture_transform.rotation: expected a finite number"), std::string::npos) << message;
  // A file that requires the extension now loads.
  TempDir required;
  const std::filesystem::path scene = TransformedPlane(required, {{"offset", {0.5, 0}}});
  nlohmann::json gltf = nlohmann::json::parse(ReadText(required / "plane.gltf"));
  gltf["extensionsRequired"] = {"KHR_texture_transform"};
  std::ofstream(required / "plane.gltf") << gltf.dump();
  EXPECT_EQ(LoadScene(scene).objects[0].albedo_texture->uv_transform.offset, Eigen::Vector2f(0.5f, 0));
}

// A glTF sampler's filters (scene.h, TextureFilter). The checker as a 2 x 2
// image (texels 0.5 wide), moved by 0.3 of a texel (KHR_texture_transform
// offset 0.15 in u): each quadrant's centre then reads u' = 0.4 or 0.9.
// NEAREST shows the closest texel whole, the quadrant's own colour; LINEAR
// (the default) blends 30% of the neighbouring texel in.
TEST(AlbedoTexture, ASamplersNearestMagFilterShowsTheClosestTexelWhole) {
  TempDir dir;
  auto render = [&](const nlohmann::json& sampler) {
    const std::filesystem::path scene_file = EditedPlane(dir, [&](nlohmann::json& gltf) {
      gltf["images"][0]["uri"] = "tiny.png";
      gltf["samplers"] = nlohmann::json::array({sampler});
      gltf["textures"][0]["sampler"] = 0;
      gltf["extensionsUsed"] = {"KHR_texture_transform"};
      gltf["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"]["KHR_texture_transform"] = {
          {"offset", {0.15, 0}}};
    });
    OIIO::ImageBuf tiny(OIIO::ImageSpec(2, 2, 3, OIIO::TypeDesc::UINT8));
    for (int v_half = 0; v_half < 2; ++v_half)
      for (int u_half = 0; u_half < 2; ++u_half) {
        const std::array<float, 3> srgb = QuadrantSrgb(u_half, v_half);
        tiny.setpixel(u_half, v_half, srgb.data());
      }
    EXPECT_TRUE(tiny.write((dir / "tiny.png").string()));
    Scene scene = LoadScene(scene_file);
    scene.camera.width = 160;
    scene.camera.height = 120;
    SceneGeometry geometry(scene);
    FrameOptions options = DefaultFrameOptions(scene, Transport::kDirect);
    options.direct_spp = 1;
    return std::make_pair(scene, RenderBands(geometry, nullptr, options));
  };
  const auto [nearest_scene, nearest] = render({{"magFilter", 9728}, {"minFilter", 9728}});
  EXPECT_EQ(nearest_scene.objects[0].albedo_texture->filter.interpolation, TexelInterpolation::kClosest);
  EXPECT_EQ(nearest_scene.objects[0].albedo_texture->filter.mip, MipLevels::kNone);
  ExpectQuadrantsAreAlbedoTimesEOverPi(nearest_scene, nearest, "magFilter NEAREST");
  const auto [linear_scene, linear] = render({{"magFilter", 9729}});
  EXPECT_EQ(linear_scene.objects[0].albedo_texture->filter, TextureFilter{});
  // Quadrant (0, 0)'s centre: red (230, 60, 40) with 30% of green (40, 180, 70) blended in.
  const CameraRays camera(linear_scene, 0);
  float px, py, depth;
  ASSERT_TRUE(camera.Project(Vec3f(-0.25f, 0, -0.25f), &px, &py, &depth));
  const float* blended = linear.at(static_cast<int>(px), static_cast<int>(py));
  const float* whole = nearest.at(static_cast<int>(px), static_cast<int>(py));
  const int nb = linear_scene.bands.band_count();
  double largest = 0;
  for (int b = 0; b < nb; ++b) largest = std::max(largest, std::abs(blended[b] / whole[b] - 1.0));
  EXPECT_GT(largest, 0.3);

  // Another number: one line naming the field.
  std::string message = UserErrorOf([&] { render({{"magFilter", 9984}}); });
  EXPECT_NE(message.find("samplers[0].magFilter: expected 9728 (NEAREST) or 9729 (LINEAR), got 9984"),
            std::string::npos)
      << message;
  message = UserErrorOf([&] { render({{"minFilter", 1}}); });
  EXPECT_NE(message.find("samplers[0].minFilter: expected 9728, 9729 or 9984 to 9987"), std::string::npos) << message;
}

// An environment variable set (or unset, for nullopt) while it lives:
// XDG_CACHE_HOME, where embedded images are written, and
// PHOS_TEXTURE_CACHE_MB, how much of them is kept (surface_textures.h).
class ScopedEnv {
 public:
  ScopedEnv(std::string name, const std::optional<std::string>& value) : name_(std::move(name)) {
    if (const char* old = std::getenv(name_.c_str())) old_ = old;
    Set(value);
  }
  ~ScopedEnv() { Set(old_); }

 private:
  void Set(const std::optional<std::string>& value) {
    if (value) {
      ::setenv(name_.c_str(), value->c_str(), 1);
    } else {
      ::unsetenv(name_.c_str());
    }
  }
  std::string name_;
  std::optional<std::string> old_;
};

// A .glb: its JSON chunk, then `bin` as its BIN chunk (glTF 2.0, 4.4).
void WriteGlb(const std::filesystem::path& path, const nlohmann::json& gltf, std::string bin) {
  std::string json = gltf.dump();
  while (json.size() % 4) json += ' ';
  while (bin.size() % 4) bin += '\0';
  std::ofstream out(path, std::ios::binary);
  auto word = [&](std::uint32_t w) { out.write(reinterpret_cast<const char*>(&w), 4); };
  out.write("glTF", 4);
  word(2);
  word(static_cast<std::uint32_t>(12 + 8 + json.size() + 8 + bin.size()));
  word(static_cast<std::uint32_t>(json.size()));
  word(0x4E4F534Au);  // JSON
  out << json;
  word(static_cast<std::uint32_t>(bin.size()));
  word(0x004E4942u);  // BIN
  out << bin;
}

// The checker plane with its image inside the glTF: a data: URI, or a .glb
// whose BIN chunk holds the PNG (the plane's own buffer stays a data: URI,
// buffers[1]). Each renders as the plane with the image in its own file,
// albedo E / pi per quadrant, and the image's file in the cache holds its bytes.
TEST(AlbedoTexture, ImagesEmbeddedInAGltfOrAGlbRenderAsTheirFiles) {
  TempDir cache;
  const ScopedEnv scoped("XDG_CACHE_HOME", cache.path().string());
  const std::string png = ReadText(Fixture("scenes/textured/checker.png"));
  auto render = [&](const std::filesystem::path& scene_file, const std::string& what) {
    const Scene scene = LoadScene(scene_file);
    ASSERT_TRUE(scene.objects[0].albedo_texture && scene.objects[0].albedo_texture->embedded) << what;
    SceneGeometry geometry(scene);
    FrameOptions options = DefaultFrameOptions(scene, Transport::kDirect);
    options.direct_spp = 1;
    ExpectQuadrantsAreAlbedoTimesEOverPi(scene, RenderBands(geometry, nullptr, options), what);
  };
  TempDir uri_dir;
  render(EditedPlane(uri_dir,
                     [&](nlohmann::json& gltf) {
                       gltf["images"][0]["uri"] = "data:image/png;base64," + OIIO::Strutil::base64_encode(png);
                     }),
         "data: URI");
  TempDir glb_dir;
  nlohmann::json gltf = nlohmann::json::parse(ReadText(Fixture("scenes/textured/plane.gltf")));
  const nlohmann::json plane_buffer = gltf["buffers"][0];
  gltf["buffers"] = nlohmann::json::array({nlohmann::json{{"byteLength", png.size()}}, plane_buffer});
  for (nlohmann::json& view : gltf["bufferViews"]) view["buffer"] = 1;
  gltf["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", 0}, {"byteLength", png.size()}});
  gltf["images"][0] = {{"bufferView", 3}, {"mimeType", "image/png"}};
  WriteGlb(glb_dir / "plane.glb", gltf, png);
  render(PlaneScene(glb_dir, "plane.glb"), "glb bufferView");
  // One file in the cache, the PNG's bytes (the same image both times).
  std::vector<std::filesystem::path> files;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(cache.path()))
    if (entry.is_regular_file()) files.push_back(entry.path());
  ASSERT_EQ(files.size(), 1u);
  EXPECT_EQ(files[0].extension(), ".png");
  EXPECT_EQ(ReadText(files[0]), png);

  // A bufferView past its buffer's end, a format other than PNG and JPEG,
  // and bytes that are no image: one line naming the field.
  gltf["bufferViews"][3]["byteLength"] = png.size() + 1;
  WriteGlb(glb_dir / "plane.glb", gltf, png);
  std::string message = UserErrorOf([&] { LoadScene(PlaneScene(glb_dir, "plane.glb")); });
  EXPECT_NE(message.find("bufferViews[3]: the image's bytes lie outside its buffer"), std::string::npos) << message;
  gltf["bufferViews"][3]["byteLength"] = png.size();
  gltf["images"][0]["mimeType"] = "image/gif";
  WriteGlb(glb_dir / "plane.glb", gltf, png);
  message = UserErrorOf([&] { LoadScene(PlaneScene(glb_dir, "plane.glb")); });
  EXPECT_NE(message.find("images[0].mimeType: expected image/png or image/jpeg"), std::string::npos) << message;
  TempDir junk_dir;
  const Scene junk = LoadScene(EditedPlane(junk_dir, [&](nlohmann::json& g) {
    g["images"][0]["uri"] = "data:image/png;base64,AAAA";
  }));  // read when rendering starts, as a file's pixels are
  message = UserErrorOf([&] { SceneGeometry geometry(junk); });
  EXPECT_NE(message.find("baseColorTexture"), std::string::npos) << message;
  EXPECT_NE(message.find("images[0] (embedded)' is not an image"), std::string::npos) << message;
  EXPECT_EQ(message.find('\n'), std::string::npos) << message;
}

// The cache of embedded images keeps within PHOS_TEXTURE_CACHE_MB, least
// recently used first: files used in the last day stay, as does the one just
// written, and a render that finds its image there marks it used.
TEST(AlbedoTexture, TheCacheOfEmbeddedImagesKeepsWithinItsBudgetLeastRecentlyUsedFirst) {
  TempDir cache;
  const ScopedEnv home("XDG_CACHE_HOME", cache.path().string());
  const std::filesystem::path folder = cache / "phos" / "textures";
  std::filesystem::create_directories(folder);
  const auto now = std::filesystem::file_time_type::clock::now();
  auto old_file = [&](const std::string& name, std::chrono::hours age) {
    testing::WriteText(folder / name, std::string(1000, 'x'));
    std::filesystem::last_write_time(folder / name, now - age);
  };
  old_file("three-days.png", std::chrono::hours(72));
  old_file("two-days.png", std::chrono::hours(48));
  old_file("one-day.png", std::chrono::hours(25));
  old_file("one-hour.png", std::chrono::hours(1));
  const std::string png = ReadText(Fixture("scenes/textured/checker.png"));
  // Room for the new image and 2000 bytes of the old files: the two oldest go.
  char budget_mib[32];
  std::snprintf(budget_mib, sizeof(budget_mib), "%.17g", static_cast<double>(png.size() + 2000) / (1024.0 * 1024.0));
  const ScopedEnv budget("PHOS_TEXTURE_CACHE_MB", budget_mib);
  TempDir scene_dir;
  const std::filesystem::path scene_file = EditedPlane(scene_dir, [&](nlohmann::json& gltf) {
    gltf["images"][0]["uri"] = "data:image/png;base64," + OIIO::Strutil::base64_encode(png);
  });
  const Scene scene = LoadScene(scene_file);
  { SceneGeometry geometry(scene); }
  std::set<std::string> kept;
  std::filesystem::path written;
  for (const auto& entry : std::filesystem::directory_iterator(folder)) {
    kept.insert(entry.path().filename().string());
    if (entry.path().extension() == ".png" && entry.file_size() == png.size()) written = entry.path();
  }
  EXPECT_EQ(kept.count("three-days.png"), 0u);
  EXPECT_EQ(kept.count("two-days.png"), 0u);
  EXPECT_EQ(kept.count("one-day.png"), 1u);
  EXPECT_EQ(kept.count("one-hour.png"), 1u);
  ASSERT_FALSE(written.empty());
  EXPECT_EQ(kept.size(), 3u);

  // Found again by a later render: marked used now.
  std::filesystem::last_write_time(written, now - std::chrono::hours(96));
  { SceneGeometry geometry(scene); }
  EXPECT_GT(std::filesystem::last_write_time(written), now - std::chrono::hours(1));

  // A budget of nothing keeps the image being rendered and the recent files.
  std::filesystem::remove(written);
  const ScopedEnv nothing("PHOS_TEXTURE_CACHE_MB", "0");
  { SceneGeometry geometry(scene); }
  EXPECT_TRUE(std::filesystem::exists(written));
  EXPECT_TRUE(std::filesystem::exists(folder / "one-hour.png"));
  EXPECT_FALSE(std::filesystem::exists(folder / "one-day.png"));

  // A budget that is no size: one line naming the variable.
  const ScopedEnv bad("PHOS_TEXTURE_CACHE_MB", "lots");
  const std::string message = UserErrorOf([&] { SceneGeometry geometry(scene); });
  EXPECT_NE(message.find("PHOS_TEXTURE_CACHE_MB: expected a size in MiB from 0 up, not 'lots'"), std::string::npos)
      << message;
}

}  // namespace
}  // namespace phos::render
