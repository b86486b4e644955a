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
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include "phos/render/albedo_texture.h"
#include "phos/render/bsdf.h"
#include "phos/render/dss.h"
#include "phos/render/subsurface.h"
#include "phos/render/transport_quality.h"
#include "phos/render/volume.h"
#include "phos/util/atomic_file.h"
#include "phos/util/colour.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/math.h"
#include "phos/util/progress.h"
#include "phos/util/random.h"

namespace phos::render {
namespace {

constexpr int kMaxBands = 64;

// A fixed per-pixel offset of the media's step grid: one sample per pixel
// shows noise, not banding.
float PixelJitter(int x, int y) { return InterleavedGradientNoise(x, y); }

// Veach's power heuristic (beta = 2): the weight of a sample drawn with
// solid-angle pdf p_this when the other strategy would draw it with p_other.
float PowerHeuristic(float p_this, float p_other) {
  const float a = p_this * p_this, b = p_other * p_other;
  return a + b > 0 ? a / (a + b) : 0.0f;
}

// Radiance or throughput per band, without allocation.
using Bands = Eigen::Array<float, Eigen::Dynamic, 1, 0, kMaxBands, 1>;

// Cosine-weighted direction about the unit normal n (Malley's method): a
// uniform point of the unit disk, by rejection from its square (on average
// 1.27 tries, 2.5 random numbers: cheaper than the sine and cosine of a polar
// map, which were a tenth of the path tracer's own time), lifted onto the
// hemisphere in the branchless orthonormal basis of Duff et al. 2017.
Vec3f SampleCosine(const Vec3f& n, SplitMix64& random) {
  float x, y, r2;
  do {
    x = 2 * random.UniformFloat() - 1;
    y = 2 * random.UniformFloat() - 1;
    r2 = x * x + y * y;
  } while (r2 >= 1.0f);
  const float sign = std::copysign(1.0f, n.z());
  const float a = -1.0f / (sign + n.z()), b = n.x() * n.y() * a;
  const Vec3f t(1.0f + sign * n.x() * n.x() * a, sign * b, -sign * n.x());
  const Vec3f bt(b, sign + n.y() * n.y() * a, -n.y());
  return x * t + y * bt + std::sqrt(1.0f - r2) * n;
}

// Barycentric weights (b1, b2) of a uniform point on a triangle without a
// square root (Heitz 2019, "A Low-Distortion Map Between Triangle and
// Square", as pbrt-v4's SampleUniformTriangle).
void SampleUniformTriangle(float u1, float u2, float& b1, float& b2) {
  if (u1 < u2) {
    b1 = u1 / 2;
    b2 = u2 - b1;
  } else {
    b2 = u2 / 2;
    b1 = u1 - b2;
  }
}

// The glowing triangles of this moment, for next-event estimation: chosen in
// proportion to their emitted power (texel Lp summed over bands, times area),
// in O(1) from an alias table (Walker 1977; Vose 1991's construction, as
// pbrt-v4's AliasTable): a binary search of a CDF over thousands of triangles
// was a tenth of the path tracer's time.
struct EmitterDistribution {
  // Everything a sample needs of its triangle in one cache line: sampling
  // walked from the entry to the mesh's indices, its vertices and the atlas's
  // per-triangle tables, a cache miss at each step.
  struct alignas(64) Entry {
    Vec3f v0, e1, e2;  // the triangle: v0 + b1 e1 + b2 e2
    Vec3f normal;      // front
    float area_pdf;    // probability per m^2 of a point on it
    std::uint32_t triangle;
    std::uint32_t first_texel;  // auto atlas: its first texel
    std::int16_t slot;          // the object's texel slot
    std::uint16_t m;            // auto atlas: subdivisions (0: UV atlas, ask TexelOf)
    std::size_t Texel(const TexelAtlas& atlas, float b1, float b2) const {
      return m > 0 ? first_texel + static_cast<std::size_t>(SubTriangleIndex(m, b1, b2))
                   : atlas.TexelOf(slot, static_cast<int>(triangle), b1, b2);
    }
  };
  struct Column {
    float keep;  // probability of keeping this column's entry over its alias
    std::uint32_t alias;
  };
  std::vector<Entry> entries;
  std::vector<Column> columns;
  std::vector<std::vector<float>> pdf;  // per object, per triangle: probability of choosing it, per m^2 of it
  std::vector<std::uint8_t> two_sided;  // per texel slot: the object glows from both faces
  bool empty() const { return entries.empty(); }

