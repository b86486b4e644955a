// Area lights (quad and disk) against closed forms and the path tracer:
//  - the unshadowed irradiance of a rectangle on a parallel plane, by the
//    configuration factor of a point below a rectangle's corner summed over
//    four rectangles (Howell's catalogue, case B-3), which is not the
//    polygon formula phos computes it with;
//  - a parallel disk seen from off its axis (Howell's case B-13);
//  - tilted lights and surfaces clipped by the horizon, against brute-force
//    quadrature of cos cos' / d^2 over the light;
//  - the direct transport's pixels and the coupled solver's texels under a
//    quad light, against the closed form;
//  - under a quad light with an occluder, the solver's texel irradiance
//    against the path tracer's floor (soft shadow, MIS with the bounces
//    that find the light).

#include <gtest/gtest.h>

#include <cmath>
#include <random>

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

// Configuration factor from a point to a parallel a x b rectangle at height
// h, the point below one of its corners: E / L = pi F.
double CornerIrradiance(double a, double b, double h) {
  const double X = a / h, Y = b / h;
  const double F = (X / std::sqrt(1 + X * X) * std::atan(Y / std::sqrt(1 + X * X)) +
                    Y / std::sqrt(1 + Y * Y) * std::atan(X / std::sqrt(1 + Y * Y))) /
                   (2 * M_PI);
  return M_PI * F;
}
// A rectangle [x0, x1] x [z0, z1] at height h over the point (px, pz): four
// corner rectangles, signed.
double RectangleIrradiance(double x0, double x1, double z0, double z1, double h, double px, double pz) {
  auto corner = [&](double x, double z) {
    const double dx = x - px, dz = z - pz;
    if (dx == 0 || dz == 0) return 0.0;
    return (dx > 0 ? 1 : -1) * (dz > 0 ? 1 : -1) * CornerIrradiance(std::abs(dx), std::abs(dz), h);
  };
  return corner(x1, z1) - corner(x0, z1) - corner(x1, z0) + corner(x0, z0);
}

// A parallel disk of radius R at height h, the point at horizontal offset x
// from its axis: E / L = pi / 2 (1 - (h^2 + x^2 - R^2) / sqrt((h^2 + x^2 + R^2)^2 - 4 R^2 x^2)).
double DiskIrradiance(double R, double h, double x) {
  const double s = h * h + x * x;
  return M_PI / 2 * (1 - (s - R * R) / std::sqrt((s + R * R) * (s + R * R) - 4 * R * R * x * x));
}

Light QuadLight(const Vec3& centre, const Vec3& normal, const Vec3& tangent, double width, double height,
                double radiance) {
  Light light;
  light.name = "panel";
  light.kind = Light::Kind::kQuad;
  light.position = centre;
  light.normal = normal.normalized();
  light.tangent = tangent.normalized();
  light.width_m = width;
  light.height_m = height;
  light.E_per_band.assign(8, radiance);
  return light;
}

Light DiskLight(const Vec3& centre, const Vec3& normal, double radius, double radiance) {
  Light light;
  light.name = "disk";
  light.kind = Light::Kind::kDisk;
  light.position = centre;
  light.normal = normal.normalized();
  light.radius_m = radius;
  light.E_per_band.assign(8, radiance);
  return light;
}

// Brute force: the integral of max(0, n . w) max(0, -N . w) / d^2 over the
// light's area, by the midpoint rule on a k x k grid of the light's square
// parameterization (the disk: only cells whose centre lies inside it).
double QuadratureIrradiance(const LightPose& light, const Eigen::Vector3d& p, const Eigen::Vector3d& n, int k = 1200) {
  const Eigen::Vector3d at = light.at.cast<double>(), u = light.u.cast<double>(), v = light.v.cast<double>();
  const Eigen::Vector3d N = light.normal.cast<double>();
  const double cell = 4 * u.norm() * v.norm() / (double(k) * k);
  double sum = 0;
  for (int i = 0; i < k; ++i)
    for (int j = 0; j < k; ++j) {
      const double x = 2 * (i + 0.5) / k - 1, y = 2 * (j + 0.5) / k - 1;
      if (light.kind == Light::Kind::kDisk && x * x + y * y > 1) continue;
      const Eigen::Vector3d d = at + x * u + y * v - p;
      const double d2 = d.squaredNorm();
      const Eigen::Vector3d w = d / std::sqrt(d2);
      sum += std::max(0.0, n.dot(w)) * std::max(0.0, -N.dot(w)) / d2 * cell;
    }
  return sum;
}

