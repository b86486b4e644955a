#include "phos/render/glassner.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <set>

#include <tbb/parallel_for.h>

#include "phos/model/rate_equation.h"
#include "phos/model/simulate.h"
#include "phos/util/error.h"
#include "phos/util/random.h"

namespace phos::render {
namespace {

void RequireStatic(const Scene& scene) {
  for (const Object& o : scene.objects)
    if (o.motion.Moves())
      ThrowUserError(scene.source, "objects", "the comparison needs static objects ('" + o.name + "' moves)");
  for (const Object& o : scene.objects)
    if (o.phosphor_map || o.phosphor_mask)
      ThrowUserError(scene.source, "objects",
                     "the comparison takes one material over each whole object ('" + o.name + "' has a " +
                         (o.phosphor_map ? "phosphor_map" : "phosphor_mask") + ")");
  for (const Light& l : scene.lights)
    if (l.motion.Moves())
      ThrowUserError(scene.source, "lights", "the comparison needs static lights ('" + l.name + "' moves)");
}

// ke of state i in band b as the solver uses it (unknown: zero if the scene says so).
double Ke(const Object& object, int i, int b) {
  const auto& ke = object.phosphor->states[i].ke[b];
  if (ke) return *ke;
  if (object.unknown_ke_as_zero) return 0.0;
  ThrowUserError(object.phosphor_path, "states[" + std::to_string(i) + "].ke[" + std::to_string(b) + "]",
                 "unknown, and object '" + object.name + "' does not assume zero (unknown_ke)");
}

template <typename PerPixel>
Image ForEachPixel(const SceneGeometry& geometry, PerPixel per_pixel) {
  const Scene& scene = geometry.scene();
  const int nb = scene.bands.band_count(), width = scene.camera.width, height = scene.camera.height;
  Image image(width, height, nb);
  const CameraRays camera(scene, geometry.time_s());
  tbb::parallel_for(0, height, [&](int y) {
    for (int x = 0; x < width; ++x) {
      const Hit hit = geometry.Intersect(camera.origin(), camera.Direction(x + 0.5f, y + 0.5f));
      if (!hit || !hit.front || !scene.objects[hit.object].phosphor) continue;
      per_pixel(hit, image.at(x, y), static_cast<std::uint64_t>(y) * width + x);
    }
  });
  return image;
}

// The light's geometric irradiance factor at a hit (lights are static here).
double UnitIrradiance(const SceneGeometry& geometry, const Light& light, const Hit& hit) {
  return render::UnitIrradiance(geometry, PoseAt(light, 0), hit.position, hit.normal);
}

}  // namespace

Image EmittedRadianceOurs(const SceneGeometry& geometry, const CoupledSolver& solver) {
  const int nb = geometry.scene().bands.band_count();
  return ForEachPixel(geometry, [&](const Hit& hit, float* out, std::uint64_t) {
    const int slot = solver.atlas().SlotOf(hit.object);
    const std::size_t texel = solver.atlas().TexelOf(slot, hit.triangle, hit.b1, hit.b2);
    if (texel == TexelAtlas::kNoTexel) return;
    for (int b = 0; b < nb; ++b) out[b] = solver.atlas().Coverage(slot, texel) * solver.Lp(slot, b, texel);
  });
}

Image EmittedRadianceReference(const SceneGeometry& geometry, double t_s) {
  const Scene& scene = geometry.scene();
  RequireStatic(scene);
  const int nb = scene.bands.band_count();
  // The moments irradiance changes: every switch between the start and t.
  std::set<double> breaks = {t_s};
  for (const Light& light : scene.lights)
    for (double t : light.schedule.ChangesBetween(scene.start_s, t_s)) breaks.insert(t);
  return ForEachPixel(geometry, [&](const Hit& hit, float* out, std::uint64_t) {
    const Object& object = scene.objects[hit.object];
    const Material& material = *object.phosphor;
    std::vector<double> unit(scene.lights.size());
    for (std::size_t l = 0; l < unit.size(); ++l) unit[l] = UnitIrradiance(geometry, scene.lights[l], hit);
    std::vector<double> r(material.state_count(), 0.0);
    if (object.initial.kind == InitialState::Kind::kUniform) std::fill(r.begin(), r.end(), object.initial.r0);
    PHOS_CHECK(object.initial.kind != InitialState::Kind::kEquilibrium);  // not needed by the study
    double t0 = scene.start_s;
    for (double t1 : breaks) {
      const double mid = 0.5 * (t0 + t1);
      for (int i = 0; i < material.state_count(); ++i) {
        double a = 0;  // Eq. 8.1: a_i = sum_b ke_i[b] E[b]
        for (std::size_t l = 0; l < unit.size(); ++l) {
          const double level = scene.lights[l].schedule.LevelAt(mid);
          if (level <= 0 || unit[l] == 0) continue;
          for (int b = 0; b < nb; ++b)
            if (scene.lights[l].E_per_band[b] > 0)
              a += Ke(object, i, b) * level * scene.lights[l].E_per_band[b] * unit[l];
        }
        r[i] = ExactStep(r[i], a, material.states[i].kr, t1 - t0);
      }
      t0 = t1;
    }
    const std::vector<double> L = EmittedRadiance(material, r.data());  // Eq. 8.2
    for (int b = 0; b < nb; ++b) out[b] = static_cast<float>(L[b]);
  });
}

Image EmittedRadianceGlassner(const SceneGeometry& geometry, double t_s, int time_samples, std::uint64_t seed,
                              std::uint64_t* shadow_rays) {
  const Scene& scene = geometry.scene();
  RequireStatic(scene);
  const int nb = scene.bands.band_count();
  std::atomic<std::uint64_t> rays{0};
  const double history = t_s - scene.start_s;
  for (const Object& o : scene.objects)
    if (o.phosphor && o.initial.kind != InitialState::Kind::kZero)
      ThrowUserError(scene.source, "objects",
                     "the Glassner baseline integrates from r = 0 ('" + o.name + "' starts otherwise)");
  Image image = ForEachPixel(geometry, [&](const Hit& hit, float* out, std::uint64_t pixel) {
    const Object& object = scene.objects[hit.object];
    const Material& material = *object.phosphor;
    SplitMix64 random(seed * 0x9E3779B97F4A7C15ull ^ (pixel + 1) * 0xD1B54A32D192ED03ull);
    auto uniform = [&] { return random.UniformDouble(); };
    std::uint64_t cast = 0;
    std::vector<double> r(material.state_count(), 0.0);
    for (int i = 0; i < material.state_count(); ++i) {
      const double kr = material.states[i].kr;
      // tau = t - s, s ~ kr e^{-kr s} truncated to [0, history]: the kernel's own shape.
      const double mass = -std::expm1(-kr * history);  // integral of kr e^{-kr s} over the history
      if (!(mass > 0)) continue;
      double sum = 0;
      for (int k = 0; k < time_samples; ++k) {
        const double s = -std::log1p(-uniform() * mass) / kr;
        const double tau = t_s - s;
        double a = 0;
        for (const Light& light : scene.lights) {
          const double level = light.schedule.LevelAt(tau);
          if (level <= 0) continue;
          double ke_E = 0;
          for (int b = 0; b < nb; ++b)
            if (light.E_per_band[b] > 0) ke_E += Ke(object, i, b) * light.E_per_band[b];
          if (ke_E == 0) continue;
          ++cast;  // a generic MC integrator asks the geometry at every sample
          a += level * ke_E * UnitIrradiance(geometry, light, hit);
        }
        // a(tau) e^{-kr s} / pdf(s), pdf = kr e^{-kr s} / mass
        sum += a * mass / kr;
      }
      r[i] = sum / time_samples;
    }
    const std::vector<double> L = EmittedRadiance(material, r.data());  // Eq. 8.2
    for (int b = 0; b < nb; ++b) out[b] = static_cast<float>(L[b]);
    rays += cast;
  });
  if (shadow_rays) *shadow_rays = rays.load();
  return image;
}

}  // namespace phos::render
