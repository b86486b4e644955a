#include "phos/render/renderer.h"

#include <algorithm>
#include <bit>
#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "phos/render/dss.h"
#include "phos/render/subsurface.h"
#include "phos/render/volume.h"
#include "phos/util/atomic_file.h"
#include "phos/util/colour.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/math.h"
#include "phos/util/random.h"

namespace phos::render {
namespace {

constexpr int kMaxBands = 64;

// A fixed per-pixel offset of the media's step grid: one sample per pixel
// shows noise, not banding.
float PixelJitter(int x, int y) { return InterleavedGradientNoise(x, y); }

// Radiance or throughput per band, without allocation.
using Bands = Eigen::Array<float, Eigen::Dynamic, 1, 0, kMaxBands, 1>;

// Cosine-weighted direction about n (Malley's method).
Vec3f SampleCosine(const Vec3f& n, float u1, float u2) {
  const float r = std::sqrt(u1), phi = 2 * kPiF * u2;
  const Vec3f t = n.unitOrthogonal(), b = n.cross(t);
  return (r * std::cos(phi) * t + r * std::sin(phi) * b + std::sqrt(std::max(0.0f, 1 - u1)) * n).normalized();
}

// The glowing triangles of this moment, for next-event estimation: chosen in
// proportion to their emitted power (texel Lp summed over bands, times area).
struct EmitterDistribution {
  struct Entry {
    int object, triangle;
    float area;
  };
  std::vector<Entry> entries;
  std::vector<double> cdf;              // cumulative power, normalized
  std::vector<std::vector<float>> pdf;  // per object, per triangle: probability of choosing it
  bool empty() const { return entries.empty(); }

  EmitterDistribution(const SceneGeometry& geometry, const CoupledSolver* solver) {
    pdf.resize(geometry.object_count());
    if (!solver) return;
    const TexelAtlas& atlas = solver->atlas();
    std::vector<double> power;
    double total = 0;
    for (std::size_t s = 0; s < atlas.objects().size(); ++s) {
      const TexelAtlas::ObjectTexels& texels = atlas.objects()[s];
      const int triangles = geometry.triangle_count(texels.object);
      // Mean Lp (summed over bands) of each triangle's texels.
      std::vector<double> sum(triangles, 0.0);
      std::vector<std::size_t> count(triangles, 0);
      const std::vector<int>& bands = solver->emission_bands(static_cast<int>(s));
      atlas.ForEachTexel(static_cast<int>(s), [&](std::size_t k, int t, float, float) {
        for (int b : bands) sum[t] += solver->Lp(static_cast<int>(s), b, k);
        ++count[t];
      });
      for (int t = 0; t < triangles; ++t) {
        const float area = geometry.Area(texels.object, t);
        const double p = count[t] ? sum[t] / static_cast<double>(count[t]) * area : 0.0;
        if (!(p > 0)) continue;
        entries.push_back({texels.object, t, area});
        power.push_back(p);
        total += p;
      }
    }
    if (entries.empty()) return;
    double running = 0;
    for (std::size_t e = 0; e < entries.size(); ++e) {
      running += power[e] / total;
      cdf.push_back(running);
      auto& object_pdf = pdf[entries[e].object];
      if (object_pdf.empty()) object_pdf.assign(geometry.triangle_count(entries[e].object), 0.0f);
      object_pdf[entries[e].triangle] = static_cast<float>(power[e] / total);
    }
    cdf.back() = 1.0;
  }
  // Probability per unit area of sampling a point of (object, triangle).
  float AreaPdf(int object, int triangle, float area) const {
    const auto& p = pdf[object];
    return p.empty() ? 0.0f : p[triangle] / area;
  }
  const Entry& Pick(float u) const {
    const auto it = std::lower_bound(cdf.begin(), cdf.end(), static_cast<double>(u));
    return entries[std::min<std::size_t>(it - cdf.begin(), entries.size() - 1)];
  }
};

class Tracer {
 public:
  Tracer(const SceneGeometry& geometry, const CoupledSolver* solver, const VolumeMedia* media,
         const FrameOptions& options)
      : geometry_(geometry),
        scene_(geometry.scene()),
        solver_(solver),
        media_(media),
        options_(options),
        nb_(scene_.bands.band_count()),
        emitters_(geometry, options.transport == Transport::kPath ? solver : nullptr) {
    const double t = geometry.time_s();
    if (scene_.environment) {
      sky_level_ = static_cast<float>(scene_.environment->schedule.LevelAt(t));
      sky_L_ = Bands(nb_);
      for (int b = 0; b < nb_; ++b) sky_L_[b] = static_cast<float>(sky_level_ * scene_.environment->L_per_band[b]);
    }
    for (const Light& light : scene_.lights) {
      const double level = light.schedule.LevelAt(t);
      if (level <= 0) continue;
      LitLight lit;
      lit.pose = PoseAt(light, t);
      lit.E = Bands(nb_);
      for (int b = 0; b < nb_; ++b) lit.E[b] = static_cast<float>(level * light.E_per_band[b]);
      lights_.push_back(lit);
    }
  }

