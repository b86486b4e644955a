#pragma once
// The scene's geometry in Embree 3 at one moment, and the automatic texel
// atlas that carries the phosphors' states (Sec. 8.5).
//
// Texels: every triangle of a phosphorescent object is split into m x m
// congruent sub-triangles (m from the texel size), and each sub-triangle is
// one texel. A texel is addressed by barycentric coordinates, so it moves
// with its object for free, needs no UV map, and its lookup from a ray hit is
// O(1) arithmetic.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "phos/render/scene.h"
#include "phos/util/large_table.h"

struct RTCSceneTy;  // Embree 3's scene handle (RTCScene), for benchmarks that call Embree directly

namespace phos::render {

using Vec3f = Eigen::Vector3f;

// A ray as SceneGeometry cast it: bench_render replays a frame's own rays
// through bare rtcIntersect1 / rtcOccluded1 to measure what the renderer
// adds to Embree's cost (its goal: at most 1.5 times).
struct CastRay {
  Vec3f origin, direction;
  float t_far;
  bool occlusion;  // a shadow ray (Occluded), else a closest hit (Intersect)
};
// Receives every ray cast while it is installed, from any thread.
class RayRecorder {
 public:
  virtual ~RayRecorder() = default;
  virtual void Record(const CastRay& ray) = 0;
};

// The sub-triangle of barycentric (b1, b2) (weights of vertices 1 and 2) in
// a triangle split m x m: an index in [0, m^2). Row i = floor(b1 m) holds
// 2 (m - i) - 1 sub-triangles, alternately upright and inverted.
inline int SubTriangleIndex(int m, float b1, float b2) {
  const float x = b1 * static_cast<float>(m), y = b2 * static_cast<float>(m);
  int i = static_cast<int>(x), j = static_cast<int>(y);
  i = i < 0 ? 0 : (i > m - 1 ? m - 1 : i);
  j = j < 0 ? 0 : (j > m - 1 - i ? m - 1 - i : j);
  const bool inverted = (x - static_cast<float>(i)) + (y - static_cast<float>(j)) > 1.0f && i + j < m - 1;
  return i * (2 * m - i) + 2 * j + (inverted ? 1 : 0);
}

// Barycentric centre (b1, b2) of sub-triangle `index` (the inverse of SubTriangleIndex).
void SubTriangleCenter(int m, int index, float& b1, float& b2);

class SurfaceTextures;

struct Hit {
  int object = -1;
  int triangle = -1;
  float b1 = 0, b2 = 0;  // barycentric weights of vertices 1 and 2
  float distance = 0;
  Vec3f position = Vec3f::Zero();
  Vec3f normal = Vec3f::Zero();  // the triangle's front normal (unit)
  bool front = false;            // the ray arrived on the front side
  explicit operator bool() const { return object >= 0; }
};

// A core's L2 cache (1 MiB on the machines measured). Tables read at random
// per ray (a large mesh's triangles, its glow, its emitter table) are
// prefetched ahead of use only when they outgrow it: below that they are in
// cache already, and the prefetches would only cost.
inline constexpr std::size_t kCoreCacheBytes = std::size_t{1} << 20;

class SceneGeometry {
 public:
  explicit SceneGeometry(const Scene& scene);
  ~SceneGeometry();
  SceneGeometry(const SceneGeometry&) = delete;
  SceneGeometry& operator=(const SceneGeometry&) = delete;

  // Places every object at time t; returns true if any object moved (the BVH was refit).
  bool SetTime(double t_s);
  double time_s() const { return time_s_; }
  // Counts the moves: caches of anything geometric compare it.
  std::uint64_t version() const { return version_; }

  Hit Intersect(const Vec3f& origin, const Vec3f& direction, float t_far = 1e30f) const;
  // True if something lies between origin and origin + t_far * direction.
  bool Occluded(const Vec3f& origin, const Vec3f& direction, float t_far) const;
  // Many independent rays at once, through Embree's stream interface
  // (rtcIntersect1M, rtcOccluded1M), which traces them in packets: the path
  // tracer's wavefront. `coherent`: rays from one point through neighbouring
  // pixels (camera rays), else scattered. Each hit as Intersect would find it.
  struct RayQuery {
    Vec3f origin, direction;
    float t_far = 1e30f;
  };
  void IntersectMany(const RayQuery* queries, std::size_t count, Hit* hits, bool coherent) const;
  void OccludedMany(const RayQuery* queries, std::size_t count, bool* occluded) const;

