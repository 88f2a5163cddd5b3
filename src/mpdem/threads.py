"""Threads within a rank: numba's parallel loops (``--threads T``).

Results do not depend on the thread count: threads split the particles,
never a sum (ARCHITECTURE.md), and reductions are max or integer sums.
"""
from __future__ import annotations

import os
import sys

from .errors import ThreadsError


# threads of the time-step kernels: one per rank unless asked (numba's own default is every core)
_requested = 1
# the cores ``bind`` bound this process to (None: not bound by mpdem)
BOUND = None


def configure(n):
    """Use ``n`` numba threads in this process (call before the first step).

    Parameters
    ----------
    n : int
        Threads, >= 1. Above the cores numba sees, numba's pool is enlarged
        when numba is not imported yet; otherwise the count is refused.
    """
    if not isinstance(n, int) or n < 1:
        raise ThreadsError(f"--threads {n!r}: accepted an integer >= 1")
    if oversubscribed(n):
        # before numba loads its OpenMP layer (at its first set_num_threads): waiting threads sleep
        # instead of spinning, so threads that share a core do not starve the one that works
        for key, value in PASSIVE.items():
            os.environ.setdefault(key, value)
    if "numba" not in sys.modules:
        # numba sizes its pool at import, to the cores this process may use: make room for n threads
        have = int(os.environ.get("NUMBA_NUM_THREADS", "0") or 0)
        if n > max(have, usable_cores()):
            os.environ["NUMBA_NUM_THREADS"] = str(n)
    import numba
    top = numba.config.NUMBA_NUM_THREADS
    if n > top:
        raise ThreadsError(f"--threads {n}: accepted 1 to {top} (numba's pool; set NUMBA_NUM_THREADS "
                           f"before starting to allow more)")
    numba.set_num_threads(n)
    global _requested
    _requested = n
    return n


# the wait policy of an oversubscribed process: GNU and LLVM OpenMP, and Intel's (numba's omp layer)
PASSIVE = {"OMP_WAIT_POLICY": "PASSIVE", "KMP_BLOCKTIME": "0"}


def ranks_on_node():
    """Ranks of this launch on this node, as the launcher says (1 when it says nothing)."""
    return int(os.environ.get("OMPI_COMM_WORLD_LOCAL_SIZE") or os.environ.get("MPI_LOCALNRANKS")
               or os.environ.get("PMI_LOCAL_SIZE") or 1)


def oversubscribed(n, cores=None):
    """Whether ``n`` threads per rank outnumber the cores: this process's (``cores``, default its
    affinity), or the node's over its ranks."""
    cores = usable_cores() if cores is None else cores
    return n > 1 and (n > cores or ranks_on_node() * n > (os.cpu_count() or 1))


def requested():
    """The requested count (1 unless ``configure`` asked for more), within numba's pool: the chunks an
    engine splits its rows into. Sets nothing."""
    import numba
    return min(_requested, numba.config.NUMBA_NUM_THREADS)


def apply():
    """Set numba to the requested count (``requested``) in this process; returns it. Called where a run
    or a benchmark starts, not by the engines."""
    import numba
    numba.set_num_threads(requested())
    return numba.get_num_threads()


def bind(comm, n_threads, mode="auto"):
    """Bind this rank to cores of its own, where the launcher left the ranks of a node unbound.

    Under MPICH's mpiexec (PyPI's ``mpich`` wheel included), ranks are not bound by default and the
    kernel may move them between cores and stack two on one. With ``mode`` "auto", when the ranks
    of this launch on this node (``comm``'s shared-memory split: a collective, every rank calls it)
    all may run on the same cores, and those number at least ranks x ``n_threads``, local rank i
    takes the i-th ``n_threads`` of them, one hyperthread of every physical core before any second
    one (``cores_first``). Anything else (a launcher that bound the ranks already, more ranks than
    cores, one rank on the node, "none") binds nothing. Must run before numba starts its threads
    (they inherit the affinity).

    Parameters
    ----------
    comm : mpi4py communicator or None
        The run's ranks (None: one rank, nothing to do).
    n_threads : int
        numba threads of each rank.
    mode : {"auto", "none"}

    Returns
    -------
    tuple of int or None
        The cores this rank was bound to, or None.
    """
    if mode == "none" or comm is None or comm.Get_size() == 1 or not hasattr(os, "sched_setaffinity"):
        return None
    from mpi4py import MPI
    node = comm.Split_type(MPI.COMM_TYPE_SHARED, key=comm.Get_rank())
    try:
        mine = sorted(os.sched_getaffinity(0))
        every = node.allgather(mine)
        local, size = node.Get_rank(), node.Get_size()
    finally:
        node.Free()
    if size == 1 or any(a != mine for a in every) or len(mine) < size * n_threads:
        return None
    global BOUND
    order = cores_first(mine)
    cores = tuple(sorted(order[local * n_threads:(local + 1) * n_threads]))
    try:
        os.sched_setaffinity(0, cores)
    except OSError:     # a container or cpuset that refuses it: the rank stays as launched
        return None
    BOUND = cores
    return cores


def cores_first(cpus, siblings=None):
    """``cpus`` ordered so that one of each physical core's hyperthreads comes before any second one:
    by the position of each among its core's siblings, then by number (x86 Linux numbers the cores
    before their siblings already; POWER and some ARM number a core's threads next to each other).

    Parameters
    ----------
    cpus : sequence of int
    siblings : callable or None
        cpu -> the sorted cpus of its physical core (default: Linux's ``thread_siblings_list``; a cpu
        whose list cannot be read is a core of its own).
    """
    siblings = siblings or _siblings

    def key(c):
        mates = siblings(c)
        return (mates.index(c) if c in mates else 0, c)
    return sorted(cpus, key=key)


def _siblings(cpu):
    """The cpus that share ``cpu``'s physical core, sorted (Linux sysfs; [cpu] when unknown)."""
    try:
        with open(f"/sys/devices/system/cpu/cpu{cpu}/topology/thread_siblings_list") as fh:
            text = fh.read().strip()
    except OSError:
        return [cpu]
    out = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        out += range(int(lo), int(hi or lo) + 1)
    return sorted(out)


def usable_cores():
    """Cores this process may run on (its affinity: one under mpiexec's default binding)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def snapshot():
    """This process's thread settings (mpdem's request, numba's count), for ``restore``."""
    import numba
    return _requested, numba.get_num_threads()


def restore(saved):
    """Put back the settings of ``snapshot`` (an in-process caller of the CLI gets its own back)."""
    import numba
    global _requested
    _requested = saved[0]
    numba.set_num_threads(saved[1])


def count():
    """Threads numba uses now."""
    import numba
    return numba.get_num_threads()
