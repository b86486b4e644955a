#include "phos/model/batch.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <type_traits>

#include <Eigen/Core>
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include "phos/model/schedule.h"
#include "phos/util/error.h"

namespace phos {
namespace {

// Points per chunk handed to one task.
constexpr std::size_t kChunk = 1024;
// Below this many points one thread does it all: TBB's overhead would dominate.
constexpr std::size_t kParallelThreshold = 1 << 15;

// The kernel is one pass over memory with everything in registers: per
// packet of points (8 floats or 4 doubles with AVX2) it loads the irradiance
// of each lit band once, forms a_i for every state, advances each state and
// writes Lp. It uses Eigen's packet math (exp for float and double) directly;
// an expression per step would make a pass over L1 per operation and run
// several times slower (docs/model.md has the measurements).
namespace ei = Eigen::internal;

template <typename Real>
using Packet = typename ei::packet_traits<Real>::type;
template <typename Real>
constexpr int kPacketSize = ei::unpacket_traits<Packet<Real>>::size;

// 1 - e^x for -1/2 < x <= 0 as the Taylor series -x * sum_n x^n / (n+1)!,
// cut where the next term is below half an ulp (degree 7 in float, 13 in
// double). A naive 1 - e^x would lose every digit as x -> 0 (charging from
// r = 0 with a short step), and Eigen has no packet expm1 for double.
template <typename Real>
EIGEN_STRONG_INLINE Packet<Real> OneMinusExpSeries(const Packet<Real>& x) {
  using P = Packet<Real>;
  // 1/(n+1)!, n = 0..13; float uses the first 8.
  static constexpr double kInverseFactorial[] = {
      1.0,         1.0 / 2,      1.0 / 6,       1.0 / 24,       1.0 / 120,       1.0 / 720,        1.0 / 5040,
      1.0 / 40320, 1.0 / 362880, 1.0 / 3628800, 1.0 / 39916800, 1.0 / 479001600, 1.0 / 6227020800, 1.0 / 87178291200};
  constexpr int kDegree = sizeof(Real) == 4 ? 7 : 13;
  P series = ei::pset1<P>(static_cast<Real>(kInverseFactorial[kDegree]));
  for (int n = kDegree - 1; n >= 0; --n)
    series = ei::pmadd(series, x, ei::pset1<P>(static_cast<Real>(kInverseFactorial[n])));
  return ei::pmul(ei::pnegate(x), series);
}

// e^x for x <= 0. Eigen's packet exp clamps its argument at the bottom of the
// normal range (in double, e^-1000 comes back as 5.6e-309), so results below
// the smallest normal number are flushed to 0: a state under 1e-308 (1e-38
// in float) is zero for every purpose of phos.
template <typename Real>
EIGEN_STRONG_INLINE Packet<Real> ExpNonPositive(const Packet<Real>& x) {
  using P = Packet<Real>;
  static const Real lowest = std::log(std::numeric_limits<Real>::min());
  return ei::pselect(ei::pcmp_lt(x, ei::pset1<P>(lowest)), ei::pzero(x), ei::pexp(x));
}

// One packet of one state; returns k = a + kr for the stability check.
template <typename Real, Integrator kIntegrator>
EIGEN_STRONG_INLINE Packet<Real> StepPacket(Packet<Real>& r, const Packet<Real>& a, const Packet<Real>& kr, Real h) {
  using P = Packet<Real>;
  const P k = ei::padd(a, kr);
  const P one = ei::pset1<P>(Real(1)), zero = ei::pzero(k);
  if constexpr (kIntegrator == Integrator::kExact) {
    // r(t+h) = r e^{-kh} + r_inf (1 - e^{-kh}), r_inf = a / k (Eq. 8.1, exact)
    const P x = ei::pmul(k, ei::pset1<P>(-h));
    const P half = ei::pset1<P>(Real(-0.5));
    // rise = 1 - e^{-kh}, decay = e^{-kh}, both to a few ulp. For kh < 1/2
    // the series gives rise and decay = 1 - rise loses nothing (decay > 0.6):
    // no exp at all, the common case of frame-sized steps. Past that,
    // decay < 0.61 and rise = 1 - decay loses nothing.
    // Each packet pays only for the branch its lanes need.
    P rise, decay;
    if (ei::predux_min(x) > Real(-0.5)) {
      rise = OneMinusExpSeries<Real>(x);
      decay = ei::psub(one, rise);
    } else if (ei::predux_max(x) <= Real(-0.5)) {
      decay = ExpNonPositive<Real>(x);
      rise = ei::psub(one, decay);
    } else {
      const P large = ei::pcmp_le(x, half), series = OneMinusExpSeries<Real>(x);
      decay = ei::pselect(large, ExpNonPositive<Real>(x), ei::psub(one, series));
      rise = ei::pselect(large, ei::psub(one, decay), series);
    }
    const P r_inf = ei::pdiv(a, ei::pmax(k, ei::pset1<P>(std::numeric_limits<Real>::min())));
    const P next = ei::pmadd(r, decay, ei::pmul(r_inf, rise));
    // The exact value lies between r and r_inf; the clamp removes rounding ulps only.
    r = ei::pmin(one, ei::pmax(zero, next));
  } else {
    // f(r) = a (1 - r) - kr r = a - k r
    const P h_p = ei::pset1<P>(h);
    auto f = [&](const P& x) { return ei::psub(a, ei::pmul(k, x)); };
    if constexpr (kIntegrator == Integrator::kEuler) {
      r = ei::pmadd(h_p, f(r), r);
    } else {
      const P half_h = ei::pset1<P>(Real(0.5) * h);
      const P k1 = f(r);
      const P k2 = f(ei::pmadd(half_h, k1, r));
      const P k3 = f(ei::pmadd(half_h, k2, r));
      const P k4 = f(ei::pmadd(h_p, k3, r));
      const P sum = ei::padd(ei::padd(k1, k4), ei::pmul(ei::pset1<P>(Real(2)), ei::padd(k2, k3)));
      r = ei::pmadd(ei::pset1<P>(h / Real(6)), sum, r);
    }
  }
  return k;
}

template <typename Real, Integrator kIntegrator>
Real StepScalar(Real r, Real a, Real kr, Real h) {
  if constexpr (kIntegrator == Integrator::kExact)
    return ExactStep(r, a, kr, h);
  else if constexpr (kIntegrator == Integrator::kEuler)
    return EulerStep(r, a, kr, h);
  else
    return Rk4Step(r, a, kr, h);
}

// Points [j0, j1) of a batch with kStates states, or with c.nc of them
// (up to kMaxStates) when kStates is 0: the many-trap materials of 5 to 16
// states (model/synthetic.h) take that one kernel, with the state loops not
// unrolled, while 1 to 4 states keep theirs, the count a constant.
// kPerPoint: each point has its own kr and emission scale
// (BatchCoefficients::per_point). Returns max k (1/s).
template <typename Real, Integrator kIntegrator, int kCount, bool kPerPoint>
Real AdvanceRange(const BatchCoefficients<Real>& c, const Real* E, std::size_t E_stride, Real h, StateBatch<Real>& s,
                  Real* Lp, std::size_t Lp_stride, std::size_t j0, std::size_t j1) {
  using P = Packet<Real>;
  constexpr int W = kPacketSize<Real>;
  constexpr int kSlots = kCount > 0 ? kCount : kMaxStates;
  const int kStates = kCount > 0 ? kCount : c.nc;
  const std::size_t n = s.n;
  Real* r_base = s.r.data();
  const Real* kr_base = kPerPoint ? c.kr_per_point.data() : nullptr;
  const Real* scale_base = kPerPoint ? c.emission_scale.data() : nullptr;
  P kr_uniform[kSlots];
  for (int i = 0; i < kStates; ++i) kr_uniform[i] = ei::pset1<P>(c.kr[i]);
  P k_max = ei::pzero(P());
  std::size_t j = j0;
  for (; j + W <= j1; j += W) {
    P a[kSlots];
    for (int i = 0; i < kStates; ++i) a[i] = ei::pzero(P());
    for (int b = 0; b < c.n_exc; ++b) {
      const P e = ei::ploadu<P>(E + b * E_stride + j);
      for (int i = 0; i < kStates; ++i) a[i] = ei::pmadd(ei::pset1<P>(c.ke[i * c.n_exc + b]), e, a[i]);
    }
    P r[kSlots];
    for (int i = 0; i < kStates; ++i) {
      r[i] = ei::ploadu<P>(r_base + i * n + j);
      const P kr = kPerPoint ? ei::ploadu<P>(kr_base + i * n + j) : kr_uniform[i];
      k_max = ei::pmax(k_max, StepPacket<Real, kIntegrator>(r[i], a[i], kr, h));
      ei::pstoreu(r_base + i * n + j, r[i]);
    }
    if (Lp != nullptr) {
      // What each state emits per unit of emission[b, i]: r, or r times the point's scale.
      P w[kSlots];
      for (int i = 0; i < kStates; ++i) w[i] = kPerPoint ? ei::pmul(ei::ploadu<P>(scale_base + i * n + j), r[i]) : r[i];
      for (int b = 0; b < c.n_em; ++b) {  // Eq. 8.2
        P L = ei::pmul(ei::pset1<P>(c.emission[b * kStates]), w[0]);
        for (int i = 1; i < kStates; ++i) L = ei::pmadd(ei::pset1<P>(c.emission[b * kStates + i]), w[i], L);
        ei::pstoreu(Lp + b * Lp_stride + j, L);
      }
    }
  }
  Real k_tail = 0;
  for (; j < j1; ++j) {  // the last few points, one at a time
    for (int i = 0; i < kStates; ++i) {
      Real a = 0;
      for (int b = 0; b < c.n_exc; ++b) a += c.ke[i * c.n_exc + b] * E[b * E_stride + j];
      const Real kr = kPerPoint ? kr_base[i * n + j] : c.kr[i];
      Real& r = r_base[i * n + j];
      r = StepScalar<Real, kIntegrator>(r, a, kr, h);
      k_tail = std::max(k_tail, a + kr);
    }
    if (Lp != nullptr)
      for (int b = 0; b < c.n_em; ++b) {
        Real L = 0;
        for (int i = 0; i < kStates; ++i)
          L += c.emission[b * kStates + i] * (kPerPoint ? scale_base[i * n + j] : Real(1)) * r_base[i * n + j];
        Lp[b * Lp_stride + j] = L;
      }
  }
  return std::max(k_tail, ei::predux_max(k_max));
}

// Per-point parameters, when given, are one per state and point of the batch.
template <typename Real>
void CheckPerPoint(const BatchCoefficients<Real>& c, const StateBatch<Real>& s) {
  if (!c.per_point()) return;
  PHOS_CHECK(c.kr_per_point.size() == static_cast<std::size_t>(c.nc) * s.n);
  PHOS_CHECK(c.emission_scale.size() == c.kr_per_point.size());
}

// Runs body(j0, j1) -> double over the chunks [j0, j1), in parallel for large batches;
// returns the max of the results.
template <typename Body>
double ForEachChunk(std::size_t n, Body body) {
  const std::size_t chunks = (n + kChunk - 1) / kChunk;
  auto run = [&](std::size_t c0, std::size_t c1, double init) {
    for (std::size_t c = c0; c < c1; ++c) {
      std::size_t j0 = c * kChunk;
      init = std::max(init, body(j0, std::min<std::size_t>(j0 + kChunk, n)));
    }
    return init;
  };
  if (n < kParallelThreshold) return run(0, chunks, 0.0);
  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, chunks, 16), 0.0,
      [&](const tbb::blocked_range<std::size_t>& range, double init) { return run(range.begin(), range.end(), init); },
      [](double x, double y) { return std::max(x, y); });
}

}  // namespace