  // Lp at a surface point seen from its front; zero elsewhere.
  // L += Lp at the hit (front sides of phosphors only): the emissive term of
  // Eq. 8.2 in a frame, added band by band with no temporary.
  void AddEmission(const Hit& hit, Bands& L) const {
    if (!solver_ || !hit.front) return;
    const int slot = solver_->atlas().SlotOf(hit.object);
    if (slot < 0) return;
    const std::size_t texel = solver_->atlas().TexelOf(slot, hit.triangle, hit.b1, hit.b2);
    for (int b : solver_->emission_bands(slot)) L[b] += solver_->Lp(slot, b, texel);
  }

  // Le = Lp at the hit; false where nothing glows.
  bool Emission(const Hit& hit, Bands& Le) const {
    if (!solver_ || !hit.front || solver_->atlas().SlotOf(hit.object) < 0) return false;
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
      const std::uint64_t seed = (std::uint64_t(std::bit_cast<std::uint32_t>(p.x())) * 73856093u) ^
                                 (std::uint64_t(std::bit_cast<std::uint32_t>(p.y())) * 19349663u) ^
                                 (std::uint64_t(std::bit_cast<std::uint32_t>(p.z())) * 83492791u);
      E += sky_L_ * UnitSkyIrradiance(geometry_, *scene_.environment, p, n_s, options_.sky_rays, seed, &rays);
    }
    for (const LitLight& light : lights_) {
      float unit = UnitIrradiance(geometry_, light.pose, p, n_s, &rays);
      // Media between the point and the light shadow it (a cloud on the floor).
      if (unit > 0 && media_)
        unit *= light.pose.kind == Light::Kind::kPoint ? media_->Transmittance(p, light.pose.at)
                                                       : media_->TransmittanceToInfinity(p, -light.pose.at);
      if (unit > 0) E += light.E * unit;
    }
  }

  Bands Albedo(int object) const {
    Bands a(nb_);
    for (int b = 0; b < nb_; ++b) a[b] = static_cast<float>(scene_.objects[object].albedo[b]);
    return a;
  }

  // The media along a camera ray up to its hit: adds their radiance to L and
  // returns the transmittance the surface behind them is seen through.
  float Media(const Vec3f& origin, const Vec3f& direction, const Hit& hit, float jitter, Bands& L) const {
    if (!media_) return 1.0f;
    return media_->March(origin, direction, hit ? hit.distance : 1e30f, jitter, L.data());
  }

  Bands Direct(const Vec3f& origin, const Vec3f& direction, float jitter, std::uint64_t& rays) const {
    Bands L = Bands::Zero(nb_);
    ++rays;
    const Hit hit = geometry_.Intersect(origin, direction);
    Bands Lm = Bands::Zero(nb_);
    const float T = Media(origin, direction, hit, jitter, Lm);
    if (!hit) return sky_level_ > 0 ? Bands(Lm + T * sky_L_ * scene_.environment->Shape(direction.y())) : Lm;
    AddEmission(hit, L);
    // A translucent object under dss: its reflection comes from the dipole
    // splat instead (RenderBands).
    if (options_.transport == Transport::kDss && scene_.objects[hit.object].subsurface) return Lm + T * L;
    Bands E;
    DirectIrradiance(hit.position, hit.front ? hit.normal : Vec3f(-hit.normal), E, rays,
                     options_.transport != Transport::kDss);
    L += Albedo(hit.object) * E / kPiF;  // Lambertian reflection (Eq. 8.2's reflected term)
    return Lm + T * L;
  }

