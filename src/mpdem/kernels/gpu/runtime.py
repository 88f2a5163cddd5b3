"""numba's CUDA target, imported once: the real one on a GPU, numba's simulator under
``NUMBA_ENABLE_CUDASIM=1`` (the tests without a GPU).

numba-cuda 0.30 reads ``numpy.row_stack``, which numpy 2.5 removed: the alias is put back before
the import (``np.vstack`` is what it was).
"""
import os

import numpy as np

if not hasattr(np, "row_stack"):
    np.row_stack = np.vstack

from numba import config  # noqa: E402
from numba import cuda  # noqa: E402

SIMULATOR = bool(config.ENABLE_CUDASIM)


if SIMULATOR:
    import threading
    import weakref

    # the exchanges of each simulated launch's warps (its threads share a manager), by (block, warp, mask)
    _EXCHANGES = weakref.WeakKeyDictionary()
    _EXCHANGES_LOCK = threading.Lock()
    # seconds a simulated lane waits for the others of its shuffle
    SHFL_TIMEOUT = 300.0

    class _Exchange:
        """The lanes of ``mask`` in one simulated warp: a barrier of as many threads and two sets of slots,
        used in turn (a lane can write the next exchange's slot only after every lane has passed this one's
        barrier, so after every lane has read the other set)."""

        def __init__(self, parties):
            self.barrier = threading.Barrier(parties)
            self.slots = ([None] * 32, [None] * 32)
            self.turn = [0] * 32

    def shfl(mask, value, src_lane):
        """``cuda.shfl_sync`` under the simulator, which has none: ``value`` of lane ``src_lane`` of this
        thread's warp, every lane of ``mask`` calling it (a barrier of those lanes)."""
        t = threading.current_thread()
        warp, lane = divmod(t.thread_id, 32)
        key = (tuple(t.blockIdx), warp, int(mask) & 0xFFFFFFFF)
        with _EXCHANGES_LOCK:
            block = _EXCHANGES.setdefault(t._manager, {})
            ex = block.get(key)
            if ex is None:
                ex = block[key] = _Exchange(bin(key[2]).count("1"))
        p = ex.turn[lane]
        ex.turn[lane] = 1 - p
        ex.slots[p][lane] = value
        # a lane that died (a failing kernel) breaks the barrier after a while instead of hanging the others
        ex.barrier.wait(timeout=SHFL_TIMEOUT)
        return ex.slots[p][int(src_lane)]
else:
    shfl = cuda.shfl_sync


def launch(kernel, grid, args):
    """``kernel[grid](*args)``.

    Under the simulator the interpreter's switch interval is left as it is: a short one ran the
    simulated kernels 4-6 x faster, but let the simulator's block barriers (``syncthreads``) lose
    a thread now and then (measured on 2026-11-26: 2 of 30 launches of 20 block reductions gave a
    wrong maximum with an interval of 10 us, none of 30 with the default 5 ms).
    """
    kernel[grid](*args)


def device(fn):
    """A device function of the kernels that reads nothing of ``cuda``: ``cuda.jit(device=True)`` on
    a GPU; under the simulator the plain function, which the simulated kernels call as Python (the
    simulator's own device functions swap module globals at every call, a hundred times slower).
    One that reads ``cuda`` is ``device_cuda``."""
    return fn if SIMULATOR else cuda.jit(device=True)(fn)


def device_cuda(fn):
    """A device function that reads ``cuda`` (thread indices, barriers, atomics): on a GPU
    ``cuda.jit(device=True)``; under the simulator a function that runs ``fn``'s code with ``cuda``
    the simulated kernel's (the simulator's own device functions swap it in the module's globals,
    which threads in one module undo for each other)."""
    if not SIMULATOR:
        return cuda.jit(device=True)(fn)
    import functools
    import types
    from numba.cuda.simulator.kernel import _get_kernel_context

    @functools.wraps(fn)
    def call(*args):
        space = dict(fn.__globals__)
        space["cuda"] = _get_kernel_context()
        return types.FunctionType(fn.__code__, space, fn.__name__, fn.__defaults__, fn.__closure__)(*args)
    return call


_CAPPED = {}


def capped(kernel, max_registers):
    """``kernel`` (a ``cuda.jit`` kernel) compiled on its own with at most ``max_registers`` registers a
    thread (ptxas's -maxrregcount: fewer registers, more resident blocks, perhaps spills; the same
    arithmetic, so the same bits); one dispatcher per kernel and cap. Under the simulator, which has
    no registers, a dispatcher of its own all the same."""
    key = (kernel.py_func, max_registers)
    if key not in _CAPPED:
        jit = cuda.jit() if SIMULATOR else cuda.jit(max_registers=max_registers)
        _CAPPED[key] = jit(kernel.py_func)
    return _CAPPED[key]


# the launcher's rank of this process among those on its node
LOCAL_RANK_VARS = ("OMPI_COMM_WORLD_LOCAL_RANK", "MPI_LOCALRANKID", "PMI_LOCAL_RANK", "SLURM_LOCALID",
                   "PALS_LOCAL_RANKID")


def gpu_of_rank(n_gpus, environ=None):
    """The GPU this process uses among the ``n_gpus`` it sees: its rank on the node modulo ``n_gpus``
    (so ranks on a node with one GPU each, or a launcher that shows each rank one GPU through
    ``CUDA_VISIBLE_DEVICES``, both get theirs); 0 when the launcher does not say the local rank."""
    env = os.environ if environ is None else environ
    local = next((env[k] for k in LOCAL_RANK_VARS if env.get(k, "").isdigit()), "0")
    return int(local) % max(1, n_gpus)


def unavailable():
    """Why no GPU can be used, in one line, or None when one can (and this process's GPU chosen,
    ``gpu_of_rank``, before anything makes a CUDA context)."""
    if SIMULATOR:
        return None
    try:
        if not cuda.is_available():
            return ("no CUDA GPU or CUDA driver found (numba.cuda.is_available() is false; "
                    "`nvidia-smi` should list the GPU)")
        cuda.select_device(gpu_of_rank(len(cuda.gpus)))
    except Exception as e:   # the driver or runtime libraries: their own message says which
        return f"the CUDA runtime cannot be used: {e}"
    return None