  EmitterDistribution(const SceneGeometry& geometry, const CoupledSolver* solver) {
    pdf.resize(geometry.object_count());
    if (!solver) return;
    const TexelAtlas& atlas = solver->atlas();
    PHOS_CHECK(atlas.objects().size() <= 32767);
    for (const TexelAtlas::ObjectTexels& texels : atlas.objects())
      two_sided.push_back(geometry.scene().objects[texels.object].two_sided);
    std::vector<double> power;
    double total = 0;
    for (std::size_t s = 0; s < atlas.objects().size(); ++s) {
      const TexelAtlas::ObjectTexels& texels = atlas.objects()[s];
      const int object = texels.object;
      const int triangles = geometry.triangle_count(object);
      // Mean Lp (summed over bands) of each triangle's texels.
      std::vector<double> sum(triangles, 0.0);
      std::vector<std::size_t> count(triangles, 0);
      const std::vector<int>& bands = solver->emission_bands(static_cast<int>(s));
      atlas.ForEachTexel(static_cast<int>(s), [&](std::size_t k, int t, float, float) {
        for (int b : bands) sum[t] += solver->Lp(static_cast<int>(s), b, k);
        ++count[t];
      });
      for (int t = 0; t < triangles; ++t) {
        const float area = geometry.Area(object, t);
        const double p = count[t] ? sum[t] / static_cast<double>(count[t]) * area : 0.0;
        if (!(p > 0)) continue;
        Entry entry;
        entry.v0 = geometry.Vertex(object, t, 0);
        entry.e1 = geometry.Vertex(object, t, 1) - entry.v0;
        entry.e2 = geometry.Vertex(object, t, 2) - entry.v0;
        entry.normal = geometry.FrontNormal(object, t);
        entry.area_pdf = area;  // divided by the total power below
        entry.triangle = static_cast<std::uint32_t>(t);
        entry.slot = static_cast<std::int16_t>(s);
        entry.m = texels.uv() ? 0 : texels.m[t];
        entry.first_texel = texels.uv() ? 0 : texels.first[t];
        entries.push_back(entry);
        power.push_back(p);
        total += p;
      }
    }
    if (entries.empty()) return;
    for (std::size_t e = 0; e < entries.size(); ++e) {
      Entry& entry = entries[e];
      const float area = entry.area_pdf;
      entry.area_pdf = static_cast<float>(power[e] / total / area);
      const int object = atlas.objects()[entry.slot].object;
      auto& object_pdf = pdf[object];
      if (object_pdf.empty()) object_pdf.assign(geometry.triangle_count(object), 0.0f);
      object_pdf[entry.triangle] = entry.area_pdf;
    }
    BuildAliasTable(power, total);
  }
  // Vose: entries scaled so the mean is 1; each under-full one is topped up
  // by an over-full one, which becomes its alias.
  void BuildAliasTable(const std::vector<double>& power, double total) {
    const std::size_t n = power.size();
    std::vector<double> scaled(n);
    std::vector<std::uint32_t> small, large;
    for (std::size_t e = 0; e < n; ++e) {
      scaled[e] = power[e] / total * static_cast<double>(n);
      (scaled[e] < 1.0 ? small : large).push_back(static_cast<std::uint32_t>(e));
    }
    columns.resize(n);
    for (std::size_t e = 0; e < n; ++e) columns[e] = {1.0f, static_cast<std::uint32_t>(e)};
    while (!small.empty() && !large.empty()) {
      const std::uint32_t under = small.back(), over = large.back();
      small.pop_back();
      columns[under] = {static_cast<float>(scaled[under]), over};
      scaled[over] -= 1.0 - scaled[under];
      if (scaled[over] < 1.0) {
        large.pop_back();
        small.push_back(over);
      }
    }
    // What remains is full up to rounding: kept with probability 1.
  }
  // Probability per unit area of sampling a point of (object, triangle).
  float AreaPdf(int object, int triangle) const {
    const auto& p = pdf[object];
    return p.empty() ? 0.0f : p[triangle];
  }
  // One 64-bit random word: the high half picks a column (Lemire's
  // multiply-shift), the low half decides between it and its alias.
  const Entry& Pick(std::uint64_t random) const {
    const std::size_t column = static_cast<std::size_t>(((random >> 32) * entries.size()) >> 32);
    const float u = static_cast<float>(random & 0xFFFFFFu) * (1.0f / 16777216.0f);
    const Column& c = columns[column];
    return entries[u < c.keep ? column : c.alias];
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
    if (options.transport == Transport::kPath && solver_) CopyGlowByTexel();
    textures_ = geometry.albedo_textures();
    for (const Object& object : scene_.objects) {
      Bands a(nb_);
      for (int b = 0; b < nb_; ++b) a[b] = static_cast<float>(object.albedo[b]);
      albedo_.push_back(a);
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

  // The texel-major glow of a hit on a phosphor's glowing side (path
  // transport): its emission bands and their Lp, prefetched; empty elsewhere.
  struct GlowTexel {
    const std::vector<int>* bands = nullptr;
    const float* Lp = nullptr;
    explicit operator bool() const { return Lp != nullptr; }
  };
  GlowTexel GlowAt(const Hit& hit) const {
    if (glow_by_texel_.empty() || !ShowsGlow(hit)) return {};
    const int slot = solver_->atlas().SlotOf(hit.object);
    if (slot < 0) return {};
    return GlowAt(slot, solver_->atlas().TexelOf(slot, hit.triangle, hit.b1, hit.b2));
  }
  GlowTexel GlowAt(int slot, std::size_t texel) const {
    const GlowByTexel& glow = glow_by_texel_[slot];
    if (glow.bands.empty() || texel == TexelAtlas::kNoTexel) return {};
    const float* Lp = &glow.Lp[texel * glow.bands.size()];
    __builtin_prefetch(Lp);
    return {&glow.bands, Lp};
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
      float unit = UnitIrradiance(geometry_, light.pose, p, n_s, &rays);
      // Media between the point and the light shadow it (a cloud on the floor;
      // scenes with media have no area lights, see scene.cpp).
      if (unit > 0 && media_) unit *= Transmittance(light.pose, p);
      if (unit > 0) E += light.E * unit;
    }
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

  // An object's gloss, or null for a Lambertian one.
  const Gloss* GlossAt(int object) const {
    const auto& gloss = scene_.objects[object].gloss;
    return gloss ? &*gloss : nullptr;
  }

  // A glossy surface's reflection in direct transport (docs/render.md,
  // "Glossy surfaces"): the delta lights (point, spot, directional, sheet)
  // through the whole BSDF toward each; area lights and the sky by their
  // irradiance times the directional albedo over pi (a uniform sky's
  // reflection exactly; an area light's as if it were spread over the sky).
  Bands GlossyReflection(const Gloss& gloss, const Bands& albedo, const Vec3f& p, const Vec3f& n_s, const Vec3f& wo,
                         std::uint64_t& rays) const {
    const GlossyBsdf bsdf(gloss, albedo.data(), nb_);
    Bands L = Bands::Zero(nb_), f(nb_), rho(nb_), E_diffuse = Bands::Zero(nb_);
    bool spread = sky_level_ > 0 && options_.transport != Transport::kDss;
    if (spread)
      E_diffuse += sky_L_ * UnitSkyIrradiance(geometry_, *scene_.environment, p, n_s, options_.sky_rays, PointSeed(p), &rays);
    for (const LitLight& light : lights_) {
      if (light.pose.area()) {
        const float unit = UnitIrradiance(geometry_, light.pose, p, n_s, &rays);
        if (unit > 0) E_diffuse += light.E * unit;
        spread = spread || unit > 0;
        continue;
      }
      const LightRay ray = RayToLight(geometry_, light.pose, p, n_s);
      if (!(ray.unit > 0)) continue;
      ++rays;
      if (geometry_.Occluded(ray.origin, ray.direction, ray.t_far)) continue;
      float unit = ray.unit;
      if (media_) unit *= Transmittance(light.pose, p);
      bsdf.Eval(n_s, wo, ray.direction, f.data());
      L += f * light.E * unit;
    }
    if (spread) {
      bsdf.DirectionalAlbedo(n_s.dot(wo), rho.data());
      L += rho * E_diffuse / kPiF;
    }
    return L;
  }

  // Converted to float bands once per frame, not at every hit.
  const Bands& Albedo(int object) const { return albedo_[object]; }

  // A camera ray's footprint (pbrt's ray differentials): the directions
  // through the next pixel right and down. Zero: none, a point lookup (the
  // path tracer's bounces, the dss surfels).
  struct RayDifferential {
    Vec3f dx = Vec3f::Zero(), dy = Vec3f::Zero();
  };
  // Whether any object is textured: only then do camera rays carry differentials.
  bool textured() const { return textures_ != nullptr; }

  // The albedo at a hit: the object's constant bands, or a textured object's
  // texture filtered over the footprint of the ray from `origin`, written to
  // `texture_albedo`. Untextured objects skip the lookup and cost what they did.
  const Bands& AlbedoAt(const Hit& hit, const Vec3f& origin, const RayDifferential& differential,
                        Bands& texture_albedo) const {
    if (!textures_ || !textures_->textured(hit.object)) return albedo_[hit.object];
    texture_albedo.resize(nb_);
    textures_->Albedo(geometry_, hit, OffsetOnHitPlane(hit, origin, differential.dx),
                      OffsetOnHitPlane(hit, origin, differential.dy), texture_albedo.data());
    return texture_albedo;
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

  Bands Direct(const Vec3f& origin, const Vec3f& direction, const RayDifferential& differential, float jitter,
               std::uint64_t& rays) const {
    Bands L = Bands::Zero(nb_);
    ++rays;
    const Hit hit = geometry_.Intersect(origin, direction);
    Bands Lm = Bands::Zero(nb_);
    const float T = Media(origin, direction, hit, jitter, Lm);
    AddAreaLightsSeen(origin, direction, hit ? hit.distance : 1e30f, Bands::Ones(nb_), Lm,
                      [](const LightPose&, const Vec3f&, float) { return 1.0f; });
    if (!hit) return sky_level_ > 0 ? Bands(Lm + T * sky_L_ * scene_.environment->Shape(direction.y())) : Lm;
    AddEmission(hit, L);
    if (const Bands* Le = EmitterAt(hit)) L += *Le;
    // A translucent object under dss: its reflection comes from the dipole
    // splat instead (RenderBands).
    if (options_.transport == Transport::kDss && scene_.objects[hit.object].subsurface) return Lm + T * L;
    Bands E;
    const Vec3f n_s = hit.front ? hit.normal : Vec3f(-hit.normal);
    Bands texture_albedo;
    const Bands& albedo = AlbedoAt(hit, origin, differential, texture_albedo);
    if (const Gloss* gloss = GlossAt(hit.object)) {
      L += GlossyReflection(*gloss, albedo, hit.position, n_s, -direction, rays);
      return Lm + T * L;
    }
    DirectIrradiance(hit.position, n_s, E, rays, options_.transport != Transport::kDss);
    L += albedo * E / kPiF;  // Lambertian reflection (Eq. 8.2's reflected term)
    return Lm + T * L;
  }

  // A path of the path tracer, one per pixel sample in flight.
  struct PathLane {
    Vec3f origin, direction;
    RayDifferential differential;  // the camera ray's; bounces have none
    Bands L, beta;
    const Bands* albedo = nullptr;  // at this bounce's hit: the object's, or texture_albedo
    Bands texture_albedo;
    float bsdf_pdf = 0;  // solid-angle pdf of the direction that led here (0: camera ray)
    SplitMix64* random = nullptr;
    // This bounce: the hit, the shading normal, the next ray's origin and the
    // shadow ray to a point on a glowing triangle (if glow_there).
    Hit hit;
    Vec3f n_s, origin_s, wi;
    float emitter_distance = 0, emitter_scale = 0;
    const Gloss* gloss = nullptr;  // a glossy hit's; null: Lambertian
    Bands glow_f_cos;              // glossy: f cos toward the glowing point (emitter_scale then w / p_light)
    GlowTexel glow_there;
    GlowTexel glow_here;
    bool scatters = false;
    const EmitterDistribution::Entry* emitter = nullptr;  // the glowing triangle to sample
    void Start(const Vec3f& camera, const Vec3f& d, const RayDifferential& footprint, SplitMix64& stream, int nb) {
      origin = camera;
      direction = d;
      differential = footprint;
      L = Bands::Zero(nb);
      beta = Bands::Ones(nb);
      bsdf_pdf = 0;
      random = &stream;
    }
  };

  // A lane's shadow ray toward one of the lights (next-event estimation).
  struct LightShadowRay {
    int lane, light;
    LightRay ray;
  };
  // A thread's lanes and the lists of one bounce, kept from row to row: a
  // lane is 1.4 KB (four Bands of kMaxBands), and allocating and zeroing 256
  // of them for every row was 2.5% of a path-traced frame (perf, bench_render
  // --benchmark_filter=PathFrameDark1spp).
  struct Wavefront {
    std::vector<PathLane> lanes;
    std::vector<int> live, scattering, shadowed;
    std::vector<LightShadowRay> light_rays;
    std::vector<SceneGeometry::RayQuery> queries;
    std::vector<Hit> hits;
    std::vector<char> blocked;
  };

  // Traces every lane's path to its end, all lanes a bounce at a time (a
  // wavefront, as in Laine, Karras and Aila 2013, "Megakernels Considered
  // Harmful"): the closest hits of every live path, then their shading, then
  // their shadow rays, then their next directions. Traced one path at a time,
  // Embree's traversal and the shading evicted each other from the caches
  // and branch predictors at every ray: the path tracer took 1.8 to 2x the
  // time of bare Embree calls on its own rays (bench_render,
  // BM_PathAgainstBareEmbree). Each lane draws from its own stream in the
  // order a lone path would, so the result is the same as path by path.
  void TracePaths(Wavefront& wave, std::uint64_t& rays) const {
    std::vector<PathLane>& lanes = wave.lanes;
    std::vector<int>& live = wave.live;
    std::vector<int>& scattering = wave.scattering;
    std::vector<int>& shadowed = wave.shadowed;
    std::vector<LightShadowRay>& light_rays = wave.light_rays;
    std::vector<SceneGeometry::RayQuery>& queries = wave.queries;
    std::vector<Hit>& hits = wave.hits;
    std::vector<char>& blocked = wave.blocked;
    live.resize(lanes.size());
    for (std::size_t i = 0; i < lanes.size(); ++i) live[i] = static_cast<int>(i);
    for (int depth = 0; depth < options_.max_depth && !live.empty(); ++depth) {
      queries.clear();
      for (int i : live) queries.push_back({lanes[i].origin, lanes[i].direction});
      hits.resize(queries.size());
      geometry_.IntersectMany(queries.data(), queries.size(), hits.data(), /*coherent=*/depth == 0);
      for (std::size_t k = 0; k < live.size(); ++k) lanes[live[k]].hit = hits[k];
      rays += live.size();
      scattering.clear();
      shadowed.clear();
      light_rays.clear();
      std::size_t kept = 0;
      for (int i : live)
        if (BeginVertex(lanes[i], depth)) live[kept++] = i;
      live.resize(kept);
      for (int i : live) {
        if (!ShadeVertex(lanes[i], i, depth, light_rays)) continue;
        scattering.push_back(i);
        if (lanes[i].glow_there) shadowed.push_back(i);
      }
      // The shadow rays: to the glowing points, then to the lights.
      queries.clear();
      for (int i : shadowed) {
        const PathLane& lane = lanes[i];
        queries.push_back({lane.origin_s, lane.wi, lane.emitter_distance * (1 - 1e-4f) - 2 * geometry_.ray_epsilon()});
      }
      for (const LightShadowRay& shadow : light_rays)
        queries.push_back({shadow.ray.origin, shadow.ray.direction, shadow.ray.t_far});
      blocked.resize(queries.size());
      geometry_.OccludedMany(queries.data(), queries.size(), reinterpret_cast<bool*>(blocked.data()));
      rays += queries.size();
      // The glowing points, where nothing lies between.
      for (std::size_t k = 0; k < shadowed.size(); ++k) {
        if (blocked[k]) continue;
        PathLane& lane = lanes[shadowed[k]];
        const Bands& albedo = lane.gloss ? lane.glow_f_cos : *lane.albedo;  // glossy: f cos, else albedo (pi folded in)
        for (std::size_t c = 0; c < lane.glow_there.bands->size(); ++c) {
          const int b = (*lane.glow_there.bands)[c];
          lane.L[b] += lane.beta[b] * albedo[b] * lane.glow_there.Lp[c] * lane.emitter_scale;
        }
      }
      // The lights, where nothing (and no medium) lies between.
      for (std::size_t k = 0; k < light_rays.size(); ++k) {
        if (blocked[shadowed.size() + k]) continue;
        const LightShadowRay& shadow = light_rays[k];
        PathLane& lane = lanes[shadow.lane];
        const LitLight& light = lights_[shadow.light];
        float unit = shadow.ray.unit;
        if (media_) unit *= Transmittance(light.pose, lane.hit.position);
        if (lane.gloss) {
          Bands f(nb_);
          GlossyBsdf(*lane.gloss, lane.albedo->data(), nb_).Eval(lane.n_s, -lane.direction, shadow.ray.direction, f.data());
          lane.L += lane.beta * f * light.E * unit;
        } else {
          lane.L += lane.beta * *lane.albedo * light.E * (unit * kInvPiF);
        }
      }
      live.clear();
      for (int i : scattering)
        if (ContinuePath(lanes[i], depth)) live.push_back(i);
    }
  }

  // At a lane's hit: the media of a camera ray, the sky on a miss, the glow
  // found there (MIS-weighted against light sampling), next-event estimation
  // of the lights, and the point on a glowing triangle its shadow ray will
  // test. False: the path ends here (a miss, or a surface that reflects nothing).
  // The first half of a vertex, for every live lane before any finishes:
  // what needs no memory beyond the hit (the media of a camera ray, the sky
  // on a miss), and the addresses of what does (the glow here, the glowing
  // triangle to sample), prefetched so that the misses of all lanes overlap.
  // False: the path ends at a miss.
  bool BeginVertex(PathLane& lane, int depth) const {
    const Hit& hit = lane.hit;
    SplitMix64& random = *lane.random;
    if (depth == 0 && media_) {
      // The camera ray's media (single scattering; later bounces pass
      // through them unattenuated, see volume.h).
      Bands Lm = Bands::Zero(nb_);
      lane.beta *= Media(lane.origin, lane.direction, hit, random.UniformFloat(), Lm);
      lane.L += Lm;
    }
    // The area lights this ray crosses: seen by the camera, or found by a
    // bounce and weighted against their next-event estimation (power
    // heuristic, p_light = d^2 / (cos_light A)).
    if (!area_lights_.empty())
      AddAreaLightsSeen(lane.origin, lane.direction, hit ? hit.distance : 1e30f, lane.beta, lane.L,
                        [&](const LightPose& pose, const Vec3f& direction, float t) {
                          if (depth == 0) return 1.0f;
                          const float p_light = t * t / (-pose.normal.dot(direction) * pose.area_m2);
                          return PowerHeuristic(lane.bsdf_pdf, p_light);
                        });
    // An emissive object's front, likewise.
    if (const Bands* Le = hit ? EmitterAt(hit) : nullptr) {
      float weight = 1;
      if (depth > 0) {
        const float cos_light = -hit.normal.dot(lane.direction);
        const float p_light = hit.distance * hit.distance / (cos_light * geometry_.EmitterArea(hit.object));
        weight = PowerHeuristic(lane.bsdf_pdf, p_light);
      }
      lane.L += lane.beta * *Le * weight;
    }
    if (!hit) {
      // The sky, found by the camera ray or a bounce (cosine sampling; no
      // light sampling for it, so no weight).
      if (sky_level_ > 0) lane.L += lane.beta * sky_L_ * scene_.environment->Shape(lane.direction.y());
      return false;
    }
    lane.glow_here = GlowAt(hit);
    // Textures are filtered over the camera ray's footprint; bounces look up
    // a point (zero derivatives: their footprint is the BSDF's, not a pixel's).
    lane.albedo = &AlbedoAt(hit, lane.origin, depth == 0 ? lane.differential : RayDifferential{}, lane.texture_albedo);
    lane.gloss = GlossAt(hit.object);
    lane.scatters = lane.gloss || lane.albedo->maxCoeff() > 0;  // a glossy coat reflects on black too
    lane.emitter = nullptr;
    if (lane.scatters && !emitters_.empty()) {
      lane.emitter = &emitters_.Pick(random.Next());
      __builtin_prefetch(lane.emitter);
    }
    return true;
  }

  // The second half (after BeginVertex on every lane): the shading normal,
  // the point on the glowing triangle and its MIS weight, the lights' shadow
  // rays, and the glow found here. False: the surface reflects nothing.
  bool ShadeVertex(PathLane& lane, int lane_index, int depth, std::vector<LightShadowRay>& light_rays) const {
    const Hit& hit = lane.hit;
    SplitMix64& random = *lane.random;
    lane.n_s = hit.front ? hit.normal : Vec3f(-hit.normal);
    const Vec3f& n_s = lane.n_s;
    const GlowTexel glow_here = lane.glow_here;
    const bool scatters = lane.scatters;
    lane.origin_s = hit.position + geometry_.ray_epsilon() * n_s;
    lane.glow_there = {};
    if (lane.emitter) {
      const auto& entry = *lane.emitter;
      float b1, b2;
      const float u1 = random.UniformFloat();
      SampleUniformTriangle(u1, random.UniformFloat(), b1, b2);
      const Vec3f q = entry.v0 + b1 * entry.e1 + b2 * entry.e2;
      lane.wi = q - hit.position;
      const float distance2 = lane.wi.squaredNorm();
      lane.emitter_distance = std::sqrt(distance2);
      lane.wi *= 1.0f / lane.emitter_distance;
      const float cos_s = n_s.dot(lane.wi), cos_front = -entry.normal.dot(lane.wi);
      const float cos_l = emitters_.two_sided[entry.slot] ? std::abs(cos_front) : cos_front;  // the side facing us
      if (cos_s > 0 && cos_l > 0) {
        lane.glow_there = GlowAt(entry.slot, entry.Texel(solver_->atlas(), b1, b2));
        // f cos / p_light with MIS (power heuristic) against the BSDF's
        // cosine sampling, f = albedo / pi: with p_light = a d^2 / cos_l
        // (a: the area pdf) and p_bsdf = cos_s / pi, the weight over
        // p_light is a d^2 cos_l / ((a d^2)^2 + p_bsdf^2 cos_l^2): one division.
        const float area_term = entry.area_pdf * distance2;
        if (lane.gloss) {  // f cos kept per band; emitter_scale the weight over p_light
          const GlossyBsdf bsdf(*lane.gloss, lane.albedo->data(), nb_);
          const Vec3f wo = -lane.direction;
          const float p_bsdf = bsdf.Pdf(n_s, wo, lane.wi);
          lane.glow_f_cos.resize(nb_);
          bsdf.Eval(n_s, wo, lane.wi, lane.glow_f_cos.data());
          lane.glow_f_cos *= cos_s;
          lane.emitter_scale = area_term * cos_l / (area_term * area_term + p_bsdf * p_bsdf * cos_l * cos_l);
        } else {
          const float p_bsdf = cos_s * kInvPiF;
          lane.emitter_scale = p_bsdf * area_term * cos_l / (area_term * area_term + p_bsdf * p_bsdf * cos_l * cos_l);
        }
      }
    }
    // Next-event estimation for the lights, when any is on: their shadow
    // rays are cast with the batch's (TracePaths). A delta light has no MIS;
    // an area light's point is weighted against the BSDF's finding it.
    if (scatters)
      for (std::size_t l = 0; l < lights_.size(); ++l) {
        const LightPose& pose = lights_[l].pose;
        LightRay ray;
        if (pose.area()) {
          const float u1 = random.UniformFloat();
          ray = RayToLight(geometry_, pose, hit.position, n_s, u1, random.UniformFloat());
          const float p_bsdf = !(ray.unit > 0) ? 0.0f
                               : lane.gloss ? GlossyBsdf(*lane.gloss, lane.albedo->data(), nb_)
                                                  .Pdf(n_s, -lane.direction, ray.direction)
                                            : n_s.dot(ray.direction) * kInvPiF;
          ray.unit *= PowerHeuristic(ray.area_pdf, p_bsdf);
        } else {
          ray = RayToLight(geometry_, pose, hit.position, n_s);
        }
        if (ray.unit > 0) light_rays.push_back({lane_index, static_cast<int>(l), ray});
      }
    // Emission found by the BSDF sample, weighted against light sampling.
    if (glow_here) {
      float weight = 1;
      if (depth > 0) {
        // p_bsdf^2 / (p_bsdf^2 + p_light^2), p_light = a d^2 / cos: one division.
        const float cos_light = -hit.normal.dot(lane.direction);
        const float area_term = emitters_.AreaPdf(hit.object, hit.triangle) * hit.distance * hit.distance;
        const float bsdf_cos = lane.bsdf_pdf * cos_light;
        weight = bsdf_cos * bsdf_cos / (bsdf_cos * bsdf_cos + area_term * area_term);
      }
      for (std::size_t k = 0; k < glow_here.bands->size(); ++k) {
        const int b = (*glow_here.bands)[k];
        lane.L[b] += lane.beta[b] * glow_here.Lp[k] * weight;
      }
    }
    return scatters;
  }

  // The next direction: cosine sampling of the diffuse BSDF (f cos / pdf =
  // albedo), then Russian roulette from the fourth bounce. False: it ends.
  bool ContinuePath(PathLane& lane, int depth) const {
    SplitMix64& random = *lane.random;
    if (lane.gloss) {
      // The glossy BSDF's own sampling: beta *= f cos / pdf.
      const GlossyBsdf bsdf(*lane.gloss, lane.albedo->data(), nb_);
      const Vec3f wo = -lane.direction;
      const float u0 = random.UniformFloat(), u1 = random.UniformFloat(), u2 = random.UniformFloat();
      Vec3f wi;
      float pdf;
      if (!bsdf.Sample(lane.n_s, wo, u0, u1, u2, &wi, &pdf)) return false;
      Bands f(nb_);
      bsdf.Eval(lane.n_s, wo, wi, f.data());
      lane.beta *= f * (lane.n_s.dot(wi) / pdf);
      lane.direction = wi;
      lane.bsdf_pdf = pdf;
      lane.origin = lane.origin_s;
    } else {
      lane.direction = SampleCosine(lane.n_s, random);
      lane.bsdf_pdf = lane.n_s.dot(lane.direction) * kInvPiF;
      lane.origin = lane.origin_s;
      lane.beta *= *lane.albedo;
    }
    if (depth >= 3) {  // Russian roulette keeps the estimate unbiased
      const float survive = std::min(1.0f, lane.beta.maxCoeff());
      if (random.UniformFloat() >= survive) return false;
      lane.beta /= survive;
    }
    return true;
  }

 private:
  struct LitLight {
    LightPose pose;
    Bands E;
  };
  // The solver keeps Lp band-major ([band][texel], for its batch kernel), so
  // one texel's bands lie a texel count apart: a cache miss per band for
  // every path vertex that meets or samples a glow. The path tracer reads a
  // texel-major copy made once per frame instead.
  struct GlowByTexel {
    std::vector<int> bands;  // the emission bands
    std::vector<float> Lp;   // [texel * bands.size() + i]
  };
  void CopyGlowByTexel() {
    const TexelAtlas& atlas = solver_->atlas();
    glow_by_texel_.resize(atlas.objects().size());
    for (std::size_t s = 0; s < atlas.objects().size(); ++s) {
      const int slot = static_cast<int>(s);
      GlowByTexel& glow = glow_by_texel_[s];
      glow.bands = solver_->emission_bands(slot);
      const std::size_t n = atlas.objects()[s].count, nb = glow.bands.size();
      glow.Lp.resize(n * nb);
      for (std::size_t i = 0; i < nb; ++i)
        for (std::size_t k = 0; k < n; ++k)  // a masked texel glows by the share its paint covers
          glow.Lp[k * nb + i] = atlas.Coverage(slot, k) * solver_->Lp(slot, glow.bands[i], k);
    }
  }
  std::vector<GlowByTexel> glow_by_texel_;  // per slot; path transport only
  const SceneGeometry& geometry_;
  const Scene& scene_;
  const CoupledSolver* solver_;
  const VolumeMedia* media_;
  FrameOptions options_;
  int nb_;
  EmitterDistribution emitters_;
  std::vector<LitLight> lights_;
  std::vector<LitLight> area_lights_;  // the quads and disks of lights_, which rays meet by HitAreaLight
  std::vector<int> emitter_of_object_;  // per object: its emissive light in lights_, or -1 (empty: none)
  std::vector<Bands> albedo_;  // per object
  const AlbedoTextures* textures_ = nullptr;
  float sky_level_ = 0;        // the sky's level now (0: none)
  Bands sky_L_;                // its band radiance times the level
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
  // Each pixel draws from a stream of its own (seed, frame, pixel), so a
  // frame is the same on any number of threads and in any range of frames.
  auto pixel_stream = [&](int x, int y) {
    return SplitMix64((std::uint64_t(options.seed) << 40) ^ options.frame * 0x9E3779B97F4A7C15ull ^
                      (std::uint64_t(y) * std::uint64_t(width) + x) * 0x2545F4914F6CDD1Dull);
  };
  // The rays through the next pixel right and down, for filtering textures;
  // none when nothing is textured (no cost there).
  auto differential = [&](float px, float py) {
    Tracer::RayDifferential d;
    if (tracer.textured()) {
      d.dx = camera.Direction(px + 1, py);
      d.dy = camera.Direction(px, py + 1);
    }
    return d;
  };
  // Path transport: each thread's row state, allocated once per frame.
  struct PathRow {
    std::vector<SplitMix64> streams;
    std::vector<Bands> sums;
    Tracer::Wavefront wave;
  };
  tbb::enumerable_thread_specific<PathRow> path_rows;
  tbb::parallel_for(0, height, [&](int y) {
    std::uint64_t rays = 0;
    if (options.transport == Transport::kPath) {
      // A row's pixels trace their s-th samples together (Tracer::TracePaths),
      // in the thread's wavefront.
      PathRow& row = path_rows.local();
      std::vector<SplitMix64>& streams = row.streams;
      streams.clear();
      for (int x = 0; x < width; ++x) streams.push_back(pixel_stream(x, y));
      std::vector<Bands>& sums = row.sums;
      sums.assign(width, Bands::Zero(nb));
      // Pixels of a row in groups of 256: enough rays per stream call for
      // Embree to fill its packets (64 measured slower), few enough lanes for
      // the L2 cache (a whole row of 512 measured slower).
      constexpr int kLanes = 256;
      std::vector<Tracer::PathLane>& lanes = row.wave.lanes;
      for (int x0 = 0; x0 < width; x0 += kLanes) {
        const int count = std::min(kLanes, width - x0);
        lanes.resize(count);
        for (int s = 0; s < spp; ++s) {
          for (int k = 0; k < count; ++k) {
            // One centred sample when there is one; jittered otherwise.
            const int x = x0 + k;
            SplitMix64& random = streams[x];
            const float jx = spp == 1 ? 0.5f : random.UniformFloat(), jy = spp == 1 ? 0.5f : random.UniformFloat();
            lanes[k].Start(camera.origin(), camera.Direction(static_cast<float>(x) + jx, static_cast<float>(y) + jy),
                           differential(static_cast<float>(x) + jx, static_cast<float>(y) + jy), random, nb);
          }
          tracer.TracePaths(row.wave, rays);
          for (int k = 0; k < count; ++k) sums[x0 + k] += lanes[k].L;
        }
      }
      for (int x = 0; x < width; ++x) {
        sums[x] /= static_cast<float>(spp);
        std::copy(sums[x].data(), sums[x].data() + nb, image.at(x, y));
      }
    } else {
      for (int x = 0; x < width; ++x) {
        SplitMix64 random = pixel_stream(x, y);
        Bands sum = Bands::Zero(nb);
        for (int s = 0; s < spp; ++s) {
          const float jx = spp == 1 ? 0.5f : random.UniformFloat(), jy = spp == 1 ? 0.5f : random.UniformFloat();
          const float px = static_cast<float>(x) + jx, py = static_cast<float>(y) + jy;
          sum += tracer.Direct(camera.origin(), camera.Direction(px, py), differential(px, py),
                               spp == 1 ? PixelJitter(x, y) : random.UniformFloat(), rays);
        }
        sum /= static_cast<float>(spp);
        std::copy(sum.data(), sum.data() + nb, image.at(x, y));
      }
    }
    total_rays += rays;
    if (options.progress_rows) options.progress_rows->Advance();
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
                        Bands E, texture_albedo;
                        for (std::size_t i = range.begin(); i != range.end(); ++i) {
                          const Surfel& s = surfels[i];
                          // The front side sends: what it reflects of the lights, and its glow
                          // (a textured surfel's albedo at its centre: a point lookup).
                          tracer.DirectIrradiance(s.position, s.normal, E, rays);
                          Bands B = tracer.AlbedoAt(FrontHit(s), s.position, {}, texture_albedo) * E;
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
      Bands texture_albedo;
      for (int x = 0; x < width; ++x) {
        const std::size_t p = static_cast<std::size_t>(y) * width + x;
        if (g.object[p] < 0) continue;
        Hit hit;  // the G-buffer's pixel, as the direct pass found it
        hit.object = g.object[p];
        hit.triangle = g.triangle[p];
        hit.b1 = g.b1[p];
        hit.b2 = g.b2[p];
        hit.position = g.position[p];
        hit.normal = g.normal[p];
        const Bands& albedo = tracer.AlbedoAt(hit, camera.origin(), differential(x + 0.5f, y + 0.5f), texture_albedo);
        const float T = media ? intervals.T_end[p] : 1.0f;
        float* out = image.at(x, y);
        for (int b = 0; b < nb; ++b) out[b] += T * albedo[b] * indirect.irradiance[p * nb + b] / kPiF;
        if (sky && !scene.objects[g.object[p]].subsurface) {
          // Directional occlusion: the sky less what the surfels hide of it.
          const float gradient = static_cast<float>(scene.environment->gradient);
          const float unit =
              SkyIrradianceFromOcclusion(indirect.occlusion[p], indirect.occlusion_y[p], g.normal[p].y(), gradient);
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
      const std::vector<float> near =
          SubsurfaceNearField(g, SurfelOptions{}.s, static_cast<float>(scene.camera.fov_deg));
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
          for (int b = 0; b < nb; ++b) out[b] += T * d[b].Exitance(E[b], near[p], exitance.irradiance[p * nb + b]) / kPiF;
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
  const TransportQuality& quality = MeasuredTransportQuality();
  std::vector<TransportCandidate> candidates;
  FrameOptions direct = base;
  direct.transport = Transport::kDirect;
  direct.direct_spp = 1;
  candidates.push_back({direct, quality.direct_ssim, time_of(direct), "direct"});
  FrameOptions dss = direct;
  dss.transport = Transport::kDss;
  candidates.push_back({dss, quality.dss_ssim, time_of(dss), "dss"});
  FrameOptions path = base;
  path.transport = Transport::kPath;
  path.spp = 1;
  const double path_1spp_s = time_of(path);
  for (int spp : {4, 16, 64, 256, 1024}) {
    path.spp = spp;
    candidates.push_back({path, quality.PathSsim(spp), path_1spp_s * spp, "path " + std::to_string(spp) + " spp"});
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
