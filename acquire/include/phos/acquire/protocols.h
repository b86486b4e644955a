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
#include "phos/acquire/session.h"

namespace phos {

// A change to the rig a protocol needs between steps: "lvf" (the linear
// variable filter in front of the camera) or "white_reference" (the white
// reference in place of the sample), in place or removed. The simulated lab
// makes it at once; on real hardware the operator does, prompted on the
// terminal (or a motorized slide). Every change is recorded as an event.
using RigChange = std::function<void(const std::string& what, bool in_place)>;

// Exposure control shared by the protocols: keep the brightest channel's
// mean signal between these fractions of the ADC range above black.
struct AutoExposure {
  double initial_exposure_s = 0.05;
  double min_exposure_s = 1e-4;
  double max_exposure_s = 4;
  double low_fraction = 0.15, high_fraction = 0.7;

  bool IsValid(std::string* error) const;
};

// Decay after saturation (Sec. 8.4.4): charge with the strongest light, light
// off, then frames on a schedule starting a few ms after light-off. The
// exposure grows as the glow fades (and shrinks if it saturates) to keep the
// signal well above the noise; every frame records its exposure and its
// delay after light-off, so fits can normalize.
struct DecayProtocolOptions {
  std::string charge_light;      // the channel to saturate with
  double charge_s = 5400;        // 90 minutes
  double interval_s = 5;         // one frame every
  double duration_s = 180;       // of decay
  double first_delay_s = 0.005;  // light-off to the first exposure
  // Frames between the first and the second slot, at delays halving from
  // interval_s / 2 down: a state that decays in well under interval_s (the
  // fast state of a two-state material, kr up to a few 1/s) is seen by
  // several frames, not one. A slot a slow camera cannot take is skipped.
  // 0: the plain schedule.
  int early_frames = 6;
  double initial_exposure_s = 0.05;
  double max_exposure_s = 4;
  double gain = 1;
  // Auto-exposure keeps the brightest channel's mean signal between these
  // fractions of the ADC range above black.
  double low_fraction = 0.15, high_fraction = 0.7;

  bool IsValid(std::string* error) const;
};

// The frames' delays after light-off: first_delay_s, then the early frames
// at first_delay_s + interval_s / 2^j (j = early_frames..1), then every
// interval_s until duration_s.
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
struct ExcitationProtocolOptions {
  std::vector<std::string> lights;  // channels to measure, one after the other
  double reset_s = 900;             // darkness before each charge (several 1/kr)
  double first_charge_s = 1;
  double max_charge_s = 4096;
  double plateau_growth = 1.03;  // stop doubling when a doubling adds < 3%
  double delay_s = 0.05;         // light-off to exposure
  double exposure_s = 1;
  double gain = 1;
  int tail_frames = 6;         // 0: one frame per charge (the paper's design)
  double tail_growth = 2;      // each tail frame's exposure over the one before
  double high_fraction = 0.7;  // a tail frame above this share of the range stops the growth

  bool IsValid(std::string* error) const;
};

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
struct SpectrumProtocolOptions {
  std::string charge_light;
  double charge_s = 600;
  double recharge_s = 300;
  int frames = 4;
  double first_delay_s = 0.005;
  double gain = 1;
  AutoExposure exposure{0.2, 1e-4, 8, 0.15, 0.7};

  bool IsValid(std::string* error) const;
};

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
struct CalibrationLine {
  std::string light;
  double wavelength_nm;
};

struct LvfCalibrationOptions {
  std::vector<CalibrationLine> lines;
  std::string flat_light = "lamp";
  double flat_temperature_k = 3000;
  double flat_irradiance = 1;  // on the white reference, in the material's units (1: relative only)
  double gain = 1;
  AutoExposure exposure{0.05, 1e-4, 8, 0.15, 0.7};
  int max_tries = 12;  // exposure steps per source before giving up

  bool IsValid(std::string* error) const;
};

struct LvfCalibrationResult {
  int frames = 0;
};

// `done`: lights whose well-exposed frame an interrupted session already holds.
LvfCalibrationResult RunLvfCalibrationProtocol(Camera& camera, Lights& lights, Clock& clock, SessionWriter& session,
                                               const RigChange& rig, const LvfCalibrationOptions& options,
                                               const std::vector<std::string>& done = {});
std::vector<std::string> ReadLvfCalibrationDone(const std::filesystem::path& session_dir);

}  // namespace phos
