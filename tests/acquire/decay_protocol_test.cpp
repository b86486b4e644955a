// The decay protocol on the simulated lab: timing, session files, and the
// physics of what it records (fitted back to the sample's own kr).

#include "phos/acquire/protocols.h"

#include <cmath>
#include <numeric>
#include <gtest/gtest.h>

#include "phos/acquire/sim_lab.h"
#include "phos/fit/decay_fit.h"
#include "phos/model/closed_form.h"
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

// ---- a decay over hours (--decay-span-s) ----------------------------------------

// A slow two-state material (kr 1e-3 and 1e-4 /s: half the glow gone after
// about 20 minutes, a tail for hours) with orange's ke and Lambda in both
// states, so every channel sees the same sum of the two.
Material SlowTwoStateMaterial() {
  Material material = LoadMaterial(testing::Fixture("materials/orange.json"));
  material.name = "slow";
  material.states.push_back(material.states[0]);
  material.states[0].kr = 1e-3;
  material.states[1].kr = 1e-4;
  ValidateMaterial(material, "slow");
  return material;
}

struct SpanCase {
  std::string material;  // a fixture, or "" for SlowTwoStateMaterial
  double span_s, max_exposure_s;
  bool reaches_floor;  // the glow goes below the range at the longest exposure
};

class DecayOverASpan : public ::testing::TestWithParam<SpanCase> {};

// What the protocol recorded of each frame.
struct Recorded {
  double delay_s, exposure_s, brightest;  // brightest channel, as a fraction of the range
  std::vector<double> mean_dn;
  bool clipped;
};

TEST_P(DecayOverASpan, FramesAreLogSpacedWellExposedAndFollowTheClosedForm) {
  const SpanCase param = GetParam();
  const Material material = param.material.empty()
                                ? SlowTwoStateMaterial()
                                : LoadMaterial(testing::Fixture("materials/" + param.material + ".json"));
  VirtualClock clock;
  SimulatedLab lab(material, std::vector<double>(8, 0.8), DefaultLights(), DefaultCameraModel(), clock);
  testing::TempDir dir;
  DecayProtocolOptions options;
  options.charge_light = "led405";
  options.span_s = param.span_s;
  options.max_exposure_s = param.max_exposure_s;
  DecayProtocolResult result;
  {
    SessionWriter session(dir / "s", {{"protocol", "decay"}});
    result = RunDecayProtocol(lab, lab.lights(), clock, session, options);
  }
  // The virtual clock covers the span: the last frame starts at it.
  EXPECT_GE(clock.now_s(), result.light_off_s + param.span_s);
  std::vector<Recorded> frames;
  for (const auto& [frame, line, fields] : ReadProtocolFrames<DecayFrameFields>(dir / "s")) {
    const double range = std::ldexp(1.0, frame.adc_bits) - 1 - frame.black_level_dn;
    double brightest = 0;
    for (double mean : fields.signal.mean_signal_dn) brightest = std::max(brightest, mean / range);
    frames.push_back({fields.delay_after_light_off_s, frame.exposure_s, brightest, fields.signal.mean_signal_dn,
                      fields.signal.clipped()});
  }
  ASSERT_EQ(static_cast<int>(frames.size()), result.frames);
  ASSERT_GE(frames.size(), 20u);
  EXPECT_NEAR(frames.back().delay_s, param.span_s, 1e-6 * param.span_s);

  // Log-spaced: after the first frame (at first_delay_s), every delay is
  // span 10^(-k/10) for a whole k, and a slot between two frames is skipped
  // only when the first one's exposure and readout (10 ms) ran over it.
  EXPECT_NEAR(frames[0].delay_s, options.first_delay_s, 1e-12);
  const std::vector<double> grid = DecayFrameDelays(options);
  for (std::size_t m = 1; m < frames.size(); ++m) {
    const double k = 10 * std::log10(param.span_s / frames[m].delay_s);
    EXPECT_NEAR(k, std::round(k), 1e-6) << frames[m].delay_s;
    for (double slot : grid)
      if (slot > frames[m - 1].delay_s + 1e-9 && slot < frames[m].delay_s - 1e-9) {
        EXPECT_LT(slot, frames[m - 1].delay_s + frames[m - 1].exposure_s + 0.0101) << "slot " << slot << " skipped";
      }
  }

  // Well exposed: once the exposure has found the glow (at most the first
  // two frames probe it), every frame lies between 15% and 70% of the range,
  // unclipped, until the glow falls below the range at the longest exposure;
  // from there on every frame is at the longest exposure. The exposure never
  // shortens as the glow fades.
  std::size_t first = 0;
  while (first < frames.size() && frames[first].brightest < options.low_fraction) ++first;
  EXPECT_LE(first, 2u);
  bool floor = false;
  for (std::size_t m = first; m < frames.size(); ++m) {
    const Recorded& f = frames[m];
    EXPECT_FALSE(f.clipped) << m;
    EXPECT_LE(f.brightest, options.high_fraction) << m;
    floor = floor || f.brightest < options.low_fraction;
    if (floor) {
      EXPECT_EQ(f.exposure_s, param.max_exposure_s) << "frame " << m << " below the range short of the longest";
    }
    if (m > first) {
      EXPECT_GE(f.exposure_s, frames[m - 1].exposure_s) << m;
    }
  }
  EXPECT_EQ(floor, param.reaches_floor);
  EXPECT_GT(frames.back().exposure_s, frames[first].exposure_s);
  EXPECT_GT(frames[first].brightest / frames[first].exposure_s,
            10 * frames.back().brightest / frames.back().exposure_s);

  // Signal per second, the dark current (2 e/s at 0.27 DN/e) removed,
  // against the closed form (model/closed_form.h): each state charged from
  // rest for charge_s, then kr r e^{-kr d} averaged over the exposure,
  // weighted by its Lambda's sum. The states' Lambda have one shape (checked
  // here), so the ratio is the camera's one constant.
  const auto sum = [](const std::vector<double>& v) { return std::accumulate(v.begin(), v.end(), 0.0); };
  for (const ExcitedState& state : material.states)
    for (std::size_t b = 0; b < state.Lambda.size(); ++b)
      ASSERT_NEAR(state.Lambda[b] / sum(state.Lambda), material.states[0].Lambda[b] / sum(material.states[0].Lambda),
                  1e-9);
  lab.lights().Set("led405", true);
  const std::vector<double> a = ExcitationRates(material, lab.IrradianceNow(), "slow");
  lab.lights().Set("led405", false);
  std::vector<double> ratio;
  for (const Recorded& f : frames) {
    double glow = 0;
    for (int i = 0; i < material.state_count(); ++i) {
      const double kr = material.states[i].kr;
      glow += kr * ChargedState(a[i], kr, options.charge_s) * DecayFactor(kr, f.delay_s, f.exposure_s) *
              sum(material.states[i].Lambda);
    }
    ratio.push_back((f.mean_dn[0] / f.exposure_s - 2 * 0.27) / glow);
  }
  const double reference = ratio[first];
  for (std::size_t m = 0; m < frames.size(); ++m) {
    // The shot noise of a frame's mean over 64 x 48 pixels: under 0.1% in
    // range, some 0.5% at the floor's faintest.
    const double tolerance = frames[m].brightest >= options.low_fraction ? 0.005 : 0.02;
    EXPECT_NEAR(ratio[m] / reference, 1, tolerance) << "frame " << m << " at " << frames[m].delay_s << " s";
  }
}

