#!/usr/bin/env bash
# Every GPU engine variant measured in one call (tools/gpu_probe.py; docs/performance.md, "GPU variants"):
# the CPU's digest, then each variant at two block shapes, one after another in one process (its compile, its
# digest against the CPU's, the 20k pile timed, its list rebuilds, its kernels' registers and spills, the 994k
# tiles timed at the first shape; a process that dies leaves that variant failed and a new one goes on), then
# tools/gpu_anatomy.py as the baseline; OUT/probe.json and OUT/probe.txt, the table printed last.
# BUDGET seconds for the variants, some 1-2 more minutes around them; for a bare machine with a GPU and no
# network (python3 with numpy, numba, numba-cuda, scipy, h5py). Exit 0 when every digest is the CPU's.
#   bash tools/gpu_probe.sh TABLE [OUT]      TABLE: the bench's landed20k.txt.gz; OUT default ./gpu_probe_out
#   VARIANTS=row,row-all,entry-all,...  SHAPES=128,256  STEPS=1000  REPEATS=3  TILES=7x7  BIG_STEPS=100
#   CHECK_STEPS=200  BUDGET=420 (seconds: a variant that would start past them is skipped, and says so)
#   (the defaults)
#   SIZE=small  a dry run on a small table (under NUMBA_ENABLE_CUDASIM=1 without a GPU: `make test` runs it)
# On a lent machine (docs/gpu.md): `bash tools/device_slim.sh on` before the call, `off` after; the call:
#   bash tools/gpu_probe.sh .devdata/landed20k.txt.gz "$OUT/probe"
set -uo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-python3}
TABLE=${1:?usage: bash tools/gpu_probe.sh TABLE [OUT]}
OUT=${2:-${OUT:-$PWD/gpu_probe_out}}
export PYTHONPATH=$PWD/src${PYTHONPATH:+:$PYTHONPATH} PYTHONUNBUFFERED=1
if [ "${SIZE:-full}" = small ]; then
    STEPS=${STEPS:-4} REPEATS=${REPEATS:-2} TILES=${TILES:-1x1} BIG_STEPS=${BIG_STEPS:-2} CHECK_STEPS=${CHECK_STEPS:-6}
    SHAPES=${SHAPES:-128}   # the simulator runs any shape as a few threads: one is enough there
fi
args=(--steps "${STEPS:-1000}" --repeats "${REPEATS:-3}" --tiles "${TILES:-7x7}" --big-steps "${BIG_STEPS:-100}"
      --check-steps "${CHECK_STEPS:-200}")
[ -n "${VARIANTS:-}" ] && args+=(--variants "$VARIANTS")
[ -n "${SHAPES:-}" ] && args+=(--shapes "$SHAPES")
[ -n "${BUDGET:-}" ] && args+=(--budget "$BUDGET")
mkdir -p "$OUT"
{ echo "gpu_probe $(date -u +%FT%TZ) at $(git rev-parse --short HEAD 2>/dev/null || echo '?')"
  nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>/dev/null || echo "gpu: none"
} | tee "$OUT/machine.txt"
"$PY" tools/gpu_probe.py all "$TABLE" "$OUT" "${args[@]}"
