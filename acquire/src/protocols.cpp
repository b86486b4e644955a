#include "phos/acquire/protocols.h"

#include <algorithm>
#include <cmath>

#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos {

bool DecayProtocolOptions::IsValid(std::string* error) const {
  if (charge_light.empty()) return *error = "no charge light named", false;
  if (!(charge_s >= 0)) return *error = "charge time must be >= 0", false;
  if (!(interval_s > 0) || !(duration_s > 0)) return *error = "interval and duration must be > 0", false;
  if (!(first_delay_s >= 0)) return *error = "first delay must be >= 0", false;
  if (!(initial_exposure_s > 0) || !(max_exposure_s >= initial_exposure_s))
    return *error = "need 0 < initial exposure <= max exposure", false;
  if (!(low_fraction > 0 && low_fraction < high_fraction && high_fraction < 1))
    return *error = "need 0 < low fraction < high fraction < 1", false;
  return true;
}

namespace {

void RecordLight(SessionWriter& session, Lights& lights, const Clock& clock, const std::string& channel, bool on) {
  lights.Set(channel, on);
  session.Event({{"t_s", clock.now_s()}, {"event", "light"}, {"channel", channel}, {"on", on}});
}

// Writes the frame with its per-channel mean signal and saturated fraction
// added to `line`; returns the brightest channel's mean as a fraction of the
// ADC range above black.
double RecordFrame(SessionWriter& session, const Frame& frame, nlohmann::json line) {
  const double range = std::pow(2.0, frame.adc_bits) - 1 - frame.black_level_dn;
  std::vector<double> means;
  double brightest = 0;
  for (int c = 0; c < frame.channels; ++c) {
    means.push_back(frame.MeanSignal(c));
    brightest = std::max(brightest, means.back() / range);
  }
  line["mean_signal_dn"] = means;
  line["saturated_fraction"] = frame.SaturatedFraction();
  session.WriteFrame(frame, line);
  return brightest;
}

// Runs a protocol's body; on any error the session is marked failed with the
// reason first (switching off can fail too, and the guard tries again), then
// the lights go off and the error goes on to the caller.
template <typename Body>
void RunRecorded(SessionWriter& session, Lights& lights, const Clock& clock, const std::string& protocol, Body body) {
  try {
    session.Event({{"t_s", clock.now_s()}, {"event", "protocol"}, {"protocol", protocol}, {"phase", "start"}});
    body();
    lights.AllOff();
    session.Event({{"t_s", clock.now_s()}, {"event", "protocol"}, {"protocol", protocol}, {"phase", "end"}});
    session.Stop("complete");
  } catch (const std::exception& e) {
    session.Stop("failed", e.what());
    try {
      lights.AllOff();
    } catch (...) {
    }
    throw;
  }
}

}  // namespace

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

    double exposure = options.initial_exposure_s;
    for (int m = 0;; ++m) {
      const double start = result.light_off_s + options.first_delay_s + m * options.interval_s;
      if (start > result.light_off_s + options.duration_s) break;
      clock.SleepUntil(start);
      // Never expose past the next frame's start.
      const double exposure_now = std::min(exposure, std::max(1e-6, 0.9 * options.interval_s));
      Frame frame = camera.Capture(exposure_now, options.gain);
      const double brightest =
          RecordFrame(session, frame, {{"delay_after_light_off_s", frame.t_start_s - result.light_off_s}});
      ++result.frames;
      // Auto-exposure for the next frame.
      if (brightest > options.high_fraction || frame.SaturatedFraction() > 0)
        exposure = std::max(exposure / 2, 1e-4);
      else if (brightest < options.low_fraction)
        exposure = std::min(exposure * 2, options.max_exposure_s);
    }
  });
  return result;
}

bool ExcitationProtocolOptions::IsValid(std::string* error) const {
  if (lights.empty()) return *error = "no light to measure", false;
  if (!(reset_s >= 0) || !(delay_s >= 0)) return *error = "reset and delay must be >= 0", false;
  if (!(first_charge_s > 0) || !(max_charge_s >= first_charge_s))
    return *error = "need 0 < first charge <= max charge", false;
  if (!(plateau_growth > 1)) return *error = "plateau growth must be > 1", false;
  if (!(exposure_s > 0)) return *error = "exposure must be > 0", false;
  return true;
}

ExcitationProtocolResult RunExcitationProtocol(Camera& camera, Lights& lights, Clock& clock, SessionWriter& session,
                                               const ExcitationProtocolOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) ThrowUserError("", "excitation protocol", error);
  const auto channels = lights.channels();
  for (const std::string& light : options.lights)
    if (std::find(channels.begin(), channels.end(), light) == channels.end()) lights.Set(light, false);  // names them
  LightsOffGuard guard(lights);
  ExcitationProtocolResult result;
  // One charge-then-measure experiment; returns the brightest channel's signal.
  auto measure = [&](const std::string& light, double charge_s) {
    lights.AllOff();
    clock.SleepFor(options.reset_s);
    RecordLight(session, lights, clock, light, true);
    clock.SleepFor(charge_s);
    RecordLight(session, lights, clock, light, false);
    const double off = clock.now_s();
    clock.SleepUntil(off + options.delay_s);
    Frame frame = camera.Capture(options.exposure_s, options.gain);
    ++result.frames;
    return RecordFrame(session, frame,
                       {{"light", light}, {"charge_s", charge_s}, {"delay_after_light_off_s", frame.t_start_s - off}});
  };
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

}  // namespace phos
