// The editing session behind the page, without HTTP: placing constraints by
// pixel, re-solving on every edit, colours as band spectra, presets, edit
// propagation, and refusing bad edits without changing anything.

#include <gtest/gtest.h>

#include <cmath>

#include "phos/editor/session.h"
#include "phos/util/error.h"
#include "test_util.h"

namespace phos::editor {
namespace {

using phos::testing::ErrorOfType;
using phos::testing::Fixture;
using phos::testing::TempDir;

struct Cornell {
  TempDir root;
  EditSession session{Fixture("scenes/cornell-phosphor.json"), Fixture("materials"), root.path()};
};

TEST(EditSession, ConstraintsSolveAndTheCurvesPassThroughTheTargets) {
  Cornell c;
  c.session.AddConstraint(128, 64, 35);  // the back wall, 5 s after the LED goes off
  c.session.AddConstraint(128, 64, 60);
  nlohmann::json state = c.session.State();
  ASSERT_EQ(state["constraints"].size(), 2u);
  EXPECT_EQ(state["constraints"][0]["object"], "back wall");
  c.session.UpdateConstraint(0, {{"rgb", {0.004, 0.02, 0.012}}});
  c.session.UpdateConstraint(1, {{"rgb", {0.0016, 0.008, 0.0048}}});
  state = c.session.State();
  for (const auto& constraint : state["constraints"]) EXPECT_LT(constraint["relative_error"].get<double>(), 1e-4);
  // One exponential through both: kr = ln(1 / 0.4) / 25 s.
  const nlohmann::json material = c.session.MaterialJson("back wall");
  EXPECT_NEAR(material["states"][0]["kr"].get<double>(), std::log(2.5) / 25, 1e-3);
  EXPECT_TRUE(state["objects"][2]["edited"].get<bool>());
  EXPECT_FALSE(c.session.FramePng(40, 1.0).empty());
}

TEST(EditSession, BadEditsChangeNothing) {
  Cornell c;
  c.session.AddConstraint(128, 64, 35);
  const std::string before = c.session.State().dump();
  EXPECT_NE(ErrorOfType<UserError>([&] { c.session.AddConstraint(40, 230, 35); }).find("'floor', which is not phosphorescent"),
            std::string::npos);
  EXPECT_NE(ErrorOfType<UserError>([&] { c.session.AddConstraint(999, 0, 35); }).find("outside"), std::string::npos);
  EXPECT_NE(ErrorOfType<UserError>([&] { c.session.UpdateConstraint(0, {{"rgb", {1, 2}}}); }).find("rgb"), std::string::npos);
  EXPECT_NE(ErrorOfType<UserError>([&] { c.session.UpdateConstraint(0, {{"rgb", {1, 1, 1}}, {"kind", "maybe"}}); })
                .find("kind"),
            std::string::npos);
  EXPECT_NE(ErrorOfType<UserError>([&] { c.session.UpdateConstraint(7, {}); }).find("no constraint 7"), std::string::npos);
  EXPECT_NE(ErrorOfType<UserError>([&] { c.session.SetPreset("back wall", "plutonium"); }).find("no preset"), std::string::npos);
  EXPECT_NE(ErrorOfType<UserError>([&] { c.session.ExportMaterial("back wall", "../x.json"); }).find("outside the project"),
            std::string::npos);
  EXPECT_NE(ErrorOfType<UserError>([&] { c.session.ExportMaterial("back wall", "/tmp/x.json"); }).find("outside the project"),
            std::string::npos);
  EXPECT_EQ(c.session.State().dump(), before);
  EXPECT_TRUE(std::filesystem::exists(c.session.ExportMaterial("back wall", "out/wall.json")));
}

TEST(EditSession, ColoursBecomeSpectraOfExactlyThatColour) {
  Cornell c;
  c.session.AddConstraint(128, 64, 35);
  for (const std::vector<double>& rgb : {std::vector<double>{0.004, 0.02, 0.012}, std::vector<double>{0.01, 0.002, 0.001},
                                        std::vector<double>{0.0, 0.03, 0.0}}) {
    c.session.UpdateConstraint(0, {{"rgb", rgb}});
    const nlohmann::json state = c.session.State();
    const nlohmann::json& constraint = state["constraints"][0];
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(constraint["predicted"][k].get<double>(), rgb[k], 1e-6 + 1e-3 * rgb[k]);
  }
}

TEST(EditSession, EditsPropagateToSimilarObjectsWithTheFalloff) {
  Cornell c;
  c.session.AddConstraint(128, 64, 35);
  c.session.UpdateConstraint(0, {{"rgb", {0.004, 0.02, 0.012}}});
  const std::string right_before = c.session.MaterialJson("right wall").dump();
  c.session.SetPropagation(0);
  EXPECT_EQ(c.session.MaterialJson("right wall").dump(), right_before);
  c.session.SetPropagation(2.0);
  const nlohmann::json propagated = c.session.MaterialJson("right wall");
  EXPECT_NE(propagated.dump(), right_before);
  EXPECT_NE(propagated["name"].get<std::string>().find("propagated"), std::string::npos);
}

}  // namespace
}  // namespace phos::editor
