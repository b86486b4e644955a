#pragma once
// Deep screen space on the CPU (the method's earlier chapters): the scene as
// a view-dependent cloud of surfels, splatted into a hierarchical interleaved
// framebuffer, so that near, strong interactions are computed precisely and
// far, weak ones coarsely, without building a hierarchy.
//
// Surfelization (every frame): each triangle, back-facing and grazing ones
// too, becomes surfels of roughly constant projected size, world radius
// r* = s tan(fov/2) (d + d_near) at distance d: the triangle is split m x m
// (as the texel atlas does) with m from its longest edge. A triangle smaller
// than one target surfel is the two-pass case: its fine surfel is kept with
// probability area / (pi r*^2) and then carries pi r*^2 of area, so the
// density is the target one and the expected area is exact.
//
// The hierarchical interleaved framebuffer: level l covers screen distances
// [R_{l-1}, R_l) around a surfel's projection, R_l = R_0 2^l pixels. At
// level l the pixels are split into 2^l x 2^l interleaved sub-buffers (pixel
// (x, y) belongs to (x mod 2^l, y mod 2^l)); each surfel splats its level-l
// shell into one sub-buffer only (chosen by a hash of the surfel), with its
// contribution times 4^l, so every level costs about the same. Shells stop
// at getMaxDist(surfel, epsilon), where the surfel's largest possible
// contribution falls below epsilon. Each level is then blurred over its
// 2^l x 2^l interleaving block, weighting neighbours by depth and normal
// (geometry-aware), and the levels are summed.
//
// On a CPU a splat is a scatter. phos bins the splats by screen tile and
// lets each thread own whole tiles (a gather per tile): no atomics, no
// per-thread copies of the framebuffer, and the same result in any thread
// count.
//
// Receivers are the G-buffer's pixels. Per receiver p with normal n, a
// surfel at q with normal m and area A contributes the point-to-disk form
// factor F = A cos_p |cos_q| / (pi r^2 + A) (r = |q - p|; only surfels in
// front of the receiver, cos_p > 0). Ambient occlusion sums F separately
// over the surfels facing the receiver and those it sees from behind, and
// keeps the larger sum, at most 1: a ray crosses a closed surface once from
// each side, so summing both counted every closed occluder twice (a block
// and its far side), while an open sheet seen from behind has only its back
// (dss.cpp, ResolveOcclusion). One-bounce diffuse irradiance is sum B F over
// surfels facing the receiver (cos_q < 0 seen from q), B the surfel's
// radiosity (for a phosphor, pi Lp: a glowing wall lighting a box in the dark).

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "phos/render/geometry.h"
#include "phos/render/subsurface.h"
#include "phos/util/math.h"

namespace phos::render {

struct Surfel {
  Vec3f position = Vec3f::Zero();
  Vec3f normal = Vec3f::Zero();  // the triangle's front normal
  float area = 0;
  int object = -1;
  int triangle = -1;
  float b1 = 0, b2 = 0;  // where on the triangle (its centre)
};

// The surfel's point as a hit on the front of its triangle (for looking up
// what it glows or how it is lit).
inline Hit FrontHit(const Surfel& s) {
  Hit hit;
  hit.object = s.object;
  hit.triangle = s.triangle;
  hit.b1 = s.b1;
  hit.b2 = s.b2;
  hit.position = s.position;
  hit.normal = s.normal;
  hit.front = true;
  return hit;
}

struct SurfelOptions {
  // Target radius as a fraction of tan(fov/2) per unit of distance. The
  // defaults here and in DssOptions are the study's choice (make study,
  // docs/dss-budget.csv): the lowest error over the fixture views within
  // 0.1 s at 128 px.
  float s = 0.04f;
  float d_near_m = 0.0f;  // added to the distance (keeps near surfels from becoming tiny)
  unsigned seed = 1;      // for the two-pass random discard
  int max_split = 256;    // at most m x m surfels per triangle
};

// Surfels of every object at the geometry's current time, seen from `eye`
// with vertical field of view fov_deg.
std::vector<Surfel> Surfelize(const SceneGeometry& geometry, const Vec3f& eye, float fov_deg,
                              const SurfelOptions& options);

// What the camera sees, per pixel: position, normal (facing the camera),
// depth along the ray; object -1 where the ray escapes.
struct GBuffer {
  int width = 0, height = 0;
  std::vector<Vec3f> position, normal;
  std::vector<float> depth;
  std::vector<int> object;
  // Where on the object (RenderGBuffer only): for looking up a texture.
  std::vector<int> triangle;
  std::vector<float> b1, b2;

