// The coupled solver against closed forms (pbrt-v4's style of analytic
// integrator tests): a closed sphere with a point light at its centre, lit
// then dark; energy accounting; and the "model only what the scene requires"
// promises, checked by counting the work done.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "phos/render/geometry.h"
#include "phos/render/renderer.h"
#include "phos/render/solver.h"
#include "phos/util/json.h"
#include "phos/util/error.h"
#include "render/scene_util.h"
#include "test_util.h"

namespace phos::render {
namespace {

using phos::testing::EmptyScene;
using phos::testing::MakeObject;
using phos::testing::PointLight;
using phos::testing::UniformPhosphor;

// r(t) of Eq. 8.1 for irradiance E held over [0, T] and darkness after (exact).
double ClosedForm(double a, double kr, double T, double t) {
  const double k = a + kr;
  const double r_T = a / k * -std::expm1(-k * std::min(t, T));
  return t <= T ? r_T : r_T * std::exp(-kr * (t - T));
}

struct SphereCase {
  double radius = 1.5, intensity = 2.0, off_s = 5.0, kr = 0.3;
  std::vector<double> ke = {0.2, 0.1, 0, 0, 0, 0, 0, 0};
  std::vector<double> Lambda = {0, 0, 1, 2, 1, 0, 0, 0};
  Scene scene = EmptyScene();
  SphereCase() {
    scene.objects.push_back(
        MakeObject("sphere", MakeSphere(radius, 4, /*inward=*/true), 0.5, UniformPhosphor(kr, ke, Lambda)));
    scene.texel_size_m = 0.05;
    // Light only in the two bands with ke, so the excitation rate is a = (0.2 + 0.1) E.
    scene.lights.push_back(PointLight(Vec3::Zero(), {intensity, intensity, 0, 0, 0, 0, 0, 0}, off_s));
  }
};

TEST(CoupledSolver, ClosedSphereFollowsTheClosedFormLitThenDark) {
  SphereCase c;
  SceneGeometry geometry(c.scene);
  CoupledSolver solver(c.scene, geometry);
  // The facets are flat: a texel at distance d from the light, on a facet at
  // distance p from the centre, gets E = I p / d^3. Bound it from the mesh.
  const Mesh& mesh = *c.scene.objects[0].mesh;
  double p_min = c.radius;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.positions[t[0]].cast<double>(), b = mesh.positions[t[1]].cast<double>(),
                          d = mesh.positions[t[2]].cast<double>();
    p_min = std::min(p_min, std::abs((b - a).cross(d - a).normalized().dot(a)));
  }
  const double E_low = c.intensity * p_min / std::pow(c.radius, 3), E_high = c.intensity / (p_min * p_min);
  ASSERT_LT(E_high / E_low, 1.02);  // level-4 icosphere: within 2% of a true sphere
  const double ke_sum = 0.3;
  const std::size_t n = solver.atlas().total_texels();
  for (double t : {0.5, 2.0, 5.0, 5.5, 9.0, 40.0}) {
    solver.AdvanceTo(t);
    const double r_low = ClosedForm(ke_sum * E_low, c.kr, c.off_s, t);
    const double r_high = ClosedForm(ke_sum * E_high, c.kr, c.off_s, t);
    double r_min = 1, r_max = 0;
    for (std::size_t j = 0; j < n; ++j) {
      const double r = solver.State(0, 0, j);
      r_min = std::min(r_min, r);
      r_max = std::max(r_max, r);
    }
    // float storage: a few ulps of slack on top of the geometric bounds.
    EXPECT_GE(r_min, r_low * (1 - 2e-5)) << "t = " << t;
    EXPECT_LE(r_max, r_high * (1 + 2e-5)) << "t = " << t;
    // Eq. 8.2: Lp = Lambda kr r, in exactly the emitting bands.
    for (std::size_t j = 0; j < n; j += 997) {
      const float r = solver.State(0, 0, j);
      EXPECT_FLOAT_EQ(solver.Lp(0, 3, j), static_cast<float>(2 * c.kr) * r);
      EXPECT_EQ(solver.Lp(0, 0, j), 0.0f);
    }
  }
}

TEST(CoupledSolver, TexelIrradianceIsInverseSquareWithCosine) {
  SphereCase c;
  SceneGeometry geometry(c.scene);
  CoupledSolver solver(c.scene, geometry);
  solver.AdvanceTo(1.0);
  double mean = 0;
  const std::size_t n = solver.atlas().total_texels();
  for (std::size_t j = 0; j < n; ++j) mean += solver.TexelIrradiance(0, j)[0];
  mean /= static_cast<double>(n);
  EXPECT_NEAR(mean, c.intensity / (c.radius * c.radius), 0.02 * c.intensity / (c.radius * c.radius));
  EXPECT_EQ(solver.TexelIrradiance(0, 0)[4], 0.0);  // no light in that band
}

TEST(CoupledSolver, EmittedEnergyNeverExceedsTheStoredCharge) {
  // After lights-out, the radiance a texel emits integrates to sum_i Lambda_i r_i(T)
  // (the integral of kr r e^{-kr t}); it can never be more, and r(T) itself is
  // bounded by the excitation absorbed, the integral of a (1 - r) <= a T.
  SphereCase c;
  SceneGeometry geometry(c.scene);
  CoupledSolver solver(c.scene, geometry);
  const std::size_t n = solver.atlas().total_texels();
  solver.AdvanceTo(c.off_s * 0.999);
  std::vector<double> excitation_rate(n);  // a = (0.2 + 0.1) E while lit
  for (std::size_t j = 0; j < n; ++j) excitation_rate[j] = 0.3 * solver.TexelIrradiance(0, j)[0];
  solver.AdvanceTo(c.off_s);
  std::vector<double> charge(n), emitted(n, 0.0), previous(n);
  for (std::size_t j = 0; j < n; ++j) {
    charge[j] = solver.State(0, 0, j);
    previous[j] = solver.Lp(0, 3, j);
    EXPECT_LE(charge[j], excitation_rate[j] * c.off_s * (1 + 1e-5));
  }
  // Trapezoids over 0.05 s steps for 60 / kr seconds: an upper sum of a convex decay.
  const double h = 0.05;
  for (double t = c.off_s + h; t <= c.off_s + 60 / c.kr; t += h) {
    solver.AdvanceTo(t);
    for (std::size_t j = 0; j < n; j += 101) {
      const double now = solver.Lp(0, 3, j);
      emitted[j] += 0.5 * h * (previous[j] + now);
      previous[j] = now;
    }
  }
  for (std::size_t j = 0; j < n; j += 101) {
    const double stored = 2.0 * charge[j];  // Lambda[3] = 2
    // The trapezoid rule overestimates a convex decay by (h kr)^2 / 12.
    EXPECT_LE(emitted[j], stored * (1 + std::pow(h * c.kr, 2) / 12 + 1e-5));
    EXPECT_GE(emitted[j], stored * (1 - 1e-4));
  }
}

TEST(CoupledSolver, DarkIntervalsCostOneClosedFormJumpAndNoIrradiance) {
  SphereCase c;
  SceneGeometry geometry(c.scene);
  CoupledSolver solver(c.scene, geometry);
  solver.AdvanceTo(c.off_s);
  const SolverStats lit = solver.stats();
  EXPECT_EQ(lit.irradiance_updates, 1u);  // one light, never moved: computed once
  solver.AdvanceTo(c.off_s + 1);
  const SolverStats one_second = solver.stats();
  solver.AdvanceTo(c.off_s + 3600);
  const SolverStats hour = solver.stats();
  EXPECT_EQ(one_second.dark_jumps - lit.dark_jumps, 1u);
  EXPECT_EQ(hour.dark_jumps - one_second.dark_jumps, 1u);
  EXPECT_EQ(hour.steps, lit.steps);
  EXPECT_EQ(hour.shadow_rays, lit.shadow_rays);
  const float r = solver.State(0, 0, 0);
  EXPECT_GE(r, 0.0f);
  EXPECT_LT(r, 1e-30f + 1e-6f * static_cast<float>(ClosedForm(0.3 * 1, c.kr, c.off_s, c.off_s)));
}

TEST(CoupledSolver, KeepsOnlyTheBandsTheSceneUses) {
  // Green (Table 8.1) under a 405 nm LED: excited in the first band only, emits in three.
  Scene scene = EmptyScene();
  auto green = std::make_shared<Material>(LoadMaterial(phos::testing::Fixture("materials/green.json")));
  scene.objects.push_back(MakeObject("wall", MakeQuad(1, 1), 0.5, green));
  scene.objects.push_back(MakeObject("floor", MakeQuad(3, 3), 0.5));
  scene.objects[1].motion.keys.push_back({});
  scene.objects[1].motion.keys[0].translate = Vec3(0, -1, 0);
  Light led = PointLight(Vec3(0, 1, 0), IntegrateOverBands(LedSpectrum(405, 15), scene.bands));
  scene.lights.push_back(led);
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  EXPECT_EQ(solver.atlas().objects().size(), 1u);  // the plain floor carries no state
  EXPECT_EQ(solver.excitation_bands(0), std::vector<int>({0}));
  EXPECT_EQ(solver.emission_bands(0), std::vector<int>({2, 3, 4}));

  // A white LED reaches bands where green's ke was never measured: refused,
  // naming the object, unless the scene states that it assumes zero there.
  scene.lights[0].E_per_band = IntegrateOverBands(WhiteLedSpectrum(), scene.bands);
  SceneGeometry geometry2(scene);
  const std::string error = phos::testing::ErrorOfType<UserError>([&] { CoupledSolver s(scene, geometry2); });
  EXPECT_NE(error.find("object 'wall'"), std::string::npos) << error;
  EXPECT_NE(error.find("512.5"), std::string::npos) << error;
  // ... and saying what a scene can do about it (not "give 0 irradiance", which a scene cannot).
  EXPECT_NE(error.find("say \"unknown_ke\": \"zero\" on the object"), std::string::npos) << error;
  scene.objects[0].unknown_ke_as_zero = true;
  SceneGeometry geometry3(scene);
  CoupledSolver assumed(scene, geometry3);
  EXPECT_EQ(assumed.excitation_bands(0), std::vector<int>({0, 1, 2}));
}

TEST(CoupledSolver, EquilibriumStartIsAFixedPoint) {
  SphereCase c;
  c.scene.lights[0].schedule.keys.clear();  // always on
  c.scene.objects[0].initial.kind = InitialState::Kind::kEquilibrium;
  SceneGeometry geometry(c.scene);
  CoupledSolver solver(c.scene, geometry);
  std::vector<float> start;
  for (std::size_t j = 0; j < solver.atlas().total_texels(); j += 53) start.push_back(solver.State(0, 0, j));
  solver.AdvanceTo(100);
  std::size_t k = 0;
  for (std::size_t j = 0; j < solver.atlas().total_texels(); j += 53, ++k) {
    EXPECT_NEAR(solver.State(0, 0, j), start[k], 1e-5f);
    // dr/dt = 0: r = a / (a + kr), a = 0.3 E, E = I / R^2 within the facets' 2%.
    const double a = 0.3 * c.intensity / (c.radius * c.radius);
    EXPECT_NEAR(start[k], a / (a + c.kr), 0.02 * a / (a + c.kr));
  }
}

TEST(CoupledSolver, AMovingLightWritesATrailThatFadesBehindIt) {
  // A light 2 cm above a floor moves from x = -0.5 to x = +0.5 in 5 s and goes
  // off. A texel under the start was charged ~5 s earlier than one under the
  // end, so it has decayed by about e^{-5 kr} relative to it.
  Scene scene = EmptyScene();
  const double kr = 0.4;
  scene.objects.push_back(MakeObject("floor", MakeQuad(1.4, 0.4), 0.5,
                                     UniformPhosphor(kr, {1, 0, 0, 0, 0, 0, 0, 0}, {0, 0, 0, 1, 0, 0, 0, 0})));
  scene.texel_size_m = 0.01;
  scene.settings.max_step_s = 0.01;
  Light light = PointLight(Vec3::Zero(), {0.002, 0, 0, 0, 0, 0, 0, 0}, 5.0);
  RigidKey a, b;
  a.translate = Vec3(-0.5, 0.02, 0);
  b.t_s = 5;
  b.translate = Vec3(0.5, 0.02, 0);
  light.motion.keys = {a, b};
  scene.lights.push_back(light);
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  solver.AdvanceTo(5.0);
  EXPECT_GE(solver.stats().irradiance_updates, 500u);  // one per step while the light moves
  auto state_at = [&](float x, float z) {
    const Hit hit = geometry.Intersect(Eigen::Vector3f(x, 1, z), Eigen::Vector3f(0, -1, 0));
    EXPECT_TRUE(hit);
    return solver.State(0, 0, solver.atlas().TexelOf(0, hit.triangle, hit.b1, hit.b2));
  };
  const float start = state_at(-0.4f, 0), end = state_at(0.4f, 0), aside = state_at(0, 0.19f);
  EXPECT_GT(end, 0.0f);
  EXPECT_NEAR(start / end, std::exp(-kr * 4.0), 0.1 * std::exp(-kr * 4.0));
  EXPECT_LT(aside, 0.05f * state_at(0, 0));
  const std::size_t updates = solver.stats().irradiance_updates;
  solver.AdvanceTo(60);  // dark and still: no more irradiance work
  EXPECT_EQ(solver.stats().irradiance_updates, updates);
}

}  // namespace
}  // namespace phos::render