  const Scene& scene() const { return scene_; }
  int object_count() const { return static_cast<int>(world_.size()); }
  int triangle_count(int object) const { return static_cast<int>(scene_.objects[object].mesh->triangles.size()); }
  Vec3f Vertex(int object, int triangle, int corner) const {
    return world_[object][scene_.objects[object].mesh->triangles[triangle][corner]];
  }
  Vec3f Point(int object, int triangle, float b1, float b2) const;
  // The unit normal on the side the triangle's winding faces (counter-
  // clockwise seen from the front), and the area: computed once per pose in
  // Upload, since every ray hit asks for them.
  const Vec3f& FrontNormal(int object, int triangle) const { return front_normal_[object][triangle]; }
  float Area(int object, int triangle) const { return area_[object][triangle]; }
  const float* Areas(int object) const { return area_[object].data(); }  // per triangle, m^2
  // An emissive object's (Light::Kind::kMesh): its area and a point on it,
  // uniform in area, at (u1, u2) in [0, 1)^2, with the triangle it lies on.
  float EmitterArea(int object) const { return area_cdf_[object].empty() ? 0.0f : area_cdf_[object].back(); }
  Vec3f SampleEmitter(int object, float u1, float u2, int* triangle) const;
  // A distance to step off a surface before casting a ray from it.
  float ray_epsilon() const { return ray_epsilon_; }
  float diagonal_m() const { return diagonal_; }

  // Installs a recorder of every ray cast (nullptr removes it). Not while
  // rays are being cast.
  void SetRayRecorder(RayRecorder* recorder) { recorder_ = recorder; }
  // The objects' albedo textures (surface_textures.h), opened with the
  // geometry so that a bad file is refused before any frame; null when no
  // object is textured.
  const SurfaceTextures* surface_textures() const { return surface_textures_.get(); }
  RTCSceneTy* embree_scene() const;

