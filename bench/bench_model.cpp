// Throughput of the batch kernel (texel-steps per second) next to the
// machine's memory bandwidth, measured in the same run by a STREAM-style copy
// (McCalpin's "Copy": a[i] = b[i], bytes = read + write) with the same
// threads (TBB) and the same array sizes as the kernel.
//
// The paper's scene: 4.7 million texels, nc = 2, 8 bands (Sec. 8.5, 3.4 ms per
// step on a GTX 770). The goal here: the exact kernel within 2x of the
// bandwidth limit. Each kernel benchmark reports
//   texel_steps/s       throughput
//   x_bandwidth_limit   its time / (bytes it must move / copy bandwidth), with
//                       copy_GB/s the best copy of the run so far (see CopyBandwidth)
// bytes = irradiance read (n_exc floats) + states read and written (2 nc)
//         + emitted radiance written (n_em), per texel, like STREAM's count.
//
// Run: build/bin/bench_model (make bench saves the output in docs/bench/).

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <random>
#include <vector>

#include <tbb/parallel_for.h>

#include <Eigen/Core>

#include "phos/model/batch.h"

namespace phos {
namespace {

constexpr std::size_t kTexels = 4'700'000;  // the paper's scene

// STREAM's Copy kernel, a[i] = b[i], as a plain loop: GCC would otherwise turn
// it into memmove, whose non-temporal stores no compute kernel gets.
__attribute__((optimize("no-tree-loop-distribute-patterns"))) void CopyRange(const float* b, float* a,
                                                                             std::size_t begin, std::size_t end) {
  for (std::size_t i = begin; i < end; ++i) a[i] = b[i];
}

void ParallelCopy(const std::vector<float>& b, std::vector<float>& a) {
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, a.size(), 1 << 16),
      [&](const tbb::blocked_range<std::size_t>& r) { CopyRange(b.data(), a.data(), r.begin(), r.end()); });
}

void BM_StreamCopy(benchmark::State& state) {
  // Large enough to leave every cache: 2 x 4.7M x 8 floats = 300 MB.
  const std::size_t n = kTexels * 8;
  std::vector<float> a(n, 1.0f), b(n, 2.0f);
  for (auto _ : state) {
    ParallelCopy(b, a);
    benchmark::DoNotOptimize(a.data());
    benchmark::ClobberMemory();
  }
  const double bytes = 2.0 * n * sizeof(float);
  state.SetBytesProcessed(static_cast<int64_t>(bytes) * state.iterations());
  state.counters["GB/s"] = benchmark::Counter(bytes * 1e-9, benchmark::Counter::kIsIterationInvariantRate);
}

// The copy bandwidth: the best this run has seen, over 20 copies of
// 2 x 150 MB before the benchmarks and 5 more right after each kernel. The
// machine is shared and its bandwidth varies by 1.5x within a minute; the
// best copy is the limit a kernel could have reached, so ratios against it
// are conservative.
double g_best_copy_bytes_per_second = 0;

double CopyBandwidth(int repeats = 5) {
  static std::vector<float> a(kTexels * 8, 1.0f), b(kTexels * 8, 2.0f);
  double best = 1e30;
  for (int repeat = 0; repeat < repeats; ++repeat) {
    auto start = std::chrono::steady_clock::now();
    ParallelCopy(b, a);
    benchmark::DoNotOptimize(a.data());
    best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  }
  g_best_copy_bytes_per_second = std::max(g_best_copy_bytes_per_second, 2.0 * a.size() * sizeof(float) / best);
  return g_best_copy_bytes_per_second;
}

// Counters every kernel reports. bytes: what one step must move (reads +
// writes, counted like STREAM). The ratio compares best with best: the
// fastest step of the loop against the fastest of 5 copies timed right
// after it, which is what this machine's noise (shared memory bandwidth)
// leaves stable from run to run.
void ReportTraffic(benchmark::State& state, double bytes, double best_step_seconds) {
  const double per_step = best_step_seconds;
  state.counters["best_ms"] = best_step_seconds * 1e3;
  const double copy_bytes_per_second = CopyBandwidth();
  const double limit = bytes / copy_bytes_per_second;  // seconds at copy bandwidth
  state.counters["copy_GB/s"] = copy_bytes_per_second * 1e-9;
  state.SetBytesProcessed(static_cast<int64_t>(bytes) * state.iterations());
  state.counters["texel_steps/s"] =
      benchmark::Counter(static_cast<double>(kTexels), benchmark::Counter::kIsIterationInvariantRate);
  state.counters["limit_ms"] = limit * 1e3;
  state.counters["x_bandwidth_limit"] = per_step / limit;  // 1 = as fast as memory allows
}

