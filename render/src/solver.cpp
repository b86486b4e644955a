#include "phos/render/solver.h"

#include "phos/render/phosphor_map.h"

#include <algorithm>
#include <cmath>
#include <array>
#include <bit>
#include <cstring>
#include <fstream>
#include <set>
#include <utility>

#include <nlohmann/json.hpp>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "phos/render/renderer.h"
#include "phos/render/volume.h"
#include "phos/util/atomic_file.h"
#include "phos/util/error.h"
#include "phos/util/json.h"
#include "phos/model/closed_form.h"

namespace phos::render {
namespace {

// A light whose schedule ever turns it on (no schedule: always on).
bool EverOn(const Light& light) {
  if (light.schedule.keys.empty()) return true;
  return std::any_of(light.schedule.keys.begin(), light.schedule.keys.end(),
                     [](const LightSchedule::Key& k) { return k.level > 0; });
}

}  // namespace

CoupledSolver::CoupledSolver(const Scene& scene, SceneGeometry& geometry)
    : scene_(scene),
      geometry_(geometry),
      atlas_(scene, geometry),
      band_count_(scene.bands.band_count()),
      time_s_(scene.start_s) {
  const int nb = band_count_;
  // Bands any light of the scene ever puts light into.
  std::vector<bool> lit(nb, false);
  for (const Light& light : scene.lights)
    if (EverOn(light))
      for (int b = 0; b < nb; ++b) lit[b] = lit[b] || light.E_per_band[b] > 0;
  if (scene.environment) {
    Light sky;  // EverOn reads only the schedule
    sky.schedule = scene.environment->schedule;
    if (EverOn(sky))
      for (int b = 0; b < nb; ++b) lit[b] = lit[b] || scene.environment->L_per_band[b] > 0;
  }
  // With phosphor_irradiance, whatever a phosphor emits also lights the others.
  glow_enabled_ = scene.settings.phosphor_irradiance && scene.HasPhosphors();
  if (glow_enabled_) {
    for (int b = 0; b < nb; ++b) {
      bool emitted = false;
      for (const Object& object : scene.objects)
        if (object.phosphor)
          for (const ExcitedState& state : object.phosphor->states) emitted = emitted || state.Lambda[b] > 0;
      if (emitted) glow_.emission_bands.push_back(b);
      lit[b] = lit[b] || emitted;
    }
  }

  for (const TexelAtlas::ObjectTexels& texels : atlas_.objects()) {
    const Object& object = scene.objects[texels.object];
    Material material = *object.phosphor;
    const std::string where = scene.source + ": object '" + object.name + "' (" + object.phosphor_path + ")";
    if (object.unknown_ke_as_zero) AssumeUnknownKeZero(material);  // the scene file states this assumption
    Group g;
    g.object = texels.object;
    g.emission_index.assign(nb, -1);
    for (int b = 0; b < nb; ++b) {
      bool excites = false, emits = false;
      for (const ExcitedState& state : material.states) {
        excites = excites || !state.ke[b] || *state.ke[b] > 0;  // unknown stays in, so Compile names it
        emits = emits || state.Lambda[b] > 0;
      }
      if (lit[b] && excites) g.excitation_bands.push_back(b);
      if (emits) {
        g.emission_index[b] = static_cast<int>(g.emission_bands.size());
        g.emission_bands.push_back(b);
      }
    }
    RequireKnownKe(scene, material, g.excitation_bands, where + " lit by the scene's lights");
    g.coefficients = BatchCoefficients<float>::Compile(material, g.excitation_bands, g.emission_bands,
                                                       where + " lit by the scene's lights", kUnknownKeRemedy);
    if (object.phosphor_map) ApplyPhosphorMap(*object.phosphor_map, material, texels.map_pixel, g.coefficients, where);
    g.states = StateBatch<float>(material.state_count(), texels.count, 0.0f);
    g.Lp.assign(g.emission_bands.size() * texels.count, 0.0f);
    g.E.assign(g.excitation_bands.size() * texels.count, 0.0f);
    g.unit_E.resize(scene.lights.size());
    g.unit_E_light_at.assign(scene.lights.size(), LightPose{});
    g.unit_E_version.assign(scene.lights.size(), ~std::uint64_t{0});
    stats_.texels += texels.count;
    groups_.push_back(std::move(g));
  }
  if (glow_enabled_) BuildGlowPatches();
  InitialStates();
  if (!scene.volumes.empty()) {
    media_ = std::make_unique<VolumeMedia>(scene, geometry);
    media_->InitialStates();
  }
}

CoupledSolver::~CoupledSolver() = default;

void CoupledSolver::BuildGlowPatches() {
  // Patches per triangle: up to 8 x 8, fewer if the scene would have more than
  // kMaxPatches (the transfer matrix is patches^2).
  constexpr std::size_t kMaxPatches = 2048;
  int ms_cap = 8;
  auto count_patches = [&](int cap) {
    std::size_t count = 0;
    for (const TexelAtlas::ObjectTexels& texels : atlas_.objects())
      for (std::uint16_t m : texels.m) count += std::size_t(std::min<int>(m, cap)) * std::min<int>(m, cap);
    return count;
  };
  while (ms_cap > 1 && count_patches(ms_cap) > kMaxPatches) --ms_cap;
  glow_.count = count_patches(ms_cap);
  stats_.glow_patches = glow_.count;
  glow_.centre.resize(glow_.count);
  glow_.normal.resize(glow_.count);
  glow_.area.resize(glow_.count);
  glow_.cells.assign(glow_.count, 0.0f);
  glow_.two_sided.resize(glow_.count);
  // Sample points of each source patch: the centres of its 4 children one level finer.
  std::vector<std::array<Vec3f, 4>> points(glow_.count);
  std::size_t base = 0;
  for (std::size_t slot = 0; slot < groups_.size(); ++slot) {
    Group& g = groups_[slot];
    const TexelAtlas::ObjectTexels& texels = atlas_.objects()[slot];
    g.texel_patch.resize(texels.count);
    std::vector<std::size_t> triangle_base(geometry_.triangle_count(g.object));
    std::size_t running = base;
    for (int t = 0; t < geometry_.triangle_count(g.object); ++t) {
      triangle_base[t] = running;
      running += std::size_t(std::min<int>(texels.m[t], ms_cap)) * std::min<int>(texels.m[t], ms_cap);
    }
    auto patch_of = [&](int t, float b1, float b2) {
      return triangle_base[t] + SubTriangleIndex(std::min<int>(texels.m[t], ms_cap), b1, b2);
    };
    atlas_.ForEachTexel(static_cast<int>(slot), [&](std::size_t k, int t, float b1, float b2) {
      g.texel_patch[k] = static_cast<std::uint32_t>(patch_of(t, b1, b2));
    });
    for (std::uint32_t patch : g.texel_patch) glow_.cells[patch] += 1;
    for (const TexelAnchor& bare : texels.bare_anchors)
      glow_.cells[patch_of(static_cast<int>(bare.triangle), bare.b1, bare.b2)] += 1;
    for (int t = 0; t < geometry_.triangle_count(g.object); ++t) {
      const int m = texels.m[t], ms = std::min(m, ms_cap);
      const float area = geometry_.Area(g.object, t) / static_cast<float>(ms * ms);
      std::vector<int> filled(ms * ms, 0);
      for (int k = 0; k < ms * ms; ++k) {
        float b1, b2;
        SubTriangleCenter(ms, k, b1, b2);
        glow_.centre[base + k] = geometry_.Point(g.object, t, b1, b2);
        glow_.normal[base + k] = geometry_.FrontNormal(g.object, t);
        glow_.area[base + k] = area;
        glow_.two_sided[base + k] = scene_.objects[g.object].two_sided;
      }
      for (int k = 0; k < 4 * ms * ms; ++k) {
        float b1, b2;
        SubTriangleCenter(2 * ms, k, b1, b2);
        const int patch = SubTriangleIndex(ms, b1, b2);
        points[base + patch][std::min(filled[patch]++, 3)] = geometry_.Point(g.object, t, b1, b2);
      }
      base += static_cast<std::size_t>(ms) * ms;
    }
  }
  // Transfer: irradiance at receiver j per unit radiance of source k, from
  // the source's glowing side to the receiver's charged side: the front, or
  // either face of a two-sided sheet (Object::two_sided).
  const std::size_t n = glow_.count;
  glow_.transfer.assign(n * n, 0.0f);
  const float epsilon = geometry_.ray_epsilon();
  tbb::parallel_for(std::size_t{0}, n, [&](std::size_t j) {
    const Vec3f& x = glow_.centre[j];
    const Vec3f& nx = glow_.normal[j];
    for (std::size_t k = 0; k < n; ++k) {
      if (k == j) continue;
      float sum = 0;
      for (const Vec3f& y : points[k]) {
        Vec3f d = y - x;
        const float distance2 = d.squaredNorm(), distance = std::sqrt(distance2);
        if (!(distance > 0)) continue;
        d /= distance;
        float cos_x = nx.dot(d), cos_y = -glow_.normal[k].dot(d);
        const float side = cos_x < 0 ? -1.0f : 1.0f;  // the receiver's face toward the source
        if (glow_.two_sided[j]) cos_x = std::abs(cos_x);
        if (glow_.two_sided[k]) cos_y = std::abs(cos_y);
        if (cos_x <= 0 || cos_y <= 0) continue;
        if (geometry_.Occluded(x + side * epsilon * nx, d, distance - 2 * epsilon)) continue;
        sum += cos_x * cos_y / distance2;
      }
      glow_.transfer[j * n + k] = sum * glow_.area[k] / 4;
    }
  });
  stats_.shadow_rays += n * n * 4;
  glow_.geometry_version = geometry_.version();
  glow_.Lp.assign(n * glow_.emission_bands.size(), 0.0f);
  glow_.E.assign(n * glow_.emission_bands.size(), 0.0f);
}

bool CoupledSolver::GatherGlow() {
  if (glow_.geometry_version != geometry_.version()) BuildGlowPatches();
  const std::size_t n = glow_.count, nbg = glow_.emission_bands.size();
  // Mean Lp of each patch over its cells, each texel by the share of paint
  // it has (a bare cell: none), band-major.
  std::fill(glow_.Lp.begin(), glow_.Lp.end(), 0.0f);
  for (std::size_t slot = 0; slot < groups_.size(); ++slot) {
    const Group& g = groups_[slot];
    const TexelAtlas::ObjectTexels& texels = atlas_.objects()[slot];
    for (std::size_t bi = 0; bi < nbg; ++bi) {
      const int e = g.emission_index[glow_.emission_bands[bi]];
      if (e < 0) continue;
      const float* Lp = g.Lp.data() + static_cast<std::size_t>(e) * g.states.n;
      float* out = glow_.Lp.data() + bi * n;
      if (texels.masked())
        for (std::size_t j = 0; j < g.states.n; ++j) out[g.texel_patch[j]] += texels.coverage[j] * Lp[j];
      else
        for (std::size_t j = 0; j < g.states.n; ++j) out[g.texel_patch[j]] += Lp[j];
    }
  }
  bool any = false;
  for (std::size_t bi = 0; bi < nbg; ++bi)
    for (std::size_t k = 0; k < n; ++k) {
      glow_.Lp[bi * n + k] /= std::max(glow_.cells[k], 1.0f);
      any = any || glow_.Lp[bi * n + k] > 0;
    }
  if (!any) return false;
  // E = T Lp, one matrix-vector product per glowing band.
  using Matrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const Eigen::Map<const Matrix> T(glow_.transfer.data(), static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(n));
  for (std::size_t bi = 0; bi < nbg; ++bi)
    Eigen::Map<Eigen::VectorXf>(glow_.E.data() + bi * n, static_cast<Eigen::Index>(n)) =
        T * Eigen::Map<const Eigen::VectorXf>(glow_.Lp.data() + bi * n, static_cast<Eigen::Index>(n));
  return true;
}

void CoupledSolver::InitialStates() {
  for (std::size_t s = 0; s < groups_.size(); ++s) {
    Group& g = groups_[s];
    const InitialState& initial = scene_.objects[g.object].initial;
    const std::size_t n = g.states.n;
    if (initial.kind == InitialState::Kind::kUniform) {
      std::fill(g.states.r.begin(), g.states.r.end(), static_cast<float>(initial.r0));
    } else if (initial.kind == InitialState::Kind::kEquilibrium && GatherIrradiance(g, scene_.start_s)) {
      // dr/dt = 0 in Eq. 8.1 (SteadyState), a_i = sum_b ke_i[b] E[b].
      const BatchCoefficients<float>& c = g.coefficients;
      tbb::parallel_for(std::size_t{0}, n, [&](std::size_t j) {
        for (int i = 0; i < c.nc; ++i) {
          double a = 0;
          for (int b = 0; b < c.n_exc; ++b) a += double(c.ke[i * c.n_exc + b]) * g.E[b * n + j];
          const double kr = c.per_point() ? c.kr_per_point[i * n + j] : c.kr[i];
          g.states.state(i)[j] = static_cast<float>(SteadyState(a, kr));
        }
      });
    }
    EmitBatch(g.coefficients, g.states, g.Lp.data(), n);
  }
}

void CoupledSolver::UpdateTexelFrames(Group& g) {
  if (g.texel_version == geometry_.version() && !g.texel_position.empty()) return;
  const int slot = atlas_.SlotOf(g.object);
  g.texel_position.resize(g.states.n);
  g.texel_normal.resize(g.states.n);
  tbb::parallel_for(std::size_t{0}, atlas_.chunk_count(slot), [&](std::size_t chunk) {
    atlas_.ForEachTexelInChunk(slot, chunk, [&](std::size_t k, int t, float b1, float b2) {
      g.texel_position[k] = geometry_.Point(g.object, t, b1, b2);
      g.texel_normal[k] = geometry_.FrontNormal(g.object, t);
    });
  });
  g.texel_version = geometry_.version();
}

const std::vector<float>& CoupledSolver::UnitIrradiance(Group& g, int l) {
  const Light& light = scene_.lights[l];
  const double t = geometry_.time_s();
  const LightPose pose = PoseAt(light, t);
  std::vector<float>& unit = g.unit_E[l];
  if (!unit.empty() && pose == g.unit_E_light_at[l] && g.unit_E_version[l] == geometry_.version()) return unit;
  UpdateTexelFrames(g);
  const std::size_t n = g.states.n;
  const bool two_sided = scene_.objects[g.object].two_sided;
  unit.resize(n);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t j = range.begin(); j != range.end(); ++j) {
      unit[j] = render::UnitIrradiance(geometry_, pose, g.texel_position[j], g.texel_normal[j]);
      // A two-sided sheet: its state also takes the irradiance on its back.
      if (two_sided)
        unit[j] += render::UnitIrradiance(geometry_, pose, g.texel_position[j], Eigen::Vector3f(-g.texel_normal[j]));
    }
  });
  g.unit_E_light_at[l] = pose;
  g.unit_E_version[l] = geometry_.version();
  ++stats_.irradiance_updates;
  stats_.shadow_rays += two_sided ? 2 * n : n;
  return unit;
}

