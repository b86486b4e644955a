// The comparison methods of Fig. 8.16 (render/glassner.h) on a closed sphere
// lit from its centre: the exact per-pixel reference against the closed form,
// the coupled solver against the reference, and the Glassner baseline's two
// kinds of error: noise that falls as 1/sqrt(N) where r is small, and the
// bias of its linear model (no saturation) where r is not.

#include <gtest/gtest.h>

#include <cmath>

#include "phos/render/glassner.h"
#include "render/scene_util.h"

namespace phos::render {
namespace {

using phos::testing::EmptyScene;
using phos::testing::MakeObject;
using phos::testing::PointLight;
using phos::testing::UniformPhosphor;

Scene Sphere(double intensity) {
  Scene scene = EmptyScene(24, 24);
  scene.objects.push_back(MakeObject("sphere", MakeSphere(1.0, 4, true), 0.5,
                                     UniformPhosphor(0.2, {0.5, 0, 0, 0, 0, 0, 0, 0}, {0, 0, 0, 1, 0, 0, 0, 0})));
  scene.texel_size_m = 0.02;
  scene.lights.push_back(PointLight(Vec3::Zero(), {intensity, 0, 0, 0, 0, 0, 0, 0}, 3.0));
  return scene;
}

double Mean(const Image& image, int band) {
  double sum = 0;
  for (std::size_t p = 0; p < image.pixels.size() / image.channels; ++p) sum += image.pixels[p * image.channels + band];
  return sum / static_cast<double>(image.pixels.size() / image.channels);
}

double RelativeRmse(const Image& a, const Image& truth) {
  double e = 0, n = 0;
  for (std::size_t i = 0; i < a.pixels.size(); ++i) {
    e += std::pow(double(a.pixels[i]) - truth.pixels[i], 2);
    n += std::pow(double(truth.pixels[i]), 2);
  }
  return std::sqrt(e / n);
}

TEST(Comparison, ReferenceAndSolverAgreeWithTheClosedForm) {
  const Scene scene = Sphere(2.0);  // a = 0.5 * 2 / 1^2 = 1/s: r nears saturation
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  const double t = 5.0, a = 1.0, kr = 0.2;
  solver.AdvanceTo(t);
  geometry.SetTime(t);
  const Image reference = EmittedRadianceReference(geometry, t);
  const double r = a / (a + kr) * -std::expm1(-(a + kr) * 3.0) * std::exp(-kr * 2.0);
  EXPECT_NEAR(Mean(reference, 3), kr * r, 0.02 * kr * r);  // facets: within 2% of the sphere
  EXPECT_LT(RelativeRmse(EmittedRadianceOurs(geometry, solver), reference), 0.01);
}

TEST(Comparison, GlassnerNoiseFallsAsOneOverSqrtSamplesWhereRIsSmall) {
  const Scene scene = Sphere(0.01);  // r < 0.5%: the linear model is right to 0.3%
  SceneGeometry geometry(scene);
  const Image reference = EmittedRadianceReference(geometry, 5.0);
  const double e16 = RelativeRmse(EmittedRadianceGlassner(geometry, 5.0, 16, 1), reference);
  const double e256 = RelativeRmse(EmittedRadianceGlassner(geometry, 5.0, 256, 1), reference);
  EXPECT_GT(e16 / e256, 2.5);  // 4 for pure noise
  EXPECT_LT(e16 / e256, 6.0);
  EXPECT_LT(e256, 0.15);
  EXPECT_NEAR(Mean(EmittedRadianceGlassner(geometry, 5.0, 4096, 2), 3), Mean(reference, 3), 0.02 * Mean(reference, 3));
}

TEST(Comparison, GlassnerOvershootsWhereTheMaterialSaturates) {
  const Scene scene = Sphere(2.0);
  SceneGeometry geometry(scene);
  const Image reference = EmittedRadianceReference(geometry, 5.0);
  const Image glassner = EmittedRadianceGlassner(geometry, 5.0, 1024, 3);
  // Linear response: r = a/kr (1 - e^{-kr 3}) e^{-2 kr} instead of the saturating closed form.
  const double a = 1.0, kr = 0.2;
  const double linear = a / kr * -std::expm1(-kr * 3.0) * std::exp(-kr * 2.0);
  EXPECT_NEAR(Mean(glassner, 3), kr * linear, 0.05 * kr * linear);
  EXPECT_GT(Mean(glassner, 3), 2 * Mean(reference, 3));
}

}  // namespace
}  // namespace phos::render
