"""A stiffening rung (``mpdem stiffen``, docs/model.md 6.6: the ramp's laws step by step, the history
rescaled at each tread) on every rank count gives the one-rank digest."""
import os

import mpdem
from mpdem import config, stiffen

from mpi_helpers import PILE, serial_digest, shared_dir


def test_a_stiffening_rung_on_all_ranks_matches_one_rank(comm):
    base = shared_dir(comm)
    # a soft pile still landing (rows migrate between the slabs during the ramp), stiffened tenfold
    soft = mpdem.run(config.load_run_config(None, PILE + ["contact.k_n=2e4", "run.max_steps=4000"]),
                     os.path.join(base, "soft"))
    assert soft.status == "max_steps"
    rung = stiffen.rung_config(os.path.join(base, "soft"), 2e5, ["run.max_steps=3000", "stiffen.ramp_time=0.2"])
    r = mpdem.run(rung, os.path.join(base, "rung"))
    ref = serial_digest(rung, os.path.join(base, "ser"), comm)
    assert r.status == "max_steps" and r.digest == ref
    assert comm.allgather(r.digest) == [ref] * comm.Get_size()