void CoupledSolver::NoteCharge(Group& g, int l, const std::vector<float>& unit) {
  g.charge.light_on = true;
  if (std::any_of(unit.begin(), unit.end(), [](float u) { return u > 0; })) {
    g.charge.received = true;
    return;
  }
  // Nothing reached the front (nor, two-sided, the back): would the light
  // reach the back? Up to 64 texels, evenly spread, with their normals turned
  // around. A two-sided sheet has counted its back already.
  if (g.charge.lit_from_behind || scene_.objects[g.object].two_sided) return;
  const LightPose pose = PoseAt(scene_.lights[l], geometry_.time_s());
  const std::size_t n = g.states.n, stride = std::max<std::size_t>(1, n / 64);
  for (std::size_t j = 0; j < n && !g.charge.lit_from_behind; j += stride)
    g.charge.lit_from_behind =
        render::UnitIrradiance(geometry_, pose, g.texel_position[j], Eigen::Vector3f(-g.texel_normal[j])) > 0;
}

bool CoupledSolver::GatherIrradiance(Group& g, double t_s) {
  const std::size_t n = g.states.n;
  const int n_exc = static_cast<int>(g.excitation_bands.size());
  bool any = false;
  for (std::size_t l = 0; l < scene_.lights.size(); ++l) {
    const Light& light = scene_.lights[l];
    const double level = light.schedule.LevelAt(t_s);
    if (level <= 0) continue;
    bool reaches = false;
    for (int b : g.excitation_bands) reaches = reaches || light.E_per_band[b] > 0;
    if (!reaches) continue;
    const std::vector<float>& unit = UnitIrradiance(g, static_cast<int>(l));
    if (!g.charge.received) NoteCharge(g, static_cast<int>(l), unit);
    // E[b] = sum over lights of level * E_light[b] * (cos / d^2, shadowed): the
    // first light writes, the others add.
    for (int bi = 0; bi < n_exc; ++bi) {
      const float scale = static_cast<float>(level * light.E_per_band[g.excitation_bands[bi]]);
      float* __restrict E = g.E.data() + static_cast<std::size_t>(bi) * n;
      const float* __restrict u = unit.data();
      if (!any) {
        for (std::size_t j = 0; j < n; ++j) E[j] = scale * u[j];
      } else {
        for (std::size_t j = 0; j < n; ++j) E[j] += scale * u[j];
      }
    }
    any = true;
  }
  // The sky (Environment): its irradiance per texel by kSkyRays shadow rays,
  // computed once per geometry (a level change only rescales it).
  if (scene_.environment) {
    const Environment& env = *scene_.environment;
    const double level = env.schedule.LevelAt(t_s);
    bool reaches = false;
    for (int b : g.excitation_bands) reaches = reaches || env.L_per_band[b] > 0;
    if (level > 0 && reaches) {
      constexpr int kSkyRays = 64;
      const bool two_sided = scene_.objects[g.object].two_sided;
      if (g.unit_sky.empty() || g.unit_sky_version != geometry_.version()) {
        UpdateTexelFrames(g);
        g.unit_sky.resize(n);
        tbb::parallel_for(
            tbb::blocked_range<std::size_t>(0, n, 256), [&](const tbb::blocked_range<std::size_t>& range) {
              for (std::size_t j = range.begin(); j != range.end(); ++j) {
                g.unit_sky[j] = UnitSkyIrradiance(geometry_, env, g.texel_position[j], g.texel_normal[j], kSkyRays, j);
                if (two_sided)  // the sky over its back too, with rays of their own
                  g.unit_sky[j] += UnitSkyIrradiance(geometry_, env, g.texel_position[j],
                                                     Eigen::Vector3f(-g.texel_normal[j]), kSkyRays, n + j);
              }
            });
        g.unit_sky_version = geometry_.version();
        ++stats_.irradiance_updates;
        stats_.shadow_rays += (two_sided ? 2 : 1) * n * kSkyRays;
      }
      g.charge.light_on = true;
      g.charge.received =
          g.charge.received || std::any_of(g.unit_sky.begin(), g.unit_sky.end(), [](float u) { return u > 0; });
      for (int bi = 0; bi < n_exc; ++bi) {
        const float scale = static_cast<float>(level * env.L_per_band[g.excitation_bands[bi]]);
        float* E = g.E.data() + static_cast<std::size_t>(bi) * n;
        for (std::size_t j = 0; j < n; ++j) E[j] = (any ? E[j] : 0.0f) + scale * g.unit_sky[j];
      }
      any = true;
    }
  }
  return any;
}

