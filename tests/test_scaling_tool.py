"""tools/scaling.py: the scaling table reads what the bench prints, and its efficiencies are 1 when R
ranks do R times one core's atom-steps."""
import importlib.util
from pathlib import Path

import pytest

from mpdem import bench, config

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("scaling", ROOT / "tools" / "scaling.py")
scaling = importlib.util.module_from_spec(spec)
spec.loader.exec_module(scaling)


def bench_text(ranks, grid):
    """The lines of a table bench of ``ranks`` ranks on ``grid``, as ``bench.report_lines`` prints them."""
    phases = {k: 0.0 for k in bench.PHASES + ("communication",)}
    fig = dict(table="t.txt.gz", tile=(2, 1), n_atoms=40000, n_mobile=38000, L_x=40.0, L_y=20.0,
               cfg=config.load(None, ["run.max_steps=1"]), ranks=ranks, steps=1000, wall=4.0, wall_max=4.2,
               rebuilds=12, phases=(phases, phases), steadiness=[dict(median=1e-3, p90=2e-3, slow=0.1, switches=3)],
               device="CPU", contacts=200000, ek=1.0, imbalance=1.05, balanced="work",
               per_rank=[phases] * ranks, grown=1e8, peak=2e8, engine_bytes=5e7, threads=1, grid=grid,
               ghosts_per_owned=0.125, refresh_bytes=2_500_000)
    return "\n".join(bench.report_lines(fig)), fig


def test_the_rows_read_the_bench_s_own_lines():
    text, fig = bench_text(4, (2, 2, 1))
    row = scaling.parse(text)
    assert row["ns"] == pytest.approx(fig["ns"], rel=1e-5)
    assert row["grid"] == "2 x 2 x 1" and row["ghosts_per_owned"] == 0.125 and row["refresh_mb"] == 2.5
    one = scaling.parse(bench_text(1, (1, 1, 1))[0])
    assert "grid" not in one and one["ns"] > 0


def test_efficiencies_and_tiles():
    # strong: the same atoms in a quarter of the time at 4 ranks; weak: 4 times the atoms in the same time
    assert scaling.efficiency(100.0, 25.0, 4) == 1.0
    assert scaling.efficiency(100.0, 50.0, 4) == 0.5
    assert scaling.efficiency(None, 50.0, 4) is None
    assert scaling.tiles_of(16) == (4, 4) and scaling.tiles_of(8) == (4, 2) and scaling.tiles_of(2) == (2, 1)
    t = scaling.table([dict(kind="weak", R=4, grid="2 x 2 x 1", ns=12.5, eff_one=0.8, eff_ceiling=0.9, rc=0,
                            ghosts_per_owned=0.1, refresh_mb=1.0),
                       dict(kind="strong", R=8, label="slabs", ns=None, rc="timeout")])
    assert "0.80" in t and "0.90" in t and "failed (timeout)" in t
