"""Compile every kernel of the GPU engine with numba-cuda for an H100 (sm_90), without a GPU.

The simulator tests run the kernels as Python; this compiles them as a GPU would (numba-cuda's
typing, lowering and NVVM), so a kernel that would not compile fails here, and checks the PTX of
each: no fused multiply-add of float64 (``fma.rn.f64``), which would round once where the CPU
engine rounds twice (docs/computing.md, "One law, two targets"). A control kernel written with
plain operators must show FMAs, or the check proves nothing.

Run with a Python that has numba-cuda and the CUDA compiler wheels (``make test-gpu-compile``
makes one, ``.venv-cuda``):  python tools/gpu_compile.py
"""
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "src"))
os.environ.pop("NUMBA_ENABLE_CUDASIM", None)

import numba  # noqa: E402
from numba import cuda  # noqa: E402
import numba.cuda.dispatcher as dispatcher  # noqa: E402

CC = (9, 0)


class _Device:
    """What numba-cuda asks of the current device when it compiles a device function."""
    compute_capability = CC


# no GPU here: device functions are compiled for CC, as the kernels are
dispatcher.get_current_device = lambda: _Device()

from mpdem.kernels.gpu import lists, step  # noqa: E402
from mpdem.kernels.law import MODEL_HERTZ, Law  # noqa: E402


@cuda.jit
def _control(a, b, c, out):
    """Plain operators: the compilers fuse the multiply and the add."""
    i = cuda.grid(1)
    if i < out.size:
        out[i] = a[i] * b[i] + c[i]


def cases():
    """Each kernel with arguments of the types the GPU engine passes (values do not matter)."""
    n = 8
    law = Law(2e5, 4e5 / 7, 40.0, 10.0, 0.5, 0.0, 0.0, -1.0, 1e-4, MODEL_HERTZ, False, True)
    x, fixed, ids = np.zeros((n, 3)), np.zeros(n, np.uint8), np.zeros(n, np.int64)
    start, nbr = np.zeros(n + 1, np.int64), np.zeros(4, np.int32)
    hist, stamp, pair = np.zeros((4, 3)), np.zeros(4, np.uint32), np.zeros((4, 6))
    red, rec, cells = np.zeros(6), np.zeros((4, 6)), np.zeros(n, np.int32)
    box = (10.0, 10.0, 5.0, 5.0)
    planes, kinds = np.zeros((2, 4)), np.zeros(2, np.int64)
    grid = (x, ids, fixed, cells, cells, cells, 3, 3, 3, *box, 1.44)
    return {
        "step.kick_drift": (step.kick_drift, (n, x, x, x, x, x, fixed, x, 1e-4, *box, True, red)),
        "step.kick": (step.kick, (n, x, x, x, x, fixed, 1e-4)),
        "step.forces": (step.forces, (n, x, x, x, x, x, fixed, start, nbr, hist, stamp, pair, True, x, planes, kinds,
                                      5, *box, law, True, red)),
        "step.advance": (step.advance, (n, x, x, x, x, x, fixed, x, start, nbr, hist, stamp, pair, x, planes, kinds,
                                        5, *box, law, True, 0.1, 4, rec, True, 4, nbr)),
        "step.entry_forces": (step.entry_forces, (4, nbr, x, x, x, fixed, nbr, hist, stamp, pair, True, 5, *box, law,
                                                  True, red)),
        "step.row_sums": (step.row_sums, (n, x, x, x, x, x, fixed, start, stamp, pair, x, planes, kinds, 5, law, True,
                                          red)),
        "lists.z_range": (lists.z_range, (n, x, np.zeros(2))),
        "lists.zero": (lists.zero, (n, cells)),
        "lists.bin_rows": (lists.bin_rows, (n, x, 3, 3, 3, 1.0, 1.0, 0.0, 1.2, cells, cells)),
        "lists.scan (cells)": (lists.scan, (cells, n - 1)),
        "lists.scan (lists)": (lists.scan, (start, n)),
        "lists.fill_cells": (lists.fill_cells, (n, cells, cells, cells)),
        "lists.count_partners": (lists.count_partners, (n, *grid, start)),
        "lists.write_partners": (lists.write_partners, (n, *grid, start, nbr)),
        "lists.carry_history": (lists.carry_history, (n, ids, start, nbr, hist, stamp, start, nbr, hist, stamp,
                                                      np.uint32(3))),
        "lists.copy_rows": (lists.copy_rows, (n, x, x)),
        "lists.entry_rows": (lists.entry_rows, (n, start, nbr)),
        "lists.gather_rows": (lists.gather_rows, (ids, x, x, x, np.zeros((3, n, 3)))),
    }


def fmas(kernel, args):
    """The PTX's fused float64 multiply-adds, and its length in lines."""
    ptx, _ = cuda.compile_ptx(kernel.py_func, tuple(numba.typeof(a) for a in args), cc=CC)
    return ptx.count("fma.rn.f64"), ptx.count("\n")


def main():
    a = np.zeros(4)
    control, _ = fmas(_control, (a, a, a, a))
    if not control:
        print("gpu_compile: the control kernel shows no fma.rn.f64: the check cannot see a fused operation")
        return 1
    bad = 0
    for name, (kernel, args) in cases().items():
        t = time.perf_counter()
        try:
            fused, lines = fmas(kernel, args)
        except Exception as e:   # the compiler's own message names the line and the types
            print(f"gpu_compile: {name}: does not compile: {type(e).__name__}: {e}")
            bad += 1
            continue
        verdict = "ok" if not fused else f"{fused} fused multiply-adds"
        print(f"gpu_compile: {name}: {verdict} ({lines} lines of PTX, {time.perf_counter() - t:.1f} s)")
        bad += bool(fused)
    print(f"gpu_compile: numba-cuda {cuda_version()}, sm_{CC[0]}{CC[1]}: {len(cases()) - bad} of {len(cases())} "
          f"kernels compile with every float64 operation rounded on its own (the control fuses {control})")
    return 1 if bad else 0


def cuda_version():
    from importlib.metadata import version
    return version("numba-cuda")


if __name__ == "__main__":
    sys.exit(main())
