// One constraint edit (Sec. 8.6): fixtures/constraints/glow-sign.json, 4 key
// frames over a 200-frame sequence, nc = 1 in RGB, and the same edit solved
// with two states (nc = 2). The paper needed 80 ms on a GPU for its grid
// search; the goal here is at most 10 ms on 2 CPU cores for nc = 1 and nc = 2
// with a cost no higher than the grid's. All are timed in this run
// and their costs printed as counters (cost; and for ours, cost_vs_grid =
// ours / grid's).
//
// Run: build/bin/bench_editor (make bench saves the output in docs/bench/).

#include <benchmark/benchmark.h>

#include "phos/editor/solve.h"

namespace phos::editor {
namespace {

const Problem& Sign() {
  static const Problem problem = LoadProblem(PHOS_FIXTURES_DIR "/constraints/glow-sign.json");
  return problem;
}

double GridCost() {
  static const double cost = SolveGridBaseline(Sign())->cost;
  return cost;
}

void BM_EditOurs(benchmark::State& state) {
  Problem problem = Sign();
  problem.states = static_cast<int>(state.range(0));
  double cost = 0;
  for (auto _ : state) {
    const Solution s = Solve(problem);
    cost = s.cost;
    benchmark::ClobberMemory();  // (DoNotOptimize on a double is miscompiled here: it garbles the value)
  }
  state.counters["cost"] = cost;
  state.counters["cost_vs_grid"] = cost / GridCost();
}
BENCHMARK(BM_EditOurs)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_EditGridBaseline(benchmark::State& state) {
  double cost = 0;
  for (auto _ : state) {
    cost = SolveGridBaseline(Sign())->cost;
    benchmark::ClobberMemory();
  }
  state.counters["cost"] = cost;
}
BENCHMARK(BM_EditGridBaseline)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace phos::editor

BENCHMARK_MAIN();
