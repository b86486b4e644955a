#include "phos/acquire/protocols.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <tuple>

#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/acquire/session_records.h"
#include "phos/util/json.h"

namespace phos {

namespace {

void RecordLight(SessionWriter& session, Lights& lights, const Clock& clock, const std::string& channel, bool on) {
  lights.Set(channel, on);
  session.Event(LightSwitchEvent{clock.now_s(), channel, on}.ToJson());
}

// What a frame shows: each channel's mean and, through the LVF, each
// column's (channels summed), black removed; the brightest of them as a
// fraction of the ADC range above black is returned in `brightest`.
FrameSignal MeasureSignal(const Frame& frame, bool through_lvf, double* brightest) {
  const double range = std::pow(2.0, frame.adc_bits) - 1 - frame.black_level_dn;
  FrameSignal signal;
  *brightest = 0;
  for (int c = 0; c < frame.channels; ++c) {
    signal.mean_signal_dn.push_back(frame.MeanSignal(c));
    *brightest = std::max(*brightest, signal.mean_signal_dn.back() / range);
  }
  signal.saturated_fraction = frame.SaturatedFraction();
  signal.lvf = through_lvf;
  // Through the LVF the light lands in a few columns: judge the exposure by
  // the brightest column, which the frame mean would hide.
  if (!through_lvf) return signal;
  // One pass: each column's mean per channel, black removed. The brightest
  // of those judges the exposure; their sum over channels is the column
  // profile a spectrum is made of, recorded with the frame so fits need
  // not decode images (the raw frame stays for reprocessing).
  std::vector<double> column(static_cast<std::size_t>(frame.width) * frame.channels, -frame.black_level_dn);
  for (int y = 0; y < frame.height; ++y)
    for (std::size_t i = 0; i < column.size(); ++i)
      column[i] += static_cast<double>(frame.pixels[static_cast<std::size_t>(y) * column.size() + i]) / frame.height;
  *brightest = 0;
  signal.column_mean_dn.assign(static_cast<std::size_t>(frame.width), 0.0);
  for (int x = 0; x < frame.width; ++x)
    for (int c = 0; c < frame.channels; ++c) {
      const double mean = column[static_cast<std::size_t>(x) * frame.channels + c];
      *brightest = std::max(*brightest, mean / range);
      signal.column_mean_dn[x] += mean;
    }
  signal.peak_column_fraction = *brightest;
  return signal;
}

// Writes the frame with its record: the protocol's fields and what the frame
// shows (MeasureSignal); returns the brightest channel's (or, through the
// LVF, column's) mean as a fraction of the ADC range above black.
template <typename Fields>
double RecordFrame(SessionWriter& session, const Frame& frame, Fields fields) {
  double brightest = 0;
  fields.signal = MeasureSignal(frame, Fields::kThroughLvf, &brightest);
  session.WriteFrame(frame, fields.ToJson());
  return brightest;
}

// The next exposure after a frame whose brightest channel sat at `brightest`
// of the range: halve when too bright or clipping, double when too dark.
// Returns `exposure` unchanged when the frame was well exposed.
double NextExposure(const AutoExposure& a, double exposure, double brightest, const Frame& frame) {
  if (brightest > a.high_fraction || frame.SaturatedFraction() > 0) return std::max(exposure / 2, a.min_exposure_s);
  if (brightest < a.low_fraction) return std::min(exposure * 2, a.max_exposure_s);
  return exposure;
}

bool WellExposed(const AutoExposure& a, double brightest, const Frame& frame) {
  return brightest >= a.low_fraction && brightest <= a.high_fraction && frame.SaturatedFraction() == 0;
}

void RecordRig(SessionWriter& session, const RigChange& rig, const Clock& clock, const std::string& what,
               bool in_place) {
  rig(what, in_place);
  session.Event(RigEvent{clock.now_s(), what, in_place}.ToJson());
}

// Runs a protocol's body; on any error the session is marked failed with the
// reason first (switching off can fail too, and the guard tries again), then
// the lights go off and the error goes on to the caller.
template <typename Body>
void RunRecorded(SessionWriter& session, Lights& lights, const Clock& clock, const std::string& protocol, Body body) {
  try {
    session.Event(ProtocolEvent{clock.now_s(), protocol, "start"}.ToJson());
    body();
    lights.AllOff();
    session.Event(ProtocolEvent{clock.now_s(), protocol, "end"}.ToJson());
    session.Stop("complete");
  } catch (const std::exception& e) {
    session.StopQuietly("failed", e.what());  // on a full disk this fails too: the error to report is the first
    try {
      lights.AllOff();
    } catch (...) {}
    throw;
  }
}

}  // namespace

namespace {

// The delays of a decay over hours (Sec. 8.4.4 for an afterglow that lasts):
// the first frame at first_delay_s, then kSpanFramesPerDecade frames per
// decade of delay ending at span_s, from the first of them at or after
// kSpanFirstSlot_s. A t^-n glow changes by the same factor from each frame
// to the next, so each is as informative as the one before, and 10 hours
// take 56 frames rather than the 7200 of a frame every 5 s.
std::vector<double> LogSpanDelays(const DecayProtocolOptions& options) {
  const double n = DecayProtocolOptions::kSpanFramesPerDecade;
  const double first_slot = std::max(DecayProtocolOptions::kSpanFirstSlot_s, options.first_delay_s);
  const int steps = static_cast<int>(std::floor(n * std::log10(options.span_s / first_slot) + 1e-9));
  std::vector<double> delays = {options.first_delay_s};
  for (int k = steps; k >= 0; --k) {
    const double delay = options.span_s * std::pow(10.0, -k / n);
    if (delay > options.first_delay_s) delays.push_back(delay);
  }
  return delays;
}

// The time from frame m's slot to the next one's (after the last: the
// schedule's own step).
double SlotGap(const std::vector<double>& delays, std::size_t m, const DecayProtocolOptions& options) {
  if (m + 1 < delays.size()) return delays[m + 1] - delays[m];
  if (options.span_s > 0) return delays[m] * (std::pow(10.0, 1.0 / DecayProtocolOptions::kSpanFramesPerDecade) - 1);
  return options.interval_s;
}

// Over a span, the exposure a faint glow needs may outlast the gap to the
// next slot: it then runs on to end (with its readout) before a later slot,
// and the slots it covers are skipped, so every frame stays on the log grid
// and well exposed. The room for an exposure of `wanted_s` at slot m.
double SpanRoom(const std::vector<double>& delays, std::size_t m, double wanted_s, double readout_s,
                const DecayProtocolOptions& options) {
  double room = 0.9 * SlotGap(delays, m, options) - readout_s;
  for (std::size_t j = m + 2; room < wanted_s && j < delays.size(); ++j)
    room = 0.9 * (delays[j] - delays[m]) - readout_s;
  return room;
}

// The decay's exposure control. The schedule of interval_s: double the
// exposure below low_fraction, halve it above high_fraction or on clipping.
// Over a span (span_s > 0), the frames lie a growing time apart and the glow
// fades by orders of magnitude, so a doubling per frame would lag: the next
// exposure is set for the glow predicted at the next slot, the last two
// frames' signal per second extrapolated as a power law of the delay (at
// most no fade), to put the signal at the geometric middle of the
// well-exposed range. It never shortens unless a frame came out too bright,
// so it grows as the glow fades, up to max_exposure_s, where the glow goes
// below the range: the camera's floor for this protocol.
class DecayExposure {
 public:
  explicit DecayExposure(const DecayProtocolOptions& options)
      : options_(options),
        exposure_(options.initial_exposure_s),
        target_(std::sqrt(options.low_fraction * options.high_fraction)) {}

