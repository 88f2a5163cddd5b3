#!/usr/bin/env bash
# The GPU engine on a real GPU, in one go (docs/gpu.md): the engine tests compiled for the GPU, the
# digests of the GPU engine against the CPU engine's on three piles (the example at mu = 0.5 and 0,
# the LAMMPS equivalence pile with Hooke and with Hertz), a restart that switches device, the GPU run
# to run, then the timings (bench on the 20k table and its 7 x 7 tiles, a paper-size pour's first
# steps). For a bare machine with a GPU and no network: needs python3 with numpy, numba, numba-cuda,
# scipy, h5py and mpi4py (an MPI library only for RANKS > 1); writes its logs and a summary to $OUT
# (default ./gpu_check_out) and prints the summary table last. About 5 minutes on an H100.
#   bash tools/gpu_check.sh [TABLE]        TABLE: the bench's landed20k.txt.gz (no timings of it without)
#   (to a lent machine: `bash tools/device_slim.sh on` before the call, `off` after: the checkout's packings
#   would pass the 64 MiB it takes; docs/gpu.md)
#   POUR_MINUTES=6 bash tools/gpu_check.sh TABLE     also the paper-size pour to its stop rule (or 6 minutes):
#       the config of a committed CPU run (REF, default the paper-size mu = 0.5 seed 1), its digest against that run's
#   PARTS="..."   which parts run, in this order whatever the order named (default all but profile):
#       bench (the GPU on the 20k table, a thread a row and an entry, and its tiles; BENCH_CPU=1 the CPU too), pour (with POUR_MINUTES),
#       digests (CPU against GPU on the example at mu = 0.5 and 0, the LAMMPS pile with Hooke and Hertz, a
#       flow-arrest pile, a stiffening rung), quick (of those the example at mu = 0.5 alone, a thread a row and
#       a thread an entry: a minute), switch (a restart that switches device, run to run, 2 ranks),
#       pytest (the engine tests compiled for the GPU), profile (Nsight Compute's launch, occupancy, throughput
#       and stall sections of the fused steps and the list build, where `ncu` is found), anatomy
#       (tools/gpu_anatomy.py: a fused step with the rows and over no rows, blocks of 128 and 256, a thread a row
#       and a thread an entry), rows (ROWS: sweep tables run on the GPU, below)
#   TILE=none  no bench of the 7 x 7 tiles (a minute of the bench part)
#   WORK=DIR   where the runs go (default $OUT/work; emptied first unless KEEP_WORK=1)
# SIZE=small runs every check on tiny piles (a dry run, e.g. under NUMBA_ENABLE_CUDASIM=1 without a GPU).
set -uo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-python3}
OUT=${OUT:-$PWD/gpu_check_out}
TABLE=${1:-}
SIZE=${SIZE:-full}
mkdir -p "$OUT"
export PYTHONPATH=$PWD/src${PYTHONPATH:+:$PYTHONPATH} PYTHONUNBUFFERED=1 OMPI_MCA_rmaps_base_oversubscribe=1
# Open MPI as root (the machines with a GPU here run commands as root); its mpiexec is the one mpi4py needs
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
SUM=$OUT/summary.txt
: > "$SUM"
say() { echo "$*" | tee -a "$SUM"; }
PARTS=${PARTS:-bench digests pour switch pytest}
has() { case " $PARTS " in *" $1 "*) return 0;; esac; return 1; }
w=${WORK:-$OUT/work}
[ "${KEEP_WORK:-0}" = 1 ] || rm -rf "$w"
mkdir -p "$w"
if [ "$SIZE" = small ]; then
    EX=(--set pour.N=40 --set box.L_x=4 --set box.L_y=4 --set pour.K0=5 --set contact.k_n=2e3); EXSTEPS=200
    LSTEPS=100; BSTEPS=20; TSTEPS=5; TILE=1x1; POUR=(--set pour.N=60 --set box.L_x=4 --set box.L_y=4); PSTEPS=100
    STIFF=(--k_n 2e4 --set run.max_steps=100 --set stiffen.ramp_time=0.02 --set stiffen.update_interval=0.005)
    FLOWT=0.1
