// Per-pixel decay maps against two independent truths: the rates a
// synthetic, noisy image stack was made with, and FitDecay (the curve fit,
// a different method) run on single pixels of the same stack.

#include "phos/fit/decay_map.h"

#include <algorithm>
#include <cmath>
#include <gtest/gtest.h>
#include <random>

#include "phos/fit/decay_fit.h"
#include "phos/util/error.h"

namespace phos {
namespace {

// A 40 x 30 stack, 3 channels: rate k(x) = 0.01 * (1 + x / 10) rising left to
// right, amplitudes 3000/1200/800 DN/s, background 2 DN/s, photon noise at
// 25 electrons per DN, exposures growing as in the decay protocol.
DecayMapInput Stack(unsigned seed) {
  DecayMapInput in;
  in.width = 40;
  in.height = 30;
  in.channels = 3;
  std::mt19937_64 rng(seed);
  const double amplitude[3] = {3000, 1200, 800};
  for (int j = 0; j < 36; ++j) {
    const double e = std::min(4.0, 0.05 * std::pow(2.0, j / 4));
    const double start = 0.005 + 5.0 * j;
    in.t_s.push_back(start + e / 2);
    in.exposure_s.push_back(e);
    std::vector<float> frame(static_cast<std::size_t>(in.width) * in.height * 3);
    for (int y = 0; y < in.height; ++y)
      for (int x = 0; x < in.width; ++x) {
        const double k = 0.01 * (1 + x / 10.0);
        for (int c = 0; c < 3; ++c) {
          // Counts over the exposure: the exact integral of A exp(-k t) + B.
          const double mean = amplitude[c] * std::exp(-k * start) * -std::expm1(-k * e) / k + 2 * e;
          std::poisson_distribution<long long> counts(25 * mean);
          frame[(static_cast<std::size_t>(y) * in.width + x) * 3 + c] = static_cast<float>(counts(rng) / 25.0 / e);
        }
      }
    in.frames.push_back(std::move(frame));
  }
  return in;
}

TEST(DecayMap, RecoversEveryPixelsRateAndAgreesWithTheCurveFit) {
  const DecayMapInput in = Stack(3);
  std::size_t rows = 0;
  const DecayMap map =
      FitDecayMap(in, DecayMapOptions{}, "stack", [&](std::size_t done) { rows = std::max(rows, done); });
  EXPECT_EQ(rows, 30u);
  EXPECT_EQ(map.no_decay, 0u);
  double worst = 0;
  for (int y = 0; y < in.height; ++y)
    for (int x = 0; x < in.width; ++x) {
      const double k = 0.01 * (1 + x / 10.0);
      worst = std::max(worst, std::fabs(map.kr[y * in.width + x] - k) / k);
    }
  EXPECT_LT(worst, 0.03);  // photon noise of single pixels

  // The same pixels through FitDecay (grid scan + Ceres, a different method).
  for (int x : {0, 17, 39}) {
    const int y = 11;
    Curve curve;
    curve.channels.resize(3);
    curve.names = {"R", "G", "B"};
    curve.t_s = in.t_s;
    curve.exposure_s = in.exposure_s;
    for (std::size_t j = 0; j < in.frames.size(); ++j) {
      const double ke = 0.01 * (1 + x / 10.0) * in.exposure_s[j] / 2;  // the exposure factor, at the true rate
      for (int c = 0; c < 3; ++c)
        curve.channels[c].push_back(in.frames[j][(static_cast<std::size_t>(y) * in.width + x) * 3 + c] /
                                    (std::sinh(ke) / ke));
    }
    DecayFitOptions options;
    options.components = 1;
    options.background = true;
    options.weighting = Weighting::kPoisson;
    const DecayFitSummary fit = FitDecay(curve, options, "pixel");
    EXPECT_NEAR(map.kr[y * in.width + x], fit.components[0].rate, 0.002 * fit.components[0].rate) << "x " << x;
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(map.amplitude[(y * in.width + x) * 3 + c], fit.components[0].amplitude[c],
                  0.01 * fit.components[0].amplitude[c]);
  }
}

TEST(DecayMap, APixelThatDoesNotDecayIsSaidAndBadStacksAreRefused) {
  DecayMapInput in = Stack(5);
  for (auto& frame : in.frames) frame[0] = frame[1] = frame[2] = 7.0f;  // pixel (0, 0): constant
  const DecayMap map = FitDecayMap(in, DecayMapOptions{}, "stack");
  EXPECT_TRUE(std::isnan(map.kr[0]));
  EXPECT_EQ(map.no_decay, 1u);
  EXPECT_NEAR(map.background[0], 7.0, 1e-3);

  DecayMapInput short_stack = in;
  short_stack.frames.resize(2);
  short_stack.t_s.resize(2);
  short_stack.exposure_s.resize(2);
  EXPECT_THROW(FitDecayMap(short_stack, DecayMapOptions{}, "stack"), UserError);
  DecayMapInput ragged = in;
  ragged.frames[4].pop_back();
  EXPECT_THROW(FitDecayMap(ragged, DecayMapOptions{}, "stack"), UserError);
}

// Random stacks (seeded): every pixel its own rate (inside and at the edges
// of the grid), amplitudes (some 0: nothing decays), background and photon
// noise, a random schedule and exposures. The fast map must find the same
// fit as the first algorithm (FitDecayMapReference) and never a worse one:
// its cost at most the reference's plus rounding on every pixel, the same
// pixels without a decay, and kr and amplitudes within 1% wherever the
// reference's Newton steps converged (its cost within 1e-6 of the fast
// map's; where the cost is that flat, kr still moves by up to 0.12%).
DecayMapInput RandomStack(unsigned seed, int width, int height) {
  DecayMapInput in;
  in.width = width;
  in.height = height;
  in.channels = 3;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0, 1);
  const int frames = 12 + static_cast<int>(unit(rng) * 30);
  const double gap = 1 + 9 * unit(rng);
  for (int j = 0; j < frames; ++j) {
    const double e = std::min(0.8 * gap, 0.05 * std::pow(2.0, j / (2 + 2 * unit(rng))));
    in.t_s.push_back(0.005 + gap * j + e / 2);
    in.exposure_s.push_back(e);
  }
  const std::size_t pixels = static_cast<std::size_t>(width) * height;
  std::vector<double> k(pixels), amplitude(pixels * 3), background(pixels * 3);
  const double span = in.t_s.back() - in.t_s.front();
  for (std::size_t p = 0; p < pixels; ++p) {
    k[p] = std::exp(std::log(0.01 / span) + unit(rng) * std::log(2000.0));  // past both ends of the grid
    const bool dark = unit(rng) < 0.05;
    for (int c = 0; c < 3; ++c) {
      amplitude[p * 3 + c] = dark ? 0 : std::pow(10.0, 1 + 3 * unit(rng));
      background[p * 3 + c] = std::pow(10.0, -1 + 2 * unit(rng));
    }
  }
  const double gain = std::pow(10.0, 2 * unit(rng));  // electrons per DN
  for (int j = 0; j < frames; ++j) {
    const double e = in.exposure_s[j], start = in.t_s[j] - e / 2;
    std::vector<float> frame(pixels * 3);
    for (std::size_t p = 0; p < pixels; ++p)
      for (int c = 0; c < 3; ++c) {
        const double mean = amplitude[p * 3 + c] * std::exp(-k[p] * start) * -std::expm1(-k[p] * e) / k[p] +
                            background[p * 3 + c] * e;
        std::poisson_distribution<long long> counts(gain * mean);
        frame[p * 3 + c] = static_cast<float>(counts(rng) / gain / e);
      }
    in.frames.push_back(std::move(frame));
  }
  return in;
}

TEST(DecayMap, FindsTheFitTheFirstAlgorithmFindsOnRandomStacks) {
  for (unsigned seed = 1; seed <= 6; ++seed) {
    const DecayMapInput in = RandomStack(seed, 37, 23);
    DecayMapOptions options;
    options.background = seed != 5;
    options.weighting = seed == 6 ? Weighting::kNone : Weighting::kPoisson;
    const DecayMap fast = FitDecayMap(in, options, "random");
    const DecayMap reference = FitDecayMapReference(in, options, "random");
    EXPECT_EQ(fast.no_decay, reference.no_decay) << "seed " << seed;
    const double samples = 3.0 * in.frames.size();
    std::size_t compared = 0;
    for (std::size_t p = 0; p < fast.kr.size(); ++p) {
      const double cost = fast.rms[p] * fast.rms[p] * samples, reference_cost = reference.rms[p] * reference.rms[p] * samples;
      ASSERT_LE(cost, reference_cost * (1 + 1e-5) + 1e-9) << "seed " << seed << " pixel " << p;
      EXPECT_EQ(std::isnan(fast.kr[p]), std::isnan(reference.kr[p])) << "seed " << seed << " pixel " << p;
      if (std::isnan(fast.kr[p]) || std::fabs(cost - reference_cost) > 1e-6 * reference_cost + 1e-9) continue;
      ++compared;
      EXPECT_NEAR(fast.kr[p], reference.kr[p], 1e-2 * reference.kr[p]) << "seed " << seed << " pixel " << p;
      const double largest = std::max({reference.amplitude[p * 3], reference.amplitude[p * 3 + 1],
                                       reference.amplitude[p * 3 + 2]});
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(fast.amplitude[p * 3 + c], reference.amplitude[p * 3 + c], 1e-2 * largest + 1e-6)
            << "seed " << seed << " pixel " << p;
    }
    EXPECT_GT(compared, fast.kr.size() / 2) << "seed " << seed;
  }
}

// ---------------------------------------------------------------------------
// Two states (options.states = 2): stacks of the model of the two-state
// materials, y_c = s_c (a1 exp(-k1 t) + a2 exp(-k2 t)) + B_c (both states
// share one emission colour s), with known rates. `gain` is electrons per DN
// (0: no noise, the exact exposure integral).
struct TwoStateTruth {
  std::vector<double> k1, k2, a1, a2;  // per pixel; a_i * colour[c] is the amplitude of channel c
};

DecayMapInput TwoStateStack(unsigned seed, int width, int height, double gain, TwoStateTruth* truth,
                            double background = 2) {
  DecayMapInput in;
  in.width = width;
  in.height = height;
  in.channels = 3;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0, 1);
  const double colour[3] = {1.0, 0.45, 0.3};
  for (int j = 0; j < 36; ++j) {
    const double e = std::min(4.0, 0.05 * std::pow(2.0, j / 4));
    in.t_s.push_back(0.005 + 5.0 * j + e / 2);
    in.exposure_s.push_back(e);
  }
  const std::size_t pixels = static_cast<std::size_t>(width) * height;
  TwoStateTruth& t = *truth;
  for (std::size_t p = 0; p < pixels; ++p) {
    // k1 0.005-0.02 /s, k2 / k1 4-20 (the fast state lives over 10-40 frames
    // of the schedule), the fast state's share of the glow at t = 0 0.3-0.8.
    t.k1.push_back(0.005 * std::pow(4.0, unit(rng)));
    t.k2.push_back(t.k1.back() * 4 * std::pow(5.0, unit(rng)));
    const double total = 2000 + 3000 * unit(rng), fast = 0.3 + 0.5 * unit(rng);
    t.a1.push_back(total * (1 - fast));
    t.a2.push_back(total * fast);
  }
  for (int j = 0; j < 36; ++j) {
    const double e = in.exposure_s[j], start = in.t_s[j] - e / 2;
    std::vector<float> frame(pixels * 3);
    for (std::size_t p = 0; p < pixels; ++p)
      for (int c = 0; c < 3; ++c) {
        // Counts over the exposure: the exact integral of the model.
        const double mean = colour[c] * (t.a1[p] * std::exp(-t.k1[p] * start) * -std::expm1(-t.k1[p] * e) / t.k1[p] +
                                         t.a2[p] * std::exp(-t.k2[p] * start) * -std::expm1(-t.k2[p] * e) / t.k2[p]) +
                            background * e;
        if (gain > 0) {
          std::poisson_distribution<long long> counts(gain * mean);
          frame[p * 3 + c] = static_cast<float>(counts(rng) / gain / e);
        } else {
          frame[p * 3 + c] = static_cast<float>(mean / e);
        }
      }
    in.frames.push_back(std::move(frame));
  }
  return in;
}

