"""``mpdem analyze`` gives the same numbers for a packing whichever number of
ranks wrote its file (rows in any order, the contact list split over ranks)."""
import math
import os

import numpy as np

from mpdem.io import checkpoint
from mpdem import config
from mpdem.analysis import bulk, report

from mpi_helpers import shared_dir

# per-run bookkeeping that differs between the two files by design
VOLATILE = ("source", "written_by_ranks", "seconds")


def jittered_fcc(seed=4):
    """A jittered FCC pile on a bed layer, ids shuffled: (arrays, L)."""
    a = math.sqrt(2.0) * 0.995
    basis = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    g = np.array([[i, j, k] for k in range(14) for j in range(6) for i in range(6)], float)
    x = ((g[:, None, :] + basis[None, :, :]).reshape(-1, 3) + 0.25) * a
    rng = np.random.default_rng(seed)
    x += 0.004 * rng.standard_normal(x.shape)
    fixed = (x[:, 2] < 0.5 * a).astype(np.uint8)
    n = len(x)
    ids = rng.permutation(n)
    arr = {"id": ids, "x": x, "fixed": fixed, "count": np.zeros(n, np.int64),
           "partner": np.zeros(0, np.int64), "ds": np.zeros((0, 3))}
    for f in ("v", "omega", "f", "torque"):
        arr[f] = np.zeros((n, 3))
    L = 6 * a
    pairs, r = bulk.find_contacts(x, L, L)
    F_t = 1e3 * rng.standard_normal((len(r), 3)) * (1 - r)[:, None]
    arr.update(id_i=ids[pairs[:, 0]], id_j=ids[pairs[:, 1]], delta=1 - r, F_n=2e5 * (1 - r),
               F_t=F_t, ds_i=np.zeros((len(r), 3)))
    return arr, L


def write(path, arr, L, comm):
    P, rank = (1, 0) if comm is None else (comm.Get_size(), comm.Get_rank())
    n, m = len(arr["id"]), len(arr["id_i"])
    share = {k: arr[k][rank * n // P:(rank + 1) * n // P] for k in checkpoint.PARTICLE_FIELDS + ("count",)}
    share["partner"], share["ds"] = arr["partner"], arr["ds"]
    share.update({k: arr[k][rank * m // P:(rank + 1) * m // P] for k in checkpoint.PAIR_FIELDS})
    cfg = config.load(None, ["run.max_steps=1", f"box.L_x={L}", f"box.L_y={L}"])
    checkpoint.write(path, share, {"kind": "snapshot", "step": 3, "time": 0.3, "n": n, "L_x": L, "L_y": L,
                                   "n_mobile": int((arr["fixed"] == 0).sum()), "n_bed": int(arr["fixed"].sum()),
                                   "config": cfg.to_toml()}, comm)


def test_analysis_does_not_depend_on_the_writers(comm):
    d = shared_dir(comm)
    arr, L = jittered_fcc()
    write(os.path.join(d, "many.h5"), arr, L, comm)
    comm.Barrier()
    if comm.Get_rank() == 0:
        write(os.path.join(d, "one.h5"), arr, L, None)
        quiet = dict(plots=False, log=lambda m: None)
        many, _ = report.analyze(os.path.join(d, "many.h5"), os.path.join(d, "a-many"), **quiet)
        one, _ = report.analyze(os.path.join(d, "one.h5"), os.path.join(d, "a-one"), **quiet)
        assert many["written_by_ranks"] == comm.Get_size() and one["written_by_ranks"] == 1
        assert {k: v for k, v in many.items() if k not in VOLATILE} == \
               {k: v for k, v in one.items() if k not in VOLATILE}
        assert many["zeta"]["n_contacts"] > 0 and 0 < many["z"] <= 12
        for name in ("profile", "coordination", "gofr", "gofr_near", "zeta"):
            with open(os.path.join(d, "a-many", f"{name}.csv")) as a, \
                    open(os.path.join(d, "a-one", f"{name}.csv")) as b:
                assert a.read() == b.read(), name
    comm.Barrier()
