#pragma once
// Simulation of one point under a light schedule: what `phos simulate` runs,
// and the ground of the integrator error study.
//
// Time runs from 0 (start of the schedule); one sample every dt_s seconds
// from 0 to the end of the schedule. Steps are dt_s long, except that a step
// never straddles a light switch: it is split there, so irradiance is
// constant over every step (Eq. 8.1 with piecewise-constant E) and the
// exact integrator stays exact.

#include <cstdint>
#include <string>
#include <vector>

#include "phos/model/material.h"
#include "phos/model/rate_equation.h"
#include "phos/model/reference.h"
#include "phos/model/schedule.h"

namespace phos {

struct SimulationOptions {
  Integrator integrator = Integrator::kExact;
  double dt_s = 1.0;
  // Euler or RK4 past their stability limit is a UserError unless this is
  // set (error studies), in which case it becomes a warning.
  bool allow_unstable = false;
  std::vector<double> r0;  // initial state per excited state; empty = all 0
  ReferenceOptions reference;
  std::int64_t max_samples = 20'000'000;
};

struct SimulationResult {
  int nc = 0, nb = 0;
  std::vector<double> t_s;  // [samples]
  std::vector<double> r;    // [samples * nc]
  std::vector<double> L;    // [samples * nb]: emitted radiance Lp per band (Eq. 8.2)
  std::vector<std::string> warnings;
  std::int64_t steps = 0;  // integrator steps taken (reference: accepted steps)

  std::size_t sample_count() const { return t_s.size(); }
  double state(std::size_t sample, int i) const { return r[sample * nc + i]; }
  double radiance(std::size_t sample, int b) const { return L[sample * nb + b]; }
};

// `where` names the material in errors (its file). Throws UserError for bad
// options, unknown ke under light, or an explicit integrator past its limit.
SimulationResult Simulate(const Material& material, const IrradianceSchedule& schedule,
                          const SimulationOptions& options, const std::string& where);

// Two instants within rounding of each other: a phase boundary summed from
// durations and a sample m dt (0.1 + 0.2 and 3 x 0.1) are the same time.
// Relative to the instants, not to dt: a phase of 1e-12 dt is its own.
bool SameTime(double x, double y);

// Emitted radiance per band of a state vector (Eq. 8.2).
std::vector<double> EmittedRadiance(const Material& material, const double* r);

}  // namespace phos
