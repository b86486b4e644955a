// Excitation per excited state (state_excitation_fit.h): recovery of every
// state's rate under every light from charges with decay tails, exact on
// noise-free data and within its stated uncertainty on noisy data, and the
// identifiability of the design (the tail against one frame per charge).

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "phos/fit/state_excitation_fit.h"
#include "phos/util/error.h"

namespace phos {
namespace {

// The protocol's design: charge times doubling from 1 s to 2048 s and their
// geometric midpoints; after each charge a frame 0.05 s after light-off and
// `tail` more, each twice as long, back to back (10 ms readout).
std::vector<ExcitationMeasurement> Design(const std::vector<std::string>& lights, int tail, double exposure_s = 0.2) {
  std::vector<double> charges;
  for (double t = 1; t <= 2048; t *= 2) charges.push_back(t);
  for (std::size_t i = 1; i < 12; ++i) charges.push_back(std::sqrt(charges[i - 1] * charges[i]));
  std::vector<ExcitationMeasurement> design;
  for (const std::string& light : lights)
    for (double charge : charges) {
      ExcitationMeasurement m{light, charge, {}};
      double delay = 0.05, e = exposure_s;
      for (int j = 0; j <= tail; ++j) {
        m.frames.push_back({delay, e, 0.0});
        delay += e + 0.01;
        e *= 2;
      }
      design.push_back(m);
    }
  return design;
}

struct Truth {
  std::vector<double> kr, S;
  std::map<std::string, std::vector<double>> a;
};

Truth TwoStates() {
  // A fast bright state and a slow one (rate ratio 8), each charged most by another light.
  return {{0.16, 0.02}, {3e4, 2e4}, {{"led420", {0.12, 0.004}}, {"led456", {0.03, 0.018}}, {"led494", {0.006, 0.009}}}};
}

std::vector<ExcitationMeasurement> Measure(std::vector<ExcitationMeasurement> design, const Truth& truth,
                                           double background, std::mt19937_64* rng, double electrons_per_dn) {
  for (auto& m : design)
    for (auto& f : m.frames) {
      f.value = ExcitationFrameSignal(truth.S, truth.a.at(m.light), truth.kr, m.charge_s, f, background);
      if (rng) {
        // Photon counting: a rate's variance is value / (exposure * gain).
        std::normal_distribution<double> noise(0.0,
                                               std::sqrt(std::max(f.value, 0.0) / (f.exposure_s * electrons_per_dn)));
        f.value += noise(*rng);
      }
    }
  return design;
}

TEST(StateExcitationFit, RecoversEveryStateUnderEveryLightFromExactData) {
  const Truth truth = TwoStates();
  const auto data = Measure(Design({"led420", "led456", "led494"}, 6), truth, 3.0, nullptr, 0);
  StateExcitationOptions options;
  options.kr = truth.kr;
  const StateExcitationFit fit = FitStateExcitation(data, options, "exact");
  EXPECT_TRUE(fit.converged) << fit.termination;
  for (const auto& [light, a] : truth.a)
    for (int i = 0; i < 2; ++i) EXPECT_NEAR(fit.a.at(light)[i], a[i], 1e-5 * a[i]) << light << " state " << i + 1;
  for (int i = 0; i < 2; ++i) EXPECT_NEAR(fit.S[i], truth.S[i], 1e-5 * truth.S[i]);
  EXPECT_NEAR(fit.background, 3.0, 1e-3);
}

// On noisy data the 1-sigma intervals cover the truth about 68% of the time
// (seeded noise, 20 repetitions, 6 rates each).
TEST(StateExcitationFit, UncertaintiesCoverTheTruthAsStated) {
  const Truth truth = TwoStates();
  const auto design = Design({"led420", "led456", "led494"}, 6);
  StateExcitationOptions options;
  options.kr = truth.kr;
  int covered = 0, total = 0;
  for (int seed = 1; seed <= 20; ++seed) {
    std::mt19937_64 rng(static_cast<unsigned>(seed));
    const StateExcitationFit fit = FitStateExcitation(Measure(design, truth, 0.0, &rng, 50.0), options, "noisy");
    for (const auto& [light, a] : truth.a)
      for (int i = 0; i < 2; ++i) {
        const double error = std::fabs(fit.a.at(light)[i] - a[i]);
        ASSERT_GT(fit.a_stderr.at(light)[i], 0.0);
        EXPECT_LT(error, 5 * fit.a_stderr.at(light)[i]) << light << " state " << i + 1 << " seed " << seed;
        covered += error <= fit.a_stderr.at(light)[i];
        ++total;
      }
  }
  const double coverage = static_cast<double>(covered) / total;
  EXPECT_GT(coverage, 0.58) << covered << " of " << total;
  EXPECT_LT(coverage, 0.78) << covered << " of " << total;
}

// The design: one frame per charge sees only the sum over the states, so
// how much of each state a charge made is pinned only by the charging
// curves' shapes (two exponentials in the charge time whose rates a + kr
// may be close); the tail's shape pins it directly, for 3% more bench time
// (25 s of tail against 900 s of reset and the charge). The Cramer-Rao
// bounds of the rates say by how much, for the rate pinned worst.
TEST(StateExcitationFit, TheDecayTailMakesTheStatesIdentifiable) {
  const Truth truth = TwoStates();
  const std::vector<std::string> lights = {"led420", "led456", "led494"};
  const DesignInformation tail = ExcitationDesignInformation(Design(lights, 6), truth.S, truth.a, truth.kr);
  const DesignInformation one = ExcitationDesignInformation(Design(lights, 0), truth.S, truth.a, truth.kr);
  std::printf(
      "worst relative 1-sigma of an a at one electron per unit: tail %.3g, one frame %.3g; "
      "condition numbers %.3g, %.3g\n",
      tail.worst_a_relative_stderr, one.worst_a_relative_stderr, tail.condition_number, one.condition_number);
  EXPECT_LT(3 * tail.worst_a_relative_stderr, one.worst_a_relative_stderr);
  // Two states whose charging rates a + kr nearly coincide under a light:
  // that light's charging curve alone cannot split them (only S, known from
  // the other lights, and the level can); the tail splits them directly.
  Truth close = truth;
  close.a["led456"] = {0.0001, 0.1403};  // a + kr = 0.1601 and 0.1603
  const DesignInformation close_tail = ExcitationDesignInformation(Design(lights, 6), close.S, close.a, close.kr);
  const DesignInformation close_one = ExcitationDesignInformation(Design(lights, 0), close.S, close.a, close.kr);
  EXPECT_LT(5 * close_tail.a_relative_stderr.at("led456")[1], close_one.a_relative_stderr.at("led456")[1]);
  // With one state both designs pin the rate (the tail's extra frames help).
  const Truth single{{0.05}, {2e4}, {{"led420", {0.03}}}};
  const double single_one =
      ExcitationDesignInformation(Design({"led420"}, 0), single.S, single.a, single.kr).worst_a_relative_stderr;
  const double single_tail =
      ExcitationDesignInformation(Design({"led420"}, 6), single.S, single.a, single.kr).worst_a_relative_stderr;
  EXPECT_LT(single_one, 0.1);
  EXPECT_LT(single_tail, single_one);
}

TEST(StateExcitationFit, BadInputIsAClearError) {
  StateExcitationOptions options;
  options.kr = {0.1};
  EXPECT_THROW(FitStateExcitation({}, options, "x"), UserError);
  std::vector<ExcitationMeasurement> data = {{"led", 1.0, {{0.05, 0.2, std::nan("")}}}};
  EXPECT_THROW(FitStateExcitation(data, options, "x"), UserError);
  data[0].frames[0].value = 0;
  EXPECT_THROW(FitStateExcitation(data, options, "x"), UserError);  // no signal at all
  data[0].frames[0].value = 10;
  options.kr = {-1};
  EXPECT_THROW(FitStateExcitation(data, options, "x"), UserError);
}

}  // namespace
}  // namespace phos
