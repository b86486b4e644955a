#pragma once
// The batch kernel: advances Eq. 8.1 for many points (texels, voxels) of one
// material at once. This is the renderer's hot path (millions of texels per
// frame), so the data are structures of arrays, the loop runs over points in
// chunks that stay in L1 and vectorize (Eigen packet math for exp/expm1), and
// chunks run in parallel with TBB.
//
// "Only what the scene requires" (docs/render.md): a BatchCoefficients is
// compiled for the bands that actually carry irradiance and the bands that
// are actually emitted; a dark step needs no irradiance at all (DecayBatch).

#include <cstddef>
#include <string>
#include <vector>

#include "phos/model/material.h"
#include "phos/model/rate_equation.h"
#include "phos/model/schedule.h"

namespace phos {

template <typename Real>
struct BatchCoefficients {
  int nc = 0;                  // excited states
  int n_exc = 0;               // bands that carry irradiance
  int n_em = 0;                // bands that are emitted
  std::vector<Real> kr;        // [nc]
  std::vector<Real> ke;        // [nc * n_exc], state-major
  std::vector<Real> emission;  // [n_em * nc]: Lambda_i[b] * kr_i (Eq. 8.2)
  // Parameters that vary from point to point (a phosphor map over a surface,
  // Sec. 8.5: "if spatial variation is desired, in textures"). Empty: every
  // point has kr and emission above. Otherwise, for the n points of the
  // batch, state-major: point j's state i decays at kr_per_point[i * n + j]
  // instead of kr[i], and emits emission[b * nc + i] * emission_scale[i * n + j].
  // Only mapped objects carry them: a uniform material pays nothing.
  std::vector<Real> kr_per_point, emission_scale;
  bool per_point() const { return !kr_per_point.empty(); }

  // excitation_bands / emission_bands index the material's grid. A band in
  // excitation_bands whose ke is unknown is a UserError (naming `where`,
  // ending with `remedy`, as ExcitationRates).
  static BatchCoefficients Compile(const Material& material, const std::vector<int>& excitation_bands,
                                   const std::vector<int>& emission_bands, const std::string& where,
                                   const std::string& remedy = kGiveZeroIrradiance);
};

// States of n points, state-major: r[i * n + j] is state i of point j.
template <typename Real>
struct StateBatch {
  int nc = 0;
  std::size_t n = 0;
  std::vector<Real> r;

  StateBatch() = default;
  StateBatch(int states, std::size_t points, Real initial = Real(0))
      : nc(states), n(points), r(static_cast<std::size_t>(states) * points, initial) {}
  Real* state(int i) { return r.data() + static_cast<std::size_t>(i) * n; }
  const Real* state(int i) const { return r.data() + static_cast<std::size_t>(i) * n; }
};

struct BatchStepInfo {
  // max over points and states of h * (a + kr); computed for Euler and RK4
  // only (0 for exact), so callers can check StabilityLimitHk.
  double max_hk = 0.0;
};

// One step of h_s seconds with irradiance E held constant: E[b * E_stride + j]
// is the band-integrated irradiance of excitation band b at point j. If Lp is
// not null, also writes the emitted radiance after the step (Eq. 8.2):
// Lp[b * Lp_stride + j] for emission band b. Integrator::kReference is not a
// batch integrator (it is scalar, for studies) and is rejected.
template <typename Real>
BatchStepInfo AdvanceBatch(Integrator integrator, const BatchCoefficients<Real>& coefficients, const Real* E,
                           std::size_t E_stride, Real h_s, StateBatch<Real>& states, Real* Lp = nullptr,
                           std::size_t Lp_stride = 0);

// A step in darkness: r *= exp(-kr h), exact for any h (the closed-form jump
// across dark intervals). Needs no irradiance. If Lp is not null, also writes
// the emitted radiance after the step, in the same pass (as AdvanceBatch).
template <typename Real>
void DecayBatch(const BatchCoefficients<Real>& coefficients, Real h_s, StateBatch<Real>& states, Real* Lp = nullptr,
                std::size_t Lp_stride = 0);

// Emitted radiance of every point (Eq. 8.2).
template <typename Real>
void EmitBatch(const BatchCoefficients<Real>& coefficients, const StateBatch<Real>& states, Real* Lp,
               std::size_t Lp_stride);

}  // namespace phos
