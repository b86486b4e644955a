#pragma once
// Capture protocols (Sec. 8.4). Each runs on any Camera, Lights and Clock
// (real hardware or the simulated lab), records every light switch and every
// exposure on the clock, leaves the lights off on every way out, and writes
// the session as it goes: LVF calibration, emission spectrum, decay and
// excitation, in the order `phos capture all` runs them.

#include <functional>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "phos/acquire/camera.h"
#include "phos/acquire/clock.h"
#include "phos/acquire/lights.h"
#include "phos/acquire/protocol_records.h"
#include "phos/acquire/session.h"

namespace phos {

// A change to the rig a protocol needs between steps: "lvf" (the linear
// variable filter in front of the camera) or "white_reference" (the white
// reference in place of the sample), in place or removed. The simulated lab
// makes it at once; on real hardware the operator does, prompted on the
// terminal (or a motorized slide). Every change is recorded as an event.
using RigChange = std::function<void(const std::string& what, bool in_place)>;

// Decay after saturation (Sec. 8.4.4): charge with the strongest light, light
// off, then frames on a schedule starting a few ms after light-off. The
// exposure grows as the glow fades (and shrinks if it saturates) to keep the
// signal well above the noise; every frame records its exposure and its
// delay after light-off, so fits can normalize (DecayProtocolOptions,
// DecayFrameFields in protocol_records.h).
//
// The frames' delays after light-off: first_delay_s, then the early frames
// at first_delay_s + interval_s / 2^j (j = early_frames..1), then every
// interval_s until duration_s. Over a span (span_s > 0, a decay over
// hours): first_delay_s, then span_s 10^(-k/10) for k = K..0, from the
// first at or after 0.1 s, and each exposure is set for the glow predicted
// at its slot (protocols.cpp, DecayExposure).
std::vector<double> DecayFrameDelays(const DecayProtocolOptions& options);

struct DecayProtocolResult {
  int frames = 0;
  double light_off_s = 0;  // on the clock
};

DecayProtocolResult RunDecayProtocol(Camera& camera, Lights& lights, Clock& clock, SessionWriter& session,
                                     const DecayProtocolOptions& options);

// Excitation per light (Sec. 8.4.6): for each light, reset in darkness,
// charge for t, switch off, wait a fixed short delay, expose; charge times
// double from first_charge_s until the response (of the tail's last frame,
// which the slowest state dominates) grows by less than `plateau_growth`
// (or max_charge_s), then the geometric midpoints of the
// rising part are measured too. Every frame records its light, charge time
// and measured delay, for the excitation fit.
//
// After each charge's first frame comes a decay tail: `tail_frames` more
// frames in the dark, back to back, each exposing `tail_growth` times longer
// than the one before (0.2 s, then 0.4 ... 12.8 s by default: 25 s in all).
// With two or more excited states, one frame per charge sees only the sum
// sum_i S_i r_i(t): how much of each state a charge made cannot be told from
// it, so neither can each state's ke. The states decay at different kr
// (known from the decay), so the tail's shape splits the sum into its
// states (docs/fit.md shows the Fisher information of both designs). A
// measurement is kept whole or redone: every frame records its charge's
// light-off time and its place in the tail.
struct ExcitationProtocolResult {
  int frames = 0;
};

// What an interrupted excitation session already measured: the brightest
// channel's response per second of exposure in each charge's last frame,
// per (light, charge time), for the measurements whose tail is whole; a
// measurement cut off inside its tail is measured again. Resuming replays the schedule
// against it and measures only what is missing (each measurement starts with
// its own reset in darkness, so nothing earlier is needed).
struct ExcitationMeasured {
  double response = 0;  // the last frame's brightest channel, per second of exposure
  // Its first frame: clipped pixels, and its brightest channel's mean as a
  // fraction of the ADC's range. The replay applies the protocol's own rule
  // to them, so a resumed light's first exposure is the one the run would
  // have had (halved after a bright first frame), not the default again,
  // which clipped the next first frame.
  bool first_saturated = false;
  double first_brightest = 0;
};
using ExcitationDone = std::map<std::pair<std::string, double>, ExcitationMeasured>;

ExcitationProtocolResult RunExcitationProtocol(Camera& camera, Lights& lights, Clock& clock, SessionWriter& session,
                                               const ExcitationProtocolOptions& options,
                                               const ExcitationDone& done = {});
// Reads the measurements of an excitation session's frames.jsonl.
ExcitationDone ReadExcitationDone(const std::filesystem::path& session_dir);

// Emission spectrum through the LVF (Sec. 8.4.2): the filter goes in, and
// then, frame after frame: charge under a strong light (charge_s the first
// time, recharge_s after), light off, expose `first_delay_s` later. The
// exposure steps between cycles until `frames` frames are well exposed, so
// a glow that fades in seconds (green, yellow) is caught as surely as a slow
// one. Each frame records its exposure and delay, and events.jsonl every
// switch, so the fit knows the state during each frame; the spectrum's
// shape does not change as it fades (Sec. 8.4.5).
struct SpectrumProtocolResult {
  int frames = 0, well_exposed = 0;
};

SpectrumProtocolResult RunSpectrumProtocol(Camera& camera, Lights& lights, Clock& clock, SessionWriter& session,
                                           const RigChange& rig, const SpectrumProtocolOptions& options);

// LVF calibration (Sec. 8.4.2): with the white reference in view and the
// filter in the path, a dark frame, then one well-exposed frame per source
// of known wavelength (which columns pass which wavelength), then a flat
// field under a lamp of known colour temperature (how much each column
// passes). The fit turns these into the filter's centre-vs-column line and
// the per-column response that spectra are divided by.
struct LvfCalibrationResult {
  int frames = 0;
};

// `done`: lights whose well-exposed frame an interrupted session already holds.
LvfCalibrationResult RunLvfCalibrationProtocol(Camera& camera, Lights& lights, Clock& clock, SessionWriter& session,
                                               const RigChange& rig, const LvfCalibrationOptions& options,
                                               const std::vector<std::string>& done = {});
std::vector<std::string> ReadLvfCalibrationDone(const std::filesystem::path& session_dir);

}  // namespace phos
