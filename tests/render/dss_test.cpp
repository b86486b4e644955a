// Deep screen space against analytic truths (docs/render.md, "Deep screen space"): an
// unoccluded plane has no occlusion; a closed box seen from inside is fully
// occluded; a disk of known radiosity gives the known irradiance on its axis,
// E = B R^2 / (R^2 + h^2). And the hierarchy against the exact gather it
// approximates (every surfel for every pixel).

#include "phos/render/dss.h"

#include <algorithm>
#include <cmath>
#include <gtest/gtest.h>

#include "scene_util.h"

namespace phos {
namespace {

using render::Vec3f;

// Surfels a few pixels wide: the exact gather (every surfel for every pixel)
// stays affordable under the sanitizers.
render::SurfelOptions Coarse() {
  render::SurfelOptions options;
  options.s = 0.05f;
  return options;
}

double Mean(const std::vector<float>& values, const render::GBuffer& g) {
  double sum = 0;
  int n = 0;
  for (std::size_t p = 0; p < values.size(); ++p)
    if (g.object[p] >= 0) sum += values[p], ++n;
  return n ? sum / n : 0;
}

TEST(DeepScreenSpace, AnUnoccludedPlaneHasNoOcclusion) {
  render::Scene scene = testing::EmptyScene(48, 48);
  scene.objects.push_back(testing::MakeObject("floor", render::MakeQuad(4, 4), 0.5));
  scene.camera.keys = {{0.0, render::Vec3(0.3, 1.0, -0.8), render::Vec3(0, 0, 0)}};
  render::SceneGeometry geometry(scene);
  const render::CameraRays camera(scene, 0);
  const auto surfels = render::Surfelize(geometry, camera.origin(), 60, Coarse());
  ASSERT_GT(surfels.size(), 100u);
  const render::GBuffer g = render::RenderGBuffer(geometry, scene, 0);
  const render::DssResult dss = render::SplatDeepScreenSpace(g, camera, surfels, {}, {});
  const render::DssResult exact = render::GatherAllSurfels(g, surfels, {}, 0);
  for (std::size_t p = 0; p < dss.occlusion.size(); ++p) {
    EXPECT_EQ(dss.occlusion[p], 0.0f);
    EXPECT_EQ(exact.occlusion[p], 0.0f);
  }
}

TEST(DeepScreenSpace, AClosedBoxSeenFromInsideIsFullyOccluded) {
  render::Scene scene = testing::EmptyScene(48, 48);
  scene.objects.push_back(testing::MakeObject("box", render::MakeBox(render::Vec3(2, 2, 2), true), 0.5));
  scene.camera.keys = {{0.0, render::Vec3(0.1, -0.2, -0.3), render::Vec3(0.4, 0.1, 1)}};
  render::SceneGeometry geometry(scene);
  const render::CameraRays camera(scene, 0);
  const auto surfels = render::Surfelize(geometry, camera.origin(), 60, Coarse());
  const render::GBuffer g = render::RenderGBuffer(geometry, scene, 0);
  const render::DssResult exact = render::GatherAllSurfels(g, surfels, {}, 0);
  const render::DssResult dss = render::SplatDeepScreenSpace(g, camera, surfels, {}, {});
  // Every direction above every wall ends on another wall: the form factors
  // of an enclosure sum to 1.
  EXPECT_GT(Mean(exact.occlusion, g), 0.97);
  EXPECT_GT(Mean(dss.occlusion, g), 0.95);
}

// A disk of radius R in the plane y = h facing down, radiosity B; a floor at
// y = 0; the camera between them looks straight down at the origin.
TEST(DeepScreenSpace, ADiskOfKnownRadiosityGivesTheKnownIrradianceOnItsAxis) {
  const float R = 0.5f, h = 1.0f, B = 2.0f;
  render::Scene scene = testing::DiskOverFloor(R, h);
  render::SceneGeometry geometry(scene);
  ASSERT_LT(geometry.FrontNormal(1, 0).y(), 0);  // the disk faces the floor
  const render::CameraRays camera(scene, 0);
  render::SurfelOptions options;
  options.s = 0.03f;
  const auto surfels = render::Surfelize(geometry, camera.origin(), 60, options);
  std::vector<float> radiosity;
  for (const render::Surfel& s : surfels) radiosity.push_back(s.object == 1 ? B : 0.0f);
  const render::GBuffer g = render::RenderGBuffer(geometry, scene, 0);
  const std::size_t centre = 16 * 33 + 16;
  ASSERT_EQ(g.object[centre], 0);
  ASSERT_LT(g.position[centre].norm(), 0.05f);
  const double truth = B * R * R / (R * R + h * h);
  const render::DssResult exact = render::GatherAllSurfels(g, surfels, radiosity, 1);
  EXPECT_NEAR(exact.irradiance[centre], truth, 0.02 * truth);
  render::DssOptions dss_options;
  dss_options.channels = 1;
  const render::DssResult dss = render::SplatDeepScreenSpace(g, camera, surfels, radiosity, dss_options);
  EXPECT_NEAR(dss.irradiance[centre], truth, 0.05 * truth);
}

TEST(DeepScreenSpace, TheHierarchyFollowsTheExactGatherAndCostsLess) {
  // The Cornell-like box of the renderer's tests: an open box and two blocks.
  render::Scene scene = testing::EmptyScene(64, 64);
  render::Mesh room = render::MakeBox(render::Vec3(2, 2, 2), true);
  std::vector<Eigen::Vector3i> kept;  // open the wall behind the camera (z = -1)
  for (const auto& t : room.triangles)
    if (!(room.positions[t[0]].z() < -0.99f && room.positions[t[1]].z() < -0.99f && room.positions[t[2]].z() < -0.99f))
      kept.push_back(t);
  ASSERT_EQ(kept.size(), room.triangles.size() - 2);
  room.triangles = kept;
  scene.objects.push_back(testing::MakeObject("room", room, 0.5));
  render::Mesh block = render::MakeBox(render::Vec3(0.5, 0.8, 0.5), false);
  for (auto& p : block.positions) p += Eigen::Vector3f(-0.4f, -0.6f, 0.3f);
  scene.objects.push_back(testing::MakeObject("block", block, 0.5));
  scene.camera.keys = {{0.0, render::Vec3(0, 0, -0.95), render::Vec3(0, -0.2, 1)}};
  render::SceneGeometry geometry(scene);
  const render::CameraRays camera(scene, 0);
  const auto surfels = render::Surfelize(geometry, camera.origin(), 60, Coarse());
  const render::GBuffer g = render::RenderGBuffer(geometry, scene, 0);
  const render::DssResult exact = render::GatherAllSurfels(g, surfels, {}, 0);
  const render::DssResult dss = render::SplatDeepScreenSpace(g, camera, surfels, {}, {});
  double error = 0;
  int n = 0;
  for (std::size_t p = 0; p < exact.occlusion.size(); ++p)
    if (g.object[p] >= 0) error += std::fabs(dss.occlusion[p] - exact.occlusion[p]), ++n;
  EXPECT_LT(error / n, 0.05);
  EXPECT_LT(dss.splats, exact.splats / 4);  // far shells touch a quarter^l of their pixels
}

// The cosine-weighted occlusion, unbounded in distance, of a point under the
// centre of a parallel a x b rectangle at height h (the ray-traced
// reference's definition, RayTracedOcclusion): the point-to-rectangle form
// factor, four times the corner case of the catalogues of configuration
// factors (e.g. Howell's),
// F = (2 / pi) [X / sqrt(1 + X^2) atan(Y / sqrt(1 + X^2)) + Y / sqrt(1 + Y^2) atan(X / sqrt(1 + Y^2))],
// X = a / 2h, Y = b / 2h.
double CentredRectangleFormFactor(double a, double b, double h) {
  const double X = a / (2 * h), Y = b / (2 * h), sx = std::sqrt(1 + X * X), sy = std::sqrt(1 + Y * Y);
  return 2 / 3.14159265358979323846 * (X / sx * std::atan(Y / sx) + Y / sy * std::atan(X / sy));
}

TEST(DeepScreenSpace, AClosedSlabOverheadOccludesOnceAndAnOpenSheetFromBehindToo) {
  // A 1 m square at h = 1 m over a floor point: F = 0.2394. As a closed slab
  // (a box 5 cm thick), every ray into it crosses its near face and then its
  // far side: blending both sides gave 2F (0.46). As a single quad facing up
  // (away from the point), only its back is seen, and it still hides F.
  const double a = 1.0, h = 1.0, thickness = 0.05, F = CentredRectangleFormFactor(a, a, h);
  ASSERT_NEAR(F, 0.2394, 1e-4);
  for (const bool closed : {true, false}) {
    render::Scene scene = testing::DiskOverFloor(0.5f, 1.0f);  // the floor, camera and centre pixel
    render::Mesh occluder = closed ? render::MakeBox(render::Vec3(a, thickness, a), false) : render::MakeQuad(a, a);
    for (auto& p : occluder.positions) p.y() += static_cast<float>(h + (closed ? thickness / 2 : 0.0));
    scene.objects[1] = testing::MakeObject(closed ? "slab" : "sheet", occluder, 0.5);
    render::SceneGeometry geometry(scene);
    const render::CameraRays camera(scene, 0);
    render::SurfelOptions options;
    options.s = 0.03f;
    const auto surfels = render::Surfelize(geometry, camera.origin(), 60, options);
    const render::GBuffer g = render::RenderGBuffer(geometry, scene, 0);
    const std::size_t centre = 16 * 33 + 16;
    ASSERT_EQ(g.object[centre], 0);
    EXPECT_NEAR(render::GatherAllSurfels(g, surfels, {}, 0).occlusion[centre], F, 0.03 * F) << closed;
    EXPECT_NEAR(render::SplatDeepScreenSpace(g, camera, surfels, {}, {}).occlusion[centre], F, 0.05 * F) << closed;
  }
}

// The cosine-weighted occlusion of a point with normal n by a polygon above
// its horizon (vertices relative to the point, either winding): Lambert's
// closed form, F = (1 / 2 pi) sum_i gamma_i n . (v_i x v_{i+1}) / |v_i x v_{i+1}|,
// gamma_i the angle between the unit vectors to consecutive vertices.
double PolygonFormFactor(const std::vector<Eigen::Vector3d>& vertices, const Eigen::Vector3d& n) {
  double sum = 0;
  for (std::size_t i = 0; i < vertices.size(); ++i) {
    const Eigen::Vector3d a = vertices[i].normalized(), b = vertices[(i + 1) % vertices.size()].normalized();
    const Eigen::Vector3d c = a.cross(b);
    sum += std::acos(std::clamp(a.dot(b), -1.0, 1.0)) * n.dot(c.normalized());
  }
  return std::fabs(sum) / (2 * 3.14159265358979323846);
}

TEST(DeepScreenSpace, DirectionCellsCountAWallBehindAWallOnce) {
  // A floor point at the origin; a wall at x = 0.5 (20 m high, 40 m wide)
  // facing it, and behind it a wall twice as large at x = 1, which hides
  // nothing more (the same directions). Truth: the near wall alone (Lambert,
  // 0.4858; an infinite wall would give 1/2). Blending sums both (about 2x);
  // direction cells count the covered directions once. (A cell that both
  // walls cover in part counts whole: here the grazing directions past the
  // walls' ends, 0.014, and the tolerance allows for them.)
  const double d = 0.5, height = 20, half_width = 20;
  const double truth = PolygonFormFactor({{d, 0, -half_width}, {d, 0, half_width}, {d, height, half_width},
                                          {d, height, -half_width}},
                                         Eigen::Vector3d::UnitY());
  ASSERT_NEAR(truth, 0.4858, 1e-4);
  render::Scene scene = testing::DiskOverFloor(0.5f, 1.0f);
  scene.objects.pop_back();
  for (const double scale : {1.0, 2.0}) {
    render::Mesh wall = render::MakeQuad(2 * half_width * scale, height * scale);  // in y = 0, normal +y
    // (x, y, z) -> (y, z, -x): turns the quad upright, its normal to -x.
    for (auto& p : wall.positions)
      p = Eigen::Vector3f(static_cast<float>(d * scale) + p.y(), p.z() + static_cast<float>(height * scale / 2), -p.x());
    scene.objects.push_back(testing::MakeObject(scale == 1 ? "near wall" : "far wall", wall, 0.5));
  }
  render::SceneGeometry geometry(scene);
  ASSERT_LT(geometry.FrontNormal(1, 0).x(), 0);  // the walls face the point
  ASSERT_LT(geometry.FrontNormal(2, 0).x(), 0);
  const render::CameraRays camera(scene, 0);
  const auto surfels = render::Surfelize(geometry, camera.origin(), 60, Coarse());
  const render::GBuffer g = render::RenderGBuffer(geometry, scene, 0);
  const std::size_t centre = 16 * 33 + 16;
  ASSERT_EQ(g.object[centre], 0);
  render::DssOptions options;
  const float blended = render::SplatDeepScreenSpace(g, camera, surfels, {}, options).occlusion[centre];
  options.occlusion_cells = 4;
  const float cells = render::SplatDeepScreenSpace(g, camera, surfels, {}, options).occlusion[centre];
  EXPECT_GT(blended, 1.7 * truth);  // the far wall counted again
  EXPECT_NEAR(cells, truth, 0.04 * truth);
}

}  // namespace
}  // namespace phos

