#pragma once
// Only the states a scene needs: the material with the fewest excited states
// whose emitted radiance (Eq. 8.2) stays within a relative tolerance of the
// full material's over the span a scene lasts, under the light it sees there.
// A one-minute scene needs fewer states than an hour-long one, and a state
// that decays within a frame or glows the same over the whole span costs a
// solver state (Eq. 8.1) for little.
//
// The error at time t (one number per time, the measure of every claim here):
//
//   e(t) = max_b |L_reduced,b(t) - L_full,b(t)| / sum_b L_full,b(t),
//
// the largest band error relative to the full material's total radiance then
// (times where the full material emits nothing are not counted). The
// reduction's error is the max of e(t) over the span [0, span_s], the states
// starting empty (r = 0) at t = 0 under `schedule` (dark after its end).
//
// Method (state_reduction.cpp says why): greedy. From the full material,
// each round tries every merge of two states adjacent in kr and every drop of
// one state, scores each candidate by its largest e(t) on a log-spaced time
// grid evaluated with the closed form (closed_form.h), and keeps the best;
// down to one state. The answer is the fewest states on that path whose
// error, checked again on a denser grid placed between the search grid's
// points, stays within margin x tolerance. The path does not depend on the
// tolerance, so a looser one never keeps more states; a shorter span
// usually keeps fewer (a different grid, so a different path: not a proof).

#include <optional>
#include <string>

#include "phos/model/material.h"
#include "phos/model/schedule.h"

namespace phos {

struct StateReductionOptions {
  double span_s = 0.0;      // the scene's duration from t = 0, s (> 0, finite)
  double dt_s = 1.0 / 30;   // the frame step, s (> 0, finite): errors count from one frame after each switch
  double tolerance = 0.01;  // relative, as e(t) above (> 0, finite)
  // The search aims at margin x tolerance, so that the claim holds on time
  // grids other than the ones searched (in (0, 1]).
  double margin = 0.9;
  // Reduce to exactly this many states instead (the best such material the
  // greedy path finds, whatever its error; for measuring the trade). Clamped
  // to the material's state count.
  std::optional<int> states;
  int points_per_decade = 16;  // of the search grid (the check uses 3x as many)
};

struct StateReduction {
  Material material;       // the reduced material (the full one when nothing can go)
  int states_before = 0;   // the full material's state count
  int states_after = 0;    // material.state_count()
  double max_error = 0.0;  // largest e(t) over the span (search and check grids)
};

// `where` names the material in errors. Bad options are a UserError naming
// the option (span_s, dt_s, tolerance, margin, states); light in a band where
// a ke is unknown is one as ExcitationRates says. Merged states keep ke
// unknown in a band where any of theirs was.
StateReduction ReduceStates(const Material& material, const IrradianceSchedule& schedule,
                            const StateReductionOptions& options, const std::string& where);

// The largest e(t) of `reduced` against `full` at the given times (s) under
// `schedule`, both starting empty; the measure above, for tests and studies.
double MaxRadianceError(const Material& full, const Material& reduced, const IrradianceSchedule& schedule,
                        const std::vector<double>& times_s, const std::string& where);

}  // namespace phos
