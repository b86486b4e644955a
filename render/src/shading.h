#pragma once
// The scene at one moment as every transport shades it (renderer.h): the
// lights that are on and their poses, the sky's level, each object's albedo
// (constant or textured) and gloss, the phosphors' glow Lp (Eq. 8.2's
// emitted term) and the media. Written once here; the direct, path and dss
// transports (transport.h) differ only in the paths they follow.
// Internal to phos_render.

#include <cstdint>

#include <Eigen/Core>

#include "phos/render/bsdf.h"
#include "phos/render/geometry.h"
#include "phos/render/renderer.h"
#include "phos/render/solver.h"
#include "phos/render/surface_textures.h"
#include "phos/render/volume.h"
#include "phos/util/math.h"

namespace phos::render {

inline constexpr int kMaxBands = 64;

// Radiance or throughput per band, without allocation.
using Bands = Eigen::Array<float, Eigen::Dynamic, 1, 0, kMaxBands, 1>;

// Veach's power heuristic (beta = 2): the weight of a sample drawn with
// solid-angle pdf p_this when the other strategy would draw it with p_other.
inline float PowerHeuristic(float p_this, float p_other) {
  const float a = p_this * p_this, b = p_other * p_other;
  return a + b > 0 ? a / (a + b) : 0.0f;
}

// A camera ray's footprint (pbrt's ray differentials): the directions
// through the next pixel right and down. Zero: none, a point lookup (the
// path tracer's bounces, the dss surfels).
struct RayDifferential {
  Vec3f dx = Vec3f::Zero(), dy = Vec3f::Zero();
};

class Shading {
 public:
  // A light that is on now: its pose and its band irradiance times its level.
  struct LitLight {
    LightPose pose;
    Bands E;
  };

  Shading(const SceneGeometry& geometry, const CoupledSolver* solver, const VolumeMedia* media,
          const FrameOptions& options);

  const SceneGeometry& geometry() const { return geometry_; }
  const Scene& scene() const { return scene_; }
  const CoupledSolver* solver() const { return solver_; }
  const VolumeMedia* media() const { return media_; }
  const FrameOptions& options() const { return options_; }
  int band_count() const { return nb_; }
  const std::vector<LitLight>& lights() const { return lights_; }
  // The quads and disks of lights(), which rays meet by HitAreaLight.
  const std::vector<LitLight>& area_lights() const { return area_lights_; }
  float sky_level() const { return sky_level_; }  // 0: no sky now
  const Bands& sky_L() const { return sky_L_; }   // the sky's band radiance times its level

  // Whether the side of a hit shows its glow: the front, or either face of a
  // two-sided phosphor (Object::two_sided).
  bool ShowsGlow(const Hit& hit) const { return hit.front || scene_.objects[hit.object].two_sided; }

  // L += Lp at the hit (the glowing sides of phosphors only): the emissive
  // term of Eq. 8.2 in a frame, added band by band with no temporary.
  void AddEmission(const Hit& hit, Bands& L) const {
    if (!solver_ || !ShowsGlow(hit)) return;
    const int slot = solver_->atlas().SlotOf(hit.object);
    if (slot < 0) return;
    const std::size_t texel = solver_->atlas().TexelOf(slot, hit.triangle, hit.b1, hit.b2);
    if (texel == TexelAtlas::kNoTexel) return;  // bare of its mask's paint
    const float coverage = solver_->atlas().Coverage(slot, texel);
    for (int b : solver_->emission_bands(slot)) L[b] += coverage * solver_->Lp(slot, b, texel);
  }

  // Le = Lp at the hit; false where nothing glows.
  bool Emission(const Hit& hit, Bands& Le) const {
    if (!solver_ || !ShowsGlow(hit) || solver_->atlas().SlotOf(hit.object) < 0) return false;
    Le.setZero(nb_);
    AddEmission(hit, Le);
    return true;
  }

  // Irradiance from the scene's lights at p on the side of n_s (shadow rays),
  // and from the sky unless `sky` is false (the path tracer finds the sky
  // by its bounces; dss shades its pixels' sky by directional occlusion).
  void DirectIrradiance(const Vec3f& p, const Vec3f& n_s, Bands& E, std::uint64_t& rays, bool sky = true) const {
    E.setZero(nb_);
    if (sky && sky_level_ > 0) {
      E += sky_L_ * UnitSkyIrradiance(geometry_, *scene_.environment, p, n_s, options_.sky_rays, PointSeed(p), &rays);
    }
    for (const LitLight& light : lights_) {
      Vec3f direction;
      const float unit = light.pose.area() ? AreaLightReaching(light, p, n_s, rays)
                                           : DeltaLightReaching(light, p, n_s, rays, direction);
      if (unit > 0) E += light.E * unit;
    }
  }