template <typename Real>
void BM_Kernel(benchmark::State& state) {
  const auto integrator = static_cast<Integrator>(state.range(0));
  const int nc = static_cast<int>(state.range(1));
  const int n_bands = static_cast<int>(state.range(2));
  const bool emit = state.range(3) != 0;
  const Real h_s = static_cast<Real>(state.range(4)) * Real(1e-3);
  const std::size_t n = kTexels;

  BatchCoefficients<Real> c;
  c.nc = nc;
  c.n_exc = n_bands;
  c.n_em = emit ? n_bands : 0;
  std::mt19937 rng(1);
  std::uniform_real_distribution<Real> u(0, 1);
  for (int i = 0; i < nc; ++i) {
    c.kr.push_back(Real(0.01) + Real(0.2) * u(rng));
    for (int b = 0; b < n_bands; ++b) c.ke.push_back(Real(0.05) * u(rng));
  }
  for (int b = 0; b < c.n_em; ++b)
    for (int i = 0; i < nc; ++i) c.emission.push_back(u(rng));
  std::vector<Real, Eigen::aligned_allocator<Real>> E(static_cast<std::size_t>(n_bands) * n),
      Lp(static_cast<std::size_t>(c.n_em) * n);
  for (Real& e : E) e = u(rng);
  StateBatch<Real> s(nc, n, Real(0.3));

  double best = 1e30;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    AdvanceBatch<Real>(integrator, c, E.data(), n, h_s, s, emit ? Lp.data() : nullptr, n);
    benchmark::ClobberMemory();
    best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  }
  ReportTraffic(state, static_cast<double>(sizeof(Real)) * n * (n_bands + 2.0 * nc + c.n_em), best);
}

void KernelArgs(benchmark::internal::Benchmark* b) {
  // integrator: 0 exact, 1 euler, 2 rk4; emit: write Lp; step_ms: 10 is a
  // frame-sized step (kh < 1/2: the exact update needs no exp), 10000 takes
  // the exp path for every texel.
  b->ArgNames({"integrator", "nc", "bands", "emit", "step_ms"});
  const int exact = static_cast<int>(Integrator::kExact);
  for (int nc : {1, 2})
    for (int bands : {3, 8}) b->Args({exact, nc, bands, 1, 10});
  b->Args({exact, 2, 8, 1, 10000});
  b->Args({exact, 2, 8, 0, 10});
  b->Args({static_cast<int>(Integrator::kEuler), 2, 8, 1, 10});
  b->Args({static_cast<int>(Integrator::kRk4), 2, 8, 1, 10});
  b->Unit(benchmark::kMillisecond)->UseRealTime();
}

void BM_DarkStep(benchmark::State& state) {
  // Lights off: the closed-form jump is one multiply per state and texel.
  BatchCoefficients<float> c;
  c.nc = 2;
  c.kr = {0.2f, 0.01f};
  StateBatch<float> s(2, kTexels, 0.5f);
  double best = 1e30;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    DecayBatch<float>(c, 0.01f, s);
    benchmark::ClobberMemory();
    best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  }
  ReportTraffic(state, 4.0 * kTexels * 2 * 2, best);
}

BENCHMARK(BM_StreamCopy)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_TEMPLATE(BM_Kernel, float)->Apply(KernelArgs);
BENCHMARK_TEMPLATE(BM_Kernel, double)
    ->ArgNames({"integrator", "nc", "bands", "emit", "step_ms"})
    ->Args({static_cast<int>(Integrator::kExact), 2, 8, 1, 10})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_DarkStep)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace phos

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  phos::CopyBandwidth(20);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