TEST(AreaLight, QuadOverAParallelPlaneIsTheCornerFormula) {
  const double width = 0.8, height = 0.5, h = 0.7;
  const LightPose pose = PoseAt(QuadLight(Vec3(0, h, 0), Vec3(0, -1, 0), Vec3(1, 0, 0), width, height, 1), 0);
  EXPECT_NEAR(pose.area_m2, width * height, 1e-6);
  std::mt19937 random(7);
  std::uniform_real_distribution<double> offset(-1.5, 1.5);
  for (int i = 0; i < 200; ++i) {
    const double px = offset(random), pz = offset(random);
    // width along x; height along normal x tangent = (0,-1,0) x (1,0,0) = (0,0,1), along z.
    const double expected = RectangleIrradiance(-width / 2, width / 2, -height / 2, height / 2, h, px, pz);
    const float got = AreaLightUnoccluded(pose, Vec3f(float(px), 0, float(pz)), Vec3f(0, 1, 0));
    ASSERT_NEAR(got, expected, 1e-4 * expected + 1e-7) << px << ", " << pz;
  }
  // Close and wide, it approaches pi (the whole hemisphere at radiance 1).
  const LightPose wide = PoseAt(QuadLight(Vec3(0, 1e-3, 0), Vec3(0, -1, 0), Vec3(1, 0, 0), 100, 100, 1), 0);
  EXPECT_NEAR(AreaLightUnoccluded(wide, Vec3f::Zero(), Vec3f(0, 1, 0)), M_PI, 1e-4);
}

TEST(AreaLight, DiskOffItsAxisIsTheParallelDiskFormula) {
  const double R = 0.3, h = 0.5;
  const LightPose pose = PoseAt(DiskLight(Vec3(0, h, 0), Vec3(0, -1, 0), R, 1), 0);
  for (double x : {0.0, 0.1, 0.29, 0.31, 0.5, 1.0, 2.0}) {
    const double expected = DiskIrradiance(R, h, x);
    // Any direction around the axis (the disk is a 48-gon inside).
    for (double angle : {0.0, 0.3, 1.1}) {
      const Vec3f p(float(x * std::cos(angle)), 0, float(x * std::sin(angle)));
      EXPECT_NEAR(AreaLightUnoccluded(pose, p, Vec3f(0, 1, 0)), expected, 2e-3 * expected) << x << " " << angle;
    }
  }
}

TEST(AreaLight, TiltedLightsAndSurfacesClippedByTheHorizonMatchQuadrature) {
  std::mt19937 random(11);
  std::normal_distribution<double> gaussian;
  std::uniform_real_distribution<double> uniform(0.1, 1.0);
  int clipped = 0;
  for (int trial = 0; trial < 40; ++trial) {
    const Vec3 normal(gaussian(random), gaussian(random), gaussian(random));
    const Vec3 centre(gaussian(random), gaussian(random), gaussian(random));
    const Light light = trial % 2 ? DiskLight(centre, normal, uniform(random), 1)
                                  : QuadLight(centre, normal, normal.unitOrthogonal() + 0.3 * Vec3::UnitX(),
                                              uniform(random), uniform(random), 1);
    Light oriented = light;
    if (light.kind == Light::Kind::kQuad) {
      Vec3 t = light.tangent - light.tangent.dot(light.normal) * light.normal;
      oriented.tangent = t.normalized();
    }
    const LightPose pose = PoseAt(oriented, 0);
    // A point on the emitting side, with a random surface normal.
    const Eigen::Vector3d p = centre + normal.normalized() * uniform(random) +
                              0.5 * Vec3(gaussian(random), gaussian(random), gaussian(random));
    const Eigen::Vector3d n = Vec3(gaussian(random), gaussian(random), gaussian(random)).normalized();
    const double expected = QuadratureIrradiance(pose, p, n);
    const float got = AreaLightUnoccluded(pose, p.cast<float>(), n.cast<float>());
    if (normal.normalized().dot(p - centre) <= 0) {
      EXPECT_EQ(got, 0.0f);
      continue;
    }
    // Part of the light under the horizon: the polygon was clipped.
    bool below = false, above = false;
    for (double a = 0; a < 2 * M_PI; a += 0.1) {
      const Eigen::Vector3d q = pose.at.cast<double>() + std::cos(a) * pose.u.cast<double>() +
                                std::sin(a) * pose.v.cast<double>() - p;
      (n.dot(q) < 0 ? below : above) = true;
    }
    clipped += below && above;
    // The disk's 48-gon and the quadrature's staircase edge: 0.5%.
    EXPECT_NEAR(got, expected, 5e-3 * expected + 1e-5) << "trial " << trial;
  }
  EXPECT_GE(clipped, 5);  // the horizon clip was exercised
}