  Bands Path(Vec3f origin, Vec3f direction, SplitMix64& random, std::uint64_t& rays) const {
    Bands L = Bands::Zero(nb_), beta = Bands::Ones(nb_), Le, E;
    float bsdf_pdf = 0;  // solid-angle pdf of the direction that led here (0: camera ray)
    for (int depth = 0; depth < options_.max_depth; ++depth) {
      ++rays;
      const Hit hit = geometry_.Intersect(origin, direction);
      if (depth == 0 && media_) {
        // The camera ray's media (single scattering; later bounces pass
        // through them unattenuated, see volume.h).
        Bands Lm = Bands::Zero(nb_);
        beta *= Media(origin, direction, hit, random.UniformFloat(), Lm);
        L += Lm;
      }
      if (!hit) {
        // The sky, found by the camera ray or a bounce (cosine sampling; no
        // light sampling for it, so no weight).
        if (sky_level_ > 0) L += beta * sky_L_ * scene_.environment->Shape(direction.y());
        break;
      }
      const Vec3f n_s = hit.front ? hit.normal : Vec3f(-hit.normal);
      // Emission found by the BSDF sample, weighted against light sampling.
      if (Emission(hit, Le)) {
        if (depth == 0) {
          L += beta * Le;
        } else {
          const float cos_light = -hit.normal.dot(direction);
          const float light_pdf =
              emitters_.AreaPdf(hit.object, hit.triangle, geometry_.Area(hit.object, hit.triangle)) * hit.distance *
              hit.distance / cos_light;
          L += beta * Le * (bsdf_pdf * bsdf_pdf / (bsdf_pdf * bsdf_pdf + light_pdf * light_pdf));
        }
      }
      const Bands albedo = Albedo(hit.object);
      if (albedo.maxCoeff() <= 0) break;
      // Next-event estimation: the lights (delta: no MIS) ...
      DirectIrradiance(hit.position, n_s, E, rays, /*sky=*/false);
      L += beta * albedo * E / kPiF;
      // ... and one point on a glowing triangle.
      const Vec3f origin_s = hit.position + geometry_.ray_epsilon() * n_s;
      if (!emitters_.empty()) {
        const auto& entry = emitters_.Pick(random.UniformFloat());
        const float su = std::sqrt(random.UniformFloat()), u2 = random.UniformFloat();
        const float b1 = su * (1 - u2), b2 = su * u2;  // uniform on the triangle
        const Vec3f q = geometry_.Point(entry.object, entry.triangle, b1, b2);
        const Vec3f nq = geometry_.FrontNormal(entry.object, entry.triangle);
        Vec3f wi = q - hit.position;
        const float distance2 = wi.squaredNorm(), distance = std::sqrt(distance2);
        wi /= distance;
        const float cos_s = n_s.dot(wi), cos_l = -nq.dot(wi);
        if (cos_s > 0 && cos_l > 0) {
          ++rays;
          if (!geometry_.Occluded(origin_s, wi, distance * (1 - 1e-4f) - 2 * geometry_.ray_epsilon())) {
            Hit at;
            at.object = entry.object;
            at.triangle = entry.triangle;
            at.b1 = b1;
            at.b2 = b2;
            at.front = true;
            Emission(at, Le);
            const float light_pdf = emitters_.AreaPdf(entry.object, entry.triangle, entry.area) * distance2 / cos_l;
            const float p_bsdf = cos_s / kPiF;
            const float weight = light_pdf * light_pdf / (light_pdf * light_pdf + p_bsdf * p_bsdf);
            L += beta * albedo / kPiF * Le * (cos_s * weight / light_pdf);
          }
        }
      }
      // Continue the path: cosine sampling of the diffuse BSDF, f cos / pdf = albedo.
      direction = SampleCosine(n_s, random.UniformFloat(), random.UniformFloat());
      bsdf_pdf = n_s.dot(direction) / kPiF;
      origin = origin_s;
      beta *= albedo;
      if (depth >= 3) {  // Russian roulette keeps the estimate unbiased
        const float survive = std::min(1.0f, beta.maxCoeff());
        if (random.UniformFloat() >= survive) break;
        beta /= survive;
      }
    }
    return L;
  }

