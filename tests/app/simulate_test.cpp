// `phos simulate` and `phos plot` as a user runs them: the DESIGN.md
// contract, and one clear line with exit code 2 for every kind of bad input.

#include <cmath>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "model/closed_form.h"
#include "phos/util/csv.h"
#include "test_util.h"

namespace phos {
namespace {

using testing::RunPhos;

std::string Green() { return testing::Fixture("materials/green.json").string(); }
const char* kBlueLight = "1,1,1,0,0,0,0,0";

TEST(SimulateCommand, CsvFollowsTheContract) {
  testing::TempDir dir;
  auto result = RunPhos("simulate --material " + Green() + " --charge-s 10 --irradiance " + kBlueLight +
                        " --decay-s 20 --dt 0.5 --out " + (dir / "g.csv").string());
  ASSERT_EQ(result.exit_code, 0) << result.err;
  CsvTable table = ReadCsv(dir / "g.csv");
  std::vector<std::string> header = {"t", "r_1", "L_1", "L_2", "L_3", "L_4", "L_5", "L_6", "L_7", "L_8"};
  EXPECT_EQ(table.header, header);
  ASSERT_EQ(table.row_count(), 61u);  // 0, 0.5, ..., 30
  const double a = 0.1 + 0.035 + 0.006, kr = 0.227;
  for (std::size_t m = 0; m < table.row_count(); ++m) {
    double t = table.columns[0][m];
    EXPECT_DOUBLE_EQ(t, 0.5 * m);
    long double r = t <= 10 ? testing::ClosedForm(0, a, kr, t)
                            : testing::ClosedForm(testing::ClosedForm(0, a, kr, 10), 0, kr, t - 10);
    EXPECT_TRUE(testing::RelativelyNear(table.columns[1][m], r, 1e-12)) << t;
    EXPECT_TRUE(testing::RelativelyNear(table.columns[5][m], 0.64 * kr * static_cast<double>(r), 1e-12));  // L_4
  }
}

TEST(SimulateCommand, JsonFollowsTheContract) {
  auto result = RunPhos("simulate --material " + Green() + " --charge-s 4 --irradiance " + kBlueLight +
                        " --decay-s 4 --dt 1 --integrator rk4 --json");
  ASSERT_EQ(result.exit_code, 0) << result.err;
  nlohmann::json j = nlohmann::json::parse(result.out);
  ASSERT_EQ(j["t"].size(), 9u);
  ASSERT_EQ(j["r"].size(), 9u);
  ASSERT_EQ(j["r"][0].size(), 1u);
  ASSERT_EQ(j["L"][8].size(), 8u);
  EXPECT_EQ(j["r"][0][0], 0.0);
  EXPECT_EQ(j["integrator"], "rk4");
  EXPECT_GT(j["r"][4][0].get<double>(), j["r"][8][0].get<double>());  // decays after the charge
}

TEST(SimulateCommand, DecayOnlyMaterialsDecayFromAGivenState) {
  auto result = RunPhos("simulate --material " + testing::Fixture("materials/stickers.json").string() +
                        " --decay-s 10 --dt 5 --r0 1 --json");
  ASSERT_EQ(result.exit_code, 0) << result.err;
  nlohmann::json j = nlohmann::json::parse(result.out);
  EXPECT_TRUE(testing::RelativelyNear(j["r"][2][0].get<double>(), std::exp(-0.039L * 10), 1e-12));
}

TEST(SimulateCommand, HelpDescribesEveryOption) {
  auto result = RunPhos("simulate --help");
  ASSERT_EQ(result.exit_code, 0);
  for (const char* option : {"--material", "--charge-s", "--irradiance", "--decay-s", "--dt", "--integrator", "--json",
                             "--r0", "--out", "--plot", "--allow-unstable"})
    EXPECT_NE(result.out.find(option), std::string::npos) << option;
  auto top = RunPhos("--help");
  EXPECT_EQ(top.exit_code, 0);
  EXPECT_NE(top.out.find("simulate"), std::string::npos);
}

struct BadInput {
  std::string arguments;
  std::string expected;  // part of the one line on stderr
};

TEST(SimulateCommand, BadInputGivesOneLineAndExitCode2) {
  testing::TempDir dir;
  testing::WriteText(dir / "broken.json", "{\"schema\": \"phos.material/1\",");
  std::string text = testing::ReadText(Green());
  text.replace(text.find("0.227"), 5, "-0.227");
  testing::WriteText(dir / "negative.json", text);
  const std::string common = " --charge-s 1 --decay-s 1 --dt 0.1";
  const BadInput cases[] = {
      {"simulate --material " + (dir / "none.json").string() + common + " --irradiance 0", "none.json: cannot open the file"},
      {"simulate --material " + (dir / "broken.json").string() + common + " --irradiance 0", "broken.json: not valid JSON"},
      {"simulate --material " + (dir / "negative.json").string() + common + " --irradiance 0",
       "negative.json: states[0].kr: expected a number >= 0, got -0.227"},
      {"simulate --material " + Green() + common + " --irradiance 1", "green.json: states[0].ke[3]: unknown (not measured)"},
      {"simulate --material " + testing::Fixture("materials/bottle.json").string() + common + " --irradiance 1",
       "cannot be charged"},
      {"simulate --material " + Green() + common + " --irradiance 1,2", "--irradiance: expected 1 value or 8"},
      {"simulate --material " + Green() + common + " --irradiance x", "--irradiance: expected a number"},
      {"simulate --material " + Green() + common + " --irradiance -1", "--irradiance: expected values in [0"},
      {"simulate --material " + Green() + " --charge-s 1 --decay-s 1 --dt 0 --irradiance 0", "--dt: expected a step > 0"},
      {"simulate --material " + Green() + " --charge-s -1 --dt 1 --irradiance 0", "--charge-s: expected seconds >= 0"},
      {"simulate --material " + Green() + common + " --irradiance 0 --integrator leapfrog", "--integrator: expected exact"},
      {"simulate --material " + Green() + " --charge-s 100 --irradiance 100,100,100,0,0,0,0,0 --dt 1 --integrator euler",
       "exceeds the stability limit 2"},
      {"simulate --material " + Green() + common + " --irradiance 0 --bogus", "bogus"},
      {"simulate" + common, "--material is required"},
      {"frobnicate", "frobnicate"},
  };
  for (const BadInput& c : cases) {
    auto result = RunPhos(c.arguments);
    EXPECT_TRUE(testing::IsOneLineUserError(result, c.expected)) << c.arguments;
    EXPECT_EQ(result.err.find("internal error"), std::string::npos) << result.err;
  }
}

TEST(SimulateCommand, AFailedRunLosesNothingAlreadyWritten) {
  testing::TempDir dir;
  testing::WriteText(dir / "keep.csv", "precious\n");
  auto result = RunPhos("simulate --material " + Green() + " --charge-s 1 --irradiance 1 --dt 1 --out " +
                        (dir / "keep.csv").string());
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_EQ(testing::ReadText(dir / "keep.csv"), "precious\n");
}

TEST(PlotCommand, DrawsOneLinePerCsv) {
  testing::TempDir dir;
  for (const char* name : {"green", "orange"}) {
    auto r = RunPhos("simulate --material " + testing::Fixture(std::string("materials/") + name + ".json").string() +
                     " --charge-s 10 --irradiance 1,1,1,0,0,0,0,0 --decay-s 30 --out " + (dir / (std::string(name) + ".csv")).string() +
                     " --plot " + (dir / (std::string(name) + ".svg")).string());
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(testing::ReadText(dir / (std::string(name) + ".svg")).find("<svg"), std::string::npos);
  }
  auto r = RunPhos("plot " + (dir / "green.csv").string() + " " + (dir / "orange.csv").string() + " --log-y --out " +
                   (dir / "all.svg").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::string svg = testing::ReadText(dir / "all.svg");
  EXPECT_NE(svg.find(">green</text>"), std::string::npos);
  EXPECT_NE(svg.find(">orange</text>"), std::string::npos);
  testing::WriteText(dir / "other.csv", "x,y\n1,2\n");
  auto bad = RunPhos("plot " + (dir / "other.csv").string() + " --out " + (dir / "x.svg").string());
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("no column 't'"), std::string::npos);
}

}  // namespace
}  // namespace phos
