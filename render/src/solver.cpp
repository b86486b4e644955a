#include "phos/render/solver.h"

#include <algorithm>
#include <cmath>
#include <set>

#include <tbb/parallel_for.h>

#include "phos/util/error.h"

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
    : scene_(scene), geometry_(geometry), atlas_(scene, geometry),
      band_count_(scene.bands.band_count()), time_s_(scene.start_s) {
  const int nb = band_count_;
  // Bands any light of the scene ever puts light into.
  std::vector<bool> lit(nb, false);
  for (const Light& light : scene.lights)
    if (EverOn(light))
      for (int b = 0; b < nb; ++b) lit[b] = lit[b] || light.E_per_band[b] > 0;

  for (const TexelAtlas::ObjectTexels& texels : atlas_.objects()) {
    const Object& object = scene.objects[texels.object];
    Material material = *object.phosphor;
    const std::string where = scene.source + ": object '" + object.name + "' (" + object.phosphor_path + ")";
    if (object.unknown_ke_as_zero)  // the scene file states this assumption explicitly
      for (ExcitedState& state : material.states)
        for (auto& ke : state.ke)
          if (!ke) ke = 0.0;
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
    g.coefficients = BatchCoefficients<float>::Compile(material, g.excitation_bands, g.emission_bands,
                                                       where + " lit by the scene's lights");
    g.states = StateBatch<float>(material.state_count(), texels.count, 0.0f);
    g.Lp.assign(g.emission_bands.size() * texels.count, 0.0f);
    g.E.assign(g.excitation_bands.size() * texels.count, 0.0f);
    g.unit_E.resize(scene.lights.size());
    g.unit_E_light_at.assign(scene.lights.size(), Eigen::Vector3d::Constant(std::nan("")));
    g.unit_E_geometry_time.assign(scene.lights.size(), -1);
    stats_.texels += texels.count;
    groups_.push_back(std::move(g));
  }
  InitialStates();
}

void CoupledSolver::InitialStates() {
  for (std::size_t s = 0; s < groups_.size(); ++s) {
    Group& g = groups_[s];
    const InitialState& initial = scene_.objects[g.object].initial;
    const std::size_t n = g.states.n;
    if (initial.kind == InitialState::Kind::kUniform) {
      std::fill(g.states.r.begin(), g.states.r.end(), static_cast<float>(initial.r0));
    } else if (initial.kind == InitialState::Kind::kEquilibrium && GatherIrradiance(g, scene_.start_s)) {
      // dr/dt = 0 in Eq. 8.1: r_i = a_i / (a_i + kr_i), a_i = sum_b ke_i[b] E[b].
      const BatchCoefficients<float>& c = g.coefficients;
      tbb::parallel_for(std::size_t{0}, n, [&](std::size_t j) {
        for (int i = 0; i < c.nc; ++i) {
          double a = 0;
          for (int b = 0; b < c.n_exc; ++b) a += double(c.ke[i * c.n_exc + b]) * g.E[b * n + j];
          g.states.state(i)[j] = a > 0 ? static_cast<float>(a / (a + c.kr[i])) : 0.0f;
        }
      });
    }
    EmitBatch(g.coefficients, g.states, g.Lp.data(), n);
  }
}

void CoupledSolver::UpdateTexelFrames(Group& g) {
  if (g.texel_time == static_cast<double>(geometry_.version()) && !g.texel_position.empty()) return;
  const TexelAtlas::ObjectTexels& texels = atlas_.objects()[atlas_.SlotOf(g.object)];
  g.texel_position.resize(texels.count);
  g.texel_normal.resize(texels.count);
  tbb::parallel_for(0, geometry_.triangle_count(g.object), [&](int t) {
    const int m = texels.m[t];
    const Vec3f normal = geometry_.FrontNormal(g.object, t);
    const Vec3f v0 = geometry_.Vertex(g.object, t, 0), e1 = geometry_.Vertex(g.object, t, 1) - v0,
                e2 = geometry_.Vertex(g.object, t, 2) - v0;
    // Texel k in SubTriangleIndex's order: row i, then upright and inverted alternately.
    std::size_t k = texels.first[t];
    for (int i = 0; i < m; ++i)
      for (int j = 0; j < m - i; ++j)
        for (int inverted = 0; inverted < (i + j < m - 1 ? 2 : 1); ++inverted) {
          const float third = inverted ? 2.0f / 3.0f : 1.0f / 3.0f;
          const float b1 = (static_cast<float>(i) + third) / static_cast<float>(m);
          const float b2 = (static_cast<float>(j) + third) / static_cast<float>(m);
          g.texel_position[k] = v0 + b1 * e1 + b2 * e2;
          g.texel_normal[k++] = normal;
        }
  });
  g.texel_time = static_cast<double>(geometry_.version());
}

