#pragma once
// Capture protocols (Sec. 8.4). Each runs on any Camera, Lights and Clock
// (real hardware or the simulated lab), records every light switch and every
// exposure on the clock, leaves the lights off on every way out, and writes
// the session as it goes. So far: decay and excitation; emission spectrum
// and LVF calibration are to come.

#include <string>
#include <vector>

#include "phos/acquire/camera.h"
#include "phos/acquire/clock.h"
#include "phos/acquire/lights.h"
#include "phos/acquire/session.h"

namespace phos {

// Decay after saturation (Sec. 8.4.4): charge with the strongest light, light
// off, then frames on a schedule starting a few ms after light-off. The
// exposure grows as the glow fades (and shrinks if it saturates) to keep the
// signal well above the noise; every frame records its exposure and its
// delay after light-off, so fits can normalize.
struct DecayProtocolOptions {
  std::string charge_light;       // the channel to saturate with
  double charge_s = 5400;         // 90 minutes
  double interval_s = 5;          // one frame every
  double duration_s = 180;        // of decay
  double first_delay_s = 0.005;   // light-off to the first exposure
  double initial_exposure_s = 0.05;
  double max_exposure_s = 4;
  double gain = 1;
  // Auto-exposure keeps the brightest channel's mean signal between these
  // fractions of the ADC range above black.
  double low_fraction = 0.15, high_fraction = 0.7;

  bool IsValid(std::string* error) const;
};

struct DecayProtocolResult {
  int frames = 0;
  double light_off_s = 0;  // on the clock
};

DecayProtocolResult RunDecayProtocol(Camera& camera, Lights& lights, Clock& clock, SessionWriter& session,
                                     const DecayProtocolOptions& options);

// Excitation per light (Sec. 8.4.6): for each light, reset in darkness,
// charge for t, switch off, wait a fixed short delay, expose; charge times
// double from first_charge_s until the response grows by less than
// `plateau_growth` (or max_charge_s), then the geometric midpoints of the
// rising part are measured too. Every frame records its light, charge time
// and measured delay, for the excitation fit.
struct ExcitationProtocolOptions {
  std::vector<std::string> lights;  // channels to measure, one after the other
  double reset_s = 900;             // darkness before each charge (several 1/kr)
  double first_charge_s = 1;
  double max_charge_s = 4096;
  double plateau_growth = 1.03;     // stop doubling when a doubling adds < 3%
  double delay_s = 0.05;            // light-off to exposure
  double exposure_s = 1;
  double gain = 1;

  bool IsValid(std::string* error) const;
};

struct ExcitationProtocolResult {
  int frames = 0;
};

ExcitationProtocolResult RunExcitationProtocol(Camera& camera, Lights& lights, Clock& clock, SessionWriter& session,
                                               const ExcitationProtocolOptions& options);

}  // namespace phos
