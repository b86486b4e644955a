#pragma once
// The closed forms of the rate equation (Eq. 8.1) over an interval of
// constant light, written once for every part of phos: the integrators
// (ExactStep, rate_equation.h), the excitation fits (fit/src/excitation_model.h),
// the editor's solver, the simulated lab and the phosphor maps.
//
//   dr/dt = (1 - r) a - kr r   =>   r(t) = r0 e^{-kt} + r_inf (1 - e^{-kt}),
//   k = a + kr,  r_inf = a / k.
//
// Templates over the number type: float, double, long double, or an
// automatic-differentiation type such as ceres::Jet (the fits and the editor
// differentiate through these very lines). So exp and expm1 are called
// unqualified after `using std::exp;` (a Jet finds its own by argument-
// dependent lookup, as in Ceres's own code), and model/ needs no Ceres. Time
// has its own type: a Jet state over a time in plain double seconds.

#include <algorithm>
#include <cmath>
#include <limits>

namespace phos {

// The state a constant excitation rate a (1/s) holds the state at, where
// dr/dt = 0 in Eq. 8.1: a / (a + kr); 0 without light.
template <typename T>
T SteadyState(const T& a, const T& kr) {
  const T k = a + kr;
  return a / std::max(k, std::numeric_limits<T>::min());  // k = 0 means a = 0: 0
}

// The state t_s seconds after r0 under a constant excitation rate a (1/s):
// r0 e^{-kt} + r_inf (1 - e^{-kt}), exact. 1 - e^{-kt} is -expm1(-kt), so a
// short charge or a weak light keeps every digit (charging from r0 = 0 is
// accurate to a few ulp however small kt is). k = 0 (no light, no decay)
// keeps r0. Not clamped to [0, 1], so that a derivative passes through
// unchanged; ExactStep clamps the rounding ulp for the simulators.
template <typename T, typename Seconds, typename R = double>
T ChargedState(const T& a, const T& kr, const Seconds& t_s, const R& r0 = R(0)) {
  using std::exp;
  using std::expm1;
  const T k = a + kr;
  const T x = -k * t_s;
  const T decay = exp(x);
  const T rise = -expm1(x);                                        // 1 - e^{-kt}, accurate for small kt
  return r0 * decay + SteadyState(a, kr) * rise;
}

// What is left of a state delay_s seconds after the light went off,
// e^{-kr d}; given an exposure e > 0, its mean over the exposure that starts
// then, e^{-kr d} (1 - e^{-kr e}) / (kr e): a camera frame reads the glow
// integrated over its exposure, per second of exposure. kr > 0.
template <typename T, typename Seconds>
T DecayFactor(const T& kr, const Seconds& delay_s, const Seconds& exposure_s = Seconds(0)) {
  using std::exp;
  using std::expm1;
  const T decay = exp(-kr * delay_s);
  if (exposure_s <= 0) return decay;
  return decay * -expm1(-kr * exposure_s) / (kr * exposure_s);
}

// The integral of r over t_s seconds from r0 under a constant a (Eq. 8.1
// integrated): r_inf t + (r0 - r_inf) (1 - e^{-kt}) / k, or r0 t when k = 0.
// An exposure collects the glow kr r Lambda (Eq. 8.2) over it this way.
template <typename T, typename Seconds, typename R = double>
T StateIntegral(const T& a, const T& kr, const Seconds& t_s, const R& r0) {
  using std::expm1;
  const T k = a + kr;
  if (!(k > 0)) return T(r0 * t_s);
  const T r_inf = a / k;
  return r_inf * t_s + (r0 - r_inf) * -expm1(-k * t_s) / k;
}

}  // namespace phos
