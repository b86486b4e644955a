#include "phos/model/material.h"

#include <cmath>
#include <functional>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <nlohmann/json.hpp>

#include "phos/model/schedule.h"
#include "phos/util/json.h"
#include "phos/util/error.h"
#include "test_util.h"

namespace phos {
namespace {

std::string ErrorOf(const std::function<void()>& f) { return testing::ErrorOfType<UserError>(f); }

const char* kPresets[] = {"blue",  "green",  "orange", "pink",   "purple",  "red",
                          "white", "yellow", "bottle", "gloves", "stickers"};

TEST(Material, AllElevenTable8_1PresetsLoad) {
  for (const char* name : kPresets) {
    Material m = LoadMaterial(testing::Fixture(std::string("materials/") + name + ".json"));
    EXPECT_EQ(m.name, name);
    EXPECT_EQ(m.band_count(), 8);
    EXPECT_EQ(m.state_count(), 1);
    EXPECT_EQ(m.bands, SpectralGrid::Paper());
  }
  Material green = LoadMaterial(testing::Fixture("materials/green.json"));
  EXPECT_DOUBLE_EQ(green.states[0].kr, 0.227);
  EXPECT_DOUBLE_EQ(*green.states[0].ke[0], 0.1);
  EXPECT_FALSE(green.states[0].ke_known(3));  // Table 8.1: bands 4-8 not measured
  EXPECT_TRUE(green.ChargeableIn(2));
  EXPECT_FALSE(green.ChargeableIn(3));
  Material bottle = LoadMaterial(testing::Fixture("materials/bottle.json"));
  for (int b = 0; b < 8; ++b) EXPECT_FALSE(bottle.ChargeableIn(b));
}

TEST(Material, UnknownKeRefusesToChargeButDecays) {
  Material bottle = LoadMaterial(testing::Fixture("materials/bottle.json"));
  std::vector<double> dark(8, 0.0), lit(8, 0.0);
  EXPECT_EQ(ExcitationRates(bottle, dark, "bottle.json")[0], 0.0);  // darkness needs no ke
  lit[1] = 1.0;
  EXPECT_EQ(ErrorOf([&] { ExcitationRates(bottle, lit, "bottle.json"); }),
            "bottle.json: states[0].ke[1]: unknown (not measured) for band 437.5-475 nm: material 'bottle' "
            "cannot be charged by irradiance 1 there; give 0 irradiance in that band");
  Material green = LoadMaterial(testing::Fixture("materials/green.json"));
  std::vector<double> blue = {1, 1, 1, 0, 0, 0, 0, 0};
  EXPECT_NEAR(ExcitationRates(green, blue, "g")[0], 0.1 + 0.035 + 0.006, 1e-15);
}

TEST(Material, SaveAndLoadRoundTrip) {
  testing::TempDir dir;
  Material m;
  m.name = "two-state";
  m.bands = SpectralGrid{{350, 400, 500, 700}};
  m.albedo = std::vector<double>{0.2, 0.5, 0.9};
  m.states.push_back({0.5, {0.1, std::nullopt, 0.0}, {1, 2, 3}, {}, {}});
  m.states.push_back({0.01, {0.2, 0.3, 0.4}, {0, 0.5, 0}, {}, {}});
  SaveMaterial(m, dir / "m.json");
  Material back = LoadMaterial(dir / "m.json");
  EXPECT_EQ(back.name, m.name);
  EXPECT_EQ(back.bands, m.bands);
  EXPECT_EQ(*back.albedo, *m.albedo);
  ASSERT_EQ(back.state_count(), 2);
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(back.states[i].kr, m.states[i].kr);
    EXPECT_EQ(back.states[i].ke, m.states[i].ke);
    EXPECT_EQ(back.states[i].Lambda, m.states[i].Lambda);
  }
}

// "units": absent is relative and is written back absent (every existing
// file loads and saves as before); "physical" round-trips.
TEST(Material, UnitsAreRelativeUnlessThePhysicalOnesAreNamed) {
  nlohmann::json j = ReadJsonFile(testing::Fixture("materials/green.json"));
  EXPECT_EQ(MaterialFromJson(j, "m.json").units, Units::kRelative);
  EXPECT_EQ(MaterialToJson(MaterialFromJson(j, "m.json")), j);
  j["units"] = "relative";
  EXPECT_EQ(MaterialFromJson(j, "m.json").units, Units::kRelative);
  j["units"] = "physical";
  const Material physical = MaterialFromJson(j, "m.json");
  EXPECT_EQ(physical.units, Units::kPhysical);
  EXPECT_EQ(MaterialToJson(physical), j);
  j["units"] = "SI";
  EXPECT_EQ(ErrorOf([&] { MaterialFromJson(j, "m.json"); }),
            "m.json: units: unknown units \"SI\" (expected \"relative\" or \"physical\")");
  j["units"] = 1;
  EXPECT_EQ(ErrorOf([&] { MaterialFromJson(j, "m.json"); }), "m.json: units: expected a string, got 1");
}

// Each broken file gives one message naming the file and the field.
struct BrokenCase {
  const char* what;
  std::function<void(nlohmann::json&)> edit;
  const char* expected;  // the message after "<file>: "
};

TEST(Material, ValidationNamesFileAndField) {
  nlohmann::json good = ReadJsonFile(testing::Fixture("materials/green.json"));
  const BrokenCase cases[] = {
      {"unknown schema", [](auto& j) { j["schema"] = "phos.material/2"; },
       "schema: unknown schema \"phos.material/2\" (expected \"phos.material/1\")"},
      {"missing kr", [](auto& j) { j["states"][0].erase("kr"); }, "states[0].kr: missing (required)"},
      {"negative kr", [](auto& j) { j["states"][0]["kr"] = -1; }, "states[0].kr: expected a number >= 0, got -1"},
      {"negative ke", [](auto& j) { j["states"][0]["ke"][1] = -0.5; },
       "states[0].ke[1]: expected a number >= 0, got -0.5"},
      {"band count", [](auto& j) { j["states"][0]["Lambda"].erase(0); },
       "states[0].Lambda: expected 8 values (one per band), got 7"},
      {"ke count", [](auto& j) { j["states"][0]["ke"].push_back(0.1); },
       "states[0].ke: expected 8 values (one per band), got 9"},
      {"not a number", [](auto& j) { j["states"][0]["Lambda"][2] = "NaN"; },
       "states[0].Lambda[2]: expected a number, got \"NaN\""},
      {"edges", [](auto& j) { j["bands_nm"][3] = 400; },
       "bands_nm[3]: band edges must increase strictly (400 follows 475)"},
      {"no states", [](auto& j) { j["states"] = nlohmann::json::array(); },
       "states: expected 1 to 16 excited states, got 0"},
      {"seventeen states",
       [](auto& j) {
         for (int i = 0; i < 16; ++i) j["states"].push_back(j["states"][0]);
       },
       "states: expected 1 to 16 excited states, got 17"},
      {"typo", [](auto& j) { j["states"][0]["Lamda"] = 1; },
       "states[0].Lamda: unknown field (expected one of: kr, ke, Lambda, kr_stderr, ke_stderr)"},
      {"albedo range", [](auto& j) { j["albedo"] = std::vector<double>(8, 1.5); },
       "albedo[0]: expected a reflectance in [0, 1], got 1.5"},
      {"missing name", [](auto& j) { j.erase("name"); }, "name: missing (required)"},
  };
  for (const BrokenCase& c : cases) {
    nlohmann::json j = good;
    c.edit(j);
    EXPECT_EQ(ErrorOf([&] { MaterialFromJson(j, "m.json"); }), std::string("m.json: ") + c.expected) << c.what;
  }
}

TEST(Material, NonFiniteValuesBuiltInCodeAreRejected) {
  Material m = LoadMaterial(testing::Fixture("materials/green.json"));
  m.states[0].ke[0] = std::nan("");  // would otherwise be written as null = "unknown"
  EXPECT_EQ(ErrorOf([&] { ValidateMaterial(m, "code"); }), "code: states[0].ke[0]: expected a finite number, got nan");
  m = LoadMaterial(testing::Fixture("materials/green.json"));
  m.states[0].kr = INFINITY;
  EXPECT_EQ(ErrorOf([&] { ValidateMaterial(m, "code"); }), "code: states[0].kr: expected a finite number, got inf");
}

TEST(Material, NumbersTooLargeForADoubleAreRejected) {
  testing::TempDir dir;
  std::string text = testing::ReadText(testing::Fixture("materials/green.json"));
  text.replace(text.find("0.227"), 5, "1e999");
  testing::WriteText(dir / "huge.json", text);
  std::string message = ErrorOf([&] { LoadMaterial(dir / "huge.json"); });
  EXPECT_EQ(message.rfind((dir / "huge.json").string(), 0), 0u) << message;
}

// kr = 1e308 was accepted and the output was not finite. Rates and
// Lambda have finite ranges (material.h), and the message names the limit.
TEST(Material, RatesOutsideTheFiniteRangeAreRefused) {
  const nlohmann::json green = nlohmann::json::parse(testing::ReadText(testing::Fixture("materials/green.json")));
  struct Case {
    std::function<void(nlohmann::json&)> edit;
    std::string expected;
  } cases[] = {
      {[](nlohmann::json& j) { j["states"][0]["kr"] = 1e308; },
       "m.json: states[0].kr: expected at most 1e+09 (the limit phos accepts), got 1e+308"},
      {[](nlohmann::json& j) { j["states"][0]["ke"][0] = 1e10; },
       "m.json: states[0].ke[0]: expected at most 1e+09 (the limit phos accepts), got 1e+10"},
      {[](nlohmann::json& j) { j["states"][0]["Lambda"][3] = 1e300; },
       "m.json: states[0].Lambda[3]: expected at most 1e+09 (the limit phos accepts), got 1e+300"},
      {[](nlohmann::json& j) { j["bands_nm"][8] = 1e300; },
       "m.json: bands_nm[8]: expected a wavelength of at most 1e+05 nm, got 1e+300"},
      {[](nlohmann::json& j) {
         j["bands_nm"] = nlohmann::json::array();
         for (int i = 0; i <= kMaxBands + 1; ++i) j["bands_nm"].push_back(400 + i);
       },
       "m.json: bands_nm: more than the limit of 256 bands"},
  };
  for (const Case& c : cases) {
    nlohmann::json j = green;
    c.edit(j);
    EXPECT_EQ(ErrorOf([&] { MaterialFromJson(j, "m.json"); }), c.expected);
  }
  // The limit itself is accepted.
  nlohmann::json j = green;
  j["states"][0]["kr"] = kMaxRate;
  EXPECT_EQ(MaterialFromJson(j, "m.json").states[0].kr, kMaxRate);
}

// A material path that is a FIFO hung; /dev/zero exhausted memory.
TEST(Material, OnlyRegularFilesAreRead) {
  testing::TempDir dir;
  ASSERT_EQ(::mkfifo((dir / "fifo.json").c_str(), 0600), 0);
  EXPECT_NE(ErrorOf([&] { LoadMaterial(dir / "fifo.json"); }).find("fifo.json: not a regular file"), std::string::npos);
  EXPECT_NE(ErrorOf([&] { LoadMaterial("/dev/zero"); }).find("/dev/zero: not a regular file"), std::string::npos);
}

}  // namespace
}  // namespace phos
