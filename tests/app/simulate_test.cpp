// `phos simulate` and `phos plot` as a user runs them: their output as
// docs/formats.md gives it, and one clear line with exit code 2 for every
// kind of bad input.

#include <array>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "model/closed_form.h"
#include "phos/model/material.h"
#include "phos/model/photometry.h"
#include "phos/util/csv.h"
#include "phos/util/version.h"
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

// A physical material's radiance is in W/(sr m²), and its luminance in cd/m²
// follows as a last column (CSV) or key (JSON); a relative material has none.
TEST(SimulateCommand, APhysicalMaterialAddsItsLuminance) {
  const std::string paint = testing::Fixture("materials/physical/sign-paint.json").string();
  const Material material = LoadMaterial(paint);
  const std::string run = "simulate --material " + paint + " --charge-s 300 --irradiance 0.2 --decay-s 600 --dt 60";
  testing::TempDir dir;
  ASSERT_EQ(RunPhos(run + " --out " + (dir / "p.csv").string()).exit_code, 0);
  const CsvTable table = ReadCsv(dir / "p.csv");
  ASSERT_EQ(table.header.back(), "luminance_cd_m2");
  ASSERT_EQ(table.header.size(), 1u + 2u + 10u + 1u);
  const auto result = RunPhos(run + " --json");
  ASSERT_EQ(result.exit_code, 0) << result.err;
  const nlohmann::json j = nlohmann::json::parse(result.out);
  ASSERT_EQ(j["luminance_cd_m2"].size(), table.row_count());
  for (std::size_t m = 0; m < table.row_count(); ++m) {
    std::vector<double> L;
    for (int b = 0; b < 10; ++b) L.push_back(table.columns[3 + b][m]);
    const double Y = Luminance(L, material.bands);
    EXPECT_TRUE(testing::RelativelyNear(table.columns.back()[m], Y, 1e-12, 1e-300)) << m;
    EXPECT_TRUE(testing::RelativelyNear(j["luminance_cd_m2"][m], Y, 1e-12, 1e-300)) << m;
  }
  EXPECT_GT(table.columns.back()[5], 0.0);
  const auto relative =
      RunPhos("simulate --material " + Green() + " --charge-s 4 --irradiance " + kBlueLight + " --json");
  EXPECT_FALSE(nlohmann::json::parse(relative.out).contains("luminance_cd_m2"));
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
      {"simulate --material " + (dir / "none.json").string() + common + " --irradiance 0",
       "none.json: cannot open the file"},
      {"simulate --material " + (dir / "broken.json").string() + common + " --irradiance 0",
       "broken.json: not valid JSON"},
      {"simulate --material " + (dir / "negative.json").string() + common + " --irradiance 0",
       "negative.json: states[0].kr: expected a number >= 0, got -0.227"},
      {"simulate --material " + Green() + common + " --irradiance 1",
       "green.json: states[0].ke[3]: unknown (not measured)"},
      {"simulate --material " + testing::Fixture("materials/bottle.json").string() + common + " --irradiance 1",
       "cannot be charged"},
      {"simulate --material " + Green() + common + " --irradiance 1,2", "--irradiance: expected 1 value or 8"},
      {"simulate --material " + Green() + common + " --irradiance x", "--irradiance: expected a number"},
      {"simulate --material " + Green() + common + " --irradiance -1", "--irradiance: expected values in [0"},
      {"simulate --material " + Green() + " --charge-s 1 --decay-s 1 --dt 0 --irradiance 0",
       "--dt: expected a step > 0"},
      {"simulate --material " + Green() + " --charge-s -1 --dt 1 --irradiance 0", "--charge-s: expected seconds >= 0"},
      {"simulate --material " + Green() + common + " --irradiance 0 --integrator leapfrog",
       "--integrator: expected exact"},
      {"simulate --material " + Green() +
           " --charge-s 100 --irradiance 100,100,100,0,0,0,0,0 --dt 1 --integrator euler",
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

TEST(SimulateCommand, SamplesTheEndWhenTheStepDoesNotDivideIt) {
  // --dt 3 over 10 + 10 s: 0, 3, ..., 18, and the end, 20.
  auto result = RunPhos("simulate --material " + Green() + " --charge-s 10 --irradiance " + kBlueLight +
                        " --decay-s 10 --dt 3 --json");
  ASSERT_EQ(result.exit_code, 0) << result.err;
  nlohmann::json j = nlohmann::json::parse(result.out);
  const std::vector<double> t = j["t"].get<std::vector<double>>();
  ASSERT_EQ(t.size(), 8u);
  EXPECT_EQ(t[6], 18.0);
  EXPECT_EQ(t.back(), 20.0);
  const double a = 0.1 + 0.035 + 0.006, kr = 0.227;
  const long double end = testing::ClosedForm(testing::ClosedForm(0, a, kr, 10), 0, kr, 10);
  EXPECT_TRUE(testing::RelativelyNear(j["r"][7][0].get<double>(), end, 1e-12));
  EXPECT_TRUE(testing::RelativelyNear(j["L"][7][3].get<double>(), 0.64 * kr * static_cast<double>(end), 1e-12));
  // Ending inside the charge (no decay) too.
  auto charge =
      RunPhos("simulate --material " + Green() + " --charge-s 10 --irradiance " + kBlueLight + " --dt 4 --json");
  ASSERT_EQ(charge.exit_code, 0) << charge.err;
  nlohmann::json c = nlohmann::json::parse(charge.out);
  EXPECT_EQ(c["t"].get<std::vector<double>>(), (std::vector<double>{0, 4, 8, 10}));
  EXPECT_TRUE(testing::RelativelyNear(c["r"][3][0].get<double>(), testing::ClosedForm(0, a, kr, 10), 1e-12));
}

TEST(SimulateCommand, AFlashFarShorterThanTheStepChargesTheState) {
  // ke = 1e9: a flash of 1e-12 to 1e-9 s charges r = 1 - e^{-a t} (a = 1e9/s,
  // kr << a), then decays; once, a charge under 1e-9 --dt left r at 0 throughout.
  testing::TempDir dir;
  {
    std::ofstream file(dir / "flash.json");
    file << R"({"schema": "phos.material/1", "name": "flash", "bands_nm": [400, 500],
                "states": [{"kr": 0.01, "ke": [1e9], "Lambda": [1]}]})";
  }
  const double a = 1e9, kr = 0.01;
  for (const char* flash : {"1e-9", "1e-10", "1e-12"}) {
    auto result = RunPhos("simulate --material " + (dir / "flash.json").string() + " --charge-s " + flash +
                          " --irradiance 1 --decay-s 2 --dt 1 --json");
    ASSERT_EQ(result.exit_code, 0) << result.err;
    nlohmann::json j = nlohmann::json::parse(result.out);
    const double t_flash = std::stod(flash);
    EXPECT_EQ(j["t"].get<std::vector<double>>(), (std::vector<double>{0, 1, 2, 2 + t_flash})) << flash;
    const long double charged = testing::ClosedForm(0, a, kr, t_flash);
    EXPECT_TRUE(testing::RelativelyNear(static_cast<double>(charged), -std::expm1(-a * t_flash), 1e-9));
    for (std::size_t m = 1; m < j["t"].size(); ++m) {
      const double t = j["t"][m].get<double>();
      EXPECT_TRUE(
          testing::RelativelyNear(j["r"][m][0].get<double>(), testing::ClosedForm(charged, 0, kr, t - t_flash), 1e-12))
          << flash << " at " << t;
    }
    // The flash alone: its end is sampled, however close to 0.
    auto alone = RunPhos("simulate --material " + (dir / "flash.json").string() + " --charge-s " + flash +
                         " --irradiance 1 --dt 1 --json");
    ASSERT_EQ(alone.exit_code, 0) << alone.err;
    nlohmann::json k = nlohmann::json::parse(alone.out);
    EXPECT_EQ(k["t"].get<std::vector<double>>(), (std::vector<double>{0, t_flash}));
    EXPECT_TRUE(testing::RelativelyNear(k["r"][1][0].get<double>(), charged, 1e-12)) << flash;
  }
}

