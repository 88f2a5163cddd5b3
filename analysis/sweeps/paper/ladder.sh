#!/usr/bin/env bash
# A stiffening ladder (docs/model.md 6.6, `mpdem stiffen`): a pile poured at k_n = 2e5, then stiffened tenfold
# rung by rung to TOP, each rung through the ramp (stiffen.ramp_time, default 10 tau) and settled by the stop rule.
# Each rung is its own run directory OUT/kn<K>; run again, the script skips the rungs that converged and restarts
# one that stopped early from its newest checkpoint. A rung that ends at run.max_steps without converging ends
# the ladder (exit 3).
#   bash analysis/sweeps/paper/ladder.sh MU SEED OUT [TOP] [CONFIG]
#   bash analysis/sweeps/paper/ladder.sh 0 4 analysis/results/paper/runs/ladder-dev/mu0_s4 2e8 analysis/sweeps/dev/dev.toml
#   FROM=analysis/results/paper/runs/size/mu0_eps0.88_kn2e5_phi0.13_s1_bed101_max_steps2e7 \
#     bash analysis/sweeps/paper/ladder.sh 0 1 analysis/results/paper/runs/ladder-size/mu0_s1_bed101 2e8
# FROM=RUN starts the ladder from a converged run instead of pouring OUT/kn2e5 (its final.h5 is the first rung's
# start; MU and SEED are then only the ladder's labels and must match it): a pile already poured at the paper's size.
# A committed run keeps its packing.npz, not its final.h5: at MU = 0 the ladder starts from that packing at rest
# (no tangential force needs a history); a frictional pile needs its final.h5 (pour it again: the same bits).
# CAP_FACTOR multiplies each new rung's cap on steps (below). DEVICE=gpu runs each rung on the GPU engine (the same bits), WALLTIME=HH:MM:SS stops a rung with a checkpoint
# before that much wall time (exit 75: run the script again to go on). THREADS=T steps each rung on T threads (the
# same bits; a ladder that should finish first gets both cores of a two-core machine). STOP_ENERGY=translational stops each
# stiffened rung it starts or restarts on the translational energy (docs/config.md `stop.energy`): for a frictional
# pile whose total energy a sphere spinning about its contacts holds above E_stop (docs/model.md 5.4). The pour
# keeps the config's rule: it is the poured set's pile (the same bits), the ladder's base.
# Each converged rung is analysed (mpdem analyze --packing). The committed rungs of analysis/results/paper keep
# their summary.json, config.toml, analysis/ and packing.npz;
# final.h5 (needed by the next rung) stays in the run directory, not in git.
set -uo pipefail
mu=$1 seed=$2 out=$3 top=${4:-2e8} cfg=${5:-analysis/sweeps/paper/size.toml}
PY=${PY:-.venv/bin/python}
opts=(--quiet ${DEVICE:+--device "$DEVICE"} ${WALLTIME:+--walltime "$WALLTIME"} ${THREADS:+--threads "$THREADS"})
stop_opts=(${STOP_ENERGY:+--set stop.energy="$STOP_ENERGY"})     # the stiffened rungs' only
mkdir -p "$out"
status() { "$PY" -c "import json,sys; print(json.load(open(sys.argv[1]))['status'])" "$1/summary.json" 2>/dev/null; }
analyse() {  # dir: its analysis and packing.npz (what git keeps of a rung), once
    [ -f "$1/analysis/summary.json" ] || "$PY" -m mpdem analyze "$1" --no-plots --quiet --packing
}
rung() {  # dir max_steps command...: the rung, unless it converged; a restart where it has a checkpoint
    local dir=$1 cap=$2; shift 2
    local extra=("${stop_opts[@]}")
    [ "$dir" = "$out/kn2e5" ] && extra=()      # the pour: the config's stop rule
    case "$(status "$dir")" in
        converged) echo "ladder: $dir converged before"; analyse "$dir"; return 0 ;;
        max_steps) echo "ladder: $dir ended at its cap without converging: the ladder stops here"; return 3 ;;
    esac
    if ls "$dir"/checkpoints/ckpt-*.h5 > /dev/null 2>&1; then
        "$PY" -m mpdem restart "$dir" "${opts[@]}" "${extra[@]}"
    else
        "$@" --out "$dir" --force "${opts[@]}" "${extra[@]}" --set run.max_steps="$cap"
    fi
    local rc=$?
    echo "ladder: $dir exit status $rc"
    [ $rc -eq 0 ] && analyse "$dir"
    return $rc
}
# the caps: some 5 times the steps a rung took at development size (1e6 at 2e5; the ramp alone is 10 tau / dt),
# times CAP_FACTOR (default 1: a Hertzian pile, whose damping weakens as its overlaps shrink, takes several times
# a Hookean pile's steps)
if [ -n "${FROM:-}" ]; then
    [ "$(status "$FROM")" = converged ] && { [ -f "$FROM/final.h5" ] || [ -f "$FROM/packing.npz" ]; } || {
        echo "ladder: FROM=$FROM is not a converged run with its final.h5 (or packing.npz, frictionless)"; exit 2; }
    "$PY" - "$FROM/config.toml" "$mu" "$seed" <<'PY' || exit 2
import sys, tomllib
c = tomllib.load(open(sys.argv[1], "rb"))
mu, seed = c["contact"]["mu"], c["run"]["seed"]
if (mu, seed) != (float(sys.argv[2]), int(sys.argv[3])):
    sys.exit(f"ladder: FROM has mu = {mu}, seed = {seed}, not MU = {sys.argv[2]}, SEED = {sys.argv[3]}")
PY
    analyse "$FROM"
    prev=$FROM
else
    rung "$out/kn2e5" 1e7 "$PY" -m mpdem run "$cfg" --set contact.mu="$mu" --set run.seed="$seed" \
        --set output.checkpoint_seconds=600 || exit $?
    prev=$out/kn2e5
fi
for k in 2e6 2e7 2e8 2e9; do
    rung "$out/kn$k" "$("$PY" -c "print(f'{5e6 * ${CAP_FACTOR:-1} * ($k / 2e5) ** 0.5:.3g}')")" \
        "$PY" -m mpdem stiffen "$prev" --k_n "$k" --set output.checkpoint_seconds=600 || exit $?
    prev=$out/kn$k
    [ "$k" = "$top" ] && break
done
echo "ladder: $out done to k_n = $top"
