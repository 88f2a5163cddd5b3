#!/usr/bin/env bash
# One segment of a chained mpdem run, then the decision what comes next.
# Used by every template in jobs/; also runs by hand (see jobs/README.md).
#
#   jobs/mpdem-segment.sh RUN_DIR CONFIG [KEY=VALUE ...] [-- RESUBMIT ...]
#   jobs/mpdem-segment.sh --sweep TABLE ROW ROOT CONFIG [KEY=VALUE ...] [-- RESUBMIT ...]
#
# CONFIG ('' = the built-in example) and each KEY=VALUE (a --set) are used by
# the first segment only (`mpdem run`); later segments `mpdem restart` RUN_DIR
# from its own config.toml. --sweep: row ROW of TABLE (1 = the first line after
# the header; '#' lines and blank lines skipped) adds its --set values after
# the KEY=VALUEs, and RUN_DIR is ROOT/<name> made from them, e.g.
# mu0.5_eps0.88_kn2e5_phi0.13_s1. Columns: mu epsilon k_n phi_i seed, or any
# section.key.
#
# restart if RUN_DIR has checkpoints/*.h5 or final.h5, else run (with --force
# if RUN_DIR/config.toml exists). Then, by mpdem's exit code:
#   0   finished                                  -> exit 0
#   3   hit run.max_steps without converging      -> exit 3, no resubmission
#       (0 or 3 without RUN_DIR/summary.json: mpdem did not run, e.g. a
#       launcher that failed to start it: exit 1, no resubmission)
#   75  interrupted, checkpoint written           -> run RESUBMIT, exit 0
#       (no RESUBMIT: exit 75, restart it yourself). Instead stop, exit 1, if
#       the newest checkpoint's number did not advance or MPDEM_MAX_SEGMENTS
#       segments have run; exit 75, no resubmission, if the ranks stopped for
#       SIGINT (scancel -s INT: a person's stop; RUN_DIR/log.txt's stop line)
#   any code, if this job itself got SIGTERM (cancelled, or at its limit): stop,
#       no resubmission (mpdem has checkpointed if it could: resubmit by hand)
#   any other: error                              -> that code, no resubmission
# One line per decision goes to RUN_DIR/jobs.log (and stderr); segments are
# counted in RUN_DIR/jobs.segments (delete it to reset the cap).
#
# Environment:
#   MPDEM_LAUNCH        MPI launcher, e.g. "srun --mpi=pmix", "mpiexec -n 8"; default (or
#                       "auto"): in a Slurm job whose srun offers pmix (srun --mpi=list),
#                       srun --mpi=pmix; else the repository's .venv/bin/mpiexec, else mpiexec
#   MPDEM_PYTHON        python (default the repository's .venv/bin/python, else python3)
#   MPDEM_CMD           the whole mpdem command, default "$MPDEM_LAUNCH $MPDEM_PYTHON -m mpdem"
#   MPDEM_WALLTIME      the job's time limit, [D-]HH:MM:SS. mpdem gets --walltime =
#                       the time left (of this, of Slurm's `squeue -o %L` or
#                       $SLURM_JOB_END_TIME, or Torque's $PBS_WALLTIME, whichever ends
#                       first) minus MPDEM_MARGIN; none of them known: no --walltime
#   MPDEM_MARGIN        seconds kept for checkpoint, shutdown, resubmission (default: a
#                       tenth of the time left, at least 20 and at most 300)
#   MPDEM_MAX_SEGMENTS  default 50
#   MPDEM_RESUBMIT      the resubmit command when none follows --
# SIGUSR1 and SIGTERM to this shell are forwarded to the launcher. When the
# resubmit command is qsub, every exported MPDEM_* variable is passed with -v
# (PBS does not pass the environment on); sbatch passes it anyway, and in a
# Slurm job gets the job's own size, time, partition, account and QOS (read
# back with scontrol), so options given on the first sbatch command line last.
set -euo pipefail
shopt -s nullglob
me=${0##*/}
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
die() { echo "$me: $*" >&2; exit 2; }
usage="usage: $me RUN_DIR CONFIG [KEY=VALUE ...] [-- RESUBMIT ...]
       $me --sweep TABLE ROW ROOT CONFIG [KEY=VALUE ...] [-- RESUBMIT ...]"

table=""
if [[ ${1:-} == --sweep ]]; then
  (( $# >= 5 )) || die "$usage"
  table=$2 row=$3 run_dir=$4 config=$5; shift 5
else
  (( $# >= 2 )) || die "$usage"
  run_dir=$1 config=$2; shift 2
fi
[[ -n $run_dir ]] || die "empty RUN_DIR"
sets=()
while (( $# )) && [[ $1 != -- ]]; do
  [[ $1 =~ ^[A-Za-z_][A-Za-z0-9_.]*= ]] || die "not KEY=VALUE: '$1'"
  sets+=(--set "$1"); shift
done
(( $# )) && shift
resub=("$@")
(( ${#resub[@]} )) || read -ra resub <<<"${MPDEM_RESUBMIT:-}"
# the launcher: what works here, and why (said in the log)
launch=${MPDEM_LAUNCH:-auto} launch_why="MPDEM_LAUNCH"
if [[ $launch == auto ]]; then
  if [[ -n ${SLURM_JOB_ID:-} ]] && command -v srun >/dev/null && srun --mpi=list 2>&1 | grep -qw pmix; then
    launch="srun --mpi=pmix" launch_why="Slurm offers pmix (srun --mpi=list)"
  elif [[ -x $repo/.venv/bin/mpiexec ]]; then
    launch=$repo/.venv/bin/mpiexec launch_why="the project's venv${SLURM_JOB_ID:+; Slurm offers no pmix}"
  else
    launch=mpiexec launch_why="on the PATH${SLURM_JOB_ID:+; Slurm offers no pmix}"
  fi
fi
python=${MPDEM_PYTHON:-}
if [[ -z $python ]]; then
  python=python3
  [[ ! -x $repo/.venv/bin/python ]] || python=$repo/.venv/bin/python
fi
read -ra cmd <<<"${MPDEM_CMD:-$launch $python -m mpdem}"
(( ${#cmd[@]} )) || die "empty MPDEM_CMD"
max=${MPDEM_MAX_SEGMENTS:-50} margin=${MPDEM_MARGIN:-auto}
[[ $max =~ ^[0-9]+$ && $margin =~ ^([0-9]+|auto)$ ]] || die "MPDEM_MAX_SEGMENTS, MPDEM_MARGIN: whole numbers"

# qsub passes no environment: hand every exported MPDEM_* on with -v
if (( ${#resub[@]} )) && [[ ${resub[0]##*/} == qsub ]]; then
  vars=""
  while read -r v; do
    [[ ${!v} != *[,$'\n']* ]] || die "$v holds a comma or newline, which qsub -v cannot pass; set it in the job script"
    vars+=${vars:+,}$v=${!v}
  done < <(compgen -e | grep '^MPDEM_' || true)
  [[ -z $vars ]] || resub=("${resub[0]}" -v "$vars" "${resub[@]:1}")
fi

# the sweep row: its --set values and the run directory's name
if [[ -n $table ]]; then
  [[ -r $table ]] || die "sweep table $table: not readable"
  [[ $row =~ ^[1-9][0-9]*$ ]] || die "sweep row '$row': not a positive whole number (no array task id?)"
  mapfile -t lines < <(awk '{ sub(/\r$/, "") } !/^[[:space:]]*(#|$)/' "$table")
  (( row < ${#lines[@]} )) || die "$table: no row $row (it has $(( ${#lines[@]} - 1 )))"
  read -ra hdr <<<"${lines[0]}"; read -ra val <<<"${lines[row]}"
  (( ${#hdr[@]} == ${#val[@]} )) || die "$table row $row: ${#val[@]} values for ${#hdr[@]} columns"
  name=""
  for i in "${!hdr[@]}"; do
    case ${hdr[i]} in
      mu) k=contact.mu t=mu ;;
      epsilon) k=contact.epsilon t=eps ;;
      k_n) k=contact.k_n t=kn ;;
      phi_i) k=pour.phi_i t=phi ;;
      seed) k=run.seed t=s ;;
      bed.seed) k=bed.seed t=bed ;;
      *.*) k=${hdr[i]} t=${hdr[i]#*.} ;;
      *) die "$table: unknown column '${hdr[i]}' (mu epsilon k_n phi_i seed, or section.key)" ;;
    esac
    [[ ${val[i]} =~ ^[A-Za-z0-9.+-]+$ ]] || die "$table row $row: value '${val[i]}' of ${hdr[i]}"
    sets+=(--set "$k=${val[i]}"); name+=${name:+_}$t${val[i]}
  done
  run_dir=$run_dir/$name
fi

# time left in this job, from every source there is
secs() { [[ $1 =~ ^(([0-9]+)-)?([0-9]+):([0-5][0-9]):([0-5][0-9])$ ]] || return 1
  echo $(( 10#${BASH_REMATCH[2]:-0} * 86400 + 10#${BASH_REMATCH[3]} * 3600 + 10#${BASH_REMATCH[4]} * 60 + 10#${BASH_REMATCH[5]} )); }
# squeue's %L: [D-]HH:MM:SS, MM:SS or SS (or UNLIMITED, NOT_SET, INVALID: none)
slurm_secs() {
  [[ $1 =~ ^(([0-9]+)-)?([0-9]+(:[0-9]+){0,2})$ ]] || return 1
  local d=${BASH_REMATCH[2]:-0} p n=0
  IFS=: read -ra p <<<"${BASH_REMATCH[3]}"
  # with days the fields are H[:M[:S]], without them [[H:]M:]S
  [[ -z ${BASH_REMATCH[1]} ]] || while (( ${#p[@]} < 3 )); do p+=(0); done
  for x in "${p[@]}"; do n=$(( n * 60 + 10#$x )); done
  echo $(( 10#$d * 86400 + n )); }
left=()
if [[ -n ${MPDEM_WALLTIME:-} ]]; then
  s=$(secs "$MPDEM_WALLTIME") || die "MPDEM_WALLTIME=$MPDEM_WALLTIME: not [D-]HH:MM:SS"
  left+=("$s")
fi
if [[ ${SLURM_JOB_END_TIME:-} =~ ^[0-9]+$ ]]; then left+=($(( SLURM_JOB_END_TIME - $(date +%s) ))); fi
if [[ -n ${SLURM_JOB_ID:-} ]] && command -v squeue >/dev/null; then
  if s=$(slurm_secs "$(squeue -h -j "$SLURM_JOB_ID" -o %L 2>/dev/null | head -n 1)"); then left+=("$s"); fi
fi
if [[ ${PBS_WALLTIME:-} =~ ^[0-9]+$ ]]; then left+=("$PBS_WALLTIME"); fi

mkdir -p "$run_dir"
job=${SLURM_JOB_ID:-${PBS_JOBID:-local-$$}}
# an array task by the name of its output file (ARRAYJOB_TASK), with its own job id
if [[ -n ${SLURM_ARRAY_JOB_ID:-} && -n ${SLURM_ARRAY_TASK_ID:-} ]]; then
  job="${SLURM_ARRAY_JOB_ID}_${SLURM_ARRAY_TASK_ID} (id $SLURM_JOB_ID)"
fi
log() { printf '%s job %s: %s\n' "$(date '+%Y-%m-%d %H:%M:%S')" "$job" "$*" | tee -a "$run_dir/jobs.log" >&2; }
newest() {  # the highest N of RUN_DIR/checkpoints/*N.h5, -1 if none
  local f n best=-1
  for f in "$run_dir"/checkpoints/*.h5; do
    n=${f##*/}; n=${n%.h5}; n=${n##*[!0-9]}
    if [[ -n $n ]] && (( 10#$n > best )); then best=$(( 10#$n )); fi
  done
  echo "$best"
}

seg_file=$run_dir/jobs.segments
done_n=0
[[ ! -s $seg_file ]] || done_n=$(<"$seg_file")
[[ $done_n =~ ^[0-9]+$ ]] || { log "error: $seg_file holds '$done_n', not a count"; exit 1; }
if (( done_n >= max )); then
  log "stop: $done_n segments have run, MPDEM_MAX_SEGMENTS=$max; not running (raise it, or delete $seg_file)"
  exit 1
fi
ckpts=("$run_dir"/checkpoints/*.h5)
before=$(newest)
if [[ -e $run_dir/final.h5 ]]; then
  args=(restart "$run_dir") what="restart (final.h5 exists)"
elif (( ${#ckpts[@]} )); then
  args=(restart "$run_dir") what="restart from checkpoint $before"
else
  [[ -z $config || -f $config ]] || { log "error: CONFIG $config not found"; exit 2; }
  args=(run) what=run
  [[ -z $config ]] || args+=("$config")
  args+=(--out "$run_dir")
  (( ${#sets[@]} == 0 )) || args+=("${sets[@]}")
  if [[ -e $run_dir/config.toml ]]; then args+=(--force) what="run --force (config.toml, no checkpoint)"; fi
fi
if (( ${#left[@]} )); then
  t=${left[0]}
  for l in "${left[@]}"; do (( l >= t )) || t=$l; done
  if [[ $margin == auto ]]; then  # a tenth of the job, 20 s to 300 s
    margin=$(( t / 10 )); (( margin >= 20 )) || margin=20; (( margin <= 300 )) || margin=300
  fi
  t=$(( t - margin - SECONDS ))
  (( t >= 30 )) || { log "error: under $(( margin + 30 ))s left in the job (margin $margin s); not running"; exit 1; }
  args+=(--walltime "$(printf '%02d:%02d:%02d' $(( t / 3600 )) $(( t % 3600 / 60 )) $(( t % 60 )))")
fi

# a resubmission by sbatch from inside a Slurm job asks for what this job got, read back
# from Slurm: options given on the first sbatch command line are not in the script
if (( ${#resub[@]} )) && [[ ${resub[0]##*/} == sbatch && -n ${SLURM_JOB_ID:-} ]] && command -v scontrol >/dev/null; then
  keep=()
  # (the record of this job only: for an array job scontrol lists every task)
  for kv in $(scontrol -o show job "$SLURM_JOB_ID" 2>/dev/null | grep -m 1 -E "^JobId=$SLURM_JOB_ID( |$)"); do
    k=${kv%%=*} v=${kv#*=}
    [[ -n $v && $v != "(null)" && $v != *[!A-Za-z0-9_.:/+-]* ]] || continue
    case $k in
      NumNodes) keep+=(--nodes="$v") ;;
      NumTasks) keep+=(--ntasks="$v") ;;
      CPUs/Task) keep+=(--cpus-per-task="$v") ;;
      TimeLimit) [[ $v == UNLIMITED ]] || keep+=(--time="$v") ;;
      Partition) keep+=(--partition="$v") ;;
      Account) keep+=(--account="$v") ;;
      QOS) keep+=(--qos="$v") ;;
      JobName) keep+=(--job-name="$v") ;;
    esac
  done
  resub=("${resub[0]}" ${keep[@]+"${keep[@]}"} "${resub[@]:1}")
fi

seg=$(( done_n + 1 ))
echo "$seg" >"$seg_file"
[[ -n ${MPDEM_CMD:-} ]] || log "launcher: $launch ($launch_why)"
log "segment $seg/$max: $what: ${cmd[*]} ${args[*]}"
got="" pid=""
forward() { got+=" $1"; [[ -z $pid ]] || kill -s "$1" "$pid" 2>/dev/null || true; }
trap 'forward USR1' USR1
trap 'forward TERM' TERM
# exit 75 is mpdem's "stopped with a checkpoint": drop the launcher's report of it, which reads
# like a crash (srun's "Exited with exit code 75", Open MPI's "non-zero status" blocks)
quiet75() {
  awk '
    /^srun: error: .*Exited with exit code 75$/ { next }
    /^--------------------+$/ { if (!inblk) { inblk = 1; blk = $0 "\n"; next }
                 inblk = 0; blk = blk $0 "\n"
                 if (blk ~ /Primary job +terminated normally/) { held = held blk }
                 else if (blk ~ /Exit code: *75\n/) { held = "" }
                 else { printf "%s%s", held, blk; held = "" }
                 fflush(); next }
    inblk { blk = blk $0 "\n"; next }
    { printf "%s", held; held = ""; print; fflush() }
    END { printf "%s%s", held, (inblk ? blk : "") }'
}
"${cmd[@]}" "${args[@]}" 2> >(quiet75 >&2) &
pid=$!
rc=0; wait "$pid" || rc=$?
while kill -0 "$pid" 2>/dev/null; do rc=0; wait "$pid" || rc=$?; done  # wait ended by a trap
trap - USR1 TERM
after=$(newest)

# mpdem's exit 0 and 3 leave RUN_DIR/summary.json; a launcher that could not start the ranks
# may exit 0 all the same (srun after "task 0 launch failed"): not a finished run
if [[ ($rc == 0 || $rc == 3) && ! -e $run_dir/summary.json ]]; then
  log "error: exit $rc but no $run_dir/summary.json: mpdem did not run to its end (did the launcher start it? see the job's output); not resubmitting"
  exit 1
fi
case $rc in
  0) log "finished (exit 0)"; exit 0 ;;
  3) log "not converged: stopped at run.max_steps (exit 3); not resubmitting"; exit 3 ;;
esac
if [[ $got == *TERM* ]]; then  # (Open MPI's mpiexec exits 1 here even when the ranks exit 75)
  log "stop: this job got SIGTERM (cancelled, or at its limit); exit $rc, newest checkpoint $after (before $before); not resubmitting"
  exit "$rc"
fi
if (( rc != 75 )); then log "error: exit $rc; not resubmitting"; exit "$rc"; fi
# SIGINT is a person's stop (`scancel -s INT`, which reaches the ranks, not this script):
# mpdem checkpoints and exits 75 as for the batch system's warning, and its log's stop line says which
if [[ -e $run_dir/log.txt ]] && [[ $(grep '^stop: ' "$run_dir/log.txt" | tail -n 1) == "stop: signal SIGINT "* ]]; then
  log "stop: the ranks got SIGINT (an interrupt); checkpoint $after written; not resubmitting"; exit 75
fi
if (( after <= before )); then
  log "stop: exit 75 but no new checkpoint (newest $after, before $before); not resubmitting"; exit 1
fi
if (( seg >= max )); then
  log "stop: checkpoint $after written; $seg segments = MPDEM_MAX_SEGMENTS; not resubmitting"; exit 1
fi
if (( ${#resub[@]} == 0 )); then
  log "interrupted (exit 75), checkpoint $after; no resubmit command: run this again"; exit 75
fi
log "checkpointed, resubmitting (mpdem exit 75: stopped before the time limit, checkpoint $after): ${resub[*]}"
out=$("${resub[@]}") || { rc=$?; log "error: resubmission failed (exit $rc); resubmit by hand"; exit 1; }
[[ -z $out ]] || echo "$out"
# a job Slurm will never start pends for ever without a word: say so, and take it back
new=$(sed -n 's/^Submitted batch job \([0-9][0-9]*\).*/\1/p' <<<"$out")
if [[ -n $new ]] && command -v squeue >/dev/null; then
  for _ in 1 2 3 4 5; do
    why=$(squeue -h -j "$new" -o %r 2>/dev/null | head -n 1 || true)
    case $why in
      PartitionConfig|PartitionNodeLimit|PartitionTimeLimit|BadConstraints|InvalidAccount|InvalidQOS|AccountNotAllowed|QOSMaxWallDurationPerJobLimit)
        log "error: Slurm will not start job $new ($why); cancelled it: mend the job's options and submit again"
        scancel "$new" 2>/dev/null || true
        exit 1 ;;
    esac
    sleep 1
  done
fi
