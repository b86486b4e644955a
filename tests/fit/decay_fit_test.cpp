// Decay fits against curves whose parameters are known, and the statistics
// of their uncertainties.

#include "phos/fit/decay_fit.h"

#include <cmath>
#include <algorithm>
#include <functional>
#include <optional>
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
      for (std::size_t i = 0; i < truth.rates.size(); ++i)
        mean += truth.amplitudes[c][i] * std::exp(-truth.rates[i] * t);
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

// A random curve whose count is identifiable: 1 to 3 components with rates
// at least 5x apart inside what the samples resolve, each with a share of
// the signal well above the noise. Half of them have a background.
struct RandomCurve {
  Truth truth;
  Curve curve;
  bool background = false;
};
RandomCurve MakeRandomCurve(std::mt19937& rng) {
  std::uniform_int_distribution<int> count(1, 3), points(200, 1000);
  std::uniform_real_distribution<double> unit(0, 1);
  RandomCurve out;
  const int nc = count(rng), m = points(rng);
  const double dt = 0.02 + 0.1 * unit(rng), span = m * dt;
  // Slowest first: its decay shows within the span; each next one 5-12x faster.
  double rate = (3 + 10 * unit(rng)) / span;
  std::vector<double> rates, amplitudes;
  for (int i = 0; i < nc; ++i) {
    rates.push_back(rate);
    amplitudes.push_back(200 + 800 * unit(rng));
    rate *= 5 + 7 * unit(rng);
  }
  out.truth = {rates, {amplitudes}, unit(rng) < 0.5 ? 0.0 : 20 + 80 * unit(rng)};
  out.background = out.truth.background > 0;
  out.curve = Synthesize(out.truth, m, dt, 1 + 4 * unit(rng), rng());
  return out;
}

TEST(DecayFit, BicChoosesTheTrueCountOnRandomCurves) {
  std::mt19937 rng(17);
  for (int trial = 0; trial < 40; ++trial) {
    const RandomCurve random = MakeRandomCurve(rng);
    DecayFitOptions options;
    options.background = random.background;
    const DecayFitSummary fit = FitDecay(random.curve, options, "random");
    EXPECT_EQ(fit.n_components, static_cast<int>(random.truth.rates.size())) << "trial " << trial << ": " << fit.choice;
  }
}

// Every fit on random curves converges at the default limit, by our own
// refinement and by Ceres's; cut to one iteration, the same fits say they
// did not, with the reason.
TEST(DecayFit, SaysWhetherItConverged) {
  std::mt19937 rng(23);
  for (int trial = 0; trial < 20; ++trial) {
    const RandomCurve random = MakeRandomCurve(rng);
    DecayFitOptions options;
    options.background = random.background;
    EXPECT_TRUE(FitDecay(random.curve, options, "random").converged) << trial;
    EXPECT_TRUE(FitDecayReference(random.curve, options, "random").converged) << trial;
    options.max_iterations = 1;
    const DecayFitSummary cut = FitDecay(random.curve, options, "random");
    EXPECT_FALSE(cut.converged) << trial;
    EXPECT_NE(cut.termination.find("max_iterations"), std::string::npos) << cut.termination;
    EXPECT_FALSE(FitDecayReference(random.curve, options, "random").converged) << trial;
  }
}