namespace phos::render {
namespace {

TEST(GlowIrradiance, InsideAUniformlyGlowingSphereIsPiTimesLp) {
  // A closed surface of uniform radiance L irradiates every point of it with pi L.
  Scene scene = EmptyScene();
  scene.objects.push_back(MakeObject("sphere", MakeSphere(1.0, 3, true), 0.5,
                                     UniformPhosphor(0.1, std::vector<double>(8, 0.1), {0, 0, 1, 2, 0, 0, 0, 0})));
  scene.objects[0].initial = {InitialState::Kind::kUniform, 0.5};
  scene.settings.phosphor_irradiance = true;
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  EXPECT_GT(solver.stats().glow_patches, 500u);
  const double Lp3 = 2 * 0.1 * 0.5;
  for (std::size_t j = 0; j < solver.atlas().total_texels(); j += 211) {
    const std::vector<double> E = solver.TexelGlowIrradiance(0, j);
    EXPECT_NEAR(E[3], M_PI * Lp3, 0.05 * M_PI * Lp3) << "texel " << j;
    EXPECT_NEAR(E[2], E[3] / 2, 1e-6);
    EXPECT_EQ(E[0], 0.0);
  }
}

TEST(GlowIrradiance, AGlowingPlateChargesTheOneFacingItInTheDark) {
  auto run = [](bool glow) {
    Scene scene = EmptyScene();
    auto material = UniformPhosphor(0.05, {0, 0, 0.5, 0.5, 0, 0, 0, 0}, {0, 0, 1, 1, 0, 0, 0, 0});
    scene.objects.push_back(MakeObject("charged", MakeQuad(1, 1), 0.5, material));  // faces +y at y = 0
    scene.objects.push_back(MakeObject("dark", MakeQuad(1, 1), 0.5, material));
    scene.objects[0].initial = {InitialState::Kind::kUniform, 0.9};
    RigidKey flip;  // 0.2 m above, facing down
    flip.translate = Vec3(0, 0.2, 0);
    flip.rotate = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI, Vec3::UnitX()));
    scene.objects[1].motion.keys = {flip};
    scene.settings.phosphor_irradiance = glow;
    scene.settings.max_step_s = 0.1;
    scene.texel_size_m = 0.05;
    SceneGeometry geometry(scene);
    CoupledSolver solver(scene, geometry);
    solver.AdvanceTo(5.0);
    double mean = 0;
    const std::size_t n = solver.atlas().objects()[1].count;
    for (std::size_t j = 0; j < n; ++j) mean += solver.State(1, 0, j);
    return mean / static_cast<double>(n);
  };
  EXPECT_EQ(run(false), 0.0);
  const double charged = run(true);
  // Upper bound: irradiance at most pi Lp (a hemisphere of the plate's radiance),
  // Lp <= 0.05 * 0.9 per band in two bands, ke = 0.5, for 5 s.
  EXPECT_GT(charged, 0.0);
  EXPECT_LT(charged, 0.5 * 2 * M_PI * 0.05 * 0.9 * 5.0);
}

