// Speed of the decay and charge fits (the goal: a 1000-point, 3-component
// decay fit in well under 1 ms). Synthetic curves with Gaussian noise, fixed seed.
//
// Run: build/bin/bench_fit (make bench saves the output in docs/bench/).

#include <benchmark/benchmark.h>

#include <sys/resource.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "phos/fit/charge_fit.h"
#include "phos/fit/decay_fit.h"
#include "phos/fit/decay_map.h"
#include "phos/model/closed_form.h"

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

// A 1-megapixel, 36-frame decay session (3 channels), as the decay
// protocol's schedule and exposures give it, rates varying across the
// image, with Gaussian noise of photon-counting size (Poisson sampling of
// 113 million values would take longer than the fit). The target:
// a map of it in at most 2 s on 2 cores, in at most twice its memory.
// With `two_states`, every pixel also has a fast state of 8 times the rate
// and the same colour, as bright as the slow one at t = 0 (two-state maps,
// docs/two-state-map.md).
DecayMapInput MakeMegapixelStack(bool two_states) {
  {
    DecayMapInput in;
    in.width = in.height = 1024;
    in.channels = 3;
    std::mt19937_64 rng(7);
    std::normal_distribution<float> unit(0.0f, 1.0f);
    const double amplitude[3] = {3400, 900, 700};
    for (int j = 0; j < 36; ++j) {
      const double e = std::min(3.2, 0.05 * std::pow(2.0, j / 3));
      const double start = 0.005 + 5.0 * j;
      in.t_s.push_back(start + e / 2);
      in.exposure_s.push_back(e);
      std::vector<float> frame(static_cast<std::size_t>(in.width) * in.height * 3);
      for (int y = 0; y < in.height; ++y)
        for (int x = 0; x < in.width; ++x) {
          const double k = 0.015 * (1 + x / 1024.0), k2 = 8 * k;
          for (int c = 0; c < 3; ++c) {
            double rate = amplitude[c] * DecayFactor(k, start, e) + 2;
            if (two_states) rate += amplitude[c] * DecayFactor(k2, start, e);
            frame[(static_cast<std::size_t>(y) * in.width + x) * 3 + c] =
                static_cast<float>(rate + unit(rng) * std::sqrt(rate / (4 * e)));
          }
        }
      in.frames.push_back(std::move(frame));
    }
    return in;
  }
}

const DecayMapInput& MegapixelStack() {
  static const DecayMapInput stack = MakeMegapixelStack(false);
  return stack;
}

double InputBytes(const DecayMapInput& in) {
  double bytes = 0;
  for (const auto& frame : in.frames) bytes += frame.size() * sizeof(float);
  return bytes;
}

// The map of the last BM_DecayMap1Megapixel iteration, for the reference
// bench to compare with.
DecayMap& FastMegapixelMap() {
  static DecayMap map;
  return map;
}

void BM_DecayMap1Megapixel(benchmark::State& state) {
  const DecayMapInput& stack = MegapixelStack();
  for (auto _ : state) {
    FastMegapixelMap() = FitDecayMap(stack, DecayMapOptions{}, "bench");
    benchmark::ClobberMemory();
    state.counters["pixels_per_s"] = 1024.0 * 1024.0 / FastMegapixelMap().seconds;
  }
  // Peak resident memory of the whole process so far (the stack, the map
  // and the fit's work space) over the stack's own size.
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  state.counters["peak_rss_per_input"] = usage.ru_maxrss * 1024.0 / InputBytes(stack);
}
BENCHMARK(BM_DecayMap1Megapixel)->Unit(benchmark::kSecond)->Iterations(2)->UseRealTime();

