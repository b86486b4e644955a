#include "phos/render/dss.h"
#include "phos/util/math.h"
#include "phos/util/random.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>

#include "sampling.h"

namespace phos::render {

std::vector<Surfel> Surfelize(const SceneGeometry& geometry, const Vec3f& eye, float fov_deg,
                              const SurfelOptions& options) {
  const float tan_half = std::tan(fov_deg * kPiF / 360.0f);
  std::vector<Surfel> surfels;
  for (int o = 0; o < geometry.object_count(); ++o) {
    for (int t = 0; t < geometry.triangle_count(o); ++t) {
      const Vec3f a = geometry.Vertex(o, t, 0), b = geometry.Vertex(o, t, 1), c = geometry.Vertex(o, t, 2);
      const float area = geometry.Area(o, t);
      if (!(area > 0)) continue;
      const Vec3f n = geometry.FrontNormal(o, t);
      // A two-sided sheet (Object::two_sided) sends from both faces: a twin
      // surfel facing the other way at each place.
      const bool twin = geometry.scene().objects[o].two_sided;
      const float d = ((a + b + c) / 3.0f - eye).norm();
      const float r_star = std::max(1e-6f, options.s * tan_half * (d + options.d_near_m));
      const float target_area = kPiF * r_star * r_star;
      if (area < target_area) {
        // Two-pass: one fine surfel, kept with probability area / target.
        if (Hash01(options.seed, static_cast<std::uint64_t>(o), static_cast<std::uint64_t>(t)) >= area / target_area)
          continue;
        surfels.push_back({(a + b + c) / 3.0f, n, target_area, o, t, 1.0f / 3, 1.0f / 3});
        if (twin) surfels.push_back({(a + b + c) / 3.0f, -n, target_area, o, t, 1.0f / 3, 1.0f / 3});
        continue;
      }
      const float edge = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
      const int m = std::clamp(static_cast<int>(std::ceil(edge / (2 * r_star))), 1, options.max_split);
      for (int k = 0; k < m * m; ++k) {
        float b1 = 0, b2 = 0;
        SubTriangleCenter(m, k, b1, b2);
        surfels.push_back({geometry.Point(o, t, b1, b2), n, area / static_cast<float>(m * m), o, t, b1, b2});
        if (twin) surfels.push_back({geometry.Point(o, t, b1, b2), -n, area / static_cast<float>(m * m), o, t, b1, b2});
      }
    }
  }
  return surfels;
}

GBuffer RenderGBuffer(const SceneGeometry& geometry, const Scene& scene, double t_s) {
  GBuffer g;
  g.width = scene.camera.width;
  g.height = scene.camera.height;
  const std::size_t n = static_cast<std::size_t>(g.width) * g.height;
  g.position.assign(n, Vec3f::Zero());
  g.normal.assign(n, Vec3f::Zero());
  g.depth.assign(n, 0.0f);
  g.object.assign(n, -1);
  g.triangle.assign(n, -1);
  g.b1.assign(n, 0.0f);
  g.b2.assign(n, 0.0f);
  const CameraRays camera(scene, t_s);
  tbb::parallel_for(tbb::blocked_range<int>(0, g.height), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y != rows.end(); ++y)
      for (int x = 0; x < g.width; ++x) {
        const Vec3f direction = camera.Direction(x + 0.5f, y + 0.5f);
        const Hit hit = geometry.Intersect(camera.origin(), direction);
        if (!hit) continue;
        const std::size_t p = static_cast<std::size_t>(y) * g.width + x;
        g.position[p] = hit.position;
        g.normal[p] = hit.front ? hit.normal : Vec3f(-hit.normal);  // the side the camera sees
        g.depth[p] = hit.distance;
        g.object[p] = hit.object;
        g.triangle[p] = hit.triangle;
        g.b1[p] = hit.b1;
        g.b2[p] = hit.b2;
      }
  });
  return g;
}

