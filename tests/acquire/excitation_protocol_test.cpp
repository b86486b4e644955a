// The excitation protocol on the simulated lab, and the excitation fit on
// what it records: capture and fit together give back the sample's ke * E.

#include <cmath>
#include <fstream>
#include <map>
#include <gtest/gtest.h>

#include "phos/acquire/protocols.h"
#include "phos/acquire/sim_lab.h"
#include "phos/fit/excitation_fit.h"
#include "phos/model/schedule.h"
#include "phos/util/error.h"
#include "phos/util/json.h"
#include "test_util.h"

namespace phos {
namespace {

TEST(ExcitationProtocol, DoublesToThePlateauAndTheFitRecoversTheExcitationRate) {
  VirtualClock clock;
  Material orange = LoadMaterial(testing::Fixture("materials/orange.json"));
  SimulatedLab lab(orange, std::vector<double>(8, 0.8), DefaultLights(), DefaultCameraModel(), clock);
  // The truth: a = sum_b ke[b] E[b] under the 405 nm LED.
  lab.lights().Set("led405", true);
  const double a_true = ExcitationRates(orange, lab.IrradianceNow(), "orange")[0];
  lab.lights().Set("led405", false);

  testing::TempDir dir;
  ExcitationProtocolOptions options;
  options.lights = {"led405"};
  options.exposure_s = 0.2;
  ExcitationProtocolResult result;
  {
    SessionWriter session(dir / "s", {{"protocol", "excitation"}});
    result = RunExcitationProtocol(lab, lab.lights(), clock, session, options);
  }
  EXPECT_EQ(ReadJsonFile(dir / "s" / "stop.json")["how"], "complete");
  EXPECT_FALSE(lab.lights().IsOn("led405"));

  std::istringstream lines(testing::ReadText(dir / "s" / "frames.jsonl"));
  std::vector<ExcitationSample> samples;
  std::vector<double> doubling;
  std::map<double, std::vector<nlohmann::json>> by_charge;  // light-off time -> the measurement's frames
  for (std::string line; std::getline(lines, line);) {
    nlohmann::json frame = nlohmann::json::parse(line);
    EXPECT_EQ(frame["light"], "led405");
    EXPECT_EQ(frame["saturated_fraction"].get<double>(), 0.0);
    EXPECT_EQ(frame["tail_frames"], options.tail_frames);
    by_charge[frame["light_off_s"].get<double>()].push_back(frame);
    if (frame["tail"] != 0) continue;
    EXPECT_NEAR(frame["delay_after_light_off_s"].get<double>(), 0.05, 1e-9);
    const double charge = frame["charge_s"], exposure = frame["exposure_s"];
    if (std::fabs(std::log2(charge) - std::round(std::log2(charge))) < 1e-9) doubling.push_back(charge);
    // The green channel's signal per second of exposure.
    samples.push_back(
        {charge, frame["delay_after_light_off_s"], exposure, frame["mean_signal_dn"][1].get<double>() / exposure});
  }
  // Doubled from 1 s until a doubling added less than 3%, then the midpoints.
  ASSERT_GE(doubling.size(), 5u);
  EXPECT_EQ(by_charge.size(), 2 * doubling.size() - 1);
  EXPECT_EQ(result.frames, static_cast<int>(by_charge.size()) * (options.tail_frames + 1));
  EXPECT_GT(doubling.back() * (a_true + 0.015), 3.0);  // it reached the plateau
  // Every charge has its whole tail: frames back to back in the dark, in
  // order, each exposing longer (or as long, near clipping) than the last.
  for (const auto& [off, frames] : by_charge) {
    ASSERT_EQ(frames.size(), static_cast<std::size_t>(options.tail_frames + 1));
    for (std::size_t j = 1; j < frames.size(); ++j) {
      EXPECT_EQ(frames[j]["tail"], static_cast<int>(j));
      EXPECT_EQ(frames[j]["charge_s"], frames[0]["charge_s"]);
      EXPECT_GT(
          frames[j]["delay_after_light_off_s"].get<double>(),
          frames[j - 1]["delay_after_light_off_s"].get<double>() + frames[j - 1]["exposure_s"].get<double>() - 1e-9);
      EXPECT_GE(frames[j]["exposure_s"].get<double>(), frames[j - 1]["exposure_s"].get<double>());
    }
  }

  ExcitationFitOptions fit_options;
  fit_options.kr = 0.015;  // orange, Table 8.1
  ExcitationFitSummary fit = FitExcitation(samples, fit_options, "session");
  EXPECT_NEAR(fit.a, a_true, 0.03 * a_true);
}

// A measurement cut off inside its tail (kill -9 mid-tail) is not "done":
// resuming measures it again whole, and the whole ones are kept.
TEST(ExcitationProtocol, AMeasurementCutInItsTailIsMeasuredAgain) {
  VirtualClock clock;
  Material orange = LoadMaterial(testing::Fixture("materials/orange.json"));
  SimulatedLab lab(orange, std::vector<double>(8, 0.8), DefaultLights(), DefaultCameraModel(), clock);
  testing::TempDir dir;
  ExcitationProtocolOptions options;
  options.lights = {"led405"};
  options.exposure_s = 0.2;
  options.tail_frames = 3;
  {
    SessionWriter session(dir / "s", {{"protocol", "excitation"}});
    RunExcitationProtocol(lab, lab.lights(), clock, session, options);
  }
  const std::vector<nlohmann::json> all = testing::ReadJsonLines(dir / "s" / "frames.jsonl");
  const ExcitationDone whole = ReadExcitationDone(dir / "s");
  ASSERT_EQ(whole.size() * 4, all.size());
  // Keep two whole measurements and two frames of the third.
  {
    std::ofstream out(dir / "s" / "frames.jsonl", std::ios::trunc);
    for (int i = 0; i < 10; ++i) out << all[i].dump() << "\n";
    std::filesystem::remove(dir / "s" / "stop.json");
  }
  const ExcitationDone done = ReadExcitationDone(dir / "s");
  EXPECT_EQ(done.size(), 2u);
  for (const auto& [key, measured] : done) {
    ASSERT_TRUE(whole.count(key));
    EXPECT_DOUBLE_EQ(measured.response, whole.at(key).response);
    EXPECT_EQ(measured.first_saturated, whole.at(key).first_saturated);
    EXPECT_DOUBLE_EQ(measured.first_brightest, whole.at(key).first_brightest);
  }
  auto session = SessionWriter::Reopen(dir / "s");
  RunExcitationProtocol(lab, lab.lights(), clock, *session, options, done);
  session.reset();
  EXPECT_EQ(ReadExcitationDone(dir / "s").size(), whole.size());
  // 10 frames kept, and every measurement but the two whole ones taken again.
  EXPECT_EQ(testing::ReadJsonLines(dir / "s" / "frames.jsonl").size(), 10 + (whole.size() - 2) * 4);
}

// A light's first exposure halves after a bright first frame. Resumed, the
// replay of the kept measurements halves it where the run did, so the next
// first frame is exposed as in a whole run; before, it started again from
// --exposure-s and clipped (a frame the fit leaves out).
TEST(ExcitationProtocol, AResumedLightKeepsItsHalvedFirstExposure) {
  Material orange = LoadMaterial(testing::Fixture("materials/orange.json"));
  ExcitationProtocolOptions options;
  options.lights = {"led405"};
  options.exposure_s = 4;  // bright enough to halve from the third charge on
  options.tail_frames = 3;
  testing::TempDir dir;
  {
    VirtualClock clock;
    SimulatedLab lab(orange, std::vector<double>(8, 0.8), DefaultLights(), DefaultCameraModel(), clock);
    SessionWriter session(dir / "s", {{"protocol", "excitation"}});
    RunExcitationProtocol(lab, lab.lights(), clock, session, options);
  }
  const std::vector<nlohmann::json> all = testing::ReadJsonLines(dir / "s" / "frames.jsonl");
  std::map<double, double> first_exposure;  // charge -> the whole run's first-frame exposure
  for (const nlohmann::json& line : all)
    if (line["tail"] == 0) first_exposure[line["charge_s"].get<double>()] = line["exposure_s"].get<double>();
  {
    std::ofstream out(dir / "s" / "frames.jsonl", std::ios::trunc);
    for (int i = 0; i < 22; ++i) out << all[i].dump() << "\n";  // five whole charges and two frames of the sixth
    std::filesystem::remove(dir / "s" / "stop.json");
  }
  {
    VirtualClock clock;
    SimulatedLab lab(orange, std::vector<double>(8, 0.8), DefaultLights(), DefaultCameraModel(), clock);
    auto session = SessionWriter::Reopen(dir / "s");
    RunExcitationProtocol(lab, lab.lights(), clock, *session, options, ReadExcitationDone(dir / "s"));
  }
  const std::vector<nlohmann::json> resumed = testing::ReadJsonLines(dir / "s" / "frames.jsonl");
  int compared = 0, halved = 0;
  for (std::size_t i = 22; i < resumed.size(); ++i) {
    if (resumed[i]["tail"] != 0) continue;
    const double whole = first_exposure.at(resumed[i]["charge_s"].get<double>());
    EXPECT_DOUBLE_EQ(resumed[i]["exposure_s"].get<double>(), whole) << "charge " << resumed[i]["charge_s"];
    ++compared;
    halved += whole < options.exposure_s;
  }
  EXPECT_GT(compared, 3);
  EXPECT_GT(halved, 0);  // the test has teeth: the run did halve before the cut
}

TEST(ExcitationProtocol, BadOptionsAreClearErrors) {
  VirtualClock clock;
  Material orange = LoadMaterial(testing::Fixture("materials/orange.json"));
  SimulatedLab lab(orange, std::vector<double>(8, 0.8), DefaultLights(), DefaultCameraModel(), clock);
  testing::TempDir dir;
  SessionWriter session(dir / "s", {{"protocol", "excitation"}});
  ExcitationProtocolOptions options;
  EXPECT_THROW(RunExcitationProtocol(lab, lab.lights(), clock, session, options), UserError);  // no light
  options.lights = {"laser"};
  EXPECT_THROW(RunExcitationProtocol(lab, lab.lights(), clock, session, options), UserError);
}

}  // namespace
}  // namespace phos