TEST(DecayMapTwoStates, RecoversBothRatesOfANoiselessStackExactly) {
  // With a background and photon weights; without a background term (none
  // in the stack) and unweighted.
  for (const bool background : {true, false}) {
    TwoStateTruth truth;
    const DecayMapInput in = TwoStateStack(11, 16, 8, 0, &truth, background ? 2 : 0);
    DecayMapOptions options;
    options.states = 2;
    options.background = background;
    options.weighting = background ? Weighting::kPoisson : Weighting::kNone;
    const DecayMap map = FitDecayMap(in, options, "stack");
    ASSERT_EQ(map.kr2.size(), map.kr.size());
    ASSERT_EQ(map.amplitude2.size(), map.amplitude.size());
    EXPECT_EQ(map.one_state, 0u);
    double worst_k1 = 0, worst_k2 = 0, worst_a = 0;
    for (std::size_t p = 0; p < map.kr.size(); ++p) {
      worst_k1 = std::max(worst_k1, std::fabs(map.kr[p] - truth.k1[p]) / truth.k1[p]);
      worst_k2 = std::max(worst_k2, std::fabs(map.kr2[p] - truth.k2[p]) / truth.k2[p]);
      worst_a = std::max({worst_a, std::fabs(map.amplitude[p * 3] - truth.a1[p]) / truth.a1[p],
                          std::fabs(map.amplitude2[p * 3] - truth.a2[p]) / truth.a2[p]});
    }
    // The frames are float: rates and amplitudes to a part in 1e3 or better.
    EXPECT_LT(worst_k1, 1e-3) << "background " << background;
    EXPECT_LT(worst_k2, 1e-3) << "background " << background;
    EXPECT_LT(worst_a, 1e-3) << "background " << background;
  }
}

