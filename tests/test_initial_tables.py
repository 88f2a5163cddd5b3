"""Settled tables load (overlaps up to checks.overlap_warn), gzip tables, tiling."""
import gzip
import re

import numpy as np
import pytest

from mpdem import build, config
from mpdem.io import tables
from mpdem.driver.simulation import Run

from helpers import settled_table


def test_check_initial_accepts_a_settled_overlap_and_names_the_largest():
    ids = np.array([7, 3, 9, 4])
    x = np.array([[1.0, 1.0, 2.0], [1.0, 1.0, 2.999], [3.0, 3.0, 2.0], [3.0, 3.996, 2.0]])
    fixed = np.zeros(4, np.uint8)
    said = []
    build.check_initial(ids, x, fixed, 5.0, 5.0, 0.0, overlap_warn=0.05, warn=said.append)
    assert len(said) == 1
    assert "2 overlapping pairs" in said[0] and re.search(r"particles 9 and 4 overlap by 0\.004\d* d", said[0])
    # deeper than overlap_warn: the error names the deepest pair and its depth
    x[3, 1] = 3.9
    with pytest.raises(build.InputError, match=r"particles 9 and 4 overlap by 0\.1\d* d .*overlap_warn = 0\.05"):
        build.check_initial(ids, x, fixed, 5.0, 5.0, 0.0, overlap_warn=0.05, warn=said.append)
    # the default refuses any overlap, as docs/model.md 8 says
    x[3, 1] = 3.996
    with pytest.raises(build.InputError, match=r"particles 9 and 4 overlap by 0\.004"):
        build.check_initial(ids, x, fixed, 5.0, 5.0, 0.0)


def test_check_initial_overlap_across_the_periodic_boundary():
    ids = np.array([0, 1])
    x = np.array([[0.1, 2.0, 2.0], [4.2, 2.0, 2.0]])          # 0.9 apart through x = 0
    with pytest.raises(build.InputError, match=r"particles 0 and 1 overlap by 0\.1"):
        build.check_initial(ids, x, np.zeros(2, np.uint8), 5.0, 5.0, 0.0, overlap_warn=0.05)


def test_run_from_a_settled_table_warns_once(tmp_path):
    settled_table(tmp_path / "settled.txt")
    cfg = config.load(None, ["run.max_steps=10", "box.L_x=6.0", "box.L_y=6.0",
                             f'run.initial_file="{tmp_path / "settled.txt"}"'])
    r = Run.new(cfg, str(tmp_path / "run"), quiet=True)
    warned = [ln for ln in (tmp_path / "run" / "log.txt").read_text().splitlines() if "overlapping pairs" in ln]
    assert len(warned) == 1 and "216 overlapping pairs accepted" in warned[0]
    assert r.n_mobile == 216 and r.n_bed == 36


def test_gzip_table_reads_as_the_plain_one(tmp_path):
    settled_table(tmp_path / "t.txt")
    with open(tmp_path / "t.txt", "rb") as src, gzip.open(tmp_path / "t.txt.gz", "wb") as dst:
        dst.write(src.read())
    a, b = tables.read_table(tmp_path / "t.txt"), tables.read_table(tmp_path / "t.txt.gz")
    assert all(np.array_equal(a[k], b[k]) for k in a)
    (tmp_path / "bad.gz").write_bytes(b"\x1f\x8bnot gzip")
    with pytest.raises(build.InputError, match="bad.gz: cannot read"):
        tables.read_table(tmp_path / "bad.gz")


def test_tile_table_copies_and_renumbers():
    t = {"id": np.array([4, 1]), "x": np.array([[0.5, 1.5, 1.0], [5.5, -0.5, 2.0]]),
         "v": np.array([[1.0, 0, 0], [0, 2.0, 0]]), "fixed": np.array([0, 1], np.uint8)}
    w = tables.tile_table(t, 6.0, 6.0, 2, 3)
    assert len(w["id"]) == 12 and len(np.unique(w["id"])) == 12
    assert w["id"][:2].tolist() == [4, 1]                       # copy 0 keeps the ids
    assert np.all((w["x"][:, 0] >= 0) & (w["x"][:, 0] < 12) & (w["x"][:, 1] >= 0) & (w["x"][:, 1] < 18))
    assert np.allclose(w["x"][2 * 5 + 1], [5.5 + 6.0, 5.5 + 12.0, 2.0])   # copy 5 = (i 1, j 2), y wrapped
    assert np.array_equal(w["fixed"], np.tile(t["fixed"], 6)) and np.array_equal(w["v"][3], t["v"][1])


def test_a_gz_that_is_not_gzip_and_a_table_without_mobile_spheres_are_refused(tmp_path):
    (tmp_path / "plain.txt.gz").write_text("id x y z\n1 1.0 1.0 1.0\n")
    with pytest.raises(build.InputError, match=r"plain.txt.gz: named .gz but not gzip-compressed"):
        tables.read_table(tmp_path / "plain.txt.gz")
    (tmp_path / "beds.txt").write_text("id x y z fixed\n1 1.0 1.0 0.5 1\n2 2.5 1.0 0.5 1\n")
    cfg = config.load(None, ["run.max_steps=10", "box.L_x=6.0", "box.L_y=6.0",
                             f'run.initial_file="{tmp_path / "beds.txt"}"'])
    with pytest.raises(build.InputError, match=r"beds.txt: no mobile sphere: all 2 are bed spheres"):
        Run.new(cfg, str(tmp_path / "run"), quiet=True)