else
    EX=(); EXSTEPS=30000; LSTEPS=2000; BSTEPS=2000; TSTEPS=200; TILE=${TILE:-7x7}
    POUR=(--set pour.N=20000 --set box.L_x=20 --set box.L_y=20); PSTEPS=20000
    STIFF=(--k_n 2e6 --set run.max_steps=3000 --set stiffen.ramp_time=0.05)
    FLOWT=1.5
fi

say "gpu_check $(date -u +%FT%TZ) at $(git rev-parse --short HEAD 2>/dev/null || echo '?')"
say "gpu: $(nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>/dev/null || echo none)"
say "python: $($PY -c 'import sys, numpy, numba; print(sys.version.split()[0], "numpy", numpy.__version__, "numba", numba.__version__)')"
$PY -c 'import importlib.metadata as m; print("numba-cuda", m.version("numba-cuda"))' 2>/dev/null | tee -a "$SUM"

t0=$SECONDS
digest() { $PY -c "import json,sys; print(json.load(open(sys.argv[1]))['digest'])" "$1/summary.json" 2>/dev/null; }
run() {  # name device steps sets...: a run; prints its digest and seconds
    local name=$1 dev=$2 steps=$3; shift 3
    local t=$SECONDS
    $PY -m mpdem run --out "$w/$name" --force --quiet --device "$dev" --set run.max_steps="$steps" \
        --set output.progress_every=100000 "$@" > "$w/$name.log" 2>&1
    local rc=$?
    local dg
    dg=$(digest "$w/$name" || echo "failed(rc=$rc)")
    echo "$dg $((SECONDS - t))"
}
compare() {  # label sets...: the same run on the CPU and on the GPU
    local label=$1 steps=$2; shift 2
    read -r dc sc < <(run "$label-cpu" cpu "$steps" "$@")
    read -r dg sg < <(run "$label-gpu" gpu "$steps" "$@")
    local v=DIFFER; [ "$dc" = "$dg" ] && v=equal
    say "digest $label ($steps steps): cpu ${dc:0:16} (${sc} s) gpu ${dg:0:16} (${sg} s): $v"
}
# 1. timings
if has bench; then
    if [ -n "$TABLE" ] && [ -f "$TABLE" ]; then
        devs=(gpu); [ "${BENCH_CPU:-0}" = 1 ] && devs+=(cpu cpu16)
        for dev in "${devs[@]}"; do
            opt=(--device ${dev%16}); [ $dev = cpu16 ] && opt+=(--threads 16)
            $PY -m mpdem bench --table "$TABLE" "${opt[@]}" --steps $BSTEPS > "$OUT/bench-$dev.log" 2>&1
            say "bench 20k $dev: $(grep -h 'rank(s)' "$OUT/bench-$dev.log" | head -1 | cut -c1-160)"
            say "    $(tail -1 "$OUT/bench-$dev.log")"
        done
        grep -h "bench: " "$OUT/bench-gpu.log" | sed -n '3,9p' | tee -a "$SUM"
        # the forces a thread an entry (engine.gpu_threads)
        $PY -m mpdem bench --table "$TABLE" --device gpu --set engine.gpu_threads=entry --steps $BSTEPS \
            > "$OUT/bench-gpu-entry.log" 2>&1
        say "bench 20k gpu, a thread an entry: $(tail -1 "$OUT/bench-gpu-entry.log")"
        if [ "$TILE" != none ]; then
            $PY -m mpdem bench --table "$TABLE" --device gpu --steps $TSTEPS --tile $TILE > "$OUT/bench-gpu-tile.log" 2>&1
            say "bench $TILE tiles gpu: $(tail -1 "$OUT/bench-gpu-tile.log")"
        fi
    else
        say "bench: no table at $TABLE"
    fi
