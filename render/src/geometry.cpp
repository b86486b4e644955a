#include "phos/render/geometry.h"

#include "phos/render/phosphor_map.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>

#include <embree3/rtcore.h>

#include "phos/render/surface_textures.h"
#include "phos/util/error.h"
#include "phos/util/math.h"
#include "phos/util/prefetch.h"
#include "phos/util/random.h"

#include "sampling.h"
#include "texel_count.h"

namespace phos::render {

void SubTriangleCenter(int m, int index, float& b1, float& b2) {
  int i = 0;
  while (i + 1 < m && (i + 1) * (2 * m - (i + 1)) <= index) ++i;
  const int within = index - i * (2 * m - i);
  const int j = within / 2;
  const float third = (within % 2 == 1) ? 2.0f / 3.0f : 1.0f / 3.0f;
  b1 = (static_cast<float>(i) + third) / static_cast<float>(m);
  b2 = (static_cast<float>(j) + third) / static_cast<float>(m);
}

struct SceneGeometry::Embree {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  std::vector<RTCGeometry> geometries;
  ~Embree() {
    for (RTCGeometry g : geometries) rtcReleaseGeometry(g);
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }
};

SceneGeometry::SceneGeometry(const Scene& scene) : scene_(scene), embree_(std::make_unique<Embree>()) {
  embree_->device = rtcNewDevice(nullptr);
  PHOS_CHECK(embree_->device != nullptr);
  embree_->scene = rtcNewScene(embree_->device);
  rtcSetSceneBuildQuality(embree_->scene, RTC_BUILD_QUALITY_HIGH);
  world_.resize(scene.objects.size());
  corners_.resize(scene.objects.size());
  front_normal_.resize(scene.objects.size());
  area_.resize(scene.objects.size());
  area_cdf_.resize(scene.objects.size());
  emissive_.assign(scene.objects.size(), false);
  for (const Light& light : scene.lights)
    if (light.kind == Light::Kind::kMesh) emissive_[light.emitter_object] = true;
  time_s_ = scene.start_s;
  for (std::size_t o = 0; o < scene.objects.size(); ++o) {
    const Mesh& mesh = *scene.objects[o].mesh;
    RTCGeometry geometry = rtcNewGeometry(embree_->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    // Embree reads vertex buffers with 16-byte loads: one float of padding.
    rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 4 * sizeof(float),
                            mesh.positions.size());
    auto* index = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                                 3 * sizeof(unsigned), mesh.triangles.size()));
    for (std::size_t t = 0; t < mesh.triangles.size(); ++t)
      for (int c = 0; c < 3; ++c) index[3 * t + c] = static_cast<unsigned>(mesh.triangles[t][c]);
    // Moving objects are refit rather than rebuilt.
    if (scene.objects[o].motion.Moves()) rtcSetGeometryBuildQuality(geometry, RTC_BUILD_QUALITY_REFIT);
    embree_->geometries.push_back(geometry);
    Upload(static_cast<int>(o));
    rtcAttachGeometryByID(embree_->scene, geometry, static_cast<unsigned>(o));
  }
  rtcCommitScene(embree_->scene);
  std::size_t triangles = 0;
  for (const auto& object_corners : corners_) triangles += object_corners.size();
  prefetch_hit_triangles_ = triangles * (sizeof(std::array<Vec3f, 3>) + sizeof(Vec3f)) > kCoreCacheBytes;
  for (const Object& object : scene.objects)
    if (object.albedo_texture || object.gloss_texture) {
      surface_textures_ = std::make_unique<SurfaceTextures>(scene);
      break;
    }
  Eigen::AlignedBox3f box;
  for (const auto& vertices : world_)
    for (const Vec3f& v : vertices) box.extend(v);
  diagonal_ = std::max(box.diagonal().norm(), 1e-6f);
  ray_epsilon_ = 1e-5f * diagonal_;
}

SceneGeometry::~SceneGeometry() = default;

