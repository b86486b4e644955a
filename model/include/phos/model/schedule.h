#pragma once
// A light schedule at one point: consecutive phases of constant,
// band-integrated irradiance E[b] (Eq. 8.1 holds E piecewise constant). A
// phase with E = 0 everywhere is darkness, where the state decays in closed form.

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "phos/model/material.h"

namespace phos {

struct IrradiancePhase {
  double duration_s = 0.0;
  std::vector<double> E;  // per band of the material's grid
  std::string label;      // "charge", "dark", ...
  bool dark() const;
};

class IrradianceSchedule {
 public:
  // The schedule of `phos simulate`: charge for charge_s under E, then dark for decay_s.
  static IrradianceSchedule ChargeThenDecay(const std::vector<double>& E, double charge_s, double decay_s);

  void Add(double duration_s, std::vector<double> E, std::string label);
  const std::vector<IrradiancePhase>& phases() const { return phases_; }
  double total_s() const;

 private:
  std::vector<IrradiancePhase> phases_;
};

// The schedule on a grid of frames of dt_s, frame f holding from f dt_s to
// (f + 1) dt_s: each frame's irradiance is the mean of the phases over it, so
// a switch inside a frame keeps that frame's dose (Eq. 8.1 then holds it
// constant over the frame). A phase boundary t with |t / dt_s - k| <= 1e-9
// max(1, k) for a whole k (the rounding of durations summed) is taken on
// k dt_s, so a frame wholly in one phase gets that phase's E exactly (a
// dark frame stays exactly dark). The phases must last a whole number of
// frames (to the same relative 1e-9; the caller names its field if not: see
// WholeFrames).
std::vector<std::vector<double>> FrameIrradiance(const IrradianceSchedule& schedule, double dt_s);
// The number of frames of dt_s that `total_s` lasts, or nullopt unless that
// is a whole number (to a relative 1e-9, as above).
std::optional<long long> WholeFrames(double total_s, double dt_s);

// The excitation rate a_i = sum_b ke_i[b] E[b] of every state (Eq. 8.1), in 1/s.
// Irradiance in a band where some ke is unknown is a UserError naming the
// state, the band and `where`: such a material may decay but not be charged
// there. `remedy` ends the message: what the caller's user can do about it.
// `charged_by`, if given, names what puts light into band b (a scene's
// lights, with their own value there) instead of E[b], for a caller whose E
// is a probe rather than the user's irradiance.
inline constexpr const char* kGiveZeroIrradiance = "give 0 irradiance in that band";
std::vector<double> ExcitationRates(const Material& material, const std::vector<double>& E, const std::string& where,
                                    const std::string& remedy = kGiveZeroIrradiance,
                                    const std::function<std::string(int band)>& charged_by = {});

}  // namespace phos