// The phos command itself: the dispatcher and its conventions.
std::filesystem::path BinFolder() { return std::filesystem::path(PHOS_BINARY).parent_path(); }

TEST(PhosCommand, VersionIsTheProjectVersion) {
  auto result = RunPhos("--version");
  EXPECT_EQ(result.exit_code, 0);
  EXPECT_EQ(result.out, std::string("phos ") + kVersion + "\n");
  EXPECT_FALSE(std::string(kVersion).empty());
}

TEST(PhosCommand, BarePhosPrintsItsUsageAndHelpListsEveryCommand) {
  auto bare = RunPhos("");
  EXPECT_EQ(bare.exit_code, 2);  // no command is a usage mistake, as for git: on stderr, as every mistake
  EXPECT_EQ(bare.out, "");
  auto help = RunPhos("--help");
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_EQ(bare.err, help.out);
  for (const char* command : {"simulate", "plot", "fit", "capture", "render", "edit", "editor", "--version"})
    EXPECT_NE(help.out.find(command), std::string::npos) << command;
  EXPECT_EQ(help.out.find("../"), std::string::npos);  // points nowhere outside the repository
  // Each command's own help says what the list says.
  auto simulate = RunPhos("simulate --help");
  EXPECT_NE(simulate.out.find("Simulate one point of a material"), std::string::npos);
  EXPECT_NE(help.out.find("Simulate one point of a material"), std::string::npos);
}

