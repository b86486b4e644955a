// Synthetic two-state materials (model/synthetic.h): the fixtures are what
// their specs make, the specs mean what they say (rate ratio, the fast
// state's share of the glow at equilibrium, rho), and the random generator
// is reproducible and stays inside its ranges.

#include <gtest/gtest.h>

#include <cmath>
#include <numeric>
#include <stdexcept>

#include "phos/model/material.h"
#include "phos/model/synthetic.h"
#include "test_util.h"

namespace phos {
namespace {

TEST(TwoStateMaterials, EveryFixtureIsExactlyItsSpecsMaterial) {
  const std::vector<TwoStateSpec> specs = TwoStateFixtureSpecs();
  ASSERT_GE(specs.size(), 5u);
  for (const TwoStateSpec& spec : specs) {
    const auto path = testing::Fixture("materials/" + spec.name + ".json");
    ASSERT_TRUE(std::filesystem::exists(path)) << path << " (build/bin/phos-two-state-fixtures writes it)";
    EXPECT_EQ(MaterialToJson(LoadMaterial(path)), MaterialToJson(TwoStateMaterial(spec))) << spec.name;
  }
}

TEST(TwoStateMaterials, TheSpecMeansWhatItSays) {
  TwoStateSpec spec;
  spec.slow_kr = 0.03;
  spec.rate_ratio = 12;
  spec.fast_share = 0.3;
  spec.fast_rho = 0.7;
  spec.slow_rho = 1.9;
  spec.glow = 0.25;
  const Material m = TwoStateMaterial(spec);
  ASSERT_EQ(m.state_count(), 2);
  EXPECT_DOUBLE_EQ(m.states[0].kr, 0.36);  // fastest first
  EXPECT_DOUBLE_EQ(m.states[1].kr, 0.03);
  // Glow at equilibrium under unit irradiance in band 1: kr Lambda r summed.
  double glow[2];
  for (int i = 0; i < 2; ++i) {
    const ExcitedState& s = m.states[i];
    const double a = *s.ke[0], r = a / (a + s.kr);
    glow[i] = s.kr * r * std::accumulate(s.Lambda.begin(), s.Lambda.end(), 0.0);
  }
  EXPECT_NEAR(glow[0] / (glow[0] + glow[1]), 0.3, 1e-12);
  EXPECT_NEAR(glow[0] + glow[1], 0.25, 1e-12);
  // rho: the largest ke over kr.
  for (int i = 0; i < 2; ++i) {
    double largest = 0;
    for (const auto& ke : m.states[i].ke) largest = std::max(largest, ke.value_or(0.0));
    EXPECT_NEAR(largest / m.states[i].kr, i == 0 ? 0.7 : 1.9, 1e-12);
  }
  // One emission shape for both states; ke known in bands 1-3 only.
  for (int b = 0; b < 8; ++b) {
    EXPECT_NEAR(m.states[0].Lambda[b] * m.states[1].Lambda[3], m.states[1].Lambda[b] * m.states[0].Lambda[3],
                1e-12 * m.states[0].Lambda[3] * m.states[1].Lambda[3]);
    EXPECT_EQ(m.states[0].ke[b].has_value(), b < 3);
  }
}

TEST(TwoStateMaterials, RandomOnesAreReproducibleAndInsideTheirRanges) {
  const TwoStateRanges ranges;
  for (std::uint64_t seed = 1; seed <= 200; ++seed) {
    const TwoStateSpec a = RandomTwoStateSpec(seed), b = RandomTwoStateSpec(seed);
    EXPECT_EQ(MaterialToJson(TwoStateMaterial(a)), MaterialToJson(TwoStateMaterial(b)));
    EXPECT_GE(a.rate_ratio, ranges.rate_ratio_min);
    EXPECT_LE(a.rate_ratio, ranges.rate_ratio_max);
    EXPECT_GE(a.fast_share, ranges.fast_share_min);
    EXPECT_LE(a.fast_share, ranges.fast_share_max);
    EXPECT_GE(a.slow_kr, ranges.slow_kr_min);
    EXPECT_LE(a.slow_kr, ranges.slow_kr_max);
  }
  // A fixed seed gives the same numbers on every machine (no
  // implementation-defined distribution behind them).
  EXPECT_NE(MaterialToJson(RandomTwoStateMaterial(1)), MaterialToJson(RandomTwoStateMaterial(2)));
}

TEST(TwoStateMaterials, ASpecOutsideItsDomainIsRefused) {
  TwoStateSpec spec;
  spec.rate_ratio = 1;
  EXPECT_THROW(TwoStateMaterial(spec), std::invalid_argument);
  spec = TwoStateSpec{};
  spec.fast_share = 1;
  EXPECT_THROW(TwoStateMaterial(spec), std::invalid_argument);
  spec = TwoStateSpec{};
  spec.fast_excitation_shape = {1.0, 0.0, 0.5};
  EXPECT_THROW(TwoStateMaterial(spec), std::invalid_argument);
}

}  // namespace
}  // namespace phos
