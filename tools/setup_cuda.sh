#!/usr/bin/env bash
# Idempotent: .venv-cuda, a virtual environment with numba-cuda and the CUDA compiler wheels (NVVM,
# NVRTC, ptxas) and NVIDIA's disassembler (nvdisasm: the SASS check), for compiling the GPU engine's kernels
# on a machine without a GPU (tools/gpu_compile.py, `make test-gpu-compile`). Pinned to what the GPU machines run (numba-cuda 0.30.4) and to the
# project's numba and numpy; some 700 MB, 20-30 s from PyPI. A stamp records a finished set-up.
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
python=${PYTHON:-python3}
venv=${MPDEM_CUDA_VENV:-$here/.venv-cuda}
NUMPY=2.4.6; NUMBA=0.68.1; NUMBA_CUDA=0.30.4; NVCC=12.9.86; NVRTC=12.9.86
# nvdisasm has no CUDA 12 wheel on PyPI; 13.2 reads sm_90 cubins made by ptxas 12.9
NVDISASM=13.2.86
want="numpy==$NUMPY numba==$NUMBA numba-cuda==$NUMBA_CUDA nvidia-cuda-nvcc-cu12==$NVCC nvidia-cuda-nvrtc-cu12==$NVRTC"
want="$want nvidia-cuda-nvdisasm==$NVDISASM"
stamp=$venv/.mpdem-cuda-stamp
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
    exit 0
fi
echo "setup-cuda: making $venv ($want)"
rm -rf "$venv"
"$python" -m venv "$venv"
# shellcheck disable=SC2086
"$venv/bin/python" -m pip install -q --disable-pip-version-check $want
echo "$want" > "$stamp"
