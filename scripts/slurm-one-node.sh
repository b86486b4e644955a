#!/bin/bash
# A one-node Slurm cluster on this machine, in a folder of its own: munged,
# slurmctld and slurmd, to try `phos slurm` (docs/scale.md) without a
# cluster. The project's Slurm test (tests/app/slurm_test.cpp) starts its
# cluster with this script too.
#
#   scripts/slurm-one-node.sh start DIR   start it; then: export SLURM_CONF=DIR/slurm.conf
#   scripts/slurm-one-node.sh stop DIR    cancel every job, stop the daemons it started
#
# Needs root (slurmd runs jobs as their users) and the Debian packages
# slurm-wlm and munge (scripts/bootstrap.sh installs them). The node has
# this machine's cores and PHOS_SLURM_MEMORY_MB of memory (default: 2000;
# give `phos slurm ... --mem-per-task` at most that), one partition "test".
# PHOS_SLURM_CRED_EXPIRE_S (default 20) is slurm.conf's cred_expire: how
# long a requeued job waits before it may start again (Slurm's default 120).
# PHOS_SLURM_TASK_PLUGIN (default task/none): task/affinity binds each task
# to its CPUs, as scripts/scale-bench.sh measures with.
set -euo pipefail

usage() {
  sed -n '7,8p' "$0" | sed 's/^# \{0,1\}//' >&2
  exit 2
}
[ $# -eq 2 ] || usage
action=$1
dir=$2

tool() {  # the path of a Slurm or munge program, or a one-line refusal
  local found
  for d in /usr/sbin /usr/bin /sbin /bin /usr/local/sbin /usr/local/bin; do
    [ -x "$d/$1" ] && { echo "$d/$1"; return; }
  done
  echo "slurm-one-node.sh: $1 is not installed (scripts/bootstrap.sh installs slurm-wlm and munge)" >&2
  exit 2
}

free_port() {  # a TCP port free now (the kernel's pick)
  python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'
}

tail_log() { [ -f "$1" ] && tail -c 600 "$1" >&2 || true; }

start() {
  [ "$(id -u)" -eq 0 ] || { echo "slurm-one-node.sh: start: needs root (slurmd runs the jobs as their users)" >&2; exit 2; }
  local munged mungekey slurmctld slurmd
  munged=$(tool munged); mungekey=$(tool mungekey); slurmctld=$(tool slurmctld); slurmd=$(tool slurmd)
  tool sinfo >/dev/null; tool sbatch >/dev/null; tool scancel >/dev/null
  if [ -f "$dir/slurm.conf" ] && [ -f "$dir/slurmctld.pid" ] && kill -0 "$(cat "$dir/slurmctld.pid")" 2>/dev/null; then
    echo "slurm-one-node.sh: $dir: a cluster is already running there ('$0 stop $dir' first)" >&2
    exit 2
  fi
  # A folder of its own: new, empty, or one this script made before (its
  # slurm.conf says so). Never /tmp or a home folder, whose mode it sets.
  if [ -e "$dir" ] && [ ! -d "$dir" ]; then
    echo "slurm-one-node.sh: $dir: not a folder; give a new folder (e.g. /tmp/slurm)" >&2
    exit 2
  fi
  if [ -n "$(ls -A "$dir" 2>/dev/null)" ] && [ ! -f "$dir/.slurm-one-node" ]; then
    echo "slurm-one-node.sh: $dir: not empty and not a cluster folder of this script; give a new folder (e.g. /tmp/slurm)" >&2
    exit 2
  fi
  mkdir -p "$dir/state" "$dir/spool"
  touch "$dir/.slurm-one-node"  # ours: a later start (after a failed one) may use it again
  dir=$(cd "$dir" && pwd)
  chmod 0755 "$dir"  # slurmd and the jobs read the config
  "$mungekey" -c -f -k "$dir/munge.key" >/dev/null
  chmod 0600 "$dir/munge.key"
  "$munged" --socket="$dir/munge.sock" --key-file="$dir/munge.key" --pid-file="$dir/munged.pid" \
    --log-file="$dir/munged.log" --seed-file="$dir/munged.seed" ||
    { echo "slurm-one-node.sh: munged did not start" >&2; tail_log "$dir/munged.log"; exit 1; }
  local host cpus
  host=$(hostname -s)
  cpus=$(nproc)
  cat > "$dir/slurm.conf" <<EOF
# Written by scripts/slurm-one-node.sh: a one-node cluster for trying phos slurm.
ClusterName=phos$$
SlurmctldHost=$host
SlurmctldPort=$(free_port)
SlurmdPort=$(free_port)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$dir/munge.sock,cred_expire=${PHOS_SLURM_CRED_EXPIRE_S:-20}
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=${PHOS_SLURM_TASK_PLUGIN:-task/none}
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/backfill
MpiDefault=none
ReturnToService=2
JobCompType=jobcomp/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SwitchType=switch/none
MinJobAge=3600
KillWait=5
NodeName=$host CPUs=$cpus RealMemory=${PHOS_SLURM_MEMORY_MB:-2000} State=UNKNOWN
PartitionName=test Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
  export SLURM_CONF=$dir/slurm.conf
  "$slurmctld" -i -f "$SLURM_CONF" || { echo "slurm-one-node.sh: slurmctld did not start" >&2; tail_log "$dir/slurmctld.log"; stop; exit 1; }
  "$slurmd" -f "$SLURM_CONF" || { echo "slurm-one-node.sh: slurmd did not start" >&2; tail_log "$dir/slurmd.log"; stop; exit 1; }
  for _ in $(seq 150); do
    if sinfo -h -o %T 2>/dev/null | grep -q idle; then
      echo "slurm-one-node.sh: one node ($host, $cpus CPUs, ${PHOS_SLURM_MEMORY_MB:-2000} MB) up in $dir"
      echo "export SLURM_CONF=$SLURM_CONF"
      return
    fi
    sleep 0.2
  done
  echo "slurm-one-node.sh: the node did not come up in 30 s" >&2
  tail_log "$dir/slurmctld.log"
  tail_log "$dir/slurmd.log"
  stop
  exit 1
}

stop() {
  [ -d "$dir" ] || { echo "slurm-one-node.sh: stop: $dir: no such folder" >&2; exit 2; }
  dir=$(cd "$dir" && pwd)
  if [ -f "$dir/slurm.conf" ]; then
    export SLURM_CONF=$dir/slurm.conf
    # Every job, whoever submitted it (a user's, under sudo, is not root's).
    local ids
    ids=$(squeue -h -o %A 2>/dev/null | sort -u || true)
    [ -n "$ids" ] && scancel --full $ids >/dev/null 2>&1 || true
    for _ in $(seq 75); do
      [ -z "$(squeue -h -t running,completing 2>/dev/null)" ] && break
      sleep 0.2
    done
  fi
  # The daemons, last started first, by their PID files: TERM, then KILL after 10 s.
  for name in slurmd slurmctld munged; do
    local file=$dir/$name.pid pid
    [ -f "$file" ] || continue
    pid=$(cat "$file")
    if [ "${pid:-0}" -gt 1 ] && kill -0 "$pid" 2>/dev/null; then
      kill -TERM "$pid" 2>/dev/null || true
      for _ in $(seq 200); do
        kill -0 "$pid" 2>/dev/null || break
        [ "$(awk '{print $3}' "/proc/$pid/stat" 2>/dev/null)" = Z ] && break
        sleep 0.05
      done
      kill -0 "$pid" 2>/dev/null && kill -KILL "$pid" 2>/dev/null || true
    fi
    rm -f "$file"
  done
}

case $action in
  start) start ;;
  stop) stop ;;
  *) usage ;;
esac
