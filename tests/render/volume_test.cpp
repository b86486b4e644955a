// Participating media: closed forms of transmittance, single scattering and
// the rate equation per voxel; the extremes of optical depth.
#include "phos/render/volume.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "phos/render/renderer.h"
#include "phos/render/solver.h"
#include "scene_util.h"

namespace phos::render {
namespace {

constexpr double kPi = 3.14159265358979323846;

Volume UniformBox(double sigma_t, int n, double albedo = 0.5, double g = 0.0) {
  Volume v;
  v.name = "box";
  v.min_m = Vec3(-1, -1, -1);
  v.max_m = Vec3(1, 1, 1);
  v.nx = v.ny = v.nz = n;
  v.density.assign(static_cast<std::size_t>(n) * n * n, 1.0f);
  v.sigma_t_per_m = sigma_t;
  v.albedo.assign(8, albedo);
  v.g = g;
  return v;
}

// A scene with the media and a small quad far away (the geometry needs a mesh).
Scene MediaScene(std::vector<Volume> volumes) {
  Scene scene = testing::EmptyScene();
  scene.objects.push_back(testing::MakeObject("far", MakeQuad(0.01, 0.01), 0.0));
  scene.objects.back().motion.keys = {{0.0, Vec3(0, -100, 0)}};
  scene.volumes = std::move(volumes);
  return scene;
}

Light Directional(const Vec3& travel, double E) {
  Light light;
  light.kind = Light::Kind::kDirectional;
  light.direction = travel.normalized();
  light.E_per_band.assign(8, E);
  return light;
}

TEST(HenyeyGreenstein, IntegratesToOneWithMeanCosineG) {
  for (float g : {-0.7f, 0.0f, 0.3f, 0.9f}) {
    double total = 0, mean_cos = 0;
    const int n = 200000;
    for (int i = 0; i < n; ++i) {
      const double mu = -1 + 2 * (i + 0.5) / n;  // d omega = 2 pi d mu
      const double p = HenyeyGreenstein(static_cast<float>(mu), g) * 2 * kPi * 2.0 / n;
      total += p;
      mean_cos += p * mu;
    }
    EXPECT_NEAR(total, 1.0, 1e-3) << g;
    EXPECT_NEAR(mean_cos, g, 1e-3) << g;
  }
}

TEST(Media, TransmittanceOfAUniformBoxIsBeerLambert) {
  for (double sigma : {0.0, 0.01, 0.7, 5.0}) {
    const Scene scene = MediaScene({UniformBox(sigma, 16)});
    SceneGeometry geometry(scene);
    VolumeMedia media(scene, geometry);
    EXPECT_NEAR(media.Transmittance(Vec3f(-3, 0.2f, 0.1f), Vec3f(3, 0.2f, 0.1f)), std::exp(-2 * sigma), 1e-5) << sigma;
    // Along a diagonal, through a corner region: the chord length times sigma.
    const Vec3f a(-2, -2, -2), b(2, 2, 2);
    EXPECT_NEAR(media.Transmittance(a, b), std::exp(-sigma * 2 * std::sqrt(3.0)), 1e-4) << sigma;
    // Points outside miss it.
    EXPECT_FLOAT_EQ(media.Transmittance(Vec3f(-3, 2, 0), Vec3f(3, 2, 0)), 1.0f);
  }
}

TEST(Media, SingleScatteringOfACollimatedBeamMatchesTheClosedForm) {
  // Light travels -y into the box [-1, 1]^3; a ray along -z at height y0 sees
  // L = albedo p_HG(0) E e^{-sigma (1 - y0)} (1 - e^{-2 sigma}).
  for (double sigma : {0.2, 0.8, 3.0})
    for (double g : {0.0, 0.5}) {
      Scene scene = MediaScene({UniformBox(sigma, 32, 0.6, g)});
      scene.lights.push_back(Directional(Vec3(0, -1, 0), 2.0));
      SceneGeometry geometry(scene);
      VolumeMedia media(scene, geometry);
      media.PrepareLighting(0);
      const double y0 = 0.3;
      float L[8] = {};
      const float T = media.March(Vec3f(0.1f, static_cast<float>(y0), 3), Vec3f(0, 0, -1), 1e30f, 0.5f, L);
      const double expected = 0.6 * HenyeyGreenstein(0.0f, static_cast<float>(g)) * 2.0 * std::exp(-sigma * (1 - y0)) *
                              (1 - std::exp(-2 * sigma));
      EXPECT_NEAR(T, std::exp(-2 * sigma), 1e-5);
      for (float l : L) EXPECT_NEAR(l / expected, 1.0, 0.01) << "sigma " << sigma << " g " << g;
    }
}

TEST(Media, ExtremeOpticalDepthsStayFiniteAndBounded) {
  for (double sigma : {0.0, 1e-12, 1e8, 1e30}) {
    Scene scene = MediaScene({UniformBox(sigma, 8, 1.0, 0.0)});
    scene.lights.push_back(Directional(Vec3(0, -1, 0), 1e12));  // a huge irradiance too
    SceneGeometry geometry(scene);
    VolumeMedia media(scene, geometry);
    media.PrepareLighting(0);
    float L[8] = {};
    const float T = media.March(Vec3f(0, 0, 3), Vec3f(0, 0, -1), 1e30f, 0.5f, L);
    EXPECT_TRUE(std::isfinite(T) && T >= 0 && T <= 1) << sigma;
    // Single scattering can never exceed albedo p E (the source, seen through an opaque cloud).
    for (float l : L) EXPECT_TRUE(std::isfinite(l) && l >= 0 && l <= 1e12 / (4 * kPi) * (1 + 1e-5)) << sigma;
    if (sigma == 0) {
      EXPECT_EQ(T, 1.0f);
      EXPECT_EQ(L[0], 0.0f);
    }
  }
}

TEST(Media, EmptyGridsCarryNothing) {
  Volume v = UniformBox(1.0, 8);
  std::fill(v.density.begin(), v.density.end(), 0.0f);
  v.density[0] = 1.0f;  // one voxel in a corner
  Scene scene = MediaScene({v});
  scene.volumes[0].phosphor = testing::UniformPhosphor(0.1, {0, 1, 0, 0, 0, 0, 0, 0}, {0, 0, 0, 0, 0.5, 0, 0, 0});
  scene.lights.push_back(Directional(Vec3(0, -1, 0), 1.0));
  SceneGeometry geometry(scene);
  VolumeMedia media(scene, geometry);
  // A state for the one voxel with density; light at its 2 x 2 x 2 neighbourhood.
  EXPECT_EQ(media.stats().phosphor_voxels, 1u);
  EXPECT_EQ(media.stats().lit_voxels, 8u);
  EXPECT_EQ(media.stats().voxels, 512u);
}

TEST(Media, PhosphorVoxelsChargeAndDecayAsTheClosedForm) {
  // An optically thin cloud: every voxel sees E, so r follows Eq. 8.1 exactly.
  const double kr = 0.05, ke = 0.3, E = 2.0, on_s = 7.0;
  Volume v = UniformBox(1e-9, 6);
  v.phosphor = testing::UniformPhosphor(kr, {0, ke, 0, 0, 0, 0, 0, 0}, {0, 0, 0, 0, 0.4, 0, 0, 0});
  Scene scene = MediaScene({v});
  Light light = Directional(Vec3(0, -1, 0), 0.0);
  light.E_per_band[1] = E;
  light.schedule.keys = {{0.0, 1.0}, {on_s, 0.0}};
  scene.lights.push_back(light);
  scene.end_s = 30;
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  ASSERT_NE(solver.media(), nullptr);
  const double a = ke * E, k = a + kr;
  for (double t : {3.0, 7.0, 20.0}) {
    solver.AdvanceTo(t);
    const double r_on = a / k * (1 - std::exp(-k * std::min(t, on_s)));
    const double r = t <= on_s ? r_on : r_on * std::exp(-kr * (t - on_s));
    for (std::size_t j : {std::size_t{0}, std::size_t{100}, std::size_t{215}}) {
      EXPECT_NEAR(solver.media()->State(0, 0, j) / r, 1.0, 1e-5) << t;
      EXPECT_NEAR(solver.media()->Lp(0, 4, j) / (0.4 * kr * r), 1.0, 1e-5) << t;
    }
  }
  EXPECT_EQ(solver.media()->stats().dark_jumps, 1u);  // 7 s to 20 s in one closed-form jump
}

TEST(Media, AnOpaqueGlowingCloudLooksLikeAPhosphorSurface) {
  // Uniform state r: Lp = Lambda kr r. An optically thick cloud shows Lp;
  // a thin one sigma d Lp; in between Lp (1 - e^{-sigma d}).
  for (double sigma : {0.05, 1.0, 1e6}) {
    Volume v = UniformBox(sigma, 8, 0.0);
    v.phosphor = testing::UniformPhosphor(0.2, {0, 1, 0, 0, 0, 0, 0, 0}, {0, 0, 0, 0.3, 0, 0, 0, 0});
    v.initial = {InitialState::Kind::kUniform, 0.5};
    Scene scene = MediaScene({v});
    SceneGeometry geometry(scene);
    CoupledSolver solver(scene, geometry);
    VolumeMedia* media = solver.media();
    media->PrepareLighting(0);
    float L[8] = {};
    media->March(Vec3f(0.2f, -0.3f, 5), Vec3f(0, 0, -1), 1e30f, 0.5f, L);
    const double Lp = 0.3 * 0.2 * 0.5;
    EXPECT_NEAR(L[3] / (Lp * (1 - std::exp(-2 * sigma))), 1.0, 1e-4) << sigma;
    EXPECT_EQ(L[2], 0.0f);
  }
}

TEST(Media, EquilibriumStartIsTheSteadyState) {
  const double kr = 0.1, ke = 0.5, E = 0.4;
  Volume v = UniformBox(1e-9, 4);
  v.phosphor = testing::UniformPhosphor(kr, {0, ke, 0, 0, 0, 0, 0, 0}, {0, 0, 0, 0, 0.4, 0, 0, 0});
  v.initial.kind = InitialState::Kind::kEquilibrium;
  Scene scene = MediaScene({v});
  Light light = Directional(Vec3(0, -1, 0), 0.0);
  light.E_per_band[1] = E;
  scene.lights.push_back(light);
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  EXPECT_NEAR(solver.media()->State(0, 0, 5), ke * E / (ke * E + kr), 1e-6);
}

TEST(Media, ASheetChargesOnlyItsSlab) {
  Volume v = UniformBox(1e-9, 20);
  v.phosphor = testing::UniformPhosphor(0.1, {0, 1, 0, 0, 0, 0, 0, 0}, {0, 0, 0, 0, 0.4, 0, 0, 0});
  Scene scene = MediaScene({v});
  Light sheet = Directional(Vec3(0, -1, 0), 0.0);
  sheet.kind = Light::Kind::kSheet;
  sheet.E_per_band[1] = 1.0;
  sheet.sheet_normal = Vec3(1, 0, 0);
  sheet.sheet_thickness_m = 0.3;
  sheet.position = Vec3(0.5, 0, 0);
  scene.lights.push_back(sheet);
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  solver.AdvanceTo(2.0);
  // Each voxel (0.1 m wide) is charged by the fraction of it inside the slab
  // [0.35, 0.65]: a = ke E coverage, the closed form of Eq. 8.1.
  for (int x = 0; x < 20; ++x) {
    const double cx = -1 + 0.1 * (x + 0.5);
    const double coverage = std::clamp((std::min(cx + 0.05, 0.65) - std::max(cx - 0.05, 0.35)) / 0.1, 0.0, 1.0);
    const double a = 1.0 * coverage, k = a + 0.1;
    const double r = a / k * (1 - std::exp(-k * 2.0));
    const float state = solver.media()->State(0, 0, static_cast<std::size_t>((7 * 20 + 9) * 20 + x));
    if (coverage > 0)
      EXPECT_NEAR(state, r, 1e-5) << cx;
    else
      EXPECT_EQ(state, 0.0f) << cx;
  }
  EXPECT_GT(solver.media()->State(0, 0, (7 * 20 + 9) * 20 + 14), 0.5f);  // x = 0.45: fully inside
}

TEST(Media, ACloudShadowsTheFloorByItsTransmittance) {
  // A slab of cloud 0.2 m thick between a point light and a floor; the camera
  // sees the floor below the cloud. The floor's centre darkens by e^{-0.2 sigma}.
  const double sigma = 3.0;
  Scene scene = testing::EmptyScene(9, 9);
  scene.camera.keys = {{0.0, Vec3(0, 0.5, 3), Vec3(0, 0, 0)}};
  scene.camera.fov_deg = 10;
  scene.objects.push_back(testing::MakeObject("floor", MakeQuad(4, 4), 0.5));
  scene.lights.push_back(testing::PointLight(Vec3(0, 3, 0), std::vector<double>(8, 1.0)));
  Volume v = UniformBox(sigma, 8, 0.0);
  v.min_m = Vec3(-0.5, 0.9, -0.5);
  v.max_m = Vec3(0.5, 1.1, 0.5);
  FrameOptions options;
  options.transport = Transport::kDirect;
  SceneGeometry plain_geometry(scene);
  const Image plain = RenderBands(plain_geometry, nullptr, options);
  scene.volumes.push_back(v);
  SceneGeometry geometry(scene);
  const Image shadowed = RenderBands(geometry, nullptr, options);
  EXPECT_NEAR(shadowed.at(4, 4)[2] / plain.at(4, 4)[2], std::exp(-0.2 * sigma), 1e-3);
}

}  // namespace
}  // namespace phos::render