 private:
  struct LitLight {
    LightPose pose;
    Bands E;
  };
  const SceneGeometry& geometry_;
  const Scene& scene_;
  const CoupledSolver* solver_;
  const VolumeMedia* media_;
  FrameOptions options_;
  int nb_;
  EmitterDistribution emitters_;
  std::vector<LitLight> lights_;
  float sky_level_ = 0;  // the sky's level now (0: none)
  Bands sky_L_;          // its band radiance times the level
 public:
  float sky_level() const { return sky_level_; }
  const Bands& sky_L() const { return sky_L_; }
};

}  // namespace

Transport ParseTransport(const std::string& name) {
  if (name == "direct") return Transport::kDirect;
  if (name == "path") return Transport::kPath;
  if (name == "dss") return Transport::kDss;
  ThrowUserError("--transport", "", "unknown transport '" + name + "' (direct, path, dss)");
}

const char* TransportName(Transport transport) {
  return transport == Transport::kPath ? "path" : transport == Transport::kDss ? "dss" : "direct";
}

FrameOptions DefaultFrameOptions(const Scene& scene, Transport transport) {
  FrameOptions options;
  options.transport = transport;
  options.spp = scene.settings.spp;
  options.direct_spp = scene.settings.direct_spp;
  options.max_depth = scene.settings.max_depth;
  options.seed = scene.settings.seed;
  return options;
}

