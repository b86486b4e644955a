// The curve fits do not depend on the units of the data or of the time: a
// curve in W/(sr m^2) (1e-9 and below), in DN (1e5) or in any unit between,
// timed in microseconds or in hours, is the same fit, its parameters in
// those units (curve.h: CurveScale). And what cannot be fitted in any unit
// is refused in one line, not fitted to garbage.

#include <cmath>
#include <functional>
#include <limits>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "phos/fit/charge_fit.h"
#include "phos/fit/decay_fit.h"
#include "phos/fit/decay_map.h"
#include "phos/util/error.h"
#include "solver_options.h"
#include "test_util.h"

namespace phos {
namespace {

std::string ErrorOf(const std::function<void()>& f) { return testing::ErrorOfType<UserError>(f); }

// Relative agreement, for parameters that must scale exactly (up to the
// rounding of the scaled inputs and the solvers' convergence tolerances).
::testing::AssertionResult Close(double actual, double expected, double rtol) {
  if (std::fabs(actual - expected) <= rtol * std::fabs(expected)) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << actual << " vs " << expected << " (relative "
                                       << std::fabs(actual - expected) / std::fabs(expected) << ")";
}

// The curve with its values times `value` and its times (and exposures)
// times `time`.
Curve InUnits(const Curve& curve, double value, double time) {
  Curve out = curve;
  for (double& t : out.t_s) t *= time;
  for (double& e : out.exposure_s) e *= time;
  for (auto& channel : out.channels)
    for (double& v : channel) v *= value;
  return out;
}

// A random decay: 1 to 3 components, rates 5 to 12 times apart inside what
// the samples resolve (from 3 per span), amplitudes over two decades per
// channel, 1 to 3 channels, a background in half of them, 1e4 counts at the
// peak with Poisson noise (Gaussian, of variance the mean) and per-sample
// exposures of 0.05 to 3 s in half of them.
struct RandomDecay {
  Curve curve;
  int components = 0;
  bool background = false;
};
RandomDecay MakeRandomDecay(std::mt19937& rng) {
  std::uniform_real_distribution<double> unit(0, 1);
  std::normal_distribution<double> gauss(0, 1);
  RandomDecay out;
  out.components = 1 + static_cast<int>(3 * unit(rng));
  const int channels = 1 + static_cast<int>(3 * unit(rng)), m = 150 + static_cast<int>(300 * unit(rng));
  const double dt = 0.02 + 0.2 * unit(rng), span = m * dt;
  std::vector<double> rates;
  for (double rate = (3 + 10 * unit(rng)) / span; static_cast<int>(rates.size()) < out.components;
       rate *= 5 + 7 * unit(rng))
    rates.push_back(rate);
  std::vector<std::vector<double>> amplitudes(channels);
  for (auto& a : amplitudes)
    for (int i = 0; i < out.components; ++i) a.push_back(1e4 * std::pow(10.0, -2 * unit(rng)));
  out.background = unit(rng) < 0.5;
  const double background = out.background ? 50 * unit(rng) : 0.0;
  const bool exposures = unit(rng) < 0.5;
  out.curve.channels.resize(channels);
  for (int c = 0; c < channels; ++c) out.curve.names.push_back("ch" + std::to_string(c));
  for (int j = 0; j < m; ++j) {
    const double t = j * dt;
    out.curve.t_s.push_back(t);
    if (exposures) out.curve.exposure_s.push_back(0.05 + 3 * unit(rng));
    for (int c = 0; c < channels; ++c) {
      double mean = background;
      for (int i = 0; i < out.components; ++i) mean += amplitudes[c][i] * std::exp(-rates[i] * t);
      out.curve.channels[c].push_back(mean + std::sqrt(mean + 1) * gauss(rng));
    }
  }
  return out;
}

void ExpectSameDecayFit(const DecayFitSummary& scaled, const DecayFitSummary& fit, double value, double time) {
  ASSERT_EQ(scaled.n_components, fit.n_components) << scaled.choice << " | " << fit.choice;
  EXPECT_EQ(scaled.choice, fit.choice);
  constexpr double kRtol = 1e-6;
  // Per channel, its level: amplitudes and a background near 0 (a component
  // the channel lacks) are compared against it, not against themselves.
  std::vector<double> level(fit.background.size(), 0.0);
  for (std::size_t c = 0; c < level.size(); ++c) {
    level[c] = std::fabs(fit.background[c]);
    for (const DecayComponent& b : fit.components) level[c] = std::max(level[c], b.amplitude[c]);
  }
  for (int i = 0; i < fit.n_components; ++i) {
    const DecayComponent &a = scaled.components[i], &b = fit.components[i];
    EXPECT_TRUE(Close(a.rate, b.rate / time, kRtol)) << "rate " << i;
    EXPECT_TRUE(Close(a.rate_stderr, b.rate_stderr / time, 1e-4)) << "rate stderr " << i;
    for (std::size_t c = 0; c < b.amplitude.size(); ++c) {
      EXPECT_NEAR(a.amplitude[c], b.amplitude[c] * value, kRtol * level[c] * value) << "amplitude " << i << " " << c;
      EXPECT_NEAR(a.amplitude_stderr[c], b.amplitude_stderr[c] * value, 1e-4 * b.amplitude_stderr[c] * value)
          << "amplitude stderr " << i << " " << c;
    }
  }
  for (std::size_t c = 0; c < fit.background.size(); ++c)
    EXPECT_NEAR(scaled.background[c], fit.background[c] * value, kRtol * level[c] * value) << "background " << c;
  EXPECT_TRUE(Close(scaled.rss, fit.rss * value * value, kRtol));
  for (std::size_t f = 0; f < fit.bic.size(); ++f)
    if (!std::isnan(fit.bic[f])) {  // differences between counts stay (the log of the unit is added to all)
      EXPECT_NEAR(scaled.bic[f] - scaled.bic[0], fit.bic[f] - fit.bic[0], 1e-6 * std::fabs(fit.bic[0])) << f;
    }
}

TEST(UnitEquivariance, DecayFitsScaleWithTheDataAndTheTime) {
  // Before the fits solved in scaled units, the objective was in the data's:
  // at 1e-9 its gradient fell below the absolute tolerances at once and BIC
  // chose 3 components for 2; at 1e200 its squares overflowed and the decay
  // was refused.
  std::mt19937 rng(2026);
  std::uniform_int_distribution<int> value_exponent(-30, 30), time_exponent(-6, 6);
  for (int trial = 0; trial < 60; ++trial) {
    const RandomDecay random = MakeRandomDecay(rng);
    DecayFitOptions options;
    options.background = random.background;
    options.weighting = trial % 2 == 0 ? Weighting::kNone : Weighting::kPoisson;
    options.amplitude_uncertainties = trial % 3 == 0;
    if (trial % 4 == 3) options.components = random.components;  // a fixed count as well as a chosen one
    const DecayFitSummary fit = FitDecay(random.curve, options, "random");
    // Random units, and the extremes of the range.
    const int k = trial < 2 ? (trial == 0 ? -30 : 30) : value_exponent(rng);
    const int j = trial < 2 ? (trial == 0 ? 6 : -6) : time_exponent(rng);
    const double value = std::pow(10.0, k), time = std::pow(10.0, j);
    SCOPED_TRACE("trial " + std::to_string(trial) + ": values x 1e" + std::to_string(k) + ", times x 1e" +
                 std::to_string(j) + ", " + WeightingName(options.weighting) + ", " + fit.choice);
    ExpectSameDecayFit(FitDecay(InUnits(random.curve, value, time), options, "scaled"), fit, value, time);
  }
}

TEST(UnitEquivariance, PoissonWeightedRssScalesWithTheValueAndTheExposure) {
  // What the fit minimized, in the data's units: sum (r / sqrt(value /
  // exposure))^2 scales as value / time.
  std::mt19937 rng(7);
  RandomDecay random = MakeRandomDecay(rng);
  while (random.curve.exposure_s.empty()) random = MakeRandomDecay(rng);
  DecayFitOptions options;
  options.weighting = Weighting::kPoisson;
  const DecayFitSummary fit = FitDecay(random.curve, options, "random");
  const DecayFitSummary scaled = FitDecay(InUnits(random.curve, 1e-9, 1e3), options, "scaled");
  EXPECT_TRUE(Close(scaled.weighted_rss, fit.weighted_rss * 1e-9 * 1e3, 1e-6));
}

Curve Growth(const std::vector<double>& L0, const std::vector<double>& Linf, double k, int m, double dt, double noise,
             std::mt19937& rng) {
  std::normal_distribution<double> gauss(0, noise);
  Curve curve;
  curve.channels.resize(L0.size());
  for (std::size_t c = 0; c < L0.size(); ++c) curve.names.push_back("ch" + std::to_string(c));
  for (int j = 0; j < m; ++j) {
    curve.t_s.push_back(j * dt);
    for (std::size_t c = 0; c < L0.size(); ++c)
      curve.channels[c].push_back(Linf[c] - (Linf[c] - L0[c]) * std::exp(-k * j * dt) + gauss(rng));
  }
  return curve;
}

TEST(UnitEquivariance, ChargeFitsScaleWithTheDataAndTheTime) {
  // Before: at 1e-100 the scan's determinants underflowed and it printed
  // "L0 0, Linf 0, rate 1 +- 0" with exit 0; at 1e160 the weights' squares
  // overflowed, Ceres gave up, and glog's lines reached the terminal.
  std::mt19937 rng(80);
  std::uniform_real_distribution<double> unit(0, 1);
  std::uniform_int_distribution<int> value_exponent(-30, 30), time_exponent(-6, 6);
  for (int trial = 0; trial < 60; ++trial) {
    const int channels = 1 + static_cast<int>(3 * unit(rng)), m = 40 + static_cast<int>(200 * unit(rng));
    const double dt = 0.05 + unit(rng), k = (2 + 20 * unit(rng)) / (m * dt);
    std::vector<double> L0, Linf;
    for (int c = 0; c < channels; ++c) {
      L0.push_back(std::pow(10.0, 2 * unit(rng) - 1) * unit(rng));
      Linf.push_back(std::pow(10.0, 2 * unit(rng)));
    }
    const Curve curve = Growth(L0, Linf, k, m, dt, 0.01 * unit(rng), rng);
    ChargeFitOptions options;
    options.weighting = trial % 2 == 0 ? Weighting::kNone : Weighting::kPoisson;
    const int kv = trial < 2 ? (trial == 0 ? -30 : 30) : value_exponent(rng);
    const int kt = trial < 2 ? (trial == 0 ? 6 : -6) : time_exponent(rng);
    const double value = std::pow(10.0, kv), time = std::pow(10.0, kt);
    SCOPED_TRACE("trial " + std::to_string(trial) + ": values x 1e" + std::to_string(kv) + ", times x 1e" +
                 std::to_string(kt) + ", " + WeightingName(options.weighting));
    const ChargeFitSummary fit = FitCharge(curve, options, "random");
    const ChargeFitSummary scaled = FitCharge(InUnits(curve, value, time), options, "scaled");
    EXPECT_TRUE(Close(scaled.rate, fit.rate / time, 1e-6));
    EXPECT_TRUE(Close(scaled.rate_stderr, fit.rate_stderr / time, 1e-4));
    ASSERT_EQ(scaled.levels.size(), fit.levels.size());
    for (int c = 0; c < channels; ++c) {
      EXPECT_TRUE(Close(scaled.levels[c].Linf, fit.levels[c].Linf * value, 1e-6)) << c;
      EXPECT_NEAR(scaled.levels[c].L0, fit.levels[c].L0 * value, 1e-6 * fit.levels[c].Linf * value) << c;
      EXPECT_TRUE(Close(scaled.levels[c].Linf_stderr, fit.levels[c].Linf_stderr * value, 1e-4)) << c;
    }
    EXPECT_TRUE(Close(scaled.rss, fit.rss * value * value, 1e-6));
  }
}

Curve Exponential(double amplitude, double rate, int m, double dt) {
  Curve curve{{}, {{}}, {"v"}};
  for (int j = 0; j < m; ++j) {
    curve.t_s.push_back(j * dt);
    curve.channels[0].push_back(amplitude * std::exp(-rate * j * dt));
  }
  return curve;
}

TEST(UnitEquivariance, ValuesWhoseSquaresOverflowOrUnderflowAreFitted) {
  // 1e200 squares to infinity and 1e-200 to 0: both were refused as "values
  // do not decrease". Only the rss, a square in the data's units, is out of
  // a double's range there.
  for (const double value : {1e200, 1e-200, 1e300, 1e-300}) {
    SCOPED_TRACE(value);
    const DecayFitSummary decay = FitDecay(Exponential(2 * value, 0.5, 100, 0.1), {}, "clean");
    ASSERT_EQ(decay.n_components, 1) << decay.choice;
    EXPECT_TRUE(Close(decay.components[0].rate, 0.5, 1e-9));
    EXPECT_TRUE(Close(decay.components[0].amplitude[0], 2 * value, 1e-9));
    Curve charge{{}, {{}}, {"v"}};
    for (int j = 0; j < 80; ++j) {
      charge.t_s.push_back(j);
      charge.channels[0].push_back(value * (3 - 2 * std::exp(-0.1 * j)));
    }
    const ChargeFitSummary fit = FitCharge(charge, {}, "clean");
    EXPECT_TRUE(Close(fit.rate, 0.1, 1e-9));
    EXPECT_TRUE(Close(fit.L0, value, 1e-9));
    EXPECT_TRUE(Close(fit.Linf, 3 * value, 1e-9));
  }
}

TEST(UnitEquivariance, WhatNoUnitMakesFittableIsRefusedInOneLine) {
  // All zeros: nothing decays or grows, in any unit.
  Curve zeros = Exponential(0, 0.5, 50, 0.1);
  EXPECT_EQ(ErrorOf([&] { FitDecay(zeros, {}, "zero.csv"); }),
            "zero.csv: every value is the same: there is no decay to fit");
  EXPECT_EQ(ErrorOf([&] { FitCharge(zeros, {}, "zero.csv"); }),
            "zero.csv: every value is the same: there is no growth to fit");
  // Subnormal values carry a few bits (none at 4.9e-324): scaled up they
  // would be a staircase, not a decay.
  const Curve subnormal = Exponential(1e-310, 0.5, 50, 0.1);
  const std::string expected =
      "tiny.csv: every |value| is at most 1e-310, below 2.2e-308 (the smallest normal double), too small to fit with "
      "precision: give the values in a smaller unit";
  EXPECT_EQ(ErrorOf([&] { FitDecay(subnormal, {}, "tiny.csv"); }), expected);
  EXPECT_EQ(ErrorOf([&] { FitCharge(subnormal, {}, "tiny.csv"); }), expected);
  // The smallest normal values are fitted.
  const DecayFitSummary smallest = FitDecay(Exponential(1e-306, 0.5, 50, 0.1), {}, "small.csv");
  EXPECT_TRUE(Close(smallest.components[0].rate, 0.5, 1e-9));
}

// A 16 x 6 stack, 2 channels: rate 0.01 to 0.04 /s left to right, amplitudes
// 3000 and 700 DN/s, background 2 DN/s, photon noise at 25 electrons per DN,
// exposures growing as in the decay protocol, in signal per second.
DecayMapInput Stack(double value, double time) {
  DecayMapInput in;
  in.width = 16;
  in.height = 6;
  in.channels = 2;
  std::mt19937_64 rng(5);
  const double amplitude[2] = {3000, 700};
  for (int j = 0; j < 30; ++j) {
    const double e = std::min(4.0, 0.05 * std::pow(2.0, j / 4)), start = 0.005 + 5.0 * j;
    in.t_s.push_back((start + e / 2) * time);
    in.exposure_s.push_back(e * time);
    std::vector<float> frame(static_cast<std::size_t>(in.width) * in.height * in.channels);
    for (int y = 0; y < in.height; ++y)
      for (int x = 0; x < in.width; ++x) {
        const double k = 0.01 * (1 + x / 5.0);
        for (int c = 0; c < in.channels; ++c) {
          const double mean = amplitude[c] * std::exp(-k * start) * -std::expm1(-k * e) / k + 2 * e;
          std::poisson_distribution<long long> counts(25 * mean);
          frame[(static_cast<std::size_t>(y) * in.width + x) * in.channels + c] =
              static_cast<float>(counts(rng) / 25.0 / e * value / time);
        }
      }
    in.frames.push_back(std::move(frame));
  }
  return in;
}

TEST(UnitEquivariance, DecayMapsScaleWithTheDataAndTheTime) {
  // The Poisson weights' floor was a thousandth of the pixel's peak but at
  // least 1e-12: radiances below that were weighted as if all equal. The
  // stack's values are floats, so they agree to float rounding.
  for (const int states : {1, 2}) {
    DecayMapOptions options;
    options.states = states;
    const DecayMap fit = FitDecayMap(Stack(1, 1), options, "stack");
    for (const auto& [k, j] : {std::pair{-9, 0}, {-15, 0}, {-30, 3}, {6, -3}, {0, 6}}) {
      const double value = std::pow(10.0, k), time = std::pow(10.0, j);
      SCOPED_TRACE(std::to_string(states) + " states, values x 1e" + std::to_string(k) + ", times x 1e" +
                   std::to_string(j));
      const DecayMap scaled = FitDecayMap(Stack(value, time), options, "scaled");
      ASSERT_EQ(scaled.no_decay, fit.no_decay);
      ASSERT_EQ(scaled.one_state, fit.one_state);
      for (std::size_t p = 0; p < fit.kr.size(); ++p) {
        EXPECT_TRUE(Close(scaled.kr[p], fit.kr[p] / time, 1e-4)) << "pixel " << p;
        if (states == 2 && !std::isnan(fit.kr2[p])) {
          EXPECT_TRUE(Close(scaled.kr2[p], fit.kr2[p] / time, 1e-4)) << "pixel " << p;
        }
        for (int c = 0; c < fit.channels; ++c) {
          const std::size_t i = p * fit.channels + c;
          EXPECT_TRUE(Close(scaled.amplitude[i], fit.amplitude[i] * value / time, 1e-4)) << "pixel " << p;
          EXPECT_NEAR(scaled.background[i], fit.background[i] * value / time, 1e-4 * fit.amplitude[i] * value / time)
              << "pixel " << p;
        }
      }
    }
  }
}

TEST(UnitEquivariance, CeresNeverWritesToTheTerminal) {
  // A residual that is not finite (as the charge fit's were, with weights
  // of 1e160 squared): Ceres gives up and says why through glog, which wrote
  // "WARNING: Logging before InitGoogleLogging()" and a page of lines to
  // stderr under phos's own message.
  struct Invalid final : public ceres::CostFunction {
    Invalid() {
      set_num_residuals(1);
      mutable_parameter_block_sizes()->push_back(1);
    }
    bool Evaluate(double const* const*, double* residuals, double** jacobians) const override {
      residuals[0] = std::numeric_limits<double>::quiet_NaN();
      if (jacobians != nullptr && jacobians[0] != nullptr) jacobians[0][0] = 1;
      return true;
    }
  };
  double x = 1;
  ceres::Problem problem;
  problem.AddResidualBlock(new Invalid, nullptr, &x);
  ceres::Solver::Summary summary;
  ::testing::internal::CaptureStdout();
  ::testing::internal::CaptureStderr();
  ceres::Solve(SmallDenseSolverOptions(100, 1e-10), &problem, &summary);
  const std::string out = ::testing::internal::GetCapturedStdout(), err = ::testing::internal::GetCapturedStderr();
  EXPECT_EQ(summary.termination_type, ceres::FAILURE) << summary.message;
  EXPECT_EQ(out, "");
  EXPECT_EQ(err, "");
}

}  // namespace
}  // namespace phos
