// `phos afterglow` (app/cmd_afterglow.cpp) as a user runs it, against the
// closed form of Eq. 8.1 written independently here (tests/model/closed_form.h)
// on random physical materials, sources and times; photometry.h, which turns
// the source's lux into band irradiance and the band radiance into cd/m², has
// its own tests (tests/model/photometry_test.cpp).

#include <cmath>
#include <random>
#include <string>
#include <vector>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "model/closed_form.h"
#include "phos/model/photometry.h"
#include "phos/util/format.h"
#include "test_util.h"

namespace phos {
namespace {

using testing::RunPhos;

struct State {
  double kr;
  std::vector<double> ke, Lambda;
};

struct Case {
  SpectralGrid bands;
  std::vector<State> states;
  std::string source;
  double lux, charge_s;
};

// A random physical material of `nc` states on a random grid, and a random charge.
Case RandomCase(std::mt19937_64& rng, int nc) {
  auto uniform = [&](double lower, double upper) { return std::uniform_real_distribution<double>(lower, upper)(rng); };
  auto log_uniform = [&](double lower, double upper) { return std::exp(uniform(std::log(lower), std::log(upper))); };
  Case c;
  const int n = std::uniform_int_distribution<int>(1, 12)(rng);
  c.bands = SpectralGrid::Uniform(uniform(300, 450), uniform(550, 780), n);
  for (int i = 0; i < nc; ++i) {
    State s{log_uniform(1e-4, 1e-1), {}, {}};
    for (int b = 0; b < n; ++b) {
      s.ke.push_back(log_uniform(1e-5, 1e-1));
      s.Lambda.push_back(log_uniform(1e-3, 10));
    }
    c.states.push_back(s);
  }
  const char* sources[] = {"d65", "a", "fluorescent", "led405"};
  c.source = sources[std::uniform_int_distribution<int>(0, 3)(rng)];
  c.lux = log_uniform(1, 1e4);
  c.charge_s = log_uniform(1, 3600);
  return c;
}

std::string WriteMaterial(const testing::TempDir& dir, const Case& c) {
  nlohmann::json j = {{"schema", "phos.material/1"},
                      {"name", "random"},
                      {"units", "physical"},
                      {"bands_nm", c.bands.edges_nm},
                      {"states", nlohmann::json::array()}};
  for (const State& s : c.states) j["states"].push_back({{"kr", s.kr}, {"ke", s.ke}, {"Lambda", s.Lambda}});
  testing::WriteText(dir / "m.json", j.dump());
  return (dir / "m.json").string();
}

// The luminance in mcd/m² t_s after the charge, from dark: per state the
// closed form of Eq. 8.1 charging for charge_s, then e^{-kr t}; Eq. 8.2.
double ClosedFormLuminance(const Case& c, double t_s) {
  const std::vector<double> E = BandsForPhotometric(*StandardSource(c.source), c.lux, c.bands, c.source);
  std::vector<double> L(E.size(), 0.0);
  for (const State& s : c.states) {
    long double a = 0;
    for (std::size_t b = 0; b < E.size(); ++b) a += s.ke[b] * E[b];
    const long double r = testing::ClosedForm(0, a, s.kr, c.charge_s) * std::exp(-static_cast<long double>(s.kr) * t_s);
    for (std::size_t b = 0; b < E.size(); ++b) L[b] += static_cast<double>(s.Lambda[b] * s.kr * r);
  }
  return 1e3 * Luminance(L, c.bands);
}

nlohmann::json Afterglow(const std::string& material, const Case& c, const std::string& more) {
  const auto result = RunPhos("afterglow " + material + " --source " + c.source + " --illuminance-lux " +
                              FormatDouble(c.lux) + " --charge-s " + FormatDouble(c.charge_s) + " --json " + more);
  EXPECT_EQ(result.exit_code, 0) << result.err;
  return nlohmann::json::parse(result.out);
}

// The issue's "done when": a single-state physical material matches the
// closed form at every time, and L60/L10 = e^{-kr 3000 s} to 1e-9.
TEST(AfterglowCommand, ASingleStateMaterialIsTheClosedFormAtEveryTime) {
  std::mt19937_64 rng(67510);
  for (int trial = 0; trial < 12; ++trial) {
    testing::TempDir dir;
    const Case c = RandomCase(rng, 1);
    const std::string minutes[] = {"10,60", "0,0.5,2,10,30,60,240"};
    const nlohmann::json j = Afterglow(WriteMaterial(dir, c), c, "--at-min " + minutes[trial % 2]);
    ASSERT_EQ(j["at_s"].size(), j["luminance_mcd_m2"].size());
    for (std::size_t m = 0; m < j["at_s"].size(); ++m) {
      const double t_s = j["at_s"][m], L = j["luminance_mcd_m2"][m];
      EXPECT_TRUE(testing::RelativelyNear(L, ClosedFormLuminance(c, t_s), 1e-12)) << trial << " t " << t_s;
    }
    if (trial % 2 == 0) {
      const double ratio = j["luminance_mcd_m2"][1].get<double>() / j["luminance_mcd_m2"][0].get<double>();
      EXPECT_TRUE(testing::RelativelyNear(ratio, std::exp(-c.states[0].kr * 3000.0), 1e-9)) << trial;
    }
    EXPECT_EQ(j["source"], c.source);
    EXPECT_NEAR(j["illuminance_lux"].get<double>(), c.lux, 1e-12 * c.lux);
    EXPECT_EQ(j["charge_s"].get<double>(), c.charge_s);
  }
}

TEST(AfterglowCommand, TwoStatesAreTheSumOfTheirClosedForms) {
  std::mt19937_64 rng(2);
  for (int trial = 0; trial < 6; ++trial) {
    testing::TempDir dir;
    const Case c = RandomCase(rng, 2);
    const nlohmann::json j = Afterglow(WriteMaterial(dir, c), c, "--at-min 0,1,10,60,600");
    for (std::size_t m = 0; m < j["at_s"].size(); ++m)
      EXPECT_TRUE(testing::RelativelyNear(j["luminance_mcd_m2"][m], ClosedFormLuminance(c, j["at_s"][m]), 1e-12))
          << trial << " t " << j["at_s"][m];
  }
}

// The time to the threshold: for one state ln(L(0) / threshold) / kr; for two,
// the instant the closed-form curve crosses it. And the marking says L10/L60
// - t(threshold) in mcd/m² (3 digits) and whole minutes.
TEST(AfterglowCommand, TheTimeToTheThresholdIsWhereTheCurveCrossesIt) {
  std::mt19937_64 rng(3);
  for (int trial = 0; trial < 8; ++trial) {
    testing::TempDir dir;
    const Case c = RandomCase(rng, 1 + trial % 2);
    const double L0 = ClosedFormLuminance(c, 0);
    const double threshold = L0 * std::exp(std::uniform_real_distribution<double>(-12, -0.1)(rng));
    const nlohmann::json j = Afterglow(WriteMaterial(dir, c), c, "--threshold-mcd " + FormatDouble(threshold));
    const double t = j["time_to_threshold_s"];
    EXPECT_EQ(j["threshold_mcd_m2"].get<double>(), threshold);
    if (c.states.size() == 1) {
      EXPECT_TRUE(testing::RelativelyNear(t, std::log(L0 / threshold) / c.states[0].kr, 1e-9)) << trial;
    }
    EXPECT_TRUE(testing::RelativelyNear(ClosedFormLuminance(c, t), threshold, 1e-9)) << trial;
    const std::string m = j["marking"];
    const auto slash = m.find('/'), dash = m.find(" - ");
    ASSERT_TRUE(slash != std::string::npos && dash != std::string::npos) << m;
    EXPECT_TRUE(testing::RelativelyNear(std::stod(m.substr(0, slash)), ClosedFormLuminance(c, 600), 5e-3)) << m;
    EXPECT_TRUE(testing::RelativelyNear(std::stod(m.substr(slash + 1, dash - slash - 1)), ClosedFormLuminance(c, 3600),
                                        5e-3, 1e-3))
        << m;
    EXPECT_EQ(std::stoll(m.substr(dash + 3)), static_cast<long long>(std::floor(t / 60))) << m;
  }
}

// A glow that outlasts the search (32,000 years) has no time: null, and "never".
TEST(AfterglowCommand, AGlowThatNeverFadesHasNoTime) {
  testing::TempDir dir;
  const Case c{SpectralGrid{{500, 600}}, {{1e-12, {1.0}, {1e9}}}, "d65", 1000, 300};
  const nlohmann::json j = Afterglow(WriteMaterial(dir, c), c, "");
  EXPECT_TRUE(j["time_to_threshold_s"].is_null());
  EXPECT_EQ(j["marking"].get<std::string>().substr(j["marking"].get<std::string>().size() - 8), " - never");
  const auto text = RunPhos("afterglow " + (dir / "m.json").string());
  EXPECT_NE(text.out.find("still above 0.3 mcd/m² after 1e+12 s\n"), std::string::npos) << text.out;
}

// The fixture sign paint under the defaults (5 min at 1000 lx of D65): the
// text a user reads and its marking.
TEST(AfterglowCommand, TheSignPaintFixtureReadsAsASign) {
  const auto result = RunPhos("afterglow " + testing::Fixture("materials/physical/sign-paint.json").string());
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_NE(result.out.find("charged 300 s by d65 at 1000 lx"), std::string::npos) << result.out;
  EXPECT_NE(result.out.find("       10 min  30.1 mcd/m²\n"), std::string::npos) << result.out;
  EXPECT_NE(result.out.find("(DIN 67510-1 style, L10/L60 - t(0.3) in mcd/m² and min): 30.1/4.53 - 420\n"),
            std::string::npos)
      << result.out;
}

// A spectrum file is a source of its own shape: a flat one over 400-700 nm at
// 1 W/m² puts 1/300 W/m² per nm into the bands.
TEST(AfterglowCommand, ASpectrumFileIsASource) {
  testing::TempDir dir;
  testing::WriteText(dir / "flat.csv", "wavelength_nm,irradiance\n400,7\n700,7\n");
  Case c{SpectralGrid{{400, 500, 700}}, {{0.01, {0.02, 0.0}, {0.0, 1.0}}}, "", 0, 100};
  const auto result = RunPhos("afterglow " + WriteMaterial(dir, c) + " --source " + (dir / "flat.csv").string() +
                              " --irradiance-w-m2 3 --charge-s 100 --at-min 0 --json");
  ASSERT_EQ(result.exit_code, 0) << result.err;
  const nlohmann::json j = nlohmann::json::parse(result.out);
  const double a = 0.02 * 1.0;  // E = 1 W/m² in 400-500 nm
  const double r = static_cast<double>(testing::ClosedForm(0, a, 0.01, 100));
  EXPECT_TRUE(testing::RelativelyNear(j["luminance_mcd_m2"][0], 1e3 * Luminance({0, 0.01 * r}, c.bands), 1e-12));
  EXPECT_EQ(j["irradiance_w_m2"].get<double>(), 3.0);
  const double lux = 683.0 * 0.01 * PhotopicEfficiency().Integrate(400, 700);  // 0.01 W/(m² nm)
  EXPECT_NEAR(j["illuminance_lux"].get<double>(), lux, 1e-12 * lux);
}

TEST(AfterglowCommand, BadInputIsOneLine) {
  testing::TempDir dir;
  const std::string paint = testing::Fixture("materials/physical/sign-paint.json").string();
  testing::WriteText(dir / "dark.csv", "wavelength_nm,irradiance\n1000,1\n1100,1\n");
  testing::WriteText(dir / "unmeasured.json",
                     R"({"schema": "phos.material/1", "name": "u", "units": "physical", "bands_nm": [400, 500, 600],
                         "states": [{"kr": 0.01, "ke": [0.1, null], "Lambda": [0, 1]}]})");
  const std::pair<std::string, std::string> cases[] = {
      {testing::Fixture("materials/green.json").string(),
       "green.json: units: a relative material has no luminance in cd/m²: phos afterglow needs \"units\": "
       "\"physical\""},
      {paint + " --source xenon", "--source: xenon: phos ships no sourced xenon-lamp table"},
      {paint + " --source d50", "--source: expected d65, a, fluorescent, led405 or a spectrum file"},
      {paint + " --source " + (dir / "dark.csv").string(), "has no light V(lambda) sees"},
      {paint + " --illuminance-lux 0", "--illuminance-lux: expected a number > 0, got 0"},
      {paint + " --illuminance-lux inf", "--illuminance-lux: expected a finite number, got inf"},
      {paint + " --irradiance-w-m2 -1", "--irradiance-w-m2: expected a number > 0, got -1"},
      {paint + " --illuminance-lux 10 --irradiance-w-m2 1", "give --illuminance-lux or --irradiance-w-m2, not both"},
      {paint + " --threshold-mcd 0", "--threshold-mcd: expected a number > 0, got 0"},
      {paint + " --threshold-mcd nan", "--threshold-mcd: expected a finite number, got nan"},
      {paint + " --charge-s -5", "--charge-s: expected a number > 0, got -5"},
      {paint + " --at-min 10,-1", "--at-min: expected a number >= 0, got -1"},
      {paint + " --illuminance-lux 1e300", "--illuminance-lux: gives"},
      {(dir / "missing.json").string(), "missing.json"},
      {(dir / "unmeasured.json").string(),
       "unmeasured.json: states[0].ke[1]: unknown (not measured) for band 500-600 nm: material 'u' cannot be charged "
       "by --source d65 ("},
  };
  for (const auto& [arguments, expected] : cases)
    EXPECT_TRUE(testing::IsOneLineUserError(RunPhos("afterglow " + arguments), expected)) << arguments;
}

}  // namespace
}  // namespace phos
