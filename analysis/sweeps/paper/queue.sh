#!/usr/bin/env bash
# The paper campaign's unfinished runs as one queue, in the order they decide the README's open rows, run
# JOBS at a time (default 2) on this machine's cores. Every job resumes where its runs stand (a ladder skips its
# converged rungs and restarts one from its newest checkpoint; a sweep skips its finished rows), so the same
# command goes on after any stop: a job whose work is done ends at once and the next one starts.
#   bash analysis/sweeps/paper/queue.sh                      # JOBS=2, logs in /tmp/mpdem-queue/<job>.log
#   JOBS=1 LOGS=DIR ONLY="flow ladder-mu0.5-s1" DEVICE=gpu bash analysis/sweeps/paper/queue.sh
# DEVICE (default cpu) is the ladders' rungs' device, THREADS (default 1) their threads (one ladder on both cores:
# JOBS=1 THREADS=2 ONLY=ladder-mu0.5-s2); a sweep's rows run as their run directories' configs say
#   bash analysis/sweeps/paper/queue.sh --list               # the jobs, in order, and what each decides
# A job's entry may name one it waits for: the rungs of one ladder never run twice at once.
# SIGTERM or SIGINT to the queue goes to every running job's processes: each run writes a checkpoint and
# stops; the queue starts nothing more and ends once all of them have ended (a ladder's shell ends at once,
# its run when its checkpoint is written). What the project keeps of the runs is committed by hand: an
# unfinished run's newest checkpoint (`git add -f`; its older ones untracked), a finished run's config.toml,
# summary.json, analysis/ and packing.npz (its checkpoints untracked); then `make collect-paper` and an entry
# in NOTES.md.
set -uo pipefail
cd "$(dirname "$0")/../../.." || exit 2
P=analysis/sweeps/paper R=analysis/results/paper/runs
PY=${PY:-.venv/bin/python}
JOBS=${JOBS:-2} LOGS=${LOGS:-/tmp/mpdem-queue}
sweep() { nice -n 10 "$PY" -m mpdem sweep "$P/$1" --config "$P/$2" --out "$R/$3" --jobs 1 --no-collect; }
# DEVICE (default cpu) for every rung: a checkpoint written on a lent GPU keeps engine.device = "gpu"
ladder() { DEVICE=${DEVICE:-cpu} nice -n 10 bash "$P/ladder.sh" "$@"; }

# name | what it decides | its function (below, with any words after it as arguments) | a job it waits for (one ladder's rungs are never run twice at once)
JOB_LIST=(
  "ladder-hertz|row 34: Hertzian ladders at N = 2000 from the three poured Hertzian piles to 2e6: the overlap fit's z_c of Hertz beside Hooke's|job_hertz|"
  "ladder-mu0-s2-2e7|rows 19-22: the second mu = 0 ladder's 2e7 rung|job_l0s2_2e7|"
  "ladder-mu0-s2-2e8|rows 19-22: the second mu = 0 ladder's 2e8 rung (does eq. 7 bend by 2e8?)|job_l0s2_2e8|ladder-mu0-s2-2e7"
  "ladder-hooke-dev|row 34: the Hookean ladders at N = 2000 from the same seeds' poured piles, to 2e8: the same protocol as the Hertzian ones|job_hooke_dev|"
  "stiff-friction|row 26: piles poured at 2e6 with friction, seeds 1 and 2 (the row's other side is the ladder's 2e6 rung)|job_stiff05|"
  "ladder-mu0.5-s1|rows 23-25 beside (with friction a stiffened pile is another protocol than the paper's pours): the mu = 0.5 ladder of seed 1 to 2e8|job_l05s1|"
  "ladder-mu0.5-s2|row 26's second stiffened seed (its 2e6 rung), rows 23-25 beside: the second mu = 0.5 ladder (its pour at 2e5 first)|job_l05s2|"
  "flow|rows 38-38d: the flow arrest kept on the incline (a second seed at 18 degrees, then 16), beside the levelled one|job_flow|"
  "stiff-2e7|row 23 at paper size: seed 1 poured at 2e7 with friction|job_stiff05_2e7|"
  "friction-seeds|rows 7, 7b, 8, 12: second seeds of mu = 0.1 and 1|job_size_d|"
  "strict|row 1: the stricter stop (E_stop = 1e-10) on seeds 2 and 3|job_strict|"
  "mu10-and-mu0-s4|rows 1, 9: a fourth mu = 0 seed, and mu = 10|job_size_c|"
  "ladder-hertz-top|row 34: the Hertzian ladders to 2e7 and 2e8 (eq. 7 with alpha_n free needs four k_n)|job_hertz_top|ladder-hertz"
)
job_flow() { sweep flow-arrest-tilted.tsv chute.toml flow; }
job_l05s1() { STOP_ENERGY=translational ladder 0.5 1 "$R/ladder-size/mu0.5_s1" 2e8; }
from0s2() { FROM=$R/size/mu0_eps0.88_kn2e5_phi0.13_s2_max_steps2e7 ladder 0 2 "$R/ladder-size/mu0_s2" "$1"; }
job_l0s2_2e7() { from0s2 2e7; }
# The N = 2000 ladders of row 34: the three poured piles of one contact law climb rung by rung, each from its
# committed packing (frictionless); a pile whose rung fails does not stop the others (the worst exit status is
# returned), a stop by signal or wall time does. A Hertzian pile's damping weakens as its overlaps shrink, so
# it settles far slower than a Hookean one: at 2e6 some 8e6 steps (half an hour of a core), the rungs above
# it hours each, and caps 4 times a Hookean rung's.
dev_ladders() {  # TAG MODEL TOP...: runs/dev/...s<seed><MODEL>_max_steps1e7 into runs/ladder-dev/mu0<TAG>_s<seed>
    local tag=$1 model=$2 s top rc worst=0
    shift 2
    for top in "$@"; do
        for s in 1 2 3; do
            FROM=$R/dev/mu0_eps0.88_kn2e5_phi0.13_s${s}${model}_max_steps1e7 \
                ladder 0 "$s" "$R/ladder-dev/mu0${tag}_s$s" "$top"
            rc=$?
            case $rc in 75|1[2-9][0-9]|2[0-9][0-9]) return $rc ;; esac
            [ $rc -gt $worst ] && worst=$rc
        done
    done
    return $worst
}
job_hertz() { CAP_FACTOR=4 dev_ladders _hertz _modelhertz 2e6; }
job_hertz_top() { CAP_FACTOR=4 dev_ladders _hertz _modelhertz 2e7 2e8; }
job_hooke_dev() { dev_ladders "" "" 2e6 2e7 2e8; }
job_stiff05() { sweep size-stiff-friction.tsv size.toml size; }
job_stiff05_2e7() { sweep size-stiff-2e7.tsv size.toml size; }
job_l05s2() { STOP_ENERGY=translational ladder 0.5 2 "$R/ladder-size/mu0.5_s2" 2e8; }
job_l0s2_2e8() { from0s2 2e8; }
job_strict() { sweep size-strict.tsv size.toml size; }
job_size_d() { sweep size-d.tsv size.toml size; }
job_size_c() { sweep size-c.tsv size.toml size; }

