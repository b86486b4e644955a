#include "phos/render/volume.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "phos/render/renderer.h"
#include "phos/util/error.h"
#include "phos/util/random.h"

namespace phos::render {

VolumeGrid::VolumeGrid(const Volume& volume) : volume_(&volume) {
  min_ = volume.min_m.cast<float>();
  max_ = volume.max_m.cast<float>();
  voxel_ = (max_ - min_).cwiseQuotient(Vec3f(volume.nx, volume.ny, volume.nz));
  inv_voxel_ = voxel_.cwiseInverse();
  min_voxel_ = voxel_.minCoeff();
}

float VolumeGrid::Sample(const float* field, const Vec3f& p) const {
  if ((p.array() < min_.array()).any() || (p.array() > max_.array()).any()) return 0.0f;
  const int n[3] = {volume_->nx, volume_->ny, volume_->nz};
  int i0[3], i1[3];
  float f[3];
  for (int a = 0; a < 3; ++a) {
    const float u = std::clamp((p[a] - min_[a]) * inv_voxel_[a] - 0.5f, 0.0f, static_cast<float>(n[a] - 1));
    i0[a] = std::min(static_cast<int>(u), n[a] - 1);
    i1[a] = std::min(i0[a] + 1, n[a] - 1);
    f[a] = u - static_cast<float>(i0[a]);
  }
  auto at = [&](int x, int y, int z) { return field[(static_cast<std::size_t>(z) * n[1] + y) * n[0] + x]; };
  const float c00 = at(i0[0], i0[1], i0[2]) * (1 - f[0]) + at(i1[0], i0[1], i0[2]) * f[0];
  const float c10 = at(i0[0], i1[1], i0[2]) * (1 - f[0]) + at(i1[0], i1[1], i0[2]) * f[0];
  const float c01 = at(i0[0], i0[1], i1[2]) * (1 - f[0]) + at(i1[0], i0[1], i1[2]) * f[0];
  const float c11 = at(i0[0], i1[1], i1[2]) * (1 - f[0]) + at(i1[0], i1[1], i1[2]) * f[0];
  return (c00 * (1 - f[1]) + c10 * f[1]) * (1 - f[2]) + (c01 * (1 - f[1]) + c11 * f[1]) * f[2];
}

bool VolumeGrid::Clip(const Vec3f& origin, const Vec3f& direction, float t_max, float* t0, float* t1) const {
  float lo = 0, hi = t_max;
  for (int a = 0; a < 3; ++a) {
    if (direction[a] == 0) {
      if (origin[a] < min_[a] || origin[a] > max_[a]) return false;
      continue;
    }
    const float inv = 1.0f / direction[a];
    float ta = (min_[a] - origin[a]) * inv, tb = (max_[a] - origin[a]) * inv;
    if (ta > tb) std::swap(ta, tb);
    lo = std::max(lo, ta);
    hi = std::min(hi, tb);
  }
  *t0 = lo;
  *t1 = hi;
  return hi > lo;
}

Vec3f VolumeGrid::VoxelCentre(std::size_t index) const {
  const std::size_t nx = volume_->nx, ny = volume_->ny;
  const std::size_t x = index % nx, y = (index / nx) % ny, z = index / (nx * ny);
  return min_ + Vec3f(x + 0.5f, y + 0.5f, z + 0.5f).cwiseProduct(voxel_);
}

// A phosphorescent medium: states of the voxels whose density is above zero.
struct VolumeMedia::Phosphor {
  std::vector<std::uint32_t> voxels;  // grid index of each state
  std::vector<int> excitation_bands, emission_bands, emission_index;
  BatchCoefficients<float> coefficients;
  StateBatch<float> states;
  std::vector<float> E;                // [n_exc * n]
  std::vector<float> unit;             // [n]: one light's, scratch
  std::vector<float> Lp;               // [n_em * n]
  std::vector<float> Lp_grid;          // [n_em * voxels of the grid]: sampled by the marches
  std::vector<std::int32_t> state_of;  // per grid voxel: index into voxels, or -1
};

VolumeMedia::VolumeMedia(const Scene& scene, const SceneGeometry& geometry, MarchOptions options)
    : scene_(scene), geometry_(geometry), options_(options), nb_(scene.bands.band_count()) {
  grids_.reserve(scene.volumes.size());
  for (const Volume& v : scene.volumes) grids_.emplace_back(v);
  caches_.assign(scene.volumes.size(), std::vector<LightCache>(scene.lights.size()));
  poses_.resize(scene.lights.size());
  levels_.assign(scene.lights.size(), 0.0f);
  // Light is needed at the voxels whose trilinear neighbourhood has density.
  for (const Volume& v : scene.volumes) {
    std::vector<std::uint8_t> needs(v.voxel_count(), 0);
    for (int z = 0; z < v.nz; ++z)
      for (int y = 0; y < v.ny; ++y)
        for (int x = 0; x < v.nx; ++x) {
          if (!(v.density[(static_cast<std::size_t>(z) * v.ny + y) * v.nx + x] > 0)) continue;
          for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
              for (int dx = -1; dx <= 1; ++dx) {
                const int X = x + dx, Y = y + dy, Z = z + dz;
                if (X < 0 || Y < 0 || Z < 0 || X >= v.nx || Y >= v.ny || Z >= v.nz) continue;
                needs[(static_cast<std::size_t>(Z) * v.ny + Y) * v.nx + X] = 1;
              }
        }
    stats_.voxels += v.voxel_count();
    stats_.lit_voxels += static_cast<std::size_t>(std::count(needs.begin(), needs.end(), 1));
    needs_light_.push_back(std::move(needs));
  }

  // Bands the lights ever put light into (as the coupled solver does).
  std::vector<bool> lit(nb_, false);
  for (const Light& light : scene.lights) {
    bool ever_on = light.schedule.keys.empty();
    for (const auto& key : light.schedule.keys) ever_on = ever_on || key.level > 0;
    if (ever_on)
      for (int b = 0; b < nb_; ++b) lit[b] = lit[b] || light.E_per_band[b] > 0;
  }
  for (std::size_t vi = 0; vi < scene.volumes.size(); ++vi) {
    const Volume& v = scene.volumes[vi];
    if (!v.phosphor) {
      phosphors_.push_back(nullptr);
      continue;
    }
    Material material = *v.phosphor;
    if (v.unknown_ke_as_zero) AssumeUnknownKeZero(material);
    auto p = std::make_unique<Phosphor>();
    p->state_of.assign(v.voxel_count(), -1);
    for (std::size_t j = 0; j < v.voxel_count(); ++j)
      if (v.density[j] > 0) {
        p->state_of[j] = static_cast<std::int32_t>(p->voxels.size());
        p->voxels.push_back(static_cast<std::uint32_t>(j));
      }
    p->emission_index.assign(nb_, -1);
    for (int b = 0; b < nb_; ++b) {
      bool excites = false, emits = false;
      for (const ExcitedState& state : material.states) {
        excites = excites || !state.ke[b] || *state.ke[b] > 0;
        emits = emits || state.Lambda[b] > 0;
      }
      if (lit[b] && excites) p->excitation_bands.push_back(b);
      if (emits) {
        p->emission_index[b] = static_cast<int>(p->emission_bands.size());
        p->emission_bands.push_back(b);
      }
    }
    const std::string where =
        scene.source + ": volume '" + v.name + "' (" + v.phosphor_path + ") lit by the scene's lights";
    RequireKnownKe(scene, material, p->excitation_bands, where);
    p->coefficients =
        BatchCoefficients<float>::Compile(material, p->excitation_bands, p->emission_bands, where, kUnknownKeRemedy);
    const std::size_t n = p->voxels.size();
    p->states = StateBatch<float>(material.state_count(), n, 0.0f);
    p->E.assign(p->excitation_bands.size() * n, 0.0f);
    p->Lp.assign(p->emission_bands.size() * n, 0.0f);
    p->Lp_grid.assign(p->emission_bands.size() * v.voxel_count(), 0.0f);
    stats_.phosphor_voxels += n;
    phosphors_.push_back(std::move(p));
  }
}

VolumeMedia::~VolumeMedia() = default;

void VolumeMedia::set_march_options(const MarchOptions& options) {
  options_ = options;
  for (auto& per_light : caches_)
    for (LightCache& cache : per_light) cache.valid = false;
}

float VolumeMedia::MediaOpticalDepth(const Vec3f& origin, const Vec3f& direction, float t_max) const {
  float tau = 0;
  for (const VolumeGrid& grid : grids_) {
    float t0, t1;
    if (!grid.Clip(origin, direction, t_max, &t0, &t1)) continue;
    const float step = options_.step_scale * grid.min_voxel_m();
    const int n = std::max(1, static_cast<int>(std::ceil((t1 - t0) / step)));
    const float ds = (t1 - t0) / static_cast<float>(n);
    float sum = 0;
    for (int k = 0; k < n; ++k) sum += grid.Density(origin + (t0 + (static_cast<float>(k) + 0.5f) * ds) * direction);
    tau += sum * ds * static_cast<float>(grid.volume().sigma_t_per_m);
  }
  return tau;
}

float VolumeMedia::Transmittance(const Vec3f& a, const Vec3f& b) const {
  const Vec3f d = b - a;
  const float length = d.norm();
  if (!(length > 0)) return 1.0f;
  return std::exp(-MediaOpticalDepth(a, d / length, length));
}

float VolumeMedia::TransmittanceToInfinity(const Vec3f& a, const Vec3f& direction) const {
  return std::exp(-MediaOpticalDepth(a, direction, 1e30f));
}

void VolumeMedia::UpdateLight(int vi, int l, const LightPose& pose) {
  LightCache& cache = caches_[vi][l];
  // A sheet's slab is applied where the light is used: its position does not
  // change the transmittance along its direction.
  LightPose key = pose;
  key.sheet_offset = 0;
  if (cache.valid && cache.pose == key && cache.version == geometry_.version()) return;
  const VolumeGrid& grid = grids_[vi];
  const std::vector<std::uint8_t>& needs = needs_light_[vi];
  cache.unit.assign(needs.size(), 0.0f);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, needs.size(), 512),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t j = r.begin(); j != r.end(); ++j) {
                        if (!needs[j]) continue;
                        const Vec3f p = grid.VoxelCentre(j);
                        if (pose.positional()) {
                          const Vec3f d = pose.at - p;
                          const float distance2 = d.squaredNorm(), distance = std::sqrt(distance2);
                          if (!(distance > 0)) continue;
                          const Vec3f w = d / distance;
                          const float falloff = pose.SpotFalloff(-w) * pose.RangeWindow(distance);
                          if (!(falloff > 0) || geometry_.Occluded(p, w, distance * (1 - 1e-4f))) continue;
                          cache.unit[j] = falloff * std::exp(-MediaOpticalDepth(p, w, distance)) / distance2;
                        } else {
                          const Vec3f w = -pose.at;
                          if (geometry_.Occluded(p, w, 1e30f)) continue;
                          cache.unit[j] = std::exp(-MediaOpticalDepth(p, w, 1e30f));
                        }
                      }
                    });
  cache.pose = key;
  cache.version = geometry_.version();
  cache.valid = true;
  ++stats_.light_updates;
}

