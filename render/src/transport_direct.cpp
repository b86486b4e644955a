// Direct transport (renderer.h): per pixel, camera rays shaded by the lights
// (shadow rays) and the phosphors' own glow Lp (Eq. 8.2); no interreflection.
#include "transport.h"

#include <algorithm>

#include "phos/util/math.h"
#include "phos/util/random.h"

namespace phos::render {
namespace {

// The direct transport's radiance along one camera ray (docs/render.md,
// "Transports"): the media before the hit, the area lights it crosses, the
// sky on a miss, and at the hit its glow and what it reflects of the lights
// and the sky. Under dss, without the sky's reflection and the reflection of
// translucent objects (the bounce adds them).
// (Static, with its one caller in this unit, so that GCC inlines it into
// the row loop: out of line, the untextured plane of bench_render
// TexturedDirectFrame/0 took 25.2 to 26.0 ms a frame against 22.5 to 22.9.)
Bands ShadeCameraRay(const Shading& shading, const Vec3f& origin, const Vec3f& direction,
                     const RayDifferential& differential, float jitter, std::uint64_t& rays) {
  const int nb = shading.band_count();
  const Scene& scene = shading.scene();
  const bool dss = shading.options().transport == Transport::kDss;
  Bands L = Bands::Zero(nb);
  ++rays;
  const Hit hit = shading.geometry().Intersect(origin, direction);
  Bands Lm = Bands::Zero(nb);
  const float T = shading.Media(origin, direction, hit, jitter, Lm);
  shading.AddAreaLightsSeen(origin, direction, hit ? hit.distance : 1e30f, Bands::Ones(nb), Lm,
                            [](const LightPose&, const Vec3f&, float) { return 1.0f; });
  if (!hit)
    return shading.sky_level() > 0 ? Bands(Lm + T * shading.sky_L() * scene.environment->Shape(direction.y())) : Lm;
  shading.AddEmission(hit, L);
  if (const Bands* Le = shading.EmitterAt(hit)) L += *Le;
  // A translucent object under dss: its reflection comes from the dipole
  // splat instead (transport_dss.cpp).
  if (dss && scene.objects[hit.object].subsurface) return Lm + T * L;
  Bands E;
  const Vec3f n_s = hit.front ? hit.normal : Vec3f(-hit.normal);
  Bands texture_albedo;
  Gloss texture_gloss;
  const Shading::Surface surface = shading.SurfaceAt(hit, origin, differential, texture_albedo, texture_gloss);
  const Bands& albedo = *surface.albedo;
  if (surface.gloss) {
    L += shading.GlossyReflection(*surface.gloss, albedo, hit.position, n_s, -direction, rays);
    return Lm + T * L;
  }
  shading.DirectIrradiance(hit.position, n_s, E, rays, !dss);
  L += albedo * E / kPiF;  // Lambertian reflection (Eq. 8.2's reflected term)
  return Lm + T * L;
}

// A fixed per-pixel offset of the media's step grid: one sample per pixel
// shows noise, not banding.
float PixelJitter(int x, int y) { return InterleavedGradientNoise(x, y); }

class DirectTransport final : public FrameTransport {
 public:
  DirectTransport(const Shading& shading, const CameraRays& camera) : shading_(shading), camera_(camera) {}

  // direct_spp samples per pixel: one at the centre, or jittered.
  void RenderRow(int y, Image& image, std::uint64_t& rays) override {
    const int nb = shading_.band_count(), spp = shading_.options().direct_spp;
    for (int x = 0; x < image.width; ++x) {
      SplitMix64 random = PixelStream(shading_.options(), image.width, x, y);
      Bands sum = Bands::Zero(nb);
      for (int s = 0; s < spp; ++s) {
        const float jx = spp == 1 ? 0.5f : random.UniformFloat(), jy = spp == 1 ? 0.5f : random.UniformFloat();
        const float px = static_cast<float>(x) + jx, py = static_cast<float>(y) + jy;
        const Vec3f through = camera_.Through(px, py);
        sum += ShadeCameraRay(shading_, camera_.origin(), through.normalized(),
                              CameraDifferential(shading_, camera_, through),
                              spp == 1 ? PixelJitter(x, y) : random.UniformFloat(), rays);
      }
      sum /= static_cast<float>(spp);
      std::copy(sum.data(), sum.data() + nb, image.at(x, y));
    }
  }

 private:
  const Shading& shading_;
  const CameraRays& camera_;
};

}  // namespace

std::unique_ptr<FrameTransport> MakeDirectTransport(const Shading& shading, const CameraRays& camera) {
  return std::make_unique<DirectTransport>(shading, camera);
}

}  // namespace phos::render