void SceneGeometry::Upload(int object) {
  const Object& o = scene_.objects[object];
  const Eigen::Affine3f transform = o.motion.At(time_s_).cast<float>();
  std::vector<Vec3f>& world = world_[object];
  world.resize(o.mesh->positions.size());
  auto* vertex = static_cast<float*>(rtcGetGeometryBufferData(embree_->geometries[object], RTC_BUFFER_TYPE_VERTEX, 0));
  for (std::size_t v = 0; v < world.size(); ++v) {
    world[v] = transform * o.mesh->positions[v];
    vertex[4 * v + 0] = world[v].x();
    vertex[4 * v + 1] = world[v].y();
    vertex[4 * v + 2] = world[v].z();
    vertex[4 * v + 3] = 0.0f;
  }
  rtcUpdateGeometryBuffer(embree_->geometries[object], RTC_BUFFER_TYPE_VERTEX, 0);
  rtcCommitGeometry(embree_->geometries[object]);
  const std::size_t triangles = o.mesh->triangles.size();
  corners_[object].resize(triangles);
  front_normal_[object].resize(triangles);
  area_[object].resize(triangles);
  for (std::size_t t = 0; t < triangles; ++t) {
    const int triangle = static_cast<int>(t);
    for (int c = 0; c < 3; ++c) corners_[object][t][c] = Vertex(object, triangle, c);
    const Vec3f v0 = Vertex(object, triangle, 0);
    const Vec3f n = (Vertex(object, triangle, 1) - v0).cross(Vertex(object, triangle, 2) - v0);
    const float length = n.norm();
    front_normal_[object][t] = length > 0 ? Vec3f(n / length) : Vec3f(0, 0, 1);
    area_[object][t] = 0.5f * length;
  }
  if (emissive_[object]) {
    std::vector<float>& cdf = area_cdf_[object];
    cdf.resize(triangles);
    float sum = 0;
    for (std::size_t t = 0; t < triangles; ++t) cdf[t] = sum += area_[object][t];
  }
}

Vec3f SceneGeometry::SampleEmitter(int object, float u1, float u2, int* triangle) const {
  const std::vector<float>& cdf = area_cdf_[object];
  const float target = u1 * cdf.back();
  const std::size_t t =
      std::min<std::size_t>(std::upper_bound(cdf.begin(), cdf.end(), target) - cdf.begin(), cdf.size() - 1);
  // u1 reused within the chosen triangle's share of the sum.
  const float before = t > 0 ? cdf[t - 1] : 0.0f, share = cdf[t] - before;
  const float v1 = share > 0 ? std::clamp((target - before) / share, 0.0f, 1.0f) : 0.5f;
  const float r = std::sqrt(v1), b1 = 1 - r, b2 = u2 * r;  // uniform on the triangle
  *triangle = static_cast<int>(t);
  const std::array<Vec3f, 3>& v = corners_[object][t];
  return v[0] + b1 * (v[1] - v[0]) + b2 * (v[2] - v[0]);
}

RTCSceneTy* SceneGeometry::embree_scene() const { return embree_->scene; }

bool SceneGeometry::SetTime(double t_s) {
  bool moved = false;
  const double before = time_s_;
  time_s_ = t_s;
  for (std::size_t o = 0; o < scene_.objects.size(); ++o) {
    const RigidMotion& motion = scene_.objects[o].motion;
    if (!motion.Moves() || motion.At(before).isApprox(motion.At(t_s), 0)) continue;
    Upload(static_cast<int>(o));
    moved = true;
  }
  if (moved) {
    rtcCommitScene(embree_->scene);
    ++version_;
  }
  return moved;
}

namespace {
// Embree's stream calls take arrays; a thread's scratch keeps them allocated.
thread_local std::vector<RTCRayHit> stream_ray_hits;
thread_local std::vector<RTCRay> stream_rays;

void SetRay(RTCRay& ray, const Vec3f& origin, const Vec3f& direction, float t_far) {
  ray.org_x = origin.x();
  ray.org_y = origin.y();
  ray.org_z = origin.z();
  ray.tnear = 0.0f;
  ray.dir_x = direction.x();
  ray.dir_y = direction.y();
  ray.dir_z = direction.z();
  ray.time = 0.0f;
  ray.tfar = t_far;
  ray.mask = 0xFFFFFFFFu;
  ray.id = 0;
  ray.flags = 0;
}

void SetRayHit(RTCRayHit& ray, const Vec3f& origin, const Vec3f& direction, float t_far) {
  SetRay(ray.ray, origin, direction, t_far);
  ray.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  ray.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
}

// The hit record of a traced ray: position from the barycentrics (closer to
// the surface than origin + t direction), the front normal, and the side.
Hit HitOf(const SceneGeometry& geometry, const RTCRayHit& ray, const Vec3f& direction) {
  Hit hit;
  if (ray.hit.geomID == RTC_INVALID_GEOMETRY_ID) return hit;
  hit.object = static_cast<int>(ray.hit.geomID);
  hit.triangle = static_cast<int>(ray.hit.primID);
  hit.b1 = ray.hit.u;
  hit.b2 = ray.hit.v;
  hit.distance = ray.ray.tfar;
  hit.position = geometry.Point(hit.object, hit.triangle, hit.b1, hit.b2);
  hit.normal = geometry.FrontNormal(hit.object, hit.triangle);
  hit.front = hit.normal.dot(direction) < 0;
  return hit;
}
}  // namespace