template <typename Real>
BatchCoefficients<Real> BatchCoefficients<Real>::Compile(const Material& material,
                                                         const std::vector<int>& excitation_bands,
                                                         const std::vector<int>& emission_bands,
                                                         const std::string& where, const std::string& remedy) {
  BatchCoefficients<Real> c;
  c.nc = material.state_count();
  c.n_exc = static_cast<int>(excitation_bands.size());
  c.n_em = static_cast<int>(emission_bands.size());
  for (int band : excitation_bands) PHOS_CHECK(band >= 0 && band < material.band_count());
  for (int band : emission_bands) PHOS_CHECK(band >= 0 && band < material.band_count());
  for (int i = 0; i < c.nc; ++i) {
    const ExcitedState& state = material.states[i];
    c.kr.push_back(static_cast<Real>(state.kr));
    for (int band : excitation_bands) {
      // Reuse the one check of unknown ke: probe with unit irradiance in that band.
      std::vector<double> probe(static_cast<std::size_t>(material.band_count()), 0.0);
      probe[band] = 1.0;
      c.ke.push_back(static_cast<Real>(ExcitationRates(material, probe, where, remedy)[i]));
    }
  }
  for (int band : emission_bands)
    for (int i = 0; i < c.nc; ++i)
      c.emission.push_back(static_cast<Real>(material.states[i].Lambda[band] * material.states[i].kr));
  return c;
}

