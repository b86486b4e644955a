// IrradianceSchedule on a grid of frames (model/schedule.h): each frame the
// mean of the phases over it, whole frames exact, the dose kept.

#include "phos/model/schedule.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace phos {
namespace {

TEST(FrameIrradiance, PhasesOnTheGridGiveTheirIrradianceExactly) {
  IrradianceSchedule s;
  s.Add(10, {1.0, 0.6, 0.2}, "charge");
  s.Add(90, {0, 0, 0}, "dark");
  const auto E = FrameIrradiance(s, 0.5);
  ASSERT_EQ(E.size(), 200u);
  for (std::size_t f = 0; f < 20; ++f) EXPECT_EQ(E[f], (std::vector<double>{1.0, 0.6, 0.2})) << f;
  for (std::size_t f = 20; f < 200; ++f) EXPECT_EQ(E[f], (std::vector<double>{0, 0, 0})) << f;
}

TEST(FrameIrradiance, BoundariesOffByRoundingStayOnTheGrid) {
  // 0.1 + 0.2 is 0.30000000000000004, not three frames of 0.1 exactly: the
  // dark frame after it must still be exactly dark, not 4e-16 lit.
  IrradianceSchedule s;
  s.Add(0.1, {2.0}, "");
  s.Add(0.2, {2.0}, "");
  s.Add(0.7, {0.0}, "");
  const auto E = FrameIrradiance(s, 0.1);
  ASSERT_EQ(E.size(), 10u);
  for (std::size_t f = 0; f < 3; ++f) EXPECT_EQ(E[f][0], 2.0) << f;
  for (std::size_t f = 3; f < 10; ++f) EXPECT_EQ(E[f][0], 0.0) << f;
}

TEST(FrameIrradiance, ASwitchInsideAFrameGivesItsMean) {
  IrradianceSchedule s;
  s.Add(1.25, {4.0, 1.0}, "");  // a quarter into frame 2 of 0.5 s
  s.Add(0.75, {0.0, 3.0}, "");
  const auto E = FrameIrradiance(s, 0.5);
  ASSERT_EQ(E.size(), 4u);
  EXPECT_EQ(E[1], (std::vector<double>{4.0, 1.0}));
  EXPECT_DOUBLE_EQ(E[2][0], 0.5 * 4.0);
  EXPECT_DOUBLE_EQ(E[2][1], 0.5 * 1.0 + 0.5 * 3.0);
  EXPECT_EQ(E[3], (std::vector<double>{0.0, 3.0}));
}

TEST(FrameIrradiance, RandomSchedulesKeepTheirDose) {
  // Phases of random lengths (most off the grid) and levels, dark ones among
  // them: every band's dose sum_f E_f dt equals sum_phases E d, each frame's
  // irradiance lies within the range of the phases it overlaps, and a frame
  // wholly inside a dark phase is exactly 0.
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> length(0.01, 3.0), level(0.0, 5.0);
  for (int trial = 0; trial < 200; ++trial) {
    const double dt = std::uniform_real_distribution<double>(0.05, 1.0)(rng);
    const int phases = 1 + trial % 7;
    IrradianceSchedule s;
    std::vector<double> dose(2, 0.0);
    double total = 0;
    for (int k = 0; k < phases; ++k) {
      double d = length(rng);
      if (k == phases - 1) d = std::ceil((total + d) / dt) * dt - total;  // whole frames
      const bool dark = rng() % 3 == 0;
      std::vector<double> e = dark ? std::vector<double>{0, 0} : std::vector<double>{level(rng), level(rng)};
      for (int b = 0; b < 2; ++b) dose[b] += e[b] * d;
      total += d;
      s.Add(d, e, "");
    }
    ASSERT_TRUE(WholeFrames(s.total_s(), dt).has_value()) << trial;
    const auto E = FrameIrradiance(s, dt);
    ASSERT_EQ(static_cast<long long>(E.size()), *WholeFrames(s.total_s(), dt));
    for (int b = 0; b < 2; ++b) {
      double sum = 0;
      for (const auto& frame : E) sum += frame[b] * dt;
      EXPECT_NEAR(sum, dose[b], 1e-9 * (1 + dose[b])) << "trial " << trial << " band " << b;
    }
    double begin = 0;
    for (const IrradiancePhase& p : s.phases()) {
      const double end = begin + p.duration_s;
      for (std::size_t f = 0; f < E.size(); ++f) {
        const double f0 = static_cast<double>(f) * dt, f1 = f0 + dt;
        if (p.dark() && f0 >= begin + 1e-9 && f1 <= end - 1e-9) {
          EXPECT_EQ(E[f][0] + E[f][1], 0.0) << trial;
        }
      }
      begin = end;
    }
    for (const auto& frame : E)
      for (double e : frame) EXPECT_TRUE(e >= 0 && e <= 5.0 + 1e-12) << trial;
  }
}

TEST(WholeFrames, CountsFramesWithinRoundingAndRefusesTheRest) {
  EXPECT_EQ(WholeFrames(0.1 + 0.2, 0.1), 3);
  EXPECT_EQ(WholeFrames(100, 0.5), 200);
  EXPECT_EQ(WholeFrames(0, 0.5), 0);
  EXPECT_FALSE(WholeFrames(0.25, 0.1).has_value());
  EXPECT_FALSE(WholeFrames(100.1, 0.5).has_value());
}

}  // namespace
}  // namespace phos
