#pragma once
// The closed forms every excitation fit in fit/ is built on (Sec. 8.4.6):
// ChargedState and DecayFactor of model/'s closed_form.h, templates that
// Ceres's Jets run through as plain doubles do (excitation_fit.cpp,
// state_excitation_fit.cpp and the joint refinement in session_fit.cpp).

#include <algorithm>
#include <cmath>

#include "phos/model/closed_form.h"

namespace phos {

// Photon counting for a rate (counts / exposure): its variance is
// value / exposure, so its weight is sqrt(exposure / value), the value
// floored so a sample near zero does not get an infinite weight.
inline double PhotonCountingWeight(double value, double exposure_s, double floor) {
  return std::sqrt(exposure_s / std::max(std::fabs(value), floor));
}

}  // namespace phos