// A floor under a 1 x 0.6 m panel 0.8 m up, facing down, with an optional
// black box between them (0.375 to 0.425 m up), seen from 0.3 m above the
// floor looking straight down (beneath the box, which it does not see).
Scene PanelOverAFloor(bool occluder, int pixels) {
  Scene scene = EmptyScene(pixels, pixels);
  scene.camera.keys = {{0, Vec3(0, 0.3, 0.001), Vec3(0, 0, 0)}};
  scene.camera.fov_deg = 100;
  scene.texel_size_m = 0.02;
  scene.objects.push_back(
      MakeObject("floor", MakeQuad(4, 4), 0.5, UniformPhosphor(0.2, std::vector<double>(8, 0.1), {0, 0, 1, 2, 1, 0, 0, 0})));
  if (occluder) {
    Object box = MakeObject("box", MakeBox(Vec3(0.4, 0.05, 0.4), false), 0.0);
    box.motion.keys = {{0, Vec3(0.15, 0.4, 0), Eigen::Quaterniond::Identity(), 1.0}};
    scene.objects.push_back(box);
  }
  scene.lights.push_back(QuadLight(Vec3(0, 0.8, 0), Vec3(0, -1, 0), Vec3(1, 0, 0), 1.0, 0.6, 2.0));
  scene.lights[0].samples = 64;
  return scene;
}

TEST(AreaLight, DirectPixelsAndSolverTexelsUnderAQuadAreTheClosedForm) {
  Scene scene = PanelOverAFloor(false, 32);
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  // Texels: the solver's irradiance at every 97th texel's centre.
  const TexelAtlas& atlas = solver.atlas();
  int checked = 0;
  for (std::size_t c = 0; c < atlas.chunk_count(0); ++c)
    atlas.ForEachTexelInChunk(0, c, [&](std::size_t texel, int triangle, float b1, float b2) {
      if (texel % 97) return;
      const Vec3f p = geometry.Point(0, triangle, b1, b2);
      const double expected = 2.0 * RectangleIrradiance(-0.5, 0.5, -0.3, 0.3, 0.8, p.x(), p.z());
      const double E = solver.TexelIrradiance(0, texel)[3];
      EXPECT_NEAR(E, expected, 0.01 * expected + 1e-6) << "texel " << texel;
      ++checked;
    });
  EXPECT_GT(checked, 100);
  // Pixels: rho E / pi at the floor point of each pixel's centre ray.
  FrameOptions direct;
  const Image d = RenderBands(geometry, nullptr, direct);
  const CameraRays camera(scene, 0);
  for (int y = 0; y < 32; y += 3)
    for (int x = 0; x < 32; x += 3) {
      const Vec3f dir = camera.Direction(x + 0.5f, y + 0.5f);
      const Vec3f p = camera.origin() + dir * (-camera.origin().y() / dir.y());
      const double expected = 0.5 * 2.0 * RectangleIrradiance(-0.5, 0.5, -0.3, 0.3, 0.8, p.x(), p.z()) / M_PI;
      EXPECT_NEAR(d.at(x, y)[3], expected, 0.01 * expected) << x << "," << y;
    }
}