template <typename Real, Integrator kIntegrator>
Real AdvanceAll(const BatchCoefficients<Real>& c, const Real* E, std::size_t E_stride, Real h, StateBatch<Real>& s,
                Real* Lp, std::size_t Lp_stride) {
  // The state count is a template argument so that a[] and r[] stay in
  // registers; 0 for more than 4 (AdvanceRange).
  auto run = [&](auto states) {
    constexpr int kStates = decltype(states)::value;
    return ForEachChunk(s.n, [&](std::size_t j0, std::size_t j1) {
      return static_cast<double>(
          c.per_point() ? AdvanceRange<Real, kIntegrator, kStates, true>(c, E, E_stride, h, s, Lp, Lp_stride, j0, j1)
                        : AdvanceRange<Real, kIntegrator, kStates, false>(c, E, E_stride, h, s, Lp, Lp_stride, j0, j1));
    });
  };
  switch (c.nc) {
    case 1: return static_cast<Real>(run(std::integral_constant<int, 1>()));
    case 2: return static_cast<Real>(run(std::integral_constant<int, 2>()));
    case 3: return static_cast<Real>(run(std::integral_constant<int, 3>()));
    case 4: return static_cast<Real>(run(std::integral_constant<int, 4>()));
  }
  PHOS_CHECK(c.nc > 4 && c.nc <= kMaxStates);
  return static_cast<Real>(run(std::integral_constant<int, 0>()));
}