namespace phos {
namespace {

// A receiver on the floor under two stacked disks (radius R at heights h1 <
// h2): the upper one glows with radiosity B, the lower one is dark and wider.
struct StackedDisks {
  render::Scene scene = testing::EmptyScene(33, 33);
  static render::Mesh Disk(float R, float h) { return testing::DiskFacingDown(R, h, 64); }
  StackedDisks(float R_low, float h_low, float R_high, float h_high) {
    scene.objects.push_back(testing::MakeObject("floor", render::MakeQuad(2, 2), 0.5));
    scene.objects.push_back(testing::MakeObject("low", Disk(R_low, h_low), 0.5));
    scene.objects.push_back(testing::MakeObject("high", Disk(R_high, h_high), 0.5));
    scene.camera.keys = {{0.0, render::Vec3(0, 0.2, 0), render::Vec3(0, 0, 0.0001)}};
    scene.camera.up = render::Vec3(0, 0, 1);
  }
};

TEST(BouncedZBuffer, HidesLightBehindANearerSurfelAndCountsNothingTwice) {
  // Disks of equal angular size at 0.5 m and 1 m: the upper glows (B = 2),
  // the lower is dark. Truth: occlusion F = R^2 / (R^2 + h^2) of one disk;
  // no light arrives. Blending sums both (2F) and lets the glow through.
  const float h1 = 0.5f, h2 = 1.0f, R1 = 0.25f, R2 = 0.5f, B = 2.0f;
  StackedDisks stack(R1, h1, R2, h2);
  render::SceneGeometry geometry(stack.scene);
  const render::CameraRays camera(stack.scene, 0);
  render::SurfelOptions options;
  options.s = 0.03f;
  const auto surfels = render::Surfelize(geometry, camera.origin(), 60, options);
  std::vector<float> radiosity;
  for (const render::Surfel& s : surfels) radiosity.push_back(s.object == 2 ? B : 0.0f);
  const render::GBuffer g = render::RenderGBuffer(geometry, stack.scene, 0);
  const std::size_t centre = 16 * 33 + 16;
  ASSERT_EQ(g.object[centre], 0);
  const double F = R1 * R1 / (R1 * R1 + h1 * h1);
  render::DssOptions dss_options;
  dss_options.channels = 1;
  const render::DssResult blend = render::SplatDeepScreenSpace(g, camera, surfels, radiosity, dss_options);
  const render::DssResult z = render::SplatBouncedZBuffer(g, camera, surfels, radiosity, dss_options);
  EXPECT_NEAR(blend.occlusion[centre], 2 * F, 0.1 * F);       // over-occlusion
  EXPECT_NEAR(blend.irradiance[centre], B * F, 0.1 * B * F);  // leaking
  EXPECT_NEAR(z.occlusion[centre], F, 0.1 * F);
  EXPECT_LT(z.irradiance[centre], 0.05 * B * F);
  // Without the dark disk the glow arrives: B F within 10%.
  StackedDisks open(R1, h1, R2, h2);
  open.scene.objects.erase(open.scene.objects.begin() + 1);
  render::SceneGeometry open_geometry(open.scene);
  const auto open_surfels = render::Surfelize(open_geometry, camera.origin(), 60, options);
  std::vector<float> open_radiosity;
  for (const render::Surfel& s : open_surfels) open_radiosity.push_back(s.object == 1 ? B : 0.0f);
  const render::GBuffer og = render::RenderGBuffer(open_geometry, open.scene, 0);
  const render::DssResult lit = render::SplatBouncedZBuffer(og, camera, open_surfels, open_radiosity, dss_options);
  EXPECT_NEAR(lit.irradiance[centre], B * F, 0.1 * B * F);
  EXPECT_NEAR(lit.occlusion[centre], F, 0.1 * F);
}

}  // namespace
}  // namespace phos