  // An area light's (quad, disk, emissive mesh) unit irradiance at p on the
  // side of n_s, shadowed (UnitIrradiance's ratio estimator) and through the
  // media; 0 where it does not reach.
  float AreaLightReaching(const LitLight& light, const Vec3f& p, const Vec3f& n_s, std::uint64_t& rays) const {
    const float unit = UnitIrradiance(geometry_, light.pose, p, n_s, &rays);
    return unit > 0 && media_ ? unit * Transmittance(light.pose, p) : unit;
  }

  // A delta light's (point, spot, directional, sheet) unit irradiance at p on
  // the side of n_s, unshadowed and through the media, and the direction
  // toward it; 0 where it does not reach.
  float DeltaLightReaching(const LitLight& light, const Vec3f& p, const Vec3f& n_s, std::uint64_t& rays,
                           Vec3f& direction) const {
    const LightRay ray = RayToLight(geometry_, light.pose, p, n_s);
    if (!(ray.unit > 0)) return 0.0f;
    ++rays;
    if (geometry_.Occluded(ray.origin, ray.direction, ray.t_far)) return 0.0f;
    direction = ray.direction;
    return media_ ? ray.unit * Transmittance(light.pose, p) : ray.unit;
  }

  // The media's transmittance from p to a light.
  float Transmittance(const LightPose& pose, const Vec3f& p) const {
    return pose.positional() || pose.area() ? media_->Transmittance(p, pose.at)
                                            : media_->TransmittanceToInfinity(p, -pose.at);
  }

  // L += the radiance of the area lights whose front a ray crosses before
  // t_far (they have no body: what lies behind shows through), each times
  // `weight(light, distance)`.
  template <typename Weight>
  void AddAreaLightsSeen(const Vec3f& origin, const Vec3f& direction, float t_far, const Bands& beta, Bands& L,
                         Weight&& weight) const {
    for (const LitLight& light : area_lights_) {
      const float t = HitAreaLight(light.pose, origin, direction, t_far);
      if (t > 0) L += beta * light.E * weight(light.pose, direction, t);
    }
  }

  // The radiance of the emissive object whose front a hit is on, or null.
  const Bands* EmitterAt(const Hit& hit) const {
    if (emitter_of_object_.empty() || !hit.front) return nullptr;
    const int l = emitter_of_object_[hit.object];
    return l >= 0 ? &lights_[l].E : nullptr;
  }

  // A glossy surface's reflection in direct transport (docs/render.md,
  // "Glossy surfaces"): the delta lights (point, spot, directional, sheet)
  // through the whole BSDF toward each, the area lights by
  // GlossyAreaLight (their highlights), and the sky by its irradiance times
  // the directional albedo over pi (a uniform sky's reflection exactly).
  Bands GlossyReflection(const Gloss& gloss, const Bands& albedo, const Vec3f& p, const Vec3f& n_s, const Vec3f& wo,
                         std::uint64_t& rays) const {
    const GlossyBsdf bsdf(gloss, albedo.data(), nb_);
    Bands L = Bands::Zero(nb_), f(nb_);
    if (sky_level_ > 0 && options_.transport != Transport::kDss) {
      Bands rho(nb_);
      bsdf.DirectionalAlbedo(n_s.dot(wo), rho.data());
      L += rho * sky_L_ *
           (UnitSkyIrradiance(geometry_, *scene_.environment, p, n_s, options_.sky_rays, PointSeed(p), &rays) / kPiF);
    }
    for (const LitLight& light : lights_) {
      if (light.pose.area()) {
        L += GlossyAreaLight(bsdf, light, p, n_s, wo, rays);
        continue;
      }
      Vec3f direction;
      const float unit = DeltaLightReaching(light, p, n_s, rays, direction);
      if (!(unit > 0)) continue;
      bsdf.Eval(n_s, wo, direction, f.data());
      L += f * light.E * unit;
    }
    return L;
  }

  // An area light's reflection in a glossy surface at p (multiple importance
  // sampling, Veach 1997 ch. 9; pbrt-v4's direct lighting): light.samples
  // stratified points on the light and as many stratified draws of the
  // BSDF, each weighted by the power heuristic against the other strategy
  // finding the same direction. The light's points serve a rough lobe, the
  // BSDF's draws a sharp highlight. Seeded by the point, as UnitIrradiance,
  // so that a pixel is the same in every frame of a still scene.
  Bands GlossyAreaLight(const GlossyBsdf& bsdf, const LitLight& light, const Vec3f& p, const Vec3f& n_s,
                        const Vec3f& wo, std::uint64_t& rays) const;