TEST(AreaLight, SolverTexelsInASoftShadowMatchThePathTracer) {
  const int pixels = 40;
  Scene scene = PanelOverAFloor(true, pixels);
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);  // zero state: the floor does not glow yet
  FrameOptions path;
  path.transport = Transport::kPath;
  path.spp = 256;
  path.max_depth = 3;  // the bounce that finds the panel (the box is black, the floor flat)
  const Image pt = RenderBands(geometry, &solver, path);
  // 5 x 5 pixel blocks: the path tracer's mean pi L / rho against the mean
  // of the solver's irradiance at the texels the pixels' centre rays meet.
  const CameraRays camera(scene, 0);
  const int block = 5;
  int penumbra = 0;
  for (int by = 0; by < pixels; by += block)
    for (int bx = 0; bx < pixels; bx += block) {
      double path_sum = 0, path_sum2 = 0, solver_sum = 0;
      for (int y = by; y < by + block; ++y)
        for (int x = bx; x < bx + block; ++x) {
          const double E = M_PI * pt.at(x, y)[3] / 0.5;
          path_sum += E;
          path_sum2 += E * E;
          const Hit hit = geometry.Intersect(camera.origin(), camera.Direction(x + 0.5f, y + 0.5f));
          ASSERT_EQ(hit.object, 0);
          solver_sum += solver.TexelIrradiance(0, solver.atlas().TexelOf(0, hit.triangle, hit.b1, hit.b2))[3];
        }
      const int n = block * block;
      const double path_mean = path_sum / n, solver_mean = solver_sum / n;
      const double spread = std::sqrt(std::max(0.0, path_sum2 / n - path_mean * path_mean) / n);
      const double unshadowed = 2.0 * RectangleIrradiance(-0.5, 0.5, -0.3, 0.3, 0.8, 0, 0);
      if (solver_mean > 0.1 * unshadowed && solver_mean < 0.9 * RectangleIrradiance(-0.5, 0.5, -0.3, 0.3, 0.8, 0, 0) * 2)
        ++penumbra;
      EXPECT_NEAR(solver_mean, path_mean, 4 * spread + 0.02 * std::max(solver_mean, path_mean) + 1e-3)
          << "block " << bx << "," << by;
    }
  EXPECT_GE(penumbra, 3);  // the comparison covered a soft shadow, not just light and umbra
}

TEST(AreaLight, TheCameraSeesItsFrontOnlyAndPathAgreesWithDirect) {
  Scene scene = EmptyScene(24, 24);
  scene.camera.keys = {{0, Vec3(0, 0, 0), Vec3(0, 1, 0.001)}};
  scene.camera.fov_deg = 60;
  scene.lights.push_back(DiskLight(Vec3(0, 1, 0), Vec3(0, -1, 0), 0.3, 3.0));
  SceneGeometry geometry(scene);
  const Image d = RenderBands(geometry, nullptr, FrameOptions{});
  EXPECT_FLOAT_EQ(d.at(12, 12)[3], 3.0f);  // the disk's centre
  EXPECT_EQ(d.at(0, 0)[3], 0.0f);           // beside it
  // Turned away, it shows nothing.
  scene.lights[0].normal = Vec3(0, 1, 0);
  SceneGeometry away(scene);
  EXPECT_EQ(RenderBands(away, nullptr, FrameOptions{}).at(12, 12)[3], 0.0f);
}

// A direct frame and a path-traced one of the same view, band 3, in 4 x 4
// pixel blocks: each block's means and the path tracer's standard error.
struct Block {
  int x, y;
  double direct, path, path_se;
};
std::vector<Block> Blocks(const Image& direct, const Image& path) {
  std::vector<Block> blocks;
  for (int by = 0; by + 4 <= direct.height; by += 4)
    for (int bx = 0; bx + 4 <= direct.width; bx += 4) {
      double sd = 0, sp = 0, sp2 = 0;
      for (int y = by; y < by + 4; ++y)
        for (int x = bx; x < bx + 4; ++x) {
          sd += direct.at(x, y)[3];
          sp += path.at(x, y)[3];
          sp2 += double(path.at(x, y)[3]) * path.at(x, y)[3];
        }
      sd /= 16;
      sp /= 16;
      blocks.push_back({bx, by, sd, sp, std::sqrt(std::max(0.0, sp2 / 16 - sp * sp) / 16)});
    }
  return blocks;
}