  // The exposure of a frame at `delay_s`, given at most `room_s`.
  double For(double delay_s, double room_s) const {
    double exposure = exposure_;
    if (options_.span_s > 0 && !rates_.empty()) {
      const auto& [t1, rate1] = rates_.back();
      const auto& [t0, rate0] = rates_.front();
      const double slope = rates_.size() == 2 ? std::log(rate1 / rate0) / std::log(t1 / t0) : 0;
      exposure = std::max(exposure, target_ / (rate1 * std::min(1.0, std::pow(delay_s / t1, slope))));
    }
    return std::min({exposure, options_.max_exposure_s, std::max(1e-6, room_s)});
  }

  // What a frame at `delay_s` exposed for `exposure_s` showed: its brightest
  // channel as a fraction of the range, and whether it clipped.
  void Saw(double delay_s, double exposure_s, double brightest, bool clipped) {
    if (options_.span_s == 0) {
      if (brightest > options_.high_fraction || clipped)
        exposure_ = std::max(exposure_ / 2, 1e-4);
      else if (brightest < options_.low_fraction)
        exposure_ = std::min(exposure_ * 2, options_.max_exposure_s);
      return;
    }
    // A clipped frame under-reads the glow (and says the rates before it
    // were wrong); one under 1% of the range reads mostly noise.
    if (clipped) rates_.clear();
    if (!clipped && brightest > 0.01) rates_.push_back({delay_s + exposure_s / 2, brightest / exposure_s});
    // The glow cannot grow in the dark: a rate that did not fall is noise.
    if (rates_.size() == 3) rates_.erase(rates_.begin());
    if (rates_.size() == 2 && !(rates_[1].second < rates_[0].second)) rates_.erase(rates_.begin());
    if (clipped)
      exposure_ = std::max(exposure_s / 2, 1e-4);
    else if (brightest > options_.high_fraction)
      exposure_ = std::max(exposure_s * target_ / brightest, 1e-4);
    else if (rates_.empty())
      exposure_ = std::min(exposure_s * 2, options_.max_exposure_s);
    else
      exposure_ = exposure_s;  // the floor: never shorter unless too bright
  }

