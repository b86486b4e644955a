#!/usr/bin/env bash
# Start-up of the phos command (app/main.cpp's dispatch): wall time and peak memory
# of the whole process, `phos` and the phos-<command> it runs, measured with
# /usr/bin/time over RUNS runs (median), on small inputs, in the Release tree.
# Also lists what each command loads at run time (LD_DEBUG=libs, the dispatcher
# and the executable it runs), and fails if one of them loads OpenImageIO,
# Embree, Aravis or OpenCV.
#
#   bench/startup.sh [OUT]    (OUT: default docs/bench/startup.txt)
#
# Time only on an otherwise idle machine (nothing compiling meanwhile).
# The goal: at most 20 ms and 30 MiB for each command below.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-docs/bench/startup.txt}
runs=${RUNS:-10}
phos=build/bin/phos
[ -x "$phos" ] || { echo "bench/startup.sh: $phos is missing: build the Release tree first (make build)" >&2; exit 2; }
command -v /usr/bin/time >/dev/null || { echo "bench/startup.sh: /usr/bin/time is missing (apt-get install time)" >&2; exit 2; }

# Small inputs: a fixture each, as the README runs them.
commands=(
  "--help"
  "--version"
  "simulate --material fixtures/materials/green.json --charge-s 10 --irradiance 1,1,1,0,0,0,0,0 --decay-s 20 --dt 5"
  "fit decay-curve fixtures/curves/decay-two-components.csv"
  "fit charge-curve --csv fixtures/curves/charge.csv"
  "edit solve fixtures/constraints/glow-sign.json --no-baseline"
  "edit solve fixtures/constraints/glow-sign.json"
)
forbidden='OpenImageIO|embree|aravis|opencv'

median() { sort -g | awk '{v[NR] = $1} END {print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2}'; }

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
status=0
{
  echo "# command: bench/startup.sh $out   (RUNS=$runs; run under flock /tmp/phos-build.lock on a shared machine)"
  echo "# date: $(date -u +%Y-%m-%dT%H:%MZ)  commit: $(git rev-parse --short HEAD 2>/dev/null || echo none)"
  echo "# machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), $(free -g | awk '/Mem:/{print $2}') GiB; load $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "# wall: median of $runs runs, from the shell's clock around /usr/bin/time (so it includes that fork);"
  echo "# /usr/bin/time's own %e has 10 ms steps. peak: /usr/bin/time's %M (maximum resident set), median."
  echo "# libs: shared libraries loaded (LD_DEBUG=libs, phos and the phos-<command> it runs)."
  echo "# goal: wall <= 20 ms, peak <= 30 MiB, none of OpenImageIO, Embree, Aravis, OpenCV loaded."
  printf '%-8s %-9s %-5s %-9s %s\n' "wall_ms" "peak_MiB" "libs" "forbidden" "phos ..."
  for args in "${commands[@]}"; do
    read -r -a argv <<<"$args"
    "$phos" "${argv[@]}" >/dev/null 2>&1 || { echo "bench/startup.sh: phos $args failed" >&2; status=1; }
    : >"$tmp/wall"; : >"$tmp/peak"
    for ((i = 0; i < runs; ++i)); do
      start=$EPOCHREALTIME
      /usr/bin/time -f '%M' -o "$tmp/time" "$phos" "${argv[@]}" >/dev/null 2>&1 || true
      end=$EPOCHREALTIME
      awk -v s="$start" -v e="$end" 'BEGIN {printf "%.2f\n", (e - s) * 1000}' >>"$tmp/wall"
      awk '{printf "%.1f\n", $1 / 1024}' "$tmp/time" >>"$tmp/peak"
    done
    LD_DEBUG=libs "$phos" "${argv[@]}" 2>"$tmp/libs" >/dev/null || true
    libs=$(grep -c 'calling init:' "$tmp/libs" || true)
    bad=$(grep 'calling init:' "$tmp/libs" | grep -oiE "lib($forbidden)[^ /]*" | sort -u | tr '\n' ' ' || true)
    [ -n "$bad" ] && status=1
    printf '%-8s %-9s %-5s %-9s %s\n' "$(median <"$tmp/wall")" "$(median <"$tmp/peak")" "$libs" "${bad:-none}" "$args"
  done
} | tee "$out"
echo "wrote $out"
exit $status
