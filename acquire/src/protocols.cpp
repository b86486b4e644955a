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
  try {
    lights.AllOff();
    session.Event({{"t_s", clock.now_s()}, {"event", "protocol"}, {"protocol", "decay"}, {"phase", "start"}});
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
      const double range = std::pow(2.0, frame.adc_bits) - 1 - frame.black_level_dn;
      nlohmann::json line;
      line["delay_after_light_off_s"] = frame.t_start_s - result.light_off_s;
      std::vector<double> means;
      double brightest = 0;
      for (int c = 0; c < frame.channels; ++c) {
        means.push_back(frame.MeanSignal(c));
        brightest = std::max(brightest, means.back() / range);
      }
      line["mean_signal_dn"] = means;
      line["saturated_fraction"] = frame.SaturatedFraction();
      session.WriteFrame(frame, line);
      ++result.frames;
      // Auto-exposure for the next frame.
      if (brightest > options.high_fraction || frame.SaturatedFraction() > 0)
        exposure = std::max(exposure / 2, 1e-4);
      else if (brightest < options.low_fraction)
        exposure = std::min(exposure * 2, options.max_exposure_s);
    }
    lights.AllOff();
    session.Event({{"t_s", clock.now_s()}, {"event", "protocol"}, {"protocol", "decay"}, {"phase", "end"}});
    session.Stop("complete");
  } catch (const std::exception& e) {
    // Record why first: switching off can fail too (the guard tries again).
    session.Stop("failed", e.what());
    try {
      lights.AllOff();
    } catch (...) {
    }
    throw;
  }
  return result;
}

}  // namespace phos