namespace {

// Occluders are summed per side, four floats per receiver: the form factors
// of the surfels facing it (their front towards it) and their y-weighted
// sums, then those of the surfels it sees from behind. See ResolveOcclusion.
// With direction cells (DssOptions::occlusion_cells) each receiver then
// holds per cell the front and the back sum.
constexpr int kSides = 4;

// The N x N grid over the unit disk onto which a receiver's cosine-weighted
// hemisphere projects (Nusselt's analogue): per cell, its share of the disk
// (area / pi: the most a cell can be occluded) and its centroid.
struct DirectionCells {
  int n = 0;
  std::vector<float> share, x, y;
  explicit DirectionCells(int cells) : n(std::max(0, cells)) {
    share.assign(n * n, 0.0f);
    x.assign(n * n, 0.0f);
    y.assign(n * n, 0.0f);
    constexpr int kSub = 32;  // sub-samples per cell side, to measure the part inside the disk
    for (int c = 0; c < n * n; ++c) {
      int inside = 0;
      for (int i = 0; i < kSub; ++i)
        for (int j = 0; j < kSub; ++j) {
          const float u = -1 + 2 * ((c % n) + (i + 0.5f) / kSub) / n, v = -1 + 2 * ((c / n) + (j + 0.5f) / kSub) / n;
          if (u * u + v * v > 1) continue;
          ++inside;
          x[c] += u;
          y[c] += v;
        }
      share[c] = static_cast<float>(inside) * 4 / (n * n * kSub * kSub) / kPiF;
      if (inside) x[c] /= static_cast<float>(inside), y[c] /= static_cast<float>(inside);
    }
  }
  int stride() const { return kSides + 2 * n * n; }
  int CellOf(float u, float v) const {
    const int i = std::clamp(static_cast<int>((u + 1) / 2 * n), 0, n - 1),
              j = std::clamp(static_cast<int>((v + 1) / 2 * n), 0, n - 1);
    return j * n + i;
  }
};

// Adds weight F to the cells of a surfel's footprint on the unit disk: a
// disk of area pi F (radius sqrt F) about its direction (u, v), shared in
// proportion to the cells' shares; smaller than a cell, into the cell it
// falls in. (The weight, 4^l at level l, scales the amount, not the
// footprint.)
inline void AddToCells(const DirectionCells& cells, float u, float v, float F, float weight, float* sums) {
  const float radius = std::sqrt(F), half_cell = 1.0f / static_cast<float>(cells.n);
  if (radius > half_cell) {
    int covered[256], count = 0;
    float total = 0;
    for (int c = 0; c < cells.n * cells.n && count < 256; ++c)
      if (cells.share[c] > 0 && std::pow(cells.x[c] - u, 2) + std::pow(cells.y[c] - v, 2) <= radius * radius)
        covered[count++] = c, total += cells.share[c];
    if (count > 0) {
      for (int k = 0; k < count; ++k) sums[2 * covered[k]] += weight * F * cells.share[covered[k]] / total;
      return;
    }
  }
  sums[2 * cells.CellOf(u, v)] += weight * F;
}

// Accumulates one surfel into one receiver pixel, weighted; `cells` null
// without direction cells, `sides` then holds kSides floats per pixel, else
// cells->stride().
inline void Accumulate(const GBuffer& g, std::size_t p, const Surfel& s, const float* B, int channels, float weight,
                       float* sides, float* irradiance, const std::vector<Dipole>* dipoles = nullptr,
                       const std::vector<float>* near_m = nullptr, const DirectionCells* cells = nullptr) {
  if (dipoles) {
    // Subsurface: light that entered at the surfel leaves at the receiver.
    if (g.object[p] != s.object) return;
    const float r = (s.position - g.position[p]).norm();
    const Dipole* d = &(*dipoles)[static_cast<std::size_t>(s.object) * channels];
    const float near = near_m ? (*near_m)[p] : 0.0f;
    for (int c = 0; c < channels; ++c)
      irradiance[p * channels + c] += weight * d[c].SurfelKernel(r, s.area, near) * B[c];
    return;
  }
  float cos_q = 0, w_y = 0;
  const float F = SurfelFormFactor(g.position[p], g.normal[p], s, &cos_q, &w_y);
  if (F <= 0) return;
  float* record = &sides[p * (cells ? cells->stride() : kSides)];
  float* side = record + (cos_q < 0 ? 0 : 2);
  side[0] += weight * F;
  side[1] += weight * F * w_y;
  if (cells && g.normal[p].squaredNorm() > 0) {
    // The direction's point on the unit disk, in the receiver's tangent frame.
    const Vec3f n = g.normal[p], t = n.unitOrthogonal(), b = n.cross(t);
    const Vec3f w = (s.position - g.position[p]).normalized();
    AddToCells(*cells, w.dot(t), w.dot(b), F, weight, record + kSides + (cos_q < 0 ? 0 : 1));
  }
  // Light arrives from the surfel's front only (it faces the receiver).
  if (channels > 0 && cos_q < 0)
    for (int c = 0; c < channels; ++c) irradiance[p * channels + c] += weight * F * B[c];
}

// A result of zeros for W x H receivers and C channels.
DssResult EmptyResult(int width, int height, int channels) {
  DssResult r;
  r.width = width;
  r.height = height;
  r.channels = channels;
  const std::size_t n = static_cast<std::size_t>(width) * height;
  r.occlusion.assign(n, 0.0f);
  r.occlusion_y.assign(n, 0.0f);
  r.irradiance.assign(n * std::max(channels, 0), 0.0f);
  return r;
}

// Occlusion from the per-side sums. A ray from a receiver outside a closed
// surface crosses it as often from the front as from the back (it enters
// and leaves): summing both sides counted every closed occluder twice, the
// block and its far side (the floor of the ambient occlusion study, docs/
// dss-trade.md). A closed surface's back-facing surfels therefore never sum
// to more than its front-facing ones, and the front sum is the right one. An
// open sheet seen from behind (a quad facing away) has only back-facing
// surfels: then the back sum is the larger and is kept. So occlusion is the
// larger of the two sums, its directional sum with it, and above 1 (surfels
// behind surfels: visibility, which blending does not know) both are
// scaled back to 1.
//
// With direction cells the same choice is made per cell, and a cell counts
// at most its share of the disk; the directional sum takes each cell's
// occlusion along its centroid's direction.
void ResolveOcclusion(const std::vector<float>& sides, DssResult& r, const GBuffer& g,
                      const DirectionCells* cells = nullptr) {
  for (std::size_t p = 0; p < r.occlusion.size(); ++p) {
    if (cells && cells->n > 0) {
      if (g.object[p] < 0) continue;
      const float* sums = &sides[p * cells->stride() + kSides];
      const Vec3f n = g.normal[p], t = n.unitOrthogonal(), b = n.cross(t);
      float occlusion = 0, occlusion_y = 0;
      for (int c = 0; c < cells->n * cells->n; ++c) {
        const float covered = std::min(cells->share[c], std::max(sums[2 * c], sums[2 * c + 1]));
        if (!(covered > 0)) continue;
        const float u = cells->x[c], v = cells->y[c], up = std::sqrt(std::max(0.0f, 1 - u * u - v * v));
        occlusion += covered;
        occlusion_y += covered * (u * t + v * b + up * n).y();
      }
      r.occlusion[p] = std::min(1.0f, occlusion);
      r.occlusion_y[p] = occlusion_y;
      continue;
    }
    const float* side = &sides[p * kSides];
    const float* kept = side[2] > side[0] ? side + 2 : side;
    r.occlusion[p] = kept[0];
    r.occlusion_y[p] = kept[1];
    if (r.occlusion[p] > 1) {
      r.occlusion_y[p] /= r.occlusion[p];
      r.occlusion[p] = 1;
    }
  }
}

}  // namespace

