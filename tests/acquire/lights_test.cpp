// Lights: recorded switches, unknown channels, and lights off on every way
// out (scope end, exception, SIGTERM, SIGINT).

#include "phos/acquire/lights.h"
#include "phos/acquire/session.h"
#include "phos/util/json.h"

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <gtest/gtest.h>

#include "phos/util/error.h"
#include "test_util.h"

namespace phos {
namespace {

TEST(RecordingLights, RecordsEverySwitchOnTheClock) {
  VirtualClock clock(10);
  RecordingLights lights({"led405", "white"}, clock);
  lights.Set("led405", true);
  clock.Advance(90);
  lights.Set("led405", false);
  ASSERT_EQ(lights.events().size(), 2u);
  EXPECT_EQ(lights.events()[0].t_s, 10);
  EXPECT_EQ(lights.events()[1].t_s, 100);
  EXPECT_FALSE(lights.IsOn("led405"));
  try {
    lights.Set("uv", true);
    FAIL();
  } catch (const UserError& e) {
    EXPECT_EQ(std::string(e.what()), "light: unknown channel 'uv' (this lab has: led405, white)");
  }
}

TEST(LightsOffGuard, SwitchesOffAtScopeEndAndOnException) {
  VirtualClock clock;
  RecordingLights lights({"a", "b"}, clock);
  {
    LightsOffGuard guard(lights);
    lights.Set("a", true);
    lights.Set("b", true);
  }
  EXPECT_FALSE(lights.IsOn("a"));
  EXPECT_FALSE(lights.IsOn("b"));
  try {
    LightsOffGuard guard(lights);
    lights.Set("a", true);
    throw std::runtime_error("camera disappeared");
  } catch (const std::runtime_error&) {}
  EXPECT_FALSE(lights.IsOn("a"));
}

// Lights whose state lives in a file, so a killed child process leaves evidence.
class FileLights final : public Lights {
 public:
  explicit FileLights(std::string path) : path_(std::move(path)) { Write(false); }
  std::vector<std::string> channels() const override { return {"lamp"}; }
  void Set(const std::string&, bool on) override { Write(on); }
  bool IsOn(const std::string&) const override {
    std::ifstream in(path_);
    std::string s;
    in >> s;
    return s == "on";
  }

 private:
  void Write(bool on) { std::ofstream(path_, std::ios::trunc) << (on ? "on" : "off") << std::flush; }
  std::string path_;
};

// A forked child says it is ready by renaming a whole file into place, so
// the parent never reads it half-written; the parent waits up to 5 s for it.
void SayReady(const std::string& ready, const std::string& text) {
  std::ofstream(ready + ".tmp") << text << std::flush;
  std::rename((ready + ".tmp").c_str(), ready.c_str());
}
std::string WaitForReady(const std::string& ready) {
  for (int i = 0; i < 500 && !std::filesystem::exists(ready); ++i) usleep(10000);
  return testing::ReadText(ready);
}

void ExpectSignalSwitchesOff(int signal_number, const std::string& name) {
  testing::TempDir dir;
  const std::string state = (dir / "lamp").string();
  const std::string ready = (dir / "ready").string();
  pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    const int err = ::open((dir / "stderr").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(err, STDERR_FILENO);
    SessionWriter session(dir / "session", {{"protocol", "decay"}});
    FileLights lights(state);
    LightsOffGuard guard(lights);
    lights.Set("lamp", true);
    SayReady(ready, "1");
    for (;;) pause();  // a protocol charging for 90 minutes
  }
  WaitForReady(ready);
  const std::string before = testing::ReadText(state);
  kill(child, signal_number);
  int status = 0;
  waitpid(child, &status, 0);
  ASSERT_EQ(before, "on");
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 128 + signal_number);
  EXPECT_EQ(testing::ReadText(state), "off");
  // The open session says it was aborted, and by which signal, and its
  // events say the lamp went off (the handler's own line).
  nlohmann::json stop = ReadJsonFile(dir / "session" / "stop.json");
  EXPECT_EQ(stop["how"], "aborted");
  EXPECT_NE(stop["why"].get<std::string>().find(name), std::string::npos) << stop.dump();
  const std::vector<nlohmann::json> events = testing::ReadJsonLines(dir / "session" / "events.jsonl");
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events.back()["channel"], "lamp");
  EXPECT_EQ(events.back()["on"], false);
  EXPECT_EQ(events.back()["by"], "signal handler");
  // Its records, the handler's own included, carry their checksums.
  EXPECT_EQ(RecordChecksumProblems(dir / "session"), std::vector<std::string>{});
  // The person at the terminal is told what happened and how to go on, in one line.
  const std::string said = testing::ReadText(dir / "stderr");
  EXPECT_EQ(said, "phos capture: " + std::string(signal_number == SIGINT ? "interrupted" : "terminated") + " (" + name +
                      "): the lights are off and every frame listed is kept; 'phos capture resume " +
                      (dir / "session").string() + "' goes on where it can\n");
}

