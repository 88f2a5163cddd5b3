#!/usr/bin/env bash
# A single-node Slurm on this machine, for trying the job templates (and for
# the `slurm` tests): munged, slurmctld and slurmd with a generated config in DIR.
#
#   tools/local-slurm.sh start DIR    # then: export SLURM_CONF=DIR/slurm.conf
#   tools/local-slurm.sh stop DIR
#   tools/local-slurm.sh check        # can it run here? (exit 0, or 1 with the reason)
#
# Needs root and Debian's slurm-wlm and munge (apt-get install slurm-wlm munge).
# Everything lives in DIR (state, spool, logs, pid files) except munged, which
# uses the system's key and socket; stop stops only what start started.
set -euo pipefail
me=${0##*/}
die() { echo "$me: $*" >&2; exit 1; }

check() {
  [[ $(id -u) == 0 ]] || { echo "not root (slurmd must run as root)"; return 1; }
  local c
  for c in munged slurmctld slurmd sbatch squeue scontrol; do
    command -v "$c" >/dev/null 2>&1 || [[ -x /usr/sbin/$c ]] || { echo "no $c (apt-get install slurm-wlm munge)"; return 1; }
  done
  [[ -r /etc/munge/munge.key ]] || { echo "no /etc/munge/munge.key"; return 1; }
}

start() {
  local dir=$1 host cpus mem port
  why=$(check) || die "cannot run Slurm here: $why"
  mkdir -p "$dir"/{state,spool}
  dir=$(cd "$dir" && pwd)
  host=$(hostname -s)
  read -r cpus mem < <(/usr/sbin/slurmd -C | awk '/^NodeName/ { for (i = 1; i <= NF; i++) { split($i, kv, "=");
    if (kv[1] == "CPUs") c = kv[2]; if (kv[1] == "RealMemory") m = kv[2] } } END { print c, m }')
  # ports of our own, away from a system Slurm's 6817/6818
  port=${LOCAL_SLURM_PORT:-16817}
  cat >"$dir/slurm.conf" <<EOF
ClusterName=local
SlurmctldHost=$host
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
SchedulerType=sched/backfill
SchedulerParameters=sched_interval=2
MessageTimeout=20
KillWait=30
InactiveLimit=0
MinJobAge=600
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
NodeName=$host CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=local Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
  # pmix's per-step client directories in DIR too: job ids start at 1 in every new DIR, and a
  # /tmp/spmix_appdir_0_2.0 left by an earlier instance fails step 2.0's launch ("File exists")
  mkdir -p "$dir/pmix"
  echo "PMIxCliTmpDirBase=$dir/pmix" >"$dir/mpi.conf"
  if ! pgrep -x munged >/dev/null; then
    mkdir -p /run/munge && chown munge:munge /run/munge
    runuser -u munge -- /usr/sbin/munged
    touch "$dir/munged.started"
  fi
  export SLURM_CONF=$dir/slurm.conf
  /usr/sbin/slurmctld -f "$SLURM_CONF" -c -i
  /usr/sbin/slurmd -f "$SLURM_CONF" -c
  local _
  for _ in $(seq 60); do
    if sinfo -h -o %T 2>/dev/null | grep -qx idle; then
      echo "$me: Slurm up in $dir (export SLURM_CONF=$SLURM_CONF)"; return 0
    fi
    sleep 1
  done
  echo "$me: Slurm did not come up; slurmctld.log:" >&2; tail -20 "$dir/slurmctld.log" >&2
  echo "$me: slurmd.log:" >&2; tail -20 "$dir/slurmd.log" >&2
  stop "$dir"; return 1
}

stop() {
  local dir=$1 f pid
  [[ -d $dir ]] || return 0
  export SLURM_CONF=$dir/slurm.conf
  if [[ -e $SLURM_CONF ]]; then
    scancel --state=PENDING,RUNNING -u root 2>/dev/null || true
    # let the cancelled jobs' steps end before slurmd goes, or their slurmstepd outlive it
    for _ in $(seq 60); do [[ -z $(squeue -h 2>/dev/null) ]] && break; sleep 0.5; done
  fi
  for f in slurmd slurmctld; do
    pid=$(cat "$dir/$f.pid" 2>/dev/null || true)
    if [[ -n $pid ]] && kill "$pid" 2>/dev/null; then
      for _ in $(seq 30); do kill -0 "$pid" 2>/dev/null || break; sleep 0.5; done
      kill -9 "$pid" 2>/dev/null || true
    fi
  done
  if [[ -e $dir/munged.started ]]; then pkill -x munged || true; rm -f "$dir/munged.started"; fi
}

case ${1:-} in
  start) (( $# == 2 )) || die "usage: $me start DIR"; start "$2" ;;
  stop) (( $# == 2 )) || die "usage: $me stop DIR"; stop "$2" ;;
  check) check ;;
  *) die "usage: $me start DIR | stop DIR | check" ;;
esac
