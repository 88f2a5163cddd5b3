"""Compile every kernel of the GPU engine with numba-cuda for an H100 (sm_90), without a GPU.

The simulator tests run the kernels as Python; this compiles them as a GPU would (numba-cuda's
typing, lowering and NVVM), so a kernel that would not compile fails here, and checks each twice
for a fused multiply-add of float64, which would round once where the CPU engine rounds twice
(docs/computing.md, "One law, two targets"):

1. its PTX has no ``fma.rn.f64`` (NVVM's contractions);
2. its SASS, assembled by ptxas as the driver would, has no DFMA that its explicit twin lacks: ptxas
   may still contract a ``mul.f64`` followed by an ``add.f64`` that carry no rounding modifier. The
   twin is the same PTX with every such plain float64 mul, add and sub given ``.rn`` (which ptxas
   never contracts), so its DFMAs are those of correctly rounded division and square root, which
   ptxas expands into DFMA sequences; one more DFMA in the kernel's own SASS is a contraction.

Controls: a kernel written with plain operators must show ``fma.rn.f64`` in its PTX, and a PTX
``mul.f64`` then ``add.f64`` must come out of ptxas as a DFMA that its twin does not have, or the
checks prove nothing. Each kernel's registers, spills and shared memory (``ptxas -v``) are printed,
with the blocks of 128 threads an H100 multiprocessor can hold at once by those resources.

Run with a Python that has numba-cuda and the CUDA compiler wheels (``make test-gpu-compile``
makes one, ``.venv-cuda``):  python tools/gpu_compile.py
"""
import math
import multiprocessing
import os
import re
import subprocess
import sys
import tempfile
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