TEST(DecayFit, FastRefinementIsNeverWorseThanCeres) {
  // FitDecay's own Newton/Levenberg-Marquardt and covariance against the
  // same fit refined by Ceres (FitDecayReference), at every count and with
  // the count chosen. Where FitDecay's fit is sound (no warning: every
  // component present, rates distinct), its residual is never higher
  // (beyond 1e-9 relative, the convergence tolerance's order); where the
  // reference's is sound too and the two found the same minimum, the rates
  // and their uncertainties agree. A count forced above the truth collapses
  // two rates or empties a component in both; there the two land at
  // different points of a flat valley, within 1% of each other's residual.
  std::mt19937 rng(1717);
  int sound = 0;
  for (int trial = 0; trial < 25; ++trial) {
    const RandomCurve random = MakeRandomCurve(rng);
    for (int nc = 0; nc <= 3; ++nc) {
      DecayFitOptions options;
      options.components = nc;
      options.background = random.background;
      const DecayFitSummary fast = FitDecay(random.curve, options, "random");
      const DecayFitSummary reference = FitDecayReference(random.curve, options, "random");
      SCOPED_TRACE("trial " + std::to_string(trial) + ", components " + std::to_string(nc) + ": " + fast.choice);
      ASSERT_EQ(fast.n_components, reference.n_components);
      EXPECT_LE(fast.rss, reference.rss * 1.01);
      if (fast.choice.find("warning") != std::string::npos) continue;
      EXPECT_LE(fast.rss, reference.rss * (1 + 1e-9));
      if (reference.choice.find("warning") != std::string::npos) continue;  // the reference's own fit is unsound
      if (fast.rss < reference.rss * (1 - 1e-9)) continue;                  // a better minimum than the reference's
      ++sound;
      for (int i = 0; i < fast.n_components; ++i) {
        // Converged to the same point: far closer than the rate's own
        // uncertainty, which both compute alike.
        EXPECT_NEAR(fast.components[i].rate, reference.components[i].rate, 0.01 * reference.components[i].rate_stderr);
        // A rate less certain than itself lies in a flat valley (a count
        // forced above the truth whose rates stayed 2% apart): its covariance
        // is near singular, and two points of the valley differ in it.
        if (reference.components[i].rate_stderr > reference.components[i].rate) continue;
        EXPECT_NEAR(fast.components[i].rate_stderr, reference.components[i].rate_stderr,
                    0.01 * reference.components[i].rate_stderr);
      }
    }
  }
  EXPECT_GE(sound, 50);  // of 100: the comparison above is not vacuous
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
  EXPECT_EQ(ErrorOf([&] { FitDecay(curve, options, "none.csv"); }),
            "none.csv: no value column (expected t,value[,value...])");
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
  curve.t_s[5] = curve.t_s[3];
  EXPECT_EQ(ErrorOf([&] { FitDecay(curve, options, "t.csv"); }),
            "t.csv: t: times must not decrease (3 follows 4 at sample 6): sort the samples by time first");
  curve.t_s[5] = curve.t_s[4];  // a replicate of sample 5: accepted (the curve still rises)
  EXPECT_EQ(ErrorOf([&] { FitDecay(curve, options, "up.csv"); }),
            "up.csv: no decaying component: the values do not decrease over time (beyond their scatter)");
  curve.t_s[0] = -0.5;
  EXPECT_EQ(ErrorOf([&] { FitDecay(curve, options, "neg.csv"); }),
            "neg.csv: t: sample 1 is at a negative time (-0.5 s); time counts from the start of the charge or the "
            "decay (keep t >= 0, e.g. with --from 0)");
  curve.t_s[0] = 0;
  curve.t_s[5] = 4.5;
  curve.channels[0][3] = std::nan("");
  EXPECT_EQ(ErrorOf([&] { FitDecay(curve, options, "nan.csv"); }), "nan.csv: v: sample 4 is not finite");
  options.components = 7;
  EXPECT_THROW(FitDecay(curve, options, "x"), UserError);
}

// Every sample of `curve` `copies` times, each copy with its own noise.
Curve WithReplicates(const Truth& truth, int points, double dt, int copies, double noise, unsigned seed) {
  Curve curve;
  for (int r = 0; r < copies; ++r) {
    const Curve copy = Synthesize(truth, points, dt, noise, seed + r);
    if (curve.channels.empty()) {
      curve.channels.resize(copy.channels.size());
      curve.names = copy.names;
    }
    curve.t_s.insert(curve.t_s.end(), copy.t_s.begin(), copy.t_s.end());
    for (std::size_t c = 0; c < copy.channels.size(); ++c)
      curve.channels[c].insert(curve.channels[c].end(), copy.channels[c].begin(), copy.channels[c].end());
  }
  return curve;
}

TEST(DecayFit, ReplicatesAreAccepted) {
  Truth truth{{0.8, 0.05}, {{300, 100}}};
  DecayFitOptions options;
  options.components = 2;
  // Exact copies: every residual counts twice, so the minimum is where it was
  // and the rss doubles.
  Curve once = Synthesize(truth, 40, 1.0, 1.0, 5);
  Curve twice = once;
  twice.t_s.insert(twice.t_s.end(), once.t_s.begin(), once.t_s.end());
  twice.channels[0].insert(twice.channels[0].end(), once.channels[0].begin(), once.channels[0].end());
  const TimeOrder order = SortByTime(&twice, "twice");
  EXPECT_TRUE(order.reordered);
  EXPECT_EQ(order.samples, 80u);
  EXPECT_EQ(order.distinct_times, 40u);
  EXPECT_EQ(order.repeated_times, 40u);
  const DecayFitSummary a = FitDecay(once, options, "once"), b = FitDecay(twice, options, "twice");
  for (int i = 0; i < 2; ++i) {
    EXPECT_NEAR(b.components[i].rate, a.components[i].rate, 1e-7 * a.components[i].rate);
    EXPECT_NEAR(b.components[i].amplitude[0], a.components[i].amplitude[0], 1e-6 * a.components[i].amplitude[0]);
  }
  EXPECT_NEAR(b.rss, 2 * a.rss, 1e-8 * a.rss);
  // Three aliquots with their own noise: the rates come back within their
  // (smaller) uncertainty, and replicates are not a time step (the scanned
  // rates stay finite).
  Curve aliquots = WithReplicates(truth, 40, 1.0, 3, 1.0, 7);
  SortByTime(&aliquots, "aliquots");
  EXPECT_EQ(SmallestTimeStep(aliquots), 1.0);
  options.components = 0;
  const DecayFitSummary fit = FitDecay(aliquots, options, "aliquots");
  ASSERT_EQ(fit.n_components, 2) << fit.choice;
  for (int i = 0; i < 2; ++i) {
    EXPECT_NEAR(fit.components[i].rate, truth.rates[i], 4 * fit.components[i].rate_stderr);
    EXPECT_LT(fit.components[i].rate_stderr, 0.02 * truth.rates[i]);
  }
  // Exact replicates give the exact rates.
  Curve exact = WithReplicates(truth, 40, 1.0, 3, 0.0, 7);
  SortByTime(&exact, "exact");
  const DecayFitSummary e = FitDecay(exact, options, "exact");
  for (int i = 0; i < 2; ++i) EXPECT_NEAR(e.components[i].rate, truth.rates[i], 1e-6 * truth.rates[i]);
}