Hit SceneGeometry::Intersect(const Vec3f& origin, const Vec3f& direction, float t_far) const {
  if (recorder_) [[unlikely]]
    recorder_->Record({origin, direction, t_far, false});
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit ray{};
  SetRayHit(ray, origin, direction, t_far);
  rtcIntersect1(embree_->scene, &context, &ray);
  return HitOf(*this, ray, direction);
}

void SceneGeometry::IntersectMany(const RayQuery* queries, std::size_t count, Hit* hits, bool coherent) const {
  if (count == 0) return;
  std::vector<RTCRayHit>& rays = stream_ray_hits;
  rays.resize(count);
  for (std::size_t i = 0; i < count; ++i) {
    if (recorder_) [[unlikely]]
      recorder_->Record({queries[i].origin, queries[i].direction, queries[i].t_far, false});
    SetRayHit(rays[i], queries[i].origin, queries[i].direction, queries[i].t_far);
  }
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  context.flags = coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
  rtcIntersect1M(embree_->scene, &context, rays.data(), static_cast<unsigned>(count), sizeof(RTCRayHit));
  // The hit triangles' corners and normals, asked for before any is read:
  // in a large mesh each is a cache miss of its own, and a stream's misses
  // overlap when they are all in flight at once. With a 1.3M-triangle
  // sphere in the Cornell box the path/bare ratio is 0.966 of what it was
  // (median of fifteen alternated pairs, bench_render
  // --benchmark_filter=PathAgainstBareEmbreeBySize/8). A scene whose tables
  // fit a core's cache skips it.
  for (std::size_t i = 0; prefetch_hit_triangles_ && i < count; ++i) {
    const RTCHit& hit = rays[i].hit;
    if (hit.geomID == RTC_INVALID_GEOMETRY_ID) continue;
    const auto* corners = &corners_[hit.geomID][hit.primID];
    Prefetch(corners);
    Prefetch(reinterpret_cast<const char*>(corners) + sizeof(*corners) - 1);
    Prefetch(&front_normal_[hit.geomID][hit.primID]);
  }
  for (std::size_t i = 0; i < count; ++i) hits[i] = HitOf(*this, rays[i], queries[i].direction);
}

void SceneGeometry::OccludedMany(const RayQuery* queries, std::size_t count, bool* occluded) const {
  if (count == 0) return;
  std::vector<RTCRay>& rays = stream_rays;
  rays.resize(count);
  for (std::size_t i = 0; i < count; ++i) {
    if (recorder_) [[unlikely]]
      recorder_->Record({queries[i].origin, queries[i].direction, queries[i].t_far, true});
    SetRay(rays[i], queries[i].origin, queries[i].direction, queries[i].t_far);
  }
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  context.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
  rtcOccluded1M(embree_->scene, &context, rays.data(), static_cast<unsigned>(count), sizeof(RTCRay));
  for (std::size_t i = 0; i < count; ++i) occluded[i] = rays[i].tfar < 0.0f;  // -inf on a hit
}

bool SceneGeometry::Occluded(const Vec3f& origin, const Vec3f& direction, float t_far) const {
  if (recorder_) [[unlikely]]
    recorder_->Record({origin, direction, t_far, true});
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRay ray{};
  SetRay(ray, origin, direction, t_far);
  rtcOccluded1(embree_->scene, &context, &ray);
  return ray.tfar < 0.0f;  // Embree sets tfar to -inf on a hit
}

Vec3f SceneGeometry::Point(int object, int triangle, float b1, float b2) const {
  const std::array<Vec3f, 3>& v = corners_[object][triangle];
  return (1 - b1 - b2) * v[0] + b1 * v[1] + b2 * v[2];
}

LightPose PoseAt(const Light& light, double t_s) {
  LightPose pose;
  pose.kind = light.kind;
  if (light.kind == Light::Kind::kMesh) {
    pose.object = light.emitter_object;
    pose.samples = light.samples;
    return pose;
  }
  if (light.area()) {
    pose.at = light.PositionAt(t_s).cast<float>();
    pose.normal = light.normal.normalized().cast<float>();
    pose.samples = light.samples;
    if (light.kind == Light::Kind::kQuad) {
      // u x v = tangent x (normal x tangent) = normal: counter-clockwise from the front.
      const Vec3 tangent = light.tangent.normalized();
      pose.u = (0.5 * light.width_m * tangent).cast<float>();
      pose.v = (0.5 * light.height_m * light.normal.normalized().cross(tangent)).cast<float>();
      pose.area_m2 = static_cast<float>(light.width_m * light.height_m);
    } else {
      const Vec3 axis = light.normal.normalized().unitOrthogonal();
      pose.u = (light.radius_m * axis).cast<float>();
      pose.v = (light.radius_m * light.normal.normalized().cross(axis)).cast<float>();
      pose.area_m2 = static_cast<float>(kPi * light.radius_m * light.radius_m);
    }
    return pose;
  }
  if (light.positional()) {
    pose.at = light.PositionAt(t_s).cast<float>();
    pose.range_m = static_cast<float>(light.range_m);
    if (light.kind == Light::Kind::kSpot) {
      pose.spot_axis = light.DirectionAt(t_s).cast<float>();
      pose.cos_inner = static_cast<float>(std::cos(light.inner_cone_deg * kPi / 180));
      pose.cos_outer = static_cast<float>(std::cos(light.outer_cone_deg * kPi / 180));
    }
    return pose;
  }
  pose.at = light.DirectionAt(t_s).cast<float>();
  if (light.kind == Light::Kind::kSheet) {
    pose.sheet_normal = light.sheet_normal.normalized().cast<float>();
    pose.sheet_offset = pose.sheet_normal.dot(light.PositionAt(t_s).cast<float>());
    pose.sheet_half_m = static_cast<float>(0.5 * light.sheet_thickness_m);
  }
  return pose;
}

