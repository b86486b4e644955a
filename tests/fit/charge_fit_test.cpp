// Charge fits against closed forms, including the model's own charging curve.

#include "phos/fit/charge_fit.h"

#include <cmath>
#include <gtest/gtest.h>
#include <random>

#include "phos/model/simulate.h"
#include "phos/util/error.h"
#include "test_util.h"

namespace phos {
namespace {

Curve Growth(double L0, double Linf, double k, int points, double dt, double noise, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> gauss(0, noise);
  Curve curve{{}, {{}}, {"value"}};
  for (int j = 0; j < points; ++j) {
    const double t = j * dt;
    curve.t_s.push_back(t);
    curve.channels[0].push_back(Linf - (Linf - L0) * std::exp(-k * t) + gauss(rng));
  }
  return curve;
}

TEST(ChargeFit, RecoversTheSaturatingGrowth) {
  ChargeFitSummary exact = FitCharge(Growth(0.1, 2.0, 0.05, 200, 0.5, 0, 1), {}, "exact");
  EXPECT_NEAR(exact.rate, 0.05, 1e-9);
  EXPECT_NEAR(exact.L0, 0.1, 1e-9);
  EXPECT_NEAR(exact.Linf, 2.0, 1e-9);
  ChargeFitSummary noisy = FitCharge(Growth(0.1, 2.0, 0.05, 200, 0.5, 0.01, 2), {}, "noisy");
  EXPECT_NEAR(noisy.rate, 0.05, 4 * noisy.rate_stderr);
  EXPECT_NEAR(noisy.Linf, 2.0, 4 * noisy.Linf_stderr);
  EXPECT_NEAR(noisy.L0, 0.1, 4 * noisy.L0_stderr);
  EXPECT_NEAR(noisy.rss / 200, 1e-4, 2e-5);
}

TEST(ChargeFit, FallingTowardALevelIsTheSameModel) {
  ChargeFitSummary fit = FitCharge(Growth(3.0, 1.0, 0.2, 100, 0.2, 0, 3), {}, "fall");
  EXPECT_NEAR(fit.rate, 0.2, 1e-9);
  EXPECT_NEAR(fit.L0, 3.0, 1e-9);
}

TEST(ChargeFit, FindsTheModelsChargingRate) {
  // Under constant light Eq. 8.1 charges with rate k = a + kr: fitting the
  // simulated emission must give it back.
  Material orange = LoadMaterial(testing::Fixture("materials/orange.json"));
  std::vector<double> E = {2, 1, 0.5, 0, 0, 0, 0, 0};
  SimulationOptions options;
  options.dt_s = 0.5;
  SimulationResult run = Simulate(orange, IrradianceSchedule::ChargeThenDecay(E, 150, 0), options, "orange");
  Curve curve{run.t_s, {{}}, {"L"}};
  for (std::size_t s = 0; s < run.sample_count(); ++s) {
    double total = 0;
    for (int b = 0; b < run.nb; ++b) total += run.radiance(s, b);
    curve.channels[0].push_back(total);
  }
  const double a = 2 * 0.015 + 1 * 0.006 + 0.5 * 0.0003;
  ChargeFitSummary fit = FitCharge(curve, {}, "orange");
  EXPECT_NEAR(fit.rate, a + 0.015, 1e-7);
  EXPECT_NEAR(fit.L0, 0, 1e-9);
}

TEST(ChargeFit, CurvesWithoutALevelAreClearErrors) {
  Curve flat{{0, 1, 2, 3, 4}, {{1, 1, 1, 1, 1}}, {"v"}};
  EXPECT_THROW(FitCharge(flat, {}, "flat"), UserError);
  Curve ramp{{}, {{}}, {"v"}};
  for (int j = 0; j < 50; ++j) {
    ramp.t_s.push_back(j);
    ramp.channels[0].push_back(j * 0.1);
  }
  try {
    FitCharge(ramp, {}, "ramp.csv");
    FAIL() << "a straight ramp was fitted";
  } catch (const UserError& e) {
    EXPECT_NE(std::string(e.what()).find("ramp.csv: the curve does not approach a level"), std::string::npos) << e.what();
  }
  Curve short_curve{{0, 1, 2}, {{0, 1, 1.5}}, {"v"}};
  EXPECT_THROW(FitCharge(short_curve, {}, "short"), UserError);
}

}  // namespace
}  // namespace phos