TEST(DecayFit, ShuffledSamplesSortedGiveTheSortedFit) {
  Truth truth{{1.2, 0.07}, {{400, 150}}};
  const Curve sorted = WithReplicates(truth, 60, 0.5, 2, 0.5, 21);
  Curve ordered = sorted, shuffled = sorted;
  SortByTime(&ordered, "ordered");
  std::vector<std::size_t> index(shuffled.size());
  for (std::size_t j = 0; j < index.size(); ++j) index[j] = j;
  std::shuffle(index.begin(), index.end(), std::mt19937(3));
  for (std::size_t j = 0; j < index.size(); ++j) {
    shuffled.t_s[j] = sorted.t_s[index[j]];
    shuffled.channels[0][j] = sorted.channels[0][index[j]];
  }
  EXPECT_TRUE(SortByTime(&shuffled, "shuffled").reordered);
  EXPECT_TRUE(std::is_sorted(shuffled.t_s.begin(), shuffled.t_s.end()));
  // Each time holds the same values (replicates may differ in order).
  const DecayFitSummary a = FitDecay(ordered, {}, "ordered"), b = FitDecay(shuffled, {}, "shuffled");
  ASSERT_EQ(a.n_components, b.n_components);
  for (int i = 0; i < a.n_components; ++i)
    EXPECT_NEAR(a.components[i].rate, b.components[i].rate, 1e-9 * a.components[i].rate);
  EXPECT_NEAR(a.rss, b.rss, 1e-9 * a.rss);
}

TEST(DecayFit, TooFewDistinctTimesAreAnError) {
  Curve curve{{0, 0, 0, 1, 1, 1, 2, 2, 2, 3}, {{9, 9.1, 8.9, 5, 5.1, 4.9, 3, 3.1, 2.9, 2}}, {"v"}};
  DecayFitOptions options;
  options.components = 2;  // 4 parameters: 5 distinct times needed
  EXPECT_EQ(ErrorOf([&] { FitDecay(curve, options, "few.csv"); }),
            "few.csv: t: has 10 samples at only 4 distinct times; this fit needs at least 5");
}

TEST(CurveWindow, KeepsTheInclusiveWindow) {
  Curve curve{{0, 1, 2, 2, 3, 4}, {{6, 5, 4, 4.1, 3, 2}}, {"v"}, {1, 1, 1, 1, 1, 2}};
  KeepTimeWindow(&curve, 1, 3);
  EXPECT_EQ(curve.t_s, (std::vector<double>{1, 2, 2, 3}));
  EXPECT_EQ(curve.channels[0], (std::vector<double>{5, 4, 4.1, 3}));
  EXPECT_EQ(curve.exposure_s.size(), 4u);
}

TEST(PeakAfterRise, FindsTheChargeBeforeTheDecay) {
  std::mt19937 rng(4);
  std::normal_distribution<double> noise(0, 1);
  Curve both{{}, {{}}, {"L"}};
  for (int j = 0; j <= 150; ++j) {
    const double t = j, peak = 500 * (1 - std::exp(-0.05 * 60));
    both.t_s.push_back(t);
    both.channels[0].push_back((t <= 60 ? 500 * (1 - std::exp(-0.05 * t)) : peak * std::exp(-0.05 * (t - 60))) +
                               noise(rng));
  }
  const std::optional<double> peak = PeakAfterRise(both);
  ASSERT_TRUE(peak.has_value());
  EXPECT_NEAR(*peak, 60, 3);
  // From the peak on it is a decay; a decay (noisy, with replicates, or with
  // several channels) never warns.
  KeepTimeWindow(&both, 60, 150);
  EXPECT_FALSE(PeakAfterRise(both).has_value());
  for (unsigned seed = 1; seed <= 20; ++seed) {
    Curve decay = WithReplicates(Truth{{1.2, 0.07}, {{400, 150}, {50, 20}}}, 100, 0.2, 2, 2.0, seed);
    SortByTime(&decay, "decay");
    EXPECT_FALSE(PeakAfterRise(decay).has_value()) << seed;
  }
  // A charge alone only rises: it is not a charge before a decay.
  Curve charge{{}, {{}}, {"L"}};
  for (int j = 0; j < 60; ++j) {
    charge.t_s.push_back(j);
    charge.channels[0].push_back(500 * (1 - std::exp(-0.05 * j)));
  }
  EXPECT_FALSE(PeakAfterRise(charge).has_value());
}

}  // namespace
}  // namespace phos
