"""``mpdem analyze RUN --series``: every snapshot of a real run measured, the final row
the same numbers as ``mpdem analyze`` of final.h5, E_k the same as thermo.csv's."""
import csv
import json
import math

import pytest

from helpers import mpdem

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.mark.validation
@pytest.mark.parametrize("mu", [0.0, 0.5])
def test_series_of_a_settling_pile(tmp_path, mu):
    run = tmp_path / "run"
    p = mpdem("run", "--out", run, "--quiet", "--set", "pour.N=300", "--set", "box.L_x=4", "--set", "box.L_y=4",
              "--set", f"contact.mu={mu}", "--set", "run.max_steps=400000", "--set", "output.snapshot_every=50000",
              timeout=900)
    assert p.returncode in (0, 3), p.stderr
    snaps = sorted((run / "snapshots").glob("snap-*.h5"))
    assert len(snaps) >= 4
    p = mpdem("analyze", run, "--series", timeout=900)
    assert p.returncode == 0, p.stderr
    with open(run / "analysis" / "series.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(snaps) + 1 and rows[-1]["kind"] == "final"
    steps = [int(r["step"]) for r in rows]
    assert steps == sorted(steps) and steps[0] == 50000
    assert (run / "analysis" / "series.png").read_bytes()[:8] == PNG
    # E_k from the snapshot's velocities is thermo.csv's at that step
    th = {int(r["step"]): float(r["ek"]) for r in csv.DictReader(open(run / "thermo.csv"))}
    both = [r for r in rows if int(r["step"]) in th]
    assert len(both) >= len(snaps)
    for r in both:
        assert math.isclose(float(r["ek"]), th[int(r["step"])], rel_tol=1e-5), r
    # the pile sits on the bed by the end: contacts per sphere rose from the dilute pour
    assert float(rows[0]["contacts_per_particle"]) < 1 < float(rows[-1]["contacts_per_particle"])
    # the final row is mpdem analyze's measurement of final.h5
    p = mpdem("analyze", run, "--no-plots", "--quiet")
    assert p.returncode == 0, p.stderr
    s = json.loads((run / "analysis" / "summary.json").read_text())
    assert float(rows[-1]["z"]) == pytest.approx(s["z"], rel=1e-9)
    assert float(rows[-1]["phi"]) == pytest.approx(s["phi"], rel=1e-9)
    assert int(rows[-1]["n_bulk"]) == s["n_bulk"]


def test_series_needs_states(tmp_path):
    (tmp_path / "empty").mkdir()
    p = mpdem("analyze", tmp_path / "empty", "--series")
    assert p.returncode == 1 and "no snapshots and no final.h5" in p.stderr and "output.snapshot_every" in p.stderr
