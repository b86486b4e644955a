// The excitation protocol on the simulated lab, and the excitation fit on
// what it records: capture and fit together give back the sample's ke * E.

#include <cmath>
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
  for (std::string line; std::getline(lines, line);) {
    nlohmann::json frame = nlohmann::json::parse(line);
    EXPECT_EQ(frame["light"], "led405");
    EXPECT_NEAR(frame["delay_after_light_off_s"].get<double>(), 0.05, 1e-9);
    EXPECT_EQ(frame["saturated_fraction"].get<double>(), 0.0);
    const double charge = frame["charge_s"], exposure = frame["exposure_s"];
    if (std::fabs(std::log2(charge) - std::round(std::log2(charge))) < 1e-9) doubling.push_back(charge);
    // The green channel's signal per second of exposure.
    samples.push_back({charge, frame["delay_after_light_off_s"], exposure, frame["mean_signal_dn"][1].get<double>() / exposure});
  }
  // Doubled from 1 s until a doubling added less than 3%, then the midpoints.
  ASSERT_GE(doubling.size(), 5u);
  EXPECT_EQ(result.frames, static_cast<int>(2 * doubling.size() - 1));
  EXPECT_GT(doubling.back() * (a_true + 0.015), 3.0);  // it reached the plateau

  ExcitationFitOptions fit_options;
  fit_options.kr = 0.015;  // orange, Table 8.1
  ExcitationFitSummary fit = FitExcitation(samples, fit_options, "session");
  EXPECT_NEAR(fit.a, a_true, 0.03 * a_true);
}

TEST(ExcitationProtocol, BadOptionsAreClearErrors) {
  VirtualClock clock;
  Material orange = LoadMaterial(testing::Fixture("materials/orange.json"));
  SimulatedLab lab(orange, std::vector<double>(8, 0.8), DefaultLights(), DefaultCameraModel(), clock);
  testing::TempDir dir;
  SessionWriter session(dir / "s", {});
  ExcitationProtocolOptions options;
  EXPECT_THROW(RunExcitationProtocol(lab, lab.lights(), clock, session, options), UserError);  // no light
  options.lights = {"laser"};
  EXPECT_THROW(RunExcitationProtocol(lab, lab.lights(), clock, session, options), UserError);
}

}  // namespace
}  // namespace phos
