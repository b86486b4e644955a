#!/usr/bin/env bash
# The measurements of docs/scale.md: a one-node Slurm cluster on this machine
# (munged, slurmctld, slurmd; task/affinity binds each task to its CPUs, so
# one task is one core, as one node of a cluster is its own cores), then
#   - the render one process runs on one core (taskset), and on all cores;
#   - the same render as job arrays of 1 and 2 tasks (one core each), timed
#     from submission to the end of the last job;
#   - the solver pass, the tasks' own times (done records), the map merge.
# Needs root, slurm-wlm and munge (scripts/bootstrap.sh). Run from the source
# tree after a Release build:   scripts/scale-bench.sh build/bin/phos
# The cluster is scripts/slurm-one-node.sh's (with task/affinity), stopped on the
# way out whatever happens.
set -euo pipefail
PHOS=$(readlink -f "${1:-build/bin/phos}")
WORK=$(mktemp -d /tmp/phos-scale-XXXXXX)
chmod 755 "$WORK"  # munged and the jobs reach the cluster's folder through it
ONE_NODE=$(dirname "$(readlink -f "$0")")/slurm-one-node.sh
stop() {
  bash "$ONE_NODE" stop "$WORK/cluster" >/dev/null 2>&1 || true
  rm -rf "$WORK" 2>/dev/null || true
}
trap stop EXIT
# The one-node cluster of scripts/slurm-one-node.sh, its tasks bound to their CPUs.
PHOS_SLURM_TASK_PLUGIN=task/affinity bash "$ONE_NODE" start "$WORK/cluster" >/dev/null
export SLURM_CONF=$WORK/cluster/slurm.conf

now() { date +%s.%N; }
dt() { python3 -c "print('%.2f' % ($2 - $1))"; }
SCENE=fixtures/scenes/cornell-phosphor.json
RENDER=(--times "$(seq -s, 5 5 60)" --width 96 --height 72 --transport path --spp 256)
echo "render: cornell-phosphor, 12 frames, 96x72, path 256 spp"
t0=$(now); taskset -c 0 "$PHOS" render $SCENE --out "$WORK/one-core" "${RENDER[@]}" >/dev/null; t1=$(now)
echo "one process, one core: $(dt $t0 $t1) s"
t0=$(now); "$PHOS" render $SCENE --out "$WORK/all-cores" "${RENDER[@]}" >/dev/null; t1=$(now)
echo "one process, $(nproc) cores: $(dt $t0 $t1) s"
t0=$(now); "$PHOS" render $SCENE --solve-only --checkpoints "$WORK/states" --tasks 2 "${RENDER[@]}" >/dev/null; t1=$(now)
echo "solver pass (process, start to end): $(dt $t0 $t1) s"
for n in 1 2; do
  t0=$(now)
  "$PHOS" slurm render --tasks $n --job-dir "$WORK/job$n" --cpus-per-task 1 --mem-per-task 500M \
    -- $SCENE --out "$WORK/frames$n" "${RENDER[@]}" >/dev/null
  t_submitted=$(now)
  while [ -n "$(squeue -h)" ]; do sleep 0.05; done
  t1=$(now)
  tasks=$(python3 -c "import json,glob; print(' '.join('%.2f' % json.load(open(f))['seconds'] for f in sorted(glob.glob('$WORK/frames$n/done/*.json'))))")
  solve=$(python3 -c "import json; print('%.3f' % json.load(open('$WORK/job$n/states/done.json'))['seconds'])")
  echo "array of $n task(s), one core each: $(dt $t0 $t1) s from submission to the last job's end" \
       "(sbatch x3: $(dt $t0 $t_submitted) s; solver job's own $solve s; tasks' own: $tasks s)"
  # The chain's timeline, as Slurm saw it (1 s resolution): when each job (and array task) ran.
  for id in $(python3 -c "import json; print(' '.join(s['job_id'] for s in json.load(open('$WORK/job$n/job.json'))['stages']))"); do
    scontrol -o show job "$id" | grep -o 'JobId=[0-9]* \|ArrayTaskId=[0-9]*\|JobName=[^ ]*\|SubmitTime=[^ ]*\|StartTime=[^ ]*\|EndTime=[^ ]*' | paste -sd' ' | sed 's/^/    /'
  done
  for f in "$WORK"/one-core/*.exr; do idiff -a "$f" "$WORK/frames$n/$(basename "$f")" >/dev/null || echo "  DIFFERS: $f"; done
done

echo "map: a 320x240 simulated decay session"
"$PHOS" capture decay --sim-material fixtures/materials/orange.json --sim-inset fixtures/materials/blue.json \
  --sim-size 320x240 --charge-s 1800 --out "$WORK/session" >/dev/null
t0=$(now); taskset -c 0 "$PHOS" fit map "$WORK/session" --out "$WORK/map-one" >/dev/null; t1=$(now)
echo "one process, one core: $(dt $t0 $t1) s"
for i in 0 1 2 3; do taskset -c 0 "$PHOS" fit map "$WORK/session" --out "$WORK/map4" --tile $i/4 >/dev/null; done
t0=$(now); "$PHOS" fit map "$WORK/session" --out "$WORK/map4" --merge >/dev/null; t1=$(now)
echo "merge of 4 tiles: $(dt $t0 $t1) s; tiles' own: $(python3 -c "import json,glob; print(' '.join('%.3f' % json.load(open(f))['seconds'] for f in sorted(glob.glob('$WORK/map4/tiles/*.json'))))") s"
