"""The bulk measurement at a run's end, made by every rank on its own rows and ghosts
(``analysis.bulkpar``), gives one rank's summary bit for bit on every grid, with and without friction,
by the force rule and the count rule; and ``bulk.bulk_summary``'s of the whole final state.

The pile: a settled development pile (N = 2000 in 10 d x 10 d, ``analysis/results/paper/runs/dev``),
written as a state file at rest and stepped once, so that the ranks hold it as a run leaves it.
"""
import json
import os

import numpy as np
import pytest
from mpi4py import MPI

from mpdem import config
from mpdem.analysis import bulk
from mpdem.io import checkpoint, packing

from mpi_helpers import run, shared_dir

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEV = os.path.join(ROOT, "analysis", "results", "paper", "runs", "dev")
PILES = {0.0: "mu0_eps0.88_kn2e5_phi0.13_s1_max_steps1e7", 0.5: "mu0.5_eps0.88_kn2e5_phi0.13_s1_max_steps1e7"}


def _state_file(mu, path):
    """The development pile of friction ``mu`` as a state file at rest (rank 0 writes it)."""
    a, attrs = packing.read(os.path.join(DEV, PILES[mu], "packing.npz"))
    n = len(a["id"])
    cfg = config.load(None, [f"contact.mu={mu}", "box.L_x=10.0", "box.L_y=10.0",
                             f"pour.N={int((a['fixed'] == 0).sum())}", "run.max_steps=1"])
    st = {"id": a["id"], "x": a["x"], "fixed": a["fixed"].astype(np.uint8), "count": np.zeros(n, np.int64),
          "partner": np.zeros(0, np.int64), "ds": np.zeros((0, 3))}
    for f in ("v", "omega", "f", "torque"):
        st[f] = np.zeros((n, 3))
    checkpoint.write(path, st, {"kind": "snapshot", "step": 0, "time": 0.0, "n": n, "L_x": 10.0, "L_y": 10.0,
                                "n_mobile": int((a["fixed"] == 0).sum()), "n_bed": int(a["fixed"].sum()),
                                "converged": False, "config": cfg.to_toml()})


def _grids(size):
    out = [[1, 1, size], [size, 1, 1]]
    if size % 2 == 0 and size > 2:
        out += [[2, size // 2, 1], [2, 1, size // 2]]
    return out


@pytest.mark.parametrize("mu", [0.0, 0.5])
@pytest.mark.parametrize("rule", ["force", "count"])
def test_the_end_s_bulk_is_one_rank_s_on_every_grid(comm, mu, rule):
    base = shared_dir(comm)
    start = os.path.join(base, "start.h5")
    if comm.Get_rank() == 0:
        _state_file(mu, start)
    comm.Barrier()
    sets = [f"run.initial_file={start}", f"contact.mu={mu}", "box.L_x=10.0", "box.L_y=10.0", "pour.N=2000",
            "run.max_steps=1", f"analysis.rattlers={rule}", "output.progress_every=100000"]
    ref = None
    if comm.Get_rank() == 0:
        _, s = run(config.load(None, sets), os.path.join(base, "one"), MPI.COMM_SELF)
        ref = s["bulk"]
        # the whole final state measured on one process (``mpdem analyze``'s way): the same bits
        a, _ = checkpoint.read_state(os.path.join(base, "one", "final.h5"))
        old = bulk.bulk_summary(a["x"], a["fixed"], 10.0, 10.0, mu, rattlers=rule)
        assert json.dumps(old, sort_keys=True) == json.dumps(ref, sort_keys=True)
        assert ref["n_bulk"] > 500 and (rule == "count" or ref["rattler_fraction"] < 0.2)
    ref = comm.bcast(ref)
    for grid in _grids(comm.Get_size()):
        g = "[" + ",".join(map(str, grid)) + "]"
        _, s = run(config.load(None, sets + [f"decomp.grid={g}"]), os.path.join(base, "g" + "x".join(map(str, grid))),
                   comm)
        if comm.Get_rank() == 0:
            assert json.dumps(s["bulk"], sort_keys=True) == json.dumps(ref, sort_keys=True), grid
