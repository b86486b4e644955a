#pragma once
// The adaptive high-accuracy reference integrator for error studies: an
// embedded Dormand-Prince 5(4) pair with step-size control, in long double.
// It does not use the closed form, so it checks the exact update
// independently. It is explicit: on stiff problems (k h in the thousands and
// more) it needs many small steps, and it refuses when it would need more
// than max_steps, rather than run for hours.

#include <cstdint>

namespace phos {

struct ReferenceOptions {
  long double relative_tolerance = 1e-16L;   // per step, on |r|
  long double absolute_tolerance = 1e-300L;  // only to avoid 0/0 at r = 0: the control is relative
  std::int64_t max_steps = 50'000'000;       // per call
};

struct ReferenceStats {
  std::int64_t accepted = 0, rejected = 0, evaluations = 0;
};

// Advances one state of Eq. 8.1 by h_s seconds under constant excitation
// rate a (1/s) and decay rate kr (1/s). Throws UserError if the interval
// would need more than options.max_steps steps.
long double ReferenceAdvance(long double r, double a, double kr, double h_s, const ReferenceOptions& options,
                             ReferenceStats* stats = nullptr);

}  // namespace phos
