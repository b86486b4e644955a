// `phos fit decay-curve` and `phos fit charge-curve` as a user runs them.

#include <cmath>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>

#include "test_util.h"

namespace phos {
namespace {

using testing::RunPhos;

// A two-component decay with noise, as CSV; returns the file.
std::string WriteDecay(const testing::TempDir& dir, const std::string& name, int points = 300) {
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0, 0.5);
  std::ostringstream csv;
  csv << "t,value\n";
  for (int j = 0; j < points; ++j) {
    const double t = j * 0.1;
    csv << t << "," << 400 * std::exp(-1.2 * t) + 150 * std::exp(-0.07 * t) + noise(rng) << "\n";
  }
  testing::WriteText(dir / name, csv.str());
  return (dir / name).string();
}

double PlainRss(const std::string& csv_text, const nlohmann::json& fit) {
  std::istringstream in(csv_text);
  std::string line;
  std::getline(in, line);
  double rss = 0;
  while (std::getline(in, line)) {
    const double t = std::stod(line.substr(0, line.find(','))), y = std::stod(line.substr(line.find(',') + 1));
    double model = 0;
    for (const auto& k : fit["components"]) model += k["amplitude"].get<double>() * std::exp(-k["rate"].get<double>() * t);
    rss += (y - model) * (y - model);
  }
  return rss;
}

TEST(FitDecayCommand, JsonFollowsTheContract) {
  testing::TempDir dir;
  const std::string csv = WriteDecay(dir, "d.csv");
  for (const char* weights : {"none", "poisson"}) {
    auto result = RunPhos("fit decay-curve --csv " + csv + " --max-components 3 --weights " + weights + " --json");
    ASSERT_EQ(result.exit_code, 0) << result.err;
    nlohmann::json j = nlohmann::json::parse(result.out);
    ASSERT_EQ(j["n_components"], 2) << j.dump();
    ASSERT_EQ(j["components"].size(), 2u);
    for (const auto& k : j["components"]) {
      EXPECT_TRUE(k.contains("amplitude") && k.contains("rate") && k.contains("rate_stderr")) << k.dump();
      EXPECT_GT(k["rate_stderr"].get<double>(), 0);
    }
    EXPECT_NEAR(j["components"][0]["rate"].get<double>(), 1.2, 0.05);
    EXPECT_NEAR(j["components"][1]["rate"].get<double>(), 0.07, 0.003);
    EXPECT_GT(j["seconds"].get<double>(), 0);
    // rss is the plain sum of squares in the data's units, whatever the weighting.
    EXPECT_NEAR(j["rss"].get<double>(), PlainRss(testing::ReadText(csv), j), 1e-6 * j["rss"].get<double>()) << weights;
  }
  auto fixed = RunPhos("fit decay-curve --csv " + csv + " --components 1 --json");
  ASSERT_EQ(fixed.exit_code, 0) << fixed.err;
  EXPECT_EQ(nlohmann::json::parse(fixed.out)["n_components"], 1);
}

TEST(FitChargeCommand, JsonFollowsTheContract) {
  testing::TempDir dir;
  std::ostringstream csv;
  csv.precision(17);
  csv << "t,value\n";
  for (int j = 0; j < 100; ++j) csv << j << "," << 5 - 4 * std::exp(-0.03 * j) << "\n";
  testing::WriteText(dir / "c.csv", csv.str());
  auto result = RunPhos("fit charge-curve --csv " + (dir / "c.csv").string() + " --json");
  ASSERT_EQ(result.exit_code, 0) << result.err;
  nlohmann::json j = nlohmann::json::parse(result.out);
  for (const char* key : {"L0", "Linf", "rate", "rss", "seconds"}) EXPECT_TRUE(j.contains(key)) << key;
  EXPECT_NEAR(j["rate"].get<double>(), 0.03, 1e-8);
  EXPECT_NEAR(j["Linf"].get<double>(), 5, 1e-8);
  EXPECT_NEAR(j["L0"].get<double>(), 1, 1e-8);
}

TEST(FitCommands, BadInputGivesOneLineAndExitCode2) {
  testing::TempDir dir;
  const std::string good = WriteDecay(dir, "good.csv");
  testing::WriteText(dir / "empty.csv", "");
  testing::WriteText(dir / "header.csv", "t,value\n");
  testing::WriteText(dir / "one.csv", "t,value\n0,1\n");
  testing::WriteText(dir / "flat.csv", "t,value\n0,1\n1,1\n2,1\n3,1\n4,1\n5,1\n6,1\n7,1\n");
  testing::WriteText(dir / "nan.csv", "t,value\n0,1\n1,nan\n");
  testing::WriteText(dir / "rising.csv", "t,value\n0,1\n1,2\n2,3\n3,4\n4,5\n5,6\n6,7\n7,8\n");
  testing::WriteText(dir / "onecol.csv", "t\n0\n1\n");
  testing::WriteText(dir / "negative.csv", "t,value\n0,-1\n1,-2\n2,-3\n3,-4\n4,-5\n5,-6\n6,-7\n7,-8\n");
  struct Case {
    std::string arguments, expected;
  } cases[] = {
      {"fit decay-curve --csv " + (dir / "none.csv").string() + " --json", "none.csv: cannot open"},
      {"fit decay-curve --csv " + (dir / "empty.csv").string() + " --json", "empty.csv: empty file"},
      {"fit decay-curve --csv " + (dir / "header.csv").string() + " --json", "header.csv: has 0 samples"},
      {"fit decay-curve --csv " + (dir / "one.csv").string() + " --json", "one.csv: has 1 sample"},
      {"fit decay-curve --csv " + (dir / "flat.csv").string() + " --components 1 --json", "every value is the same"},
      {"fit decay-curve --csv " + (dir / "nan.csv").string() + " --json", "nan.csv: line 3, column value: expected a finite number"},
      {"fit decay-curve --csv " + (dir / "rising.csv").string() + " --components 1 --json", "no decaying component"},
      {"fit decay-curve --csv " + (dir / "onecol.csv").string() + " --json", "expected columns t,value"},
      {"fit decay-curve --csv " + (dir / "negative.csv").string() + " --components 1 --json", "no decaying component"},
      {"fit decay-curve --csv " + good + " --components 5 --json", "--components: expected 1 to 4, got 5"},
      {"fit decay-curve --csv " + good + " --components 2 --max-components 3 --json", "excludes"},
      {"fit decay-curve --csv " + good + " --weights gauss --json", "--weights: expected none or poisson"},
      {"fit charge-curve --csv " + (dir / "flat.csv").string() + " --json", "no growth to fit"},
      {"fit charge-curve --csv " + good + " --weights x --json", "--weights"},
      {"fit", "phos fit: A subcommand is required"},
  };
  for (const Case& c : cases) {
    auto result = RunPhos(c.arguments);
    EXPECT_TRUE(testing::IsOneLineUserError(result, c.expected)) << c.arguments;
  }
}

}  // namespace
}  // namespace phos
