// The integrators of Eq. 8.1 against closed forms, their orders of accuracy,
// their stability limits, and the simulation driver of `phos simulate`.

#include <cmath>
#include <gtest/gtest.h>

#include "model/closed_form.h"
#include "phos/model/reference.h"
#include "phos/model/simulate.h"
#include "phos/util/error.h"
#include "test_util.h"

namespace phos {
namespace {

using testing::ClosedForm;
using testing::RelativelyNear;

TEST(ExactStep, PureDecayComposesToTheClosedForm) {
  for (double kr : {1e-6, 1e-3, 0.227, 1.0, 1e3})
    for (double r0 : {1.0, 0.5, 1e-10}) {
      const int steps = 1000;
      const double h = 5.0 / (kr * steps);  // five time constants in all
      double r = r0;
      for (int n = 0; n < steps; ++n) r = ExactStep(r, 0.0, kr, h);
      EXPECT_TRUE(RelativelyNear(r, r0 * std::exp(-static_cast<long double>(kr) * h * steps), 1e-12))
          << "kr " << kr << " r0 " << r0;
    }
}

TEST(ExactStep, EquilibriumIsAFixedPoint) {
  for (double a : {1e-6, 0.1, 1.0, 1e6})
    for (double kr : {1e-6, 0.227, 1e6}) {
      const double r_inf = a / (a + kr);
      double r = r_inf;
      for (double h : {1e-6, 1e-3, 1.0, 1e3, 1e5}) r = ExactStep(r, a, kr, h);
      EXPECT_TRUE(RelativelyNear(r, static_cast<long double>(a) / (static_cast<long double>(a) + kr), 1e-12));
    }
}

TEST(ExactStep, ChargingFromZeroKeepsEveryDigitForTinySteps) {
  // r = r_inf (1 - e^{-kh}); a naive 1 - exp(-kh) would lose all digits at kh = 1e-12.
  for (double kh : {1e-15, 1e-12, 1e-8, 1e-3, 0.5, 1.0, 30.0, 800.0})
    for (double a : {0.1, 1.0, 1e4}) {
      const double kr = 0.227, h = kh / (a + kr);
      EXPECT_TRUE(RelativelyNear(ExactStep(0.0, a, kr, h), ClosedForm(0, a, kr, h), 1e-13)) << kh;
    }
}

TEST(ExactStep, ManyStepsEqualOneStep) {
  // Piecewise-constant irradiance: splitting a step changes nothing (up to rounding).
  const double a = 0.3, kr = 0.05;
  double one = ExactStep(0.2, a, kr, 10.0), many = 0.2;
  for (int n = 0; n < 1000; ++n) many = ExactStep(many, a, kr, 0.01);
  EXPECT_TRUE(RelativelyNear(many, one, 1e-12));
}

TEST(ReferenceAdvance, MatchesTheClosedFormIndependently) {
  ReferenceOptions options;
  for (double a : {0.0, 0.01, 0.14, 2.0})
    for (double kr : {0.015, 0.227, 1.0})
      for (double t : {0.5, 10.0, 60.0}) {
        if ((a + kr) * t > 200) continue;
        long double r = ReferenceAdvance(0.25L, a, kr, t, options);
        EXPECT_TRUE(RelativelyNear(static_cast<double>(r), ClosedForm(0.25L, a, kr, t), 1e-12))
            << a << " " << kr << " " << t;
      }
}

TEST(ReferenceAdvance, RefusesStiffIntervalsItCannotFinish) {
  ReferenceOptions options;
  options.max_steps = 1000;
  EXPECT_THROW(ReferenceAdvance(0.0L, 1e6, 1.0, 1e3, options), UserError);
}

// Error of one integrator at step h on a charge-then-decay schedule, as max
// relative error of r over the samples.
double MaxError(Integrator integrator, double h) {
  Material m = LoadMaterial(testing::Fixture("materials/green.json"));
  std::vector<double> E = {1, 1, 1, 0, 0, 0, 0, 0};
  const double a = 0.141, kr = 0.227;
  SimulationOptions options;
  options.integrator = integrator;
  options.dt_s = h;
  SimulationResult result = Simulate(m, IrradianceSchedule::ChargeThenDecay(E, 8.0, 8.0), options, "green");
  double worst = 0;
  for (std::size_t s = 0; s < result.sample_count(); ++s) {
    double t = result.t_s[s];
    long double expected = t <= 8.0 ? ClosedForm(0, a, kr, t) : ClosedForm(ClosedForm(0, a, kr, 8.0), 0, kr, t - 8.0);
    if (expected > 0) worst = std::max(worst, static_cast<double>(std::fabs(result.state(s, 0) - expected) / expected));
  }
  return worst;
}

TEST(Integrators, EulerIsFirstOrderAndRk4FourthOrder) {
  // Halving the step divides the error by 2^p.
  double euler_ratio = MaxError(Integrator::kEuler, 0.1) / MaxError(Integrator::kEuler, 0.05);
  double rk4_ratio = MaxError(Integrator::kRk4, 0.4) / MaxError(Integrator::kRk4, 0.2);
  EXPECT_NEAR(euler_ratio, 2.0, 0.1);
  EXPECT_NEAR(rk4_ratio, 16.0, 1.5);
  EXPECT_LT(MaxError(Integrator::kExact, 1.0), 1e-13);
  EXPECT_LT(MaxError(Integrator::kReference, 1.0), 1e-12);
}

TEST(Integrators, StabilityLimitsAreWhereTheStepStopsContracting) {
  // Pure decay from r = 1: one step multiplies r by the stability function R(-hk).
  auto R = [](Integrator integrator, double hk) {
    return integrator == Integrator::kEuler ? EulerStep(1.0, 0.0, 1.0, hk) : Rk4Step(1.0, 0.0, 1.0, hk);
  };
  EXPECT_NEAR(R(Integrator::kEuler, 2.0), -1.0, 1e-15);
  EXPECT_LT(std::fabs(R(Integrator::kEuler, 1.9)), 1.0);
  EXPECT_GT(std::fabs(R(Integrator::kEuler, 2.1)), 1.0);
  EXPECT_LT(R(Integrator::kEuler, 1.5), 0.0);  // past hk = 1 Euler overshoots equilibrium
  EXPECT_NEAR(R(Integrator::kRk4, kRk4StabilityLimitHk), 1.0, 1e-12);
  EXPECT_LT(R(Integrator::kRk4, kRk4StabilityLimitHk - 0.01), 1.0);
  EXPECT_GT(R(Integrator::kRk4, kRk4StabilityLimitHk + 0.01), 1.0);
  for (double hk = 0; hk < 10; hk += 0.01) EXPECT_GT(R(Integrator::kRk4, hk), 0.0);  // RK4 never overshoots
}

TEST(Simulate, SamplesEveryDtAndSplitsStepsAtTheLightSwitch) {
  Material m = LoadMaterial(testing::Fixture("materials/orange.json"));
  std::vector<double> E = {2, 1, 0.5, 0, 0, 0, 0, 0};
  const double a = 2 * 0.015 + 1 * 0.006 + 0.5 * 0.0003, kr = 0.015;
  SimulationOptions options;
  options.dt_s = 1.0;
  // The light goes off at 10.3 s, inside the step from 10 to 11.
  SimulationResult result = Simulate(m, IrradianceSchedule::ChargeThenDecay(E, 10.3, 20.0), options, "orange");
  ASSERT_EQ(result.sample_count(), 31u);  // t = 0..30
  EXPECT_EQ(result.t_s.back(), 30.0);
  EXPECT_EQ(result.steps, 31);  // 30 steps, one of them split in two
  for (std::size_t s = 0; s < result.sample_count(); ++s) {
    double t = result.t_s[s];
    long double expected =
        t <= 10.3 ? ClosedForm(0, a, kr, t) : ClosedForm(ClosedForm(0, a, kr, 10.3), 0, kr, t - 10.3);
    EXPECT_TRUE(RelativelyNear(result.state(s, 0), expected, 1e-12)) << t;
    for (int b = 0; b < 8; ++b)  // Eq. 8.2
      EXPECT_DOUBLE_EQ(result.radiance(s, b), m.states[0].Lambda[b] * kr * result.state(s, 0));
  }
  EXPECT_TRUE(result.warnings.empty());
}

TEST(Simulate, EulerPastItsLimitsIsRefusedOrWarnedNeverSilent) {
  Material m = LoadMaterial(testing::Fixture("materials/yellow.json"));  // kr = 0.251
  std::vector<double> E = {10, 10, 10, 0, 0, 0, 0, 0};                   // a = 1.9, k = 2.151
  SimulationOptions options;
  options.integrator = Integrator::kEuler;
  options.dt_s = 1.0;  // hk = 2.151 > 2
  try {
    Simulate(m, IrradianceSchedule::ChargeThenDecay(E, 10, 10), options, "yellow");
    FAIL() << "unstable Euler was not refused";
  } catch (const UserError& e) {
    EXPECT_NE(std::string(e.what()).find("exceeds the stability limit 2"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("--dt <= "), std::string::npos) << e.what();
  }
  options.allow_unstable = true;
  SimulationResult forced = Simulate(m, IrradianceSchedule::ChargeThenDecay(E, 10, 10), options, "yellow");
  ASSERT_EQ(forced.warnings.size(), 1u);
  EXPECT_EQ(forced.warnings[0].rfind("unstable:", 0), 0u);

  options.allow_unstable = false;
  options.dt_s = 0.7;  // hk = 1.5: stable but overshoots
  SimulationResult overshoot = Simulate(m, IrradianceSchedule::ChargeThenDecay(E, 10, 10), options, "yellow");
  ASSERT_EQ(overshoot.warnings.size(), 1u);
  EXPECT_EQ(overshoot.warnings[0].rfind("not monotone:", 0), 0u);

  options.integrator = Integrator::kRk4;
  options.dt_s = 1.0;  // 2.151 < 2.785: fine for RK4
  EXPECT_TRUE(Simulate(m, IrradianceSchedule::ChargeThenDecay(E, 10, 10), options, "yellow").warnings.empty());
  options.dt_s = 1.5;  // 3.2 > 2.785
  EXPECT_THROW(Simulate(m, IrradianceSchedule::ChargeThenDecay(E, 10, 10), options, "yellow"), UserError);
}

// A material that a flash charges: one state, kr = 0.01/s, ke = 1e9 per unit irradiance.
Material FlashMaterial() {
  return MaterialFromJson(nlohmann::json::parse(R"({"schema": "phos.material/1", "name": "flash",
      "bands_nm": [400, 500], "states": [{"kr": 0.01, "ke": [1e9], "Lambda": [1]}]})"),
                          "flash");
}

TEST(Simulate, AFlashFarShorterThanTheStepChargesByItsDose) {
  // Under a = 1e9/s a flash of t_p charges r = a/k (1 - e^{-k t_p}), about
  // 1 - e^{-a t_p}, then decays. Phase ends within 1e-9 dt of a sample
  // were once taken as the sample: a flash shorter than that charged nothing.
  const Material m = FlashMaterial();
  const double a = 1e9, kr = 0.01;
  for (double dt : {1.0, 0.5, 1e3})
    for (double fraction : {1e-3, 1e-6, 1e-9, 3e-10, 1e-10, 1e-11, 1e-12}) {
      const double flash = fraction * dt;
      SimulationOptions options;
      options.dt_s = dt;
      const SimulationResult result =
          Simulate(m, IrradianceSchedule::ChargeThenDecay({1}, flash, 3 * dt), options, "flash");
      ASSERT_EQ(result.sample_count(), 4u) << flash;
      const long double charged = ClosedForm(0, a, kr, flash);
      EXPECT_TRUE(RelativelyNear(static_cast<double>(charged), -std::expm1(-a * flash), 1e-9));  // kr << a
      EXPECT_EQ(result.state(0, 0), 0.0);
      for (std::size_t s = 1; s < result.sample_count(); ++s)
        EXPECT_TRUE(RelativelyNear(result.state(s, 0), ClosedForm(charged, 0, kr, result.t_s[s] - flash), 1e-12))
            << "dt " << dt << " flash " << flash << " t " << result.t_s[s];
      EXPECT_EQ(result.steps, 4);  // the flash, the rest of the first step, two more
    }
}

TEST(Simulate, ALastSamplePastTheSchedulesSumStaysInItsLastPhase) {
  // 9999.99999999 s at --dt 1 has its last sample at 10000, 1e-8 s past the
  // end: the last phase runs on to it (the loop once split there forever).
  const Material m = FlashMaterial();
  SimulationOptions options;
  const SimulationResult result =
      Simulate(m, IrradianceSchedule::ChargeThenDecay({1e-9}, 9999.99999999, 0), options, "flash");
  ASSERT_EQ(result.sample_count(), 10001u);
  EXPECT_EQ(result.t_s.back(), 10000.0);
  EXPECT_TRUE(RelativelyNear(result.state(10000, 0), ClosedForm(0, 1, 0.01, 10000), 1e-12));
}

TEST(Simulate, BadOptionsAreUserErrors) {
  Material m = LoadMaterial(testing::Fixture("materials/green.json"));
  std::vector<double> E = {1, 1, 1, 0, 0, 0, 0, 0};
  SimulationOptions options;
  for (double dt : {0.0, -1.0, std::nan("")}) {
    options.dt_s = dt;
    EXPECT_THROW(Simulate(m, IrradianceSchedule::ChargeThenDecay(E, 1, 1), options, "g"), UserError) << dt;
  }
  options.dt_s = 1e-9;  // 2e9 samples
  EXPECT_THROW(Simulate(m, IrradianceSchedule::ChargeThenDecay(E, 1, 1), options, "g"), UserError);
  options.dt_s = 1;
  std::vector<double> negative = {-1, 0, 0, 0, 0, 0, 0, 0};
  EXPECT_THROW(Simulate(m, IrradianceSchedule::ChargeThenDecay(negative, 1, 1), options, "g"), UserError);
}

}  // namespace
}  // namespace phos
