// `phos capture decay` as a user runs it.

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "phos/util/json.h"
#include "test_util.h"

namespace phos {
namespace {

using testing::RunPhos;

TEST(CaptureDecayCommand, WritesACompleteSession) {
  testing::TempDir dir;
  auto result = RunPhos("capture decay --device sim --sim-material " +
                        testing::Fixture("materials/orange.json").string() + " --out " + (dir / "s").string() +
                        " --charge-s 600 --duration-s 30");
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_NE(result.out.find("6 frames"), std::string::npos) << result.out;
  nlohmann::json start = ReadJsonFile(dir / "s" / "session.json");
  EXPECT_EQ(start["protocol"], "decay");
  EXPECT_EQ(start["schema"], "phos.session/1");
  EXPECT_EQ(start["uid"].get<std::string>().size(), 32u);
  EXPECT_EQ(ReadJsonFile(dir / "s" / "stop.json")["how"], "complete");
}

TEST(CaptureExcitationCommand, WritesACompleteSession) {
  testing::TempDir dir;
  auto result = RunPhos("capture excitation --sim-material " + testing::Fixture("materials/orange.json").string() +
                        " --out " + (dir / "s").string() + " --light led405 --exposure-s 0.2");
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_NE(result.out.find("for 1 light(s)"), std::string::npos) << result.out;
  EXPECT_EQ(ReadJsonFile(dir / "s" / "session.json")["protocol"], "excitation");
  EXPECT_EQ(ReadJsonFile(dir / "s" / "stop.json")["how"], "complete");
  auto bad = RunPhos("capture excitation --sim-material " + testing::Fixture("materials/orange.json").string() +
                     " --out " + (dir / "t").string() + " --first-charge-s 0");
  EXPECT_TRUE(testing::IsOneLineUserError(bad, "need 0 < first charge <= max charge"));
}

TEST(CaptureDecayCommand, BadInputGivesOneLineAndExitCode2) {
  testing::TempDir dir;
  std::filesystem::create_directories(dir / "full");
  testing::WriteText(dir / "full" / "keep.txt", "precious");
  const std::string orange = " --sim-material " + testing::Fixture("materials/orange.json").string();
  struct Case {
    std::string arguments, expected;
  } cases[] = {
      {"capture decay --device aravis" + orange + " --out " + (dir / "a").string(), "--device: only 'sim'"},
      {"capture decay --out " + (dir / "b").string(), "--sim-material is required"},
      {"capture decay --sim-material " + (dir / "none.json").string() + " --out " + (dir / "c").string(), "cannot open"},
      {"capture decay" + orange + " --out " + (dir / "full").string(), "already holds files"},
      {"capture decay" + orange + " --out " + (dir / "d").string() + " --light uv", "unknown channel 'uv'"},
      {"capture decay" + orange + " --out " + (dir / "e").string() + " --interval-s 0", "interval and duration must be > 0"},
  };
  for (const Case& c : cases) {
    auto result = RunPhos(c.arguments);
    EXPECT_TRUE(testing::IsOneLineUserError(result, c.expected)) << c.arguments;
  }
  EXPECT_EQ(testing::ReadText(dir / "full" / "keep.txt"), "precious");
}

TEST(CaptureDecayCommand, ALightTheSampleCannotTakeFailsTheSessionWithTheReason) {
  // Green's ke is unknown beyond 512.5 nm; the white LED reaches there.
  testing::TempDir dir;
  auto result = RunPhos("capture decay --sim-material " + testing::Fixture("materials/green.json").string() +
                        " --out " + (dir / "s").string() + " --light white --charge-s 60 --duration-s 10");
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_EQ(testing::LineCount(result.err), 1) << result.err;
  nlohmann::json stop = ReadJsonFile(dir / "s" / "stop.json");
  EXPECT_EQ(stop["how"], "failed");
  EXPECT_NE(stop["why"].get<std::string>().find("unknown (not measured)"), std::string::npos) << stop.dump();
}

}  // namespace
}  // namespace phos