 private:
  void Upload(int object);
  const Scene& scene_;
  struct Embree;
  std::unique_ptr<Embree> embree_;
  std::vector<std::vector<Vec3f>> world_;  // world-space vertices per object
  // Per object, per triangle: its three world-space vertices side by side, so
  // that a hit's position is one cache line away, not a walk through the
  // mesh's index buffer.
  std::vector<LargeTable<std::array<Vec3f, 3>>> corners_;
  std::vector<LargeTable<Vec3f>> front_normal_;  // per object, per triangle
  // IntersectMany prefetches a stream's hit triangles (corners_,
  // front_normal_) only when those tables outgrow kCoreCacheBytes.
  bool prefetch_hit_triangles_ = false;
  std::vector<LargeTable<float>> area_;           // per object, per triangle, m^2
  std::vector<std::vector<float>> area_cdf_;      // emissive objects: running sums of area_; others empty
  std::vector<bool> emissive_;                    // per object: some Light::Kind::kMesh light is it
  RayRecorder* recorder_ = nullptr;
  std::unique_ptr<SurfaceTextures> surface_textures_;
  double time_s_ = 0;
  std::uint64_t version_ = 0;
  float ray_epsilon_ = 1e-4f, diagonal_ = 1.0f;
};

// Where a texel sits on its object: a triangle and barycentric weights.
struct TexelAnchor {
  std::uint32_t triangle;
  float b1, b2;
};

// A light at one moment, as the irradiance computations need it.
struct LightPose {
  Light::Kind kind = Light::Kind::kPoint;
  Vec3f at = Vec3f::Zero();  // point: position; directional, sheet: travel direction
  // Sheet: the slab |sheet_normal . p - sheet_offset| <= sheet_half_m.
  Vec3f sheet_normal = Vec3f::Zero();
  float sheet_offset = 0, sheet_half_m = 0;
  // Area lights: `at` is the centre; the emitting side's unit normal; a
  // quad's half edges (width along u, height along v) or a disk's radius
  // along two unit axes u and v; its area; shadow rays per shaded point.
  Vec3f normal = Vec3f::Zero(), u = Vec3f::Zero(), v = Vec3f::Zero();
  float area_m2 = 0;
  int samples = 1;
  int object = -1;  // kMesh: the emissive object
  bool area() const { return kind == Light::Kind::kQuad || kind == Light::Kind::kDisk || kind == Light::Kind::kMesh; }
  // A quad or disk: a light without a body, found by HitAreaLight, not by Embree.
  bool bodiless() const { return kind == Light::Kind::kQuad || kind == Light::Kind::kDisk; }
  bool positional() const { return kind == Light::Kind::kPoint || kind == Light::Kind::kSpot; }
  // Spot: the axis and the cone (KHR_lights_punctual's falloff: the square of
  // the cosine to the axis mapped linearly from cos_outer (0) to cos_inner (1)).
  Vec3f spot_axis = Vec3f::Zero();
  float cos_inner = 1, cos_outer = 0;
  // The spot's share of its intensity toward unit direction w (from the
  // light); 1 for every other light.
  float SpotFalloff(const Vec3f& w) const {
    if (kind != Light::Kind::kSpot) return 1.0f;
    const float scale = 1.0f / std::max(1e-3f, cos_inner - cos_outer);
    const float a = std::clamp((spot_axis.dot(w) - cos_outer) * scale, 0.0f, 1.0f);
    return a * a;
  }
  // Point, spot: KHR_lights_punctual's range window at `distance`,
  // clamp(1 - (distance / range)^4, 0, 1) times the inverse square the
  // caller applies (the glTF 2.0 extension's README, "Range Property");
  // 1 without a range (range_m 0).
  float range_m = 0;
  float RangeWindow(float distance) const {
    if (!(range_m > 0)) return 1.0f;
    const float x2 = (distance / range_m) * (distance / range_m);
    return std::clamp(1 - x2 * x2, 0.0f, 1.0f);
  }
  // The point of a quad or disk at (u1, u2) in [0, 1)^2, uniform in area
  // (a disk by Shirley and Chiu's concentric map).
  Vec3f SamplePoint(float u1, float u2) const;
  float SheetMask(const Vec3f& p) const {
    return kind != Light::Kind::kSheet || std::fabs(sheet_normal.dot(p) - sheet_offset) <= sheet_half_m ? 1.0f : 0.0f;
  }
  // The fraction of a cell around p, extending half_extent_m either way along
  // the sheet's normal, that lies inside the slab (a voxel's share of a sweep
  // without aliasing on the voxel grid).
  float SheetCoverage(const Vec3f& p, float half_extent_m) const {
    if (kind != Light::Kind::kSheet) return 1.0f;
    if (!(half_extent_m > 0)) return SheetMask(p);
    const float c = sheet_normal.dot(p) - sheet_offset;
    const float overlap = std::min(c + half_extent_m, sheet_half_m) - std::max(c - half_extent_m, -sheet_half_m);
    return std::clamp(overlap / (2 * half_extent_m), 0.0f, 1.0f);
  }
  bool operator==(const LightPose& o) const {
    return kind == o.kind && at == o.at && sheet_normal == o.sheet_normal && sheet_offset == o.sheet_offset &&
           sheet_half_m == o.sheet_half_m && normal == o.normal && u == o.u && v == o.v && samples == o.samples &&
           spot_axis == o.spot_axis && cos_inner == o.cos_inner && cos_outer == o.cos_outer && object == o.object &&
           range_m == o.range_m;
  }
};
LightPose PoseAt(const Light& light, double t_s);

// Irradiance at point p (front normal n) per unit of a light's band
// irradiance, shadowed by one Embree ray from just off the surface: cos / d^2
// for a point light, cos for a directional light or inside a sheet's slab;
// 0 behind the surface, in shadow or outside the sheet (E = I cos / d^2,
// Sec. 8.5). If `rays` is given, it counts the shadow rays cast. Used by the
// coupled solver, every transport, the comparison methods and the editor, so
// that all of them light a point the same way.
// UnitIrradiance in two steps, for callers that cast their shadow rays in
// batches (the path tracer): the ray, and what the point receives if nothing
// blocks it (unit = 0: nothing to test, the light does not reach it).
//
// An area light is sampled: RayToLight goes to its point at (u1, u2), with
// unit = cos cos_light A / d^2 (the area estimator per unit radiance, which
// the path tracer averages), and area_pdf = d^2 / (cos_light A), the
// solid-angle pdf of that direction (its MIS weight). UnitIrradiance shades
// a point by Heitz et al. 2018's ratio estimator ("Combining analytic direct
// illumination and stochastic shadows"): the unshadowed irradiance in
// closed form (AreaLightUnoccluded) times the visible fraction of
// light.samples stratified shadow rays, each weighted by its share of that
// irradiance. Unshadowed it is exact; a penumbra is soft and, at a given
// point, the same at every call (the strata's jitter is seeded by the point).
struct LightRay {
  Vec3f origin = Vec3f::Zero(), direction = Vec3f::Zero();
  float t_far = 0, unit = 0;
  float area_pdf = 0;  // area lights only
};
LightRay RayToLight(const SceneGeometry& geometry, const LightPose& light, const Vec3f& p, const Vec3f& n,
                    float u1 = 0.5f, float u2 = 0.5f);
float UnitIrradiance(const SceneGeometry& geometry, const LightPose& light, const Vec3f& p, const Vec3f& n,
                     std::uint64_t* rays = nullptr);
// An area light's irradiance at p (unit normal n) per unit radiance with
// nothing in the way: Lambert's formula for a polygon (Arvo 1995, "Applications
// of irradiance tensors"), E = 1/2 sum_i theta_i n . g_i over the edges of the
// light clipped to p's upper hemisphere, theta_i the angle an edge subtends
// and g_i the unit normal of the plane through p and that edge. A disk is a
// regular 48-gon of the disk's area. 0 where p lies behind the light.
// An emissive mesh is the sum over its triangles whose front p is in front of.
float AreaLightUnoccluded(const SceneGeometry& geometry, const LightPose& light, const Vec3f& p, const Vec3f& n);
// A quad's or disk's (no geometry needed).
float AreaLightUnoccluded(const LightPose& light, const Vec3f& p, const Vec3f& n);
// Where a ray from origin along unit `direction` crosses an area light's
// emitting side before t_far: its distance, or a negative number.
float HitAreaLight(const LightPose& light, const Vec3f& origin, const Vec3f& direction, float t_far);

// A seed for the random numbers of the point p, from its coordinates' bits:
// a point shaded twice (a texel at each step, a pixel in each frame) draws
// the same numbers, so its noise holds still.
std::uint64_t PointSeed(const Vec3f& p);

// The sky's irradiance at p (normal n) per unit of its band radiance, by
// `rays` cosine-distributed shadow rays, stratified on a sqrt(rays) grid
// (E = pi mean of Shape(w) over the unblocked rays); `seed` decorrelates
// neighbouring points.
float UnitSkyIrradiance(const SceneGeometry& geometry, const Environment& environment, const Vec3f& p, const Vec3f& n,
                        int rays, std::uint64_t seed, std::uint64_t* count = nullptr);

// The pinhole camera at one moment: ray directions through image points in
// pixels ((x + 0.5, y + 0.5) is the centre of pixel x, y).
class CameraRays {
 public:
  CameraRays(const Scene& scene, double t_s);
  Vec3f origin() const { return origin_; }
  Vec3f Direction(float x, float y) const { return Through(x, y).normalized(); }
  // Direction's ray before it is normalized, and the steps that take it one
  // pixel right and one pixel down: the rays through the next pixels (a
  // camera ray's differentials) at the cost of an addition each.
  Vec3f Through(float x, float y) const;
  Vec3f pixel_right() const { return pixel_right_; }
  Vec3f pixel_down() const { return pixel_down_; }
  // The image point (pixels) of a world point and its depth along the view
  // axis; false when it lies behind the camera.
  bool Project(const Vec3f& p, float* x, float* y, float* depth) const;
  float tan_half_y() const { return tan_half_y_; }