// A unit cube (MakeBox's triangles) as an OBJ whose UV map is laid out by
// `layout`: each face's own square (s, t) in [0, 1]^2, face f of 6 (the
// bottom, -y, is face 0; as BoxTextured of Khronos's glTF samples, where
// u runs 0 to 6, and before this test its texels all lay on one face).
enum class UvLayout { kTiled, kReused, kAtlas };
std::filesystem::path WriteCubeObj(const std::filesystem::path& dir, UvLayout layout) {
  const Mesh box = MakeBox(Vec3(1, 1, 1), false);
  std::filesystem::create_directories(dir);
  const std::filesystem::path obj = dir / "cube.obj";
  std::ofstream out(obj);
  for (const Vec3f& p : box.positions) out << "v " << p.x() << " " << p.y() << " " << p.z() << "\n";
  int vt = 0;
  for (const Eigen::Vector3i& t : box.triangles) {
    const Vec3f n = (box.positions[t[1]] - box.positions[t[0]]).cross(box.positions[t[2]] - box.positions[t[0]]);
    int axis;
    n.cwiseAbs().maxCoeff(&axis);
    // Faces in the order -y, +y, -x, +x, -z, +z.
    const int face = (axis == 1 ? 0 : axis == 0 ? 2 : 4) + (n[axis] > 0 ? 1 : 0);
    for (int c = 0; c < 3; ++c) {
      const Vec3f& p = box.positions[t[c]];
      const float s = p[(axis + 1) % 3] + 0.5f, r = p[(axis + 2) % 3] + 0.5f;
      float u = s, v = r;
      if (layout == UvLayout::kTiled) u = static_cast<float>(face) + s;
      if (layout == UvLayout::kAtlas) {
        u = (static_cast<float>(face % 3) + 0.9f * s + 0.05f) / 3;
        v = (static_cast<float>(face / 3) + 0.9f * r + 0.05f) / 2;
      }
      out << "vt " << u << " " << v << "\n";
    }
    out << "f";
    for (int c = 0; c < 3; ++c) out << " " << t[c] + 1 << "/" << ++vt;
    out << "\n";
  }
  return obj;
}

