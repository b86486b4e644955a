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
    EXPECT_NE(std::string(e.what()).find("ramp.csv: the curve does not approach a level"), std::string::npos)
        << e.what();
  }
  Curve short_curve{{0, 1, 2}, {{0, 1, 1.5}}, {"v"}};
  EXPECT_THROW(FitCharge(short_curve, {}, "short"), UserError);
}

TEST(ChargeFit, ChannelsShareTheRateAndKeepTheirLevels) {
  // Three channels of one growth rate; exact data give every level back.
  const double k = 0.08;
  const double L0[3] = {0.0, 0.2, 3.0}, Linf[3] = {3.0, 8.0, 1.5};  // the third falls toward its level
  Curve exact{{}, {{}, {}, {}}, {"a", "b", "c"}};
  for (int j = 0; j < 60; ++j) {
    exact.t_s.push_back(j * 1.5);
    for (int c = 0; c < 3; ++c) exact.channels[c].push_back(Linf[c] - (Linf[c] - L0[c]) * std::exp(-k * j * 1.5));
  }
  const ChargeFitSummary fit = FitCharge(exact, {}, "exact");
  EXPECT_NEAR(fit.rate, k, 1e-9);
  ASSERT_EQ(fit.levels.size(), 3u);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(fit.levels[c].L0, L0[c], 1e-8) << c;
    EXPECT_NEAR(fit.levels[c].Linf, Linf[c], 1e-8) << c;
  }
  EXPECT_EQ(fit.L0, fit.levels[0].L0);
  EXPECT_EQ(fit.Linf, fit.levels[0].Linf);
  // With noise the shared rate is better known than from any one channel.
  std::mt19937 rng(8);
  std::normal_distribution<double> gauss(0, 0.02);
  Curve noisy = exact;
  for (auto& channel : noisy.channels)
    for (double& v : channel) v += gauss(rng);
  const ChargeFitSummary shared = FitCharge(noisy, {}, "noisy");
  EXPECT_NEAR(shared.rate, k, 4 * shared.rate_stderr);
  Curve alone{noisy.t_s, {noisy.channels[0]}, {"a"}};
  EXPECT_LT(shared.rate_stderr, FitCharge(alone, {}, "alone").rate_stderr);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(shared.levels[c].Linf, Linf[c], 4 * shared.levels[c].Linf_stderr) << c;
  // A flat channel beside growing ones is a level, not an error.
  Curve with_flat = exact;
  with_flat.channels[2].assign(exact.size(), 0.7);
  const ChargeFitSummary flat = FitCharge(with_flat, {}, "flat");
  EXPECT_NEAR(flat.rate, k, 1e-9);
  EXPECT_NEAR(flat.levels[2].L0, 0.7, 1e-9);
  EXPECT_NEAR(flat.levels[2].Linf, 0.7, 1e-9);
}

TEST(ChargeFit, ReplicatesAreAccepted) {
  // Two aliquots per time with their own noise, sorted by time (equal times
  // side by side): the rate comes back, and exact copies change nothing.
  const Curve a = Growth(0.1, 2.0, 0.05, 100, 1.0, 0.01, 4), b = Growth(0.1, 2.0, 0.05, 100, 1.0, 0.01, 5);
  Curve both{{}, {{}}, {"value"}};
  for (std::size_t j = 0; j < a.size(); ++j)
    for (const Curve* copy : {&a, &b}) {
      both.t_s.push_back(copy->t_s[j]);
      both.channels[0].push_back(copy->channels[0][j]);
    }
  const ChargeFitSummary fit = FitCharge(both, {}, "both");
  EXPECT_NEAR(fit.rate, 0.05, 4 * fit.rate_stderr);
  EXPECT_LT(fit.rate_stderr, FitCharge(a, {}, "a").rate_stderr);
  Curve twice{{}, {{}}, {"value"}};
  for (std::size_t j = 0; j < a.size(); ++j)
    for (int r = 0; r < 2; ++r) {
      twice.t_s.push_back(a.t_s[j]);
      twice.channels[0].push_back(a.channels[0][j]);
    }
  const ChargeFitSummary once = FitCharge(a, {}, "once"), doubled = FitCharge(twice, {}, "twice");
  EXPECT_NEAR(doubled.rate, once.rate, 1e-9 * once.rate);
  EXPECT_NEAR(doubled.rss, 2 * once.rss, 1e-9 * once.rss);
}

TEST(ChargeFit, NegativeTimesAreAClearError) {
  // Once a crash: from t = -390 s, e^{-kt} overflows at the fastest scanned
  // rates, and ceres::Covariance crashed on the non-finite Jacobian.
  Curve curve{{}, {{}}, {"value"}};
  for (int j = 0; j < 61; ++j) {
    const double t = -389.848 + j * 1.48306;
    curve.t_s.push_back(t);
    curve.channels[0].push_back(5 - 4 * std::exp(-0.943978 * t));
  }
  try {
    FitCharge(curve, {}, "neg.csv");
    FAIL() << "negative times were fitted";
  } catch (const UserError& e) {
    EXPECT_NE(std::string(e.what()).find("neg.csv: t: sample 1 is at a negative time (-389.848 s)"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace phos
