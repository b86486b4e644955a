// `phos edit solve` as docs/formats.md specifies it: the JSON keys, the material it
// returns, the baseline beside it, and one-line errors; and `phos editor` on a
// port in use.

#include <gtest/gtest.h>

#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include "phos/editor/solve.h"
#include "phos/model/material.h"
#include "test_util.h"

namespace phos::testing {
namespace {

const std::string kSign = Fixture("constraints/glow-sign.json").string();

TEST(EditCommand, JsonFollowsTheContract) {
  TempDir dir;
  const CommandResult r = RunPhos("edit solve " + kSign + " --json --out " + (dir / "m.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  for (const char* key : {"material", "cost", "residuals", "seconds", "baseline"}) EXPECT_TRUE(j.contains(key)) << key;
  EXPECT_EQ(j["residuals"].size(), 4u);
  EXPECT_LE(j["cost"].get<double>(), j["baseline"]["cost"].get<double>());
  // The material is a valid phos.material/1 whose cost is the one reported.
  const Material m = MaterialFromJson(j["material"], "output");
  EXPECT_NEAR(editor::Cost(editor::LoadProblem(kSign), m), j["cost"].get<double>(), 1e-9);
  EXPECT_EQ(LoadMaterial(dir / "m.json").states.size(), 1u);
}

TEST(EditCommand, KeIsUnknownWhereNoLightReaches) {
  // Lit in the blue band only: green and red ke stay unknown, in the file and on screen.
  TempDir dir;
  std::string irradiance;
  for (int f = 0; f < 60; ++f) irradiance += std::string(f ? ", " : "") + (f < 20 ? "[1, 0, 0]" : "[0, 0, 0]");
  WriteText(dir / "c.json", R"({"schema": "phos.constraints/1", "bands_nm": [380, 490, 580, 720], "dt_s": 0.5,
    "irradiance": [)" + irradiance +
                                R"(], "albedo": [0.5, 0.5, 0.5], "states": 1,
    "constraints": [{"t_s": 11, "radiance": [0.02, 0.06, 0.01]}, {"t_s": 25, "radiance": [0.01, 0.03, 0.005]}]})");
  const CommandResult text =
      RunPhos("edit solve " + (dir / "c.json").string() + " --no-baseline --out " + (dir / "m.json").string());
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_NE(text.out.find(", unknown, unknown]"), std::string::npos) << text.out;
  const Material m = LoadMaterial(dir / "m.json");
  EXPECT_TRUE(m.states[0].ke[0].has_value());
  EXPECT_FALSE(m.states[0].ke[1].has_value());
  EXPECT_FALSE(m.states[0].ke[2].has_value());
}

TEST(EditCommand, PhasesSolveAsTheirRows) {
  // glow-sign.json's 200 rows written as its two phases: the same material.
  TempDir dir;
  const std::string sign_phases = Fixture("constraints/glow-sign-phases.json").string();
  nlohmann::json phases = nlohmann::json::parse(ReadText(sign_phases));
  const CommandResult rows = RunPhos("edit solve " + kSign + " --json --no-baseline");
  const CommandResult two = RunPhos("edit solve " + sign_phases + " --json --no-baseline");
  ASSERT_EQ(rows.exit_code, 0) << rows.err;
  ASSERT_EQ(two.exit_code, 0) << two.err;
  EXPECT_EQ(nlohmann::json::parse(rows.out)["material"]["states"], nlohmann::json::parse(two.out)["material"]["states"]);
  // Off the frame grid in all: one line, exit 2.
  phases["irradiance"][1]["duration_s"] = 90.2;
  WriteText(dir / "off.json", phases.dump());
  EXPECT_TRUE(IsOneLineUserError(RunPhos("edit solve " + (dir / "off.json").string()),
                                 "irradiance: the phases last 100.2 s, not a whole number of frames"));
}

TEST(EditCommand, BadInputIsOneLineAndExitTwo) {
  TempDir dir;
  EXPECT_TRUE(IsOneLineUserError(RunPhos("edit solve /nonexistent.json"), "nonexistent.json"));
  EXPECT_TRUE(IsOneLineUserError(RunPhos("edit solve " + kSign + " --states 7"), "--states"));
  WriteText(dir / "c.json", R"({"schema": "phos.constraints/1", "bands_nm": [380, 490, 580, 720], "dt_s": 0.5,
    "irradiance": [[1, 1, 1]], "albedo": [0.5, 0.5, 0.5], "constraints": []})");
  EXPECT_TRUE(IsOneLineUserError(RunPhos("edit solve " + (dir / "c.json").string()), "constraints"));
  EXPECT_TRUE(IsOneLineUserError(RunPhos("edit"), "edit"));
  // What the editor page refuses, the file is refused for too: a zero target
  // and a point no light reaches (each could only be met with Lambda = 0).
  WriteText(dir / "zero.json", R"({"schema": "phos.constraints/1", "bands_nm": [380, 490, 580, 720], "dt_s": 0.5,
    "irradiance": [[1, 1, 1], [0, 0, 0]], "albedo": [0.5, 0.5, 0.5],
    "constraints": [{"t_s": 0.5, "radiance": [0, 0, 0]}, {"t_s": 0.5, "at_most": [0, 0, 0]}]})");
  EXPECT_TRUE(IsOneLineUserError(RunPhos("edit solve " + (dir / "zero.json").string()),
                                 "constraints[0].radiance: a target of zero in every band would give Lambda = 0"));
  WriteText(dir / "dark.json", R"({"schema": "phos.constraints/1", "bands_nm": [380, 490, 580, 720], "dt_s": 0.5,
    "irradiance": [[0, 0, 0], [0, 0, 0]], "albedo": [0.5, 0.5, 0.5],
    "constraints": [{"t_s": 0.5, "radiance": [0.1, 0.1, 0.1]}]})");
  EXPECT_TRUE(IsOneLineUserError(RunPhos("edit solve " + (dir / "dark.json").string()),
                                 "irradiance: zero at every frame: nothing charges the point"));
}

TEST(EditorCommand, APortInUseIsRefusedWithExitTwo) {
  // Something already listens on the port (as a first phos editor would).
  // Without SO_REUSEPORT the second cannot bind it too and share its requests.
  const int listener = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::bind(listener, reinterpret_cast<sockaddr*>(&address), sizeof address), 0);
  ASSERT_EQ(::listen(listener, 4), 0);
  socklen_t length = sizeof address;
  ::getsockname(listener, reinterpret_cast<sockaddr*>(&address), &length);
  const int port = ntohs(address.sin_port);
  // `timeout`: an editor that started anyway would serve forever.
  TempDir dir;
  const std::string command = "timeout 60 " + std::string(PHOS_BINARY) + " editor --port " + std::to_string(port) +
                              " --scene " + Fixture("scenes/cornell-phosphor.json").string() + " >" +
                              (dir / "out").string() + " 2>" + (dir / "err").string() + " </dev/null";
  const int status = std::system(command.c_str());
  CommandResult r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.err = ReadText(dir / "err");
  EXPECT_TRUE(IsOneLineUserError(r, "127.0.0.1:" + std::to_string(port) + " is in use"));
  ::close(listener);
}

}  // namespace
}  // namespace phos::testing
