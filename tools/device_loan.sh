#!/usr/bin/env bash
# One lent GPU machine, one call (docs/gpu.md, "A loan in one call"): first the probe of every GPU variant
# (tools/gpu_probe.py, the GPU to itself), then, until UNTIL seconds after the start, the paper-size ladder
# rungs carried in .ladder/ stepped on the GPU (one core) while tools/scaling.py measures the CPU engine on
# the other cores; what comes back under $OUT (eight files at most): loan.log, probe.tgz, scaling.tgz and
# ladder.tgz in parts of 15 MiB (ladder.tgz.aa, .ab, ...; at most five).
#   here:  bash tools/device_slim.sh on; bash tools/device_loan.sh pack RUNG_DIR [...]   (.ladder/, .devdata/)
#   there: bash tools/device_loan.sh call          (OUT set; env below)
#   here:  bash tools/device_slim.sh off; cat FILES_AT/ladder.tgz.* > /tmp/ladder.tgz; bash tools/device_loan.sh unpack /tmp/ladder.tgz
# A RUNG_DIR is a rung of a ladder (analysis/sweeps/paper/ladder.sh) with a checkpoint: it travels as its
# small files and its newest checkpoint, restarts there on the GPU, and on converging is stiffened tenfold
# into the next rung (k_n <= LADDER_TOP) for as long as the call allows; a converged rung travels without
# one (frictionless: its packing.npz, not its final.h5; with friction its final.h5) and is stiffened at once
# (LADDER_TOP=2e9 for the paper's top rung); each stops with a checkpoint
# (--walltime) in time to be packed. Unpacked, each rung directory replaces its files here (its checkpoints
# here deleted first: a ladder running here must be stopped before).
# Env (call): UNTIL=530 (s), PROBE_BUDGET=260 (s), VARIANTS (gpu_probe's names, likeliest first),
# SHAPES=128,256, TILES=7x7, BIG_STEPS=50, SCALING_RANKS=1,2,4,8 (on cores 0-14; the rungs on core 15),
# SCALING_STEPS=500, SCALING_WIDE=none (or the wide case's tiles, 7x7, at the last rank count), LADDER_TOP=2e8; PROBE_BUDGET=0 leaves the probe out, LADDER_DEVICE=cpu LADDER_CORE=1
# SCALING_CORES=0 try the rest on a machine without a GPU, SCALING_RANKS=none leaves the scaling out;
# POUR=S (s, default 0: none) times a pour from nothing to its stop rule on the GPU after the probe, at most S s
# (POUR_CONFIG, default analysis/sweeps/paper/size.toml: the paper's size; POUR_SETS="key=value ...", default
# "run.max_steps=2e7";
# POUR_DEVICE=gpu), its steps, status and wall time in loan.log
# (tests/test_device_loan.py). EXCHANGE=S (s, default 0: none) then times two ranks on the one GPU, the bench's
# table with engine.gpu_exchange = "host" and "device" (EXCHANGE_STEPS=2000; EXCHANGE_TABLE, EXCHANGE_DEVICE,
# EXCHANGE_MPIEXEC and EXCHANGE_SETS="--set k=v ..." for a try without a GPU), their bench lines in loan.log.
# MPICH and mpi4py come from .whl/ (carried) for the scaling's ranks and the exchange's.
set -uo pipefail
cd "$(dirname "$0")/.."
RUNS_ROOT=${RUNS_ROOT:-analysis/results/paper/runs}

status_of() { python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['status'])" "$1/summary.json" 2>/dev/null; }
# a run's friction as its config.toml says (0 where it does not say: the default)
mu_of() { python3 -c "import sys, tomllib; print(f\"{tomllib.load(open(sys.argv[1], 'rb')).get('contact', {}).get('mu', 0.0):g}\")" "$1/config.toml" 2>/dev/null; }
rel() { python3 -c "import os,sys; print(os.path.relpath(sys.argv[1], sys.argv[2]))" "$1" "$2"; }

