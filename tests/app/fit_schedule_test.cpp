// phos fit schedule-curve on files: the JSON contract, the prediction, the
// plot, the units of the data, and bad input as one line with exit code 2.

#include <cmath>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>
#include <string>

#include "phos/model/closed_form.h"
#include "test_util.h"

namespace phos {
namespace {

using testing::RunPhos;

// Two states (kr 0.2 and 0.02/s, a 0.1 and 0.03/s under the light, signals
// 300 and 500), a prompt of 40 and a background of 5: 30 s dark, 300 s light
// on [30, 330), 600 s dark, one sample a second, noise sigma 0.5, values
// times `scale`.
std::string WriteTwoStateCurve(const testing::TempDir& dir, const std::string& name, double scale = 1) {
  const double kr[2] = {0.2, 0.02}, a[2] = {0.1, 0.03}, S[2] = {300, 500};
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0, 0.5);
  std::ostringstream csv;
  csv.precision(17);
  csv << "t,counts\n";
  for (int j = 0; j <= 930; ++j) {
    const double t = j;
    double y = 5 + (t >= 30 && t < 330 ? 40 : 0) + noise(rng);
    for (int i = 0; i < 2; ++i)
      y += S[i] * (t < 30    ? 0.0
                   : t < 330 ? ChargedState(a[i], kr[i], t - 30)
                             : ChargedState(a[i], kr[i], 300.0) * DecayFactor(kr[i], t - 330));
    csv << t << "," << y * scale << "\n";
  }
  testing::WriteText(dir / name, csv.str());
  return (dir / name).string();
}

nlohmann::json FitJson(const std::string& arguments) {
  auto result = RunPhos("fit schedule-curve " + arguments + " --json");
  EXPECT_EQ(result.exit_code, 0) << arguments << ": " << result.err;
  return nlohmann::json::parse(result.out);
}

TEST(FitScheduleCommand, JsonFollowsTheContract) {
  testing::TempDir dir;
  const std::string csv = WriteTwoStateCurve(dir, "c.csv");
  const std::string plot = (dir / "fit.svg").string();
  const nlohmann::json j = FitJson(csv + " --light-on 30:330 --predict-charge-s 60 --plot " + plot);
  ASSERT_EQ(j["n_states"], 2) << j.dump();
  ASSERT_EQ(j["states"].size(), 2u);
  const double kr[2] = {0.2, 0.02}, a[2] = {0.1, 0.03};
  for (int i = 0; i < 2; ++i) {
    const nlohmann::json& s = j["states"][i];
    EXPECT_NEAR(s["kr"].get<double>(), kr[i], 0.03 * kr[i]);
    EXPECT_GT(s["kr_stderr"].get<double>(), 0);
    EXPECT_NEAR(s["charge_rate"].get<double>(), a[i], 0.1 * a[i]);
    EXPECT_EQ(s["emission"].size(), 1u);
    EXPECT_EQ(s["emission_stderr"].size(), 1u);
  }
  EXPECT_NEAR(j["prompt"][0].get<double>(), 40, 2);
  EXPECT_NEAR(j["background"][0].get<double>(), 5, 1);
  ASSERT_GE(j["residual_by_decade"].size(), 3u);
  for (const nlohmann::json& d : j["residual_by_decade"]) {
    EXPECT_NEAR(d["to_s"].get<double>(), 10 * d["from_s"].get<double>(), 1e-9 * d["to_s"].get<double>());
    EXPECT_LT(d["rms_relative"].get<double>(), 0.05);
  }
  EXPECT_EQ(j["lights"][0]["on_s"], 30.0);
  EXPECT_EQ(j["lights"][0]["off_s"], 330.0);
  // The prediction: t from the light going on; the glow at the switch-off
  // of a 60 s charge, from the closed form of the truth.
  const nlohmann::json& p = j["prediction"];
  EXPECT_EQ(p["charge_s"], 60.0);
  ASSERT_EQ(p["t_s"].size(), p["values"][0].size());
  const double S[2] = {300, 500};
  double truth = 5;
  for (int i = 0; i < 2; ++i) truth += S[i] * ChargedState(a[i], kr[i], 60.0);
  EXPECT_EQ(p["t_s"][20], 60.0);
  EXPECT_NEAR(p["values"][0][20].get<double>(), truth, 0.01 * truth);
  EXPECT_TRUE(std::filesystem::exists(plot));
  // Text: the states with their uncertainties.
  auto text = RunPhos("fit schedule-curve " + csv + " --light-on 30:330");
  EXPECT_EQ(text.exit_code, 0) << text.err;
  EXPECT_NE(text.out.find("state 2: kr 0.0"), std::string::npos) << text.out;
  EXPECT_NE(text.out.find("prompt counts 4"), std::string::npos) << text.out;
}

TEST(FitScheduleCommand, TheUnitOfTheValuesDoesNotMatter) {
  // The same curve in W/(sr m^2) at 1e-9: the same rates.
  testing::TempDir dir;
  const nlohmann::json counts = FitJson(WriteTwoStateCurve(dir, "c.csv") + " --light-on 30:330");
  const nlohmann::json radiance = FitJson(WriteTwoStateCurve(dir, "r.csv", 1e-9) + " --light-on 30:330");
  ASSERT_EQ(counts["n_states"], radiance["n_states"]);
  for (std::size_t i = 0; i < counts["states"].size(); ++i) {
    const double kr = counts["states"][i]["kr"].get<double>();
    EXPECT_NEAR(radiance["states"][i]["kr"].get<double>(), kr, 1e-6 * kr);
    const double S = counts["states"][i]["emission"][0].get<double>();
    EXPECT_NEAR(radiance["states"][i]["emission"][0].get<double>() * 1e9, S, 1e-6 * S);
  }
}

TEST(FitScheduleCommand, BadInputGivesOneLineAndExitCode2) {
  testing::TempDir dir;
  const std::string csv = WriteTwoStateCurve(dir, "c.csv");
  struct Case {
    std::string arguments, expected;
  } cases[] = {
      {csv + " --light-on 30:1000", "c.csv: --light-on: 30:1000 is outside the curve's time range (0 to 930 s"},
      {csv + " --light-on -10:330", "--light-on: -10:330 is outside the curve's time range"},
      {csv + " --light-on 30:330 --light-on 300:400", "--light-on: 300:400 overlaps the light before it"},
      {csv + " --light-on 30:928.5", "30:928.5: the curve has 2 sample(s) in the dark after this light"},
      {csv + " --light-on 330:30", "--light-on: 330:30: the light must go off after it goes on"},
      {csv + " --light-on 30-330", "--light-on: expected T0:T1 (seconds"},
      {csv, "--light-on: give at least one light window"},
      {csv + " --light-on 30:330 --predict-charge-s 0", "--predict-charge-s: expected a charge of more than 0 s"},
      {csv + " --light-on 30:330 --predict-charge-s -5", "--predict-charge-s: expected a charge of more than 0 s"},
      {csv + " --light-on 30:330 --states 0", "--states: expected 1 to 8, got 0"},
      {csv + " --light-on 30:330 --max-states 9", "--max-states: expected 1 to 8, got 9"},
      {csv + " --light-on 30:330 --weights x", "--weights: expected none or poisson"},
      {(dir / "none.csv").string() + " --light-on 30:330", "none.csv: cannot open"},
      {"--light-on 30:330", "give one curve file"},
      {csv + " --light-on 30:330 --max-iterations 1",
       "c.csv: no number of states fits the curve (1 state: the solve did not converge within the iteration limit)"},
  };
  for (const Case& c : cases) {
    auto result = RunPhos("fit schedule-curve " + c.arguments);
    EXPECT_TRUE(testing::IsOneLineUserError(result, c.expected)) << c.arguments;
  }
}

TEST(FitScheduleCommand, MoreStatesThanTheCurveSupportsAreSaidAndFittedFewer) {
  testing::TempDir dir;
  testing::WriteText(dir / "short.csv", "t,v\n0,1\n1,1\n2,30\n3,40\n4,45\n5,20\n6,12\n7,8\n8,5\n9,3\n10,2\n");
  auto result = RunPhos("fit schedule-curve " + (dir / "short.csv").string() + " --light-on 2:5 --states 3 --json");
  EXPECT_EQ(result.exit_code, 0) << result.err;
  EXPECT_NE(result.err.find("phos: warning: " + (dir / "short.csv").string() + ": the curve supports only"),
            std::string::npos)
      << result.err;
  const nlohmann::json j = nlohmann::json::parse(result.out);
  EXPECT_LT(j["n_states"].get<int>(), 3);
  EXPECT_EQ(j["warnings"].size(), 1u);
}

TEST(FitScheduleCommand, AnUnconvergedFitIsShownOnlyWhenAsked) {
  testing::TempDir dir;
  const std::string csv = WriteTwoStateCurve(dir, "c.csv");
  auto result =
      RunPhos("fit schedule-curve " + csv + " --light-on 30:330 --max-iterations 2 --keep-unconverged --json");
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_NE(result.err.find("the fit did not converge (the iteration limit); shown because of --keep-unconverged"),
            std::string::npos)
      << result.err;
  EXPECT_FALSE(nlohmann::json::parse(result.out)["converged"].get<bool>());
}

}  // namespace
}  // namespace phos
