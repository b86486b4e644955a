// The editor's solver (Sec. 8.6): it recovers a material from constraints
// that the material itself produced (cost ~ 0, for nc = 1 and 2, RGB and 8
// bands), meets bounds, never does worse than the paper's grid search, and
// says which constraints contradict.

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include <nlohmann/json.hpp>

#include "phos/editor/solve.h"
#include "phos/util/error.h"
#include "phos/util/json.h"
#include "test_util.h"

namespace phos::editor {
namespace {

Material Truth(const SpectralGrid& bands, std::vector<double> kr, std::vector<std::vector<double>> ke,
               std::vector<std::vector<double>> Lambda) {
  Material m;
  m.name = "truth";
  m.bands = bands;
  for (std::size_t i = 0; i < kr.size(); ++i) {
    ExcitedState s;
    s.kr = kr[i];
    for (double k : ke[i]) s.ke.emplace_back(k);
    s.Lambda = Lambda[i];
    m.states.push_back(s);
  }
  return m;
}

// 200 frames of 0.5 s: lit for the first 10 s, then dark; targets from `truth` at `times`.
Problem FromTruth(const Material& truth, const std::vector<double>& E_lit, const std::vector<double>& times) {
  Problem p;
  p.source = "test";
  p.bands = truth.bands;
  p.dt_s = 0.5;
  const int nb = truth.band_count();
  Point point;
  for (int f = 0; f < 200; ++f) point.irradiance.push_back(f < 20 ? E_lit : std::vector<double>(nb, 0.0));
  point.albedo.assign(nb, 0.5);
  p.points.push_back(point);
  p.states = truth.state_count();
  for (double t : times)
    p.constraints.push_back(
        {Constraint::Kind::kTarget, 0, t, t, std::vector<double>(nb, 0.0), 1, "t" + std::to_string(t)});
  const auto L = PredictRadiance(p, truth, times);
  for (std::size_t c = 0; c < times.size(); ++c) p.constraints[c].radiance = L[c];
  return p;
}

double Scale(const Problem& p) {
  double s = 0;
  for (const Constraint& c : p.constraints)
    for (double v : c.radiance) s += v * v;
  return s;
}

const SpectralGrid kRgb{{380, 490, 580, 720}};

TEST(EditorSolve, RecoversAnRgbMaterialFromItsOwnLook) {
  const Material truth = Truth(kRgb, {0.3}, {{0.2, 0.1, 0.05}}, {{0.5, 2.0, 0.3}});
  const Problem p = FromTruth(truth, {1.0, 0.6, 0.2}, {5, 11, 30, 90});
  EXPECT_NEAR(Cost(p, truth), 0.0, 1e-20);
  const Solution s = Solve(p);
  EXPECT_LT(s.cost, 1e-8 * Scale(p));
  for (const ConstraintResult& c : s.constraints) EXPECT_LT(c.residual, 1e-4);
  EXPECT_TRUE(s.feedback.empty()) << s.feedback.front();
  EXPECT_NEAR(s.material.states[0].kr, 0.3, 0.003);  // the decay is pinned by three dark targets
  const std::optional<Solution> grid = SolveGridBaseline(p);
  ASSERT_TRUE(grid.has_value());
  EXPECT_LE(s.cost, grid->cost);
  EXPECT_GT(grid->cost, 10 * s.cost);  // the grid cannot land on kr = 0.3
  // The cost reported is the cost of the material returned.
  EXPECT_NEAR(Cost(p, s.material), s.cost, 1e-12 + 1e-9 * s.cost);
}

TEST(EditorSolve, KeStaysUnknownInBandsNoLightReaches) {
  // Lit in blue only: the look says nothing of ke in green and red, so the
  // solution leaves it unknown there (ToMaterial wrote 0), in the solve and
  // in the grid baseline (which searches ke in every band).
  const Material truth = Truth(kRgb, {0.3}, {{0.2, 0.1, 0.05}}, {{0.5, 2.0, 0.3}});
  const Problem p = FromTruth(truth, {1.0, 0.0, 0.0}, {5, 11, 30, 90});
  const Solution s = Solve(p);
  EXPECT_LT(s.cost, 1e-8 * Scale(p));
  const std::optional<Solution> grid = SolveGridBaseline(p);
  ASSERT_TRUE(grid.has_value());
  for (const Material* m : {&s.material, &grid->material}) {
    EXPECT_TRUE(m->states[0].ke[0].has_value());
    EXPECT_FALSE(m->states[0].ke[1].has_value());
    EXPECT_FALSE(m->states[0].ke[2].has_value());
  }
  EXPECT_NEAR(Cost(p, s.material), s.cost, 1e-12);  // unknown where unlit is no obstacle
  // ... but unknown where the constraints' light falls has no value to simulate with.
  Material unmeasured = truth;
  unmeasured.states[0].ke[0].reset();
  EXPECT_NE(phos::testing::ErrorOfType<UserError>([&] {
              Cost(p, unmeasured);
            }).find("unknown (not measured) for band 380-490"),
            std::string::npos);
}

TEST(EditorSolve, OneTargetInTheDarkGivesTheLeastPhosphorThatMakesIt) {
  // One target tau after the light goes off is met exactly by every kr, with
  // Lambda scaled to it: the cost alone chose among them by rounding (one
  // build gave kr = 6.2 /s and Lambda ~1e11, a wall glowing 1e11 while lit).
  // The solve takes the least Lambda: saturated, the glow kr e^(-kr tau) per
  // unit Lambda is largest at kr = 1 / tau, so kr is within 2x of it, whatever
  // material made the target (random truths, seeded).
  std::mt19937 rng(20261202);
  std::uniform_real_distribution<double> log_uniform(-2.0, 0.5);
  for (int trial = 0; trial < 8; ++trial) {
    const double tau_s = 2.5 + 5.0 * trial;  // the light goes off at 10 s
    const Material truth = Truth(kRgb, {std::pow(10.0, log_uniform(rng))},
                                 {{std::pow(10.0, log_uniform(rng)), std::pow(10.0, log_uniform(rng)), 0.05}},
                                 {{std::pow(10.0, log_uniform(rng)), 2.0, std::pow(10.0, log_uniform(rng))}});
    const Problem p = FromTruth(truth, {1.0, 0.6, 0.2}, {10 + tau_s});
    const Solution s = Solve(p);
    SCOPED_TRACE("tau " + std::to_string(tau_s) + " s, truth kr " + std::to_string(truth.states[0].kr));
    EXPECT_LT(s.cost, 1e-8 * Scale(p));
    const double kr = s.material.states[0].kr;
    EXPECT_GT(kr, 0.5 / tau_s);
    EXPECT_LT(kr, 2.0 / tau_s);
    for (double Lambda : s.material.states[0].Lambda) EXPECT_LE(Lambda, kMaxLambda);
    // The glow as the light goes off is at most e^2 times the target (kr tau <= 2).
    const double at_off = PredictRadiance(p, s.material, {10.0 - 1e-9})[0][1] - 0.5 * 0.6 / std::numbers::pi;
    EXPECT_LT(at_off, std::exp(2.0) * p.constraints[0].radiance[1] * 1.01);
  }
}
TEST(EditorSolve, TwoStatesInEightBands) {
  const SpectralGrid paper = SpectralGrid::Paper();
  const Material truth = Truth(paper, {1.5, 0.05}, {{0.3, 0.2, 0.1, 0, 0, 0, 0, 0}, {0.05, 0.04, 0.02, 0, 0, 0, 0, 0}},
                               {{0, 0.2, 0.5, 0.3, 0, 0, 0, 0}, {0, 0, 0.4, 1.2, 0.5, 0.1, 0, 0}});
  const Problem p = FromTruth(truth, {1, 1, 1, 0, 0, 0, 0, 0}, {3, 10.5, 12, 20, 40, 90});
  const Solution two = Solve(p);
  EXPECT_LT(two.cost, 1e-6 * Scale(p));
  Problem one_state = p;
  one_state.states = 1;
  const Solution one = Solve(one_state);
  EXPECT_GT(one.cost, 100 * two.cost);  // one exponential cannot make this look
  EXPECT_FALSE(one.feedback.empty());
  std::string why;
  EXPECT_FALSE(SolveGridBaseline(p, &why).has_value());
  EXPECT_NE(why.find("nc = 1"), std::string::npos);
}

TEST(EditorSolve, ReachesTheLookOfRandomTwoStateMaterials) {
  // Seeded random two-state truths over the ranges of model/synthetic.h: kr ratios 2
  // to 50, ke and Lambda per state and band; their own look at a lit target,
  // just after the light goes off and through the decay. The truth meets
  // every target, so the solve must too, each within 1% (the feedback calls
  // a miss of 10% one), with a cost below 1e-8 of the targets' energy. The
  // curve library, the projected refinement and the starts are all tried
  // here: a start stuck on a plateau of saturated or weak-light curves, or a
  // refinement that stops on the cost's absolute scale, leaves some of these
  // at 1e-5 and misses of 5-70%.
  std::mt19937 rng(13);
  auto log_uniform = [&](double lo, double hi) {
    return lo * std::pow(hi / lo, std::uniform_real_distribution<double>(0, 1)(rng));
  };
  auto uniform = [&](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
  for (int edit = 0; edit < 24; ++edit) {
    const double kr_slow = log_uniform(0.01, 0.2), ratio = log_uniform(2, 50);
    std::vector<std::vector<double>> ke(2), Lambda(2);
    for (int i = 0; i < 2; ++i)
      for (int b = 0; b < 3; ++b) {
        ke[i].push_back(log_uniform(0.01, 0.5));
        Lambda[i].push_back(uniform(0.1, 2.0));
      }
    const Material truth = Truth(kRgb, {ratio * kr_slow, kr_slow}, ke, Lambda);
    const Problem p = FromTruth(truth, {1.0, 0.6, 0.2}, {3, 10.5, 12, 20, 40, 90});
    const Solution s = Solve(p);
    SCOPED_TRACE("edit " + std::to_string(edit) + ": kr " + std::to_string(truth.states[0].kr) + ", " +
                 std::to_string(kr_slow));
    EXPECT_LT(s.cost, 1e-8 * Scale(p));
    for (std::size_t c = 0; c < s.constraints.size(); ++c) {
      double norm2 = 0;
      for (double v : p.constraints[c].radiance) norm2 += v * v;
      EXPECT_LT(s.constraints[c].residual, 1e-2 * std::sqrt(norm2)) << s.constraints[c].label;
    }
  }
}

// Started from the material a point wears (Problem::start), a constraint at
// its own look changes nothing: every parameter stays as it was, unknown ke
// and name included, on fresh random materials of 1 to 3 states. Started
// from a material that does not meet the targets, the solve still reaches
// them (the start is one more candidate, not a constraint).
TEST(EditorSolve, AConstraintAtTheCurrentLookKeepsTheMaterialItStartsFrom) {
  std::mt19937 rng(20261208);
  auto log_uniform = [&](double lo, double hi) {
    return lo * std::pow(hi / lo, std::uniform_real_distribution<double>(0, 1)(rng));
  };
  for (int trial = 0; trial < 12; ++trial) {
    const int nc = 1 + trial % 3;
    std::vector<double> kr;
    std::vector<std::vector<double>> ke(nc), Lambda(nc);
    for (int i = 0; i < nc; ++i) {
      kr.push_back(log_uniform(0.01, 1.0));
      for (int b = 0; b < 3; ++b) {
        ke[i].push_back(log_uniform(0.01, 0.5));
        Lambda[i].push_back(log_uniform(0.05, 2.0));
      }
    }
    Material wears = Truth(kRgb, kr, ke, Lambda);
    wears.name = "aqua paint";
    wears.states[0].ke[2].reset();  // unknown in a band the light reaches: taken as 0 by the curves
    Material known = wears;
    AssumeUnknownKeZero(known);
    Problem p = FromTruth(known, {1.0, 0.6, 0.2}, {5, 12, 30});
    p.start = wears;
    const Solution kept = Solve(p);
    SCOPED_TRACE("trial " + std::to_string(trial) + ", nc " + std::to_string(nc));
    EXPECT_TRUE(kept.kept_start);
    EXPECT_EQ(MaterialToJson(kept.material), MaterialToJson(wears));

    // A start that misses the look (its rates 3 times off) is refined like
    // any candidate; the look is reached as without it.
    Material off = known;
    for (ExcitedState& state : off.states) state.kr *= 3;
    p.start = off;
    const Solution solved = Solve(p);
    EXPECT_FALSE(solved.kept_start);
    EXPECT_LT(solved.cost, 1e-8 * Scale(p));
  }
}

TEST(EditorSolve, BoundsAreMet) {
  // "At least 0.05 in green until 60 s" with a fast-fading look otherwise.
  const Material truth = Truth(kRgb, {0.5}, {{0.2, 0.1, 0.05}}, {{0.5, 2.0, 0.3}});
  Problem p = FromTruth(truth, {1.0, 0.6, 0.2}, {5, 11});
  p.constraints.push_back({Constraint::Kind::kAtLeast, 0, 10, 60, {0, 0.05, 0}, 100, "bright until 60 s"});
  const Solution s = Solve(p);
  EXPECT_LT(s.constraints.back().residual, 1e-3);  // largest violation over the range
  const auto L = PredictRadiance(p, s.material, {20, 40, 60});
  for (const auto& l : L) EXPECT_GE(l[1], 0.05 - 1e-3);
}

TEST(EditorSolve, ContradictionsAreNamed) {
  const Material truth = Truth(kRgb, {0.3}, {{0.2, 0.1, 0.05}}, {{0.5, 2.0, 0.3}});
  Problem p = FromTruth(truth, {1.0, 0.6, 0.2}, {11, 30});
  p.constraints[1].radiance[1] = 3 * p.constraints[0].radiance[1];  // brighter later, in the dark
  p.constraints[0].label = "early";
  p.constraints[1].label = "late";
  const Solution s = Solve(p);
  bool named = false;
  for (const std::string& note : s.feedback)
    named = named || (note.find("early and late contradict") != std::string::npos);
  EXPECT_TRUE(named);
}

TEST(EditorSolve, SeveralPointsShareOneMaterial) {
  // Two points of one surface, one lit twice as strongly: the same material
  // must explain both looks.
  const Material truth = Truth(kRgb, {0.3}, {{0.2, 0.1, 0.05}}, {{0.5, 2.0, 0.3}});
  Problem p = FromTruth(truth, {1.0, 0.6, 0.2}, {5, 11, 30});
  Point bright = p.points[0];
  for (auto& E : bright.irradiance)
    for (double& e : E) e *= 2;
  p.points.push_back(bright);
  const auto L = PredictRadiance(p, truth, {11, 30}, 1);
  p.constraints.push_back({Constraint::Kind::kTarget, 1, 11, 11, L[0], 1, "bright 11"});
  p.constraints.push_back({Constraint::Kind::kTarget, 1, 30, 30, L[1], 1, "bright 30"});
  const Solution s = Solve(p);
  EXPECT_LT(s.cost, 1e-8 * Scale(p));
  EXPECT_NEAR(s.material.states[0].kr, 0.3, 0.003);
  // Saturation differs between the points, which pins ke (not only ke * Lambda).
  EXPECT_NEAR(s.material.states[0].ke[0].value() * 1.0 + s.material.states[0].ke[1].value() * 0.6 +
                  s.material.states[0].ke[2].value() * 0.2,
              0.2 + 0.06 + 0.01, 0.01);
}

// What ProblemFromJson refuses in a constraint file once `edit` has changed it.
std::string ErrorOfEdited(const nlohmann::json& file, const std::function<void(nlohmann::json&)>& edit) {
  nlohmann::json copy = file;
  edit(copy);
  return phos::testing::ErrorOfType<UserError>([&] { ProblemFromJson(copy, "c.json"); });
}

TEST(EditorSolve, BadConstraintFilesNameTheField) {
  nlohmann::json j = phos::ReadJsonFile(phos::testing::Fixture("constraints/glow-sign.json"));
  EXPECT_NO_THROW(ProblemFromJson(j, "glow-sign.json"));
  auto error = [&](const std::function<void(nlohmann::json&)>& edit) { return ErrorOfEdited(j, edit); };
  EXPECT_NE(error([](nlohmann::json& c) { c["constraints"][0]["t_s"] = 500; }).find("constraints[0].t_s"),
            std::string::npos);
  EXPECT_NE(error([](nlohmann::json& c) { c["irradiance"][3] = {1, 2}; }).find("irradiance[3]"), std::string::npos);
  EXPECT_NE(error([](nlohmann::json& c) { c["constraints"][1].erase("radiance"); }).find("exactly one of"),
            std::string::npos);
  EXPECT_NE(error([](nlohmann::json& c) { c["states"] = 9; }).find("states"), std::string::npos);
  EXPECT_NE(error([](nlohmann::json& c) { c["albedo"][0] = 2; }).find("albedo[0]"), std::string::npos);
  EXPECT_NE(error([](nlohmann::json& c) { c["constraints"][0]["until_s"] = 9; }).find("ranges are for"),
            std::string::npos);
}

TEST(EditorSolve, PhasesGiveTheSameProblemAsRows) {
  // glow-sign.json's 200 rows are 10 s lit, then 90 s dark: the two phases
  // of glow-sign-phases.json.
  const nlohmann::json rows = phos::ReadJsonFile(phos::testing::Fixture("constraints/glow-sign.json"));
  nlohmann::json phases = phos::ReadJsonFile(phos::testing::Fixture("constraints/glow-sign-phases.json"));
  const Problem a = ProblemFromJson(rows, "rows.json"), b = ProblemFromJson(phases, "phases.json");
  ASSERT_EQ(a.points.size(), 1u);
  ASSERT_EQ(b.points.size(), 1u);
  EXPECT_EQ(a.points[0].irradiance, b.points[0].irradiance);
  EXPECT_EQ(a.end_s(), b.end_s());
  EXPECT_EQ(Solve(a).material.states[0].kr, Solve(b).material.states[0].kr);

  // A switch inside a frame: that frame gets the mean (0.25 s lit of 0.5).
  phases["irradiance"][0]["duration_s"] = 10.25;
  phases["irradiance"][1]["duration_s"] = 89.75;
  const Problem c = ProblemFromJson(phases, "phases.json");
  ASSERT_EQ(c.points[0].irradiance.size(), 200u);
  EXPECT_EQ(c.points[0].irradiance[19], (std::vector<double>{1.0, 0.6, 0.2}));
  EXPECT_EQ(c.points[0].irradiance[20], (std::vector<double>{0.5, 0.3, 0.1}));
  EXPECT_EQ(c.points[0].irradiance[21], (std::vector<double>{0, 0, 0}));
}

TEST(EditorSolve, BadPhasesNameTheField) {
  nlohmann::json j = phos::ReadJsonFile(phos::testing::Fixture("constraints/glow-sign-phases.json"));
  ASSERT_NO_THROW(ProblemFromJson(j, "c.json"));
  auto error = [&](const std::function<void(nlohmann::json&)>& edit) { return ErrorOfEdited(j, edit); };
  EXPECT_NE(
      error([](nlohmann::json& c) { c["irradiance"][1]["duration_s"] = 90.2; }).find("not a whole number of frames"),
      std::string::npos);
  EXPECT_NE(error([](nlohmann::json& c) { c["irradiance"][1]["duraton_s"] = 90; }).find("irradiance[1]"),
            std::string::npos);
  EXPECT_NE(error([](nlohmann::json& c) {
              c["irradiance"][1] = {0, 0, 0};
            }).find("irradiance[1]: a row among phases"),
            std::string::npos);
  const nlohmann::json rows = phos::ReadJsonFile(phos::testing::Fixture("constraints/glow-sign.json"));
  EXPECT_NE(
      ErrorOfEdited(rows, [&](nlohmann::json& c) { c["irradiance"][1] = j["irradiance"][1]; })  // a phase among rows
          .find("irradiance[1]: a phase among rows"),
      std::string::npos);
  EXPECT_NE(error([](nlohmann::json& c) {
              c["irradiance"][0]["irradiance"] = {1, 2};
            }).find("irradiance[0].irradiance"),
            std::string::npos);
  EXPECT_NE(error([](nlohmann::json& c) { c["irradiance"][0]["duration_s"] = -1; }).find("irradiance[0].duration_s"),
            std::string::npos);
  EXPECT_NE(error([](nlohmann::json& c) { c["irradiance"][0].erase("irradiance"); }).find("zero at every frame"),
            std::string::npos);
  EXPECT_NE(error([](nlohmann::json& c) { c["irradiance"][1]["duration_s"] = 1e9; }).find("irradiance[1].duration_s"),
            std::string::npos);
}

}  // namespace
}  // namespace phos::editor
