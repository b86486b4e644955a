// Every input that ever crashed, hung or gave an internal error (found by
// mutating the fixtures by hand and by the fuzz harnesses, docs/fuzzing.md) is kept in
// fuzz/regressions/<target>/ and run here through the harness's own function
// (fuzz/targets.h), under the ASan + UBSan build of CI: each must be refused
// in one line. The loaders' unit tests check the messages of most of them;
// the lab config and the command-line option have theirs here.

#include <gtest/gtest.h>

#include <filesystem>
#include <stdexcept>
#include <string>

#include "fuzz/targets.h"
#include "phos/acquire/lab.h"
#include "phos/util/error.h"
#include "test_util.h"

namespace phos {
namespace {

const std::filesystem::path kRegressions = std::filesystem::path(PHOS_FUZZ_ROOT) / "fuzz/regressions";

TEST(FuzzRegressions, EveryInputThatEverCrashedIsRefusedInOneLine) {
  int inputs = 0;
  for (const fuzz::Target& target : fuzz::kTargets) {
    const std::filesystem::path dir = kRegressions / target.name;
    if (!std::filesystem::is_directory(dir)) continue;
    for (const auto& entry : std::filesystem::directory_iterator(dir)) {
      const std::string data = testing::ReadText(entry.path());
      try {
        EXPECT_FALSE(target.run(data)) << entry.path() << " was accepted";
      } catch (const std::exception& e) {
        ADD_FAILURE() << entry.path() << ": " << e.what();
      }
      ++inputs;
    }
  }
  EXPECT_GE(inputs, 15);  // the hand-mutated cases, and what the harnesses found
}

// A lab config with a camera region of 1e9 crashed (ASan SEGV in
// the camera); 1e10 does not even fit the int it was cast to.
TEST(FuzzRegressions, ALabCameraRegionIsWholePixelsOfARealSensor) {
  testing::TempDir dir;
  auto error_of = [&](const std::string& region) {
    testing::WriteText(dir / "lab.json",
                       R"({"schema": "phos.lab/1", "camera": {"aravis": "Fake_1", "region": )" + region +
                           R"(}, "lights": {"backend": "none", "channels": {"led405": {"line": 1}}}})");
    return testing::ErrorOfType<UserError>([&] { LoadLabConfig(dir / "lab.json"); });
  };
  EXPECT_EQ(error_of("[0, 0, 128, 96]"), "(no error)");
  EXPECT_EQ(error_of("[0, 0, 1e9, 1e9]"),
            (dir / "lab.json").string() + ": camera.region[2]: expected a whole number from 1 to 65536, got 1e+09");
  EXPECT_EQ(error_of("[1e10, 0, 16, 16]"),
            (dir / "lab.json").string() + ": camera.region[0]: expected a whole number from 0 to 65536, got 1e+10");
  EXPECT_EQ(error_of("[65530, 0, 16, 16]"),
            (dir / "lab.json").string() +
                ": camera.region: the region reaches past 65536 pixels, the largest sensor "
                "phos accepts");
}

// The fuzz harness reads lab configs from memory (LabConfigFromJson); a file
// read by LoadLabConfig gives the same config and the same messages, and an
// irradiance_csv is found beside the path given.
TEST(FuzzRegressions, ALabConfigFromMemoryIsTheSameAsFromItsFile) {
  testing::TempDir dir;
  testing::WriteText(dir / "led.csv", "wavelength_nm,irradiance\n400,1\n500,2\n600,1\n");
  const std::string good = R"({"schema": "phos.lab/1", "camera": {"aravis": "Fake_1"}, "lights": {"backend": "none",
      "channels": {"led405": {"line": 1, "irradiance_csv": "led.csv"}}}})";
  testing::WriteText(dir / "lab.json", good);
  EXPECT_EQ(LabConfigFromJson(good, dir / "lab.json").ToJson(), LoadLabConfig(dir / "lab.json").ToJson());
  EXPECT_EQ(LabConfigFromJson(good, dir / "lab.json").source, dir / "lab.json");
  for (const std::string& bad :
       {std::string("{"), std::string(R"({"schema": "phos.lab/2"})"),
        std::string(R"({"schema": "phos.lab/1", "camera": {"aravis": "Fake_1", "region": [0, 0, 1e9, 1]}})")}) {
    testing::WriteText(dir / "lab.json", bad);
    const std::string from_file = testing::ErrorOfType<UserError>([&] { LoadLabConfig(dir / "lab.json"); });
    EXPECT_NE(from_file, "(no error)");
    EXPECT_EQ(testing::ErrorOfType<UserError>([&] { LabConfigFromJson(bad, dir / "lab.json"); }), from_file);
  }
}

// NaN and infinity in a numeric option (app/cli_finite.h).
TEST(FuzzRegressions, NonFiniteOptionValuesAreRefused) {
  const std::string curve = testing::Fixture("curves/charge.csv").string();
  EXPECT_TRUE(testing::IsOneLineUserError(testing::RunPhos("fit decay-curve " + curve + " --from nan"),
                                          "--from: expected a finite number, got nan"));
  EXPECT_TRUE(testing::IsOneLineUserError(testing::RunPhos("fit charge-curve " + curve + " --to 1e999"),
                                          "--to: expected a finite number, got 1e999"));
  const std::string green = testing::Fixture("materials/green.json").string();
  EXPECT_TRUE(testing::IsOneLineUserError(
      testing::RunPhos("simulate --material " + green + " --charge-s nan --irradiance 1,1,1,0,0,0,0,0"),
      "--charge-s: expected a finite number, got nan"));
  EXPECT_TRUE(testing::IsOneLineUserError(testing::RunPhos("simulate --material " + green + " --r0 0 --decay-s inf"),
                                          "--decay-s: expected a finite number, got inf"));
  EXPECT_TRUE(testing::IsOneLineUserError(
      testing::RunPhos("simulate --material " + green + " --charge-s 1 --irradiance 1e300,1,1,0,0,0,0,0"),
      "--irradiance: expected values in [0, 1e+09], got 1e+300"));
}

}  // namespace
}  // namespace phos