DssResult GatherAllSurfels(const GBuffer& g, const std::vector<Surfel>& surfels, const std::vector<float>& radiosity,
                           int channels, const std::vector<Dipole>* dipoles, const std::vector<float>* near_m) {
  const auto started = std::chrono::steady_clock::now();
  DssResult r = EmptyResult(g.width, g.height, channels);
  const std::size_t n = static_cast<std::size_t>(g.width) * g.height;
  std::vector<float> sides(n * kSides, 0.0f);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t p = range.begin(); p != range.end(); ++p) {
      if (g.object[p] < 0) continue;
      for (std::size_t s = 0; s < surfels.size(); ++s)
        Accumulate(g, p, surfels[s], channels > 0 ? &radiosity[s * channels] : nullptr, channels, 1.0f, sides.data(),
                   r.irradiance.data(), dipoles, near_m);
    }
  });
  ResolveOcclusion(sides, r, g);
  r.splats = static_cast<std::uint64_t>(n) * surfels.size();
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  return r;
}

namespace {

// Per surfel: its world radius per level and the screen rectangle each
// level's shell can reach.
struct Reach {
  float rho[8];      // shell outer radius per level (world)
  int rect[8][4];    // x0, y0, x1, y1 per level (inclusive)
  int offset[8][2];  // interleave offset per level
  float r_max;
  bool any;
};

std::vector<Reach> ComputeReach(const GBuffer& g, const CameraRays& camera, const std::vector<Surfel>& surfels,
                                const std::vector<float>& radiosity, const DssOptions& options) {
  // Per surfel: its world radius per level and the screen rectangle each
  // level's shell can reach (conservative: the bounding square of the
  // sphere's projection; the whole screen when the sphere reaches the eye).
  const int W = g.width, H = g.height, L = std::max(1, options.levels), C = std::max(0, options.channels);
  const float pixel_scale = H / (2 * camera.tan_half_y());  // pixels per unit of lateral size at depth 1
  std::vector<Reach> reach(surfels.size());
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, surfels.size()), [&](const tbb::blocked_range<std::size_t>& range) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
          const Surfel& s = surfels[i];
          Reach& R = reach[i];
          // getMaxDist: F <= A / (pi r^2) < epsilon beyond this distance; for
          // the dipole, where Rd(r) A falls below epsilon (per unit of E).
          R.r_max = std::sqrt(s.area / (kPiF * options.epsilon));
          if (options.dipoles) {
            R.r_max = 0;
            for (int c = 0; c < C; ++c) {
              const float E = radiosity[i * C + c];
              if (E > 0)
                R.r_max = std::max(R.r_max, (*options.dipoles)[static_cast<std::size_t>(s.object) * C + c].MaxDistance(
                                                s.area * E, options.epsilon));
            }
          }
          float x = 0, y = 0, depth = 0;
          const bool in_front = camera.Project(s.position, &x, &y, &depth);
          // R_0 pixels at the surfel's depth, in world units.
          const float rho0 = options.base_radius_px * std::max(depth, 1e-6f) / pixel_scale;
          R.any = false;
          for (int l = 0; l < L && l < 8; ++l) {
            R.rho[l] = l == L - 1 ? R.r_max : std::min(R.r_max, rho0 * static_cast<float>(1 << l));
            const float inner = l == 0 ? 0.0f : std::min(R.r_max, rho0 * static_cast<float>(1 << (l - 1)));
            const int block = 1 << l;
            R.offset[l][0] = static_cast<int>(Hash01(i, static_cast<std::uint64_t>(l), 1) * block);
            R.offset[l][1] = static_cast<int>(Hash01(i, static_cast<std::uint64_t>(l), 2) * block);
            if (inner >= R.r_max) {
              R.rect[l][0] = 1;
              R.rect[l][2] = 0;  // empty
              continue;
            }
            const float rho = R.rho[l];
            if (!in_front || depth - rho <= 1e-4f) {
              R.rect[l][0] = 0;
              R.rect[l][1] = 0;
              R.rect[l][2] = W - 1;
              R.rect[l][3] = H - 1;
            } else {
              const float half = rho * pixel_scale / (depth - rho) + 1;
              R.rect[l][0] = std::max(0, static_cast<int>(std::floor(x - half)));
              R.rect[l][1] = std::max(0, static_cast<int>(std::floor(y - half)));
              R.rect[l][2] = std::min(W - 1, static_cast<int>(std::ceil(x + half)));
              R.rect[l][3] = std::min(H - 1, static_cast<int>(std::ceil(y + half)));
            }
            R.any = R.any || (R.rect[l][0] <= R.rect[l][2] && R.rect[l][1] <= R.rect[l][3]);
          }
        }
      });

  return reach;
}

