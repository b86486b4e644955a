// Speed of the decay and charge fits (issue: a 1000-point, 3-component decay
// fit in well under 1 ms). Synthetic curves with Gaussian noise, fixed seed.
//
// Run: build/bin/bench_fit (make bench saves the output in docs/bench/).

#include <benchmark/benchmark.h>

#include <cmath>
#include <random>

#include "phos/fit/charge_fit.h"
#include "phos/fit/decay_fit.h"

namespace phos {
namespace {

Curve ThreeComponentDecay(int points) {
  std::mt19937 rng(1);
  std::normal_distribution<double> noise(0, 1);
  Curve curve;
  curve.names = {"value"};
  curve.channels.resize(1);
  for (int j = 0; j < points; ++j) {
    const double t = j * 50.0 / points;
    curve.t_s.push_back(t);
    curve.channels[0].push_back(1000 * std::exp(-2 * t) + 300 * std::exp(-0.3 * t) + 50 * std::exp(-0.02 * t) +
                                noise(rng));
  }
  return curve;
}

void BM_DecayFit(benchmark::State& state) {
  const Curve curve = ThreeComponentDecay(static_cast<int>(state.range(0)));
  DecayFitOptions options;
  options.components = static_cast<int>(state.range(1));  // 0: choose by BIC up to 3
  // stderr: 0 none, 1 rates (the contract's rate_stderr), 2 rates and amplitudes
  options.compute_uncertainties = state.range(2) >= 1;
  options.amplitude_uncertainties = state.range(2) >= 2;
  for (auto _ : state) benchmark::DoNotOptimize(FitDecay(curve, options, "bench"));
}
BENCHMARK(BM_DecayFit)
    ->ArgNames({"points", "components", "stderr"})
    ->Args({1000, 3, 1})
    ->Args({1000, 3, 0})
    ->Args({1000, 3, 2})
    ->Args({1000, 0, 1})
    ->Args({100, 3, 1})
    ->Unit(benchmark::kMicrosecond);

void BM_ChargeFit(benchmark::State& state) {
  std::mt19937 rng(2);
  std::normal_distribution<double> noise(0, 0.01);
  Curve curve;
  curve.names = {"value"};
  curve.channels.resize(1);
  for (int j = 0; j < 1000; ++j) {
    const double t = j * 0.1;
    curve.t_s.push_back(t);
    curve.channels[0].push_back(2 - 1.9 * std::exp(-0.05 * t) + noise(rng));
  }
  for (auto _ : state) benchmark::DoNotOptimize(FitCharge(curve, ChargeFitOptions{}, "bench"));
}
BENCHMARK(BM_ChargeFit)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace phos

BENCHMARK_MAIN();