pack() {  # RUNG_DIR...: into .ladder/<path under RUNS_ROOT>, and the bench's table into .devdata/
    rm -rf .ladder; mkdir -p .ladder .devdata
    [ -f .devdata/landed20k.txt.gz ] || cp ../shared/bench/landed20k.txt.gz .devdata/ 2>/dev/null ||
        echo "device_loan: no ../shared/bench/landed20k.txt.gz: put the bench's table in .devdata/ for the probe" >&2
    for d in "$@"; do
        local ck r skip=()
        ck=$(ls "$d"/checkpoints/ckpt-*.h5 2>/dev/null | sort | tail -1)
        r=$(rel "$d" "$RUNS_ROOT")
        if [ -z "$ck" ] && [ "$(status_of "$d")" = converged ]; then
            # a converged rung, to be stiffened into the next there: a frictionless pile from its committed
            # packing (what anyone can start from), a frictional one from its final state (committed
            # only where a ladder's rung kept it)
            if [ -f "$d/packing.npz" ] && [ "$(mu_of "$d")" = 0 ]; then
                skip=(! -name 'final.*')
            elif [ ! -f "$d/final.h5" ]; then
                echo "device_loan: $d converged with friction but has no final.h5 to stiffen from" >&2; exit 2
            fi
        elif [ -z "$ck" ]; then
            echo "device_loan: $d has no checkpoint (and has not converged)" >&2; exit 2
        fi
        mkdir -p ".ladder/$r/checkpoints"
        echo "$r" >> .ladder/order          # the call steps the rungs in this order
        find "$d" -maxdepth 1 -type f ! -name '.*' "${skip[@]}" -exec cp -p {} ".ladder/$r/" \;
        if [ -n "$ck" ]; then
            cp -p "$ck" ".ladder/$r/checkpoints/"
            echo "device_loan: packed $r at $(basename "$ck")"
        else
            echo "device_loan: packed $r, converged: it is stiffened into the next rung there (LADDER_TOP)"
        fi
    done
    du -sh .ladder .devdata .whl 2>/dev/null || true
}

unpack() {  # TGZ: each rung directory back under RUNS_ROOT
    local tmp; tmp=$(mktemp -d)
    tar xzf "$1" -C "$tmp"
    local d
    for d in $(cd "$tmp/.ladder" && find . -name config.toml -printf '%h\n' | sort); do
        local src=$tmp/.ladder/$d dst=$RUNS_ROOT/$d
        mkdir -p "$dst/checkpoints"
        rm -f "$dst"/checkpoints/ckpt-*.h5   # the device's newest (or none: converged) is further on than any here
        cp -rp "$src"/. "$dst/"
        echo "device_loan: unpacked $d ($(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['status'])" "$dst/summary.json" 2>/dev/null || echo 'not ended'))"
    done
    rm -rf "$tmp"
    # a checkpoint keeps the run's engine.device = "gpu": the same bits go on here with --device cpu
    echo "device_loan: go on here with DEVICE=cpu bash analysis/sweeps/paper/ladder.sh ... (or restart --device cpu)"
}

hms() { printf '%02d:%02d:%02d' $(($1 / 3600)) $(($1 % 3600 / 60)) $(($1 % 60)); }