Image RenderBands(const SceneGeometry& geometry, const CoupledSolver* solver, const FrameOptions& options,
                  FrameStats* stats) {
  const Scene& scene = geometry.scene();
  const int nb = scene.bands.band_count();
  if (nb > kMaxBands) ThrowUserError(scene.source, "bands_nm", "more than " + std::to_string(kMaxBands) + " bands");
  const int width = scene.camera.width, height = scene.camera.height;
  Image image(width, height, nb);
  // The media: the solver's (with the phosphorescent voxels' states), or this frame's own.
  std::unique_ptr<VolumeMedia> own_media;
  VolumeMedia* media = solver ? solver->media() : nullptr;
  if (!media && !scene.volumes.empty()) {
    own_media = std::make_unique<VolumeMedia>(scene, geometry);
    media = own_media.get();
  }
  if (media) media->PrepareLighting(geometry.time_s());
  const Tracer tracer(geometry, solver, media, options);
  const CameraRays camera(scene, geometry.time_s());
  std::atomic<std::uint64_t> total_rays{0};
  const int spp = options.transport == Transport::kPath ? options.spp : options.direct_spp;
  tbb::parallel_for(0, height, [&](int y) {
    std::uint64_t rays = 0;
    for (int x = 0; x < width; ++x) {
      SplitMix64 random((std::uint64_t(options.seed) << 40) ^ options.frame * 0x9E3779B97F4A7C15ull ^
                        (std::uint64_t(y) * std::uint64_t(width) + x) * 0x2545F4914F6CDD1Dull);
      Bands sum = Bands::Zero(nb);
      for (int s = 0; s < spp; ++s) {
        // One centred sample when there is one; jittered otherwise.
        const float jx = spp == 1 ? 0.5f : random.UniformFloat(), jy = spp == 1 ? 0.5f : random.UniformFloat();
        const Vec3f direction = camera.Direction(static_cast<float>(x) + jx, static_cast<float>(y) + jy);
        sum +=
            options.transport == Transport::kPath
                ? tracer.Path(camera.origin(), direction, random, rays)
                : tracer.Direct(camera.origin(), direction, spp == 1 ? PixelJitter(x, y) : random.UniformFloat(), rays);
      }
      sum /= static_cast<float>(spp);
      std::copy(sum.data(), sum.data() + nb, image.at(x, y));
    }
    total_rays += rays;
  });
  if (options.transport == Transport::kDss) {
    // One bounce through deep screen space: the surfels' radiosity, splatted
    // as irradiance onto what the camera sees, reflected by its albedo.
    const std::vector<Surfel> surfels =
        Surfelize(geometry, camera.origin(), static_cast<float>(scene.camera.fov_deg), SurfelOptions{});
    // Translucent objects' dipoles (subsurface.h), per object and band.
    std::vector<Dipole> dipoles(scene.objects.size() * nb);
    bool translucent = false;
    for (std::size_t o = 0; o < scene.objects.size(); ++o) {
      const auto& sss = scene.objects[o].subsurface;
      if (!sss) continue;
      translucent = true;
      for (int b = 0; b < nb; ++b)
        dipoles[o * nb + b] = Dipole::From(sss->sigma_a_per_m[b], sss->sigma_s_prime_per_m[b], sss->eta);
    }
    std::vector<float> radiosity(surfels.size() * nb, 0.0f);
    // The irradiance on translucent objects' surfels, kept for the dipole.
    std::vector<float> surfel_E(translucent ? surfels.size() * nb : 0, 0.0f);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, surfels.size()),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                        std::uint64_t rays = 0;
                        Bands E;
                        for (std::size_t i = range.begin(); i != range.end(); ++i) {
                          const Surfel& s = surfels[i];
                          // The front side sends: what it reflects of the lights, and its glow.
                          tracer.DirectIrradiance(s.position, s.normal, E, rays);
                          Bands B = tracer.Albedo(s.object) * E;
                          Bands Le;
                          if (tracer.Emission(FrontHit(s), Le)) B += kPiF * Le;
                          std::copy(B.data(), B.data() + nb, &radiosity[i * nb]);
                          if (translucent && scene.objects[s.object].subsurface)
                            std::copy(E.data(), E.data() + nb, &surfel_E[i * nb]);
                        }
                        total_rays += rays;
                      });
    // Only surfels that send light matter to either receiver (the occlusion
    // is not used here): a dark scene's unlit floor costs nothing. The sky
    // needs every surfel (they occlude it).
    const bool sky = tracer.sky_level() > 0;
    std::vector<Surfel> sending;
    std::vector<float> sending_B;
    if (!sky)
      for (std::size_t i = 0; i < surfels.size(); ++i) {
        bool sends = false;
        for (int b = 0; b < nb; ++b) sends = sends || radiosity[i * nb + b] > 0;
        if (!sends) continue;
        sending.push_back(surfels[i]);
        sending_B.insert(sending_B.end(), &radiosity[i * nb], &radiosity[i * nb] + nb);
      }
    const std::vector<Surfel>& senders = sky ? surfels : sending;
    const std::vector<float>& sent = sky ? radiosity : sending_B;
    const GBuffer g = RenderGBuffer(geometry, scene, geometry.time_s());
    DssOptions dss;
    dss.channels = nb;
    // With indirect visibility every surfel counts (the dark ones hide the glowing ones behind them).
    const DssResult indirect = options.indirect_visibility ? SplatBouncedZBuffer(g, camera, surfels, radiosity, dss)
                                                           : SplatDeepScreenSpace(g, camera, senders, sent, dss);
    // The media between the camera and the surfaces dim the bounce as they
    // dim the surface, and receive the surfels' light themselves.
    IntervalMap intervals;
    if (media) intervals = BuildIntervalMap(*media, g, camera, options.interval_layers);
    tbb::parallel_for(0, height, [&](int y) {
      for (int x = 0; x < width; ++x) {
        const std::size_t p = static_cast<std::size_t>(y) * width + x;
        if (g.object[p] < 0) continue;
        const Bands albedo = tracer.Albedo(g.object[p]);
        const float T = media ? intervals.T_end[p] : 1.0f;
        float* out = image.at(x, y);
        for (int b = 0; b < nb; ++b) out[b] += T * albedo[b] * indirect.irradiance[p * nb + b] / kPiF;
        if (sky && !scene.objects[g.object[p]].subsurface) {
          // Directional occlusion: the sky less what the surfels hide of it.
          const float gradient = static_cast<float>(scene.environment->gradient);
          const float unit =
              std::max(0.0f, kPiF * (1 - indirect.occlusion[p]) +
                                 gradient * (2 * kPiF / 3 * g.normal[p].y() - kPiF * indirect.occlusion_y[p]));
          for (int b = 0; b < nb; ++b) out[b] += T * albedo[b] * tracer.sky_L()[b] * unit / kPiF;
        }
      }
    });
    // Translucent objects: the lights' irradiance on their surfels, carried
    // beneath the surface by the dipole (subsurface.h) to the pixels of the
    // same object.
    if (translucent) {
      std::vector<Surfel> entering;
      std::vector<float> E_in;
      for (std::size_t i = 0; i < surfels.size(); ++i) {
        const float* E = &surfel_E[i * nb];
        if (!scene.objects[surfels[i].object].subsurface || *std::max_element(E, E + nb) <= 0) continue;
        entering.push_back(surfels[i]);
        E_in.insert(E_in.end(), E, E + nb);
      }
      // The near field of each receiver (two target surfel radii at its
      // depth) from its own irradiance in closed form; the surfels send the rest.
      const float tan_half = std::tan(static_cast<float>(scene.camera.fov_deg) * kPiF / 360.0f);
      std::vector<float> near(g.depth.size(), 0.0f);
      for (std::size_t p = 0; p < near.size(); ++p) near[p] = 2 * SurfelOptions{}.s * tan_half * g.depth[p];
      DssOptions sss_options = dss;
      sss_options.dipoles = &dipoles;
      sss_options.near_m = &near;
      const DssResult exitance = SplatDeepScreenSpace(g, camera, entering, E_in, sss_options);
      tbb::parallel_for(0, height, [&](int y) {
        std::uint64_t rays = 0;
        Bands E;
        for (int x = 0; x < width; ++x) {
          const std::size_t p = static_cast<std::size_t>(y) * width + x;
          if (g.object[p] < 0 || !scene.objects[g.object[p]].subsurface) continue;
          const float T = media ? intervals.T_end[p] : 1.0f;
          tracer.DirectIrradiance(g.position[p], g.normal[p], E, rays);
          const Dipole* d = &dipoles[static_cast<std::size_t>(g.object[p]) * nb];
          float* out = image.at(x, y);
          for (int b = 0; b < nb; ++b)
            out[b] += T *
                      (E[b] * static_cast<float>(d[b].AnnulusIntegral(0, near[p])) + exitance.irradiance[p * nb + b]) /
                      kPiF;
        }
        total_rays += rays;
      });
    }
    for (const GBuffer& layer : intervals.layer) {
      if (senders.empty()) break;
      const DssResult in_medium = SplatDeepScreenSpace(layer, camera, senders, sent, dss);
      tbb::parallel_for(0, height, [&](int y) {
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
  if (stats) stats->rays = total_rays.load();
  return image;
}

std::vector<TransportCandidate> MeasureTransportCandidates(const SceneGeometry& geometry, const CoupledSolver* solver,
                                                           const FrameOptions& base) {
  auto time_of = [&](const FrameOptions& options) {
    const auto start = std::chrono::steady_clock::now();
    RenderBands(geometry, solver, options);
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  std::vector<TransportCandidate> candidates;
  FrameOptions direct = base;
  direct.transport = Transport::kDirect;
  direct.direct_spp = 1;
  candidates.push_back({direct, 0.44, time_of(direct), "direct"});
  FrameOptions dss = direct;
  dss.transport = Transport::kDss;
  candidates.push_back({dss, 0.90, time_of(dss), "dss"});
  FrameOptions path = base;
  path.transport = Transport::kPath;
  path.spp = 1;
  const double path_1spp_s = time_of(path);
  for (const auto& [spp, ssim] :
       std::vector<std::pair<int, double>>{{4, 0.59}, {16, 0.80}, {64, 0.93}, {256, 0.965}, {1024, 0.9825}}) {
    path.spp = spp;
    candidates.push_back({path, ssim, path_1spp_s * spp, "path " + std::to_string(spp) + " spp"});
  }
  return candidates;
}

TransportChoice ChooseTransport(std::vector<TransportCandidate> candidates, double budget_s, double min_ssim) {
  PHOS_CHECK(!candidates.empty());
  TransportChoice choice;
  choice.candidates = candidates;
  const TransportCandidate* best = nullptr;
  if (budget_s > 0) {
    for (const TransportCandidate& c : candidates)
      if (c.estimated_s <= budget_s && (!best || c.expected_ssim > best->expected_ssim)) best = &c;
    if (!best) {  // nothing fits: the fastest
      choice.fits = false;
      for (const TransportCandidate& c : candidates)
        if (!best || c.estimated_s < best->estimated_s) best = &c;
    }
  } else {
    for (const TransportCandidate& c : candidates)
      if (c.expected_ssim >= min_ssim && (!best || c.estimated_s < best->estimated_s)) best = &c;
    if (!best) {  // nothing is that good: the best there is
      choice.fits = false;
      for (const TransportCandidate& c : candidates)
        if (!best || c.expected_ssim > best->expected_ssim) best = &c;
    }
  }
  choice.chosen = *best;
  return choice;
}

std::vector<double> BandToXyzWeights(const SpectralGrid& grid) {
  const int nb = grid.band_count();
  std::vector<double> w(3 * static_cast<std::size_t>(nb), 0.0);
  double y_total = 0;
  for (int b = 0; b < nb; ++b) {
    // Band averages of the matching functions (radiance is uniform inside a band).
    const Tristimulus mean = Cie1931CmfBandMean(grid.lower_nm(b), grid.upper_nm(b));
    for (int c = 0; c < 3; ++c) w[c * nb + b] = mean[c];
    y_total += w[nb + b];
  }
  for (double& v : w) v /= y_total;
  return w;
}

Image BandsToLinearSrgb(const Image& bands, const SpectralGrid& grid) {
  const int nb = grid.band_count();
  PHOS_CHECK(bands.channels == nb);
  const std::vector<double> w = BandToXyzWeights(grid);
  Image rgb(bands.width, bands.height, 3);
  const std::size_t pixels = std::size_t(bands.width) * bands.height;
  for (std::size_t p = 0; p < pixels; ++p) {
    Tristimulus xyz = {0, 0, 0};
    for (int c = 0; c < 3; ++c)
      for (int b = 0; b < nb; ++b) xyz[c] += w[c * nb + b] * bands.pixels[p * nb + b];
    const Tristimulus linear = XyzToLinearSrgb(xyz);
    for (int c = 0; c < 3; ++c) rgb.pixels[3 * p + c] = static_cast<float>(linear[c]);
  }
  return rgb;
}

namespace {

void WriteImageAtomically(const std::filesystem::path& path, const OIIO::ImageSpec& spec, OIIO::TypeDesc type,
                          const void* data) {
  WriteAtomically(path, [&](const std::filesystem::path& temporary) {
    auto out = OIIO::ImageOutput::create(temporary.string());
    if (!out) ThrowUserError(path.string(), "", "no image writer for this format: " + OIIO::geterror());
    if (!out->open(temporary.string(), spec) || !out->write_image(type, data) || !out->close())
      ThrowUserError(path.string(), "", "could not write the image: " + out->geterror());
  });
}

}  // namespace

void WriteExr(const std::filesystem::path& path, const Image& rgb, const Image& bands, const SpectralGrid& grid) {
  const int nb = bands.channels;
  OIIO::ImageSpec spec(rgb.width, rgb.height, 3 + nb, OIIO::TypeDesc::FLOAT);
  spec.channelnames = {"R", "G", "B"};
  for (int b = 0; b < nb; ++b) spec.channelnames.push_back("band" + std::to_string(b));
  spec.attribute("compression", "zip");
  std::string edges;
  for (double e : grid.edges_nm) {
    if (!edges.empty()) edges += ',';
    edges += FormatDouble(e);
  }
  spec.attribute("phos:bands_nm", edges);
  std::vector<float> data(std::size_t(rgb.width) * rgb.height * (3 + nb));
  for (std::size_t p = 0; p < std::size_t(rgb.width) * rgb.height; ++p) {
    std::copy_n(&rgb.pixels[3 * p], 3, &data[p * (3 + nb)]);
    std::copy_n(&bands.pixels[p * nb], nb, &data[p * (3 + nb) + 3]);
  }
  WriteImageAtomically(path, spec, OIIO::TypeDesc::FLOAT, data.data());
}

Image ToneMap(const Image& rgb, double exposure) {
  PHOS_CHECK(rgb.channels == 3);
  Image display(rgb.width, rgb.height, 3);
  for (std::size_t p = 0; p < rgb.pixels.size() / 3; ++p) {
    // Reinhard's global operator on luminance (Reinhard et al. 2002): a glow
    // a hundred times dimmer than the lit scene stays visible, and lit
    // highlights roll off instead of clipping. Hue is kept.
    const float* c = &rgb.pixels[3 * p];
    const double Y = std::max(0.0, exposure * LinearSrgbLuminance(c[0], c[1], c[2]));
    const double scale = exposure / (1 + Y);
    for (int k = 0; k < 3; ++k) {
      const double v = std::clamp(c[k] * scale, 0.0, 1.0);
      display.pixels[3 * p + k] = static_cast<float>(v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055);
    }
  }
  return display;
}

namespace {

void WriteDisplayPng(const std::filesystem::path& path, const Image& display) {
  std::vector<std::uint8_t> data(display.pixels.size());
  for (std::size_t i = 0; i < data.size(); ++i)
    data[i] = static_cast<std::uint8_t>(std::lround(std::clamp(display.pixels[i], 0.0f, 1.0f) * 255));
  OIIO::ImageSpec spec(display.width, display.height, display.channels, OIIO::TypeDesc::UINT8);
  WriteImageAtomically(path, spec, OIIO::TypeDesc::UINT8, data.data());
}

}  // namespace

void WritePng(const std::filesystem::path& path, const Image& rgb, double exposure) {
  WriteDisplayPng(path, ToneMap(rgb, exposure));
}

void WriteContactSheet(const std::filesystem::path& path, const std::vector<Image>& frames,
                       const std::vector<std::string>& labels, int columns) {
  PHOS_CHECK(!frames.empty() && labels.size() == frames.size() && columns > 0);
  const int pad = 4, label_height = 22;
  const int w = frames[0].width, h = frames[0].height;
  columns = std::min<int>(columns, static_cast<int>(frames.size()));
  const int rows = (static_cast<int>(frames.size()) + columns - 1) / columns;
  const int cell_w = w + pad, cell_h = h + label_height + pad;
  OIIO::ImageBuf sheet(OIIO::ImageSpec(columns * cell_w + pad, rows * cell_h + pad, 3, OIIO::TypeDesc::FLOAT));
  const float background[3] = {0.12f, 0.12f, 0.12f};
  OIIO::ImageBufAlgo::fill(sheet, background);
  for (std::size_t f = 0; f < frames.size(); ++f) {
    const int x0 = pad + static_cast<int>(f % columns) * cell_w, y0 = pad + static_cast<int>(f / columns) * cell_h;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) sheet.setpixel(x0 + x, y0 + label_height + y, frames[f].at(x, y), 3);
    // Labels need a font file; without one the sheet is still written.
    const float white[3] = {0.9f, 0.9f, 0.9f};
    OIIO::ImageBufAlgo::render_text(sheet, x0 + 2, y0 + 16, labels[f], 15,
                                    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf", white);
  }
  Image display(sheet.spec().width, sheet.spec().height, 3);
  sheet.get_pixels(OIIO::ROI::All(), OIIO::TypeDesc::FLOAT, display.pixels.data());
  WriteDisplayPng(path, display);
}

Image ReadImage(const std::filesystem::path& path) {
  auto in = OIIO::ImageInput::open(path.string());
  if (!in) ThrowUserError(path.string(), "", "cannot read the image: " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  Image image(spec.width, spec.height, spec.nchannels);
  if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, image.pixels.data()))
    ThrowUserError(path.string(), "", "cannot read the image: " + in->geterror());
  return image;
}

}  // namespace phos::render
