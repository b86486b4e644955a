// The closed forms of Eq. 8.1 (closed_form.h) against the copies of them
// that the fits, the editor, the renderer and the simulated lab each wrote
// by hand before they called model/: the old expressions are kept here as
// references, and every caller's numbers (and, where Ceres differentiates
// them, its derivatives) must stay where they were, on random inputs over
// many decades: kr h from 1e-12 to 1e3, a from 0 to 1e9.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <type_traits>
#include <vector>

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "model/closed_form.h"
#include "phos/model/closed_form.h"
#include "phos/model/material.h"
#include "phos/model/rate_equation.h"
#include "phos/model/simulate.h"
#include "test_util.h"

namespace phos {
namespace {

using Jet = ceres::Jet<double, 3>;

// ---- the old expressions, as each caller wrote them ----------------------------

// model/rate_equation.h's ExactStep.
template <typename Real>
Real OldExactStep(Real r, Real a, Real kr, Real h) {
  Real k = a + kr;
  Real x = -k * h;
  Real decay = std::exp(x);
  Real rise = -std::expm1(x);
  Real r_inf = a / std::max(k, std::numeric_limits<Real>::min());
  Real next = r * decay + r_inf * rise;
  return std::min(Real(1), std::max(Real(0), next));
}

// model/src/rate_equation.cpp's ClosedFormState.
double OldClosedFormState(double r0, double a, double kr, double t) {
  double k = a + kr;
  if (k <= 0) return r0;
  double r_inf = a / k;
  return r_inf + (r0 - r_inf) * std::exp(-k * t);
}

// fit/src/excitation_model.h's ChargedState and DecayFactor.
template <typename T>
T OldFitChargedState(const T& a, const T& kr, double charge_s, double r0 = 0.0) {
  using std::exp;
  using std::expm1;
  const T k = a + kr;
  return a / k * -expm1(-k * charge_s) + r0 * exp(-k * charge_s);
}
template <typename T>
T OldFitDecayFactor(const T& kr, double delay_s, double exposure_s) {
  using std::exp;
  using std::expm1;
  const T decay = exp(-kr * delay_s);
  if (exposure_s <= 0) return decay;
  return decay * -expm1(-kr * exposure_s) / (kr * exposure_s);
}

// editor/src/solve.cpp's StateAtSamples, one step.
template <typename T>
T OldEditorStep(const T& r, const T& a, const T& kr, double h_s) {
  using std::expm1;
  const T k = a + kr;
  const T rise = -expm1(-k * h_s);
  return r * (T(1.0) - rise) + a / k * rise;
}

// render/src/phosphor_map.cpp's level of a state after the map's charge.
double OldPhosphorMapLevel(double a, double kr, double charge_s) {
  const double k = a + kr;
  return a / k * -std::expm1(-k * charge_s);
}

// acquire/src/sim_lab.cpp's state integrated over an exposure.
double OldSimLabIntegral(double r, double a, double kr, double exposure_s) {
  const double k = a + kr, r_inf = k > 0 ? a / k : 0;
  return k > 0 ? r_inf * exposure_s + (r - r_inf) * -std::expm1(-k * exposure_s) / k : r * exposure_s;
}

// fit/src/session_fit.cpp (JointDecayResidual, CorrectForExposure): the
// exposure mean around the exposure's middle t.
double SessionFitSinhMean(double k, double t, double e) {
  const double x = k * e / 2;
  return std::exp(-k * t) * (x > 1e-8 ? std::sinh(x) / x : 1.0);
}

// ---- comparisons ------------------------------------------------------------------

// Distance in units in the last place (same sign assumed; 0 and -0 are 0 apart).
template <typename Real>
std::int64_t Ulps(Real x, Real y) {
  if (x == y) return 0;
  using Bits = std::conditional_t<sizeof(Real) == 8, std::int64_t, std::int32_t>;
  Bits bx, by;
  std::memcpy(&bx, &x, sizeof x);
  std::memcpy(&by, &y, sizeof y);
  if ((bx < 0) != (by < 0)) return std::numeric_limits<std::int64_t>::max();
  return std::abs(static_cast<std::int64_t>(bx) - static_cast<std::int64_t>(by));
}

::testing::AssertionResult WithinUlps(double value, double expected, int ulps) {
  if (Ulps(value, expected) <= ulps) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "value " << value << " expected " << expected << " (" << Ulps(value, expected)
                                       << " ulp apart)";
}

// |value - expected| <= 1e-14 |expected| + absolute.
::testing::AssertionResult Near(double value, double expected, double absolute = 0) {
  if (std::isfinite(value) && std::fabs(value - expected) <= 1e-14 * std::fabs(expected) + absolute)
    return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "value " << value << " expected " << expected << " difference "
                                       << value - expected;
}

// The same for a Jet, each derivative allowed 4 ulp of `scale`, the sum of
// the magnitudes it is made of: a derivative summed from terms that cancel
// (dr/da of a nearly full state) keeps their rounding, not its own.
::testing::AssertionResult NearJet(const Jet& value, const Jet& expected, const Jet& scale, double absolute = 0) {
  const double ulps = 4 * std::numeric_limits<double>::epsilon();
  if (!Near(value.a, expected.a, absolute + ulps * scale.a))
    return Near(value.a, expected.a, absolute + ulps * scale.a) << " (value)";
  for (int d = 0; d < 3; ++d)
    if (!Near(value.v[d], expected.v[d], absolute + ulps * scale.v[d]))
      return Near(value.v[d], expected.v[d], absolute + ulps * scale.v[d]) << " (derivative " << d << ")";
  return ::testing::AssertionSuccess();
}

// |r0 e^{-kt}| + |r_inf (1 - e^{-kt})|, value and derivatives taken apart:
// the scale of ChargedState's rounding.
template <typename R>
Jet ChargedStateScale(const Jet& a, const Jet& kr, double t_s, const R& r0) {
  const Jet k = a + kr, decay = exp(-k * t_s), kept = r0 * decay, charged = a / k * -expm1(-k * t_s);
  Jet scale(std::fabs(kept.a) + std::fabs(charged.a));
  for (int d = 0; d < 3; ++d) scale.v[d] = std::fabs(kept.v[d]) + std::fabs(charged.v[d]);
  return scale;
}

// Random inputs over the decades callers meet and beyond.
struct Inputs {
  double r, a, kr, h;
};

class RandomInputs {
 public:
  explicit RandomInputs(std::uint64_t seed) : rng_(seed) {}
  double LogUniform(double lo, double hi) {
    return std::exp(std::uniform_real_distribution<double>(std::log(lo), std::log(hi))(rng_));
  }
  Inputs Next() {
    Inputs in;
    const double u = std::uniform_real_distribution<double>(0, 1)(rng_);
    // r: 0, 1, in between, or tiny; a: 0 one time in eight, else 1e-9 to 1e9.
    in.r = u < 0.15 ? 0.0 : u < 0.3 ? 1.0 : u < 0.45 ? LogUniform(1e-300, 1e-6) : u * u;
    in.a = std::uniform_int_distribution<int>(0, 7)(rng_) == 0 ? 0.0 : LogUniform(1e-9, 1e9);
    in.kr = LogUniform(1e-6, 1e6);
    in.h = LogUniform(1e-12, 1e3) / in.kr;  // kr h from 1e-12 to 1e3
    return in;
  }