std::vector<double> CoupledSolver::TexelIrradiance(int slot, std::size_t texel) {
  Group& g = groups_[slot];
  std::vector<double> E(band_count_, 0.0);
  for (std::size_t l = 0; l < scene_.lights.size(); ++l) {
    const Light& light = scene_.lights[l];
    const double level = light.schedule.LevelAt(time_s_);
    if (level <= 0) continue;
    const double unit = UnitIrradiance(g, static_cast<int>(l))[texel];
    for (int b = 0; b < band_count_; ++b) E[b] += level * light.E_per_band[b] * unit;
  }
  if (scene_.environment && !g.unit_sky.empty()) {
    const double level = scene_.environment->schedule.LevelAt(time_s_);
    for (int b = 0; b < band_count_; ++b) E[b] += level * scene_.environment->L_per_band[b] * g.unit_sky[texel];
  }
  return E;
}

std::vector<double> CoupledSolver::TexelGlowIrradiance(int slot, std::size_t texel) {
  std::vector<double> E(band_count_, 0.0);
  if (!glow_enabled_ || !GatherGlow()) return E;
  const std::uint32_t patch = groups_[slot].texel_patch[texel];
  for (std::size_t bi = 0; bi < glow_.emission_bands.size(); ++bi)
    E[glow_.emission_bands[bi]] = glow_.E[bi * glow_.count + patch];
  return E;
}