fi
# 2. POUR_MINUTES=M: a committed CPU run's pour (REF: its config.toml and summary.json) from its start to its stop
# rule on the GPU, or M minutes of it; the issue's target for the paper size: 5 minutes. Converged, its digest is
# compared with the CPU run's.
if has pour && [ "${POUR_MINUTES:-0}" -gt 0 ]; then
    REF=${REF:-analysis/results/paper/runs/size/mu0.5_eps0.88_kn2e5_phi0.13_s1_max_steps2e7}
    t=$SECONDS
    $PY -m mpdem run "$REF/config.toml" --out "$w/whole" --force --quiet --device gpu \
        --set output.progress_every=1000000 --walltime "00:$(printf %02d "$POUR_MINUTES"):00" > "$w/whole.log" 2>&1
    rc=$?
    dw=$(digest "$w/whole"); dr=$(digest "$REF")
    v=DIFFER; [ -n "$dw" ] && [ "$dw" = "$dr" ] && v=equal
    say "pour to the stop rule on the gpu ($REF): exit status $rc (0 converged, 75 the time ran out) after $((SECONDS - t)) s; thermo's last step,E_k,rebuilds,loop seconds: $(tail -1 "$w/whole/thermo.csv" | cut -d, -f1,3,10,11)"
    say "    digest ${dw:0:16} against the CPU run's ${dr:0:16} ($(grep -o '"steps": [0-9]*' "$REF/summary.json")): $v"
    tail -3 "$w/whole.log" | tee -a "$SUM"
fi
# 3. the digests, CPU against GPU
entry_digest() {  # the forces a thread an entry (engine.gpu_threads = "entry") against the CPU run of the first pile
    read -r de se < <(run example-mu0.5-entry gpu $EXSTEPS "${EX[@]}" --set contact.mu=0.5 --set engine.gpu_threads=entry)
    dc=$(digest "$w/example-mu0.5-cpu")
    v=DIFFER; [ -n "$dc" ] && [ "$dc" = "$de" ] && v=equal
    say "digest example-mu0.5, a thread an entry ($EXSTEPS steps): cpu ${dc:0:16} gpu ${de:0:16} (${se} s): $v"
}
if has quick && ! has digests; then
    compare example-mu0.5 $EXSTEPS "${EX[@]}" --set contact.mu=0.5
    entry_digest
fi
if has digests; then
    compare example-mu0.5 $EXSTEPS "${EX[@]}" --set contact.mu=0.5
    compare example-mu0 $EXSTEPS "${EX[@]}" --set contact.mu=0
    LMP=(--set 'run.initial_file="tests/data/lammps_sphere.data"' --set 'run.fixed_types=[2]' --set contact.gamma_t=20)
    compare lammps-hooke $LSTEPS "${LMP[@]}" --set contact.mu=0.5
    compare lammps-hertz $LSTEPS "${LMP[@]}" --set contact.mu=0.5 --set contact.model=hertz --set bed.wall=true
    # flow arrest (docs/model.md 5.5): poured onto a bed tilted by 25 degrees, levelled halfway
    compare flow-arrest $EXSTEPS "${EX[@]}" --set contact.mu=0.5 --set flow.incline=25 --set flow.time=$FLOWT
    entry_digest
    # a stiffening rung of that pile (docs/model.md 6.6: the ramp's laws, the history rescaled) on both devices
    for dev in cpu gpu; do
        $PY -m mpdem stiffen "$w/example-mu0.5-cpu" "${STIFF[@]}" --out "$w/stiff-$dev" --force --quiet --device $dev \
            > "$w/stiff-$dev.log" 2>&1
    done
    dc=$(digest "$w/stiff-cpu"); dg=$(digest "$w/stiff-gpu")
    v=DIFFER; [ -n "$dc" ] && [ "$dc" = "$dg" ] && v=equal
    say "digest stiffened ${STIFF[*]:0:2}: cpu ${dc:0:16} gpu ${dg:0:16}: $v"
    say "digests done at $((SECONDS - t0)) s"