const std::vector<float>& CoupledSolver::UnitIrradiance(Group& g, int l) {
  const Light& light = scene_.lights[l];
  const double t = geometry_.time_s();
  const Eigen::Vector3d at = light.kind == Light::Kind::kPoint ? light.PositionAt(t) : light.DirectionAt(t);
  std::vector<float>& unit = g.unit_E[l];
  if (!unit.empty() && at == g.unit_E_light_at[l] && g.unit_E_geometry_time[l] == double(geometry_.version()))
    return unit;
  UpdateTexelFrames(g);
  const std::size_t n = g.states.n;
  unit.resize(n);
  const float epsilon = geometry_.ray_epsilon();
  const Vec3f p_light = at.cast<float>();
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t j = range.begin(); j != range.end(); ++j) {
      const Vec3f& p = g.texel_position[j];
      const Vec3f& normal = g.texel_normal[j];
      float value = 0;
      if (light.kind == Light::Kind::kPoint) {
        const Vec3f d = p_light - p;
        const float distance2 = d.squaredNorm();
        const float distance = std::sqrt(distance2);
        const float cosine = distance > 0 ? normal.dot(d) / distance : 0;
        // E = I cos(theta) / d^2 for a point light, on the front side only.
        if (cosine > 0 && !geometry_.Occluded(p + epsilon * normal, d / distance, distance * (1 - 1e-4f) - epsilon))
          value = cosine / distance2;
      } else {
        const Vec3f to_light = -p_light;  // `at` is the direction light travels
        const float cosine = normal.dot(to_light);
        if (cosine > 0 && !geometry_.Occluded(p + epsilon * normal, to_light, 1e30f)) value = cosine;
      }
      unit[j] = value;
    }
  });
  g.unit_E_light_at[l] = at;
  g.unit_E_geometry_time[l] = double(geometry_.version());
  ++stats_.irradiance_updates;
  stats_.shadow_rays += n;
  return unit;
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
  for (Group& g : groups_) {
    const std::size_t n = g.states.n;
    if (!g.excitation_bands.empty() && GatherIrradiance(g, mid)) {
      AdvanceBatch(Integrator::kExact, g.coefficients, g.E.data(), n, static_cast<float>(h), g.states, g.Lp.data(), n);
      ++stats_.steps;
    } else {
      DecayBatch(g.coefficients, static_cast<float>(h), g.states, g.Lp.data(), n);  // closed-form jump, any length
      ++stats_.dark_jumps;
    }
  }
}

void CoupledSolver::AdvanceTo(double t_s) {
  PHOS_CHECK(t_s >= time_s_);
  if (t_s == time_s_) return;
  // Break points: light switches and keyframes inside (time_s_, t_s).
  std::set<double> breaks = {t_s};
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
    const int substeps = moving ? std::max(1, static_cast<int>(std::ceil((t1 - t0) / max_step - 1e-9))) : 1;
    for (int k = 0; k < substeps; ++k)
      Step(t0 + (t1 - t0) * k / substeps, k + 1 == substeps ? t1 : t0 + (t1 - t0) * (k + 1) / substeps, moving);
    t0 = t1;
  }
  time_s_ = t_s;
  geometry_.SetTime(t_s);
}

}  // namespace phos::render