# QUEUE_DEFS=FILE: a bash file read here, which may redefine JOB_LIST and the functions (a site's own jobs)
if [ -n "${QUEUE_DEFS:-}" ]; then
    # shellcheck source=/dev/null
    source "$QUEUE_DEFS" || { echo "queue: QUEUE_DEFS=$QUEUE_DEFS: cannot be read"; exit 2; }
fi
if [ "${1:-}" = --list ]; then
    for j in "${JOB_LIST[@]}"; do
        IFS='|' read -r name what _ after <<< "$j"
        printf '%-20s %s%s\n' "$name" "$what" "${after:+ (after $after)}"
    done
    exit 0
fi
[ -x "$PY" ] || { echo "queue: no $PY (run \`make setup\` first, or set PY)"; exit 2; }
case "$JOBS" in ''|*[!0-9]*|0) echo "queue: JOBS=$JOBS: a positive whole number of jobs at once"; exit 2 ;; esac
mkdir -p "$LOGS" || exit 2
set -m      # each job in a process group of its own: a signal reaches its runs, not only its shell
stopping=0
declare -A pid=()
running() { [ -n "${pid[$1]:-}" ] && jobs -pr | grep -qx "${pid[$1]}"; }
groups=()   # the process groups signalled: the queue ends once every process in them has
stop() {
    stopping=1
    echo "queue: stopping: SIGTERM to every running job (each run writes a checkpoint)"
    for p in $(jobs -pr); do kill -TERM -- "-$p" 2>/dev/null; groups+=("$p"); done
}
trap stop TERM INT
todo=()
for j in "${JOB_LIST[@]}"; do
    IFS='|' read -r name _ _ _ <<< "$j"
    if [ -z "${ONLY:-}" ] || [[ " $ONLY " == *" $name "* ]]; then todo+=("$j"); fi
done
while [ "$stopping" = 0 ] && [ "${#todo[@]}" -gt 0 ]; do
    if [ "$(jobs -pr | wc -l)" -ge "$JOBS" ]; then wait -n; continue; fi
    next=-1
    for i in "${!todo[@]}"; do
        IFS='|' read -r name what fn after <<< "${todo[$i]}"
        if [ -z "$after" ] || ! running "$after"; then next=$i; break; fi
    done
    if [ "$next" = -1 ]; then wait -n; continue; fi     # each waits for a job still running
    IFS='|' read -r name what fn after <<< "${todo[$next]}"
    unset "todo[$next]"; todo=("${todo[@]}")
    echo "queue: $(date '+%F %T') start $name ($what): log $LOGS/$name.log"
    ( trap : TERM INT; $fn; rc=$?; echo "queue: $(date '+%F %T') $name ended with exit status $rc" ) \
        >> "$LOGS/$name.log" 2>&1 &
    pid[$name]=$!
    # a stop that came while this one was being started: it was not among the jobs signalled
    if [ "$stopping" = 1 ]; then kill -TERM -- "-$!" 2>/dev/null; groups+=("$!"); fi
done
while [ -n "$(jobs -pr)" ]; do wait -n; done
# a job's shell may end before its run (a ladder's bash dies at the signal): wait for the run's checkpoint
for p in "${groups[@]}"; do while kill -0 -- "-$p" 2>/dev/null; do sleep 1; done; done
echo "queue: $(date '+%F %T') nothing more to start$([ "$stopping" = 1 ] && echo ' (stopped by a signal)')"