fi
# 4. a restart that switches device, run to run, two ranks
if has switch; then
    # a restart that switches device: the first half on the CPU, the rest on the GPU
    half=$((EXSTEPS / 2))
    $PY -m mpdem run --out "$w/switch" --force --quiet --device cpu --set run.max_steps=$half \
        --set output.checkpoint_every=$half "${EX[@]}" --set contact.mu=0.5 > "$w/switch.log" 2>&1
    $PY -m mpdem restart "$w/switch" --device gpu --set run.max_steps=$EXSTEPS --quiet >> "$w/switch.log" 2>&1
    ds=$(digest "$w/switch")
    ref=$(digest "$w/example-mu0.5-cpu")
    v=DIFFER; [ -n "$ds" ] && [ "$ds" = "$ref" ] && v=equal
    say "digest restart cpu -> gpu at step $half: ${ds:0:16} against the straight cpu ${ref:0:16}: $v"
    # run to run on the GPU
    read -r d2 s2 < <(run example-mu0.5-gpu2 gpu $EXSTEPS "${EX[@]}" --set contact.mu=0.5)
    d1=$(digest "$w/example-mu0.5-gpu")
    v=DIFFER; [ "$d1" = "$d2" ] && v=equal
    say "digest gpu run to run: ${d1:0:16} ${d2:0:16}: $v"
    # two ranks, each with the GPU engine (here both on the one GPU), against one CPU rank
    if command -v mpiexec > /dev/null; then
        mpiexec -n 2 $PY -m mpdem run --out "$w/two" --force --quiet --device gpu --set run.max_steps=$EXSTEPS \
            "${EX[@]}" --set contact.mu=0.5 > "$w/two.log" 2>&1
        dt=$(digest "$w/two")
        v=DIFFER; [ -n "$dt" ] && [ "$dt" = "$ref" ] && v=equal
        say "digest 2 ranks on the gpu: ${dt:0:16} against 1 cpu rank ${ref:0:16}: $v"
        # the same with the history kept on the GPU at every rebuild (engine.gpu_exchange = "device"), both timed
        mpiexec -n 2 $PY -m mpdem run --out "$w/two-migrate" --force --quiet --device gpu --set run.max_steps=$EXSTEPS \
            "${EX[@]}" --set contact.mu=0.5 --set engine.gpu_exchange=device > "$w/two-migrate.log" 2>&1
        dm=$(digest "$w/two-migrate")
        v=DIFFER; [ -n "$dm" ] && [ "$dm" = "$ref" ] && v=equal
        wall() { grep -h '^end:' "$1/log.txt" 2>/dev/null | grep -o 'wall [0-9.]* s' | cut -d' ' -f2; }
        say "digest 2 ranks on the gpu, engine.gpu_exchange = device: ${dm:0:16} against 1 cpu rank ${ref:0:16}: $v" \
            "(stepping: host $(wall "$w/two") s, device $(wall "$w/two-migrate") s)"
    else
        say "digest 2 ranks on the gpu: no mpiexec here"
    fi
    say "switch checks done at $((SECONDS - t0)) s"
fi
# 5. the engine tests with the kernels compiled for the GPU (the pour and no-GPU tests need MPI and none)
if has pytest; then
    MPDEM_REAL_GPU=1 $PY -m pytest -q -p no:cacheprovider tests/test_gpu_engine.py -k "not pour and not no_gpu" \
        > "$OUT/pytest.log" 2>&1
    say "pytest tests/test_gpu_engine.py on the GPU: $(tail -1 "$OUT/pytest.log") ($((SECONDS - t0)) s)"