 private:
  Vec3f origin_, forward_, right_, up_, pixel_right_, pixel_down_;
  float tan_half_y_, aspect_, width_, height_;
};

// The texels of the phosphorescent objects: the mesh's UV map when it has
// one (a grid of uv_resolution^2 texels over [0, 1]^2, of which only those a
// triangle covers carry a state), else the automatic per-triangle atlas.
class TexelAtlas {
 public:
  // Auto: m per triangle = ceil(longest edge / texel size), at least 1.
  // UV: resolution from the texel size and the ratio of surface to UV area.
  TexelAtlas(const Scene& scene, const SceneGeometry& geometry);

  struct ObjectTexels {
    int object = -1;
    std::size_t count = 0;  // texels of the object
    // Auto atlas: per triangle, the index of its first texel and its subdivisions.
    // UV atlas: first is unused and m is 8 (the glow patches' granularity).
    LargeTable<std::uint32_t> first;
    LargeTable<std::uint16_t> m;
    // UV atlas.
    int uv_resolution = 0;                    // 0: auto atlas
    std::vector<std::int32_t> uv_index;       // [y * resolution + x]: texel, or -1 where no triangle lies
    std::vector<TexelAnchor> anchors;         // per texel
    std::vector<Eigen::Vector2f> uv_corners;  // [3 * triangle + corner], in texels
    const Mesh* mesh = nullptr;
    // A masked phosphor (Object::phosphor_mask): per texel, the share the
    // phosphor covers, in (0, 1]; the texels the mask leaves bare have no
    // index (uv_index kMaskedOut) and are counted here. Empty: unmasked.
    std::vector<float> coverage;
    std::size_t masked_out = 0;  // bare texels of a mask, and texels over a map's pixels without a decay
    // A mapped phosphor (Object::phosphor_map): per texel, the map's pixel
    // under its centre. Empty: unmapped.
    std::vector<std::uint32_t> map_pixel;
    // Where the bare texels lie (masks and maps): the glow patches
    // (phosphor_irradiance) count them, so that a patch glows by its share of paint.
    std::vector<TexelAnchor> bare_anchors;
    bool uv() const { return uv_resolution > 0; }
    bool masked() const { return !coverage.empty(); }
  };
  // What TexelOf gives where a mask leaves the surface bare: no texel, no glow.
  static constexpr std::size_t kNoTexel = ~std::size_t{0};
  // The share of texel k of slot s the phosphor covers (1 when unmasked).
  float Coverage(int slot, std::size_t texel) const {
    const ObjectTexels& o = objects_[slot];
    return o.coverage.empty() ? 1.0f : o.coverage[texel];
  }
  // Index into objects() of a phosphorescent object, or -1.
  int SlotOf(int object) const { return slot_[object]; }
  const std::vector<ObjectTexels>& objects() const { return objects_; }
  std::size_t total_texels() const;

