#pragma once
// Excitation fits (Sec. 8.4.6). One experiment: the sample is reset in the
// dark (r = 0), charged for t_c under a light, the light goes off, and after
// a delay t_d the camera integrates the glow for t_e. For one state with
// decay rate kr (known from the decay fit) and excitation rate a under that
// light, Eq. 8.1 gives in closed form
//
//   value = S * r(t_c) * D,   r(t_c) = a / (a + kr) * (1 - exp(-(a + kr) t_c)),
//   D = exp(-kr t_d) * (1 - exp(-kr t_e)) / (kr t_e),
//
// S being the signal of a saturated sample (r = 1) at light-off. D is the
// decay during the delay and the exposure: the paper names the delay as its
// main source of error, so it is part of the model, not ignored. Ceres fits
// log a and S with automatic differentiation (Jets) through this exact
// update; a series over charge times (the doubling schedule) pins both the
// equilibrium level and the charging speed.
//
// When S is known independently (the initial signal of a decay experiment on
// a saturated sample), the level alone and the speed alone each give a; the
// summary reports both and says where they disagree.

#include <optional>
#include <string>
#include <vector>

#include "phos/fit/curve.h"

namespace phos {

struct ExcitationSample {
  double charge_s = 0;    // t_c
  double delay_s = 0;     // t_d, light-off to the start of the exposure
  double exposure_s = 0;  // t_e (0: an instantaneous reading)
  double value = 0;       // measured signal, same units as S
};

struct ExcitationFitOptions {
  double kr = 0;                           // 1/s, from the decay fit
  std::optional<double> saturated_signal;  // S, when measured independently
  Weighting weighting = Weighting::kNone;
  int max_iterations = 100;
};

struct ExcitationFitSummary {
  double a = 0, a_stderr = 0;          // excitation rate under this light, 1/s
  double scale = 0, scale_stderr = 0;  // S (fitted, or the given one)
  double rss = 0;
  // With a known S: a from the level reached alone and from the charging
  // speed alone, and whether they differ by more than 3 combined sigma.
  std::optional<double> a_from_level, a_from_speed;
  bool level_and_speed_disagree = false;
  std::string note;
  double seconds = 0;
};

// The model above, for tests and reports.
double ExcitationSignal(double a, double kr, double S, const ExcitationSample& sample);

ExcitationFitSummary FitExcitation(const std::vector<ExcitationSample>& samples, const ExcitationFitOptions& options,
                                   const std::string& where);

// ke per band from the excitation rates measured under several lights,
// a_l = sum_b ke[b] E_l[b] with ke >= 0 (a bounded Ceres least-squares
// problem). E_per_light[l][b]: band-integrated irradiance of light l. A band
// that no light reaches stays unknown (nullopt): the data say nothing of it,
// and unknown is not zero (docs/model.md).
std::vector<std::optional<double>> KeFromExcitationRates(const std::vector<std::vector<double>>& E_per_light,
                                                         const std::vector<double>& a_per_light,
                                                         const std::string& where);

// The same with the rates' 1-sigma uncertainties: ke as above, and for every
// band whose ke is above its bound 0 the linearized 1-sigma of the weighted
// problem, sqrt(diag((E' W E)^-1)) over those bands (W = 1 / sigma_a^2).
// A band at its bound gets no uncertainty (nullopt), as an unknown band.
struct KeEstimate {
  std::vector<std::optional<double>> ke, ke_stderr;
};
KeEstimate KeWithUncertainty(const std::vector<std::vector<double>>& E_per_light,
                             const std::vector<double>& a_per_light, const std::vector<double>& a_stderr_per_light,
                             const std::string& where);

}  // namespace phos
