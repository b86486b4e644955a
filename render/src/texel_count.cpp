// How many texels a scene's phosphors take, counted from the scene alone
// (no geometry built), so that the loader, --check and the texel atlas
// refuse a scene past the limits before anything is allocated
// (docs/formats.md). Apart from geometry.cpp, which needs Embree, so the
// fuzz harnesses (fuzz/) build the scene loader with it.

#include "texel_count.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <Eigen/Geometry>

#include "phos/render/scene.h"
#include "phos/util/error.h"

namespace phos::render {

using Vec3f = Eigen::Vector3f;

// Texels along each edge of a triangle of the auto atlas: its longest edge
// over the texel size, so texels are never longer than asked (1 to 4096).
int AutoSubdivisions(float longest_m, double texel_size_m) {
  return std::clamp(static_cast<int>(std::ceil(longest_m / texel_size_m)), 1, 4096);
}

// Texels per UV unit of a UV atlas: the object's uv_resolution, or texels of
// about texel_size_m, from the ratio of world area to UV area (1 to 8192).
int UvResolution(const Object& object, double world_area, double texel_size_m) {
  if (object.uv_resolution > 0) return object.uv_resolution;
  const Mesh& mesh = *object.mesh;
  double uv_area = 0;
  for (std::size_t t = 0; t < mesh.uv_triangles.size(); ++t) {
    const Eigen::Vector2f a = mesh.uvs[mesh.uv_triangles[t][0]], b = mesh.uvs[mesh.uv_triangles[t][1]],
                          c = mesh.uvs[mesh.uv_triangles[t][2]];
    uv_area += 0.5 * std::abs((b - a).x() * (c - a).y() - (b - a).y() * (c - a).x());
  }
  return std::clamp(static_cast<int>(std::ceil(std::sqrt(world_area / std::max(uv_area, 1e-12)) / texel_size_m)), 1,
                    8192);
}

bool UsesUvMap(const Object& object) {
  return object.texels == "uv" || (object.texels.empty() && UvMapIsOneToOne(*object.mesh));
}

std::vector<std::size_t> CountTexels(const Scene& scene) {
  // World vertices at the start, as SceneGeometry places them (in float).
  std::vector<std::vector<Vec3f>> world(scene.objects.size());
  Eigen::AlignedBox3f box;
  for (std::size_t o = 0; o < scene.objects.size(); ++o) {
    const Object& object = scene.objects[o];
    const Eigen::Affine3f transform = object.motion.At(scene.start_s).cast<float>();
    world[o].reserve(object.mesh->positions.size());
    for (const Vec3f& p : object.mesh->positions) box.extend(world[o].emplace_back(transform * p));
  }
  const float diagonal_m = std::max(box.diagonal().norm(), 1e-6f);
  const double default_size = scene.texel_size_m > 0 ? scene.texel_size_m : diagonal_m / 200.0;
  std::vector<std::size_t> counts(scene.objects.size(), 0);
  for (std::size_t o = 0; o < scene.objects.size(); ++o) {
    const Object& object = scene.objects[o];
    if (!object.phosphor) continue;
    const double size = object.texel_size_m > 0 ? object.texel_size_m : default_size;
    const std::vector<Vec3f>& v = world[o];
    double world_area = 0;
    std::size_t count = 0;
    for (const Eigen::Vector3i& t : object.mesh->triangles) {
      const Vec3f e[3] = {v[t[1]] - v[t[0]], v[t[2]] - v[t[1]], v[t[0]] - v[t[2]]};
      world_area += 0.5f * e[0].cross(-e[2]).norm();
      const std::size_t m = AutoSubdivisions(std::max({e[0].norm(), e[1].norm(), e[2].norm()}), size);
      count += m * m;
    }
    if (UsesUvMap(object)) {
      const std::size_t R = UvResolution(object, world_area, size);
      count = R * R;
    }
    counts[o] = count;
  }
  return counts;
}

void CheckTexelLimits(const Scene& scene) {
  const std::vector<std::size_t> counts = CountTexels(scene);
  std::size_t total = 0, largest = 0;
  for (std::size_t o = 0; o < counts.size(); ++o) {
    total += counts[o];
    if (counts[o] > counts[largest]) largest = o;
  }
  const std::size_t lights = std::max<std::size_t>(scene.lights.size(), 1);
  if (total <= kMaxTexels && total <= kMaxTexelLights / lights) return;
  const Object& object = scene.objects[largest];
  const std::string o = "objects[" + std::to_string(largest) + "]";
  const std::string field = object.uv_resolution > 0 && UsesUvMap(object) ? o + ".uv_resolution"
                            : object.texel_size_m > 0                     ? o + ".texel_size_m"
                                                                          : "texel_size_m";
  std::string why = "the phosphors would have " + std::to_string(total) + " texels ('" + object.name + "' " +
                    std::to_string(counts[largest]) + " of them), ";
  if (total > kMaxTexels)
    why += "more than the limit of " + std::to_string(kMaxTexels);
  else
    why += "times " + std::to_string(lights) + " lights more than the limit of " + std::to_string(kMaxTexelLights) +
           " texel-lights (each light's irradiance is kept per texel)";
  ThrowUserError(scene.source, field, why + "; choose a larger texel size");
}

}  // namespace phos::render
