"""What every rank-count-independent result rests on: exact reductions and
collective HDF5, checked under several ranks."""
import os
import tempfile

import h5py
import numpy as np
from mpi4py import MPI

from mpdem.kernels.exactsum import add_exact, new_accumulator, to_float


def test_launched_with_several_ranks(comm):
    assert comm.Get_size() > 1


def test_exact_sum_is_independent_of_the_split(comm):
    g = np.random.default_rng(42)
    vals = g.random(10007) * 10.0 ** g.integers(-12, 4, 10007)
    serial = new_accumulator()
    for v in vals:
        add_exact(serial, v)
    # an uneven, rank-dependent share of the values on each rank
    cuts = np.sort(np.random.default_rng(comm.Get_size()).integers(0, len(vals), comm.Get_size() - 1))
    mine = np.split(vals, cuts)[comm.Get_rank()]
    part = new_accumulator()
    for v in mine[::-1]:
        add_exact(part, v)
    total = np.empty_like(part)
    comm.Allreduce(part, total, op=MPI.SUM)
    assert np.array_equal(total, serial)
    assert to_float(total) == to_float(serial)


def test_collective_hdf5_write_and_read(comm):
    path = comm.bcast(os.path.join(tempfile.mkdtemp(), "c.h5") if comm.Get_rank() == 0 else None)
    n_local = 3 + comm.Get_rank()
    counts = comm.allgather(n_local)
    start = sum(counts[:comm.Get_rank()])
    with h5py.File(path, "w", driver="mpio", comm=comm) as f:
        d = f.create_dataset("x", (sum(counts), 3), dtype="f8")
        d[start:start + n_local] = comm.Get_rank() + np.arange(n_local)[:, None] * np.ones(3)
    with h5py.File(path, "r", driver="mpio", comm=comm) as f:
        x = f["x"][()]
    k = 0
    for r, c in enumerate(counts):
        assert np.array_equal(x[k:k + c, 0], r + np.arange(c))
        k += c


def test_ranks_bind_to_cores_of_their_own_only_where_the_launcher_left_them_free(comm):
    """``threads.bind``: ranks that may all run on the same cores (as MPICH's mpiexec leaves them) take
    disjoint sets of ``n_threads`` cores when they fit, in local-rank order; more than fit, or ranks a
    launcher bound already (different affinities), are left as they are."""
    from mpdem import threads
    saved = os.sched_getaffinity(0)
    node = sorted(set().union(*comm.allgather(sorted(saved))))
    try:
        for n_threads in (1, 2):
            os.sched_setaffinity(0, node)       # unbound, as a launcher that binds nothing leaves them
            got = threads.bind(comm, n_threads)
            fits = comm.Get_size() * n_threads <= len(node)    # every rank of these tests is on one node
            if not fits:
                assert got is None and sorted(os.sched_getaffinity(0)) == node
                continue
            every = comm.allgather(got)
            assert every[comm.Get_rank()] == tuple(sorted(os.sched_getaffinity(0)))
            assert all(len(c) == n_threads for c in every)
            # disjoint, in rank order, one hyperthread of every core first
            first = threads.cores_first(node)
            assert list(every) == [tuple(sorted(first[r * n_threads:(r + 1) * n_threads]))
                                   for r in range(comm.Get_size())]
        # ranks a launcher bound, to sets that differ (rank 0's all the node's cores, which alone would fit),
        # are left alone
        os.sched_setaffinity(0, node if comm.Get_rank() == 0 else node[-1:])
        before = os.sched_getaffinity(0)
        got = threads.bind(comm, 1)
        if len(node) > 1:
            assert got is None and os.sched_getaffinity(0) == before
        # "none" binds nothing
        os.sched_setaffinity(0, node)
        assert threads.bind(comm, 1, "none") is None and sorted(os.sched_getaffinity(0)) == node
    finally:
        os.sched_setaffinity(0, saved)
        threads.BOUND = None