// A glowing ball (an emissive icosphere of radius R, radiance L) over a
// grey floor, seen from above: the floor is lit as by a point light of
// intensity pi R^2 L at its centre (a Lambertian sphere), while the
// ball's own body blocks the rays to its far side.
Scene EmissiveBallOverAFloor(int pixels) {
  Scene scene = EmptyScene(pixels, pixels);
  scene.camera.keys = {{0, Vec3(0, 0.5, 0.001), Vec3(0, 0, 0)}};
  scene.camera.fov_deg = 90;
  scene.objects.push_back(MakeObject("floor", MakeQuad(6, 6), 0.5));
  Object ball = MakeObject("ball", MakeSphere(0.2, 3, false), 0.0);
  ball.motion.keys = {{0, Vec3(0.3, 1.0, 0), Eigen::Quaterniond::Identity(), 1.0}};
  scene.objects.push_back(ball);
  Light emission;
  emission.name = "ball";
  emission.kind = Light::Kind::kMesh;
  emission.emitter_object = 1;
  emission.E_per_band.assign(8, 3.0);
  scene.lights.push_back(emission);
  return scene;
}

TEST(AreaLight, AnEmissiveBallLightsTheFloorAsAPointOfIntensityPiR2L) {
  const Scene scene = EmissiveBallOverAFloor(16);
  SceneGeometry geometry(scene);
  const LightPose pose = PoseAt(scene.lights[0], 0);
  // The icosphere's polyhedron is a little smaller than the sphere: its
  // irradiance, summed triangle by triangle, within 1% of the sphere's
  // (0.5% measured).
  for (double x : {0.3, 0.0, -0.5, 1.0, 2.0}) {
    const Vec3f p(float(x), 0, 0.1f);
    const Eigen::Vector3d d = Vec3(0.3, 1.0, 0) - p.cast<double>();
    const double expected = M_PI * 0.2 * 0.2 * (d.y() / d.norm()) / d.squaredNorm();
    EXPECT_NEAR(AreaLightUnoccluded(geometry, pose, p, Vec3f(0, 1, 0)), expected, 0.01 * expected) << x;
    // Nothing but the ball's own body between: the ratio estimator's shadow
    // rays (lifted off the floor, grazing the ball's silhouette) all arrive.
    const float unshadowed = AreaLightUnoccluded(geometry, pose, p, Vec3f(0, 1, 0));
    EXPECT_NEAR(UnitIrradiance(geometry, pose, p, Vec3f(0, 1, 0)), unshadowed, 1e-6 * unshadowed) << x;
  }
  // At the ball's centre, behind every face: nothing.
  EXPECT_EQ(AreaLightUnoccluded(geometry, pose, Vec3f(0.3f, 1.0f, 0), Vec3f(0, 1, 0)), 0.0f);
}

TEST(AreaLight, AnEmissiveBallIsSeenAndThePathTracerAgreesWithDirect) {
  const Scene scene = EmissiveBallOverAFloor(32);
  SceneGeometry geometry(scene);
  const Image d = RenderBands(geometry, nullptr, FrameOptions{});
  FrameOptions path;
  path.transport = Transport::kPath;
  path.spp = 64;
  path.max_depth = 2;  // the floor's bounce that finds the ball (nothing else reflects back)
  const Image pt = RenderBands(geometry, nullptr, path);
  // Floor pixels: direct's rho E / pi against the path tracer's, in 4 x 4 blocks.
  for (const Block& b : Blocks(d, pt))
    EXPECT_NEAR(b.path, b.direct, 4 * b.path_se + 0.02 * b.direct + 1e-6) << "block " << b.x << "," << b.y;
}

