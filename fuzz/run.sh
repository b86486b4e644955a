#!/usr/bin/env bash
# Runs every fuzz harness (or those named) for FUZZ_SECONDS each, FUZZ_JOBS
# at a time (default 1: one core, so a machine stays usable through `make
# fuzz`; `make test` runs nproc at once), at the lowest CPU priority: libFuzzer with
# -max_total_time, seeded from fixtures/ (and fuzz/seeds/), the corpus it
# grows kept in build-fuzz/corpus/<target>. A crash, a sanitizer report, a
# timeout (FUZZ_TIMEOUT s for one input) or running out of memory
# (FUZZ_RSS_MB) stops that harness and writes the input to
# build-fuzz/findings/<target>/; the script then exits 1. Each harness's
# executions and the command go to build-fuzz/fuzz-summary.txt.
#   FUZZ_SECONDS=60 fuzz/run.sh              (make fuzz)
#   FUZZ_SECONDS=10 fuzz/run.sh scene gltf   (two of them)
#   FUZZ_RUNS=1000000 fuzz/run.sh            (a million executions each, however long)
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
BIN=$ROOT/build-fuzz/bin
SECONDS_EACH=${FUZZ_SECONDS:-60}
JOBS=${FUZZ_JOBS:-1}
TIMEOUT=${FUZZ_TIMEOUT:-10}
RSS_MB=${FUZZ_RSS_MB:-2048}
MAX_LEN=${FUZZ_MAX_LEN:-65536}
TARGETS=("$@")
[ ${#TARGETS[@]} -eq 0 ] && TARGETS=(material scene obj gltf constraints lab curve_csv session editor)

seeds() {  # the seed files of a target
  case $1 in
    material) ls fixtures/materials/*.json ;;
    scene) ls fixtures/scenes/*.json ;;
    obj) ls fixtures/scenes/meshes/*.obj ;;
    gltf) ls fixtures/scenes/meshes/*.gltf fixtures/scenes/*/*.gltf ;;
    constraints) ls fixtures/constraints/*.json ;;
    lab) ls fuzz/seeds/lab/* ;;
    curve_csv) ls fixtures/curves/*.csv fixtures/curves/*.dat fixtures/curves/*.txt fixtures/cameras/*.csv ;;
    session) ls fuzz/seeds/session/* ;;
    editor) ls fuzz/seeds/editor/* ;;
  esac
  [ -d "fuzz/regressions/$1" ] && ls -d "fuzz/regressions/$1"/* 2>/dev/null
  return 0
}

status=0
summary=$ROOT/build-fuzz/fuzz-summary.txt
budget_text="$SECONDS_EACH s"
[ -n "${FUZZ_RUNS:-}" ] && budget_text="$FUZZ_RUNS runs"
echo "# $(date -u +%FT%TZ), $budget_text per harness, $(nproc) cores" >>"$summary"
for t in "${TARGETS[@]}"; do
  [ -x "$BIN/fuzz-$t" ] || { echo "fuzz: $BIN/fuzz-$t missing (build it: cmake --preset fuzz -S fuzz && cmake --build build-fuzz)" >&2; exit 2; }
done

# One harness for its budget; returns its fuzzer's exit code.
fuzz_one() {
  local t=$1
  local exe=$BIN/fuzz-$t
  local corpus=$ROOT/build-fuzz/corpus/$t seed=$ROOT/build-fuzz/seeds/$t findings=$ROOT/build-fuzz/findings/$t
  mkdir -p "$corpus" "$seed" "$findings"
  seeds "$t" | while read -r f; do cp -f "$f" "$seed/"; done
  local dict=() log budget cmd rc runs took line
  [ -f "fuzz/$t.dict" ] && dict=(-dict="fuzz/$t.dict")
  log=$ROOT/build-fuzz/fuzz-$t.log
  budget=(-max_total_time="$SECONDS_EACH")
  [ -n "${FUZZ_RUNS:-}" ] && budget=(-runs="$FUZZ_RUNS")
  cmd=(nice -n 19 "$exe" "${budget[@]}" -timeout="$TIMEOUT" -rss_limit_mb="$RSS_MB"
       -max_len="$MAX_LEN" -print_final_stats=1 -artifact_prefix="$findings/" "${dict[@]}" "$corpus" "$seed")
  # nice alone does not keep the fuzzer off a build started from another
  # terminal: with sched_autogroup each session is a scheduling group and
  # nice weighs only within it (a nice-19 fuzzer took a whole core from a
  # build here). So each fuzzer runs in a session of its own whose group is
  # niced too.
  ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    setsid --wait bash -c 'echo 19 > /proc/self/autogroup 2>/dev/null; exec "$@"' fuzz "${cmd[@]}" >"$log" 2>&1
  rc=$?
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' | tail -1)
  took=$(grep -o 'Done [0-9]* runs in [0-9]* second' "$log" | grep -o 'in [0-9]*' | grep -o '[0-9]*' | tail -1)
  line="$t: ${runs:-?} executions in ${took:-$SECONDS_EACH} s, exit $rc: ${cmd[*]}"
  echo "fuzz: $line"
  echo "$line" >>"$summary"
  if [ $rc -ne 0 ]; then
    echo "fuzz: $t found a problem; the input is in $findings/, the log in $log:" >&2
    grep -m6 -E "ERROR|SUMMARY|runtime error|internal error|terminate|logic_error|what\(\)" "$log" >&2
  fi
  return $rc
}

# FUZZ_JOBS harnesses at a time (each on one core); as each ends, the next starts.
running=0
for t in "${TARGETS[@]}"; do
  if [ $running -ge "$JOBS" ]; then
    wait -n || status=1
    running=$((running - 1))
  fi
  fuzz_one "$t" &
  running=$((running + 1))
done
while [ $running -gt 0 ]; do
  wait -n || status=1
  running=$((running - 1))
done
exit $status