fi
# 6. PARTS=profile: Nsight Compute on the fused steps and the GPU list build of a short bench (launch, occupancy,
# throughput, stalls); the first four launches are the bench's warm-up on a tiny pile
if has profile; then
    NCU=$(command -v ncu || ls /opt/nvidia/nsight-compute/*/ncu /usr/local/cuda/bin/ncu 2>/dev/null | head -1)
    if [ -n "$NCU" ] && [ -n "$TABLE" ] && [ -f "$TABLE" ]; then
        t=$SECONDS
        "$NCU" --clock-control none --target-processes all -k 'regex:advance|count_partners|write_partners|carry_history' \
            --launch-count ${NCU_LAUNCHES:-12} --section LaunchStats --section Occupancy --section SpeedOfLight \
            --section WarpStateStats --section MemoryWorkloadAnalysis \
            $PY -m mpdem bench --table "$TABLE" --device gpu --steps ${NCU_STEPS:-300} > "$OUT/ncu.txt" 2>&1
        say "profile: $OUT/ncu.txt (rc $?, $((SECONDS - t)) s)"
    else
        say "profile: no ncu or no table"
    fi
fi
# 7. PARTS=anatomy: what a fused step costs with the rows and without (tools/gpu_anatomy.py)
if has anatomy && [ -n "$TABLE" ] && [ -f "$TABLE" ]; then
    for t in row entry; do
        for b in 128 256; do
            timeout "${ANATOMY_SECONDS:-90}" $PY tools/gpu_anatomy.py "$TABLE" 1000 $b $t 2>&1 | grep "^gpu_anatomy" |
                tee -a "$SUM"
        done
    done
fi
# 8. PARTS=rows: the rows of sweep tables (ROWS, under ROWS_CONFIG; ROWS_SET="key=value ..." beside them) on the GPU,
# one after the other, until ROWS_SECONDS (default 400) are spent, or until ROWS_UNTIL seconds after this script's
# start where that is set (leave the device call's own limit a minute beyond it: a row still starting when the time
# is up may take up to ROWS_KILL_AFTER, default 30 s, to stop, and a call killed before the packing below brings
# back only the rows finished by then); ROWS_FROM=DIR: row directories (their config.toml and newest checkpoint, or
# analysis/summary.json for a row to skip) copied in first, so that the rows go on from there; then the sweep stops them with a checkpoint. Each
# row this call ran comes back as $OUT/<row>.tgz, packed as soon as it is finished and analysed, the others when the
# sweep has stopped (at most 8 files come back from the device: keep the rows few): its
# run and analysis files with final.h5, or, where it did not finish, its newest checkpoint to go on from with
# `mpdem sweep` or `mpdem restart` on any machine (the digest does not depend on the device).
if has rows && [ -n "${ROWS:-}" ]; then
    t=$SECONDS
    mkdir -p "$w/rows"
    [ -n "${ROWS_FROM:-}" ] && cp -r "$ROWS_FROM"/. "$w/rows/"
    rsec=${ROWS_SECONDS:-400}
    [ -n "${ROWS_UNTIL:-}" ] && rsec=$((ROWS_UNTIL - (SECONDS - t0)))
    [ "$rsec" -lt 30 ] && rsec=30
    say "rows: $rsec s"
    rs=(); for kv in ${ROWS_SET:-}; do rs+=(--set "$kv"); done
    touch "$w/rows.start"; rm -f "$w/rows.end"
    mkdir -p "$w/pack"
    pack_row() {  # a row's directory as $OUT/<row>.tgz: the newest checkpoint alone, none once it has its final.h5
        local d=${1%/} n ck c
        n=$(basename "$d")
        ck=$(ls "$d"/checkpoints/ckpt-*.h5 2>/dev/null | sort | tail -1)
        for c in "$d"/checkpoints/ckpt-*.h5; do
            [ -f "$c" ] && { [ -f "$d/final.h5" ] || [ "$c" != "$ck" ]; } && rm -f "$c"
        done
        tar -czf "$w/pack/$n.tgz" --exclude=.lock -C "$w/rows" "$n" && mv "$w/pack/$n.tgz" "$OUT/$n.tgz"
    }
    # a row finished and analysed is packed at once, so that a call cut off later still brings it back
    ( while [ ! -f "$w/rows.end" ]; do
        sleep 5
        for d in "$w"/rows/*/; do
            [ ! -f "$OUT/$(basename "$d").tgz" ] && grep -qE "^sweep: $(basename "$d"): (done|not converged)" "$OUT/rows.log" 2>/dev/null &&
                pack_row "$d"
        done
      done ) &
    watcher=$!
    # shellcheck disable=SC2086  # ROWS: several tables
    timeout -s TERM --kill-after="${ROWS_KILL_AFTER:-30}" "$rsec" $PY -m mpdem sweep $ROWS ${ROWS_CONFIG:+--config "$ROWS_CONFIG"} \
        --out "$w/rows" --set engine.device=gpu "${rs[@]}" --jobs 1 --no-collect --progress 60 > "$OUT/rows.log" 2>&1
    say "rows ($ROWS): sweep exit status $? after $((SECONDS - t)) s"
    # the watcher ends after its round in hand (a row it is packing is packed whole, never twice)
    touch "$w/rows.end"; wait "$watcher" 2>/dev/null
    grep "^sweep: " "$OUT/rows.log" | tail -n 12 | tee -a "$SUM"
    for d in "$w"/rows/*/; do
        n=$(basename "$d")
        # the rows this call ran (not those it was given and did not reach, nor the skip marks of finished ones)
        [ -n "$(find "$d" -type f -newer "$w/rows.start" | head -1)" ] || continue
        [ -f "$OUT/$n.tgz" ] || pack_row "$d"
        say "    $n: $(tail -1 "$d/thermo.csv" 2>/dev/null | cut -d, -f1,3) $(ls "$d" | tr '\n' ' ')"
    done
fi
say "gpu_check done in $((SECONDS - t0)) s"
echo "---- summary ($SUM)"
cat "$SUM"