  // Pixel p's hit as RenderGBuffer found it, on the side the camera sees
  // (taken as its front, as FrontHit takes a surfel's); p must hit.
  Hit SeenHit(std::size_t p) const {
    Hit hit;
    hit.object = object[p];
    hit.triangle = triangle[p];
    hit.b1 = b1[p];
    hit.b2 = b2[p];
    hit.distance = depth[p];
    hit.position = position[p];
    hit.normal = normal[p];
    hit.front = true;
    return hit;
  }
};
GBuffer RenderGBuffer(const SceneGeometry& geometry, const Scene& scene, double t_s);

struct DssOptions {
  int levels = 3;            // l_max + 1 levels
  float base_radius_px = 6;  // R_0
  // A single surfel contribution below epsilon is not splatted. Keep it small:
  // surfels near the camera are tiny, and many tiny contributions add up (a
  // disk of 60 000 surfels 1 m away lights its axis with 4e-6 each; 1e-5
  // lost it all).
  float epsilon = 1e-6f;
  bool blur = true;  // geometry-aware blur of the interleaved levels
  // Occlusion by direction cells (0: off). Blending sums form factors and
  // cannot tell a surfel from the one behind it (a block and the wall behind
  // count twice). With N > 0 each receiver's cosine-weighted hemisphere,
  // projected onto the unit disk (Nusselt's analogue: a surfel covers pi F
  // of it), is cut into an N x N grid; a surfel's F goes to the cells its
  // footprint (radius sqrt F) covers, and each cell counts at most its
  // share of the disk: what lies behind a covered direction counts once.
  // Costs 2 N^2 floats per pixel and level.
  int occlusion_cells = 0;
  int tile_px = 32;
  // Radiosity per surfel and channel (B, e.g. pi Lp per band), or empty for
  // occlusion only.
  int channels = 0;
  // Subsurface scattering instead of form factors (subsurface.h): the
  // surfels carry irradiance E per channel, only receivers of the surfel's
  // own object receive, with Rd(r) A per channel from dipoles[object *
  // channels + c]; `irradiance` is then the radiant exitance M.
  const std::vector<Dipole>* dipoles = nullptr;
  // With dipoles: per receiver pixel, the radius of its near field (the
  // caller adds E(x) AnnulusIntegral(0, near) itself; subsurface.h).
  const std::vector<float>* near_m = nullptr;
};

struct DssResult {
  int width = 0, height = 0, channels = 0;
  std::vector<float> occlusion;  // per pixel, in [0, 1]
  // Directional occlusion: per pixel, sum of F w_y (w the unit direction to
  // each surfel), scaled like `occlusion` where that sum exceeded 1. The sky
  // L(w) = L (1 + g w_y) then gives E = L [pi (1 - occlusion) + g (2 pi / 3 n_y
  // - pi occlusion_y)] (renderer.h's dss transport; scene.h's Environment).
  std::vector<float> occlusion_y;
  std::vector<float> irradiance;  // per pixel and channel
  std::uint64_t splats = 0;       // receiver updates, all levels
  double seconds = 0;
};

// `radiosity`: surfels.size() * options.channels values (may be empty when
// channels == 0).
DssResult SplatDeepScreenSpace(const GBuffer& gbuffer, const CameraRays& camera, const std::vector<Surfel>& surfels,
                               const std::vector<float>& radiosity, const DssOptions& options);

// Indirect visibility, the bounced z-buffer: every receiver keeps a small
// z-buffer of directions instead of sums. Its cosine-weighted hemisphere is
// projected onto the unit disk (Nusselt's analogue: a surfel covers pi F of
// it) and cut into 64 cells of equal area (8 rings x 8 sectors). A surfel
// covers the cells its footprint (radius sqrt F about its direction) holds,
// or, smaller than a cell, its share of the one it falls in; a cell keeps
// its nearest surfel (surfels within 5% of that distance add their
// coverage). Splats go through the same hierarchical interleaved shells;
// level l's maps are then merged over the 2^l x 2^l block (nearest per
// cell, geometry-aware) and the levels by nearest per cell. Occlusion is
// the covered share of the hemisphere, irradiance sum cover B / 64 over the
// cells whose surfel faces the receiver: nothing counts twice (no
// over-occlusion) and light behind a nearer surfel is hidden (no leaking).
DssResult SplatBouncedZBuffer(const GBuffer& gbuffer, const CameraRays& camera, const std::vector<Surfel>& surfels,
                              const std::vector<float>& radiosity, const DssOptions& options);

// The same sums over every surfel for every pixel, with no hierarchy: the
// exact gather DSS approximates (O(pixels x surfels), for tests and studies).
DssResult GatherAllSurfels(const GBuffer& gbuffer, const std::vector<Surfel>& surfels,
                           const std::vector<float>& radiosity, int channels,
                           const std::vector<Dipole>* dipoles = nullptr, const std::vector<float>* near_m = nullptr);

// Plain screen space (one depth layer), for the trade study: the surfels are
// the G-buffer's own pixels, each a disk of the area it covers on its
// surface; what the camera does not see does not occlude.
std::vector<Surfel> SurfelsFromGBuffer(const GBuffer& gbuffer, const CameraRays& camera);

// Monte Carlo ambient occlusion with Embree: per pixel, `rays` cosine-
// distributed rays from the visible point; occlusion is the fraction that
// hit anything (no distance limit, as DSS has none beyond epsilon). With many
// rays, the reference; with few, the "same budget" rival.
std::vector<float> RayTracedOcclusion(const SceneGeometry& geometry, const GBuffer& gbuffer, int rays, unsigned seed);

// The sky's irradiance per unit radiance through directional occlusion: the
// sky L (1 + g w_y) (scene.h's Environment) less what the surfels hide,
// E / L = pi (1 - occlusion) + g (2 pi / 3 n_y - pi occlusion_y), at least 0
// (DssResult's occlusion and occlusion_y, n_y the receiver normal's y).
inline float SkyIrradianceFromOcclusion(float occlusion, float occlusion_y, float normal_y, float gradient) {
  return std::max(0.0f, kPiF * (1 - occlusion) + gradient * (2 * kPiF / 3 * normal_y - kPiF * occlusion_y));
}

// Per receiver pixel, the radius of the subsurface near field (DssOptions::
// near_m): two target surfel radii at its depth, 2 s tan(fov/2) depth, inside
// which the caller integrates the dipole in closed form (subsurface.h's
// AnnulusIntegral); surfels carry the rest.
std::vector<float> SubsurfaceNearField(const GBuffer& gbuffer, float s, float fov_deg);

// The point-to-disk form factor above; 0 behind the receiver. Optionally
// the cosine at the surfel and the y component of the unit direction to it.
inline float SurfelFormFactor(const Vec3f& p, const Vec3f& n, const Surfel& s, float* cos_q_out = nullptr,
                              float* direction_y_out = nullptr) {
  const Vec3f d = s.position - p;
  const float r2 = d.squaredNorm();
  if (r2 <= 0) return 0;
  const float r = std::sqrt(r2);
  // A receiver with no normal is a point in a medium (volume.h's interval
  // map): it receives from every direction, F_iso = A |cos_q| / (pi r^2 + A),
  // and sum B F_iso is the radiance integrated over the sphere.
  const float cos_p = n.squaredNorm() == 0 ? 1.0f : n.dot(d) / r;
  if (cos_p <= 0) return 0;
  const float cos_q = s.normal.dot(d) / r;  // > 0: the surfel faces away from p
  if (cos_q_out) *cos_q_out = cos_q;
  if (direction_y_out) *direction_y_out = d.y() / r;
  return s.area * cos_p * std::fabs(cos_q) / (kPiF * r2 + s.area);
}

}  // namespace phos::render
