"""physics.md 9.7: a frictionless pile settles to rest with bulk z near 6.1.

N = 2000 in a 10 d x 10 d cell, mu = 0, k_n = 2e5 (epsilon 0.88, the
defaults otherwise). About 1.3 million steps: a few minutes on one core.
"""
import json

import pytest

from mpdem import config
from mpdem.simulation import Run


@pytest.mark.slow
def test_frictionless_pile_settles_to_z_near_6(tmp_path):
    cfg = config.load(None, ["run.max_steps=3000000", "box.L_x=10.0", "box.L_y=10.0", "pour.N=2000",
                             "contact.mu=0.0", "output.progress_every=200000"])
    run = Run(cfg, str(tmp_path / "pile"), quiet=True)
    run.prepare()
    assert run.run(), "the pile did not settle within 3e6 steps"
    summary = run.finish()
    assert summary["E_k_per_particle"] < 1e-8
    bulk = summary["bulk"]
    # physics.md: within a few per cent of 6.1 (reference 6.140 at this size)
    assert abs(bulk["z"] - 6.1) < 0.03 * 6.1, bulk
    assert 0.62 < bulk["phi"] < 0.66, bulk
    assert bulk["n_bulk"] > 500
    assert json.loads((tmp_path / "pile" / "summary.json").read_text())["converged"] is True