// Tiles own their pixels: each thread gathers, for its tile, the shells
// that reach it, so no two threads write the same pixel. Calls
// visit(p, i, l, weight) for every receiver pixel p inside level l's shell
// of surfel i and in its sub-buffer (weight 4^l); returns the count.
template <typename Visit>
std::uint64_t GatherShells(const GBuffer& g, const std::vector<Surfel>& surfels, const std::vector<Reach>& reach,
                           int levels, int tile_px, Visit&& visit) {
  const int W = g.width, H = g.height, L = std::min(levels, 8);
  const int T = std::max(8, tile_px);
  const int tiles_x = (W + T - 1) / T, tiles_y = (H + T - 1) / T;
  std::atomic<std::uint64_t> splats{0};
  tbb::parallel_for(tbb::blocked_range<int>(0, tiles_x * tiles_y), [&](const tbb::blocked_range<int>& range) {
    std::uint64_t local = 0;
    for (int tile = range.begin(); tile != range.end(); ++tile) {
      const int tx0 = (tile % tiles_x) * T, ty0 = (tile / tiles_x) * T;
      const int tx1 = std::min(W - 1, tx0 + T - 1), ty1 = std::min(H - 1, ty0 + T - 1);
      for (std::size_t i = 0; i < surfels.size(); ++i) {
        const Reach& R = reach[i];
        if (!R.any) continue;
        const Surfel& s = surfels[i];
        for (int l = 0; l < L; ++l) {
          const int* rect = R.rect[l];
          const int x0 = std::max(rect[0], tx0), y0 = std::max(rect[1], ty0);
          const int x1 = std::min(rect[2], tx1), y1 = std::min(rect[3], ty1);
          if (x0 > x1 || y0 > y1) continue;
          const int block = 1 << l;
          const float inner = l == 0 ? 0.0f : R.rho[l - 1];
          const float inner2 = inner * inner, outer2 = R.rho[l] * R.rho[l];
          const float weight = static_cast<float>(block * block);
          // First pixel of this surfel's sub-buffer at or after (x0, y0).
          const int sx = x0 + ((R.offset[l][0] - x0) % block + block) % block;
          const int sy = y0 + ((R.offset[l][1] - y0) % block + block) % block;
          for (int y = sy; y <= y1; y += block)
            for (int x = sx; x <= x1; x += block) {
              const std::size_t p = static_cast<std::size_t>(y) * W + x;
              if (g.object[p] < 0) continue;
              const float r2 = (s.position - g.position[p]).squaredNorm();
              if (r2 < inner2 || r2 >= outer2) continue;
              visit(p, i, l, weight);
              ++local;
            }
        }
      }
    }
    splats += local;
  });
  return splats;
}

}  // namespace