  // Texel of a hit on object slot s; kNoTexel where its mask leaves it bare.
  std::size_t TexelOf(int slot, int triangle, float b1, float b2) const {
    const ObjectTexels& o = objects_[slot];
    if (!o.uv()) return o.first[triangle] + static_cast<std::size_t>(SubTriangleIndex(o.m[triangle], b1, b2));
    return UvTexelOf(o, triangle, b1, b2);
  }

  // Calls f(texel, triangle, b1, b2) for every texel of slot s in `chunk`, for
  // chunk in [0, chunk_count(s)): chunks can run in parallel.
  std::size_t chunk_count(int slot) const {
    const ObjectTexels& o = objects_[slot];
    return o.uv() ? (o.anchors.size() + kUvChunk - 1) / kUvChunk : o.m.size();
  }
  template <typename F>
  void ForEachTexelInChunk(int slot, std::size_t chunk, F&& f) const {
    const ObjectTexels& o = objects_[slot];
    if (o.uv()) {
      const std::size_t end = std::min(o.anchors.size(), (chunk + 1) * kUvChunk);
      for (std::size_t k = chunk * kUvChunk; k < end; ++k)
        f(k, static_cast<int>(o.anchors[k].triangle), o.anchors[k].b1, o.anchors[k].b2);
      return;
    }
    // Texel k in SubTriangleIndex's order: row i, then upright and inverted alternately.
    const int t = static_cast<int>(chunk), m = o.m[t];
    std::size_t k = o.first[t];
    for (int i = 0; i < m; ++i)
      for (int j = 0; j < m - i; ++j)
        for (int inverted = 0; inverted < (i + j < m - 1 ? 2 : 1); ++inverted) {
          const float third = inverted ? 2.0f / 3.0f : 1.0f / 3.0f;
          f(k++, t, (static_cast<float>(i) + third) / static_cast<float>(m),
            (static_cast<float>(j) + third) / static_cast<float>(m));
        }
  }
  template <typename F>
  void ForEachTexel(int slot, F&& f) const {
    for (std::size_t c = 0; c < chunk_count(slot); ++c) ForEachTexelInChunk(slot, c, f);
  }

 private:
  static constexpr std::size_t kUvChunk = 4096;
  static constexpr std::int32_t kMaskedOut = -2;  // uv_index of a cell the mask leaves bare (-1: no triangle)
  static std::size_t UvTexelOf(const ObjectTexels& o, int triangle, float b1, float b2);
  void BuildUv(ObjectTexels& texels, const Object& object, const SceneGeometry& geometry, double texel_size_m);
  std::vector<int> slot_;
  std::vector<ObjectTexels> objects_;
};

}  // namespace phos::render
