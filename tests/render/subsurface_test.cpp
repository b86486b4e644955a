// Subsurface scattering by dipole diffusion: the profile's closed forms, and
// the splat against them on a uniformly lit plane and at a shadow's edge.
#include "phos/render/subsurface.h"

#include <gtest/gtest.h>

#include <cmath>

#include "phos/render/dss.h"
#include "phos/render/renderer.h"
#include "scene_util.h"

namespace phos::render {
namespace {

TEST(Dipole, ProfileIntegratesToTheTotalDiffuseReflectance) {
  for (const auto& [sigma_a, sigma_s] :
       std::vector<std::pair<double, double>>{{10, 1000}, {100, 300}, {1, 5000}, {2000, 10}}) {
    const Dipole d = Dipole::From(sigma_a, sigma_s, 1.3);
    // Numerically, on a logarithmic grid of r (the profile spans decades).
    double integral = 0;
    const double r0 = 1e-3 * d.z_r, r1 = 60 / d.sigma_tr + 100 * d.z_v;
    const int n = 200000;
    for (int i = 0; i < n; ++i) {
      const double a = r0 * std::pow(r1 / r0, double(i) / n), b = r0 * std::pow(r1 / r0, double(i + 1) / n);
      const double r = 0.5 * (a + b);
      integral += d.Rd(static_cast<float>(r)) * 2 * 3.14159265358979 * r * (b - a);
    }
    integral += d.AnnulusIntegral(0, r0);
    EXPECT_NEAR(integral / d.TotalReflectance(), 1.0, 2e-3) << sigma_a << " " << sigma_s;
    // The annulus closed form agrees with the total, and a surfel's kernel is the point rule when small.
    EXPECT_NEAR(d.AnnulusIntegral(0, INFINITY) / d.TotalReflectance(), 1.0, 1e-5);  // float parameters
    const float r = 3 * d.z_v, area = 1e-6f * d.z_r * d.z_r;
    EXPECT_NEAR(d.SurfelKernel(r, area) / (d.Rd(r) * area), 1.0, 1e-3);
    // Disks of a hexagonal lattice (spacing 2 mean free paths) beyond a near
    // field of two spacings, plus the near field in closed form, sum to the
    // total wherever the receiver sits among them.
    const double spacing = 2 / d.sigma_tr, cell = std::sqrt(3.0) / 2 * spacing * spacing;
    const float near = static_cast<float>(2 * spacing);
    for (const auto& [ox, oy] : std::vector<std::pair<double, double>>{{0, 0}, {0.5, 0}, {0.5, 0.29}, {0.25, 0.1}}) {
      double lattice = d.AnnulusIntegral(0, near);
      for (int i = -200; i <= 200; ++i)
        for (int j = -200; j <= 200; ++j) {
          const double x = spacing * (i + 0.5 * j - ox), y = spacing * (std::sqrt(3.0) / 2 * j - oy);
          const double rr = std::sqrt(x * x + y * y);
          if (rr < 60 / d.sigma_tr) lattice += d.SurfelKernel(static_cast<float>(rr), static_cast<float>(cell), near);
        }
      EXPECT_NEAR(lattice / d.TotalReflectance(), 1.0, 0.03)
          << sigma_a << " " << sigma_s << " offset " << ox << "," << oy;
    }
    EXPECT_GT(d.TotalReflectance(), 0);
    EXPECT_LT(d.TotalReflectance(), 1);
  }
  // More scattering, less absorption: brighter.
  EXPECT_GT(Dipole::From(1, 1000, 1.3).TotalReflectance(), Dipole::From(10, 1000, 1.3).TotalReflectance());
}

// A translucent square 0.4 m wide under a light from straight above, seen
// from above; optionally a blocker shadows its half x < 0.
Scene TranslucentPlane(bool shadow) {
  Scene scene = testing::EmptyScene(41, 41);
  scene.camera.keys = {{0.0, Vec3(0, 0.6, 0), Vec3(0, 0, 0.0001)}};
  scene.camera.up = Vec3(0, 0, 1);
  scene.camera.fov_deg = 30;
  Object slab = testing::MakeObject("wax", MakeQuad(0.4, 0.4), 0.0);
  Subsurface sss;
  sss.sigma_a_per_m.assign(8, 3.0);
  sss.sigma_s_prime_per_m.assign(8, 300.0);
  slab.subsurface = sss;
  const double Rd = Dipole::From(3, 300, 1.3).TotalReflectance();
  slab.albedo.assign(8, Rd);
  scene.objects.push_back(slab);
  if (shadow) {
    Object blocker = testing::MakeObject("blocker", MakeQuad(1.0, 2.0), 0.5);
    blocker.motion.keys = {{0.0, Vec3(-0.5, 2.0, 0)}};  // covers x < 0, far above, facing up
    scene.objects.push_back(blocker);
  }
  Light light;
  light.kind = Light::Kind::kDirectional;
  light.direction = Vec3(0, -1, 0);
  light.E_per_band.assign(8, 1.0);
  scene.lights.push_back(light);
  return scene;
}

TEST(Subsurface, AUniformlyLitPlaneReturnsTheTotalDiffuseReflectance) {
  const Scene scene = TranslucentPlane(false);
  SceneGeometry geometry(scene);
  const CameraRays camera(scene, 0);
  const Dipole d = Dipole::From(3, 300, 1.3);
  std::vector<Dipole> dipoles(8, d);
  const auto surfels = Surfelize(geometry, camera.origin(), 30, {});
  const std::vector<float> E(surfels.size(), 1.0f);
  const GBuffer g = RenderGBuffer(geometry, scene, 0);
  const std::size_t centre = 20 * 41 + 20;
  ASSERT_EQ(g.object[centre], 0);
  // The profile reaches about 2 cm (1 / sigma_tr), the surfels are about 7 mm apart: the near field
  // (two surfel radii) comes from the receiver's own E = 1 in closed form.
  const float near_m = 2 * SurfelOptions{}.s * std::tan(15 * 3.14159265f / 180) * g.depth[centre];
  const std::vector<float> near(g.depth.size(), near_m);
  const double near_field = d.AnnulusIntegral(0, near_m);
  EXPECT_LT(near_field, 0.9 * d.TotalReflectance());  // the surfels' part matters
  const DssResult exact = GatherAllSurfels(g, surfels, E, 1, &dipoles, &near);
  EXPECT_NEAR((near_field + exact.irradiance[centre]) / d.TotalReflectance(), 1.0, 0.03);
  DssOptions options;
  options.channels = 1;
  options.dipoles = &dipoles;
  options.near_m = &near;
  const DssResult dss = SplatDeepScreenSpace(g, camera, surfels, E, options);
  EXPECT_NEAR((near_field + dss.irradiance[centre]) / d.TotalReflectance(), 1.0, 0.05);

  // The dss transport agrees with direct (albedo R_d) where the light is uniform.
  FrameOptions frame;
  frame.transport = Transport::kDss;
  const float with_dss = RenderBands(geometry, nullptr, frame).at(20, 20)[3];
  frame.transport = Transport::kDirect;
  const float with_direct = RenderBands(geometry, nullptr, frame).at(20, 20)[3];
  EXPECT_NEAR(with_dss / with_direct, 1.0, 0.05);
}

TEST(Subsurface, LightBleedsIntoTheShadowByTheProfile) {
  const Scene scene = TranslucentPlane(true);
  SceneGeometry geometry(scene);
  FrameOptions frame;
  frame.transport = Transport::kDss;
  const Image dss = RenderBands(geometry, nullptr, frame);
  frame.transport = Transport::kDirect;
  const Image direct = RenderBands(geometry, nullptr, frame);
  // Image x grows with world -x here (looking down, up = +z): find the edge from direct.
  int lit_side = direct.at(35, 20)[3] > 0 ? 35 : 5, dark_side = 40 - lit_side;
  ASSERT_EQ(direct.at(dark_side, 20)[3], 0.0f);
  ASSERT_GT(direct.at(lit_side, 20)[3], 0.0f);
  // Along the row from the lit side into the shadow: direct drops to zero at
  // the edge; dss falls off smoothly, lights the shadow next to the edge, and
  // deep in the shadow (many mean free paths) is dark again.
  const int step = lit_side > dark_side ? -1 : 1;
  int edge = lit_side;
  while (direct.at(edge, 20)[3] > 0) edge += step;
  EXPECT_GT(dss.at(edge, 20)[3], 0.02f * dss.at(lit_side, 20)[3]);  // bleeding
  EXPECT_LT(dss.at(dark_side, 20)[3], 1e-3f * dss.at(lit_side, 20)[3]);
  for (int x = edge; x != dark_side; x += step) EXPECT_LE(dss.at(x + step, 20)[3], dss.at(x, 20)[3] * 1.0001f + 1e-9f);
}

}  // namespace
}  // namespace phos::render
