// The batch kernel against the scalar steps it vectorizes, its parallel path
// against its serial path, and "model only what the scene requires".

#include "phos/model/batch.h"

#include <cmath>
#include <gtest/gtest.h>
#include <random>

#include "model/closed_form.h"
#include "phos/model/simulate.h"
#include "phos/model/synthetic.h"
#include "phos/util/error.h"
#include "test_util.h"

namespace phos {
namespace {

Material TwoStateMaterial() {
  Material m;
  m.name = "two-state";
  m.bands = SpectralGrid::Paper();
  m.states.push_back({0.3, {0.2, 0.1, 0.05, 0.01, 0, 0, 0, 0}, {0, 0, 0.1, 0.6, 0.2, 0, 0, 0}, {}, {}});
  m.states.push_back({0.01, {0.02, 0.03, 0.01, 0.0, 0, 0, 0, 0}, {0, 0.1, 0.3, 0.2, 0, 0, 0, 0}, {}, {}});
  return m;
}

struct Scene {
  std::size_t n;
  std::vector<double> E;  // [3 * n]: bands 0..2 lit
  StateBatch<double> s;
};

Scene RandomScene(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  Scene scene{n, std::vector<double>(3 * n), StateBatch<double>(2, n)};
  for (double& e : scene.E) e = 10 * u(rng);
  for (double& r : scene.s.r) r = u(rng);
  return scene;
}

TEST(Batch, MatchesTheScalarStepsOfEveryIntegrator) {
  Material m = TwoStateMaterial();
  auto c = BatchCoefficients<double>::Compile(m, {0, 1, 2}, {2, 3}, "m");
  for (Integrator integrator : {Integrator::kExact, Integrator::kEuler, Integrator::kRk4}) {
    Scene scene = RandomScene(1000, 1);
    StateBatch<double> before = scene.s;
    std::vector<double> Lp(2 * scene.n);
    BatchStepInfo info = AdvanceBatch<double>(integrator, c, scene.E.data(), scene.n, 0.1, scene.s, Lp.data(), scene.n);
    double max_hk = 0;
    for (std::size_t j = 0; j < scene.n; ++j) {
      std::vector<double> E8(8, 0.0);
      for (int b = 0; b < 3; ++b) E8[b] = scene.E[b * scene.n + j];
      std::vector<double> a = ExcitationRates(m, E8, "m");
      double r[2];
      for (int i = 0; i < 2; ++i) {
        double r0 = before.state(i)[j], kr = m.states[i].kr;
        max_hk = std::max(max_hk, 0.1 * (a[i] + kr));
        r[i] = integrator == Integrator::kExact   ? ExactStep(r0, a[i], kr, 0.1)
               : integrator == Integrator::kEuler ? EulerStep(r0, a[i], kr, 0.1)
                                                  : Rk4Step(r0, a[i], kr, 0.1);
        EXPECT_TRUE(testing::RelativelyNear(scene.s.state(i)[j], r[i], 1e-14));
      }
      std::vector<double> L = EmittedRadiance(m, r);
      EXPECT_TRUE(testing::RelativelyNear(Lp[j], L[2], 1e-14));
      EXPECT_TRUE(testing::RelativelyNear(Lp[scene.n + j], L[3], 1e-14));
    }
    if (integrator == Integrator::kExact)
      EXPECT_EQ(info.max_hk, 0.0);
    else
      EXPECT_NEAR(info.max_hk, max_hk, 1e-12 * max_hk);
  }
}

TEST(Batch, ParallelChunksGiveTheSameBitsAsOneThread) {
  // 100k points take the TBB path; each point's result must not depend on it.
  Material m = TwoStateMaterial();
  auto c = BatchCoefficients<double>::Compile(m, {0, 1, 2}, {}, "m");
  Scene big = RandomScene(100'000, 2);
  Scene small{1000, {}, StateBatch<double>(2, 1000)};
  for (int b = 0; b < 3; ++b)
    small.E.insert(small.E.end(), big.E.begin() + b * big.n + 50'000, big.E.begin() + b * big.n + 51'000);
  for (int i = 0; i < 2; ++i) std::copy_n(big.s.state(i) + 50'000, 1000, small.s.state(i));
  AdvanceBatch<double>(Integrator::kExact, c, big.E.data(), big.n, 2.0, big.s);
  AdvanceBatch<double>(Integrator::kExact, c, small.E.data(), small.n, 2.0, small.s);
  for (int i = 0; i < 2; ++i)
    for (std::size_t j = 0; j < 1000; ++j) ASSERT_EQ(big.s.state(i)[50'000 + j], small.s.state(i)[j]);
}

TEST(Batch, DarkStepIsTheClosedFormJump) {
  Material m = TwoStateMaterial();
  auto c = BatchCoefficients<double>::Compile(m, {}, {}, "m");
  Scene scene = RandomScene(500, 3);
  StateBatch<double> before = scene.s;
  DecayBatch<double>(c, 3600.0, scene.s);  // an hour after lights-out, in one step
  for (int i = 0; i < 2; ++i)
    for (std::size_t j = 0; j < scene.n; ++j)
      EXPECT_TRUE(testing::RelativelyNear(
          scene.s.state(i)[j], before.state(i)[j] * std::exp(-static_cast<long double>(m.states[i].kr) * 3600), 1e-13));
}

TEST(Batch, OnlyTheBandsThatCarryLightAreComputed) {
  // Compiling for bands 0..2 gives the same states as all 8 bands with zeros
  // in 3..7, and it refuses a band whose ke is unknown.
  Material m = TwoStateMaterial();
  auto few = BatchCoefficients<double>::Compile(m, {0, 1, 2}, {}, "m");
  auto all = BatchCoefficients<double>::Compile(m, {0, 1, 2, 3, 4, 5, 6, 7}, {}, "m");
  EXPECT_EQ(few.n_exc, 3);
  Scene scene = RandomScene(300, 4);
  StateBatch<double> s_all = scene.s;
  std::vector<double> E_all(8 * scene.n, 0.0);
  std::copy(scene.E.begin(), scene.E.end(), E_all.begin());
  AdvanceBatch<double>(Integrator::kExact, few, scene.E.data(), scene.n, 0.5, scene.s);
  AdvanceBatch<double>(Integrator::kExact, all, E_all.data(), scene.n, 0.5, s_all);
  for (std::size_t k = 0; k < scene.s.r.size(); ++k)
    EXPECT_TRUE(testing::RelativelyNear(scene.s.r[k], s_all.r[k], 1e-15));

  Material green = LoadMaterial(testing::Fixture("materials/green.json"));
  EXPECT_THROW(BatchCoefficients<float>::Compile(green, {0, 3}, {}, "green.json"), UserError);
  EXPECT_NO_THROW(BatchCoefficients<float>::Compile(green, {0, 1, 2}, {0, 1, 2, 3, 4, 5, 6, 7}, "green.json"));
}

TEST(Batch, FloatAgreesWithDouble) {
  Material m = TwoStateMaterial();
  auto cd = BatchCoefficients<double>::Compile(m, {0, 1, 2}, {3}, "m");
  auto cf = BatchCoefficients<float>::Compile(m, {0, 1, 2}, {3}, "m");
  Scene scene = RandomScene(2000, 5);
  std::vector<float> Ef(scene.E.begin(), scene.E.end());
  StateBatch<float> sf(2, scene.n);
  std::copy(scene.s.r.begin(), scene.s.r.end(), sf.r.begin());
  std::vector<double> Ld(scene.n);
  std::vector<float> Lf(scene.n);
  for (int step = 0; step < 100; ++step) {
    AdvanceBatch<double>(Integrator::kExact, cd, scene.E.data(), scene.n, 0.05, scene.s, Ld.data(), scene.n);
    AdvanceBatch<float>(Integrator::kExact, cf, Ef.data(), scene.n, 0.05f, sf, Lf.data(), scene.n);
  }
  for (std::size_t j = 0; j < scene.n; ++j) EXPECT_TRUE(testing::RelativelyNear(Lf[j], Ld[j], 1e-5, 1e-30));
}

}  // namespace

// A phosphor map's batch (BatchCoefficients::per_point): every point decays at
// its own kr and emits by its own scale, exactly as the scalar steps of that
// point's material would, in every integrator, lit and dark, over a count
// that is not a multiple of the packet width.
BatchCoefficients<double> WithRandomMap(BatchCoefficients<double> c, std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> log_kr(std::log(1e-4), std::log(50.0)), scale(0.0, 3.0);
  for (int i = 0; i < c.nc; ++i)
    for (std::size_t j = 0; j < n; ++j) {
      c.kr_per_point.push_back(std::exp(log_kr(rng)));
      c.emission_scale.push_back(scale(rng));
    }
  return c;
}

TEST(Batch, PerPointParametersMatchTheScalarStepsOfEachPoint) {
  Material m = TwoStateMaterial();
  const std::size_t n = 1003;
  auto c = WithRandomMap(BatchCoefficients<double>::Compile(m, {0, 1, 2}, {2, 3}, "m"), n, 7);
  for (Integrator integrator : {Integrator::kExact, Integrator::kEuler, Integrator::kRk4}) {
    Scene scene = RandomScene(n, 8);
    StateBatch<double> before = scene.s;
    std::vector<double> Lp(2 * n);
    const double h = integrator == Integrator::kExact ? 30.0 : 0.01;
    BatchStepInfo info = AdvanceBatch<double>(integrator, c, scene.E.data(), n, h, scene.s, Lp.data(), n);
    double max_hk = 0;
    for (std::size_t j = 0; j < n; ++j) {
      std::vector<double> E8(8, 0.0);
      for (int b = 0; b < 3; ++b) E8[b] = scene.E[b * n + j];
      std::vector<double> a = ExcitationRates(m, E8, "m");
      double L2 = 0, L3 = 0;
      for (int i = 0; i < 2; ++i) {
        const double r0 = before.state(i)[j], kr = c.kr_per_point[i * n + j];
        max_hk = std::max(max_hk, h * (a[i] + kr));
        const double r = integrator == Integrator::kExact   ? ExactStep(r0, a[i], kr, h)
                         : integrator == Integrator::kEuler ? EulerStep(r0, a[i], kr, h)
                                                            : Rk4Step(r0, a[i], kr, h);
        EXPECT_TRUE(testing::RelativelyNear(scene.s.state(i)[j], r, 1e-13)) << j;
        const double scale = c.emission_scale[i * n + j];
        L2 += m.states[i].Lambda[2] * m.states[i].kr * scale * r;
        L3 += m.states[i].Lambda[3] * m.states[i].kr * scale * r;
      }
      EXPECT_TRUE(testing::RelativelyNear(Lp[j], L2, 1e-13));
      EXPECT_TRUE(testing::RelativelyNear(Lp[n + j], L3, 1e-13));
    }
    if (integrator != Integrator::kExact) {
      EXPECT_NEAR(info.max_hk, max_hk, 1e-12 * max_hk);
    }
  }
  // In the dark each point jumps by its own e^{-kr h}, and Lp follows.
  Scene scene = RandomScene(n, 9);
  StateBatch<double> before = scene.s;
  std::vector<double> Lp(2 * n), Lp_emit(2 * n);
  DecayBatch<double>(c, 600.0, scene.s, Lp.data(), n);
  EmitBatch<double>(c, scene.s, Lp_emit.data(), n);
  for (std::size_t j = 0; j < n; ++j) {
    double L3 = 0;
    for (int i = 0; i < 2; ++i) {
      const double kr = c.kr_per_point[i * n + j];
      EXPECT_TRUE(testing::RelativelyNear(scene.s.state(i)[j],
                                          before.state(i)[j] * std::exp(-static_cast<long double>(kr) * 600), 1e-13));
      L3 += m.states[i].Lambda[3] * m.states[i].kr * c.emission_scale[i * n + j] * scene.s.state(i)[j];
    }
    EXPECT_TRUE(testing::RelativelyNear(Lp[n + j], L3, 1e-13));
    EXPECT_EQ(Lp[n + j], Lp_emit[n + j]);
  }
}

TEST(Batch, AUniformMapGivesTheUniformMaterialsBits) {
  // kr_per_point = kr and scale 1 everywhere: the same states and Lp, bit for bit.
  Material m = TwoStateMaterial();
  const std::size_t n = 777;
  auto uniform = BatchCoefficients<float>::Compile(m, {0, 1, 2}, {2, 3}, "m");
  auto mapped = uniform;
  for (int i = 0; i < 2; ++i)
    for (std::size_t j = 0; j < n; ++j) {
      mapped.kr_per_point.push_back(uniform.kr[i]);
      mapped.emission_scale.push_back(1.0f);
    }
  Scene scene = RandomScene(n, 10);
  std::vector<float> E(scene.E.begin(), scene.E.end());
  StateBatch<float> a(2, n), b(2, n);
  std::copy(scene.s.r.begin(), scene.s.r.end(), a.r.begin());
  b.r = a.r;
  std::vector<float> La(2 * n), Lb(2 * n);
  for (int step = 0; step < 5; ++step) {
    AdvanceBatch<float>(Integrator::kExact, uniform, E.data(), n, 0.7f, a, La.data(), n);
    AdvanceBatch<float>(Integrator::kExact, mapped, E.data(), n, 0.7f, b, Lb.data(), n);
  }
  EXPECT_EQ(a.r, b.r);
  EXPECT_EQ(La, Lb);
  // In the dark the uniform batch takes one exp per state, the mapped one a
  // packet exp per point: the same to float rounding.
  DecayBatch<float>(uniform, 5.0f, a, La.data(), n);
  DecayBatch<float>(mapped, 5.0f, b, Lb.data(), n);
  for (std::size_t k = 0; k < a.r.size(); ++k) EXPECT_TRUE(testing::RelativelyNear(b.r[k], a.r[k], 3e-7)) << k;
  for (std::size_t k = 0; k < La.size(); ++k) EXPECT_TRUE(testing::RelativelyNear(Lb[k], La[k], 3e-7)) << k;
}

TEST(Batch, ManyStatesMatchTheScalarStepsOfEveryIntegrator) {
  // A many-trap material (5 to 16 states) takes the kernel whose state count
  // is not a constant: per point and state the scalar step, uniform and mapped.
  for (int states : {5, 9, 16}) {
    ManyTrapSpec spec;
    spec.states = states;
    spec.from_s = 0.5;  // rates up to 60/s: a step of 0.01 s is stable for RK4
    spec.to_s = 500;
    const Material m = ManyTrapMaterial(spec);
    const std::size_t n = 301;
    for (bool mapped : {false, true}) {
      auto c = BatchCoefficients<double>::Compile(m, {0, 1, 2}, {2, 3}, "m");
      if (mapped) c = WithRandomMap(c, n, 11);
      for (Integrator integrator : {Integrator::kExact, Integrator::kEuler, Integrator::kRk4}) {
        std::mt19937 rng(static_cast<unsigned>(states));
        std::uniform_real_distribution<double> u(0, 1);
        std::vector<double> E(3 * n);
        for (double& e : E) e = 10 * u(rng);
        StateBatch<double> s(states, n);
        for (double& r : s.r) r = u(rng);
        const StateBatch<double> before = s;
        std::vector<double> Lp(2 * n);
        const double h = integrator == Integrator::kExact ? 3.0 : 0.01;
        AdvanceBatch<double>(integrator, c, E.data(), n, h, s, Lp.data(), n);
        for (std::size_t j = 0; j < n; j += 7) {
          std::vector<double> E8(8, 0.0);
          for (int b = 0; b < 3; ++b) E8[b] = E[b * n + j];
          const std::vector<double> a = ExcitationRates(m, E8, "m");
          double L3 = 0;
          for (int i = 0; i < states; ++i) {
            const double r0 = before.state(i)[j], kr = mapped ? c.kr_per_point[i * n + j] : m.states[i].kr;
            const double r = integrator == Integrator::kExact   ? ExactStep(r0, a[i], kr, h)
                             : integrator == Integrator::kEuler ? EulerStep(r0, a[i], kr, h)
                                                                : Rk4Step(r0, a[i], kr, h);
            EXPECT_TRUE(testing::RelativelyNear(s.state(i)[j], r, 1e-13)) << states << " " << i << " " << j;
            L3 += m.states[i].Lambda[3] * m.states[i].kr * (mapped ? c.emission_scale[i * n + j] : 1.0) * r;
          }
          EXPECT_TRUE(testing::RelativelyNear(Lp[n + j], L3, 1e-12)) << states << " " << j;
        }
      }
    }
  }
}

}  // namespace phos
