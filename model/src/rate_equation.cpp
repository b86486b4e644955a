#include "phos/model/rate_equation.h"

#include "phos/util/error.h"

namespace phos {

std::optional<Integrator> ParseIntegrator(std::string_view name) {
  if (name == "exact") return Integrator::kExact;
  if (name == "euler") return Integrator::kEuler;
  if (name == "rk4") return Integrator::kRk4;
  if (name == "reference") return Integrator::kReference;
  return std::nullopt;
}

const char* IntegratorName(Integrator integrator) {
  switch (integrator) {
    case Integrator::kExact: return "exact";
    case Integrator::kEuler: return "euler";
    case Integrator::kRk4: return "rk4";
    case Integrator::kReference: return "reference";
  }
  return "?";
}

double StabilityLimitHk(Integrator integrator) {
  switch (integrator) {
    case Integrator::kEuler: return 2.0;
    case Integrator::kRk4: return kRk4StabilityLimitHk;
    default: return std::numeric_limits<double>::infinity();  // exact; reference adapts its steps
  }
}

double MonotoneLimitHk(Integrator integrator) {
  switch (integrator) {
    case Integrator::kEuler: return 1.0;
    // R(-x) = 1 - x + x^2/2 - x^3/6 + x^4/24 > 0 for all x: RK4 never
    // overshoots; it only diverges past its stability limit.
    case Integrator::kRk4: return kRk4StabilityLimitHk;
    default: return std::numeric_limits<double>::infinity();
  }
}

double ClosedFormState(double r0, double a, double kr, double t) {
  if (a + kr <= 0) return r0;
  return ChargedState(a, kr, t, r0);
}

}  // namespace phos