template <typename Real>
BatchStepInfo AdvanceBatch(Integrator integrator, const BatchCoefficients<Real>& c, const Real* E, std::size_t E_stride,
                           Real h_s, StateBatch<Real>& s, Real* Lp, std::size_t Lp_stride) {
  PHOS_CHECK(s.nc == c.nc);
  CheckPerPoint(c, s);
  // An empty batch (a phosphorescent medium with no voxel of density > 0)
  // has nothing to advance, and its empty E may well be null.
  PHOS_CHECK(c.n_exc == 0 || s.n == 0 || E != nullptr);
  BatchStepInfo info;
  switch (integrator) {
    case Integrator::kExact: AdvanceAll<Real, Integrator::kExact>(c, E, E_stride, h_s, s, Lp, Lp_stride); break;
    case Integrator::kEuler:
      info.max_hk = h_s * AdvanceAll<Real, Integrator::kEuler>(c, E, E_stride, h_s, s, Lp, Lp_stride);
      break;
    case Integrator::kRk4:
      info.max_hk = h_s * AdvanceAll<Real, Integrator::kRk4>(c, E, E_stride, h_s, s, Lp, Lp_stride);
      break;
    case Integrator::kReference: PHOS_CHECK(!"the reference integrator is scalar: use Simulate()");
  }
  return info;
}