// kill -9 reaches no handler: the guardian process switches the lamp off
// when capture is gone.
TEST(LightsGuardian, SwitchesOffWhenCaptureIsKilledWithSigkill) {
  testing::TempDir dir;
  const std::string state = (dir / "lamp").string();
  const std::string ready = (dir / "ready").string();
  pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    FileLights lights(state);
    LightsGuardian guardian(lights);
    lights.Set("lamp", true);
    SayReady(ready, std::to_string(guardian.pid()));
    for (;;) pause();
  }
  const std::string guardian_pid = WaitForReady(ready);
  const std::string before = testing::ReadText(state);
  // Killed before anything is asserted: a failed assertion must not leave
  // the child (and its guardian) running, holding ctest's output open.
  kill(child, SIGKILL);
  waitpid(child, nullptr, 0);
  ASSERT_EQ(before, "on");
  const int guardian = std::atoi(guardian_pid.c_str());
  // The guardian is not our child: wait for the lamp to go off (at most 5 s).
  EXPECT_GT(guardian, 0);
  for (int i = 0; i < 500 && testing::ReadText(state) != "off"; ++i) usleep(10000);
  EXPECT_EQ(testing::ReadText(state), "off");
}

// A normal end stands the guardian down: it does not touch the lights.
TEST(LightsGuardian, StandsDownAtANormalEnd) {
  testing::TempDir dir;
  const std::string state = (dir / "lamp").string();
  FileLights lights(state);
  {
    LightsGuardian guardian(lights);
    EXPECT_GT(guardian.pid(), 0);
  }
  lights.Set("lamp", true);  // after the guardian has gone: nothing switches it off
  usleep(50000);
  EXPECT_EQ(testing::ReadText(state), "on");
}

TEST(LightsOffGuard, ASignalAfterTheSessionEndedLeavesItsRecord) {
  testing::TempDir dir;
  const std::string ready = (dir / "ready").string();
  pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    SessionWriter session(dir / "session", {{"protocol", "decay"}});
    session.Stop("complete");
    FileLights lights((dir / "lamp").string());
    LightsOffGuard guard(lights);
    SayReady(ready, "1");
    for (;;) pause();
  }
  WaitForReady(ready);
  kill(child, SIGTERM);
  int status = 0;
  waitpid(child, &status, 0);
  EXPECT_EQ(ReadJsonFile(dir / "session" / "stop.json")["how"], "complete");
}

TEST(LightsOffGuard, SwitchesOffOnSigtermAndTheSessionSaysAborted) { ExpectSignalSwitchesOff(SIGTERM, "SIGTERM"); }
TEST(LightsOffGuard, SwitchesOffOnSigintAndTheSessionSaysAborted) { ExpectSignalSwitchesOff(SIGINT, "SIGINT"); }

}  // namespace
}  // namespace phos