void CoupledSolver::Step(double t0_s, double t1_s, bool moving) {
  const double h = t1_s - t0_s;
  if (!(h > 0)) return;
  // Irradiance is held constant over the step (Eq. 8.1 with piecewise-constant
  // E): the exact update is then exact. Levels are constant inside a step (steps
  // split at switches); positions are taken at the midpoint while things move.
  const double mid = 0.5 * (t0_s + t1_s);
  if (moving) geometry_.SetTime(mid);
  // The glow lighting the phosphors is taken at the start of the step (lagged
  // coupling; steps are short while it is on).
  const bool glowing = glow_enabled_ && GatherGlow();
  for (Group& g : groups_) {
    const std::size_t n = g.states.n;
    bool lit = !g.excitation_bands.empty() && GatherIrradiance(g, mid);
    if (glowing && !g.excitation_bands.empty()) {
      if (!lit) std::fill(g.E.begin(), g.E.end(), 0.0f);
      lit = true;
      for (std::size_t bi = 0; bi < g.excitation_bands.size(); ++bi) {
        const auto it = std::find(glow_.emission_bands.begin(), glow_.emission_bands.end(), g.excitation_bands[bi]);
        if (it == glow_.emission_bands.end()) continue;
        const float* glow_E =
            glow_.E.data() + static_cast<std::size_t>(it - glow_.emission_bands.begin()) * glow_.count;
        float* E = g.E.data() + bi * n;
        for (std::size_t j = 0; j < n; ++j) E[j] += glow_E[g.texel_patch[j]];
      }
    }
    if (lit) {
      AdvanceBatch(Integrator::kExact, g.coefficients, g.E.data(), n, static_cast<float>(h), g.states, g.Lp.data(), n);
      ++stats_.steps;
    } else {
      DecayBatch(g.coefficients, static_cast<float>(h), g.states, g.Lp.data(), n);  // closed-form jump, any length
      ++stats_.dark_jumps;
    }
  }
  if (media_) media_->Step(t0_s, t1_s);
}