DssResult SplatDeepScreenSpace(const GBuffer& g, const CameraRays& camera, const std::vector<Surfel>& surfels,
                               const std::vector<float>& radiosity, const DssOptions& options) {
  const auto started = std::chrono::steady_clock::now();
  const int W = g.width, H = g.height, L = std::max(1, options.levels), C = std::max(0, options.channels);
  const std::size_t n = static_cast<std::size_t>(W) * H;
  // One accumulation buffer per level (they are blurred separately).
  const DirectionCells cells(options.dipoles ? 0 : options.occlusion_cells);
  const DirectionCells* cells_used = cells.n > 0 ? &cells : nullptr;
  const int S = cells_used ? cells.stride() : kSides;  // floats per pixel of occlusion sums
  std::vector<std::vector<float>> sides(L, std::vector<float>(n * S, 0.0f));
  std::vector<std::vector<float>> irradiance(L, std::vector<float>(n * C, 0.0f));

  const std::vector<Reach> reach = ComputeReach(g, camera, surfels, radiosity, options);

  const std::uint64_t splats =
      GatherShells(g, surfels, reach, L, options.tile_px, [&](std::size_t p, std::size_t i, int l, float weight) {
        Accumulate(g, p, surfels[i], C > 0 ? &radiosity[i * C] : nullptr, C, weight, sides[l].data(),
                   irradiance[l].data(), options.dipoles, options.near_m, cells_used);
      });

  // Unshuffle and blur: level l's pixels each saw a quarter^l of the shells;
  // averaging over the 2^l x 2^l block around a pixel (every sub-buffer
  // once) restores the sum, weighted by depth and normal so it does not
  // leak across edges.
  DssResult r = EmptyResult(W, H, C);
  std::vector<float> summed(n * S, 0.0f);
  for (int l = 0; l < L; ++l) {
    const int block = 1 << l;
    const bool blur = options.blur && l > 0;
    tbb::parallel_for(tbb::blocked_range<int>(0, H), [&](const tbb::blocked_range<int>& rows) {
      std::vector<float> osum(S);
      for (int y = rows.begin(); y != rows.end(); ++y)
        for (int x = 0; x < W; ++x) {
          const std::size_t p = static_cast<std::size_t>(y) * W + x;
          if (g.object[p] < 0) continue;
          if (!blur) {
            for (int k = 0; k < S; ++k) summed[p * S + k] += sides[l][p * S + k];
            for (int c = 0; c < C; ++c) r.irradiance[p * C + c] += irradiance[l][p * C + c];
            continue;
          }
          // The block of 2^l x 2^l pixels around (x, y), clamped inside the image.
          const int bx = std::clamp(x - block / 2, 0, std::max(0, W - block)),
                    by = std::clamp(y - block / 2, 0, std::max(0, H - block));
          float wsum = 0;
          std::fill(osum.begin(), osum.end(), 0.0f);
          float isum[16] = {};
          for (int v = by; v < std::min(H, by + block); ++v)
            for (int u = bx; u < std::min(W, bx + block); ++u) {
              const std::size_t q = static_cast<std::size_t>(v) * W + u;
              if (g.object[q] < 0) continue;
              const float depth_ratio = std::fabs(g.depth[q] - g.depth[p]) / std::max(g.depth[p], 1e-6f);
              // Points in a medium (no normal) are weighted by depth only.
              const float normal_w =
                  g.normal[p].squaredNorm() == 0 ? 1.0f : std::max(0.0f, g.normal[q].dot(g.normal[p]));
              const bool same = !options.dipoles || g.object[q] == g.object[p];  // translucency stays in its object
              const float w = normal_w * (depth_ratio < 0.05f && same ? 1.0f : 0.0f);
              if (w <= 0) continue;
              wsum += w;
              for (int k = 0; k < S; ++k) osum[k] += w * sides[l][q * S + k];
              for (int c = 0; c < C && c < 16; ++c) isum[c] += w * irradiance[l][q * C + c];
            }
          if (wsum > 0) {
            for (int k = 0; k < S; ++k) summed[p * S + k] += osum[k] / wsum;
            for (int c = 0; c < C && c < 16; ++c) r.irradiance[p * C + c] += isum[c] / wsum;
          }
        }
    });
  }
  ResolveOcclusion(summed, r, g, cells_used);
  r.splats = splats;
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  return r;
}