namespace {

// Eq. 8.2 over [j0, j1): Lp[b] = sum_i Lambda_i[b] kr_i r_i, band by band so
// that each inner loop is a contiguous multiply-add the compiler vectorizes.
template <typename Real>
void EmitRange(const BatchCoefficients<Real>& c, const StateBatch<Real>& s, Real* Lp, std::size_t Lp_stride,
               std::size_t j0, std::size_t j1) {
  for (int b = 0; b < c.n_em; ++b) {
    Real* __restrict out = Lp + b * Lp_stride;
    for (int i = 0; i < c.nc; ++i) {
      const Real e = c.emission[b * c.nc + i];
      const Real* __restrict r = s.state(i);
      if (c.per_point()) {
        const Real* __restrict scale = c.emission_scale.data() + static_cast<std::size_t>(i) * s.n;
        if (i == 0)
          for (std::size_t j = j0; j < j1; ++j) out[j] = e * scale[j] * r[j];
        else
          for (std::size_t j = j0; j < j1; ++j) out[j] += e * scale[j] * r[j];
      } else if (i == 0) {
        for (std::size_t j = j0; j < j1; ++j) out[j] = e * r[j];
      } else {
        for (std::size_t j = j0; j < j1; ++j) out[j] += e * r[j];
      }
    }
  }
}

// r *= e^{-kr h} with each point's own kr, a packet at a time.
template <typename Real>
void DecayRangePerPoint(const BatchCoefficients<Real>& c, Real h, StateBatch<Real>& s, std::size_t j0, std::size_t j1) {
  using P = Packet<Real>;
  constexpr int W = kPacketSize<Real>;
  const P minus_h = ei::pset1<P>(-h);
  for (int i = 0; i < c.nc; ++i) {
    Real* __restrict r = s.state(i);
    const Real* __restrict kr = c.kr_per_point.data() + static_cast<std::size_t>(i) * s.n;
    std::size_t j = j0;
    for (; j + W <= j1; j += W)
      ei::pstoreu(r + j,
                  ei::pmul(ei::ploadu<P>(r + j), ExpNonPositive<Real>(ei::pmul(ei::ploadu<P>(kr + j), minus_h))));
    for (; j < j1; ++j) r[j] *= DecayFactor(kr[j], h);
  }
}

}  // namespace

template <typename Real>
void DecayBatch(const BatchCoefficients<Real>& c, Real h_s, StateBatch<Real>& s, Real* Lp, std::size_t Lp_stride) {
  PHOS_CHECK(s.nc == c.nc);
  // In the dark a = 0, so e^{-kr h} is one number per state: a multiply per
  // point, exact for any h (the closed-form jump across dark intervals). The
  // emission of the chunk is written while its states are still in L1.
  // A mapped batch (per_point) takes one exp per point and state instead.
  CheckPerPoint(c, s);
  Real decay[kMaxStates];
  for (int i = 0; i < c.nc; ++i) decay[i] = DecayFactor(c.kr[i], h_s);
  ForEachChunk(s.n, [&](std::size_t j0, std::size_t j1) {
    if (c.per_point())
      DecayRangePerPoint(c, h_s, s, j0, j1);
    else
      for (int i = 0; i < c.nc; ++i) {
        Real* __restrict r = s.state(i);
        for (std::size_t j = j0; j < j1; ++j) r[j] *= decay[i];
      }
    if (Lp) EmitRange(c, s, Lp, Lp_stride, j0, j1);
    return 0.0;
  });
}

template <typename Real>
void EmitBatch(const BatchCoefficients<Real>& c, const StateBatch<Real>& s, Real* Lp, std::size_t Lp_stride) {
  PHOS_CHECK(s.nc == c.nc);
  CheckPerPoint(c, s);
  ForEachChunk(s.n, [&](std::size_t j0, std::size_t j1) {
    EmitRange(c, s, Lp, Lp_stride, j0, j1);
    return 0.0;
  });
}

#define PHOS_INSTANTIATE_BATCH(Real)                                                                              \
  template struct BatchCoefficients<Real>;                                                                        \
  template BatchStepInfo AdvanceBatch<Real>(Integrator, const BatchCoefficients<Real>&, const Real*, std::size_t, \
                                            Real, StateBatch<Real>&, Real*, std::size_t);                         \
  template void DecayBatch<Real>(const BatchCoefficients<Real>&, Real, StateBatch<Real>&, Real*, std::size_t);    \
  template void EmitBatch<Real>(const BatchCoefficients<Real>&, const StateBatch<Real>&, Real*, std::size_t);
PHOS_INSTANTIATE_BATCH(float)
PHOS_INSTANTIATE_BATCH(double)

}  // namespace phos
