#pragma once
// The closed forms every excitation fit in fit/ is built on (Sec. 8.4.6),
// written once: templates, so Ceres's Jets run through the same lines as
// plain doubles (excitation_fit.cpp, state_excitation_fit.cpp and the joint
// refinement in session_fit.cpp).

#include <algorithm>
#include <cmath>

namespace phos {

// The state after charging for t_c from r0 under an excitation rate a
// (Eq. 8.1, exact: r_inf + (r0 - r_inf) e^{-k t_c}, k = a + kr); -expm1
// keeps a weak charge's digits.
template <typename T>
T ChargedState(const T& a, const T& kr, double charge_s, double r0 = 0.0) {
  using std::exp;
  using std::expm1;
  const T k = a + kr;
  return a / k * -expm1(-k * charge_s) + r0 * exp(-k * charge_s);
}

// The decay of a state over the delay after light-off and the exposure,
// per second of exposure: e^{-kr d} (1 - e^{-kr e}) / (kr e), or e^{-kr d}
// for an instantaneous reading (e = 0).
template <typename T>
T DecayFactor(const T& kr, double delay_s, double exposure_s) {
  using std::exp;
  using std::expm1;
  const T decay = exp(-kr * delay_s);
  if (exposure_s <= 0) return decay;
  return decay * -expm1(-kr * exposure_s) / (kr * exposure_s);
}

// Photon counting for a rate (counts / exposure): its variance is
// value / exposure, so its weight is sqrt(exposure / value), the value
// floored so a sample near zero does not get an infinite weight.
inline double PhotonCountingWeight(double value, double exposure_s, double floor) {
  return std::sqrt(exposure_s / std::max(std::fabs(value), floor));
}

}  // namespace phos