 private:
  const DecayProtocolOptions& options_;
  double exposure_;                               // the next exposure's floor
  double target_;                                 // the signal aimed at, as a fraction of the range
  std::vector<std::pair<double, double>> rates_;  // (mid-exposure delay, brightest fraction per second)
};

}  // namespace

std::vector<double> DecayFrameDelays(const DecayProtocolOptions& options) {
  if (options.span_s > 0) return LogSpanDelays(options);
  std::vector<double> delays = {options.first_delay_s};
  for (int j = options.early_frames; j >= 1; --j)
    delays.push_back(options.first_delay_s + options.interval_s / std::ldexp(1.0, j));
  for (int m = 1; options.first_delay_s + m * options.interval_s <= options.duration_s; ++m)
    delays.push_back(options.first_delay_s + m * options.interval_s);
  return delays;
}

DecayProtocolResult RunDecayProtocol(Camera& camera, Lights& lights, Clock& clock, SessionWriter& session,
                                     const DecayProtocolOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) ThrowUserError("", "decay protocol", error);
  const auto channels = lights.channels();
  if (std::find(channels.begin(), channels.end(), options.charge_light) == channels.end())
    lights.Set(options.charge_light, false);  // names the known channels in its error
  LightsOffGuard guard(lights);
  DecayProtocolResult result;
  RunRecorded(session, lights, clock, "decay", [&] {
    lights.AllOff();
    RecordLight(session, lights, clock, options.charge_light, true);
    clock.SleepFor(options.charge_s);
    RecordLight(session, lights, clock, options.charge_light, false);
    result.light_off_s = clock.now_s();

    DecayExposure exposure(options);
    const std::vector<double> delays = DecayFrameDelays(options);
    double readout_s = 0;     // the camera's time per frame beyond the exposure, as last measured
    double busy_until_s = 0;  // on the clock: the last frame's end
    for (std::size_t m = 0; m < delays.size(); ++m) {
      const double start = result.light_off_s + delays[m];
      if (options.span_s > 0 && busy_until_s > start) continue;  // a longer exposure ran over it
      clock.SleepUntil(start);
      // Never expose (and read out) past the next frame's start. A slot the
      // camera cannot take (its readout leaves under 0.1 ms of exposure, or
      // the slot is gone by now: early frames on a slow camera) is skipped.
      const double delay = clock.now_s() - result.light_off_s;
      const double room = options.span_s > 0 ? SpanRoom(delays, m, exposure.For(delay, HUGE_VAL), readout_s, options)
                                             : 0.9 * SlotGap(delays, m, options) - readout_s;
      if (m + 1 < delays.size() && (room < 1e-4 || clock.now_s() >= result.light_off_s + delays[m + 1])) continue;
      const double exposure_now = exposure.For(delay, room);
      Frame frame = camera.Capture(exposure_now, options.gain);
      busy_until_s = clock.now_s();
      readout_s = std::max(0.0, clock.now_s() - frame.t_start_s - exposure_now);
      const double brightest = RecordFrame(session, frame, DecayFrameFields{frame.t_start_s - result.light_off_s, {}});
      ++result.frames;
      exposure.Saw(frame.t_start_s - result.light_off_s, exposure_now, brightest, frame.SaturatedFraction() > 0);
    }
  });
  return result;
}