Vec3f LightPose::SamplePoint(float u1, float u2) const {
  const float x = 2 * u1 - 1, y = 2 * u2 - 1;
  if (kind == Light::Kind::kQuad) return at + x * u + y * v;
  // Shirley and Chiu 1997's concentric map of the square onto the disk.
  if (x == 0 && y == 0) return at;
  float r, phi;
  if (std::abs(x) > std::abs(y)) {
    r = x;
    phi = kPiF / 4 * (y / x);
  } else {
    r = y;
    phi = kPiF / 2 - kPiF / 4 * (x / y);
  }
  return at + r * std::cos(phi) * u + r * std::sin(phi) * v;
}

namespace {

// The light's outline as a convex polygon, counter-clockwise seen from its
// front: a quad's corners, or a disk as a regular polygon of the disk's area
// (its circumradius R sqrt(2 pi / (n sin(2 pi / n))), 1.0011 R for n = 48).
constexpr int kDiskSides = 48;
int AreaLightOutline(const LightPose& light, Vec3f* corners) {
  if (light.kind == Light::Kind::kQuad) {
    corners[0] = light.at - light.u - light.v;
    corners[1] = light.at + light.u - light.v;
    corners[2] = light.at + light.u + light.v;
    corners[3] = light.at - light.u + light.v;
    return 4;
  }
  struct Ring {
    float cos[kDiskSides], sin[kDiskSides];
    Ring() {
      const double step = 2 * kPi / kDiskSides, scale = std::sqrt(step / std::sin(step));
      for (int i = 0; i < kDiskSides; ++i) {
        cos[i] = static_cast<float>(scale * std::cos(i * step));
        sin[i] = static_cast<float>(scale * std::sin(i * step));
      }
    }
  };
  static const Ring ring;
  for (int i = 0; i < kDiskSides; ++i) corners[i] = light.at + ring.cos[i] * light.u + ring.sin[i] * light.v;
  return kDiskSides;
}

// Lambert's formula for a convex polygon of `count` <= kDiskSides corners
// whose front p lies in front of (geometry.h).
float PolygonIrradiance(const Vec3f* corners, int count, const Vec3f& p, const Vec3f& n) {
  // Clip to p's upper hemisphere, n . x >= 0 (Sutherland and Hodgman): only
  // what lies above the horizon shines on p. A convex polygon and one plane
  // add at most one vertex.
  Vec3f clipped[kDiskSides + 1];
  int kept = 0;
  for (int i = 0; i < count; ++i) {
    const Vec3f a = corners[i] - p, b = corners[(i + 1) % count] - p;
    const float da = n.dot(a), db = n.dot(b);
    if (da >= 0) clipped[kept++] = a;
    if ((da >= 0) != (db >= 0)) clipped[kept++] = a + (da / (da - db)) * (b - a);
  }
  if (kept < 3) return 0.0f;
  // Lambert: sum of the edges' angles times n . (unit normal of the plane through p and the edge).
  float sum = 0;
  for (int i = 0; i < kept; ++i) {
    const Vec3f a = clipped[i].normalized(), b = clipped[(i + 1) % kept].normalized();
    const Vec3f cross = a.cross(b);
    const float sine = cross.norm();
    if (!(sine > 0)) continue;
    sum += std::atan2(sine, a.dot(b)) * n.dot(cross) / sine;
  }
  return 0.5f * std::abs(sum);
}

}  // namespace

float AreaLightUnoccluded(const LightPose& light, const Vec3f& p, const Vec3f& n) {
  if (!(light.normal.dot(p - light.at) > 0)) return 0.0f;  // behind the light, or in its plane
  Vec3f corners[kDiskSides];
  const int count = AreaLightOutline(light, corners);
  return PolygonIrradiance(corners, count, p, n);
}