// Two states per pixel (options.states = 2) on the two-state stack: speed,
// and the largest relative errors of k1 and k2 against the rates it was made
// with over all pixels, their medians, and the pixels where BIC kept one
// state (here a miss: every pixel has two).
void BM_DecayMap1MegapixelTwoStates(benchmark::State& state) {
  static const DecayMapInput stack = MakeMegapixelStack(true);
  DecayMapOptions options;
  options.states = 2;
  DecayMap map;
  for (auto _ : state) {
    map = FitDecayMap(stack, options, "bench");
    benchmark::ClobberMemory();
    state.counters["pixels_per_s"] = 1024.0 * 1024.0 / map.seconds;
  }
  std::vector<double> e1, e2;
  for (int y = 0; y < stack.height; ++y)
    for (int x = 0; x < stack.width; ++x) {
      const std::size_t p = static_cast<std::size_t>(y) * stack.width + x;
      if (std::isnan(map.kr2[p])) continue;
      const double k = 0.015 * (1 + x / 1024.0);
      e1.push_back(std::fabs(map.kr[p] - k) / k);
      e2.push_back(std::fabs(map.kr2[p] - 8 * k) / (8 * k));
    }
  std::sort(e1.begin(), e1.end());
  std::sort(e2.begin(), e2.end());
  state.counters["one_state"] = static_cast<double>(map.one_state);
  state.counters["k1_err_median"] = e1.empty() ? NAN : e1[e1.size() / 2];
  state.counters["k2_err_median"] = e2.empty() ? NAN : e2[e2.size() / 2];
  state.counters["k1_err_max"] = e1.empty() ? NAN : e1.back();
  state.counters["k2_err_max"] = e2.empty() ? NAN : e2.back();
  // As BM_DecayMap1Megapixel's: the whole process's peak, so it means the
  // two-state map's own only when this bench runs alone (--benchmark_filter=TwoStates).
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  state.counters["peak_rss_per_input"] = usage.ru_maxrss * 1024.0 / InputBytes(stack);
}
BENCHMARK(BM_DecayMap1MegapixelTwoStates)->Unit(benchmark::kSecond)->Iterations(2)->UseRealTime();

// The first algorithm (FitDecayMapReference) on the same stack, once: its
// speed, and the largest differences of the fast map from it over every
// pixel: kr (relative), amplitude (relative to the channel's amplitude),
// background (relative to the channel's amplitude) and rms (relative; the
// fast map's is never worse than rounding allows).
void BM_DecayMap1MegapixelReference(benchmark::State& state) {
  const DecayMapInput& stack = MegapixelStack();
  if (FastMegapixelMap().kr.empty()) FastMegapixelMap() = FitDecayMap(stack, DecayMapOptions{}, "bench");
  const DecayMap& fast = FastMegapixelMap();
  DecayMap reference;
  for (auto _ : state) {
    reference = FitDecayMapReference(stack, DecayMapOptions{}, "bench");
    benchmark::ClobberMemory();
    state.counters["pixels_per_s"] = 1024.0 * 1024.0 / reference.seconds;
  }
  double kr = 0, amplitude = 0, background = 0, rms_worse = 0, no_decay_differs = 0;
  for (std::size_t p = 0; p < reference.kr.size(); ++p) {
    if (std::isnan(reference.kr[p]) != std::isnan(fast.kr[p])) ++no_decay_differs;
    if (!std::isnan(reference.kr[p]) && !std::isnan(fast.kr[p]))
      kr = std::max(kr, std::fabs(double(fast.kr[p]) - reference.kr[p]) / reference.kr[p]);
    for (int c = 0; c < 3; ++c) {
      const double A = reference.amplitude[p * 3 + c];
      if (!(A > 0)) continue;
      amplitude = std::max(amplitude, std::fabs(fast.amplitude[p * 3 + c] - A) / A);
      background = std::max(background, std::fabs(fast.background[p * 3 + c] - reference.background[p * 3 + c]) / A);
    }
    rms_worse = std::max(rms_worse, (fast.rms[p] - reference.rms[p]) / double(reference.rms[p]));
  }
  state.counters["max_kr_diff"] = kr;
  state.counters["max_A_diff"] = amplitude;
  state.counters["max_B_diff"] = background;
  state.counters["max_rms_worse"] = rms_worse;
  state.counters["nan_differs"] = no_decay_differs;
  state.counters["speedup"] = reference.seconds / fast.seconds;
}
BENCHMARK(BM_DecayMap1MegapixelReference)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

}  // namespace
}  // namespace phos

BENCHMARK_MAIN();
