#include "phos/model/batch.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Core>
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include "phos/model/schedule.h"
#include "phos/util/error.h"

namespace phos {
namespace {

// Points per chunk: every temporary of a chunk stays in L1, and the loop
// bodies are whole Eigen expressions that vectorize (exp and log have packet
// versions for float and double).
constexpr Eigen::Index kChunk = 256;
// Below this many points one thread does it all: TBB's overhead would dominate.
constexpr std::size_t kParallelThreshold = 1 << 15;

template <typename Real>
using ChunkArray = Eigen::Array<Real, Eigen::Dynamic, 1, 0, kChunk, 1>;
template <typename Real>
using ConstSegment = Eigen::Map<const Eigen::Array<Real, Eigen::Dynamic, 1>>;
template <typename Real>
using Segment = Eigen::Map<Eigen::Array<Real, Eigen::Dynamic, 1>>;

// e^x for x <= 0, vectorized. Eigen's packet exp clamps its argument at the
// bottom of the normal range (for double, e^-1000 comes back as 5.6e-309), so
// results below the smallest normal number are flushed to 0 here: a state
// under 1e-308 (1e-38 in float) is zero for every purpose of phos.
template <typename Real>
ChunkArray<Real> Exp(const ChunkArray<Real>& x) {
  const Real lowest = std::log(std::numeric_limits<Real>::min());
  return (x < lowest).select(ChunkArray<Real>::Zero(x.size()), x.exp());
}

// 1 - e^x for x <= 0, given u = Exp(x); accurate to a few ulp for every x.
// Eigen has no packet expm1 for double, so for |x| < 1 this is Kahan's
// identity expm1(x) = (u - 1) x / log(u), which cancels the rounding of u and
// loses no digits however small |x| is; for x <= -1, u <= 0.37 and 1 - u is
// already accurate (and log(u) would not be, near underflow).
template <typename Real>
ChunkArray<Real> OneMinusExp(const ChunkArray<Real>& x, const ChunkArray<Real>& u) {
  ChunkArray<Real> kahan = (Real(1) - u) * x / u.log();
  // u == 1: |x| is below half an ulp of 1 and 1 - e^x = -x to full precision.
  ChunkArray<Real> small = (u == Real(1)).select(-x, kahan);
  return (x <= Real(-1)).select(Real(1) - u, small);
}

template <typename Real>
void EmitChunk(const BatchCoefficients<Real>& c, const StateBatch<Real>& s, Real* Lp, std::size_t Lp_stride,
               std::size_t j0, Eigen::Index m) {
  for (int b = 0; b < c.n_em; ++b) {
    Segment<Real> out(Lp + static_cast<std::size_t>(b) * Lp_stride + j0, m);
    out = c.emission[static_cast<std::size_t>(b) * c.nc] * ConstSegment<Real>(s.state(0) + j0, m);
    for (int i = 1; i < c.nc; ++i)
      out += c.emission[static_cast<std::size_t>(b) * c.nc + i] * ConstSegment<Real>(s.state(i) + j0, m);
  }
}

template <typename Real, Integrator kIntegrator>
double AdvanceChunk(const BatchCoefficients<Real>& c, const Real* E, std::size_t E_stride, Real h,
                    StateBatch<Real>& s, Real* Lp, std::size_t Lp_stride, std::size_t j0, Eigen::Index m) {
  double max_hk = 0.0;
  ChunkArray<Real> a(m);
  for (int i = 0; i < c.nc; ++i) {
    // a = sum_b ke[b] E[b] (Eq. 8.1), only over the bands that carry light.
    a.setZero();
    for (int b = 0; b < c.n_exc; ++b)
      a += c.ke[static_cast<std::size_t>(i) * c.n_exc + b] *
           ConstSegment<Real>(E + static_cast<std::size_t>(b) * E_stride + j0, m);
    const Real kr = c.kr[i];
    Segment<Real> r(s.state(i) + j0, m);
    if constexpr (kIntegrator == Integrator::kExact) {
      ChunkArray<Real> k = a + kr;
      ChunkArray<Real> x = -h * k;
      ChunkArray<Real> decay = Exp<Real>(x);
      ChunkArray<Real> r_inf = a / k.max(std::numeric_limits<Real>::min());
      // Convex combination of r and r_inf; the clamp removes rounding ulps only.
      r = (r * decay + r_inf * OneMinusExp<Real>(x, decay)).max(Real(0)).min(Real(1));
    } else if constexpr (kIntegrator == Integrator::kEuler) {
      max_hk = std::max(max_hk, static_cast<double>(h * (a.maxCoeff() + kr)));
      r += h * (a * (Real(1) - r) - kr * r);
    } else {
      static_assert(kIntegrator == Integrator::kRk4);
      max_hk = std::max(max_hk, static_cast<double>(h * (a.maxCoeff() + kr)));
      auto f = [&](const ChunkArray<Real>& x) -> ChunkArray<Real> { return a * (Real(1) - x) - kr * x; };
      ChunkArray<Real> k1 = f(r);
      ChunkArray<Real> k2 = f(r + Real(0.5) * h * k1);
      ChunkArray<Real> k3 = f(r + Real(0.5) * h * k2);
      ChunkArray<Real> k4 = f(r + h * k3);
      r += (h / Real(6)) * (k1 + Real(2) * k2 + Real(2) * k3 + k4);
    }
  }
  if (Lp != nullptr) EmitChunk(c, s, Lp, Lp_stride, j0, m);
  return max_hk;
}

// Runs body(j0, m) -> double over all chunks, in parallel for large batches;
// returns the max of the results.
template <typename Body>
double ForEachChunk(std::size_t n, Body body) {
  const std::size_t chunks = (n + kChunk - 1) / kChunk;
  auto run = [&](std::size_t c0, std::size_t c1, double init) {
    for (std::size_t c = c0; c < c1; ++c) {
      std::size_t j0 = c * kChunk;
      init = std::max(init, body(j0, static_cast<Eigen::Index>(std::min<std::size_t>(kChunk, n - j0))));
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
                                                         const std::string& where) {
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
      c.ke.push_back(static_cast<Real>(ExcitationRates(material, probe, where)[i]));
    }
  }
  for (int band : emission_bands)
    for (int i = 0; i < c.nc; ++i)
      c.emission.push_back(static_cast<Real>(material.states[i].Lambda[band] * material.states[i].kr));
  return c;
}

template <typename Real>
BatchStepInfo AdvanceBatch(Integrator integrator, const BatchCoefficients<Real>& c, const Real* E,
                           std::size_t E_stride, Real h_s, StateBatch<Real>& s, Real* Lp, std::size_t Lp_stride) {
  PHOS_CHECK(s.nc == c.nc);
  PHOS_CHECK(c.n_exc == 0 || E != nullptr);
  BatchStepInfo info;
  switch (integrator) {
    case Integrator::kExact:
      ForEachChunk(s.n, [&](std::size_t j0, Eigen::Index m) {
        return AdvanceChunk<Real, Integrator::kExact>(c, E, E_stride, h_s, s, Lp, Lp_stride, j0, m);
      });
      break;
    case Integrator::kEuler:
      info.max_hk = ForEachChunk(s.n, [&](std::size_t j0, Eigen::Index m) {
        return AdvanceChunk<Real, Integrator::kEuler>(c, E, E_stride, h_s, s, Lp, Lp_stride, j0, m);
      });
      break;
    case Integrator::kRk4:
      info.max_hk = ForEachChunk(s.n, [&](std::size_t j0, Eigen::Index m) {
        return AdvanceChunk<Real, Integrator::kRk4>(c, E, E_stride, h_s, s, Lp, Lp_stride, j0, m);
      });
      break;
    case Integrator::kReference:
      PHOS_CHECK(!"the reference integrator is scalar: use Simulate()");
  }
  return info;
}

template <typename Real>
void DecayBatch(const BatchCoefficients<Real>& c, Real h_s, StateBatch<Real>& s) {
  PHOS_CHECK(s.nc == c.nc);
  // In the dark a = 0, so e^{-kr h} is one number per state: a multiply per point.
  for (int i = 0; i < c.nc; ++i) {
    const Real decay = std::exp(-c.kr[i] * h_s);
    Real* r = s.state(i);
    ForEachChunk(s.n, [&](std::size_t j0, Eigen::Index m) {
      Segment<Real>(r + j0, m) *= decay;
      return 0.0;
    });
  }
}

template <typename Real>
void EmitBatch(const BatchCoefficients<Real>& c, const StateBatch<Real>& s, Real* Lp, std::size_t Lp_stride) {
  PHOS_CHECK(s.nc == c.nc);
  ForEachChunk(s.n, [&](std::size_t j0, Eigen::Index m) {
    EmitChunk(c, s, Lp, Lp_stride, j0, m);
    return 0.0;
  });
}

#define PHOS_INSTANTIATE_BATCH(Real)                                                                       \
  template struct BatchCoefficients<Real>;                                                                 \
  template BatchStepInfo AdvanceBatch<Real>(Integrator, const BatchCoefficients<Real>&, const Real*,       \
                                            std::size_t, Real, StateBatch<Real>&, Real*, std::size_t);     \
  template void DecayBatch<Real>(const BatchCoefficients<Real>&, Real, StateBatch<Real>&);                 \
  template void EmitBatch<Real>(const BatchCoefficients<Real>&, const StateBatch<Real>&, Real*, std::size_t);
PHOS_INSTANTIATE_BATCH(float)
PHOS_INSTANTIATE_BATCH(double)

}  // namespace phos