float AreaLightUnoccluded(const SceneGeometry& geometry, const LightPose& light, const Vec3f& p, const Vec3f& n) {
  if (light.kind != Light::Kind::kMesh) return AreaLightUnoccluded(light, p, n);
  float sum = 0;
  for (int t = 0; t < geometry.triangle_count(light.object); ++t) {
    const Vec3f corners[3] = {geometry.Vertex(light.object, t, 0), geometry.Vertex(light.object, t, 1),
                              geometry.Vertex(light.object, t, 2)};
    if (!(geometry.FrontNormal(light.object, t).dot(p - corners[0]) > 0) || !(geometry.Area(light.object, t) > 0))
      continue;  // p is behind this triangle's emitting front
    sum += PolygonIrradiance(corners, 3, p, n);
  }
  return sum;
}

float HitAreaLight(const LightPose& light, const Vec3f& origin, const Vec3f& direction, float t_far) {
  const float facing = light.normal.dot(direction);
  if (!(facing < 0)) return -1.0f;  // parallel, or arriving at its back
  const float t = light.normal.dot(light.at - origin) / facing;
  if (!(t > 0 && t < t_far)) return -1.0f;
  const Vec3f q = origin + t * direction - light.at;
  const float x = q.dot(light.u) / light.u.squaredNorm(), y = q.dot(light.v) / light.v.squaredNorm();
  const bool inside = light.kind == Light::Kind::kQuad ? std::abs(x) <= 1 && std::abs(y) <= 1 : x * x + y * y <= 1;
  return inside ? t : -1.0f;
}

std::uint64_t PointSeed(const Vec3f& p) {
  return (std::uint64_t(std::bit_cast<std::uint32_t>(p.x())) * 73856093u) ^
         (std::uint64_t(std::bit_cast<std::uint32_t>(p.y())) * 19349663u) ^
         (std::uint64_t(std::bit_cast<std::uint32_t>(p.z())) * 83492791u);
}

LightRay RayToLight(const SceneGeometry& geometry, const LightPose& light, const Vec3f& p, const Vec3f& n, float u1,
                    float u2) {
  LightRay ray;
  ray.origin = p + geometry.ray_epsilon() * n;
  if (light.area()) {
    Vec3f q, normal;
    float area;
    if (light.kind == Light::Kind::kMesh) {
      int triangle;
      q = geometry.SampleEmitter(light.object, u1, u2, &triangle);
      normal = geometry.FrontNormal(light.object, triangle);
      area = geometry.EmitterArea(light.object);
    } else {
      q = light.SamplePoint(u1, u2);
      normal = light.normal;
      area = light.area_m2;
    }
    const Vec3f d = q - p;
    const float distance2 = d.squaredNorm(), distance = std::sqrt(distance2);
    if (!(distance > 0)) return ray;
    const Vec3f w = d / distance;
    const float cosine = n.dot(w), cos_light = -normal.dot(w);
    if (!(cosine > 0 && cos_light > 0)) return ray;
    // From the ray's origin (off the surface) to the light's point itself,
    // stopping short of it: the same direction from p, lifted off the
    // surface, would end inside an emissive mesh's body when it grazes the
    // face it samples (2% of a ball's light lost so).
    const Vec3f from_origin = q - ray.origin;
    const float length = from_origin.norm();
    if (!(length > 0)) return ray;
    ray.direction = from_origin / length;
    ray.t_far = length * (1 - 1e-4f);
    ray.unit = cosine * cos_light * area / distance2;
    ray.area_pdf = distance2 / (cos_light * area);
    return ray;
  }
  if (light.positional()) {
    const Vec3f d = light.at - p;
    const float distance2 = d.squaredNorm(), distance = std::sqrt(distance2);
    const float cosine = distance > 0 ? n.dot(d) / distance : 0.0f;
    if (!(cosine > 0)) return ray;  // behind the surface: only its front charges and reflects
    ray.direction = d / distance;
    const float falloff = light.SpotFalloff(-ray.direction) * light.RangeWindow(distance);
    if (!(falloff > 0)) return ray;  // outside a spot's cone or the light's range
    ray.t_far = distance * (1 - 1e-4f) - geometry.ray_epsilon();
    ray.unit = falloff * cosine / distance2;
    return ray;
  }
  if (light.SheetMask(p) == 0) return ray;
  const Vec3f to_light = -light.at;
  const float cosine = n.dot(to_light);
  if (!(cosine > 0)) return ray;
  ray.direction = to_light;
  ray.t_far = 1e30f;
  ray.unit = cosine;
  return ray;
}