  // Where a ray from `origin` along unit `direction` meets an area light's
  // emitting side unoccluded: the solid-angle pdf with which RayToLight
  // would draw that direction; 0 where it does not (occluded, missed, the
  // back of the light).
  float AreaLightSeenPdf(const LightPose& pose, const Vec3f& origin, const Vec3f& direction,
                         std::uint64_t& rays) const;

  // Converted to float bands once per frame, not at every hit.
  const Bands& Albedo(int object) const { return albedo_[object]; }

  // Whether any object is textured: only then do camera rays carry differentials.
  bool textured() const { return textures_ != nullptr; }

  // A hit's surface: its albedo and, on a glossy object, its gloss (null on
  // a Lambertian one). Each is the object's constant, or its texture
  // filtered over the footprint of the ray from `origin` (one footprint for
  // both), written to `texture_albedo` or `texture_gloss`. Untextured
  // objects skip the lookups and cost what they did.
  struct Surface {
    const Bands* albedo;
    const Gloss* gloss;
    bool reflects;  // glossy, or some band of the albedo above 0: the path goes on
  };
  Surface SurfaceAt(const Hit& hit, const Vec3f& origin, const RayDifferential& differential, Bands& texture_albedo,
                    Gloss& texture_gloss) const {
    const auto& gloss = scene_.objects[hit.object].gloss;
    Surface surface{&albedo_[hit.object], gloss ? &*gloss : nullptr, gloss || albedo_reflects_[hit.object]};
    if (!textures_ || !textures_->any_textured(hit.object)) return surface;
    const UvFootprint footprint = Footprint(hit, origin, differential);
    if (textures_->textured(hit.object)) {
      texture_albedo.resize(nb_);
      textures_->Albedo(hit.object, footprint, texture_albedo.data());
      surface.albedo = &texture_albedo;
      surface.reflects = gloss || texture_albedo.maxCoeff() > 0;
    }
    if (gloss && textures_->gloss_textured(hit.object)) {
      texture_gloss = textures_->GlossAt(hit.object, footprint, *gloss);
      surface.gloss = &texture_gloss;
    }
    return surface;
  }

  // The albedo at a hit alone (as SurfaceAt's).
  const Bands& AlbedoAt(const Hit& hit, const Vec3f& origin, const RayDifferential& differential,
                        Bands& texture_albedo) const {
    if (!textures_ || !textures_->textured(hit.object)) return albedo_[hit.object];
    texture_albedo.resize(nb_);
    textures_->Albedo(hit.object, Footprint(hit, origin, differential), texture_albedo.data());
    return texture_albedo;
  }

  // The hit's UV footprint for the ray from `origin` and its differential.
  UvFootprint Footprint(const Hit& hit, const Vec3f& origin, const RayDifferential& differential) const {
    return textures_->Footprint(geometry_, hit, OffsetOnHitPlane(hit, origin, differential.dx),
                                OffsetOnHitPlane(hit, origin, differential.dy));
  }

  // Where the ray from origin along `direction` meets the hit's plane, less
  // the hit; zero for no direction or a ray along the plane.
  static Vec3f OffsetOnHitPlane(const Hit& hit, const Vec3f& origin, const Vec3f& direction) {
    const float along = hit.normal.dot(direction);
    if (direction.isZero() || std::abs(along) < 1e-8f) return Vec3f::Zero();
    const float t = hit.normal.dot(hit.position - origin) / along;
    return origin + t * direction - hit.position;
  }

  // The media along a camera ray up to its hit: adds their radiance to L and
  // returns the transmittance the surface behind them is seen through.
  float Media(const Vec3f& origin, const Vec3f& direction, const Hit& hit, float jitter, Bands& L) const {
    if (!media_) return 1.0f;
    return media_->March(origin, direction, hit ? hit.distance : 1e30f, jitter, L.data());
  }

 private:
  const SceneGeometry& geometry_;
  const Scene& scene_;
  const CoupledSolver* solver_;
  const VolumeMedia* media_;
  FrameOptions options_;
  int nb_;
  std::vector<LitLight> lights_;
  std::vector<LitLight> area_lights_;
  std::vector<int> emitter_of_object_;  // per object: its emissive light in lights_, or -1 (empty: none)
  std::vector<Bands> albedo_;           // per object
  // Per object: some band of its albedo is above 0 (a path hitting it goes
  // on), known once rather than found by a reduction over the bands at
  // every path vertex.
  std::vector<char> albedo_reflects_;
  const SurfaceTextures* textures_ = nullptr;
  float sky_level_ = 0;
  Bands sky_L_;
};

}  // namespace phos::render