from mpdem.kernels.gpu import lists, samples, step  # noqa: E402
from mpdem.kernels.law import MODEL_HERTZ, MODEL_HOOKE, Law  # noqa: E402


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
    red, rec, cells = np.zeros(step.RED_SLOTS), np.zeros((4, 6)), np.zeros(n, np.int32)
    acc = np.zeros((4, 72), np.int64)
    box = (10.0, 10.0, 5.0, 5.0)
    planes, kinds = np.zeros((2, 4)), np.zeros(2, np.int64)
    grid = (x, ids, fixed, cells, cells, cells, 3, 3, 3, *box, 1.44)
    rec8 = np.zeros((4, step.RED_SLOTS))
    advance_lists = (n, x, x, x, x, x, fixed, x, start, nbr, hist, stamp, pair, x, planes, kinds, 5, *box, law, True,
                     0.1, 4, rec8, 4, nbr, True, x, x, x, True, ids, np.zeros(3), cells, cells, cells, cells, start,
                     nbr, hist, stamp, 3, 3, 8, 1.0, 1.0, 1.2, 1.44, 19, True, 20, 0, cells, x, x, x, x, x, x, fixed,
                     ids, cells, cells, ids, ids, ids)
    dims = np.zeros(2, np.int64)
    grid_in = (x, ids, fixed, cells, cells, cells, 3, 3, dims, *box, 1.44)
    advance = (n, x, x, x, x, x, fixed, x, start, nbr, hist, stamp, pair, x, planes, kinds, 5, *box, law, True, 0.1, 4,
               rec, True, 4, nbr, True, x, x, x, True)
    return {
        "step.kick_drift": (step.kick_drift, (n, x, x, x, x, x, fixed, x, 1e-4, *box, True, red)),
        "step.kick": (step.kick, (n, x, x, x, x, fixed, 1e-4)),
        "step.forces": (step.forces, (n, x, x, x, x, x, fixed, start, nbr, hist, stamp, pair, True, x, planes, kinds,
                                      5, *box, law, True, red)),
        "step.advance": (step.advance, advance),
        "step.advance_one": (step.advance_one, advance),
        # list rebuilds inside the launch (engine.gpu_rebuild = "launch"), a thread a row
        "step.advance_lists": (step.advance_lists, advance_lists),
        "step.advance_lists_sorted": (step.advance_lists_sorted, advance_lists),
        "step.advance_lists pinned (fused, drift fused, Hooke, mu > 0)": (
            step.pinned_advance(False, True, True, MODEL_HOOKE, True, False, False, 1), advance_lists),
        "step.advance_lists_sorted pinned (fused, drift fused, Hooke, mu > 0)": (
            step.pinned_advance(False, True, True, MODEL_HOOKE, True, False, False, 2), advance_lists),
        # the same a thread an entry (engine.gpu_threads = "entry")
        "step.advance_lists_entry": (step.advance_lists_entry, advance_lists),
        "step.advance_lists_entry_sorted": (step.advance_lists_entry_sorted, advance_lists),
        "step.advance_lists_entry pinned (fused, drift fused, Hooke, mu > 0)": (
            step.pinned_advance(True, True, True, MODEL_HOOKE, True, False, False, 1), advance_lists),
        "step.advance_lists_entry_sorted pinned (fused, drift fused, Hooke, mu > 0)": (
            step.pinned_advance(True, True, True, MODEL_HOOKE, True, False, False, 2), advance_lists),
        # lanes of a warp a row (engine.gpu_threads = "lanes4"; other L differ by a constant) with the reductions by
        # warp shuffles (engine.gpu_reductions = "warp"), and frictionless with the fused trees and no rebuild
        "step.advance_lists pinned (lanes4, warp, drift fused, Hooke, mu > 0)": (
            step.pinned_advance(False, step.WARP, True, MODEL_HOOKE, True, False, False, 1, 4), advance_lists),
        "step.advance pinned (lanes4, fused, drift fused, Hooke, mu = 0)": (
            step.pinned_advance(False, True, True, MODEL_HOOKE, False, False, False, 0, 4), advance),
        # compiled for one run's options (engine.gpu_pinned): a row a thread, Hooke, frictionless and frictional,
        # then a thread an entry, the fused reductions and the fused drift (engine.gpu_drift)
        "step.advance pinned (row, Hooke, mu = 0)": (step.pinned_advance(False, False, False, MODEL_HOOKE, False,
                                                                         False, False), advance),
        "step.advance pinned (row, Hooke, mu > 0)": (step.pinned_advance(False, False, False, MODEL_HOOKE, True,
                                                                         False, False), advance),
        "step.advance pinned (entry, fused, drift fused, Hooke, mu > 0)": (
            step.pinned_advance(True, True, True, MODEL_HOOKE, True, False, False), advance),
        "step.entry_forces": (step.entry_forces, (4, nbr, x, x, x, fixed, nbr, hist, stamp, pair, True, 5, *box, law,
                                                  True, red)),
        "step.row_sums": (step.row_sums, (n, x, x, x, x, x, fixed, start, stamp, pair, x, planes, kinds, 5, law, True,
                                          red)),
        "samples.kinetic_sums": (samples.kinetic_sums, (n, x, x, fixed, acc)),
        "samples.balance_sums": (samples.balance_sums, (n, x, fixed, start, stamp, pair, np.uint32(5), acc)),
        "samples.zero": (samples.zero, (acc,)),
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
        # the rebuild in place (engine.gpu_rebuild = "device")
        "lists.grid_depth": (lists.grid_depth, (np.zeros(3), 3, 3, 8, 1.2, dims)),
        "lists.zero_cells": (lists.zero_cells, (cells, dims)),
        "lists.bin_rows_in": (lists.bin_rows_in, (n, x, 3, 3, 1.0, 1.0, np.zeros(3), dims, 1.2, cells, cells)),
        "lists.scan_in": (lists.scan_in, (cells, cells, dims)),
        "lists.count_partners_in": (lists.count_partners_in, (n, *grid_in, start)),
        "lists.write_partners_in": (lists.write_partners_in, (n, *grid_in, start, nbr, red)),
        "lists.carry_history_in": (lists.carry_history_in, (n, ids, start, nbr, hist, stamp, start, nbr, hist, stamp,
                                                            np.uint32(3))),
        "lists.entry_rows_in": (lists.entry_rows_in, (n, start, nbr)),
        # the rows ordered by cell on the GPU (engine.gpu_sort = "device")
        "lists.sort_cells_of": (lists.sort_cells_of, (n, x, 3, 3, 1.0, 1.0, np.zeros(3), dims, 1.2, ids, ids, ids,
                                                      cells, cells)),
        "lists.sort_within_cells": (lists.sort_within_cells, (dims, cells, cells, ids)),
        "lists.permute_rows (ids)": (lists.permute_rows, (n, cells, ids, ids)),
        "lists.permute_rows (fixed)": (lists.permute_rows, (n, cells, fixed, fixed)),
        "lists.permute_rows3": (lists.permute_rows3, (n, cells, x, x)),
        "lists.carry_history_moved": (lists.carry_history_moved, (n, cells, ids, ids, start, nbr, hist, stamp, start,
                                                                  nbr, hist, stamp, np.uint32(3))),
        "lists.copy_rows": (lists.copy_rows, (n, x, x)),
        "lists.entry_rows": (lists.entry_rows, (n, start, nbr)),
        "lists.gather_rows": (lists.gather_rows, (ids, x, x, x, np.zeros((3, n, 3)))),
        # a migration on several ranks with the history kept on the GPU (engine.gpu_exchange = "device")
        "lists.pack_ghosts": (lists.pack_ghosts, (ids, ids, ids, x, x, x, np.zeros(9 * n))),
        "lists.unpack_ghosts": (lists.unpack_ghosts, (ids, ids, ids, np.zeros(9 * n), x, x, x)),
        "lists.count_contacts_of": (lists.count_contacts_of, (ids, start, stamp, np.uint32(3), ids)),
        "lists.pack_contacts_of": (lists.pack_contacts_of, (ids, ids, ids, start, nbr, hist, stamp, np.uint32(3), ids,
                                                            hist)),
        "lists.permute_kept3": (lists.permute_kept3, (n, cells, x, x)),
        "lists.scatter_rows3": (lists.scatter_rows3, (ids, x, x)),
        "lists.carry_history_migrated": (lists.carry_history_migrated, (n, cells, ids, ids, start, nbr, hist, stamp,
                                                                        start, ids, hist, start, nbr, hist, stamp,
                                                                        np.uint32(3), np.uint32(4))),
    }


