// The sky (Environment) and directional occlusion through deep screen space:
// closed forms for an open floor and under a disk, ray-traced sky as the
// reference in a corner, and a phosphor charged by the sky.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "phos/render/bsdf.h"
#include "phos/render/dss.h"
#include "phos/render/renderer.h"
#include "phos/render/solver.h"
#include "phos/util/random.h"
#include "scene_util.h"

namespace phos::render {
namespace {

constexpr double kPi = 3.14159265358979323846;

Environment Sky(double L, double gradient) {
  Environment env;
  env.L_per_band.assign(8, L);
  env.gradient = gradient;
  return env;
}

Scene FloorUnderSky(double gradient) {
  Scene scene = testing::EmptyScene(11, 11);
  scene.camera.keys = {{0.0, Vec3(0, 1, 0.0001), Vec3(0, 0, 0)}};
  scene.camera.fov_deg = 40;
  scene.objects.push_back(testing::MakeObject("floor", MakeQuad(2, 2), 0.5));
  scene.environment = Sky(2.0, gradient);
  return scene;
}

TEST(Sky, AnOpenFloorReceivesTheClosedForm) {
  // E = L (pi + 2 pi / 3 g n_y): radiance albedo E / pi, in every transport.
  for (double gradient : {0.0, 0.6, -0.5}) {
    const Scene scene = FloorUnderSky(gradient);
    SceneGeometry geometry(scene);
    const double expected = 0.5 * 2.0 * (kPi + 2 * kPi / 3 * gradient) / kPi;
    FrameOptions options;
    options.transport = Transport::kDirect;
    options.sky_rays = 256;
    EXPECT_NEAR(RenderBands(geometry, nullptr, options).at(5, 5)[2] / expected, 1.0, 0.01) << gradient;
    options.transport = Transport::kDss;
    EXPECT_NEAR(RenderBands(geometry, nullptr, options).at(5, 5)[2] / expected, 1.0, 1e-4)
        << gradient;  // nothing occludes
    options.transport = Transport::kPath;
    options.spp = 256;
    options.max_depth = 2;
    EXPECT_NEAR(RenderBands(geometry, nullptr, options).at(5, 5)[2] / expected, 1.0, 0.03) << gradient;
  }
}

// A floor of albedo `base` and `gloss` under FloorUnderSky's sky, seen
// `view_rad` off the zenith through a narrow camera; and rho(w_o) of band 2,
// its BSDF's directional albedo toward that camera.
Scene GlossyFloorUnderSky(double gradient, double view_rad, double base, Gloss gloss) {
  Scene scene = FloorUnderSky(gradient);
  scene.camera.keys = {{0.0, Vec3(0, std::cos(view_rad), std::sin(view_rad) + 0.0001), Vec3(0, 0, 0)}};
  scene.camera.fov_deg = 10;
  scene.objects[0].albedo.assign(8, base);
  scene.objects[0].gloss = gloss;
  return scene;
}
double DirectionalAlbedoTowardCamera(const Scene& scene, double view_rad) {
  const std::vector<float> albedo(scene.objects[0].albedo.begin(), scene.objects[0].albedo.end());
  float rho[8];
  GlossyBsdf(*scene.objects[0].gloss, albedo.data(), 8).DirectionalAlbedo(static_cast<float>(std::cos(view_rad)), rho);
  return rho[2];
}
// Band 2 at the frame's centre (the mean of its 3 x 3 middle pixels) is
// `expected` in direct transport and dss (1%) and, when `path`, in the path
// tracer (3%, 1024 spp).
void ExpectTransportsShow(const SceneGeometry& geometry, double expected, bool path, const std::string& at) {
  auto centre = [](const Image& image) {
    double sum = 0;
    for (int y = 4; y <= 6; ++y)
      for (int x = 4; x <= 6; ++x) sum += image.at(x, y)[2];
    return sum / 9;
  };
  FrameOptions options;
  options.transport = Transport::kDirect;
  options.sky_rays = 256;
  EXPECT_NEAR(centre(RenderBands(geometry, nullptr, options)) / expected, 1.0, 0.01) << at;
  options.transport = Transport::kDss;
  EXPECT_NEAR(centre(RenderBands(geometry, nullptr, options)) / expected, 1.0, 0.01) << at;
  if (!path) return;
  options.transport = Transport::kPath;
  options.spp = 1024;
  options.max_depth = 2;
  EXPECT_NEAR(centre(RenderBands(geometry, nullptr, options)) / expected, 1.0, 0.03) << at;
}

// A dark glossy floor under an open sky, seen straight down and at 60
// degrees: its radiance is rho(w_o) E / pi, rho the BSDF's directional
// albedo toward the camera, in direct transport and in dss (before, dss
// reflected its sky by the Lambertian albedo, 0.05, about half of rho
// here). That is exact for a uniform sky, where the path tracer agrees; a
// sky brighter at the zenith (gradient 0.6) puts a highlight in the lobe
// that rho averages away (the path tracer 1.057 of it straight down, 0.954
// at 60 degrees): the path tracer is held to it only without a gradient.
TEST(Sky, AGlossyFloorReflectsTheOpenSkyAlikeInEveryTransport) {
  for (double gradient : {0.0, 0.6})
    for (double view_deg : {0.0, 60.0}) {
      const double a = view_deg * kPi / 180;
      const Scene scene = GlossyFloorUnderSky(gradient, a, 0.05, Gloss{0.0f, 0.3f});
      SceneGeometry geometry(scene);
      const double rho = DirectionalAlbedoTowardCamera(scene, a);
      ASSERT_GT(rho, 1.5 * 0.05);  // what the test tells apart
      const double expected = rho * 2.0 * (kPi + 2 * kPi / 3 * gradient) / kPi;
      ExpectTransportsShow(geometry, expected, gradient == 0,
                           "gradient " + std::to_string(gradient) + ", view " + std::to_string(view_deg));
    }
}

// The same on glossy floors drawn at random (seeded): base colour 0.02 to
// 0.9, metallic 0 to 1, roughness 0.15 to 0.9, seen from 0 to 70 degrees,
// under a uniform sky: rho(w_o) E / pi in direct and dss (1%), and in the
// path tracer (3%).
TEST(Sky, RandomGlossyFloorsReflectTheUniformSkyAlikeInEveryTransport) {
  SplitMix64 random(20261206);
  for (int trial = 0; trial < 4; ++trial) {
    const float base = 0.02f + 0.88f * random.UniformFloat(), metallic = random.UniformFloat(),
                roughness = 0.15f + 0.75f * random.UniformFloat();
    const double a = 70 * kPi / 180 * random.UniformDouble();
    const Scene scene = GlossyFloorUnderSky(0.0, a, base, Gloss{metallic, roughness});
    SceneGeometry geometry(scene);
    // E / pi = 2 under a uniform sky of radiance 2.
    const double expected = DirectionalAlbedoTowardCamera(scene, a) * 2.0;
    ExpectTransportsShow(geometry, expected, true,
                         "base " + std::to_string(base) + ", metallic " + std::to_string(metallic) + ", roughness " +
                             std::to_string(roughness) + ", view " + std::to_string(a * 180 / kPi));
  }
}

TEST(Sky, DirectionalOcclusionUnderADiskIsTheClosedForm) {
  // A disk of angular radius theta0 straight above the receiver hides
  // 2 pi L [sin^2(theta0) / 2 + g (1 - cos^3(theta0)) / 3] of the sky's irradiance.
  const float R = 0.5f, h = 1.0f;
  const double g = 0.8;
  Scene scene = testing::DiskOverFloor(R, h);
  SceneGeometry geometry(scene);
  const CameraRays camera(scene, 0);
  // The floor's own surfels cannot hide the sky from a floor point: the disk's alone.
  const std::vector<Surfel> surfels = testing::DiskSurfels(geometry, camera);
  const GBuffer gb = RenderGBuffer(geometry, scene, 0);
  const std::size_t centre = 16 * 33 + 16;
  const double cos0 = h / std::sqrt(h * h + R * R), sin2 = 1 - cos0 * cos0;
  const double truth = kPi + 2 * kPi / 3 * g - 2 * kPi * (sin2 / 2 + g * (1 - cos0 * cos0 * cos0) / 3);
  auto sky_irradiance = [&](const DssResult& r) {
    return kPi * (1 - r.occlusion[centre]) + g * (2 * kPi / 3 * gb.normal[centre].y() - kPi * r.occlusion_y[centre]);
  };
  // The disk seen from below also hides its own floor's sky; the blocked part is what matters.
  const double blocked = kPi + 2 * kPi / 3 * g - truth;
  EXPECT_NEAR(kPi + 2 * kPi / 3 * g - sky_irradiance(GatherAllSurfels(gb, surfels, {}, 0)), blocked, 0.02 * blocked);
  EXPECT_NEAR(kPi + 2 * kPi / 3 * g - sky_irradiance(SplatDeepScreenSpace(gb, camera, surfels, {}, {})), blocked,
              0.05 * blocked);
  // The gradient matters: ambient occlusion times the open sky's irradiance
  // (what a uniform treatment gives) misses the blocked part by far more.
  const double ao_estimate = sin2 * (kPi + 2 * kPi / 3 * g);
  EXPECT_GT(std::fabs(ao_estimate - blocked), 0.1 * blocked);
}

TEST(Sky, DssDarkensACornerAsRayTracingDoes) {
  // A floor and a wall under a sky: near their corner the wall hides half the
  // sky. Direct with many sky rays is the reference for the shading of the
  // camera's pixels (one bounce off the wall aside, which dss adds and
  // direct does not); dss's directional occlusion must follow it.
  Scene scene = testing::EmptyScene(48, 32);
  scene.camera.keys = {{0.0, Vec3(0.0, 0.6, 1.2), Vec3(0, 0.1, 0)}};
  scene.camera.fov_deg = 50;
  scene.objects.push_back(testing::MakeObject("floor", MakeQuad(3, 3), 0.5));
  Object wall = testing::MakeObject("wall", MakeQuad(3, 1.5), 0.0);  // black: no bounce
  RigidKey up;
  up.rotate = Eigen::Quaterniond(Eigen::AngleAxisd(kPi / 2, Vec3::UnitX()));
  up.translate = Vec3(0, 0.75, -0.2);
  wall.motion.keys = {up};
  scene.objects.push_back(wall);
  scene.environment = Sky(1.0, 0.5);
  SceneGeometry geometry(scene);
  FrameOptions options;
  options.transport = Transport::kDirect;
  options.sky_rays = 1024;
  const Image reference = RenderBands(geometry, nullptr, options);
  options.transport = Transport::kDss;
  const Image dss = RenderBands(geometry, nullptr, options);
  const Image open = [&] {
    Scene no_wall = scene;
    no_wall.objects.pop_back();
    SceneGeometry g2(no_wall);
    options.transport = Transport::kDss;
    return RenderBands(g2, nullptr, options);
  }();
  // Over the floor's pixels: dss is much closer to the reference than the open sky is.
  double err_dss = 0, err_open = 0;
  int n = 0;
  const GBuffer gb = RenderGBuffer(geometry, scene, 0);
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 48; ++x) {
      if (gb.object[static_cast<std::size_t>(y) * 48 + x] != 0) continue;
      err_dss += std::fabs(dss.at(x, y)[2] - reference.at(x, y)[2]);
      err_open += std::fabs(open.at(x, y)[2] - reference.at(x, y)[2]);
      ++n;
    }
  ASSERT_GT(n, 300);
  EXPECT_LT(err_dss, 0.35 * err_open) << err_dss / n << " vs " << err_open / n;
}

TEST(Sky, APhosphorUnderTheSkyChargesAsTheClosedForm) {
  Scene scene = FloorUnderSky(0.4);
  scene.objects[0].phosphor = testing::UniformPhosphor(0.05, {0, 0.2, 0, 0, 0, 0, 0, 0}, {0, 0, 0, 0, 0.3, 0, 0, 0});
  scene.environment->schedule.keys = {{0.0, 1.0}, {10.0, 0.0}};
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  solver.AdvanceTo(10);
  const double E = 2.0 * (kPi + 2 * kPi / 3 * 0.4), a = 0.2 * E, k = a + 0.05;
  const double r = a / k * (1 - std::exp(-k * 10));
  EXPECT_NEAR(solver.State(0, 0, 0) / r, 1.0, 0.01);
  EXPECT_NEAR(solver.TexelIrradiance(0, 0)[1], 0.0, 1e-12);  // off at 10 s
  solver.AdvanceTo(30);
  EXPECT_NEAR(solver.State(0, 0, 0) / (r * std::exp(-0.05 * 20)), 1.0, 0.01);
}

}  // namespace
}  // namespace phos::render