void VolumeMedia::PrepareLighting(double t_s) {
  for (std::size_t l = 0; l < scene_.lights.size(); ++l) {
    const Light& light = scene_.lights[l];
    levels_[l] = static_cast<float>(light.schedule.LevelAt(t_s));
    poses_[l] = PoseAt(light, t_s);
    if (levels_[l] <= 0) continue;
    for (std::size_t v = 0; v < grids_.size(); ++v) UpdateLight(static_cast<int>(v), static_cast<int>(l), poses_[l]);
  }
}

int VolumeMedia::Segments(const Vec3f& origin, const Vec3f& direction, float t_max, Segment* segments) const {
  int count = 0;
  for (std::size_t v = 0; v < grids_.size() && count < kMaxSegments; ++v) {
    float t0, t1;
    if (grids_[v].Clip(origin, direction, t_max, &t0, &t1)) segments[count++] = {t0, t1, static_cast<int>(v)};
  }
  // Front to back (overlapping media are marched one after the other).
  std::sort(segments, segments + count, [](const Segment& a, const Segment& b) { return a.t0 < b.t0; });
  return count;
}

float VolumeMedia::March(const Vec3f& origin, const Vec3f& direction, float t_max, float jitter, float* L) const {
  Segment segments[kMaxSegments];
  const int count = Segments(origin, direction, t_max, segments);
  float T = 1;
  float J[64];
  for (int s = 0; s < count && T > 1e-7f; ++s) {
    const VolumeGrid& grid = grids_[segments[s].volume];
    const Volume& v = grid.volume();
    const Phosphor* phosphor = phosphors_[segments[s].volume].get();
    const auto& caches = caches_[segments[s].volume];
    const float step = options_.step_scale * grid.min_voxel_m();
    const float t0 = segments[s].t0, t1 = segments[s].t1;
    const int n = std::max(1, static_cast<int>(std::ceil((t1 - t0) / step)));
    const float ds = (t1 - t0) / static_cast<float>(n);
    for (int k = 0; k < n && T > 1e-7f; ++k) {
      const Vec3f p = origin + (t0 + (static_cast<float>(k) + jitter) * ds) * direction;
      const float sigma = grid.Density(p) * static_cast<float>(v.sigma_t_per_m);
      if (!(sigma > 0)) continue;
      std::fill(J, J + nb_, 0.0f);
      // Single scattering of each light: albedo E unit p_HG.
      for (std::size_t l = 0; l < caches.size(); ++l) {
        if (levels_[l] <= 0 || !caches[l].valid) continue;
        const LightPose& pose = poses_[l];
        const float unit = grid.Sample(caches[l].unit.data(), p) * pose.SheetMask(p);
        if (!(unit > 0)) continue;
        const Vec3f travel = pose.positional() ? Vec3f((p - pose.at).normalized()) : pose.at;
        const float phase = HenyeyGreenstein(travel.dot(-direction), static_cast<float>(v.g));
        const Light& light = scene_.lights[l];
        for (int b = 0; b < nb_; ++b)
          J[b] += static_cast<float>(v.albedo[b] * light.E_per_band[b]) * levels_[l] * unit * phase;
      }
      // The particles' glow: radiance Lp over their cross-section.
      if (phosphor)
        for (std::size_t e = 0; e < phosphor->emission_bands.size(); ++e)
          J[phosphor->emission_bands[e]] += grid.Sample(phosphor->Lp_grid.data() + e * v.voxel_count(), p);
      const float absorbed = -std::expm1(-sigma * ds);  // 1 - e^{-sigma ds}, exact for any optical depth
      for (int b = 0; b < nb_; ++b) L[b] += T * absorbed * J[b];
      T *= 1 - absorbed;
    }
  }
  return T;
}

