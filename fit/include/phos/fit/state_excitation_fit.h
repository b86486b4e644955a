#pragma once
// Excitation per excited state (Sec. 8.4.6 for nc >= 1). One measurement:
// the sample is reset in the dark (r = 0), charged for t_c under a light,
// the light goes off, and the camera takes a first frame after a short delay
// and then a decay tail of longer frames in the dark. Frame j (delay d_j
// after light-off, exposure e_j) reads, per second of exposure,
//
//   y_j = sum_i S_i r_i(t_c) D_i(d_j, e_j) + B,
//   r_i(t_c) = a_i / (a_i + kr_i) (1 - exp(-(a_i + kr_i) t_c))       (Eq. 8.1)
//   D_i(d, e) = exp(-kr_i d) (1 - exp(-kr_i e)) / (kr_i e),
//
// S_i being state i's signal when saturated (r_i = 1) at light-off, the same
// under every light, a_il = sum_b ke_i[b] E_l[b] its excitation rate
// under light l, and B what is left of the camera's dark signal per second
// (fitted: the tails' faint frames would turn a dark signal taken from
// elsewhere and off by a little into a bias of every a). The kr_i come from the decay. With one frame per charge
// only the sum over states is seen; the tail's shape (the states decay at
// different kr) tells how much of each state a charge made, so every a_il
// is identifiable.
//
// Method: for every measurement, the frames are split into the states by
// non-negative least squares on the known D_i (variable projection's linear
// step); per state, the light that charges it most gives S_i and its a
// (level and speed of the charging curve), the other lights their a with
// S_i known; then one Ceres problem refines every S_i and a_il on all raw
// frames (photon-counting weights), twice: the second time with each
// charge's starting state carried over from the one before (see
// ExcitationMeasurement). 1-sigma uncertainties come from the covariance in
// relative parameters, scaled by the reduced chi-square.

#include <cmath>
#include <map>
#include <string>
#include <vector>

#include "phos/fit/curve.h"

namespace phos {

struct ExcitationFrame {
  double delay_s = 0;     // light-off to the start of the exposure
  double exposure_s = 0;  // 0: an instantaneous reading
  double value = 0;       // signal per second of exposure, background removed
};

struct ExcitationMeasurement {
  std::string light;
  double charge_s = 0;
  std::vector<ExcitationFrame> frames;  // the first frame, then the tail
  // When the light went off, on the session's clock (NaN: not recorded).
  // The reset in the dark before a charge leaves a state that decays at
  // kr_slow a little of the one before it (e^{-kr reset}: 7e-5 for kr 0.01/s
  // after 900 s, a bias at the noise of a frame's mean); the fit carries
  // each state over from the charge before, in the order of these times.
  double light_off_s = std::nan("");
  // The session's run that measured it (0, then one more per resume): each
  // run's clock starts anew, so light_off_s orders measurements within a
  // run only, and nothing is carried over into a run's first measurement.
  int run = 0;
  std::vector<double> start_state = {};  // r_i at the charge's start (empty: 0); the fit sets it
};

struct StateExcitationOptions {
  std::vector<double> kr;  // per state, 1/s, from the decay fit
  bool background = true;  // fit B (else B = 0)
  Weighting weighting = Weighting::kPoisson;
  int max_iterations = 200;
  bool compute_uncertainties = true;

  bool IsValid(std::string* error) const;
};

struct StateExcitationFit {
  std::vector<double> S, S_stderr;                         // per state
  double background = 0;                                   // B, per second
  std::map<std::string, std::vector<double>> a, a_stderr;  // per light, per state (1/s)
  double rss = 0, weighted_rss = 0;
  int frames = 0, iterations = 0;
  bool converged = false;
  std::string termination;  // Ceres's own words when it did not converge
  // Of the weighted Jacobian in relative parameters (d residual / d log p)
  // at the solution: how well the design pins every S_i and a_il.
  double condition_number = 0;
  std::vector<std::string> notes;
  double seconds = 0;
  // The measurements as fitted, each with its carried-over start_state.
  std::vector<ExcitationMeasurement> fitted_measurements;
};

// The model above for one frame.
double ExcitationFrameSignal(const std::vector<double>& S, const std::vector<double>& a, const std::vector<double>& kr,
                             double charge_s, const ExcitationFrame& frame, double background = 0,
                             const std::vector<double>& start_state = {});

// Sets every measurement's start_state from the one before it in time (by
// light_off_s within its run; the first of a run, and any without a time,
// start at 0): its state at light-off under `a` (per light, per state),
// decayed in the dark until this charge began. A resumed run's first
// measurement starts at 0 because the sample rested in the dark between the
// interruption and the resume, and its reset then came on top of that.
void CarryOverStartStates(std::vector<ExcitationMeasurement>& measurements,
                          const std::map<std::string, std::vector<double>>& a, const std::vector<double>& kr);

// Bad data (no measurement, no positive signal) is a UserError naming `where`.
StateExcitationFit FitStateExcitation(const std::vector<ExcitationMeasurement>& measurements,
                                      const StateExcitationOptions& options, const std::string& where);

// What a design (the measurements' charges, delays and exposures; their
// values are ignored) can tell of given parameters, before any data exist:
// the Fisher information for photon-counting noise of one photo-electron
// per unit of value and second of exposure, J' W J in relative parameters.
struct DesignInformation {
  double condition_number = 0;  // of the weighted Jacobian
  // The Cramer-Rao bound of each a_il relative to itself, per light and
  // state (scale it by 1/sqrt(electrons per unit) for a real camera), and
  // the largest of them: the rate the design pins worst.
  std::map<std::string, std::vector<double>> a_relative_stderr;
  double worst_a_relative_stderr = 0;
};
DesignInformation ExcitationDesignInformation(const std::vector<ExcitationMeasurement>& design,
                                              const std::vector<double>& S,
                                              const std::map<std::string, std::vector<double>>& a,
                                              const std::vector<double>& kr);

}  // namespace phos