namespace {

// The ratio estimator of UnitIrradiance for an area light (geometry.h).
float UnitAreaIrradiance(const SceneGeometry& geometry, const LightPose& light, const Vec3f& p, const Vec3f& n,
                         std::uint64_t* rays) {
  const float unshadowed = AreaLightUnoccluded(geometry, light, p, n);
  if (!(unshadowed > 0)) return 0.0f;
  const int side = std::max(1, static_cast<int>(std::lround(std::sqrt(static_cast<double>(light.samples)))));
  SplitMix64 random(PointSeed(p) * 0x9E3779B97F4A7C15ull + 0xD1B54A32D192ED03ull);
  float weight = 0, visible = 0;
  for (int i = 0; i < side; ++i)
    for (int j = 0; j < side; ++j) {
      const float u1 = (static_cast<float>(i) + random.UniformFloat()) / static_cast<float>(side);
      const float u2 = (static_cast<float>(j) + random.UniformFloat()) / static_cast<float>(side);
      const LightRay ray = RayToLight(geometry, light, p, n, u1, u2);
      if (!(ray.unit > 0)) continue;
      weight += ray.unit;
      if (rays) ++*rays;
      if (!geometry.Occluded(ray.origin, ray.direction, ray.t_far)) visible += ray.unit;
    }
  // No stratum above the horizon: the sliver that is has no sample to say
  // whether it is seen, and is left dark.
  return weight > 0 ? unshadowed * (visible / weight) : 0.0f;
}

}  // namespace

float UnitIrradiance(const SceneGeometry& geometry, const LightPose& light, const Vec3f& p, const Vec3f& n,
                     std::uint64_t* rays) {
  if (light.area()) return UnitAreaIrradiance(geometry, light, p, n, rays);
  const LightRay ray = RayToLight(geometry, light, p, n);
  if (ray.unit == 0) return 0.0f;
  if (rays) ++*rays;
  return geometry.Occluded(ray.origin, ray.direction, ray.t_far) ? 0.0f : ray.unit;
}

float UnitSkyIrradiance(const SceneGeometry& geometry, const Environment& environment, const Vec3f& p, const Vec3f& n,
                        int rays, std::uint64_t seed, std::uint64_t* count) {
  const int side = std::max(1, static_cast<int>(std::lround(std::sqrt(static_cast<double>(rays)))));
  const TangentFrame frame(n);
  const Vec3f origin = p + geometry.ray_epsilon() * n;
  SplitMix64 random(seed * 0x9E3779B97F4A7C15ull + 0x632BE59BD9B4E019ull);
  auto uniform = [&] { return random.UniformFloat(); };
  float sum = 0;
  for (int i = 0; i < side; ++i)
    for (int j = 0; j < side; ++j) {
      const float u1 = (static_cast<float>(i) + uniform()) / static_cast<float>(side);
      const float u2 = (static_cast<float>(j) + uniform()) / static_cast<float>(side);
      const Vec3f w = SampleCosineHemisphere(frame, u1, u2);
      if (count) ++*count;
      if (!geometry.Occluded(origin, w, 1e30f)) sum += environment.Shape(w.y());
    }
  return kPiF * sum / static_cast<float>(side * side);
}

CameraRays::CameraRays(const Scene& scene, double t_s) {
  const CameraKey key = scene.camera.At(t_s);
  origin_ = key.position.cast<float>();
  forward_ = (key.look_at - key.position).normalized().cast<float>();
  right_ = forward_.cross(scene.camera.up.cast<float>()).normalized();
  if (!right_.allFinite()) right_ = forward_.unitOrthogonal();  // looking along `up`
  up_ = right_.cross(forward_);
  tan_half_y_ = std::tan(static_cast<float>(scene.camera.fov_deg) * kPiF / 360.0f);
  width_ = static_cast<float>(scene.camera.width);
  height_ = static_cast<float>(scene.camera.height);
  aspect_ = width_ / height_;
  pixel_right_ = (2 / width_) * tan_half_y_ * aspect_ * right_;
  pixel_down_ = -(2 / height_) * tan_half_y_ * up_;
}

bool CameraRays::Project(const Vec3f& p, float* x, float* y, float* depth) const {
  const Vec3f d = p - origin_;
  *depth = d.dot(forward_);
  if (*depth <= 0) return false;
  const float sx = d.dot(right_) / *depth, sy = d.dot(up_) / *depth;
  // The inverse of Direction: sx = (2 x / width - 1) tan_half aspect, sy = (1 - 2 y / height) tan_half.
  *x = (sx / (tan_half_y_ * aspect_) + 1) * width_ / 2;
  *y = (1 - sy / tan_half_y_) * height_ / 2;
  return true;
}

Vec3f CameraRays::Through(float x, float y) const {
  const float sx = (2 * x / width_ - 1) * tan_half_y_ * aspect_;
  const float sy = (1 - 2 * y / height_) * tan_half_y_;
  return forward_ + sx * right_ + sy * up_;
}

