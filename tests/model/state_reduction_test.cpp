// ReduceStates (model/state_reduction.h): the fewest states whose radiance
// stays within a relative tolerance of the full material's over a span,
// checked on grids and by a simulator the search never saw.

#include "phos/model/state_reduction.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "phos/model/simulate.h"
#include "phos/model/synthetic.h"
#include "phos/util/error.h"

namespace phos {
namespace {

constexpr double kDt_s = 1.0 / 30;
const std::vector<double> kLight = {1.0, 0.6, 0.2, 0, 0, 0, 0, 0};

// A random material of `states` states with kr log-uniform over four decades
// (1e-4 to 1/s), ke in bands 0-2 (unknown elsewhere, as Table 8.1), and one
// emission shape for all states or one per state.
Material RandomMaterial(std::mt19937_64& rng, int states, bool per_state_shape) {
  std::uniform_real_distribution<double> u(0, 1);
  Material m;
  m.name = "random";
  m.bands = SpectralGrid::Paper();
  std::vector<double> shape(8);
  for (double& s : shape) s = u(rng);
  for (int i = 0; i < states; ++i) {
    ExcitedState state;
    state.kr = std::pow(10.0, -4 + 4 * u(rng));
    for (int b = 0; b < 8; ++b) state.ke.push_back(b < 3 ? std::optional(0.01 + 0.2 * u(rng)) : std::nullopt);
    const double scale = 0.2 + u(rng);
    for (int b = 0; b < 8; ++b) state.Lambda.push_back(scale * (per_state_shape ? u(rng) : shape[b]));
    m.states.push_back(state);
  }
  return m;
}

// A power law t^-1 (equal weights on 16 rates log-spaced from 0.5/s to
// 1/(10 h)), the many-trap kind of long-afterglow paint.
Material PowerLawMaterial(int states = 16) {
  Material m;
  m.name = "power-law";
  m.bands = SpectralGrid::Paper();
  for (int i = 0; i < states; ++i) {
    ExcitedState state;
    state.kr = 0.5 * std::pow(1 / (0.5 * 36000.0), i / (states - 1.0));
    for (int b = 0; b < 8; ++b) state.ke.push_back(b < 3 ? std::optional(0.05) : std::nullopt);
    for (int b = 0; b < 8; ++b) state.Lambda.push_back(std::exp(-0.5 * std::pow((b - 3.0) / 1.2, 2)));
    m.states.push_back(state);
  }
  return m;
}

IrradianceSchedule Charge(double charge_s, double span_s) {
  return IrradianceSchedule::ChargeThenDecay(kLight, charge_s, span_s - charge_s);
}

// Times the search never used: 64 per decade (4x its 16), at offsets its
// grids do not have, after each of the two switches.
std::vector<double> OtherGrid(double charge_s, double span_s) {
  std::vector<double> times;
  for (double s : {0.0, charge_s})
    for (int j = 0;; ++j) {
      const double t = s + kDt_s * std::pow(10.0, (j + 0.37) / 64);
      if (t > span_s) break;
      times.push_back(t);
    }
  return times;
}

// e(t) of the header, maxed over the frames of `phos simulate` from one frame on.
double SimulatedError(const Material& full, const Material& reduced, const IrradianceSchedule& schedule) {
  SimulationOptions options;
  options.dt_s = kDt_s;
  const SimulationResult a = Simulate(full, schedule, options, "full");
  const SimulationResult b = Simulate(reduced, schedule, options, "reduced");
  double worst = 0;
  for (std::size_t s = 1; s < a.sample_count(); ++s) {
    double total = 0, band = 0;
    for (int k = 0; k < a.nb; ++k) {
      total += a.radiance(s, k);
      band = std::max(band, std::fabs(a.radiance(s, k) - b.radiance(s, k)));
    }
    if (total > 0) worst = std::max(worst, band / total);
  }
  return worst;
}

TEST(ReduceStates, RandomMaterialsStayWithinTheToleranceOnGridsItNeverSaw) {
  int reduced = 0;
  for (int seed = 1; seed <= 16; ++seed) {
    std::mt19937_64 rng(seed);
    const Material m = RandomMaterial(rng, 4, seed % 2 == 0);
    const double tolerance = seed % 3 == 0 ? 0.01 : 0.03, charge_s = 60, span_s = 600;
    const IrradianceSchedule schedule = Charge(charge_s, span_s);
    StateReductionOptions options;
    options.span_s = span_s;
    options.dt_s = kDt_s;
    options.tolerance = tolerance;
    const StateReduction r = ReduceStates(m, schedule, options, "random");
    EXPECT_EQ(r.states_before, 4);
    EXPECT_EQ(r.states_after, r.material.state_count());
    EXPECT_LE(r.max_error, tolerance) << seed;
    EXPECT_LE(MaxRadianceError(m, r.material, schedule, OtherGrid(charge_s, span_s), "random"), tolerance) << seed;
    EXPECT_LE(SimulatedError(m, r.material, schedule), tolerance) << seed;
    reduced += r.states_after < 4;
  }
  EXPECT_GE(reduced, 8);  // the test is about reduced materials
}

TEST(ReduceStates, APowerLawOfSixteenStatesStaysWithinTheTolerance) {
  const Material m = PowerLawMaterial();
  for (double span_s : {60.0, 600.0, 3600.0}) {
    const IrradianceSchedule schedule = Charge(std::min(300.0, span_s / 2), span_s);
    StateReductionOptions options;
    options.span_s = span_s;
    options.tolerance = 0.01;
    const StateReduction r = ReduceStates(m, schedule, options, "power-law");
    EXPECT_LT(r.states_after, 16) << span_s;
    EXPECT_LE(MaxRadianceError(m, r.material, schedule, OtherGrid(std::min(300.0, span_s / 2), span_s), "pl"), 0.01)
        << span_s;
  }
}

TEST(ReduceStates, RandomManyTrapMaterialsStayWithinTheToleranceInEveryFrame) {
  for (int seed = 1; seed <= 6; ++seed) {
    ManyTrapRanges ranges;
    ranges.per_state_spectra = seed % 2 == 0;
    const Material m = RandomManyTrapMaterial(seed, ranges);
    const IrradianceSchedule schedule = Charge(300, 3600);
    StateReductionOptions options;
    options.span_s = 3600;
    options.tolerance = 0.02;
    const StateReduction r = ReduceStates(m, schedule, options, "many-trap");
    EXPECT_LT(r.states_after, r.states_before) << seed;
    EXPECT_LE(MaxRadianceError(m, r.material, schedule, OtherGrid(300, 3600), "many-trap"), 0.02) << seed;
    EXPECT_LE(SimulatedError(m, r.material, schedule), 0.02) << seed;
  }
}

// The renderer's case: the sign-paint fixture in scenes of 1 min, 10 min
// and 1 h after a 5 min charge, every frame of 1/30 s within 1%.
TEST(ReduceStates, SignPaintKeepsEveryFrameWithinTheTolerance) {
  const Material m = LoadMaterial(std::string(PHOS_FIXTURES_DIR) + "/materials/sign-paint.json");
  for (double scene_s : {60.0, 600.0, 3600.0}) {
    const IrradianceSchedule schedule = Charge(300, 300 + scene_s);
    StateReductionOptions options;
    options.span_s = 300 + scene_s;
    options.tolerance = 0.01;
    const StateReduction r = ReduceStates(m, schedule, options, "sign-paint");
    EXPECT_LT(r.states_after, 16) << scene_s;
    EXPECT_LE(r.max_error, 0.01) << scene_s;
    EXPECT_LE(SimulatedError(m, r.material, schedule), 0.01) << scene_s;
  }
}

TEST(ReduceStates, FewerStatesForALooserToleranceOrAShorterSpan) {
  for (int seed = 1; seed <= 6; ++seed) {
    std::mt19937_64 rng(100 + seed);
    const Material m = seed <= 2 ? PowerLawMaterial(8 + 4 * seed) : RandomMaterial(rng, 4, seed % 2 == 0);
    int previous = 1000;
    for (double tolerance : {0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.3}) {
      StateReductionOptions options;
      options.span_s = 1200;
      options.tolerance = tolerance;
      const int k = ReduceStates(m, Charge(60, 1200), options, "m").states_after;
      EXPECT_LE(k, previous) << seed << " " << tolerance;
      previous = k;
    }
    previous = 0;
    for (double span_s : {120.0, 600.0, 3600.0, 36000.0}) {
      StateReductionOptions options;
      options.span_s = span_s;
      options.tolerance = 0.01;
      const int k = ReduceStates(m, Charge(60, span_s), options, "m").states_after;
      EXPECT_GE(k, previous) << seed << " " << span_s;
      previous = k;
    }
  }
}

TEST(ReduceStates, AMinimalMaterialStaysWhole) {
  // Two states three decades apart, each half of the glow at some time.
  Material m = PowerLawMaterial(2);
  m.states[0].kr = 1.0;
  m.states[1].kr = 1e-3;
  StateReductionOptions options;
  options.span_s = 600;
  options.tolerance = 0.01;
  const StateReduction r = ReduceStates(m, Charge(60, 600), options, "m");
  EXPECT_EQ(r.states_after, 2);
  EXPECT_EQ(r.max_error, 0.0);
  EXPECT_EQ(r.material.states[0].kr, 1.0);
  EXPECT_EQ(r.material.states[1].kr, 1e-3);
}

TEST(ReduceStates, AStateFasterThanAFrameOrDarkGoesWhenTheToleranceAllows) {
  Material m = PowerLawMaterial(3);
  m.states[0].kr = 0.01;
  m.states[1].kr = 1000;  // gone within a frame of 1/30 s; at most 0.06% of the glow (one frame into the charge)
  for (auto& ke : m.states[1].ke)
    if (ke) *ke = 1e-8;
  m.states[2].kr = 0.05;
  for (double& l : m.states[2].Lambda) l = 0;  // emits nothing
  StateReductionOptions options;
  options.span_s = 600;
  options.tolerance = 0.01;
  const IrradianceSchedule schedule = Charge(60, 600);
  StateReduction r = ReduceStates(m, schedule, options, "m");
  ASSERT_EQ(r.states_after, 1);
  EXPECT_NEAR(r.material.states[0].kr, 0.01, 1e-4);  // the slow state, or all but
  EXPECT_GT(r.max_error, 0.0);
  options.tolerance = 1e-4;  // the fast state's share matters now; the dark one still goes
  r = ReduceStates(m, schedule, options, "m");
  ASSERT_EQ(r.states_after, 2);
  EXPECT_EQ(r.material.states[1].kr, 1000);
}

TEST(ReduceStates, AFixedCountGivesThatManyStates) {
  const Material m = PowerLawMaterial();
  double previous = -1;
  for (int k : {16, 8, 4, 2, 1}) {
    StateReductionOptions options;
    options.span_s = 3600;
    options.states = k;
    const StateReduction r = ReduceStates(m, Charge(300, 3600), options, "m");
    EXPECT_EQ(r.states_after, k);
    EXPECT_GE(r.max_error, previous) << k;  // fewer states cost more here
    previous = r.max_error;
  }
  EXPECT_GT(previous, 0.1);  // one state cannot follow a power law over an hour
}

TEST(ReduceStates, BadOptionsAreOneLineNamingTheOption) {
  const Material m = PowerLawMaterial(2);
  auto message = [&](StateReductionOptions options) {
    try {
      ReduceStates(m, Charge(60, 600), options, "m.json");
    } catch (const UserError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  StateReductionOptions good;
  good.span_s = 600;
  for (double bad : {0.0, -1.0, std::nan(""), std::numeric_limits<double>::infinity()}) {
    StateReductionOptions o = good;
    o.span_s = bad;
    EXPECT_NE(message(o).find("m.json: span_s: expected a finite number > 0"), std::string::npos) << message(o);
    o = good;
    o.tolerance = bad;
    EXPECT_NE(message(o).find("m.json: tolerance: expected a finite number > 0"), std::string::npos) << message(o);
    o = good;
    o.dt_s = bad;
    EXPECT_NE(message(o).find("dt_s"), std::string::npos) << message(o);
  }
  StateReductionOptions o = good;
  o.states = 0;
  EXPECT_NE(message(o).find("states"), std::string::npos);
}

}  // namespace
}  // namespace phos
