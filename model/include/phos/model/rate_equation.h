#pragma once
// The rate equation of one excited state (Eq. 8.1) and the integrators phos
// offers for it, with their stability limits. Its closed forms are in
// closed_form.h.
//
//   dr/dt = (1 - r) a - kr r,   a = sum_b ke[b] E[b]
//
// With E piecewise constant over a step of h seconds, k = a + kr is constant
// and the equation is linear, so the exact update is
//
//   r(t + h) = r(t) e^{-kh} + r_inf (1 - e^{-kh}),   r_inf = a / k.
//
// It is a convex combination of r(t) and r_inf, both in [0, 1], so it is
// unconditionally stable and stays in [0, 1]; 1 - e^{-kh} is computed as
// -expm1(-kh) so that a short step or a weak light loses no digits (charging
// from r = 0 is then accurate to a few ulp however small kh is).
//
// Forward Euler (the paper's choice, Sec. 8.5) multiplies the distance to
// equilibrium by (1 - hk): stable only for hk < 2 and monotone only for
// hk <= 1. Classic RK4 multiplies it by the degree-4 Taylor polynomial of
// e^{-hk}, which is positive for every hk and below 1 for hk < 2.7853. Both
// limits are checked before a step is taken (SimulationOptions, batch.h).

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <string_view>

#include "phos/model/closed_form.h"

namespace phos {

enum class Integrator {
  kExact,      // closed-form exponential update: the default
  kEuler,      // forward Euler, as in the paper
  kRk4,        // classic fourth-order Runge-Kutta
  kReference,  // adaptive Dormand-Prince 5(4) in long double, for error studies
};

std::optional<Integrator> ParseIntegrator(std::string_view name);
const char* IntegratorName(Integrator integrator);

// Largest hk for which the integrator's step does not amplify errors (|R| <= 1).
double StabilityLimitHk(Integrator integrator);
// Largest hk for which a step never overshoots equilibrium (R >= 0), so r
// cannot leave [0, 1].
double MonotoneLimitHk(Integrator integrator);

// The RK4 limit: real root of x^3 - 4x^2 + 12x - 24 = 0 (|R(-x)| = 1).
inline constexpr double kRk4StabilityLimitHk = 2.785293563405282;

// One step of each integrator for one state, with a = excitation rate (1/s),
// kr (1/s), h (s). Templates so the batch kernels and tests share them.
template <typename Real>
inline Real ExactStep(Real r, Real a, Real kr, Real h) {
  const Real next = ChargedState(a, kr, h, r);  // closed_form.h
  // The exact value lies between r and r_inf, inside [0, 1]; the clamp only
  // removes a rounding ulp, it never hides an error.
  return std::min(Real(1), std::max(Real(0), next));
}

template <typename Real>
inline Real EulerStep(Real r, Real a, Real kr, Real h) {
  return r + h * (a * (Real(1) - r) - kr * r);
}

template <typename Real>
inline Real Rk4Step(Real r, Real a, Real kr, Real h) {
  auto f = [&](Real x) { return a * (Real(1) - x) - kr * x; };
  Real k1 = f(r);
  Real k2 = f(r + Real(0.5) * h * k1);
  Real k3 = f(r + Real(0.5) * h * k2);
  Real k4 = f(r + h * k3);
  return r + h / Real(6) * (k1 + Real(2) * k2 + Real(2) * k3 + k4);
}

// r(t) for constant a from r(0) = r0 in double (ChargedState), for the tests
// and the error study.
double ClosedFormState(double r0, double a, double kr, double t);

}  // namespace phos
