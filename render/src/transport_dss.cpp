// dss transport (renderer.h, docs/render.md): the direct transport's rows,
// then one bounce of diffuse light through deep screen space (dss.h), the
// dipole's light beneath translucent surfaces (subsurface.h), and the
// surfels' light on the media (volume.h).
#include <algorithm>
#include <atomic>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "phos/render/bsdf.h"
#include "phos/render/dss.h"
#include "phos/render/subsurface.h"
#include "phos/render/volume.h"
#include "phos/util/math.h"
#include "transport.h"

namespace phos::render {
namespace {

class DssTransport final : public FrameTransport {
 public:
  DssTransport(const Shading& shading, const CameraRays& camera)
      : shading_(shading), camera_(camera), direct_(MakeDirectTransport(shading, camera)) {}

  // The direct transport's pixels, without the sky's reflection and the
  // translucent objects' (ShadeCameraRay): Finish adds them.
  void RenderRow(int y, Image& image, std::uint64_t& rays) override { direct_->RenderRow(y, image, rays); }

  // The bounce, in stages: the surfels and what they send, the bounce on
  // what the camera sees (and the sky it still sees), the dipole beneath
  // translucent surfaces, and the surfels' light on the media.
  std::uint64_t Finish(Image& image) override {
    const Scene& scene = shading_.scene();
    const bool translucent =
        std::any_of(scene.objects.begin(), scene.objects.end(), [](const Object& o) { return bool(o.subsurface); });
    const SurfelLight light = LightSurfels(translucent);
    std::uint64_t rays = light.rays;
    // Only surfels that send light matter to either receiver (the occlusion
    // is not used here): a dark scene's unlit floor costs nothing. The sky
    // needs every surfel (they occlude it).
    const bool sky = shading_.sky_level() > 0;
    const SurfelLight sending = sky ? SurfelLight{} : KeepSending(light);
    const std::vector<Surfel>& senders = sky ? light.surfels : sending.surfels;
    const std::vector<float>& sent = sky ? light.radiosity : sending.radiosity;
    const GBuffer g = RenderGBuffer(shading_.geometry(), scene, shading_.geometry().time_s());
    DssOptions dss;
    dss.channels = shading_.band_count();
    // With indirect visibility every surfel counts (the dark ones hide the glowing ones behind them).
    const DssResult indirect = shading_.options().indirect_visibility
                                   ? SplatBouncedZBuffer(g, camera_, light.surfels, light.radiosity, dss)
                                   : SplatDeepScreenSpace(g, camera_, senders, sent, dss);
    // The media between the camera and the surfaces dim the bounce as they
    // dim the surface, and receive the surfels' light themselves.
    IntervalMap intervals;
    if (shading_.media())
      intervals = BuildIntervalMap(*shading_.media(), g, camera_, shading_.options().interval_layers);
    AddBounce(g, indirect, intervals, image);
    if (translucent) rays += AddSubsurface(g, light, intervals, dss, image);
    if (!senders.empty()) AddMediaBounce(intervals, senders, sent, dss, image);
    return rays;
  }

 private:
  // Surfels and what each sends (B = albedo E + pi Lp), [surfel * nb + band];
  // E: the lights' irradiance on translucent objects' surfels, for the dipole
  // (empty when none is translucent).
  struct SurfelLight {
    std::vector<Surfel> surfels;
    std::vector<float> radiosity, E;
    std::uint64_t rays = 0;
  };

