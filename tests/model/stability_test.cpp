// Numerical stability at the extremes: rates kr and ke*E from 1e-6 to 1e6 per second (and 1e12
// from huge irradiance), steps from 1e-6 to 1e5 s, irradiance 0 and 1e12, r
// near 0 and 1, and runs of 1e7 steps. Every state must stay finite and in
// [0, 1]; the exact update must match the closed form to 1e-12 relative.

#include <cmath>
#include <gtest/gtest.h>

#include "model/closed_form.h"
#include "phos/model/batch.h"
#include "phos/model/simulate.h"
#include "phos/util/error.h"
#include "test_util.h"

namespace phos {
namespace {

using testing::ClosedForm;
using testing::RelativelyNear;

const double kRates[] = {1e-6, 1e-3, 1.0, 1e3, 1e6};
const double kSteps[] = {1e-6, 1e-3, 1.0, 1e3, 1e5};
const double kStates[] = {0.0, 1e-300, 1e-15, 0.5, 1 - 1e-15, 1.0};
// a = ke * E: every rate above, plus darkness (E = 0) and ke = 1 under E = 1e12.
std::vector<double> ExcitationRatesGrid() {
  std::vector<double> a = {0.0, 1.0 * 1e12};
  a.insert(a.end(), std::begin(kRates), std::end(kRates));
  return a;
}

TEST(Extremes, ExactStepStaysInRangeAndMatchesTheClosedForm) {
  int cases = 0;
  for (double kr : kRates)
    for (double a : ExcitationRatesGrid())
      for (double h : kSteps)
        for (double r0 : kStates) {
          double r = ExactStep(r0, a, kr, h);
          ASSERT_TRUE(std::isfinite(r));
          ASSERT_GE(r, 0.0);
          ASSERT_LE(r, 1.0);
          EXPECT_TRUE(RelativelyNear(r, ClosedForm(r0, a, kr, h), 1e-12))
              << "kr " << kr << " a " << a << " h " << h << " r0 " << r0;
          ++cases;
        }
  EXPECT_EQ(cases, 5 * 7 * 5 * 6);
}

// The batch kernel (Eigen packet exp/log, float and double) over the same grid.
template <typename Real>
void CheckBatchExtremes(double tolerance, double floor) {
  std::vector<double> as = ExcitationRatesGrid();
  // One point per (a, r0); one material state per kr; E carries a directly (ke = 1).
  const std::size_t n = as.size() * std::size(kStates);
  for (double kr : kRates)
    for (double h : kSteps) {
      BatchCoefficients<Real> c;
      c.nc = 1;
      c.n_exc = 1;
      c.kr = {static_cast<Real>(kr)};
      c.ke = {Real(1)};
      std::vector<Real> E(n);
      StateBatch<Real> s(1, n);
      for (std::size_t j = 0; j < n; ++j) {
        E[j] = static_cast<Real>(as[j / std::size(kStates)]);
        s.r[j] = static_cast<Real>(kStates[j % std::size(kStates)]);
      }
      StateBatch<Real> before = s;
      AdvanceBatch<Real>(Integrator::kExact, c, E.data(), n, static_cast<Real>(h), s);
      for (std::size_t j = 0; j < n; ++j) {
        ASSERT_TRUE(std::isfinite(s.r[j]));
        ASSERT_GE(s.r[j], Real(0));
        ASSERT_LE(s.r[j], Real(1));
        // Compare with the closed form of the inputs as the kernel saw them.
        long double expected = ClosedForm(before.r[j], E[j], static_cast<Real>(kr), static_cast<Real>(h));
        EXPECT_TRUE(RelativelyNear(s.r[j], expected, tolerance, floor))
            << "kr " << kr << " a " << E[j] << " h " << h << " r0 " << before.r[j];
      }
    }
}

TEST(Extremes, BatchKernelInDouble) { CheckBatchExtremes<double>(1e-12, 1e-290); }
// Float carries 7 digits; 1e-5 relative is a few hundred ulp at worst, and
// values below 1e-30 are compared absolutely.
TEST(Extremes, BatchKernelInFloat) { CheckBatchExtremes<float>(1e-5, 1e-30); }

TEST(Extremes, TenMillionStepsOfLightAndDarkReachThePeriodicSteadyState) {
  // Alternating lit and dark steps: the map is a contraction, so rounding
  // does not accumulate and r converges to the fixed point of the two-step
  // cycle, known in closed form.
  const double a = 3.0, kr = 0.5, h = 0.01;
  const long double e_lit = std::exp(-(a + kr) * static_cast<long double>(h)),
                    e_dark = std::exp(-kr * static_cast<long double>(h));
  const long double r_inf = a / (a + kr);
  const long double fixed = r_inf * (1 - e_lit) * e_dark / (1 - e_lit * e_dark);  // r after a dark step
  double r = 0.0;
  bool in_range = true;
  for (int n = 0; n < 5'000'000; ++n) {
    r = ExactStep(r, a, kr, h);
    in_range = in_range && r >= 0 && r <= 1;
    r = ExactStep(r, 0.0, kr, h);
    in_range = in_range && r >= 0 && r <= 1;
  }
  EXPECT_TRUE(in_range);
  EXPECT_TRUE(RelativelyNear(r, fixed, 1e-12));
}

TEST(Extremes, TenMillionDecayStepsAccumulateOnlyRounding) {
  // r = exp(-kr t) as a product of 1e7 rounded factors: the relative error
  // is bounded by N * eps = 1.1e-9 (each step rounds once, the same way).
  const double kr = 1e-6, h = 1e-3;
  const int steps = 10'000'000;
  double r = 1.0;
  for (int n = 0; n < steps; ++n) r = ExactStep(r, 0.0, kr, h);
  EXPECT_TRUE(RelativelyNear(r, std::exp(-static_cast<long double>(kr) * h * steps), steps * 1.12e-16));
  EXPECT_GT(r, 0.0);
}

TEST(Extremes, TenMillionBatchStepsStayInRange) {
  // The batch kernel for 1e7 steps of points spanning the rate range, with
  // the light switching every 1000 steps: finite and in [0, 1] throughout.
  const std::size_t n = 5;
  BatchCoefficients<double> c;
  c.nc = 2;
  c.n_exc = 1;
  c.kr = {1e-6, 1e6};
  c.ke = {1.0, 1.0};
  std::vector<double> lit = {1e-6, 1.0, 1e3, 1e6, 1e12}, dark(n, 0.0);
  StateBatch<double> s(2, n);
  double lo = 1, hi = 0;
  bool finite = true;
  for (int step = 0; step < 10'000'000; ++step) {
    const bool on = (step / 1000) % 2 == 0;
    AdvanceBatch<double>(Integrator::kExact, c, on ? lit.data() : dark.data(), n, 1e-3, s);
    if (step % 997 == 0 || step == 9'999'999)
      for (double r : s.r) {
        finite = finite && std::isfinite(r);
        lo = std::min(lo, r);
        hi = std::max(hi, r);
      }
  }
  EXPECT_TRUE(finite);
  EXPECT_GE(lo, 0.0);
  EXPECT_LE(hi, 1.0);
}

TEST(Extremes, EulerIsRefusedOrWarnedWheneverItCouldLeaveTheRange) {
  // Over the whole grid, Euler either refuses (hk > 2), warns (hk > 1), or
  // gives states that are finite and inside [0, 1]. Never silently wrong.
  Material m;
  m.name = "extreme";
  m.bands = SpectralGrid{{400, 500}};
  m.states.push_back({1.0, {1.0}, {1.0}, {}, {}});
  int refused = 0, warned = 0, clean = 0;
  for (double kr : kRates)
    for (double a : ExcitationRatesGrid())
      for (double h : kSteps) {
        if ((a + kr) * h > 1e30) continue;
        m.states[0].kr = kr;
        SimulationOptions options;
        options.integrator = Integrator::kEuler;
        options.dt_s = h;
        // Ten steps of charge and ten of decay.
        IrradianceSchedule schedule = IrradianceSchedule::ChargeThenDecay({a}, 10 * h, 10 * h);
        try {
          SimulationResult result = Simulate(m, schedule, options, "extreme");
          if (!result.warnings.empty()) {
            ++warned;
            continue;
          }
          for (double r : result.r) {
            ASSERT_TRUE(std::isfinite(r));
            ASSERT_GE(r, 0.0) << "kr " << kr << " a " << a << " h " << h;
            ASSERT_LE(r, 1.0) << "kr " << kr << " a " << a << " h " << h;
          }
          ++clean;
        } catch (const UserError& e) {
          EXPECT_NE(std::string(e.what()).find("stability limit"), std::string::npos);
          ++refused;
        }
      }
  EXPECT_GT(refused, 0);
  EXPECT_GT(warned, 0);
  EXPECT_GT(clean, 0);
}

TEST(Extremes, HugeIrradianceSaturatesAndDarknessNeedsNoKe) {
  Material green = LoadMaterial(testing::Fixture("materials/green.json"));
  SimulationOptions options;
  options.dt_s = 1e-3;
  std::vector<double> E = {1e12, 1e12, 1e12, 0, 0, 0, 0, 0};
  SimulationResult result = Simulate(green, IrradianceSchedule::ChargeThenDecay(E, 0.01, 0.0), options, "green");
  const long double a = 1e12L * (0.1L + 0.035L + 0.006L), kr = 0.227L;
  EXPECT_TRUE(RelativelyNear(result.state(result.sample_count() - 1, 0), a / (a + kr), 1e-12));  // saturated
  Material bottle = LoadMaterial(testing::Fixture("materials/bottle.json"));
  options.r0 = {1.0};
  options.dt_s = 1.0;
  SimulationResult decay =
      Simulate(bottle, IrradianceSchedule::ChargeThenDecay(std::vector<double>(8, 0.0), 0, 100), options, "bottle");
  EXPECT_TRUE(RelativelyNear(decay.state(100, 0), std::exp(-0.185L * 100), 1e-12));
}

}  // namespace
}  // namespace phos