 private:
  std::mt19937_64 rng_;
};

constexpr int kTrials = 20000;

// A Jet seeded with derivative 1 in component `d` (d < 0: a constant).
Jet Seeded(double value, int d) {
  Jet j(value);
  if (d >= 0) j.v[d] = 1;
  return j;
}

// ---- the integrators' ExactStep ----------------------------------------------------

TEST(ClosedForm, ExactStepIsTheOldExactStepInDoubleAndFloat) {
  RandomInputs random(1);
  for (int trial = 0; trial < kTrials; ++trial) {
    const Inputs in = random.Next();
    EXPECT_TRUE(WithinUlps(ExactStep(in.r, in.a, in.kr, in.h), OldExactStep(in.r, in.a, in.kr, in.h), 2))
        << in.r << " " << in.a << " " << in.kr << " " << in.h;
    const float r = static_cast<float>(in.r), a = static_cast<float>(in.a), kr = static_cast<float>(in.kr),
                h = static_cast<float>(in.h);
    EXPECT_LE(Ulps(ExactStep(r, a, kr, h), OldExactStep(r, a, kr, h)), 2) << in.r << " " << in.a << " " << in.kr;
  }
}

TEST(ClosedForm, ExactStepKeepsItsClampAndItsEdges) {
  // k = 0: nothing moves; r_inf rounding past 1 or a rounding below 0 is clamped;
  // a NaN (infinite light over an infinite time) comes back as 0, as before.
  const double inf = std::numeric_limits<double>::infinity();
  for (const Inputs& in : std::vector<Inputs>{{0.4, 0.0, 0.0, 5.0},
                                              {1.0, 1e300, 1e-300, 1e-3},
                                              {0.0, 0.0, 1.0, 1e3},
                                              {1.0, 1e9, 1e-6, 1e3},
                                              {0.5, inf, 1.0, 1.0},
                                              {0.5, 0.0, 1.0, inf},
                                              {1e-310, 0.0, 1e-3, 1.0}})
    EXPECT_EQ(ExactStep(in.r, in.a, in.kr, in.h), OldExactStep(in.r, in.a, in.kr, in.h))
        << in.r << " " << in.a << " " << in.kr << " " << in.h;
  // Jets take the same lines (Ceres's fits and the editor's solver do).
  const Jet step = ExactStep(Seeded(0.2, 0), Seeded(3.0, 1), Seeded(0.5, 2), Jet(0.1));
  EXPECT_NEAR(step.a, ExactStep(0.2, 3.0, 0.5, 0.1), 1e-16);
  EXPECT_NEAR(step.v[0], std::exp(-3.5 * 0.1), 1e-16);  // dr'/dr = e^{-kh}
}

TEST(ClosedForm, ClosedFormStateIsTheOldOneToItsRounding) {
  // The old r_inf + (r0 - r_inf) e^{-kt} rounds to an ulp of the larger of
  // r0 and r_inf; ChargedState keeps the digits of a short charge.
  RandomInputs random(2);
  for (int trial = 0; trial < kTrials; ++trial) {
    const Inputs in = random.Next();
    const double r_inf = in.a / (in.a + in.kr);
    EXPECT_TRUE(Near(ClosedFormState(in.r, in.a, in.kr, in.h), OldClosedFormState(in.r, in.a, in.kr, in.h),
                     4 * std::numeric_limits<double>::epsilon() * std::max(in.r, r_inf)))
        << in.r << " " << in.a << " " << in.kr << " " << in.h;
  }
  EXPECT_EQ(ClosedFormState(0.3, 0.0, 0.0, 7.0), 0.3);
  // Where the old form lost every digit: a charge of k t = 1e-12 from 0.
  EXPECT_TRUE(
      testing::RelativelyNear(ClosedFormState(0, 1.0, 1e-3, 1e-12), testing::ClosedForm(0, 1.0, 1e-3, 1e-12), 1e-14));
}

// ---- fit/: the excitation fits' ChargedState and DecayFactor, values and Jets ----

TEST(ClosedForm, FitChargedStateAndDecayFactorAreTheOldOnesWithTheirDerivatives) {
  RandomInputs random(3);
  for (int trial = 0; trial < kTrials; ++trial) {
    const Inputs in = random.Next();
    EXPECT_TRUE(WithinUlps(ChargedState(in.a, in.kr, in.h, in.r), OldFitChargedState(in.a, in.kr, in.h, in.r), 2));
    EXPECT_TRUE(WithinUlps(ChargedState(in.a, in.kr, in.h), OldFitChargedState(in.a, in.kr, in.h), 2));
    // d/da and d/dkr, as the fits' residuals take them.
    const Jet a = Seeded(in.a, 0), kr = Seeded(in.kr, 1);
    EXPECT_TRUE(NearJet(ChargedState(a, kr, in.h, in.r), OldFitChargedState(a, kr, in.h, in.r),
                        ChargedStateScale(a, kr, in.h, in.r)))
        << in.r << " " << in.a << " " << in.kr << " " << in.h;
    // A delay and an exposure from 0 to 1e3 time constants.
    const double delay = random.LogUniform(1e-12, 1e3) / in.kr, exposure = trial % 5 ? in.h : 0.0;
    EXPECT_TRUE(WithinUlps(DecayFactor(in.kr, delay, exposure), OldFitDecayFactor(in.kr, delay, exposure), 2));
    EXPECT_TRUE(NearJet(DecayFactor(kr, delay, exposure), OldFitDecayFactor(kr, delay, exposure), Jet(0.0)))
        << in.kr << " " << delay << " " << exposure;
  }
}

TEST(ClosedForm, DecayFactorWithoutAnExposureIsTheExponential) {
  // state_excitation_fit.cpp's carry-over through the dark and the batch's DecayBatch.
  RandomInputs random(4);
  for (int trial = 0; trial < kTrials; ++trial) {
    const Inputs in = random.Next();
    EXPECT_EQ(DecayFactor(in.kr, in.h), std::exp(-in.kr * in.h));
    const float kr = static_cast<float>(in.kr), h = static_cast<float>(in.h);
    EXPECT_EQ(DecayFactor(kr, h), std::exp(-kr * h));
  }
}

// ---- editor/: the solver's step, values and Jets --------------------------------

TEST(ClosedForm, EditorStepIsTheOldOneToTheOldDecaysRounding) {
  // The old step took the decay as 1 - (1 - e^{-kh}), which rounds to an
  // ulp of 1 (and to 0 past kh = 37): the two agree to 1e-14 relative plus
  // an ulp of r; in the dark the new one keeps the digits the old lost.
  RandomInputs random(5);
  const double eps = std::numeric_limits<double>::epsilon();
  for (int trial = 0; trial < kTrials; ++trial) {
    const Inputs in = random.Next();
    EXPECT_TRUE(Near(ChargedState(in.a, in.kr, in.h, in.r), OldEditorStep(in.r, in.a, in.kr, in.h), 2 * eps * in.r))
        << in.r << " " << in.a << " " << in.kr << " " << in.h;
    // d/dr, d/da, d/dkr: the solver's r carries derivatives from the steps
    // before. The old decay's derivative came from Ceres's expm1, which
    // takes e^x as expm1(x) + 1: an absolute error of an ulp of r h.
    const Jet r = Seeded(in.r, 0), a = Seeded(in.a, 1), kr = Seeded(in.kr, 2);
    EXPECT_TRUE(NearJet(ChargedState(a, kr, in.h, r), OldEditorStep(r, a, kr, in.h), ChargedStateScale(a, kr, in.h, r),
                        2 * eps * (std::max(1.0, in.r) + in.r * in.h)))
        << in.r << " " << in.a << " " << in.kr << " " << in.h;
  }
  // In the dark after 40 time constants: e^{-40} r, not 0.
  EXPECT_TRUE(testing::RelativelyNear(ChargedState(0.0, 1.0, 40.0, 0.5), testing::ClosedForm(0.5, 0, 1, 40), 1e-14));
  EXPECT_EQ(OldEditorStep(0.5, 0.0, 1.0, 40.0), 0.0);
}

// ---- render/ and acquire/ ----------------------------------------------------------

TEST(ClosedForm, PhosphorMapLevelAndSimLabIntegralAreTheOldOnes) {
  RandomInputs random(6);
  for (int trial = 0; trial < kTrials; ++trial) {
    Inputs in = random.Next();
    EXPECT_TRUE(WithinUlps(StateIntegral(in.a, in.kr, in.h, in.r), OldSimLabIntegral(in.r, in.a, in.kr, in.h), 2))
        << in.r << " " << in.a << " " << in.kr << " " << in.h;
    if (in.a == 0) in.a = 1e-3;  // the map refuses a charge that excites nothing
    EXPECT_TRUE(WithinUlps(ChargedState(in.a, in.kr, in.h), OldPhosphorMapLevel(in.a, in.kr, in.h), 2))
        << in.a << " " << in.kr << " " << in.h;
  }
  EXPECT_EQ(StateIntegral(0.0, 0.0, 2.0, 0.25), 0.5);  // k = 0: r0 t
}

TEST(ClosedForm, EmittedRadianceIsTheLoopTheRendererAndTheLabWrote) {
  // glassner.cpp and sim_lab.cpp summed Lambda_i[b] kr_i r_i over the states per band.
  const Material material = LoadMaterial(testing::Fixture("materials/green.json"));
  RandomInputs random(7);
  for (int trial = 0; trial < 100; ++trial) {
    std::vector<double> r;
    for (int i = 0; i < material.state_count(); ++i) r.push_back(random.Next().r);
    const std::vector<double> L = EmittedRadiance(material, r.data());
    ASSERT_EQ(static_cast<int>(L.size()), material.band_count());
    for (int b = 0; b < material.band_count(); ++b) {
      double old = 0;
      for (int i = 0; i < material.state_count(); ++i)
        old += material.states[i].Lambda[b] * material.states[i].kr * r[i];
      EXPECT_TRUE(WithinUlps(L[b], old, 2));
    }
  }
}

// ---- what fit/src/session_fit.cpp still writes by hand ---------------------------

TEST(ClosedForm, SessionFitsSinhMeanIsDecayFactorOverTheExposure) {
  // e^{-k t} sinh(k e / 2) / (k e / 2) around the middle t = d + e/2 of the
  // exposure is DecayFactor(k, d, e): session_fit.cpp's JointDecayResidual
  // and CorrectForExposure may call it with d = t - e/2.
  RandomInputs random(8);
  for (int trial = 0; trial < kTrials; ++trial) {
    const double k = random.LogUniform(1e-6, 1e3), e = random.LogUniform(1e-12, 30) / k;
    const double d = random.LogUniform(1e-12, 30) / k, t = d + e / 2;
    EXPECT_TRUE(testing::RelativelyNear(DecayFactor(k, t - e / 2, e), SessionFitSinhMean(k, t, e), 1e-13))
        << k << " " << d << " " << e;
  }
}

}  // namespace
}  // namespace phos