void CoupledSolver::AdvanceTo(double t_s) {
  PHOS_CHECK(t_s >= time_s_);
  if (t_s == time_s_) return;
  // Break points: light switches and keyframes inside (time_s_, t_s).
  std::set<double> breaks = {t_s};
  if (scene_.environment)
    for (double t : scene_.environment->schedule.ChangesBetween(time_s_, t_s)) breaks.insert(t);
  for (const Light& light : scene_.lights) {
    for (double t : light.schedule.ChangesBetween(time_s_, t_s)) breaks.insert(t);
    for (const RigidKey& key : light.motion.keys)
      if (key.t_s > time_s_ && key.t_s < t_s) breaks.insert(key.t_s);
  }
  for (const Object& object : scene_.objects)
    for (const RigidKey& key : object.motion.keys)
      if (key.t_s > time_s_ && key.t_s < t_s) breaks.insert(key.t_s);
  const double max_step = scene_.settings.max_step_s > 0 ? scene_.settings.max_step_s : 1.0 / scene_.fps;
  double t0 = time_s_;
  for (double t1 : breaks) {
    bool moving = false;
    for (const Light& light : scene_.lights) moving = moving || light.motion.MovesBetween(t0, t1);
    for (const Object& object : scene_.objects) moving = moving || object.motion.MovesBetween(t0, t1);
    const bool substep = moving || glow_enabled_;  // the glow changes within any interval
    const int substeps = substep ? std::max(1, static_cast<int>(std::ceil((t1 - t0) / max_step - 1e-9))) : 1;
    for (int k = 0; k < substeps; ++k)
      Step(t0 + (t1 - t0) * k / substeps, k + 1 == substeps ? t1 : t0 + (t1 - t0) * (k + 1) / substeps, moving);
    t0 = t1;
  }
  time_s_ = t_s;
  geometry_.SetTime(t_s);
}

