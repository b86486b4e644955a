#pragma once
// The rate equation itself (Eq. 8.1) fitted to one curve measured while a
// light of constant level switches on and off: what a photometer, a
// spectrometer or a luminescence reader records of a charge and the decay
// after it, as one curve. Per state i, its decay rate kr_i, its charge rate
// a_i = sum_b ke_i[b] E[b] under that light, and per channel c the signal
// S_ic of the state full (r_i = 1: kr_i Lambda_i seen through the channel,
// Eq. 8.2); per channel a prompt term P_c (a signal while the light is on:
// fluorescence, or a state faster than the sampling) and a background B_c:
//
//   y_c(t) = B_c + P_c on(t) + sum_i S_ic r_i(t),
//   dr_i/dt = (1 - r_i) a_i on(t) - kr_i r_i,   r_i = 0 before the first sample.
//
// r_i follows the closed form over every interval of constant light
// (model/closed_form.h), so the fit is exact for any sampling. The sample
// is assumed dark (r = 0) at the curve's first sample: a sample still
// glowing from an earlier charge shows as a decay before the first light,
// which FitSchedule warns about.
//
// Method. In the curve's own units (curve.h: CurveScale): for given rates
// the model is linear in S, P and B, so states are added one at a time, each
// new (kr, a) from a log grid with the others held and S, P, B solved by
// least squares (S, P >= 0); then Ceres refines every parameter (log kr,
// log a, S, P, B) with automatic differentiation through the closed form;
// 1-sigma uncertainties come from Ceres's covariance scaled by the reduced
// chi-square. The number of states is fixed or chosen by BIC as in the decay
// fits (the fewest within 2 of the lowest, among fits whose states are all
// present and whose rates are more than 2% apart).

#include <string>
#include <vector>

#include "phos/fit/curve.h"

namespace phos {

// The light is on for on_s <= t < off_s (seconds, the curve's time axis).
struct LightWindow {
  double on_s = 0, off_s = 0;
};

struct ScheduleFitOptions {
  std::vector<LightWindow> lights;  // in time order, not overlapping
  int states = 0;                   // fixed number of states, or 0 to choose up to max_states
  int max_states = 6;
  // kPoisson for photon counts: a decay over decades has its tail, a
  // thousandth of its peak, seen at all only when the residuals are
  // weighted by 1 / sqrt(value) (curve.h: SampleWeights).
  Weighting weighting = Weighting::kNone;
  int rate_grid_size = 40;    // kr scanned per added state
  int charge_grid_size = 12;  // a scanned per added state
  int max_iterations = 200;
  // A refinement that stopped at max_iterations, not at a tolerance, is not
  // a result (as for the decay fits): such a count of states is not chosen,
  // and a fit with none converged is a UserError. True: they count, and
  // converged says false.
  bool keep_unconverged = false;

  bool IsValid(std::string* error) const;
};

struct ScheduleState {
  double kr = 0, kr_stderr = 0;  // 1/s
  // a = ke E under the light, 1/s; stderr infinite (JSON null) when a
  // reached (within 10%) a bound of its search (a tenth of a thirtieth of one per longest
  // light, ten times three per smallest step): not resolved.
  double charge_rate = 0, charge_rate_stderr = 0;
  std::vector<double> emission, emission_stderr;  // per channel, the signal at r = 1
};

// The fit's residual over one decade of time after a light went off.
struct DecadeResidual {
  int light = 0;                // which light's switch-off the times count from
  double from_s = 0, to_s = 0;  // after the switch-off
  std::size_t samples = 0;
  double rms_relative = 0;  // rms of the residual over the rms of the fitted signal there, every channel
};

struct ScheduleFitSummary {
  std::vector<ScheduleState> states;                  // fastest first
  std::vector<double> prompt, prompt_stderr;          // per channel
  std::vector<double> background, background_stderr;  // per channel
  int n_states = 0;
  std::vector<double> bic;  // per number of states tried (index n - 1); NaN where invalid
  std::string choice;       // how n_states was chosen, in words
  std::vector<std::string> warnings;
  std::vector<DecadeResidual> residual_by_decade;
  double rss = 0;           // plain sum of squared residuals, data units, every channel
  double weighted_rss = 0;  // what the fit minimized
  bool converged = false;
  int iterations = 0;
  double seconds = 0;
};

// Checks a schedule against a sorted curve: every window inside the curve's
// time range (on_s >= its first time, off_s before its last), in order and
// not overlapping, each followed by dark samples before the next light or
// the end. Problems are UserErrors naming `where` and `option` (e.g. "--light-on").
void ValidateSchedule(const Curve& curve, const std::vector<LightWindow>& lights, const std::string& where,
                      const std::string& option);

// Fits a sorted curve (one or more channels). Bad data is a UserError naming
// `where`; more states than the curve supports are fitted fewer, with a warning.
ScheduleFitSummary FitSchedule(const Curve& curve, const ScheduleFitOptions& options, const std::string& where);

// The fitted model per channel at times t_s (sorted, >= start_s) under
// `lights`, from a dark sample (r = 0) at start_s: values[c][j].
std::vector<std::vector<double>> EvaluateSchedule(const ScheduleFitSummary& fit, const std::vector<LightWindow>& lights,
                                                  double start_s, const std::vector<double>& t_s);

}  // namespace phos
