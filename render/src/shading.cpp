#include "shading.h"

#include <algorithm>
#include <cmath>

#include "phos/util/random.h"

namespace phos::render {

Shading::Shading(const SceneGeometry& geometry, const CoupledSolver* solver, const VolumeMedia* media,
                 const FrameOptions& options)
    : geometry_(geometry),
      scene_(geometry.scene()),
      solver_(solver),
      media_(media),
      options_(options),
      nb_(scene_.bands.band_count()) {
  const double t = geometry.time_s();
  if (scene_.environment) {
    sky_level_ = static_cast<float>(scene_.environment->schedule.LevelAt(t));
    sky_L_ = Bands(nb_);
    for (int b = 0; b < nb_; ++b) sky_L_[b] = static_cast<float>(sky_level_ * scene_.environment->L_per_band[b]);
  }
  textures_ = geometry.surface_textures();
  for (const Object& object : scene_.objects) {
    Bands a(nb_);
    for (int b = 0; b < nb_; ++b) a[b] = static_cast<float>(object.albedo[b]);
    albedo_.push_back(a);
    albedo_reflects_.push_back(std::any_of(object.albedo.begin(), object.albedo.begin() + nb_, [](double v) { return v > 0; }));
  }
  for (const Light& light : scene_.lights) {
    const double level = light.schedule.LevelAt(t);
    if (level <= 0) continue;
    LitLight lit;
    lit.pose = PoseAt(light, t);
    lit.E = Bands(nb_);
    for (int b = 0; b < nb_; ++b) lit.E[b] = static_cast<float>(level * light.E_per_band[b]);
    lights_.push_back(lit);
    if (lit.pose.bodiless()) area_lights_.push_back(lit);
    if (light.kind == Light::Kind::kMesh) {
      if (emitter_of_object_.empty()) emitter_of_object_.assign(scene_.objects.size(), -1);
      emitter_of_object_[light.emitter_object] = static_cast<int>(lights_.size() - 1);
    }
  }
}

Bands Shading::GlossyAreaLight(const GlossyBsdf& bsdf, const LitLight& light, const Vec3f& p, const Vec3f& n_s,
                               const Vec3f& wo, std::uint64_t& rays) const {
  const LightPose& pose = light.pose;
  Bands L = Bands::Zero(nb_), f(nb_);
  const int side = std::max(1, static_cast<int>(std::lround(std::sqrt(static_cast<double>(pose.samples)))));
  SplitMix64 random(PointSeed(p) * 0x9E3779B97F4A7C15ull + 0x94D049BB133111EBull);
  const Vec3f origin = p + geometry_.ray_epsilon() * n_s;
  for (int i = 0; i < side; ++i)
    for (int j = 0; j < side; ++j) {
      // A point on the light: f cos / p_light = f unit.
      float u1 = (static_cast<float>(i) + random.UniformFloat()) / static_cast<float>(side);
      float u2 = (static_cast<float>(j) + random.UniformFloat()) / static_cast<float>(side);
      const LightRay ray = RayToLight(geometry_, pose, p, n_s, u1, u2);
      if (ray.unit > 0) {
        ++rays;
        if (!geometry_.Occluded(ray.origin, ray.direction, ray.t_far)) {
          bsdf.Eval(n_s, wo, ray.direction, f.data());
          L += f * (ray.unit * PowerHeuristic(ray.area_pdf, bsdf.Pdf(n_s, wo, ray.direction)));
        }
      }
      // A draw of the BSDF that finds the light: f cos / p_bsdf.
      const float u0 = random.UniformFloat();
      u1 = (static_cast<float>(i) + random.UniformFloat()) / static_cast<float>(side);
      u2 = (static_cast<float>(j) + random.UniformFloat()) / static_cast<float>(side);
      Vec3f wi;
      float p_bsdf;
      if (!bsdf.Sample(n_s, wo, u0, u1, u2, &wi, &p_bsdf) || !(p_bsdf > 0)) continue;
      const float cosine = n_s.dot(wi);
      if (!(cosine > 0)) continue;
      const float p_light = AreaLightSeenPdf(pose, origin, wi, rays);
      if (!(p_light > 0)) continue;
      bsdf.Eval(n_s, wo, wi, f.data());
      L += f * (cosine / p_bsdf * PowerHeuristic(p_bsdf, p_light));
    }
  L *= light.E / static_cast<float>(side * side);
  if (media_) L *= Transmittance(pose, p);
  return L;
}

float Shading::AreaLightSeenPdf(const LightPose& pose, const Vec3f& origin, const Vec3f& direction,
                                std::uint64_t& rays) const {
  if (pose.bodiless()) {
    const float t = HitAreaLight(pose, origin, direction, 1e30f);
    if (!(t > 0)) return 0.0f;
    ++rays;
    if (geometry_.Occluded(origin, direction, t * (1 - 1e-4f))) return 0.0f;
    return t * t / (-pose.normal.dot(direction) * pose.area_m2);
  }
  // An emissive mesh: the ray must find its front first.
  ++rays;
  const Hit hit = geometry_.Intersect(origin, direction);
  if (!hit || hit.object != pose.object || !hit.front) return 0.0f;
  const float cos_light = -hit.normal.dot(direction);
  return cos_light > 0 ? hit.distance * hit.distance / (cos_light * geometry_.EmitterArea(pose.object)) : 0.0f;
}

}  // namespace phos::render
