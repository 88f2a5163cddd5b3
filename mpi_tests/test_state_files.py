"""Collective state files under K ranks: written by all ranks, read back by
all ranks (each its share, then to the slab owners) or by one process, with
the same digest; a damaged file is refused on every rank, none hangs."""
import os

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from mpdem.io import checkpoint
from mpdem import config
from mpdem.io import rundir
from mpdem.io.checkpoint import StateFileError
from mpdem.decomp import Domain

from mpi_helpers import PILE, run, shared_dir


@pytest.fixture(scope="module")
def landed(tmp_path_factory):
    comm = MPI.COMM_WORLD
    base = shared_dir(comm)
    cfg = config.load(None, PILE + ["run.max_steps=20000", "output.checkpoint_every=20000"])
    r, s = run(cfg, os.path.join(base, "w"), comm)
    return r, comm.bcast(s["digest"] if comm.Get_rank() == 0 else None)


def gathered_digest(dom, st):
    arrays = dom.gather_arrays(checkpoint.gather_state(st))
    return dom.net.bcast(checkpoint.digest(arrays) if dom.rank == 0 else None)


def test_written_by_all_read_by_all(comm, landed):
    r, ref = landed
    path = rundir.checkpoint_path(r.out, 0)
    local, attrs = checkpoint.read(path, comm)
    n = comm.allreduce(len(local["id"]))
    assert n == attrs["n"] and attrs["ranks"] == comm.Get_size() and attrs["step"] == 20000
    dom = Domain(comm)
    st = dom.distribute(local, attrs["L_x"], attrs["L_y"])
    assert gathered_digest(dom, st) == ref
    # every rank owns the particles of its slab after the redistribution
    z = st.x[:st.n_own, 2]
    assert np.all((z >= dom.bounds[dom.rank]) & (z < dom.bounds[dom.rank + 1]))
    # one process reads the same file whole
    if comm.Get_rank() == 0:
        whole, _ = checkpoint.read_state(path)
        assert checkpoint.digest(whole) == ref
    # the final file holds the contact list once: as many pairs as one rank finds
    fin, _ = checkpoint.read(rundir.final_path(r.out), comm, pairs=True)
    pairs = comm.allgather(np.column_stack([fin["id_i"], fin["id_j"]]))
    if comm.Get_rank() == 0:
        p = np.concatenate(pairs)
        assert len(p) > 0 and len(np.unique(p, axis=0)) == len(p)


def test_damaged_file_is_refused_on_every_rank(comm, landed):
    r, _ = landed
    src = rundir.checkpoint_path(r.out, 0)
    bad = os.path.join(os.path.dirname(src), "bad.h5")
    if comm.Get_rank() == 0:
        with open(src, "rb") as a, open(bad, "wb") as b:
            b.write(a.read())
        with h5py.File(bad, "r+") as f:
            # the last row: read by the last rank only, yet every rank must refuse
            v = f["particles/v"][()]
            v[-1, 0] = -v[-1, 0] if v[-1, 0] else 1e-300
            f["particles/v"][...] = v
    comm.Barrier()
    with pytest.raises(StateFileError, match="checksum mismatch in /particles"):
        checkpoint.read(bad, comm)
    comm.Barrier()


def test_a_file_one_rank_cannot_see_is_refused_on_every_rank(comm, landed, monkeypatch):
    """A rank that finds no file (a stale view of a shared file system) while the others do: every rank
    refuses it, before the open that parallel HDF5 makes collective, where the others would wait alone."""
    r, _ = landed
    path = rundir.checkpoint_path(r.out, 0)
    last = comm.Get_size() - 1
    if comm.Get_rank() == last:
        monkeypatch.setattr(checkpoint, "_not_a_file", lambda p: f"{p}: no such file")
    with pytest.raises(StateFileError, match="no such file"):
        checkpoint.read(path, comm)
    comm.Barrier()


def test_without_parallel_hdf5_rank_0_writes_the_same_file(comm, landed, monkeypatch):
    """h5py without ``mpio`` (pip's wheel, docs/install.md): the rows go to rank 0, which writes the
    file alone, and every rank reads its share plainly; the datasets and attributes are those of the
    collective write."""
    r, ref = landed
    src = rundir.checkpoint_path(r.out, 0)
    local, attrs = checkpoint.read(src, comm)
    monkeypatch.setattr(checkpoint, "parallel_hdf5", lambda: False)
    path = os.path.join(os.path.dirname(src), "through-root.h5")
    checkpoint.write(path, local, attrs, comm)
    again, attrs2 = checkpoint.read(path, comm)
    assert attrs2["ranks"] == comm.Get_size()
    for k in local:
        assert np.array_equal(np.asarray(local[k]).reshape(np.shape(again[k])), again[k]), k
    comm.Barrier()
    if comm.Get_rank() == 0:
        with h5py.File(src) as a, h5py.File(path) as b:
            names = []
            a.visit(lambda n: names.append(n) if isinstance(a[n], h5py.Dataset) else None)
            assert names and all(np.array_equal(a[n][()], b[n][()]) for n in names)
            assert {k: str(v) for k, v in a.attrs.items()} == {k: str(v) for k, v in b.attrs.items()}
        whole, _ = checkpoint.read_state(path)
        assert checkpoint.digest(whole) == ref


@pytest.mark.parametrize("layout", ["blocks", "scattered", "one rank empty"])
@pytest.mark.parametrize("chunk", [1, 7, 1 << 18])
@pytest.mark.parametrize("spread", ["dense", "wide", "an outlier"])
def test_the_digest_by_chunks_of_ids_is_the_whole_states(comm, layout, chunk, spread):
    """``checkpoint.digest_parts``: each rank's id-sorted rows with their contact slots (and wall
    histories), brought to rank 0 a chunk of ids at a time, hash as ``digest`` of the whole state does:
    ids with gaps, ids spread wide (ranges of many ids), ids above 2^53 (no float can tell them apart),
    rows of no slot, chunks of one row, and a rank holding nothing."""
    from mpdem.io import checkpoint
    from mpdem.parallel import Channel
    rng = np.random.default_rng(11)
    n = 50
    if spread == "dense":
        ids = rng.choice(10_000, n, replace=False)
    elif spread == "wide":
        ids = rng.choice(10_000_000, n, replace=False)
    else:
        ids = np.r_[rng.choice(100, n - 2, replace=False), 2**53 + 1, 2**53 + 3]
    ids = np.sort(ids).astype(np.int64)
    count = rng.integers(0, 4, n)
    whole = {"id": ids, "x": rng.random((n, 3)), "v": rng.random((n, 3)), "omega": rng.random((n, 3)),
             "f": rng.random((n, 3)), "torque": rng.random((n, 3)), "fixed": (rng.random(n) < 0.2).astype(np.uint8),
             "count": count.astype(np.int32), "partner": rng.integers(0, 10_000, count.sum()).astype(np.int64),
             "ds": rng.random((count.sum(), 3)), "wall_ds": rng.random((n, 3))}
    P, r = comm.Get_size(), comm.Get_rank()
    if layout == "blocks":
        owner = np.arange(n) * P // n
    elif layout == "scattered":
        owner = rng.integers(0, P, n)
    else:
        owner = rng.integers(1, P, n) if P > 1 else np.zeros(n, np.int64)
    from mpdem.state import select_rows
    part = select_rows(whole, np.flatnonzero(owner == r))
    got = checkpoint.digest_parts(part, Channel(comm), chunk=chunk)
    if r == 0:
        assert "wall_ds" in [f.name for f in checkpoint._digest_fields(whole)]
        assert got == checkpoint.digest(whole)
    else:
        assert got is None
