// Decay fits against curves whose parameters are known, and the statistics
// of their uncertainties.

#include "phos/fit/decay_fit.h"

#include <cmath>
#include <functional>
#include <gtest/gtest.h>
#include <random>

#include "phos/util/error.h"
#include "test_util.h"

namespace phos {
namespace {

struct Truth {
  std::vector<double> rates;                    // 1/s
  std::vector<std::vector<double>> amplitudes;  // [channel][component]
  double background = 0;
};

Curve Synthesize(const Truth& truth, int points, double dt, double noise, unsigned seed, bool poisson = false) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> gauss(0, noise);
  Curve curve;
  curve.channels.resize(truth.amplitudes.size());
  for (std::size_t c = 0; c < truth.amplitudes.size(); ++c) curve.names.push_back("ch" + std::to_string(c));
  for (int j = 0; j < points; ++j) {
    const double t = j * dt;
    curve.t_s.push_back(t);
    for (std::size_t c = 0; c < truth.amplitudes.size(); ++c) {
      double mean = truth.background;
      for (std::size_t i = 0; i < truth.rates.size(); ++i) mean += truth.amplitudes[c][i] * std::exp(-truth.rates[i] * t);
      double value = mean + gauss(rng);
      if (poisson) value = static_cast<double>(std::poisson_distribution<long>(mean)(rng));
      curve.channels[c].push_back(value);
    }
  }
  return curve;
}

std::string ErrorOf(const std::function<void()>& f) { return testing::ErrorOfType<UserError>(f); }

TEST(DecayFit, ExactDataGiveExactParameters) {
  Truth truth{{2.0, 0.3, 0.02}, {{1000, 300, 50}}};
  DecayFitOptions options;
  options.components = 3;
  DecayFitSummary fit = FitDecay(Synthesize(truth, 1000, 0.05, 0, 1), options, "exact");
  ASSERT_EQ(fit.n_components, 3);
  for (int i = 0; i < 3; ++i) {  // fastest first
    EXPECT_NEAR(fit.components[i].rate, truth.rates[i], 1e-6 * truth.rates[i]);
    EXPECT_NEAR(fit.components[i].amplitude[0], truth.amplitudes[0][i], 1e-6 * truth.amplitudes[0][i]);
  }
  EXPECT_LT(fit.rss, 1e-12);
}

TEST(DecayFit, NoisyRatesLandWithinTheirUncertainty) {
  Truth truth{{2.0, 0.3, 0.02}, {{1000, 300, 50}}};
  DecayFitOptions options;
  options.components = 3;
  options.amplitude_uncertainties = true;
  DecayFitSummary fit = FitDecay(Synthesize(truth, 1000, 0.05, 1.0, 2), options, "noisy");
  for (int i = 0; i < 3; ++i) {
    const DecayComponent& k = fit.components[i];
    EXPECT_GT(k.rate_stderr, 0);
    EXPECT_LT(k.rate_stderr, 0.05 * k.rate);
    EXPECT_NEAR(k.rate, truth.rates[i], 4 * k.rate_stderr);
    EXPECT_GT(k.amplitude_stderr[0], 0);
    EXPECT_NEAR(k.amplitude[0], truth.amplitudes[0][i], 4 * k.amplitude_stderr[0]);
  }
  // rss is the plain sum of squares: about one noise variance per sample.
  EXPECT_NEAR(fit.rss / 1000, 1.0, 0.15);
}

TEST(DecayFit, OneSigmaCoversTheTruthTwoThirdsOfTheTime) {
  // 200 independent noisy curves: |k - k_true| < stderr should hold for
  // about 68% of them if the uncertainties are calibrated.
  Truth truth{{0.5, 0.05}, {{100, 40}}};
  DecayFitOptions options;
  options.components = 2;
  int covered = 0;
  const int trials = 200;
  for (int trial = 0; trial < trials; ++trial) {
    DecayFitSummary fit = FitDecay(Synthesize(truth, 200, 0.25, 0.5, 100 + trial), options, "trial");
    covered += std::fabs(fit.components[1].rate - 0.05) < fit.components[1].rate_stderr;
  }
  EXPECT_NEAR(static_cast<double>(covered) / trials, 0.683, 0.08);
}

TEST(DecayFit, BicChoosesTheTrueNumberOfComponents) {
  const std::vector<Truth> truths = {
      {{0.4}, {{500}}},
      {{1.5, 0.1}, {{500, 200}}},
      {{3.0, 0.4, 0.03}, {{800, 300, 60}}},
  };
  DecayFitOptions options;
  options.max_components = 4;
  for (std::size_t n = 0; n < truths.size(); ++n) {
    DecayFitSummary fit = FitDecay(Synthesize(truths[n], 600, 0.1, 0.5, 7), options, "bic");
    EXPECT_EQ(fit.n_components, static_cast<int>(n + 1)) << fit.choice;
    EXPECT_EQ(fit.bic.size(), 4u);
  }
}

TEST(DecayFit, ChannelsShareRatesAndKeepTheirOwnAmplitudes) {
  Truth truth{{1.0, 0.08}, {{300, 100}, {50, 200}, {10, 0}}};  // the blue channel lacks the slow component
  DecayFitOptions options;
  options.components = 2;
  DecayFitSummary fit = FitDecay(Synthesize(truth, 400, 0.1, 0.3, 3), options, "rgb");
  ASSERT_EQ(fit.components[0].amplitude.size(), 3u);
  EXPECT_NEAR(fit.components[0].rate, 1.0, 0.02);
  EXPECT_NEAR(fit.components[1].rate, 0.08, 0.002);
  EXPECT_NEAR(fit.components[1].amplitude[1], 200, 3);
  for (const DecayComponent& k : fit.components)
    for (double a : k.amplitude) EXPECT_GE(a, 0.0);  // never negative, even where the truth is 0
}

TEST(DecayFit, BackgroundIsFittedWhenAskedAndHurtsWhenIgnored) {
  Truth truth{{0.2}, {{400}}, 100.0};
  Curve curve = Synthesize(truth, 300, 0.2, 0.5, 4);
  DecayFitOptions options;
  options.components = 1;
  options.background = true;
  DecayFitSummary with = FitDecay(curve, options, "bg");
  EXPECT_NEAR(with.background[0], 100, 1.0);
  EXPECT_NEAR(with.components[0].rate, 0.2, 0.003);
  options.background = false;
  DecayFitSummary without = FitDecay(curve, options, "bg");
  EXPECT_GT(without.rss, 10 * with.rss);
}

TEST(DecayFit, PoissonWeightsFitPhotonCounts) {
  // Counts from a Poisson process: weighting by 1/sqrt(counts) makes the
  // weighted residuals unit-variance (reduced chi-square near 1) and the rate
  // more precise than with equal weights, on average over curves.
  Truth truth{{0.3}, {{5000}}, 5.0};
  double weighted_error = 0, plain_error = 0, chi2 = 0;
  const int trials = 40;
  for (int trial = 0; trial < trials; ++trial) {
    Curve curve = Synthesize(truth, 200, 0.1, 0, 500 + trial, true);
    DecayFitOptions options;
    options.components = 1;
    options.background = true;
    options.weighting = Weighting::kPoisson;
    DecayFitSummary weighted = FitDecay(curve, options, "poisson");
    options.weighting = Weighting::kNone;
    DecayFitSummary plain = FitDecay(curve, options, "poisson");
    weighted_error += std::pow(weighted.components[0].rate - 0.3, 2);
    plain_error += std::pow(plain.components[0].rate - 0.3, 2);
    chi2 += weighted.weighted_rss / (200 - 3);
  }
  EXPECT_LT(weighted_error, plain_error);
  EXPECT_NEAR(chi2 / trials, 1.0, 0.15);
}

TEST(DecayFit, BadCurvesAreClearErrors) {
  DecayFitOptions options;
  Curve curve;
  curve.names = {"v"};
  curve.channels = {};
  EXPECT_EQ(ErrorOf([&] { FitDecay(curve, options, "none.csv"); }), "none.csv: no value column (expected t,value[,value...])");
  curve.channels = {{}};
  EXPECT_EQ(ErrorOf([&] { FitDecay(curve, options, "e.csv"); }), "e.csv: has 0 samples; this fit needs at least 7");
  curve.t_s = {0};
  curve.channels = {{5}};
  EXPECT_EQ(ErrorOf([&] { FitDecay(curve, options, "one.csv"); }), "one.csv: has 1 sample; this fit needs at least 7");
  for (int j = 0; j < 20; ++j) {
    curve.t_s.push_back(j + 1);
    curve.channels[0].push_back(5);
  }
  EXPECT_EQ(ErrorOf([&] { FitDecay(curve, options, "flat.csv"); }),
            "flat.csv: every value is the same: there is no decay to fit");
  for (int j = 0; j < 21; ++j) curve.channels[0][j] = j;  // rising
  EXPECT_EQ(ErrorOf([&] { FitDecay(curve, options, "up.csv"); }),
            "up.csv: no decaying component: the values do not decrease over time (beyond their scatter)");
  curve.t_s[5] = curve.t_s[4];
  EXPECT_EQ(ErrorOf([&] { FitDecay(curve, options, "t.csv"); }),
            "t.csv: t: times must increase strictly (4 follows 4 at sample 6)");
  curve.t_s[5] = 4.5;
  curve.channels[0][3] = std::nan("");
  EXPECT_EQ(ErrorOf([&] { FitDecay(curve, options, "nan.csv"); }), "nan.csv: v: sample 4 is not finite");
  options.components = 7;
  EXPECT_THROW(FitDecay(curve, options, "x"), UserError);
}

}  // namespace
}  // namespace phos