ladder() {  # each carried rung, then the next ones, until the deadline (seconds since the start)
    local deadline=$1 top=${LADDER_TOP:-2e8} d k next left
    # in the order packed (.ladder/order), else of their paths
    local order
    order=$( { [ -f .ladder/order ] && sed 's|^|.ladder/|' .ladder/order; } || find .ladder -name config.toml -printf '%h\n' | sort)
    for d in $order; do
        while :; do
            left=$((deadline - SECONDS - 15))
            [ "$left" -gt 60 ] || { echo "ladder: no time left for $d"; break; }
            if [ "$(status_of "$d")" != converged ]; then
                echo "ladder: $d restarted on ${LADDER_DEVICE:-gpu} for at most $left s"
                taskset -c "${LADDER_CORE:-15}" python3 -m mpdem restart "$d" --device "${LADDER_DEVICE:-gpu}" --walltime "$(hms "$left")" --quiet
                echo "ladder: $d exit status $? after $SECONDS s"
                [ "$(status_of "$d")" = converged ] || break
            fi
            k=${d##*/kn}
            [ "$k" = "$top" ] && break
            next=${d%/kn*}/kn$(python3 -c "import sys; print(f'{10 * float(sys.argv[1]):.0e}'.replace('e+0', 'e'))" "$k")
            left=$((deadline - SECONDS - 15))
            [ "$left" -gt 60 ] || break
            local cap; cap=$(python3 -c "import sys; print(f'{5e6 * (float(sys.argv[1]) / 2e5) ** 0.5:.3g}')" "${next##*/kn}")
            echo "ladder: $d converged; stiffened into $next on ${LADDER_DEVICE:-gpu} for at most $left s"
            taskset -c "${LADDER_CORE:-15}" python3 -m mpdem stiffen "$d" --k_n "${next##*/kn}" --out "$next" --force --device "${LADDER_DEVICE:-gpu}" \
                --walltime "$(hms "$left")" --quiet --set output.checkpoint_seconds=600 --set run.max_steps="$cap"
            echo "ladder: $next exit status $? after $SECONDS s"
            d=$next
            [ "$(status_of "$d")" = converged ] || break
        done
    done
    # what comes back: each rung's small files and its newest checkpoint (or none, once it converged)
    for d in $(find .ladder -name config.toml -printf '%h\n'); do
        ls "$d"/checkpoints/ckpt-*.h5 2>/dev/null | sort | head -n -1 | xargs -r rm -f
        [ "$(status_of "$d")" = converged ] && rm -f "$d"/checkpoints/ckpt-*.h5
    done
    # in parts of 15 MiB (a file that comes back is 16 MiB at most): cat ladder.tgz.* > ladder.tgz here
    tar czf - --exclude=.lock .ladder | split -b 15M - "$OUT/ladder.tgz."
}

pour() {  # S: a pour from nothing to its stop rule, at most S seconds, timed (the GPU to itself)
    local sets=() kv t=$SECONDS
    for kv in ${POUR_SETS:-run.max_steps=2e7}; do sets+=(--set "$kv"); done
    rm -rf /tmp/pour
    echo "pour: $(date -u +%T) ${POUR_CONFIG:-analysis/sweeps/paper/size.toml} ${sets[*]} on ${POUR_DEVICE:-gpu}, at most $1 s"
    timeout -s TERM "$1" python3 -m mpdem run "${POUR_CONFIG:-analysis/sweeps/paper/size.toml}" --device "${POUR_DEVICE:-gpu}" \
        --out /tmp/pour --force --quiet "${sets[@]}"
    echo "pour: exit status $? after $((SECONDS - t)) s; $(python3 -c "import json,sys; s = json.load(open(sys.argv[1])); print(f\"{s['status']} at step {s['steps']}, {s['wall_seconds']:.1f} s of stepping, digest {s['digest'][:16]}\")" /tmp/pour/summary.json 2>/dev/null || echo 'no summary: stopped before its end')"
    tail -n 3 /tmp/pour/log.txt 2>/dev/null
}

exchange() {  # S: two ranks on the one GPU, the bench's table with engine.gpu_exchange = host then device, at most S s
    (
        local t=$SECONDS mpi=${EXCHANGE_MPIEXEC:-} x left
        if [ -z "$mpi" ]; then
            python3 -m pip install -q --no-index --no-deps --no-compile --prefix /tmp/mp .whl/mpich-*.whl &&
            python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site .whl/mpi4py-*.whl ||
                { echo "exchange: no MPI (.whl/ carried?)"; exit 0; }
            export PATH=/tmp/mp/bin:$PATH LD_LIBRARY_PATH=/tmp/mp/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH} \
                PYTHONPATH=/tmp/site:$PYTHONPATH
            mpi=/tmp/mp/bin/mpiexec
        fi
        for x in host device; do
            left=$(($1 - (SECONDS - t)))
            [ "$left" -gt 20 ] || { echo "exchange $x: no time left"; break; }
            echo "exchange $x: $(date -u +%T) 2 ranks, ${EXCHANGE_DEVICE:-gpu}, ${EXCHANGE_STEPS:-2000} steps, at most $left s"
            # python3 by its path: a launcher may start the ranks with another PATH
            timeout -s TERM "$left" "$mpi" -n 2 "$(command -v python3)" -m mpdem bench --table "${EXCHANGE_TABLE:-.devdata/landed20k.txt.gz}" \
                --device "${EXCHANGE_DEVICE:-gpu}" --steps "${EXCHANGE_STEPS:-2000}" --set engine.gpu_exchange=$x \
                ${EXCHANGE_SETS:-} > "/tmp/exchange-$x.log" 2>&1
            echo "exchange $x: exit status $? after $((SECONDS - t)) s"
            grep -E "^bench: (2 rank|phase|steps)|^ns_per_atom_step" "/tmp/exchange-$x.log" | sed "s/^/exchange $x: /"
        done
    )
}

