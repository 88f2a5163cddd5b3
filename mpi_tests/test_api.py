"""The Python API under mpiexec: every rank calls mpdem.run with the same arguments."""
import os

from mpi4py import MPI

import mpdem
from mpdem import config

from mpi_helpers import PILE, serial_digest, shared_dir


def test_api_run_and_restart_on_all_ranks_match_one_rank(comm):
    base = shared_dir(comm)
    sets = dict(item.split("=", 1) for item in PILE)
    sets = {k: float(v) if "." in v or "e" in v else int(v) for k, v in sets.items()}
    cfg = mpdem.load_config(None, **sets, **{"run.max_steps": 20000})
    r = mpdem.run(cfg, os.path.join(base, "api"))          # MPI's COMM_WORLD by default
    assert r.status == "max_steps" and r.steps == 20000
    assert r.digest == r.summary["digest"] and r.final == os.path.join(base, "api", "final.h5")
    more = mpdem.restart(os.path.join(base, "api"), **{"run.max_steps": 30000})
    ref = serial_digest(config.load_run_config(None, PILE + ["run.max_steps=30000"]), os.path.join(base, "ser"), comm)
    # every rank holds the result, and it is the one-rank run's
    assert more.steps == 30000 and more.digest == ref
    assert comm.allgather(more.digest) == [ref] * comm.Get_size()
    # the unbalanced-force ratio is summed exactly: the one-rank value to the last bit
    one = None
    if comm.Get_rank() == 0:
        one = mpdem.run(config.load_run_config(None, PILE + ["run.max_steps=30000"]), os.path.join(base, "one"),
                        net=MPI.COMM_SELF).summary["force_ratio"]
    assert more.summary["force_ratio"] == comm.bcast(one)