TexelAtlas::TexelAtlas(const Scene& scene, const SceneGeometry& geometry) : slot_(scene.objects.size(), -1) {
  CheckTexelLimits(scene);  // before any texel is allocated
  const double default_size = scene.texel_size_m > 0 ? scene.texel_size_m : geometry.diagonal_m() / 200.0;
  for (std::size_t o = 0; o < scene.objects.size(); ++o) {
    const Object& object = scene.objects[o];
    if (!object.phosphor) continue;
    const double size = object.texel_size_m > 0 ? object.texel_size_m : default_size;
    ObjectTexels texels;
    texels.object = static_cast<int>(o);
    texels.mesh = object.mesh.get();
    const int triangles = geometry.triangle_count(static_cast<int>(o));
    // By default a mesh's UV map holds its texels when it can (a tiled or
    // reused map cannot: it would give one state to several places).
    if (UsesUvMap(object)) {
      BuildUv(texels, object, geometry, size);
    } else {
      for (int t = 0; t < triangles; ++t) {
        // Longest edge over the texel size: texels never longer than asked.
        float longest = 0;
        for (int c = 0; c < 3; ++c)
          longest = std::max(longest, (geometry.Vertex(static_cast<int>(o), t, (c + 1) % 3) -
                                       geometry.Vertex(static_cast<int>(o), t, c))
                                          .norm());
        const int m = AutoSubdivisions(longest, size);
        texels.first.push_back(static_cast<std::uint32_t>(texels.count));
        texels.m.push_back(static_cast<std::uint16_t>(m));
        texels.count += static_cast<std::size_t>(m) * static_cast<std::size_t>(m);
      }
    }
    slot_[o] = static_cast<int>(objects_.size());
    objects_.push_back(std::move(texels));
  }
}