INSTANTIATE_TEST_SUITE_P(OneAndTenHours, DecayOverASpan,
                         ::testing::Values(SpanCase{"", 3600, 30, false}, SpanCase{"", 36000, 30, true},
                                           SpanCase{"", 36000, 4, true}, SpanCase{"sign-paint", 3600, 30, true},
                                           SpanCase{"sign-paint", 36000, 30, true}));

// The span is written to session.json only when set; a session without it
// (every one recorded before it existed) reads as the schedule of interval_s
// and duration_s, and one with a span too short is refused naming the key.
TEST(DecayProtocolOptions, TheSpanIsWrittenOnlyWhenSetAndItsAbsenceIsTheOldSchedule) {
  DecayProtocolOptions options;
  options.charge_light = "led405";
  EXPECT_FALSE(options.ToJson().contains("span_s"));
  const DecayProtocolOptions old = DecayProtocolOptions::FromJson(options.ToJson(), "settings");
  EXPECT_EQ(old.span_s, 0);
  EXPECT_EQ(DecayFrameDelays(old).size(), 42u);
  options.span_s = 3600;
  const nlohmann::json j = options.ToJson();
  EXPECT_EQ(j["span_s"], 3600);
  EXPECT_EQ(DecayProtocolOptions::FromJson(j, "settings").span_s, 3600);
  // From 0.1 s (k = 45) to 3600 s (k = 0), after the first frame at 5 ms.
  const std::vector<double> delays = DecayFrameDelays(DecayProtocolOptions::FromJson(j, "settings"));
  ASSERT_EQ(delays.size(), 47u);
  EXPECT_NEAR(delays[1], 3600 * std::pow(10.0, -4.5), 1e-12);
  for (std::size_t m = 2; m < delays.size(); ++m) EXPECT_NEAR(delays[m] / delays[m - 1], std::pow(10.0, 0.1), 1e-12);
  nlohmann::json short_span = j;
  short_span["span_s"] = 0.5;
  EXPECT_THROW(
      {
        try {
          DecayProtocolOptions::FromJson(short_span, "session.json: settings");
        } catch (const UserError& e) {
          EXPECT_NE(std::string(e.what()).find("span_s"), std::string::npos) << e.what();
          throw;
        }
      },
      UserError);
  // Not positive, not finite, or shorter than a decade of frames: refused.
  std::string error;
  for (double bad : {-1.0, std::nan(""), HUGE_VAL, 0.5, 0.04}) {
    options.span_s = bad;
    EXPECT_FALSE(options.IsValid(&error)) << bad;
    EXPECT_NE(error.find("--decay-span-s"), std::string::npos) << error;
  }
}

TEST(SessionWriter, RefusesAFolderThatHoldsFiles) {
  testing::TempDir dir;
  testing::WriteText(dir / "keep.txt", "precious");
  EXPECT_THROW(SessionWriter(dir.path(), {}), UserError);
  EXPECT_EQ(testing::ReadText(dir / "keep.txt"), "precious");
}

}  // namespace
}  // namespace phos