namespace phos::render {
namespace {

TEST(IntervalMap, ADiskLightsAPointInAMediumWithItsSolidAngle) {
  // A disk of radius R at height h facing down with radiosity B: at a point
  // of a medium on its axis at distance z the radiance over the sphere
  // integrates to Phi = (B / pi) 2 pi (1 - z / sqrt(z^2 + R^2)).
  const float R = 0.5f, h = 1.0f, B = 2.0f;
  Scene scene = testing::DiskOverFloor(R, h);
  SceneGeometry geometry(scene);
  const CameraRays camera(scene, 0);
  // Only the disk sends light to a point in a medium: its surfels alone.
  const std::vector<Surfel> surfels = testing::DiskSurfels(geometry, camera);
  const std::vector<float> radiosity(surfels.size(), B);
  const std::size_t centre = 16 * 33 + 16;
  for (float y : {0.1f, 0.3f}) {
    // Receivers: points in a medium (no normal) along each pixel's ray.
    GBuffer g = RenderGBuffer(geometry, scene, 0);
    for (std::size_t p = 0; p < g.normal.size(); ++p) g.normal[p] = Vec3f::Zero();
    g.position[centre] = Vec3f(0, y, 0);
    g.depth[centre] = 0.5f - y;
    const double z = h - y, truth = 2 * B * (1 - z / std::sqrt(z * z + R * R));
    const DssResult exact = GatherAllSurfels(g, surfels, radiosity, 1);
    EXPECT_NEAR(exact.irradiance[centre], truth, 0.02 * truth) << y;
    DssOptions dss_options;
    dss_options.channels = 1;
    const DssResult dss = SplatDeepScreenSpace(g, camera, surfels, radiosity, dss_options);
    EXPECT_NEAR(dss.irradiance[centre], truth, 0.05 * truth) << y;
  }
}

TEST(IntervalMap, AGlowingWallLightsTheMediumInFrontOfIt) {
  // A glowing square (half-size a, radiance Lp) behind a slab of medium
  // (z in [0.2, 0.4], sigma, albedo): the centre pixel sees
  //   T Lp + albedo / (4 pi) int Lp Omega(z) sigma e^{-sigma (0.4 - z)} dz,
  // Omega(z) = 4 asin(a^2 / (a^2 + z^2)) the square's solid angle on its axis.
  const double a = 1.0, sigma = 2.0, albedo = 0.8, kr = 0.2, Lambda = 0.5, r0 = 0.5;
  Scene scene = testing::EmptyScene(33, 33);
  scene.camera.keys = {{0.0, Vec3(0, 0, 3), Vec3(0, 0, 0)}};
  scene.camera.fov_deg = 20;
  Object wall =
      testing::MakeObject("wall", MakeQuad(2 * a, 2 * a), 0.0,
                          testing::UniformPhosphor(kr, {0, 1, 0, 0, 0, 0, 0, 0}, {0, 0, 0, 0, Lambda, 0, 0, 0}));
  RigidKey upright;
  upright.rotate = Eigen::Quaterniond(Eigen::AngleAxisd(kPi / 2, Vec3::UnitX()));  // normal +y -> +z
  wall.motion.keys = {upright};
  wall.initial = {InitialState::Kind::kUniform, r0};
  scene.objects.push_back(wall);
  Volume slab = UniformBox(sigma, 12, albedo);
  slab.min_m = Vec3(-0.3, -0.3, 0.2);
  slab.max_m = Vec3(0.3, 0.3, 0.4);
  scene.volumes.push_back(slab);
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  FrameOptions options;
  options.transport = Transport::kDss;
  options.interval_layers = 16;
  const Image image = RenderBands(geometry, &solver, options);
  const double Lp = Lambda * kr * r0;
  double in_medium = 0;
  const int n = 4000;
  for (int i = 0; i < n; ++i) {
    const double z = 0.2 + 0.2 * (i + 0.5) / n;
    in_medium += albedo / (4 * kPi) * Lp * 4 * std::asin(a * a / (a * a + z * z)) * sigma *
                 std::exp(-sigma * (0.4 - z)) * 0.2 / n;
  }
  const double T = std::exp(-0.2 * sigma);
  const float centre = image.at(16, 16)[4];
  EXPECT_NEAR((centre - T * Lp) / in_medium, 1.0, 0.05);
  // Without the interval map (direct), the medium only dims the wall.
  options.transport = Transport::kDirect;
  EXPECT_NEAR(RenderBands(geometry, &solver, options).at(16, 16)[4], T * Lp, 1e-3 * Lp);
}

}  // namespace
}  // namespace phos::render