namespace {

constexpr int kRings = 8, kSectors = 8, kCells = kRings * kSectors;

// One direction cell of a receiver's bounced z-buffer.
struct ZCell {
  float distance = std::numeric_limits<float>::infinity();
  float cover = 0;
  std::int32_t surfel = -1;
};

// The cell of a point (x, y) of the unit disk: equal-area rings (r^2 in
// steps of 1 / kRings) and equal sectors.
inline int CellOf(float x, float y) {
  const int ring = std::min(kRings - 1, static_cast<int>((x * x + y * y) * kRings));
  float angle = std::atan2(y, x);
  if (angle < 0) angle += 2 * kPiF;
  const int sector = std::min(kSectors - 1, static_cast<int>(angle / (2 * kPiF) * kSectors));
  return ring * kSectors + sector;
}

struct CellCentres {
  float x[kCells], y[kCells];
  CellCentres() {
    for (int ring = 0; ring < kRings; ++ring)
      for (int sector = 0; sector < kSectors; ++sector) {
        const float r = std::sqrt((ring + 0.5f) / kRings), a = (sector + 0.5f) * 2 * kPiF / kSectors;
        x[ring * kSectors + sector] = r * std::cos(a);
        y[ring * kSectors + sector] = r * std::sin(a);
      }
  }
};

// Two surfels lie on one surface (one layer of the z-buffer) when each is
// within its neighbour's tangent plane by less than the larger radius: the
// parts of one wall that fall into one cell add up instead of hiding each
// other; a surfel behind that surface is hidden.
inline bool SameLayer(const Surfel& a, const Surfel& b) {
  const float reach = std::sqrt(std::max(a.area, b.area) / kPiF) * 1.5f;
  const Vec3f d = b.position - a.position;
  return std::fabs(d.dot(a.normal)) < reach && std::fabs(d.dot(b.normal)) < reach;
}

inline void Cover(ZCell& cell, float distance, float cover, std::int32_t surfel, const std::vector<Surfel>& surfels) {
  if (cell.surfel < 0) {
    cell = {distance, std::min(1.0f, cover), surfel};
    return;
  }
  const bool same = SameLayer(surfels[cell.surfel], surfels[surfel]);
  if (distance < cell.distance) {
    cell = {distance, std::min(1.0f, cover + (same ? cell.cover : 0.0f)), surfel};
  } else if (same) {
    cell.cover = std::min(1.0f, cell.cover + cover);
  }
}

// Splats one surfel into one receiver's map.
inline void SplatIntoMap(const GBuffer& g, std::size_t p, const Vec3f& t, const Vec3f& b,
                         const std::vector<Surfel>& surfels, std::int32_t index, float weight,
                         const CellCentres& centres, ZCell* map) {
  const Surfel& s = surfels[index];
  const Vec3f d = s.position - g.position[p];
  const float r2 = d.squaredNorm();
  if (!(r2 > 0)) return;
  const float r = std::sqrt(r2);
  const Vec3f w = d / r;
  const float cos_p = g.normal[p].dot(w);
  if (cos_p <= 0) return;
  const float F = s.area * cos_p * std::fabs(s.normal.dot(w)) / (kPiF * r2 + s.area);
  if (!(F > 0)) return;
  const float x = w.dot(t), y = w.dot(b);  // the direction's point in the unit disk
  const float radius = std::sqrt(F);       // footprint of area pi F
  constexpr float kCellRadius = 0.125f;    // sqrt(1 / kCells): a cell's equal-area radius
  if (radius < kCellRadius) {
    Cover(map[CellOf(x, y)], r, weight * F * kCells, index, surfels);
    return;
  }
  bool any = false;
  for (int c = 0; c < kCells; ++c) {
    const float dx = centres.x[c] - x, dy = centres.y[c] - y;
    if (dx * dx + dy * dy <= radius * radius) Cover(map[c], r, 1.0f, index, surfels), any = true;
  }
  if (!any) Cover(map[CellOf(x, y)], r, weight * F * kCells, index, surfels);
}

}  // namespace