# a float64 multiply then add with no rounding modifier: ptxas fuses them into one DFMA
CONTROL_PTX = """.version 8.0
.target sm_90
.address_size 64
.visible .entry control(.param .u64 p)
{
    .reg .b64 %rd<3>;
    .reg .f64 %fd<5>;
    ld.param.u64 %rd1, [p];
    cvta.to.global.u64 %rd2, %rd1;
    ld.global.f64 %fd1, [%rd2];
    ld.global.f64 %fd2, [%rd2+8];
    ld.global.f64 %fd3, [%rd2+16];
    mul.f64 %fd4, %fd1, %fd2;
    add.f64 %fd4, %fd4, %fd3;
    st.global.f64 [%rd2+24], %fd4;
    ret;
}
"""
# a plain float64 mul, add or sub at the start of an instruction (a guard predicate allowed)
PLAIN = re.compile(r"(?m)^(\s*(?:@!?%p\d+\s+)?)(mul|add|sub)\.f64\b")
# an H100 multiprocessor: registers, warps, blocks and shared memory it holds at once; registers are
# given to a warp in units of 256
SM_REGISTERS, SM_WARPS, SM_BLOCKS, SM_SHARED, BLOCK_RESERVED = 65536, 64, 32, 233472, 1024


def ptx_of(kernel, args):
    """The kernel's PTX for CC."""
    ptx, _ = cuda.compile_ptx(kernel.py_func, tuple(numba.typeof(a) for a in args), cc=CC)
    return ptx


