#!/usr/bin/env bash
# The digests of a fixed set of short runs, one line each: "name digest".
# A refactor that must keep every bit runs this on main and on its branch and diffs the two outputs:
#   bash tools/digests.sh > /tmp/before.txt   (on main)
#   bash tools/digests.sh > /tmp/after.txt    (on the branch); diff /tmp/before.txt /tmp/after.txt
# Cases: frictionless and frictional Hookean piles, Hertz, a wall under the bed, the rotate history,
# each on 1 rank and the frictional one on 2 ranks (one thread: threads are checked by the tests), and a restart from a checkpoint.
# Exit status 3 (max_steps reached) is expected: the piles are still falling. About 2 minutes on 2 idle cores.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-.venv/bin/python}
MPIEXEC=${MPIEXEC:-$(dirname "$PY")/mpiexec}
export PYTHONPATH=src${PYTHONPATH:+:$PYTHONPATH}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
common=(--set pour.N=300 --set box.L_x=8 --set box.L_y=8 --set run.max_steps=40000 --set run.seed=3)
case_() {  # name ranks threads sets...
    local name=$1 n=$2 t=$3; shift 3
    "$MPIEXEC" -n "$n" "$PY" -m mpdem run --out "$out/$name" --threads "$t" "${common[@]}" "$@" > "$out/$name.log" 2>&1 \
        || [ $? -eq 3 ] || { echo "$name: run failed"; tail -5 "$out/$name.log"; exit 1; }
    echo "$name $("$PY" -m mpdem info "$out/$name/final.h5" --digest | tail -1)"
}
case_ mu0 1 1 --set contact.mu=0
case_ mu0.5 1 1 --set contact.mu=0.5
case_ mu0.5-2ranks 2 1 --set contact.mu=0.5
case_ hertz 1 1 --set contact.model=hertz --set contact.mu=0.5
case_ wall 1 1 --set bed.wall=true --set contact.mu=0.5
case_ rotate 1 1 --set contact.history=rotate --set contact.mu=1
# a restart: the first 20000 steps, then the rest from the checkpoint
"$MPIEXEC" -n 2 "$PY" -m mpdem run --out "$out/restart" "${common[@]}" --set contact.mu=0.5 --set run.max_steps=20000 \
    --set output.checkpoint_every=20000 > "$out/restart.log" 2>&1 || [ $? -eq 3 ]
"$MPIEXEC" -n 1 "$PY" -m mpdem restart "$out/restart" --set run.max_steps=40000 >> "$out/restart.log" 2>&1 || [ $? -eq 3 ]
echo "restart $("$PY" -m mpdem info "$out/restart/final.h5" --digest | tail -1)"
