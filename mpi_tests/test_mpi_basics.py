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