nlohmann::json SolverCheckpoint::HeaderJson() const {
  nlohmann::json sizes = nlohmann::json::array();
  for (const std::vector<float>& a : arrays) sizes.push_back(a.size());
  return {{"format", kFormat}, {"time_s", time_s}, {"frame", frame}, {"scene", scene}, {"array_sizes", sizes}};
}

void WriteSolverCheckpoint(const std::filesystem::path& path, const SolverCheckpoint& checkpoint) {
  static_assert(std::endian::native == std::endian::little, "the state file's floats are little-endian");
  std::string bytes = checkpoint.HeaderJson().dump() + "\n";
  for (const std::vector<float>& a : checkpoint.arrays)
    bytes.append(reinterpret_cast<const char*>(a.data()), a.size() * sizeof(float));
  WriteFileAtomically(path, bytes);
}

SolverCheckpoint ReadSolverCheckpoint(const std::filesystem::path& path) {
  // The largest state phos reads is the input limit: 64 M floats.
  const std::string bytes = ReadFileText(path);
  const std::size_t newline = bytes.find('\n');
  if (newline == std::string::npos) ThrowUserError(path.string(), "", "is not a solver state (no header line)");
  const nlohmann::json header = ParseJsonText(std::string_view(bytes).substr(0, newline), path.string());
  const JsonField h(header, path.string());
  if (h["format"].String() != SolverCheckpoint::kFormat)
    h["format"].Fail(std::string("expected \"") + SolverCheckpoint::kFormat + "\"");
  SolverCheckpoint c;
  c.time_s = h["time_s"].Number();
  c.frame = h["frame"].Integer(0, 1 << 30);
  c.scene = h["scene"].String();
  const JsonField sizes = h["array_sizes"];
  std::size_t offset = newline + 1;
  for (std::size_t i = 0; i < sizes.ArraySize(); ++i) {
    const double count = sizes.At(i).NumberInRange(0, double(kMaxInputFileBytes / sizeof(float)));
    const std::size_t n = static_cast<std::size_t>(count);
    if (double(n) != count) sizes.At(i).Fail("expected a whole number of floats");
    if (bytes.size() - offset < n * sizeof(float))
      ThrowUserError(path.string(), "", "is shorter than its header says (a torn copy?)");
    std::vector<float> a(n);
    std::memcpy(a.data(), bytes.data() + offset, n * sizeof(float));
    offset += n * sizeof(float);
    c.arrays.push_back(std::move(a));
  }
  if (offset != bytes.size()) ThrowUserError(path.string(), "", "is longer than its header says");
  return c;
}

