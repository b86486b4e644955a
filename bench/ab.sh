#!/bin/bash
# Two builds of a benchmark alternated in one run, so that the machine's
# noise hits both alike: a change is measured as pairs of its counter, the
# code before (A) then the code after (B), N times.
#
#   bench/ab.sh A B N FILTER [COUNTER]
#
#   A, B     two benchmark binaries (e.g. a copy of build/bin/bench_render
#            made before the change, and the one after)
#   N        pairs to run
#   FILTER   --benchmark_filter, e.g. 'PathAgainstBareEmbree/40|GlowingBySize/8/'
#   COUNTER  the user counter to print (default: ratio)
#
# Prints, per pair, each benchmark's counter under A and under B.
set -euo pipefail
if [ $# -lt 4 ]; then
  sed -n '2,14p' "$0" | sed 's/^# \{0,1\}//' >&2
  exit 2
fi
a=$1 b=$2 pairs=$3 filter=$4 counter=${5:-ratio}
for binary in "$a" "$b"; do
  [ -x "$binary" ] || { echo "ab.sh: $binary: not an executable benchmark" >&2; exit 2; }
done
[[ "$pairs" =~ ^[1-9][0-9]*$ ]] || { echo "ab.sh: N: expected a count of pairs from 1 up, not '$pairs'" >&2; exit 2; }

# One run of a binary: "name=value" for each benchmark, from its JSON
# output (the CSV reporter stops at a benchmark whose counters differ from
# the first one's, as the glowing spheres' do from the box's).
counters() {
  "$1" --benchmark_filter="$filter" --benchmark_format=json 2>/dev/null |
    python3 -c '
import json, re, sys
counter = sys.argv[1]
runs = json.load(sys.stdin)["benchmarks"]
if any(counter not in run for run in runs):
    sys.exit("ab.sh: no counter \"%s\"" % counter)
print("  ".join("%s=%.6g" % (re.sub(r"/(min_time|real_time).*", "", run["name"]), run[counter]) for run in runs))
' "$counter"
}
for ((pair = 1; pair <= pairs; ++pair)); do
  for side in A B; do
    binary=$a
    [ "$side" = B ] && binary=$b
    line=$(counters "$binary") || exit 2  # the counter is missing: said on stderr
    echo "pair $pair $side: $line"
  done
done
