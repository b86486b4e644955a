// Excitation fits (Sec. 8.4.6) against the closed form and against the
// model's own simulation of the charge-then-measure experiment.

#include "phos/fit/excitation_fit.h"

#include <cmath>
#include <gtest/gtest.h>
#include <random>

#include "phos/model/simulate.h"
#include "phos/util/error.h"
#include "test_util.h"

namespace phos {
namespace {

// The doubling schedule of charge times, 1 s to 512 s.
std::vector<ExcitationSample> Doubling(double a, double kr, double S, double delay, double exposure, double noise,
                                       unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> gauss(0, noise);
  std::vector<ExcitationSample> samples;
  for (double t = 1; t <= 512; t *= 2) {
    ExcitationSample s{t, delay, exposure, 0};
    s.value = ExcitationSignal(a, kr, S, s) * (1 + gauss(rng));
    samples.push_back(s);
  }
  return samples;
}

TEST(ExcitationFit, ExactDataGiveTheExcitationRate) {
  ExcitationFitOptions options;
  options.kr = 0.03;
  ExcitationFitSummary fit = FitExcitation(Doubling(0.05, 0.03, 1000, 0.5, 1.0, 0, 1), options, "exact");
  EXPECT_NEAR(fit.a, 0.05, 1e-8);
  EXPECT_NEAR(fit.scale, 1000, 1e-5);
}

TEST(ExcitationFit, RecoversKeFromTheModelsOwnExperiment) {
  // The experiment run by the model: charge green under one band at a time,
  // lights off, 0.5 s delay, a 1 s exposure integrated numerically.
  Material green = LoadMaterial(testing::Fixture("materials/green.json"));
  const double kr = green.states[0].kr;
  std::vector<std::vector<double>> lights;
  std::vector<double> rates;
  for (int band = 0; band < 3; ++band) {
    std::vector<double> E(8, 0.0);
    E[band] = 2.0;
    std::vector<ExcitationSample> samples;
    for (double t = 1; t <= 64; t *= 2) {
      SimulationOptions options;
      options.dt_s = 0.001;
      IrradianceSchedule schedule;
      schedule.Add(t, E, "charge");
      schedule.Add(1.5, std::vector<double>(8, 0.0), "dark");
      SimulationResult run = Simulate(green, schedule, options, "green");
      // Trapezoid over the exposure window [t + 0.5, t + 1.5] of the total emission.
      double integral = 0;
      for (std::size_t s = 1; s < run.sample_count(); ++s) {
        if (run.t_s[s - 1] < t + 0.5 - 1e-9 || run.t_s[s] > t + 1.5 + 1e-9) continue;
        double L0 = 0, L1 = 0;
        for (int b = 0; b < 8; ++b) {
          L0 += run.radiance(s - 1, b);
          L1 += run.radiance(s, b);
        }
        integral += 0.5 * (L0 + L1) * (run.t_s[s] - run.t_s[s - 1]);
      }
      samples.push_back({t, 0.5, 1.0, integral / 1.0});
    }
    ExcitationFitOptions options;
    options.kr = kr;
    ExcitationFitSummary fit = FitExcitation(samples, options, "green");
    EXPECT_NEAR(fit.a, *green.states[0].ke[band] * 2.0, 1e-4 * fit.a) << band;
    lights.push_back(E);
    rates.push_back(fit.a);
  }
  std::vector<std::optional<double>> ke = KeFromExcitationRates(lights, rates, "green");
  for (int band = 0; band < 3; ++band) {
    ASSERT_TRUE(ke[band].has_value());
    EXPECT_NEAR(*ke[band], *green.states[0].ke[band], 1e-4 * *ke[band]) << band;
  }
  for (int band = 3; band < 8; ++band) EXPECT_FALSE(ke[band].has_value()) << band;  // no light there: unknown
}

TEST(ExcitationFit, TheDelayMattersWhenTheSaturatedSignalIsKnown) {
  // The paper's main source of error: with S known, ignoring a 3 s delay
  // reads the decayed glow as a lower equilibrium and underestimates a.
  const double a = 0.02, kr = 0.05, S = 500;
  std::vector<ExcitationSample> samples = Doubling(a, kr, S, 3.0, 0.5, 0, 2);
  ExcitationFitOptions options;
  options.kr = kr;
  options.saturated_signal = S;
  EXPECT_NEAR(FitExcitation(samples, options, "with delay").a, a, 1e-7);
  for (ExcitationSample& s : samples) s.delay_s = 0;
  const double ignored = FitExcitation(samples, options, "no delay").a;
  EXPECT_LT(ignored, 0.9 * a);
}

TEST(ExcitationFit, LevelAndSpeedAreComparedAndDisagreementReported) {
  const double a = 0.02, kr = 0.05, S = 500;
  ExcitationFitOptions options;
  options.kr = kr;
  options.saturated_signal = S;
  ExcitationFitSummary agree = FitExcitation(Doubling(a, kr, S, 0.5, 0.5, 0.01, 3), options, "agree");
  ASSERT_TRUE(agree.a_from_level && agree.a_from_speed);
  EXPECT_NEAR(*agree.a_from_level, a, 0.05 * a);
  EXPECT_NEAR(*agree.a_from_speed, a, 0.05 * a);
  EXPECT_FALSE(agree.level_and_speed_disagree) << agree.note;
  options.saturated_signal = 1.6 * S;  // a wrong calibration of the saturated signal
  ExcitationFitSummary disagree = FitExcitation(Doubling(a, kr, S, 0.5, 0.5, 0.01, 3), options, "disagree");
  EXPECT_TRUE(disagree.level_and_speed_disagree);
  EXPECT_NE(disagree.note.find("the equilibrium level gives a ="), std::string::npos) << disagree.note;
}

TEST(KeFromExcitationRates, UnmixesLightsThatSpanSeveralBands) {
  // Broad lights (an LED bank, a lamp) each reach several bands.
  const std::vector<double> truth = {0.1, 0.035, 0.006};
  const std::vector<std::vector<double>> lights = {{1, 0.5, 0}, {0, 1, 1}, {1, 0, 1}, {0.2, 0.2, 0.2}};
  std::vector<double> rates;
  for (const auto& E : lights) rates.push_back(E[0] * truth[0] + E[1] * truth[1] + E[2] * truth[2]);
  std::vector<std::optional<double>> ke = KeFromExcitationRates(lights, rates, "mix");
  for (int b = 0; b < 3; ++b) EXPECT_NEAR(*ke[b], truth[b], 1e-9) << b;
}

TEST(ExcitationFit, BadSeriesAreClearErrors) {
  ExcitationFitOptions options;
  options.kr = 0.05;
  std::vector<ExcitationSample> two = {{1, 0, 0, 1}, {2, 0, 0, 2}};
  EXPECT_THROW(FitExcitation(two, options, "two"), UserError);
  std::vector<ExcitationSample> same = {{5, 0, 0, 1}, {5, 0, 0, 1.1}, {5, 0, 0, 0.9}};
  EXPECT_THROW(FitExcitation(same, options, "same"), UserError);
  std::vector<ExcitationSample> dark = {{1, 0, 0, 0}, {2, 0, 0, 0}, {4, 0, 0, 0}};
  EXPECT_THROW(FitExcitation(dark, options, "dark"), UserError);
  options.kr = 0;
  EXPECT_THROW(FitExcitation(Doubling(0.1, 0.05, 1, 0, 0, 0, 4), options, "kr"), UserError);
  EXPECT_THROW(KeFromExcitationRates({{1, 0}}, {0.1, 0.2}, "ke"), UserError);
}

}  // namespace
}  // namespace phos
