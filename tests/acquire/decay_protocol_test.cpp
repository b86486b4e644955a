// The decay protocol on the simulated lab: timing, session files, and the
// physics of what it records (fitted back to the sample's own kr).

#include "phos/acquire/protocols.h"

#include <cmath>
#include <gtest/gtest.h>

#include "phos/acquire/sim_lab.h"
#include "phos/fit/decay_fit.h"
#include "phos/model/rate_equation.h"
#include "phos/model/schedule.h"
#include "phos/util/error.h"
#include "phos/util/json.h"
#include "acquire/lab_util.h"
#include "test_util.h"

namespace phos {
namespace {

using testing::ReadJsonLines;

using testing::Lab;

TEST(SimulatedLab, ChargingFollowsTheModel) {
  Lab lab("orange");
  const std::vector<double> E = [&] {
    lab.lab.lights().Set("led405", true);
    return lab.lab.IrradianceNow();
  }();
  EXPECT_GT(E[0], 0.5);                              // the 405 nm LED lands in 400-437.5 nm ...
  for (int b = 2; b < 8; ++b) EXPECT_EQ(E[b], 0.0);  // ... and nowhere near the red
  lab.clock.Advance(100);
  const double a = ExcitationRates(lab.material, E, "orange")[0];
  EXPECT_NEAR(lab.lab.StateNow()[0], ClosedFormState(0, a, 0.015, 100), 1e-12);
  lab.lab.lights().Set("led405", false);
  lab.clock.Advance(50);
  EXPECT_NEAR(lab.lab.StateNow()[0], ClosedFormState(0, a, 0.015, 100) * std::exp(-0.015 * 50), 1e-12);
}

TEST(SimulatedLab, UnmeasuredKeRefusesALightThatReachesThere) {
  Lab lab("green");
  // White light reaches bands 4-8, where ke is unknown: the switch is refused
  // and the light stays off.
  EXPECT_THROW(lab.lab.lights().Set("white", true), UserError);
  EXPECT_FALSE(lab.lab.lights().IsOn("white"));
}

TEST(DecayProtocol, RecordsTimingFramesAndTheSamplesDecayRate) {
  Lab lab("orange");
  testing::TempDir dir;
  DecayProtocolOptions options;
  options.charge_light = "led405";
  options.charge_s = 1800;
  options.interval_s = 5;
  options.duration_s = 180;
  DecayProtocolResult result;
  {
    SessionWriter session(dir / "s", {{"protocol", "decay"}});
    result = RunDecayProtocol(lab.lab, lab.lab.lights(), lab.clock, session, options);
  }
  // The first slot, 6 early frames before the second, then every 5 s to 180 s.
  EXPECT_EQ(result.frames, 36 + 6);
  EXPECT_EQ(result.light_off_s, 1800);
  EXPECT_FALSE(lab.lab.lights().IsOn("led405"));

  nlohmann::json stop = ReadJsonFile(dir / "s" / "stop.json");
  EXPECT_EQ(stop["how"], "complete");
  std::vector<nlohmann::json> events = ReadJsonLines(dir / "s" / "events.jsonl");
  ASSERT_GE(events.size(), 4u);
  EXPECT_EQ(events[1]["channel"], "led405");
  EXPECT_EQ(events[2]["on"], false);
  EXPECT_EQ(events[2]["t_s"], 1800);
  std::vector<nlohmann::json> frames = ReadJsonLines(dir / "s" / "frames.jsonl");
  ASSERT_EQ(frames.size(), 42u);

  // Timing is part of the data: 5 ms after light-off, then 5 ms + 5 s / 2^j
  // for j = 6..1, then 5 ms + 5 m s.
  const std::vector<double> delays = DecayFrameDelays(options);
  ASSERT_EQ(delays.size(), 42u);
  Curve curve{{}, {{}}, {"G"}};
  for (std::size_t m = 0; m < frames.size(); ++m) {
    const double delay = frames[m]["delay_after_light_off_s"];
    const double expected = m == 0   ? 0.005
                            : m <= 6 ? 0.005 + 5.0 / std::ldexp(1.0, 7 - static_cast<int>(m))
                                     : 0.005 + 5.0 * (m - 6.0);
    EXPECT_NEAR(delays[m], expected, 1e-12);
    EXPECT_NEAR(delay, expected, 1e-9);
    // An exposure never runs into the next frame's slot.
    if (m + 1 < frames.size()) {
      EXPECT_LE(frames[m]["exposure_s"].get<double>(), 0.9 * (delays[m + 1] - delays[m]) + 1e-12);
    }
    Frame frame = ReadFrame(dir / "s" / frames[m]["file"].get<std::string>());
    EXPECT_EQ(frame.width * frame.height * frame.channels, 64 * 48 * 3);
    // Signal per second of exposure, at the middle of the exposure.
    frame.black_level_dn = frames[m]["black_level_dn"];
    const double exposure = frames[m]["exposure_s"];
    curve.t_s.push_back(delay + exposure / 2);
    curve.channels[0].push_back(frame.MeanSignal(1) / exposure);
  }
  // The exposure grew as the glow faded.
  EXPECT_GT(frames.back()["exposure_s"].get<double>(), frames.front()["exposure_s"].get<double>());
  // The recorded decay, fitted, gives back the sample's kr (Table 8.1: 0.015/s).
  DecayFitOptions fit_options;
  fit_options.components = 1;
  fit_options.background = true;  // dark current
  DecayFitSummary fit = FitDecay(curve, fit_options, "session");
  EXPECT_NEAR(fit.components[0].rate, 0.015, 0.03 * 0.015);
}

TEST(DecayProtocol, AFailureMidRunKeepsWhatWasCapturedAndSaysWhy) {
  Lab lab("orange");
  testing::TempDir dir;
  DecayProtocolOptions options;
  options.charge_light = "led405";
  options.charge_s = 60;
  options.max_exposure_s = 100;     // past the camera's 30 s
  options.initial_exposure_s = 20;  // grows to 40 s at some frame: refused
  options.interval_s = 200;
  options.duration_s = 2000;
  {
    SessionWriter session(dir / "s", {{"protocol", "decay"}});
    EXPECT_THROW(RunDecayProtocol(lab.lab, lab.lab.lights(), lab.clock, session, options), UserError);
  }
  EXPECT_FALSE(lab.lab.lights().IsOn("led405"));
  nlohmann::json stop = ReadJsonFile(dir / "s" / "stop.json");
  EXPECT_EQ(stop["how"], "failed");
  EXPECT_NE(stop["why"].get<std::string>().find("cannot expose"), std::string::npos) << stop.dump();
  const int captured = stop["frames"];
  EXPECT_GE(captured, 1);
  EXPECT_EQ(static_cast<int>(ReadJsonLines(dir / "s" / "frames.jsonl").size()), captured);
}

TEST(SessionWriter, RefusesAFolderThatHoldsFiles) {
  testing::TempDir dir;
  testing::WriteText(dir / "keep.txt", "precious");
  EXPECT_THROW(SessionWriter(dir.path(), {}), UserError);
  EXPECT_EQ(testing::ReadText(dir / "keep.txt"), "precious");
}

}  // namespace
}  // namespace phos