ExcitationProtocolResult RunExcitationProtocol(Camera& camera, Lights& lights, Clock& clock, SessionWriter& session,
                                               const ExcitationProtocolOptions& options, const ExcitationDone& done) {
  std::string error;
  if (!options.IsValid(&error)) ThrowUserError("", "excitation protocol", error);
  const auto channels = lights.channels();
  for (const std::string& light : options.lights)
    if (std::find(channels.begin(), channels.end(), light) == channels.end()) lights.Set(light, false);  // names them
  LightsOffGuard guard(lights);
  ExcitationProtocolResult result;
  // Each light's first exposure: halved after a first frame that reached
  // half the clipping point, since the next charge (twice as long) can
  // double the glow; the first frame, the brightest and most informative,
  // is then not lost to clipping on a bright sample.
  std::map<std::string, double> first_exposure;
  auto first_exposure_of = [&](const std::string& light) -> double& {
    return first_exposure.try_emplace(light, options.exposure_s).first->second;
  };
  // The rule, after a charge's first frame: one taken now, or one of an
  // interrupted run replayed, so a resumed light goes on as the run would.
  auto after_first_frame = [&](const std::string& light, bool saturated, double brightest) {
    if (saturated || brightest > options.high_fraction / 2)
      first_exposure_of(light) = std::max(first_exposure_of(light) / 2, 1e-4);
  };
  // One charge-then-measure experiment; returns the brightest channel's signal.
  auto measure = [&](const std::string& light, double charge_s) {
    // Already measured before an interruption: replay its response. Charge
    // times come from doublings and square roots of the same numbers, so
    // they repeat exactly; a relative tolerance guards the last bit.
    for (auto it = done.lower_bound({light, charge_s * (1 - 1e-9)});
         it != done.end() && it->first.first == light && it->first.second <= charge_s * (1 + 1e-9); ++it) {
      const ExcitationMeasured& measured = it->second;
      after_first_frame(light, measured.first_saturated, measured.first_brightest);
      return measured.response;
    }
    lights.AllOff();
    clock.SleepFor(options.reset_s);
    RecordLight(session, lights, clock, light, true);
    clock.SleepFor(charge_s);
    RecordLight(session, lights, clock, light, false);
    const double off = clock.now_s();
    clock.SleepUntil(off + options.delay_s);
    double response = 0, exposure = first_exposure_of(light);
    for (int tail = 0; tail <= options.tail_frames; ++tail) {
      Frame frame = camera.Capture(std::min(exposure, camera.max_exposure_s()), options.gain);
      ++result.frames;
      ExcitationFrameFields fields;
      fields.light = light;
      fields.charge_s = charge_s;
      fields.light_off_s = off;
      fields.delay_after_light_off_s = frame.t_start_s - off;
      fields.tail = tail;
      fields.tail_frames = options.tail_frames;
      const double brightest = RecordFrame(session, frame, fields);
      // The doubling stops on the last frame's response per second: late in
      // the tail the slowest state dominates, and it is the last to reach
      // its plateau (a fast, bright state plateaus first and would stop
      // the doubling while a slow one is still rising).
      if (tail == options.tail_frames) response = brightest / frame.exposure_s;
      if (tail == 0) after_first_frame(light, frame.SaturatedFraction() > 0, brightest);
      // The next frame exposes longer, unless this one came close to clipping.
      if (frame.SaturatedFraction() > 0)
        exposure /= options.tail_growth;
      else if (brightest < options.high_fraction / options.tail_growth)
        exposure *= options.tail_growth;
    }
    return response;
  };
  if (!done.empty()) session.Event(ResumeEvent(clock.now_s(), "measurements_kept", done.size()));
  RunRecorded(session, lights, clock, "excitation", [&] {
    for (const std::string& light : options.lights) {
      // Doubling until the response stops growing.
      std::vector<double> times;
      double previous = -1;
      for (double t = options.first_charge_s; t <= options.max_charge_s * (1 + 1e-12); t *= 2) {
        const double response = measure(light, t);
        times.push_back(t);
        if (previous > 0 && response < options.plateau_growth * previous) break;
        previous = response;
      }
      // Then the midpoints of the rising part, where the charging speed shows.
      for (std::size_t i = 1; i < times.size(); ++i) measure(light, std::sqrt(times[i - 1] * times[i]));
    }
  });
  return result;
}