  // Every surfel of what the camera sees, and its radiosity: its front side
  // sends what it reflects of the lights, and its glow (a textured surfel's
  // albedo at its centre: a point lookup).
  SurfelLight LightSurfels(bool translucent) const {
    const Scene& scene = shading_.scene();
    const int nb = shading_.band_count();
    SurfelLight light;
    light.surfels =
        Surfelize(shading_.geometry(), camera_.origin(), static_cast<float>(scene.camera.fov_deg), SurfelOptions{});
    const std::vector<Surfel>& surfels = light.surfels;
    light.radiosity.assign(surfels.size() * nb, 0.0f);
    light.E.assign(translucent ? surfels.size() * nb : 0, 0.0f);
    std::atomic<std::uint64_t> total_rays{0};
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, surfels.size()),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                        std::uint64_t rays = 0;
                        Bands E, texture_albedo;
                        for (std::size_t i = range.begin(); i != range.end(); ++i) {
                          const Surfel& s = surfels[i];
                          shading_.DirectIrradiance(s.position, s.normal, E, rays);
                          Bands B = shading_.AlbedoAt(FrontHit(s), s.position, {}, texture_albedo) * E;
                          Bands Le;
                          if (shading_.Emission(FrontHit(s), Le)) B += kPiF * Le;
                          std::copy(B.data(), B.data() + nb, &light.radiosity[i * nb]);
                          if (translucent && scene.objects[s.object].subsurface)
                            std::copy(E.data(), E.data() + nb, &light.E[i * nb]);
                        }
                        total_rays += rays;
                      });
    light.rays = total_rays.load();
    return light;
  }

  // The surfels that send any light, with their radiosity (no E, no rays).
  SurfelLight KeepSending(const SurfelLight& light) const {
    const int nb = shading_.band_count();
    SurfelLight sending;
    for (std::size_t i = 0; i < light.surfels.size(); ++i) {
      const float* B = &light.radiosity[i * nb];
      if (!std::any_of(B, B + nb, [](float v) { return v > 0; })) continue;
      sending.surfels.push_back(light.surfels[i]);
      sending.radiosity.insert(sending.radiosity.end(), B, B + nb);
    }
    return sending;
  }

  // image += the bounce's irradiance at each pixel reflected by its albedo,
  // and under a sky the sky less what the surfels hide of it (directional
  // occlusion), both dimmed by the media in front.
  void AddBounce(const GBuffer& g, const DssResult& indirect, const IntervalMap& intervals, Image& image) const {
    const Scene& scene = shading_.scene();
    const int nb = shading_.band_count(), width = image.width;
    const bool sky = shading_.sky_level() > 0, media = shading_.media() != nullptr;
    tbb::parallel_for(0, image.height, [&](int y) {
      Bands texture_albedo, directional_albedo(nb);
      Gloss texture_gloss;
      for (int x = 0; x < width; ++x) {
        const std::size_t p = static_cast<std::size_t>(y) * width + x;
        if (g.object[p] < 0) continue;
        const Hit hit = g.SeenHit(p);
        const Shading::Surface surface =
            shading_.SurfaceAt(hit, camera_.origin(), CameraDifferential(shading_, camera_, camera_.Through(x + 0.5f, y + 0.5f)),
                               texture_albedo, texture_gloss);
        // A glossy surface reflects the bounce and the sky, light from every
        // side, by its directional albedo toward the camera: exact for a
        // uniform incident radiance, as direct transport reflects the sky
        // (Shading::GlossyReflection). Its Lambertian albedo alone left a
        // dark glossy floor at half the sky the other transports show.
        if (surface.gloss) {
          const Vec3f wo = (camera_.origin() - hit.position).normalized();
          GlossyBsdf(*surface.gloss, surface.albedo->data(), nb).DirectionalAlbedo(hit.normal.dot(wo), directional_albedo.data());
        }
        const Bands& albedo = surface.gloss ? directional_albedo : *surface.albedo;
        const float T = media ? intervals.T_end[p] : 1.0f;
        float* out = image.at(x, y);
        for (int b = 0; b < nb; ++b) out[b] += T * albedo[b] * indirect.irradiance[p * nb + b] / kPiF;
        if (sky && !scene.objects[g.object[p]].subsurface) {
          const float gradient = static_cast<float>(scene.environment->gradient);
          const float unit =
              SkyIrradianceFromOcclusion(indirect.occlusion[p], indirect.occlusion_y[p], g.normal[p].y(), gradient);
          for (int b = 0; b < nb; ++b) out[b] += T * albedo[b] * shading_.sky_L()[b] * unit / kPiF;
        }
      }
    });
  }

  // Translucent objects: the lights' irradiance on their surfels, carried
  // beneath the surface by the dipole (subsurface.h) to the pixels of the
  // same object. Returns the rays cast.
  std::uint64_t AddSubsurface(const GBuffer& g, const SurfelLight& light, const IntervalMap& intervals,
                              const DssOptions& dss, Image& image) const {
    const Scene& scene = shading_.scene();
    const int nb = shading_.band_count(), width = image.width;
    const bool media = shading_.media() != nullptr;
    // Translucent objects' dipoles, per object and band.
    std::vector<Dipole> dipoles(scene.objects.size() * nb);
    for (std::size_t o = 0; o < scene.objects.size(); ++o) {
      const auto& sss = scene.objects[o].subsurface;
      if (!sss) continue;
      for (int b = 0; b < nb; ++b)
        dipoles[o * nb + b] = Dipole::From(sss->sigma_a_per_m[b], sss->sigma_s_prime_per_m[b], sss->eta);
    }
    std::vector<Surfel> entering;
    std::vector<float> E_in;
    for (std::size_t i = 0; i < light.surfels.size(); ++i) {
      const float* E = &light.E[i * nb];
      if (!scene.objects[light.surfels[i].object].subsurface || *std::max_element(E, E + nb) <= 0) continue;
      entering.push_back(light.surfels[i]);
      E_in.insert(E_in.end(), E, E + nb);
    }
    // The near field of each receiver (two target surfel radii at its
    // depth) from its own irradiance in closed form; the surfels send the rest.
    const std::vector<float> near = SubsurfaceNearField(g, SurfelOptions{}.s, static_cast<float>(scene.camera.fov_deg));
    DssOptions sss_options = dss;
    sss_options.dipoles = &dipoles;
    sss_options.near_m = &near;
    const DssResult exitance = SplatDeepScreenSpace(g, camera_, entering, E_in, sss_options);
    std::atomic<std::uint64_t> total_rays{0};
    tbb::parallel_for(0, image.height, [&](int y) {
      std::uint64_t rays = 0;
      Bands E;
      for (int x = 0; x < width; ++x) {
        const std::size_t p = static_cast<std::size_t>(y) * width + x;
        if (g.object[p] < 0 || !scene.objects[g.object[p]].subsurface) continue;
        const float T = media ? intervals.T_end[p] : 1.0f;
        shading_.DirectIrradiance(g.position[p], g.normal[p], E, rays);
        const Dipole* d = &dipoles[static_cast<std::size_t>(g.object[p]) * nb];
        float* out = image.at(x, y);
        for (int b = 0; b < nb; ++b) out[b] += T * d[b].Exitance(E[b], near[p], exitance.irradiance[p * nb + b]) / kPiF;
      }
      total_rays += rays;
    });
    return total_rays.load();
  }

  // The surfels' light scattered by the media toward the camera (isotropic
  // phase function, 1 / 4 pi), at each layer of the interval map.
  void AddMediaBounce(const IntervalMap& intervals, const std::vector<Surfel>& senders, const std::vector<float>& sent,
                      const DssOptions& dss, Image& image) const {
    const Scene& scene = shading_.scene();
    const int nb = shading_.band_count(), width = image.width;
    for (const GBuffer& layer : intervals.layer) {
      const DssResult in_medium = SplatDeepScreenSpace(layer, camera_, senders, sent, dss);
      tbb::parallel_for(0, image.height, [&](int y) {
        for (int x = 0; x < width; ++x) {
          const std::size_t p = static_cast<std::size_t>(y) * width + x;
          const int v = layer.object[p];
          if (v < 0) continue;
          const std::vector<double>& albedo = scene.volumes[v].albedo;
          float* out = image.at(x, y);
          for (int b = 0; b < nb; ++b)
            out[b] +=
                intervals.delta_T[p] * static_cast<float>(albedo[b]) * in_medium.irradiance[p * nb + b] / (4 * kPiF);
        }
      });
    }
  }

  const Shading& shading_;
  const CameraRays& camera_;
  std::unique_ptr<FrameTransport> direct_;
};

}  // namespace

std::unique_ptr<FrameTransport> MakeDssTransport(const Shading& shading, const CameraRays& camera) {
  return std::make_unique<DssTransport>(shading, camera);
}

}  // namespace phos::render