DssResult SplatBouncedZBuffer(const GBuffer& g, const CameraRays& camera, const std::vector<Surfel>& surfels,
                              const std::vector<float>& radiosity, const DssOptions& options) {
  const auto started = std::chrono::steady_clock::now();
  const int W = g.width, H = g.height, L = std::max(1, std::min(options.levels, 8)), C = std::max(0, options.channels);
  const std::size_t n = static_cast<std::size_t>(W) * H;
  const std::vector<Reach> reach = ComputeReach(g, camera, surfels, radiosity, options);
  const CellCentres centres;
  // Per level, per pixel: its z-buffer of directions. And per pixel a frame.
  std::vector<std::vector<ZCell>> maps(L, std::vector<ZCell>(n * kCells));
  std::vector<Vec3f> tangent(n), bitangent(n);
  for (std::size_t p = 0; p < n; ++p) {
    if (g.object[p] < 0 || g.normal[p].squaredNorm() == 0) continue;
    tangent[p] = g.normal[p].unitOrthogonal();
    bitangent[p] = g.normal[p].cross(tangent[p]);
  }
  // A pixel of level l sees a quarter^l of the surfels: their partial
  // covers count 4^l (as the blending's weights do).
  const std::uint64_t splats =
      GatherShells(g, surfels, reach, L, options.tile_px, [&](std::size_t p, std::size_t i, int l, float weight) {
        SplatIntoMap(g, p, tangent[p], bitangent[p], surfels, static_cast<std::int32_t>(i), weight, centres,
                     &maps[l][p * kCells]);
      });

  // Merge: level l's pixel saw a quarter^l of the shells; the nearest per
  // cell over its 2^l x 2^l block (neighbours of like depth and normal)
  // stands for all of them. Then the nearest per cell over the levels.
  DssResult r = EmptyResult(W, H, C);
  tbb::parallel_for(tbb::blocked_range<int>(0, H), [&](const tbb::blocked_range<int>& rows) {
    ZCell merged[kCells];
    for (int y = rows.begin(); y != rows.end(); ++y)
      for (int x = 0; x < W; ++x) {
        const std::size_t p = static_cast<std::size_t>(y) * W + x;
        if (g.object[p] < 0) continue;
        for (ZCell& c : merged) c = ZCell{};
        for (int l = 0; l < L; ++l) {
          const int block = 1 << l;
          const int bx = std::clamp(x - block / 2, 0, std::max(0, W - block)),
                    by = std::clamp(y - block / 2, 0, std::max(0, H - block));
          for (int v = by; v < std::min(H, by + block); ++v)
            for (int u = bx; u < std::min(W, bx + block); ++u) {
              const std::size_t q = static_cast<std::size_t>(v) * W + u;
              if (g.object[q] < 0) continue;
              if (q != p &&
                  (std::fabs(g.depth[q] - g.depth[p]) > 0.05f * g.depth[p] || g.normal[q].dot(g.normal[p]) < 0.9f))
                continue;
              const ZCell* map = &maps[l][q * kCells];
              for (int c = 0; c < kCells; ++c)
                if (map[c].surfel >= 0 && map[c].distance < merged[c].distance) merged[c] = map[c];
            }
        }
        float occlusion = 0, occlusion_y = 0;
        for (int c = 0; c < kCells; ++c) {
          if (merged[c].surfel < 0) continue;
          const Surfel& s = surfels[merged[c].surfel];
          const Vec3f w = (s.position - g.position[p]).normalized();
          const float share = merged[c].cover / kCells;
          occlusion += share;
          occlusion_y += share * w.y();
          if (C > 0 && s.normal.dot(w) < 0)  // it faces the receiver
            for (int k = 0; k < C; ++k) r.irradiance[p * C + k] += share * radiosity[merged[c].surfel * C + k];
        }
        r.occlusion[p] = std::min(1.0f, occlusion);
        r.occlusion_y[p] = occlusion_y;
      }
  });
  r.splats = splats;
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  return r;
}