TEST(DecayMapTwoStates, RecoversBothRatesOfNoisyRandomStacks) {
  for (unsigned seed : {21u, 22u}) {
    TwoStateTruth truth;
    // 25 electrons per DN: photon noise of a few percent on the late frames.
    const DecayMapInput in = TwoStateStack(seed, 24, 16, 25, &truth);
    DecayMapOptions options;
    options.states = 2;
    const DecayMap map = FitDecayMap(in, options, "stack");
    EXPECT_EQ(map.no_decay, 0u);
    EXPECT_EQ(map.one_state, 0u) << "seed " << seed;
    std::vector<double> e1, e2;
    for (std::size_t p = 0; p < map.kr.size(); ++p) {
      if (std::isnan(map.kr2[p])) continue;
      e1.push_back(std::fabs(map.kr[p] - truth.k1[p]) / truth.k1[p]);
      e2.push_back(std::fabs(map.kr2[p] - truth.k2[p]) / truth.k2[p]);
    }
    ASSERT_FALSE(e1.empty());
    std::sort(e1.begin(), e1.end());
    std::sort(e2.begin(), e2.end());
    // Single pixels' photon noise: median errors of a few percent, nine
    // pixels in ten within 20% (k1) and 15% (k2). The worst k1 are slow
    // states (k1 near 0.005 /s: a third of a decay over the 175 s recorded)
    // that trade with the background; ten times the photons shrink every
    // error by about sqrt(10), as noise, not a bias, does.
    const std::size_t n = e1.size();
    EXPECT_LT(e1[n / 2], 0.03) << "seed " << seed;
    EXPECT_LT(e2[n / 2], 0.05) << "seed " << seed;
    EXPECT_LT(e1[n * 9 / 10], 0.2) << "seed " << seed;
    EXPECT_LT(e2[n * 9 / 10], 0.15) << "seed " << seed;
  }
}