float VolumeMedia::FindTransmittanceDepths(const Vec3f& origin, const Vec3f& direction, float t_max,
                                           const float* targets, int count, float* distance, int* volume) const {
  Segment segments[kMaxSegments];
  const int n_segments = Segments(origin, direction, t_max, segments);
  for (int k = 0; k < count; ++k) volume[k] = -1;
  int next = 0;  // the next target to reach
  float tau = 0;
  for (int s = 0; s < n_segments; ++s) {
    const VolumeGrid& grid = grids_[segments[s].volume];
    const float sigma_scale = static_cast<float>(grid.volume().sigma_t_per_m);
    const float step = options_.step_scale * grid.min_voxel_m();
    const float t0 = segments[s].t0, t1 = segments[s].t1;
    const int n = std::max(1, static_cast<int>(std::ceil((t1 - t0) / step)));
    const float ds = (t1 - t0) / static_cast<float>(n);
    for (int k = 0; k < n; ++k) {
      const float a = t0 + static_cast<float>(k) * ds;
      const float dtau = grid.Density(origin + (a + 0.5f * ds) * direction) * sigma_scale * ds;
      // Targets crossed inside this step: tau grows linearly across it.
      while (next < count && dtau > 0 && tau + dtau >= -std::log(targets[next])) {
        const float need = -std::log(targets[next]) - tau;
        distance[next] = a + ds * std::clamp(need / dtau, 0.0f, 1.0f);
        volume[next] = segments[s].volume;
        ++next;
      }
      tau += dtau;
    }
  }
  return std::exp(-tau);
}

