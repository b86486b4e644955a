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

# One run of a binary: "name=value" for each benchmark, the counter's column
# found by its name in the CSV header.
counters() {
  "$1" --benchmark_filter="$filter" --benchmark_format=csv 2>/dev/null |
    awk -F, -v counter="\"$counter\"" '
      /^name,/ { for (i = 1; i <= NF; ++i) if ($i == counter) column = i; next }
      column && /^"/ { name = $1; gsub(/"/, "", name); sub(/\/min_time.*|\/real_time.*/, "", name); printf "%s=%s  ", name, $column }
      END { if (!column) { print "ab.sh: no counter " counter > "/dev/stderr"; exit 2 } }'
}
for ((pair = 1; pair <= pairs; ++pair)); do
  echo "pair $pair A: $(counters "$a")"
  echo "pair $pair B: $(counters "$b")"
done
