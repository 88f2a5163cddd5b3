"""Flow arrest from one config (``flowarrest``, docs/model.md 5.5): a pile poured onto a bed tilted by
flow.incline flows downslope across the slabs, then the incline drops; on every rank count the run
gives the one-rank digest, straight and restarted inside the flow."""
import os

import mpdem
from mpdem import config

from mpi_helpers import PILE, serial_digest, shared_dir

FLOW = PILE + ["contact.mu=0.5", "flow.incline=25", "flow.time=0.15", "box.incline=5", "run.max_steps=3000"]


def test_a_flow_arrest_run_on_all_ranks_matches_one_rank(comm):
    base = shared_dir(comm)
    cfg = config.load_run_config(None, FLOW)
    r = mpdem.run(cfg, os.path.join(base, "straight"))
    ref = serial_digest(cfg, os.path.join(base, "ser"), comm)
    assert r.status == "max_steps" and r.digest == ref
    assert comm.allgather(r.digest) == [ref] * comm.Get_size()
    # stopped inside the flow (a checkpoint at step 900 of its 1500), restarted across the switch
    first = mpdem.run(config.load_run_config(None, FLOW[:-1] + ["run.max_steps=900", "output.checkpoint_every=900"]),
                      os.path.join(base, "split"))
    assert first.status == "max_steps"
    again = mpdem.restart(os.path.join(base, "split"), set_items=["run.max_steps=3000"])
    assert again.digest == ref
