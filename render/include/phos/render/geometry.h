#pragma once
// The scene's geometry in Embree 3 at one moment, and the automatic texel
// atlas that carries the phosphors' states (Sec. 8.5).
//
// Texels: every triangle of a phosphorescent object is split into m x m
// congruent sub-triangles (m from the texel size), and each sub-triangle is
// one texel. A texel is addressed by barycentric coordinates, so it moves
// with its object for free, needs no UV map, and its lookup from a ray hit is
// O(1) arithmetic.

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "phos/render/scene.h"

namespace phos::render {

using Vec3f = Eigen::Vector3f;

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

  const Scene& scene() const { return scene_; }
  int object_count() const { return static_cast<int>(world_.size()); }
  int triangle_count(int object) const { return static_cast<int>(scene_.objects[object].mesh->triangles.size()); }
  Vec3f Vertex(int object, int triangle, int corner) const {
    return world_[object][scene_.objects[object].mesh->triangles[triangle][corner]];
  }
  Vec3f Point(int object, int triangle, float b1, float b2) const;
  Vec3f FrontNormal(int object, int triangle) const;
  float Area(int object, int triangle) const;
  // A distance to step off a surface before casting a ray from it.
  float ray_epsilon() const { return ray_epsilon_; }
  float diagonal_m() const { return diagonal_; }

 private:
  void Upload(int object);
  const Scene& scene_;
  struct Embree;
  std::unique_ptr<Embree> embree_;
  std::vector<std::vector<Vec3f>> world_;  // world-space vertices per object
  double time_s_ = 0;
  std::uint64_t version_ = 0;
  float ray_epsilon_ = 1e-4f, diagonal_ = 1.0f;
};

// The texels of the phosphorescent objects.
class TexelAtlas {
 public:
  // m per triangle = ceil(triangle edge scale / texel size), at least 1.
  TexelAtlas(const Scene& scene, const SceneGeometry& geometry);

  struct ObjectTexels {
    int object = -1;
    std::vector<std::uint32_t> first;  // per triangle: index of its first texel within the object
    std::vector<std::uint16_t> m;      // per triangle: subdivisions
    std::size_t count = 0;             // texels of the object
  };
  // Index into objects() of a phosphorescent object, or -1.
  int SlotOf(int object) const { return slot_[object]; }
  const std::vector<ObjectTexels>& objects() const { return objects_; }
  std::size_t total_texels() const;
  // Texel of a hit on object slot s.
  std::size_t TexelOf(int slot, int triangle, float b1, float b2) const {
    const ObjectTexels& o = objects_[slot];
    return o.first[triangle] + static_cast<std::size_t>(SubTriangleIndex(o.m[triangle], b1, b2));
  }

 private:
  std::vector<int> slot_;
  std::vector<ObjectTexels> objects_;
};

}  // namespace phos::render
