// Glossy surfaces (render/bsdf.h) against what must hold whatever the
// tables and the sampling: energy, reciprocity, the sampler's pdf, and the
// white furnace in the path tracer.
//  - White furnace of the BSDF: albedo 1, any metallic and roughness, any
//    view: the integral of f cos over the hemisphere is 1 within 1% (by the
//    BSDF's sampler, and where its grid resolves the lobe by uniform
//    hemisphere quadrature, independent of the sampler).
//  - Its directional albedo for a coloured base equals the same integral.
//  - f(wo, wi) = f(wi, wo).
//  - The sampler draws wi with the pdf it states: the mean of f cos / pdf
//    over its samples equals the quadrature.
//  - The white furnace in the path tracer: a white glossy ball under a
//    uniform sky of radiance L shows L (1%).

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "phos/render/bsdf.h"
#include "phos/render/renderer.h"
#include "phos/render/scene.h"
#include "phos/render/solver.h"
#include "phos/util/error.h"
#include "phos/util/json.h"
#include "render/scene_util.h"
#include "test_util.h"

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

namespace phos::render {
namespace {

using phos::testing::EmptyScene;
using phos::testing::MakeObject;

// The integral of f cos over the hemisphere around n = z by stratified
// uniform sampling of (cos theta, phi), per band.
std::vector<double> Quadrature(const GlossyBsdf& bsdf, const Vec3f& wo, int nb, int side = 400) {
  std::vector<double> sum(nb, 0.0);
  std::vector<float> f(nb);
  const Vec3f n(0, 0, 1);
  for (int i = 0; i < side; ++i)
    for (int j = 0; j < side; ++j) {
      const float mu = (i + 0.5f) / side, phi = 2 * float(M_PI) * (j + 0.5f) / side;
      const float s = std::sqrt(1 - mu * mu);
      const Vec3f wi(s * std::cos(phi), s * std::sin(phi), mu);
      bsdf.Eval(n, wo, wi, f.data());
      for (int b = 0; b < nb; ++b) sum[b] += f[b] * mu;
    }
  for (double& v : sum) v *= 2 * M_PI / (double(side) * side);  // d omega = dmu dphi
  return sum;
}

Vec3f View(float mu) { return Vec3f(std::sqrt(1 - mu * mu), 0, mu); }

// The same integral by the BSDF's own sampler (mean of f cos / pdf), which
// TheSamplerDrawsWithThePdfItStates checks against the quadrature where the
// quadrature's grid resolves the lobe; below roughness 0.3 or at grazing
// views it does not, and only the sampler's estimate is used.
std::vector<double> Sampled(const GlossyBsdf& bsdf, const Vec3f& wo, int nb, int n = 80000) {
  std::mt19937 random(17);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<double> sum(nb, 0.0);
  std::vector<float> f(nb);
  for (int k = 0; k < n; ++k) {
    Vec3f wi;
    float pdf;
    if (!bsdf.Sample(Vec3f(0, 0, 1), wo, u(random), u(random), u(random), &wi, &pdf)) continue;
    bsdf.Eval(Vec3f(0, 0, 1), wo, wi, f.data());
    for (int b = 0; b < nb; ++b) sum[b] += f[b] * wi.z() / pdf;
  }
  for (double& v : sum) v /= n;
  return sum;
}

TEST(GlossyBsdf, AWhiteSurfaceReflectsAllItReceivesAtAnyRoughness) {
  const std::vector<float> white(1, 1.0f);
  for (float metallic : {0.0f, 0.5f, 1.0f})
    for (float roughness : {0.1f, 0.3f, 0.6f, 1.0f})
      for (float mu : {0.15f, 0.5f, 0.95f}) {
        const GlossyBsdf bsdf({metallic, roughness}, white.data(), 1);
        EXPECT_NEAR(Sampled(bsdf, View(mu), 1)[0], 1.0, 0.01)
            << "metallic " << metallic << " roughness " << roughness << " mu " << mu;
        if (roughness >= 0.3f && mu >= 0.3f) {  // braces: EXPECT_NEAR is an if-else inside
          EXPECT_NEAR(Quadrature(bsdf, View(mu), 1)[0], 1.0, 0.01)
              << "metallic " << metallic << " roughness " << roughness << " mu " << mu;
        }
        float rho;
        bsdf.DirectionalAlbedo(mu, &rho);
        EXPECT_NEAR(rho, 1.0, 0.01);
      }
}

TEST(GlossyBsdf, DirectionalAlbedoIsTheIntegralAndFIsReciprocal) {
  const std::vector<float> colour = {0.1f, 0.5f, 0.9f};
  std::mt19937 random(3);
  std::uniform_real_distribution<float> u(0.05f, 0.95f);
  for (float metallic : {0.0f, 1.0f, 0.3f})
    for (float roughness : {0.2f, 0.7f}) {
      const GlossyBsdf bsdf({metallic, roughness}, colour.data(), 3);
      const float mu = u(random);
      const std::vector<double> integral = Sampled(bsdf, View(mu), 3);
      std::vector<float> rho(3);
      bsdf.DirectionalAlbedo(mu, rho.data());
      for (int b = 0; b < 3; ++b)
        EXPECT_NEAR(rho[b], integral[b], 0.01) << metallic << " " << roughness << " mu " << mu << " band " << b;
      for (int k = 0; k < 20; ++k) {
        const Vec3f a = Vec3f(u(random) - 0.5f, u(random) - 0.5f, u(random)).normalized();
        const Vec3f c = Vec3f(u(random) - 0.5f, u(random) - 0.5f, u(random)).normalized();
        std::vector<float> f_ac(3), f_ca(3);
        bsdf.Eval(Vec3f(0, 0, 1), a, c, f_ac.data());
        bsdf.Eval(Vec3f(0, 0, 1), c, a, f_ca.data());
        for (int b = 0; b < 3; ++b) EXPECT_NEAR(f_ac[b], f_ca[b], 1e-5f * (1 + f_ac[b]));
      }
    }
}

TEST(GlossyBsdf, TheSamplerDrawsWithThePdfItStates) {
  const std::vector<float> colour = {0.3f, 0.8f};
  std::mt19937 random(9);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (float metallic : {0.0f, 1.0f})
    for (float roughness : {0.15f, 0.5f, 1.0f}) {
      const GlossyBsdf bsdf({metallic, roughness}, colour.data(), 2);
      const Vec3f wo = View(0.6f);
      const std::vector<double> integral = Quadrature(bsdf, wo, 2);
      const int n = 150000;
      std::vector<double> sum(2, 0.0);
      std::vector<float> f(2);
      for (int k = 0; k < n; ++k) {
        Vec3f wi;
        float pdf;
        if (!bsdf.Sample(Vec3f(0, 0, 1), wo, u(random), u(random), u(random), &wi, &pdf)) continue;
        EXPECT_NEAR(pdf, bsdf.Pdf(Vec3f(0, 0, 1), wo, wi), 1e-4f * pdf);
        bsdf.Eval(Vec3f(0, 0, 1), wo, wi, f.data());
        for (int b = 0; b < 2; ++b) sum[b] += f[b] * wi.z() / pdf;
      }
      for (int b = 0; b < 2; ++b)
        EXPECT_NEAR(sum[b] / n, integral[b], 0.01 * integral[b] + 1e-3) << metallic << " " << roughness << " " << b;
    }
}

TEST(GlossyBsdf, AWhiteGlossyBallUnderAUniformSkyShowsTheSkyInThePathTracer) {
  for (float metallic : {0.0f, 1.0f})
    for (float roughness : {0.2f, 0.8f}) {
      Scene scene = EmptyScene(24, 24);
      scene.camera.keys = {{0, Vec3(0, 0, 3), Vec3(0, 0, 0)}};
      scene.camera.fov_deg = 20;  // the ball fills the middle of the frame
      Object ball = MakeObject("ball", MakeSphere(0.5, 4, false), 1.0);
      ball.gloss = Gloss{metallic, roughness};
      scene.objects.push_back(ball);
      Environment sky;
      sky.L_per_band.assign(8, 2.0);
      scene.environment = sky;
      SceneGeometry geometry(scene);
      FrameOptions path;
      path.transport = Transport::kPath;
      path.spp = 64;
      path.max_depth = 50;  // a convex ball: one bounce leaves it
      const Image image = RenderBands(geometry, nullptr, path);
      double sum = 0;
      int n = 0;
      for (int y = 9; y < 15; ++y)
        for (int x = 9; x < 15; ++x, ++n) sum += image.at(x, y)[3];
      EXPECT_NEAR(sum / n, 2.0, 0.02) << "metallic " << metallic << " roughness " << roughness;
      // Direct transport: a uniform sky's reflection through the directional albedo.
      const Image direct = RenderBands(geometry, nullptr, FrameOptions{});
      EXPECT_NEAR(direct.at(12, 12)[3], 2.0, 0.02) << "metallic " << metallic << " roughness " << roughness;
    }
}

// A glowing disk facing down over a floor, seen in the floor from below
// the disk's side: a white near-mirror metal floor shows the glow at about
// its own radiance (Sec. 8.3.4: the glow is isotropic, its reflection is
// the floor's); a Lambertian floor only its form factor's share.
double GlowSeenInTheFloor(std::optional<Gloss> gloss) {
  Scene scene = EmptyScene(9, 9);
  scene.camera.keys = {{0, Vec3(0, 0.6, 0.6), Vec3(0, 0, 0)}};
  scene.camera.fov_deg = 4;
  Object floor = MakeObject("floor", MakeQuad(4, 4), 1.0);
  floor.gloss = gloss;
  scene.objects.push_back(floor);
  render::Mesh disk = phos::testing::DiskFacingDown(0.2f, 0.0f, 48);
  Object glow = MakeObject("disk", disk, 0.0,
                           phos::testing::UniformPhosphor(0.2, std::vector<double>(8, 0.1), {0, 0, 1, 2, 1, 0, 0, 0}));
  glow.motion.keys = {{0, Vec3(0, 0.4, -0.4), Eigen::Quaterniond::Identity(), 1.0}};
  glow.initial = {InitialState::Kind::kUniform, 0.5};
  scene.objects.push_back(glow);
  scene.texel_size_m = 0.05;
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  FrameOptions path;
  path.transport = Transport::kPath;
  path.spp = 256;
  path.max_depth = 3;
  return RenderBands(geometry, &solver, path).at(4, 4)[3];
}

TEST(GlossyBsdf, ThePathTracerShowsTheGlowReflectedInAGlossyFloor) {
  const double Lp = 2 * 0.2 * 0.5;  // Eq. 8.2, band 3
  const double mirror = GlowSeenInTheFloor(Gloss{1.0f, 0.05f});
  const double matte = GlowSeenInTheFloor(std::nullopt);
  EXPECT_NEAR(mirror, Lp, 0.1 * Lp);
  EXPECT_LT(matte, 0.5 * mirror);
}

TEST(GlossyBsdf, GltfMetallicRoughnessBecomesTheObjectsGloss) {
  nlohmann::json gltf = ReadJsonFile(phos::testing::Fixture("scenes/textured/plane.gltf"));
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "gloss";
  std::filesystem::create_directories(dir);
  std::filesystem::copy_file(phos::testing::Fixture("scenes/textured/checker.png"), dir / "checker.png",
                             std::filesystem::copy_options::overwrite_existing);
  // metallic 0, roughness 1: Lambertian, as before.
  std::ofstream(dir / "rough.gltf") << gltf.dump();
  EXPECT_FALSE(LoadMesh(dir / "rough.gltf", "", "test").gloss.has_value());
  gltf["materials"][0]["pbrMetallicRoughness"]["metallicFactor"] = 0.7;
  gltf["materials"][0]["pbrMetallicRoughness"]["roughnessFactor"] = 0.3;
  std::ofstream(dir / "glossy.gltf") << gltf.dump();
  const Mesh mesh = LoadMesh(dir / "glossy.gltf", "", "test");
  ASSERT_TRUE(mesh.gloss.has_value());
  EXPECT_FLOAT_EQ(mesh.gloss->metallic, 0.7f);
  EXPECT_FLOAT_EQ(mesh.gloss->roughness, 0.3f);
  gltf["materials"][0]["pbrMetallicRoughness"]["roughnessFactor"] = 1.5;
  std::ofstream(dir / "bad.gltf") << gltf.dump();
  std::string message = "accepted";
  try {
    LoadMesh(dir / "bad.gltf", "", "test");
  } catch (const UserError& e) {
    message = e.what();
  }
  EXPECT_NE(message.find("roughnessFactor"), std::string::npos) << message;
}

}  // namespace
}  // namespace phos::render