TEST(PhosCommand, AMistypedWordIsNamedWithTheNearestValidOne) {
  // Whatever CLI11 would have said first (a required option missing, words
  // not expected, a subcommand required), in every command and at every level.
  const std::string green = " --material " + Green();
  const std::vector<BadInput> cases = {
      {"simulate --materal a.json --charge-s 1 --irradiance 0",
       "phos simulate: --materal: unknown option; did you mean --material?"},
      {"simulate" + green + " --irradiance 0 --charg-s 1",
       "phos simulate: --charg-s: unknown option; did you mean --charge-s?"},
      {"simulate" + green + " --irradiance=0 --charg-s=1", "--charg-s: unknown option; did you mean --charge-s?"},
      {"simulate" + green + " --irradiance 0 --frobnicate",
       "phos simulate: --frobnicate: unknown option (see 'phos simulate --help')"},
      {"plot a.csv --log_y", "phos plot: --log_y: unknown option; did you mean --log-y?"},
      {"render scene.json --exposre 2", "phos render: --exposre: unknown option; did you mean --exposure?"},
      {"fit decay-curve --csv a.csv --component 2",
       "phos fit decay-curve: --component: unknown option; did you mean --components?"},
      {"fit decay-curv --csv a.csv", "phos fit: decay-curv: unknown subcommand; did you mean decay-curve?"},
      {"fit schedule-curv", "phos fit: schedule-curv: unknown subcommand; did you mean schedule-curve?"},
      {"fit frobnicate",
       "phos fit: frobnicate: unknown subcommand (one of decay-curve, charge-curve, schedule-curve, session, map, "
       "batch)"},
      {"fit session dir --out m.json --max-component 2",
       "phos fit session: --max-component: unknown option; did you mean --max-components?"},
      {"capture decy --out x", "phos capture: decy: unknown subcommand; did you mean decay?"},
      {"edit solv", "phos edit: solv: unknown subcommand; did you mean solve?"},
      {"editor --prot 8000", "phos editor: --prot: unknown option; did you mean --port?"},
      {"slurm rendr", "phos slurm: rendr: unknown subcommand; did you mean render?"},
      {"slurm render --taks 4 --job-dir j -- scene.json --out f",
       "phos slurm render: --taks: unknown option; did you mean --tasks?"},
      {"simulat --dt 1", "phos: simulat: unknown command; did you mean simulate?"},
      {"frobnicate", "phos: frobnicate: unknown command (one of simulate, plot, fit, capture"},
      {"--verison", "phos: --verison: unknown option; did you mean --version?"},
  };
  for (const BadInput& c : cases) {
    auto result = RunPhos(c.arguments);
    EXPECT_TRUE(testing::IsOneLineUserError(result, c.expected)) << c.arguments;
  }
}

TEST(PhosCommand, CommandsRunTheSameWithoutTheDispatcher) {
  const std::string args =
      " --material " + Green() + " --charge-s 2 --irradiance " + kBlueLight + " --decay-s 2 --json";
  auto through = RunPhos("simulate" + args);
  ASSERT_EQ(through.exit_code, 0) << through.err;
  testing::TempDir dir;
  const std::string direct = (BinFolder() / "phos-simulate").string() + args + " > " + (dir / "out").string();
  ASSERT_EQ(std::system(direct.c_str()), 0);
  EXPECT_EQ(testing::ReadText(dir / "out"), through.out);
}

