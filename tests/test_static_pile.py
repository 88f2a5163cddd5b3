"""docs/model.md 9.7: a frictionless pile settles to rest with bulk z near 6.1.

N = 2000 in a 10 d x 10 d cell, mu = 0, k_n = 2e5 (epsilon 0.88, the
defaults otherwise). About 1.3 million steps: a few minutes on one core.
"""
import json

import pytest

from mpdem import config
from mpdem.analysis import report
from mpdem.driver.simulation import Run


@pytest.mark.validation
def test_frictionless_pile_settles_to_z_near_6(tmp_path):
    cfg = config.load(None, ["run.max_steps=3000000", "box.L_x=10.0", "box.L_y=10.0", "pour.N=2000",
                             "contact.mu=0.0", "output.progress_every=200000"])
    run = Run.new(cfg, str(tmp_path / "pile"), quiet=True)
    assert run.run() == "converged", "the pile did not settle within 3e6 steps"
    summary = run.finish()
    assert summary["E_k_per_particle"] < 1e-8
    bulk = summary["bulk"]
    # docs/model.md: within a few per cent of 6.1 (reference 6.140 at this size)
    assert abs(bulk["z"] - 6.1) < 0.03 * 6.1, bulk
    assert 0.62 < bulk["phi"] < 0.66, bulk
    assert bulk["n_bulk"] > 500
    assert json.loads((tmp_path / "pile" / "summary.json").read_text())["converged"] is True
    # mpdem analyze on the run directory: the same bulk, and the rest of docs/model.md 6
    s, out = report.analyze(str(tmp_path / "pile"), log=lambda m: None)
    assert out == str(tmp_path / "pile" / "analysis")
    for k in ("z", "z_no_rattlers", "rattler_fraction", "phi", "n_bulk", "z1", "z2"):
        assert s[k] == bulk[k], k
    assert s["zeta"] is None and s["zeta_note"].startswith("mu = 0")
    # a frictionless pile near contact: g rises steeply (alpha > 0) and contacts per sphere near z
    assert s["alpha"] > 0.2 and abs(s["gofr"]["near_contacts_per_ref"] - bulk["z"]) < 0.3
    for name in ("summary.json", "profile.png", "coordination.png", "gofr.png", "gofr_near.png",
                 "profile.csv", "coordination.csv", "gofr.csv", "gofr_near.csv"):
        assert (tmp_path / "pile" / "analysis" / name).stat().st_size > 0, name