ExcitationDone ReadExcitationDone(const std::filesystem::path& session_dir) {
  // Per charge (run, light, light-off time: each run's clock starts anew)
  // its last frame's response per second (what the doubling compares) and
  // how many of its frames were recorded.
  struct Measurement {
    double charge_s = 0, response = -1;
    int frames = 0, expected = 1;
    bool first_saturated = false;
    double first_brightest = 0;
  };
  std::map<std::tuple<int, std::string, double>, Measurement> measurements;
  for (const auto& [frame, line, fields] : ReadProtocolFrames<ExcitationFrameFields>(session_dir)) {
    const double range = std::pow(2.0, frame.adc_bits) - 1 - frame.black_level_dn;
    double brightest = 0;
    for (double mean : fields.signal.mean_signal_dn) brightest = std::max(brightest, mean / range);
    Measurement& m = measurements[{frame.run, fields.light, fields.light_off_s}];
    m.charge_s = fields.charge_s;
    m.expected = fields.tail_frames + 1;
    ++m.frames;
    if (fields.tail == m.expected - 1) m.response = brightest / frame.exposure_s;
    if (fields.tail == 0) {
      m.first_saturated = fields.signal.clipped();
      m.first_brightest = brightest;
    }
  }
  ExcitationDone done;
  for (const auto& [key, m] : measurements)
    if (m.frames == m.expected && m.response >= 0)
      done[{std::get<1>(key), m.charge_s}] = {m.response, m.first_saturated, m.first_brightest};
  return done;
}

SpectrumProtocolResult RunSpectrumProtocol(Camera& camera, Lights& lights, Clock& clock, SessionWriter& session,
                                           const RigChange& rig, const SpectrumProtocolOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) ThrowUserError("", "spectrum protocol", error);
  const auto channels = lights.channels();
  if (std::find(channels.begin(), channels.end(), options.charge_light) == channels.end())
    lights.Set(options.charge_light, false);  // names the known channels in its error
  LightsOffGuard guard(lights);
  SpectrumProtocolResult result;
  RunRecorded(session, lights, clock, "spectrum", [&] {
    lights.AllOff();
    // The filter goes in before the first charge, so no glow is lost to it.
    RecordRig(session, rig, clock, "lvf", true);
    double exposure = options.exposure.initial_exposure_s;
    // Every frame is kept; a series that never settles stops after 4x the asked count.
    for (int attempt = 0; result.well_exposed < options.frames && attempt < 4 * options.frames + 8; ++attempt) {
      RecordLight(session, lights, clock, options.charge_light, true);
      clock.SleepFor(attempt == 0 ? options.charge_s : options.recharge_s);
      RecordLight(session, lights, clock, options.charge_light, false);
      const double off = clock.now_s();
      clock.SleepUntil(off + options.first_delay_s);
      Frame frame = camera.Capture(std::min(exposure, camera.max_exposure_s()), options.gain);
      // The glow lands in a few columns per band; judge the exposure there.
      const double brightest = RecordFrame(session, frame, SpectrumFrameFields{frame.t_start_s - off, {}});
      ++result.frames;
      const bool good = WellExposed(options.exposure, brightest, frame);
      result.well_exposed += good;
      session.Event(ExposureEvent{clock.now_s(), session.frame_count(), good}.ToJson());
      exposure = NextExposure(options.exposure, exposure, brightest, frame);
    }
    RecordRig(session, rig, clock, "lvf", false);
    if (result.well_exposed < options.frames)
      ThrowUserError(
          "", "spectrum protocol",
          "only " + std::to_string(result.well_exposed) + " of " + std::to_string(options.frames) +
              " frames were well exposed (the glow is too faint through the filter even at the longest exposure)");
  });
  return result;
}