def explicit_twin(ptx):
    """The PTX with every plain float64 mul, add and sub rounded explicitly (``.rn``: never contracted)."""
    return PLAIN.sub(r"\1\2.rn.f64", ptx)


def toolkit():
    """(ptxas, nvdisasm): the paths of NVIDIA's assembler and disassembler in the CUDA wheels
    (``tools/setup_cuda.sh``), or None where one is missing."""
    found = {}
    for root in sys.path:
        for name, sub in (("ptxas", "cuda_nvcc"), ("nvdisasm", "cu13"), ("nvdisasm", "cuda_nvdisasm")):
            p = os.path.join(root, "nvidia", sub, "bin", name)
            if name not in found and os.access(p, os.X_OK):
                found[name] = p
    return found.get("ptxas"), found.get("nvdisasm")


# the register caps swept for the fused step (engine.gpu_max_registers): its registers and spills under each
CAPS = (64, 80, 96)


def sass(ptx, tools, max_registers=0):
    """Assemble ``ptx`` for CC as a whole program (as the driver does), or relocatable where it calls
    the device runtime (the cooperative kernel's grid barrier, linked at load), and disassemble it:
    (DFMA count, ``resources``)."""
    ptxas, nvdisasm = tools
    with tempfile.TemporaryDirectory() as d:
        src, cubin = os.path.join(d, "k.ptx"), os.path.join(d, "k.cubin")
        with open(src, "w") as fh:
            fh.write(ptx)
        for mode in ([], ["-c"]):
            cap = [f"--maxrregcount={max_registers}"] if max_registers else []
            p = subprocess.run([ptxas, f"-arch=sm_{CC[0]}{CC[1]}", *mode, *cap, "-v", "-o", cubin, src],
                               capture_output=True, text=True)
            if p.returncode == 0 or "Unresolved extern" not in p.stderr:
                break
        if p.returncode:
            raise RuntimeError(f"ptxas: {p.stderr.strip()[-500:]}")
        asm = subprocess.run([nvdisasm, cubin], capture_output=True, text=True, check=True).stdout
    return len(re.findall(r"\bDFMA\b", asm)), resources(p.stderr, relocatable=bool(mode))


def resources(log, relocatable=False):
    """The entry's resources from ``ptxas -v``'s report (the last function it reports): registers, bytes
    of spill stores and loads, of stack frame, and of static shared memory (None where the code is
    relocatable: ptxas does not report it then)."""
    def last(pattern):
        got = re.findall(pattern, log)
        return int(got[-1]) if got else 0
    return {"registers": last(r"Used (\d+) registers"), "spill_stores": last(r"(\d+) bytes spill stores"),
            "spill_loads": last(r"(\d+) bytes spill loads"), "stack": last(r"(\d+) bytes stack frame"),
            "shared": None if relocatable else last(r"(\d+) bytes smem")}