TEST(AreaLight, AnEmissiveObjectShowsItsRadianceOnItsFrontOnly) {
  Scene scene = EmptyScene(16, 16);
  scene.camera.keys = {{0, Vec3(0, 0, 0), Vec3(0, 1, 0.001)}};
  Object panel = MakeObject("panel", MakeQuad(4, 4), 0.0);  // normal +y: its front faces away from the camera
  panel.motion.keys = {{0, Vec3(0, 1, 0), Eigen::Quaterniond::Identity(), 1.0}};
  scene.objects.push_back(panel);
  Light emission;
  emission.kind = Light::Kind::kMesh;
  emission.emitter_object = 0;
  emission.E_per_band.assign(8, 2.0);
  scene.lights.push_back(emission);
  {
    SceneGeometry geometry(scene);
    EXPECT_EQ(RenderBands(geometry, nullptr, FrameOptions{}).at(8, 8)[3], 0.0f);
  }
  scene.objects[0].motion.keys[0].rotate = Eigen::AngleAxisd(M_PI, Vec3::UnitX());  // now facing the camera
  SceneGeometry geometry(scene);
  EXPECT_FLOAT_EQ(RenderBands(geometry, nullptr, FrameOptions{}).at(8, 8)[3], 2.0f);
}

// A glossy floor under an area light, seen where the light's mirror image
// falls: the direct transport's highlight (the light's points and the
// BSDF's draws, weighted by MIS) against the path tracer's, which finds the
// light by its own next-event estimation and bounces. Spreading the light's
// irradiance over the directional albedo, as for a uniform sky (before
// this test), made the first case's highlight 35x too dark and the
// second's surroundings up to 1.8x too bright.
TEST(AreaLight, AGlossyFloorShowsItsHighlightInDirectAsInThePathTracer) {
  struct Case {
    Gloss gloss;
    Light light;
  };
  const std::vector<Case> cases = {
      {{1.0f, 0.15f}, QuadLight(Vec3(0, 1, -0.5), Vec3(0.2, -1, 0.3), Vec3(1, 0, 0), 0.4, 0.3, 3.0)},
      {{0.0f, 0.3f}, DiskLight(Vec3(0.1, 0.8, -0.3), Vec3(0, -1, 0.2), 0.15, 5.0)},
      {{0.5f, 0.5f}, QuadLight(Vec3(-0.2, 1.2, -0.6), Vec3(0, -1, 0), Vec3(1, 0, 1), 0.5, 0.5, 2.0)},
  };
  for (const Case& c : cases) {
    Scene scene = EmptyScene(32, 32);
    scene.camera.keys = {{0, Vec3(0, 0.6, 1.2), Vec3(0, 0, 0.3)}};
    scene.camera.fov_deg = 60;
    Object floor = MakeObject("floor", MakeQuad(6, 6), 0.5);
    floor.gloss = c.gloss;
    scene.objects.push_back(floor);
    scene.lights.push_back(c.light);
    SceneGeometry geometry(scene);
    const Image d = RenderBands(geometry, nullptr, FrameOptions{});
    FrameOptions path;
    path.transport = Transport::kPath;
    path.spp = 256;
    path.max_depth = 2;  // the floor's bounce that finds the light (nothing else reflects back)
    const Image pt = RenderBands(geometry, nullptr, path);
    double brightest = 0, dimmest = 1e30;
    for (const Block& b : Blocks(d, pt)) {
      EXPECT_NEAR(b.direct, b.path, 4 * b.path_se + 0.03 * b.path + 1e-4)
          << "metallic " << c.gloss.metallic << " roughness " << c.gloss.roughness << ", block " << b.x << "," << b.y;
      brightest = std::max(brightest, b.direct);
      dimmest = std::min(dimmest, b.direct);
    }
    EXPECT_GT(brightest, 5 * dimmest) << "a highlight";
  }
}

