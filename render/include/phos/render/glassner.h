#pragma once
// The emitted radiance Lp at each pixel's visible point, three ways, for the
// comparison of Fig. 8.16 (phosphorescence by the coupled solver against a
// Monte Carlo baseline after Glassner 1995). For comparison only: phos
// renders with the coupled solver.
//
//  - Ours: the coupled solver's texel state (what a direct frame shows).
//  - Glassner: no state at all; each pixel integrates its point's past
//    irradiance against the decay kernel, r_i(t) = int a_i(tau) e^{-kr_i (t - tau)} dtau,
//    sampling tau in proportion to the kernel (temporal importance sampling),
//    one shadow ray per sample and lit light. Glassner's model is linear: it
//    has no saturation (the (1 - r) of Eq. 8.1), and its cost per frame grows
//    with the history it must integrate.
//  - Reference: the exact solution of Eq. 8.1 at the pixel's exact point
//    (irradiance is piecewise constant in time there, so the exact update is
//    exact), in double.
//
// All three need static geometry and static lights (switching and dimming are
// fine); a scene with motion is a UserError.

#include <cstdint>

#include "phos/render/renderer.h"
#include "phos/render/solver.h"

namespace phos::render {

// One sample at each pixel centre; Lp per band, zero where no phosphor is seen.
Image EmittedRadianceOurs(const SceneGeometry& geometry, const CoupledSolver& solver);
Image EmittedRadianceReference(const SceneGeometry& geometry, double t_s);
Image EmittedRadianceGlassner(const SceneGeometry& geometry, double t_s, int time_samples, std::uint64_t seed,
                              std::uint64_t* shadow_rays = nullptr);

}  // namespace phos::render