IntervalMap BuildIntervalMap(const VolumeMedia& media, const GBuffer& g, const CameraRays& camera, int layers) {
  IntervalMap map;
  map.layers = std::clamp(layers, 1, 64);
  const std::size_t n = static_cast<std::size_t>(g.width) * g.height;
  map.layer.resize(map.layers);
  for (GBuffer& layer : map.layer) {
    layer.width = g.width;
    layer.height = g.height;
    layer.position.assign(n, Vec3f::Zero());
    layer.normal.assign(n, Vec3f::Zero());  // a point in a medium: no normal
    layer.depth.assign(n, 0.0f);
    layer.object.assign(n, -1);
  }
  map.delta_T.assign(n, 0.0f);
  map.T_end.assign(n, 1.0f);
  tbb::parallel_for(tbb::blocked_range<int>(0, g.height), [&](const tbb::blocked_range<int>& rows) {
    float targets[64], distance[64];
    int volume[64];
    for (int y = rows.begin(); y != rows.end(); ++y)
      for (int x = 0; x < g.width; ++x) {
        const std::size_t p = static_cast<std::size_t>(y) * g.width + x;
        const Vec3f d = camera.Direction(x + 0.5f, y + 0.5f);
        const float t_max = g.object[p] >= 0 ? g.depth[p] : 1e30f;
        // Pass 1: the transmittance to the end; pass 2: the points.
        const float T_end = media.FindTransmittanceDepths(camera.origin(), d, t_max, targets, 0, distance, volume);
        map.T_end[p] = T_end;
        if (!(T_end < 1.0f - 1e-6f)) continue;
        const float dT = (1 - T_end) / static_cast<float>(map.layers);
        // Interleaved gradient noise: a per-pixel offset of the points.
        const float xi = InterleavedGradientNoise(x, y);
        for (int k = 0; k < map.layers; ++k) targets[k] = std::max(1 - (static_cast<float>(k) + xi) * dT, 1e-30f);
        media.FindTransmittanceDepths(camera.origin(), d, t_max, targets, map.layers, distance, volume);
        map.delta_T[p] = dT;
        for (int k = 0; k < map.layers; ++k) {
          if (volume[k] < 0) continue;
          GBuffer& layer = map.layer[k];
          layer.position[p] = camera.origin() + distance[k] * d;
          layer.depth[p] = distance[k];
          layer.object[p] = volume[k];
        }
      }
  });
  return map;
}

