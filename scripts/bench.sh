#!/usr/bin/env bash
# Runs the benchmarks (Release) and keeps their output, with the command and
# the machine, in docs/bench/, where docs/ and the README quote them from.
set -euo pipefail
cd "$(dirname "$0")/.."
mkdir -p docs/bench
# Names on the command line run only those (e.g. scripts/bench.sh render).
names=("$@")
[ ${#names[@]} -eq 0 ] && names=(model fit render editor)
for name in "${names[@]}"; do
  out=docs/bench/$name.txt
  {
    echo "# command: build/bin/bench_$name --benchmark_counters_tabular=true"
    echo "# date: $(date -u +%Y-%m-%dT%H:%MZ)  commit: $(git rev-parse --short HEAD 2>/dev/null || echo none)"
    echo "# machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), $(free -g | awk '/Mem:/{print $2}') GiB"
    echo "# (the 'Library was built as DEBUG' warning is about Debian's libbenchmark package, not phos)"
    "build/bin/bench_$name" --benchmark_counters_tabular=true 2>&1
  } | tee "$out"
  echo "wrote $out"
done