LvfCalibrationResult RunLvfCalibrationProtocol(Camera& camera, Lights& lights, Clock& clock, SessionWriter& session,
                                               const RigChange& rig, const LvfCalibrationOptions& options,
                                               const std::vector<std::string>& done) {
  std::string error;
  if (!options.IsValid(&error)) ThrowUserError("", "lvf-calibration protocol", error);
  const auto channels = lights.channels();
  for (const CalibrationLine& line : options.lines)
    if (std::find(channels.begin(), channels.end(), line.light) == channels.end()) lights.Set(line.light, false);
  if (std::find(channels.begin(), channels.end(), options.flat_light) == channels.end())
    lights.Set(options.flat_light, false);
  LightsOffGuard guard(lights);
  LvfCalibrationResult result;
  auto is_done = [&](const std::string& light) { return std::find(done.begin(), done.end(), light) != done.end(); };
  // One source: on, step the exposure until a frame is well exposed, off.
  // Every frame is recorded; the well-exposed one says so.
  auto expose = [&](const std::string& light, const LvfCalibrationFrameFields& what) {
    if (!light.empty()) RecordLight(session, lights, clock, light, true);
    // The dark frame is exposed long (an eighth of the longest exposure):
    // the dark signal per second it measures is then well above its noise.
    double exposure = light.empty() ? std::max(options.exposure.initial_exposure_s, options.exposure.max_exposure_s / 8)
                                    : options.exposure.initial_exposure_s;
    bool good = false;
    for (int attempt = 0; attempt < options.max_tries && !good; ++attempt) {
      Frame frame = camera.Capture(std::min(exposure, camera.max_exposure_s()), options.gain);
      const double brightest = RecordFrame(session, frame, what);
      ++result.frames;
      good = light.empty() || WellExposed(options.exposure, brightest, frame);
      session.Event(ExposureEvent{clock.now_s(), session.frame_count(), good}.ToJson());
      const double next = NextExposure(options.exposure, exposure, brightest, frame);
      if (!good && next == exposure) break;  // at a bound: more tries would change nothing
      exposure = next;
    }
    if (!light.empty()) RecordLight(session, lights, clock, light, false);
    if (!good)
      ThrowUserError("", "lvf-calibration protocol",
                     "no well-exposed frame of '" + light + "' (is it on, and does it reach the white reference?)");
    session.Event(CalibratedEvent{clock.now_s(), light}.ToJson());
  };
  if (!done.empty()) session.Event(ResumeEvent(clock.now_s(), "sources_kept", done));
  RunRecorded(session, lights, clock, "lvf-calibration", [&] {
    lights.AllOff();
    RecordRig(session, rig, clock, "white_reference", true);
    RecordRig(session, rig, clock, "lvf", true);
    using Fields = LvfCalibrationFrameFields;
    if (!is_done("")) expose("", Fields::Dark());
    for (const CalibrationLine& line : options.lines)
      if (!is_done(line.light)) expose(line.light, Fields::Line(line.light, line.wavelength_nm));
    if (!is_done(options.flat_light))
      expose(options.flat_light, Fields::Flat(options.flat_light, options.flat_temperature_k, options.flat_irradiance));
    RecordRig(session, rig, clock, "lvf", false);
    RecordRig(session, rig, clock, "white_reference", false);
  });
  return result;
}

std::vector<std::string> ReadLvfCalibrationDone(const std::filesystem::path& session_dir) {
  // A source is done once the event "calibrated" names it ("" = the dark
  // frame) and frames.jsonl still lists its well-exposed frame: a frame set
  // aside, or a lost frame list, means measuring it again.
  std::set<int> well_exposed;
  for (const ExposureEvent& event : ReadExposureEvents(session_dir))
    if (event.well_exposed) well_exposed.insert(event.seq);
  std::vector<std::string> calibrated;
  for (const CalibratedEvent& event : ReadCalibratedEvents(session_dir)) calibrated.push_back(event.light);
  std::set<std::string> listed;
  for (const auto& [frame, line, fields] : ReadProtocolFrames<LvfCalibrationFrameFields>(session_dir))
    if (well_exposed.count(frame.seq))
      listed.insert(fields.kind == LvfCalibrationFrameFields::Kind::kDark ? "" : fields.light);
  std::vector<std::string> done;
  for (const std::string& light : calibrated)
    if (listed.count(light) && std::find(done.begin(), done.end(), light) == done.end()) done.push_back(light);
  return done;
}

}  // namespace phos