void VolumeMedia::Step(double t0_s, double t1_s) {
  const double h = t1_s - t0_s;
  if (!(h > 0)) return;
  bool any_phosphor = false;
  for (const auto& p : phosphors_) any_phosphor = any_phosphor || p != nullptr;
  if (!any_phosphor) return;
  PrepareLighting(0.5 * (t0_s + t1_s));
  for (std::size_t vi = 0; vi < phosphors_.size(); ++vi)
    if (phosphors_[vi]) StepVolume(static_cast<int>(vi), h);
}

void VolumeMedia::StepVolume(int vi, double h) {
  Phosphor* p = phosphors_[vi].get();
  const std::size_t n = p->voxels.size();
  const VolumeGrid& grid = grids_[vi];
  bool lit = false;
  for (std::size_t l = 0; l < scene_.lights.size() && !p->excitation_bands.empty(); ++l) {
    if (levels_[l] <= 0) continue;
    const Light& light = scene_.lights[l];
    const std::vector<float>& unit = caches_[vi][l].unit;
    // Each voxel's light from this light, the sheet's covered fraction
    // included (a voxel's half extent along the sheet's normal), once for
    // all bands.
    const float half = 0.5f * grid.voxel_m().cwiseProduct(poses_[l].sheet_normal).cwiseAbs().sum();
    p->unit.resize(n);
    for (std::size_t j = 0; j < n; ++j)
      p->unit[j] = unit[p->voxels[j]] * poses_[l].SheetCoverage(grid.VoxelCentre(p->voxels[j]), half);
    for (std::size_t bi = 0; bi < p->excitation_bands.size(); ++bi) {
      const float scale = static_cast<float>(levels_[l] * light.E_per_band[p->excitation_bands[bi]]);
      float* E = p->E.data() + bi * n;
      for (std::size_t j = 0; j < n; ++j) E[j] = (lit ? E[j] : 0.0f) + scale * p->unit[j];
    }
    lit = true;
  }
  if (lit) {
    AdvanceBatch(Integrator::kExact, p->coefficients, p->E.data(), n, static_cast<float>(h), p->states, p->Lp.data(),
                 n);
    ++stats_.steps;
  } else {
    DecayBatch(p->coefficients, static_cast<float>(h), p->states, p->Lp.data(), n);  // closed form, any length
    ++stats_.dark_jumps;
  }
  ScatterLp(vi);
}