// What `ldd` lists for an executable of the bin folder.
std::string SharedLibraries(const std::string& executable) {
  testing::TempDir dir;
  const std::string command = "ldd " + (BinFolder() / executable).string() + " > " + (dir / "ldd").string() + " 2>&1";
  EXPECT_EQ(std::system(command.c_str()), 0) << command;
  return testing::ReadText(dir / "ldd");
}

TEST(PhosCommand, QuickCommandsLinkNoImageRenderOrCameraLibrary) {
  // These start in milliseconds because they load none of these (app/CMakeLists.txt).
  const std::array<const char*, 4> heavy = {"libOpenImageIO", "libembree", "libaravis", "libopencv"};
  for (const char* executable : {"phos", "phos-simulate", "phos-plot", "phos-fit-curve", "phos-edit"}) {
    const std::string libraries = SharedLibraries(executable);
    for (const char* library : heavy)
      EXPECT_EQ(libraries.find(library), std::string::npos) << executable << ": " << library;
  }
  // The check sees them where they are.
  EXPECT_NE(SharedLibraries("phos-render").find("libembree"), std::string::npos);
}

TEST(PlotCommand, DrawsOneLinePerCsv) {
  testing::TempDir dir;
  for (const char* name : {"green", "orange"}) {
    auto r = RunPhos("simulate --material " + testing::Fixture(std::string("materials/") + name + ".json").string() +
                     " --charge-s 10 --irradiance 1,1,1,0,0,0,0,0 --decay-s 30 --out " +
                     (dir / (std::string(name) + ".csv")).string() + " --plot " +
                     (dir / (std::string(name) + ".svg")).string());
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

TEST(PlotCommand, LinesTakeTheColourOfTheirGlowAndTheLogAxisFollowsTheData) {
  testing::TempDir dir;
  std::string files;
  for (const char* name : {"green", "red", "blue"}) {
    const std::string csv = (dir / (std::string(name) + ".csv")).string();
    auto r = RunPhos("simulate --material " + testing::Fixture(std::string("materials/") + name + ".json").string() +
                     " --charge-s 10 --irradiance 1,1,1,0,0,0,0,0 --decay-s 300 --dt 2 --out " + csv);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    files += " " + csv;
  }
  auto r = RunPhos("plot" + files + " --log-y --json --out " + (dir / "all.svg").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  ASSERT_EQ(j["series"].size(), 3u);
  auto rgb = [](const std::string& hex) {
    std::array<long, 3> c{};
    for (int i = 0; i < 3; ++i) c[i] = std::strtol(hex.substr(1 + 2 * i, 2).c_str(), nullptr, 16);
    return c;
  };
  const auto green = rgb(j["series"][0]["color"]), red = rgb(j["series"][1]["color"]),
             blue = rgb(j["series"][2]["color"]);
  EXPECT_TRUE(green[1] > green[0] && green[1] > green[2]) << j["series"][0]["color"];
  EXPECT_TRUE(red[0] > red[1] && red[0] > red[2]) << j["series"][1]["color"];
  EXPECT_TRUE(blue[2] > blue[0] && blue[2] > blue[1]) << j["series"][2]["color"];
  EXPECT_EQ(j["series"][0]["label"], "green");
  EXPECT_EQ(j["out"], (dir / "all.svg").string());
  const std::string svg = testing::ReadText(dir / "all.svg");
  EXPECT_NE(svg.find("stroke=\"" + j["series"][0]["color"].get<std::string>() + "\""), std::string::npos);
  EXPECT_NE(svg.find("(unit of Lambda)"), std::string::npos);
  // Green decays at kr = 0.227/s for 300 s: 30 decades below its peak, all on the axis.
  double lowest = INFINITY;
  for (std::size_t p = svg.find("text-anchor=\"end\">"); p != std::string::npos;
       p = svg.find("text-anchor=\"end\">", p + 1))
    lowest = std::min(lowest, std::atof(svg.c_str() + p + 18));
  EXPECT_LE(lowest, j["series"][0]["end_radiance"].get<double>());
}

}  // namespace
}  // namespace phos