std::shared_ptr<const void> CoupledSolver::DerivedTables() const {
  const std::lock_guard<std::mutex> lock(derived_mutex_);
  return derived_version_ == geometry_.version() ? derived_tables_ : nullptr;
}

void CoupledSolver::KeepDerivedTables(std::shared_ptr<const void> tables) const {
  const std::lock_guard<std::mutex> lock(derived_mutex_);
  derived_tables_ = std::move(tables);
  derived_version_ = geometry_.version();
}

SolverCheckpoint CoupledSolver::Checkpoint(int frame) const {
  SolverCheckpoint c;
  c.time_s = time_s_;
  c.frame = frame;
  c.scene = scene_.name;
  for (const Group& g : groups_) {
    c.arrays.push_back(g.states.r);
    c.arrays.push_back(g.Lp);
  }
  if (media_) media_->SaveStates(&c.arrays);
  return c;
}

void CoupledSolver::Restore(const SolverCheckpoint& c, const std::string& source) {
  if (c.scene != scene_.name)
    ThrowUserError(source, "scene", "is '" + c.scene + "', the scene rendered is '" + scene_.name + "'");
  if (c.arrays.size() < 2 * groups_.size())
    ThrowUserError(source, "arrays", "fewer than the scene's phosphorescent objects need (a state of another scene?)");
  for (std::size_t s = 0; s < groups_.size(); ++s) {
    Group& g = groups_[s];
    if (c.arrays[2 * s].size() != g.states.r.size() || c.arrays[2 * s + 1].size() != g.Lp.size())
      ThrowUserError(source, "arrays",
                     "do not match the texels of object '" + scene_.objects[g.object].name +
                         "' (a state of another version of the scene?)");
    g.states.r = c.arrays[2 * s];
    g.Lp = c.arrays[2 * s + 1];
  }
  if (media_)
    media_->RestoreStates(c.arrays, 2 * groups_.size(), source);
  else if (c.arrays.size() != 2 * groups_.size())
    ThrowUserError(source, "arrays", "more than the scene's phosphors hold (a state of another scene?)");
  time_s_ = c.time_s;
  geometry_.SetTime(c.time_s);
}

}  // namespace phos::render