def resident_blocks(res, block=128):
    """Blocks of ``block`` threads one H100 multiprocessor holds at once by the kernel's registers and
    shared memory (an upper bound: the occupancy calculator's rules, not a measurement)."""
    warps = block // 32
    per_warp = math.ceil(max(res["registers"], 1) * 32 / 256) * 256
    by_regs = SM_REGISTERS // (per_warp * warps)
    by_shared = SM_SHARED // ((res["shared"] or 0) + BLOCK_RESERVED)
    return min(SM_BLOCKS, SM_WARPS // warps, by_regs, by_shared)


def check(name, kernel, args, tools):
    """One kernel's line of the report; returns (ok, line, resources, PTX)."""
    ptx = ptx_of(kernel, args)
    fused = ptx.count("fma.rn.f64")
    dfma, res = sass(ptx, tools)
    # no DFMA at all: nothing a twin could explain (and one ptxas run saved)
    allowed = sass(explicit_twin(ptx), tools)[0] if dfma else 0
    extra = dfma - allowed
    faults = ([f"{fused} fma.rn.f64 in the PTX"] if fused else []) + \
        ([f"{extra} DFMA in the SASS beyond the explicit twin's {allowed} (ptxas contracted a mul and an add)"]
         if extra > 0 else [])
    spills = res["spill_stores"] + res["spill_loads"]
    shared = "shared memory not reported (relocatable)" if res["shared"] is None else f"{res['shared']} B shared"
    line = (f"{'; '.join(faults) if faults else 'ok'} ({ptx.count(chr(10))} lines of PTX; SASS: {res['registers']} "
            f"registers, {spills} B spilled, {shared}, at most {resident_blocks(res)} blocks of 128 a "
            f"multiprocessor; {dfma} DFMA, those of division and square root)")
    return not faults, line, res, ptx


def controls(tools):
    """Both controls' counts: (fma.rn.f64 in the plain kernel's PTX, DFMA of the plain PTX, of its twin)."""
    a = np.zeros(4)
    ptx_fmas = ptx_of(_control, (a, a, a, a)).count("fma.rn.f64")
    return ptx_fmas, sass(CONTROL_PTX, tools)[0], sass(explicit_twin(CONTROL_PTX), tools)[0]


def main():
    tools = toolkit()
    if None in tools:
        print(f"gpu_compile: ptxas or nvdisasm not found (ptxas {tools[0]}, nvdisasm {tools[1]}): run "
              f"tools/setup_cuda.sh (make test-gpu-compile does)")
        return 1
    ptx_fmas, plain, twin = controls(tools)
    if not ptx_fmas:
        print("gpu_compile: the control kernel shows no fma.rn.f64: the check cannot see a fused operation")
        return 1
    if not (plain > twin == 0):
        print(f"gpu_compile: the SASS control (mul.f64 then add.f64) shows {plain} DFMA, its explicit twin {twin}: "
              f"the SASS check cannot see a contraction")
        return 1
    table = cases()
    # the kernels in parallel processes (forked after the imports; compiling needs no GPU), the largest
    # first so that the processes end together; the report in the table's order
    names = sorted(table, key=lambda n: not n.startswith("step.advance"))
    jobs = min(len(names), os.cpu_count() or 1)
    with multiprocessing.get_context("fork").Pool(jobs) as pool:
        done = dict(zip(names, pool.map(_report, [(n, tools) for n in names], chunksize=1)))
    bad = 0
    for name in table:
        ok, lines = done[name]
        print("\n".join(lines))
        bad += not ok
    print(f"gpu_compile: numba-cuda {cuda_version()}, sm_{CC[0]}{CC[1]}: {len(table) - bad} of {len(table)} "
          f"kernels compile with every float64 operation rounded on its own, in the PTX and in ptxas's SASS "
          f"(the controls fuse {ptx_fmas} in the PTX and {plain} in the SASS, their twins {twin})")
    return 1 if bad else 0


def _report(job):
    """(ok, the report's lines) of one kernel of ``cases()`` (``job``: its name and ``toolkit()``); for the
    fused step also its registers and spills under each of CAPS."""
    name, tools = job
    kernel, args = cases()[name]
    t = time.perf_counter()
    try:
        ok, line, _, ptx = check(name, kernel, args, tools)
    except Exception as e:   # the compiler's own message names the line and the types
        return False, [f"gpu_compile: {name}: does not compile: {type(e).__name__}: {e}"]
    lines = [f"gpu_compile: {name}: {line}, {time.perf_counter() - t:.1f} s"]
    if name == "step.advance":
        for cap in CAPS:
            res = sass(ptx, tools, cap)[1]
            lines.append(f"gpu_compile: step.advance under engine.gpu_max_registers = {cap}: {res['registers']} "
                         f"registers, {res['spill_stores']} B spill stores, {res['spill_loads']} B spill loads, "
                         f"{res['stack']} B stack, at most {resident_blocks(res)} blocks of 128 a multiprocessor")
    return ok, lines


def cuda_version():
    from importlib.metadata import version
    return version("numba-cuda")


if __name__ == "__main__":
    sys.exit(main())