void TexelAtlas::BuildUv(ObjectTexels& texels, const Object& object, const SceneGeometry& geometry,
                         double texel_size_m) {
  const Mesh& mesh = *object.mesh;
  const int o = texels.object, triangles = static_cast<int>(mesh.triangles.size());
  // Resolution: texels of about texel_size_m, from world area over UV area.
  double world_area = 0;
  for (int t = 0; t < triangles; ++t) world_area += geometry.Area(o, t);
  const int R = UvResolution(object, world_area, texel_size_m);
  texels.uv_resolution = R;
  texels.m.assign(triangles, 8);
  texels.uv_corners.resize(3 * static_cast<std::size_t>(triangles));
  // Rasterize every triangle in UV space. A texel belongs to the triangle that
  // covers its centre (or, along chart borders, comes nearest to it), so every
  // texel a triangle touches has a state and a point on the surface.
  std::vector<float> best(std::size_t(R) * R, -1e30f);
  std::vector<TexelAnchor> anchor(std::size_t(R) * R);
  for (int t = 0; t < triangles; ++t) {
    Eigen::Vector2f p[3];
    for (int c = 0; c < 3; ++c)
      p[c] = texels.uv_corners[3 * t + c] = mesh.uvs[mesh.uv_triangles[t][c]] * static_cast<float>(R);
    const float area2 = (p[1] - p[0]).x() * (p[2] - p[0]).y() - (p[1] - p[0]).y() * (p[2] - p[0]).x();
    if (std::abs(area2) < 1e-12f) continue;  // degenerate in UV: nothing to store on it
    const Eigen::Vector2f lo = p[0].cwiseMin(p[1]).cwiseMin(p[2]), hi = p[0].cwiseMax(p[1]).cwiseMax(p[2]);
    const int x0 = std::clamp(static_cast<int>(std::floor(lo.x())) - 1, 0, R - 1),
              x1 = std::clamp(static_cast<int>(std::ceil(hi.x())), 0, R - 1);
    const int y0 = std::clamp(static_cast<int>(std::floor(lo.y())) - 1, 0, R - 1),
              y1 = std::clamp(static_cast<int>(std::ceil(hi.y())), 0, R - 1);
    // Per edge (opposite corner c): its length, and half the extent of a texel
    // square along the edge's normal, (|n_x| + |n_y|) / 2.
    float edge_length[3], half_extent[3];
    for (int c = 0; c < 3; ++c) {
      const Eigen::Vector2f e = p[(c + 2) % 3] - p[(c + 1) % 3];
      edge_length[c] = std::max(e.norm(), 1e-12f);
      half_extent[c] = 0.5f * (std::abs(e.x()) + std::abs(e.y())) / edge_length[c];
    }
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) {
        const Eigen::Vector2f q(x + 0.5f, y + 0.5f);
        float lambda[3];
        for (int c = 0; c < 3; ++c) {
          const Eigen::Vector2f a = p[(c + 1) % 3], b = p[(c + 2) % 3];
          lambda[c] = ((b - a).x() * (q - a).y() - (b - a).y() * (q - a).x()) / area2;
        }
        // Signed distance (in texels) from the centre to each edge's line: the
        // texel's square reaches inside every edge (strictly: touching is not
        // covering). Score: the smallest distance, the centre's depth inside.
        float score = 1e30f;
        bool overlaps = true;
        for (int c = 0; c < 3; ++c) {
          const float distance = lambda[c] * std::abs(area2) / edge_length[c];
          overlaps = overlaps && distance > -half_extent[c] + 1e-6f;
          score = std::min(score, distance);
        }
        if (!overlaps) continue;
        const std::size_t cell = std::size_t(y) * R + x;
        if (score <= best[cell]) continue;
        best[cell] = score;
        float l0 = std::max(lambda[0], 0.0f), l1 = std::max(lambda[1], 0.0f), l2 = std::max(lambda[2], 0.0f);
        const float sum = l0 + l1 + l2;
        anchor[cell] = {static_cast<std::uint32_t>(t), l1 / sum, l2 / sum};
      }
  }
  // Model only what the scene requires: a mask's bare cells get no state.
  std::vector<float> mask;
  if (object.phosphor_mask)
    mask = SampleMaskGrid(*object.phosphor_mask, mesh.v_up, R,
                          geometry.scene().source + ": objects[" + std::to_string(o) + "] '" + object.name + "'");
  // A map's pixels without a decay are bare too: the measured sample did not glow there.
  const PhosphorMap* map = object.phosphor_map.get();
  auto map_pixel = [&](std::size_t cell) {
    const float u = (static_cast<float>(cell % R) + 0.5f) / static_cast<float>(R);
    const float v = (static_cast<float>(cell / R) + 0.5f) / static_cast<float>(R);
    return map->PixelAt(u, v, mesh.v_up);
  };
  texels.uv_index.assign(std::size_t(R) * R, -1);
  for (std::size_t cell = 0; cell < best.size(); ++cell) {
    if (best[cell] == -1e30f) continue;
    const std::size_t pixel = map ? map_pixel(cell) : 0;
    if ((!mask.empty() && !(mask[cell] > 0)) || (map && !map->Decays(pixel))) {
      texels.uv_index[cell] = kMaskedOut;
      ++texels.masked_out;
      texels.bare_anchors.push_back(anchor[cell]);
      continue;
    }
    texels.uv_index[cell] = static_cast<std::int32_t>(texels.anchors.size());
    texels.anchors.push_back(anchor[cell]);
    if (!mask.empty()) texels.coverage.push_back(mask[cell]);
    if (map) texels.map_pixel.push_back(static_cast<std::uint32_t>(pixel));
  }
  texels.count = texels.anchors.size();
  if (object.phosphor_mask && texels.count == 0)
    ThrowUserError(geometry.scene().source, "objects[" + std::to_string(o) + "].phosphor_mask",
                   "the mask '" + object.phosphor_mask->string() + "' is 0 wherever the mesh's UV map lies");
  if (map && texels.count == 0)
    ThrowUserError(geometry.scene().source, "objects[" + std::to_string(o) + "].phosphor_map",
                   "the map '" + map->file.string() + "' has no pixel with a decay wherever the mesh's UV map lies");
}

std::size_t TexelAtlas::UvTexelOf(const ObjectTexels& o, int triangle, float b1, float b2) {
  const Eigen::Vector2f uv = (1 - b1 - b2) * o.uv_corners[3 * triangle] + b1 * o.uv_corners[3 * triangle + 1] +
                             b2 * o.uv_corners[3 * triangle + 2];
  const int R = o.uv_resolution;
  const int x = std::clamp(static_cast<int>(uv.x()), 0, R - 1), y = std::clamp(static_cast<int>(uv.y()), 0, R - 1);
  const std::int32_t texel = o.uv_index[std::size_t(y) * R + x];
  if (texel >= 0) return static_cast<std::size_t>(texel);
  if (texel == kMaskedOut) return kNoTexel;
  // Rounding at a chart's border: the nearest stored neighbour.
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      const int xx = std::clamp(x + dx, 0, R - 1), yy = std::clamp(y + dy, 0, R - 1);
      if (o.uv_index[std::size_t(yy) * R + xx] >= 0)
        return static_cast<std::size_t>(o.uv_index[std::size_t(yy) * R + xx]);
    }
  return o.masked() || !o.map_pixel.empty() ? kNoTexel : 0;
}

std::size_t TexelAtlas::total_texels() const {
  std::size_t total = 0;
  for (const ObjectTexels& o : objects_) total += o.count;
  return total;
}

}  // namespace phos::render
