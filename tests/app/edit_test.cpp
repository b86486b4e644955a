// `phos edit solve` as DESIGN.md specifies it: the JSON keys, the material it
// returns, the baseline beside it, and one-line errors.

#include <gtest/gtest.h>

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

TEST(EditCommand, BadInputIsOneLineAndExitTwo) {
  TempDir dir;
  EXPECT_TRUE(IsOneLineUserError(RunPhos("edit solve /nonexistent.json"), "nonexistent.json"));
  EXPECT_TRUE(IsOneLineUserError(RunPhos("edit solve " + kSign + " --states 7"), "--states"));
  WriteText(dir / "c.json", R"({"schema": "phos.constraints/1", "bands_nm": [380, 490, 580, 720], "dt_s": 0.5,
    "irradiance": [[1, 1, 1]], "albedo": [0.5, 0.5, 0.5], "constraints": []})");
  EXPECT_TRUE(IsOneLineUserError(RunPhos("edit solve " + (dir / "c.json").string()), "constraints"));
  EXPECT_TRUE(IsOneLineUserError(RunPhos("edit"), "edit"));
}

}  // namespace
}  // namespace phos::testing