TEST(TexelAtlas, AUvMapThatTilesOrReusesItsSquareLeavesTheTexelsToTheTriangles) {
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "uv-layouts";
  for (UvLayout layout : {UvLayout::kTiled, UvLayout::kReused, UvLayout::kAtlas}) {
    const Mesh cube = LoadMesh(WriteCubeObj(dir, layout), "", "test");
    const bool one_to_one = layout == UvLayout::kAtlas;
    EXPECT_EQ(UvMapIsOneToOne(cube), one_to_one) << static_cast<int>(layout);
    // Lit from above: its top charges, whichever texels it has.
    Scene scene = EmptyScene(8, 8);
    scene.objects.push_back(MakeObject("cube", cube, 0.5,
                                       UniformPhosphor(0.2, std::vector<double>(8, 0.1), {0, 0, 1, 2, 1, 0, 0, 0})));
    scene.lights.push_back(PointLight(Vec3(0.2, 3, 0.1), std::vector<double>(8, 1.0), 5.0));
    SceneGeometry geometry(scene);
    CoupledSolver solver(scene, geometry);
    solver.AdvanceTo(1.0);
    EXPECT_EQ(solver.atlas().objects()[0].uv(), one_to_one) << static_cast<int>(layout);
    EXPECT_FALSE(solver.charge_report(0).NeverCharged()) << static_cast<int>(layout);
    EXPECT_TRUE(solver.charge_report(0).received) << static_cast<int>(layout);
  }
  // Asked for ("texels": "uv", or a mask or map, which imply it), a map that
  // is not one-to-one is one line naming the field.
  WriteCubeObj(dir, UvLayout::kTiled);
  const nlohmann::json json = nlohmann::json::parse(R"({"schema": "phos.scene/1",
    "camera": {"position": [0, 0, 3], "look_at": [0, 0, 0]},
    "objects": [{"name": "cube", "mesh": "cube.obj", "albedo": 0.5, "texels": "uv",
                 "phosphor": ")" + std::string(PHOS_FIXTURES_DIR) + R"(/materials/green.json", "unknown_ke": "zero"}],
    "lights": []})");
  const std::string error = phos::testing::ErrorOfType<UserError>([&] { SceneFromJson(json, dir, "cube.json"); });
  EXPECT_NE(error.find("objects[0].texels"), std::string::npos) << error;
  EXPECT_NE(error.find("is not one-to-one"), std::string::npos) << error;
}

}  // namespace
}  // namespace phos::render