call() {
    : "${OUT:?OUT: the folder that comes back}"
    local until=${UNTIL:-530} t0=$SECONDS
    exec > >(tee -a "$OUT/loan.log") 2>&1
    # the sources by their physical path: numba's cache of compiled kernels is found by it (a checkout that links
    # src elsewhere would compile every kernel again)
    export PYTHONPATH=$(cd src && pwd -P) PYTHONUNBUFFERED=1
    echo "device_loan $(date -u +%FT%TZ) at $(git rev-parse --short HEAD 2>/dev/null || echo '?'); $(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null); $(nproc) cores"
    [ "${PROBE_BUDGET:-260}" = 0 ] || python3 tools/gpu_probe.py all .devdata/landed20k.txt.gz "$OUT/probe" --no-anatomy \
        --budget "${PROBE_BUDGET:-260}" --tiles "${TILES:-7x7}" --big-steps "${BIG_STEPS:-50}" \
        ${VARIANTS:+--variants "$VARIANTS"} --shapes "${SHAPES:-128,256}"
    echo "probe: exit status $? after $((SECONDS - t0)) s"
    [ -d "$OUT/probe" ] && tar czf "$OUT/probe.tgz" -C "$OUT" probe && rm -rf "$OUT/probe"
    [ "${POUR:-0}" = 0 ] || pour "$POUR"
    [ "${EXCHANGE:-0}" = 0 ] || exchange "$EXCHANGE"
    # the CPU engine's scaling beside the rungs (cores 0-14), with MPICH from the carried wheels
    (
        [ "${SCALING_RANKS:-}" = none ] && exit 0
        python3 -m pip install -q --no-index --no-deps --no-compile --prefix /tmp/mp .whl/mpich-*.whl &&
        python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site .whl/mpi4py-*.whl || exit
        export PATH=/tmp/mp/bin:$PATH LD_LIBRARY_PATH=/tmp/mp/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH} \
            PYTHONPATH=/tmp/site:$PYTHONPATH
        left=$((until - (SECONDS - t0) - 20))
        [ "$left" -gt 30 ] || { echo "scaling: no time left"; exit 0; }
        timeout -s TERM "$left" taskset -c "${SCALING_CORES:-0-14}" python3 tools/scaling.py .devdata/landed20k.txt.gz "$OUT/scaling" \
            --ranks "${SCALING_RANKS:-1,2,4,8}" --steps "${SCALING_STEPS:-500}" --wide "${SCALING_WIDE:-none}" --wide-steps 50 --timeout 90 \
            --mpiexec /tmp/mp/bin/mpiexec
        echo "scaling: exit status $? after $((SECONDS - t0)) s"
    ) &
    local sp=$!
    [ -d .ladder ] && ladder $((t0 + until))
    wait "$sp"
    [ -d "$OUT/scaling" ] && tar czf "$OUT/scaling.tgz" -C "$OUT" scaling && rm -rf "$OUT/scaling"
    echo "device_loan: done after $((SECONDS - t0)) s"
    ls -la "$OUT"
}

case "${1:-}" in
    pack) shift; pack "$@" ;;
    unpack) shift; unpack "$@" ;;
    call) call ;;
    *) echo "usage: bash tools/device_loan.sh pack RUNG_DIR... | call | unpack LADDER.tgz" >&2; exit 2 ;;
esac