std::vector<float> SubsurfaceNearField(const GBuffer& g, float s, float fov_deg) {
  const float tan_half = std::tan(fov_deg * kPiF / 360.0f);
  std::vector<float> near(g.depth.size(), 0.0f);
  for (std::size_t p = 0; p < near.size(); ++p) near[p] = 2 * s * tan_half * g.depth[p];
  return near;
}

std::vector<Surfel> SurfelsFromGBuffer(const GBuffer& g, const CameraRays& camera) {
  std::vector<Surfel> surfels;
  const float pixel = 2 * camera.tan_half_y() / g.height;  // lateral size of a pixel at depth 1
  for (int y = 0; y < g.height; ++y)
    for (int x = 0; x < g.width; ++x) {
      const std::size_t p = static_cast<std::size_t>(y) * g.width + x;
      if (g.object[p] < 0) continue;
      const Vec3f view = (g.position[p] - camera.origin()).normalized();
      const float cos_view = std::max(0.05f, std::fabs(view.dot(g.normal[p])));
      float px = 0, py = 0, depth = 0;
      camera.Project(g.position[p], &px, &py, &depth);
      const float side = pixel * depth;
      surfels.push_back({g.position[p], g.normal[p], side * side / cos_view, g.object[p], -1, 0, 0});
    }
  return surfels;
}

std::vector<float> RayTracedOcclusion(const SceneGeometry& geometry, const GBuffer& g, int rays, unsigned seed) {
  const std::size_t n = static_cast<std::size_t>(g.width) * g.height;
  std::vector<float> occlusion(n, 0.0f);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t p = range.begin(); p != range.end(); ++p) {
      if (g.object[p] < 0) continue;
      const Vec3f nrm = g.normal[p];
      const TangentFrame frame(nrm);
      const Vec3f origin = g.position[p] + geometry.ray_epsilon() * nrm;
      int hits = 0;
      for (int k = 0; k < rays; ++k) {
        const float u1 = Hash01(seed, p, 2 * static_cast<std::uint64_t>(k)),
                    u2 = Hash01(seed, p, 2 * static_cast<std::uint64_t>(k) + 1);
        const Vec3f d = SampleCosineHemisphere(frame, u1, u2);
        hits += geometry.Occluded(origin, d, 1e30f);
      }
      occlusion[p] = static_cast<float>(hits) / static_cast<float>(std::max(rays, 1));
    }
  });
  return occlusion;
}

}  // namespace phos::render