// The voxels' Lp into the grids the marches sample.
void VolumeMedia::ScatterLp(int vi) {
  Phosphor* p = phosphors_[vi].get();
  const std::size_t n = p->voxels.size(), voxels = grids_[vi].volume().voxel_count();
  for (std::size_t e = 0; e < p->emission_bands.size(); ++e)
    for (std::size_t j = 0; j < n; ++j) p->Lp_grid[e * voxels + p->voxels[j]] = p->Lp[e * n + j];
}

void VolumeMedia::InitialStates() {
  for (std::size_t vi = 0; vi < phosphors_.size(); ++vi) {
    Phosphor* p = phosphors_[vi].get();
    if (!p) continue;
    const Volume& v = scene_.volumes[vi];
    const std::size_t n = p->voxels.size();
    if (v.initial.kind == InitialState::Kind::kUniform) {
      std::fill(p->states.r.begin(), p->states.r.end(), static_cast<float>(v.initial.r0));
    } else if (v.initial.kind == InitialState::Kind::kEquilibrium) {
      // The exact step over an endless interval lands on r_inf = a / (a + kr).
      std::fill(p->states.r.begin(), p->states.r.end(), 0.0f);
      PrepareLighting(scene_.start_s);
      StepVolume(static_cast<int>(vi), 1e30);
    }
    EmitBatch(p->coefficients, p->states, p->Lp.data(), n);
    ScatterLp(static_cast<int>(vi));
  }
}

float VolumeMedia::Lp(int volume, int band, std::size_t voxel) const {
  const Phosphor* p = phosphors_[volume].get();
  if (!p || p->emission_index[band] < 0) return 0.0f;
  return p->Lp_grid[static_cast<std::size_t>(p->emission_index[band]) * grids_[volume].volume().voxel_count() + voxel];
}

float VolumeMedia::State(int volume, int i, std::size_t voxel) const {
  const Phosphor* p = phosphors_[volume].get();
  if (!p || p->state_of[voxel] < 0) return 0.0f;
  return p->states.state(i)[p->state_of[voxel]];
}

void VolumeMedia::SaveStates(std::vector<std::vector<float>>* arrays) const {
  for (const auto& p : phosphors_) {
    if (!p) continue;
    arrays->push_back(p->states.r);
    arrays->push_back(p->Lp);
  }
}

void VolumeMedia::RestoreStates(const std::vector<std::vector<float>>& arrays, std::size_t first,
                                const std::string& source) {
  std::size_t a = first;
  for (std::size_t vi = 0; vi < phosphors_.size(); ++vi) {
    Phosphor* p = phosphors_[vi].get();
    if (!p) continue;
    if (a + 2 > arrays.size() || arrays[a].size() != p->states.r.size() || arrays[a + 1].size() != p->Lp.size())
      ThrowUserError(source, "arrays", "do not match the scene's phosphorescent voxels (a state of another scene?)");
    p->states.r = arrays[a];
    p->Lp = arrays[a + 1];
    ScatterLp(static_cast<int>(vi));
    a += 2;
  }
  if (a != arrays.size())
    ThrowUserError(source, "arrays", "more than the scene's phosphors hold (a state of another scene?)");
}

}  // namespace phos::render