TEST(DecayMapTwoStates, ASingleStateStackKeepsOneStateAndBadOptionsAreRefused) {
  const DecayMapInput in = Stack(3);
  const DecayMap one = FitDecayMap(in, DecayMapOptions{}, "stack");
  DecayMapOptions options;
  options.states = 2;
  const DecayMap two = FitDecayMap(in, options, "stack");
  // BIC keeps one state on (nearly) every pixel, and there the map is the
  // one-state map exactly.
  std::size_t kept = 0;
  for (std::size_t p = 0; p < one.kr.size(); ++p) {
    if (!std::isnan(two.kr2[p])) continue;
    ++kept;
    EXPECT_EQ(two.kr[p], one.kr[p]);
    EXPECT_EQ(two.rms[p], one.rms[p]);
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(two.amplitude[p * 3 + c], one.amplitude[p * 3 + c]);
      EXPECT_EQ(two.amplitude2[p * 3 + c], 0.0f);
    }
  }
  EXPECT_EQ(kept, two.one_state);
  EXPECT_GE(kept, one.kr.size() * 99 / 100);
  EXPECT_TRUE(one.kr2.empty());

  options.states = 3;
  EXPECT_THROW(FitDecayMap(in, options, "stack"), UserError);
  options.states = 2;
  DecayMapInput short_stack = in;
  short_stack.frames.resize(5);
  short_stack.t_s.resize(5);
  short_stack.exposure_s.resize(5);
  EXPECT_THROW(FitDecayMap(short_stack, options, "stack"), UserError);
}

}  // namespace
}  // namespace phos