TEST(AreaLight, ScenesDeclareThemWithUnitsAndBadOnesAreOneLine) {
  // The Cornell fixture, its lights replaced.
  auto scene_with = [](nlohmann::json light) {
    nlohmann::json j = ReadJsonFile(phos::testing::Fixture("scenes/cornell-phosphor.json"));
    j["lights"] = nlohmann::json::array({light});
    return SceneFromJson(j, phos::testing::Fixture("scenes"), "cornell-phosphor.json");
  };
  const Scene quad = scene_with({{"type", "quad"},
                                 {"position", {0, 2, 0}},
                                 {"normal", {0, -2, 0}},
                                 {"size_m", {1.0, 0.5}},
                                 {"intensity", 3},
                                 {"spectrum", {{"type", "white_led"}}}});
  ASSERT_EQ(quad.lights[0].kind, Light::Kind::kQuad);
  EXPECT_EQ(quad.lights[0].normal, Vec3(0, -1, 0));
  EXPECT_EQ(quad.lights[0].tangent, Vec3(1, 0, 0));
  EXPECT_EQ(quad.lights[0].samples, 16);
  const Scene disk = scene_with({{"type", "disk"},
                                 {"position", {0, 2, 0}},
                                 {"normal", {1, 0, 0}},
                                 {"radius_m", 0.2},
                                 {"samples", 4},
                                 {"intensity", 3},
                                 {"spectrum", {{"type", "white_led"}}}});
  EXPECT_EQ(disk.lights[0].kind, Light::Kind::kDisk);
  EXPECT_EQ(disk.lights[0].samples, 4);
  auto message = [&](nlohmann::json light) {
    try {
      scene_with(light);
    } catch (const UserError& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  nlohmann::json base = {{"type", "quad"},       {"position", {0, 2, 0}}, {"normal", {0, -1, 0}},
                         {"size_m", {1, 1}},     {"intensity", 1},        {"spectrum", {{"type", "white_led"}}}};
  nlohmann::json parallel = base;
  parallel["tangent"] = {0, 3, 0};
  EXPECT_NE(message(parallel).find("tangent"), std::string::npos) << message(parallel);
  nlohmann::json one_size = base;
  one_size["size_m"] = {1};
  EXPECT_NE(message(one_size).find("size_m"), std::string::npos) << message(one_size);
  nlohmann::json radius_on_quad = base;
  radius_on_quad["radius_m"] = 1;
  EXPECT_NE(message(radius_on_quad).find("only a disk"), std::string::npos) << message(radius_on_quad);
  nlohmann::json samples_on_point = {{"type", "point"}, {"position", {0, 1, 0}}, {"samples", 4},
                                     {"intensity", 1},  {"spectrum", {{"type", "white_led"}}}};
  EXPECT_NE(message(samples_on_point).find("samples"), std::string::npos) << message(samples_on_point);
  for (const std::string& m : {message(parallel), message(one_size), message(radius_on_quad)})
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
  // An object's emission is a light of its own, named after it.
  nlohmann::json emissive = ReadJsonFile(phos::testing::Fixture("scenes/cornell-phosphor.json"));
  emissive["objects"][0]["emission"] = {{"intensity", 5}, {"spectrum", {{"type", "white_led"}}}, {"samples", 9}};
  const Scene with_emission = SceneFromJson(emissive, phos::testing::Fixture("scenes"), "cornell-phosphor.json");
  const Light& glow = with_emission.lights[0];
  EXPECT_EQ(glow.kind, Light::Kind::kMesh);
  EXPECT_EQ(glow.emitter_object, 0);
  EXPECT_EQ(glow.name, with_emission.objects[0].name);
  EXPECT_EQ(glow.samples, 9);
  emissive["objects"][0]["emission"]["radiance"] = 1;
  std::string unknown = "accepted";
  try {
    SceneFromJson(emissive, phos::testing::Fixture("scenes"), "cornell-phosphor.json");
  } catch (const UserError& e) {
    unknown = e.what();
  }
  EXPECT_NE(unknown.find("radiance"), std::string::npos) << unknown;
  // Media are lit by the other kinds only, and say so.
  nlohmann::json media = ReadJsonFile(phos::testing::Fixture("scenes/dust-sheets.json"));
  media["lights"][0] = base;
  std::string refused = "accepted";
  try {
    SceneFromJson(media, phos::testing::Fixture("scenes"), "dust-sheets.json");
  } catch (const UserError& e) {
    refused = e.what();
  }
  EXPECT_NE(refused.find("area light"), std::string::npos) << refused;
}

}  // namespace
}  // namespace phos::render
