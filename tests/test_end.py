"""The end of a run (``Run.finish``): the digest, and the bulk measurement only where it is asked for
(``output.bulk_at_end``), so that a run of a pile too large for one rank ends without gathering it.

The digest by chunks of ids on several ranks is ``mpi_tests/test_state_files.py``'s; a rank's messages
at the end at two pile sizes ``mpi_tests/test_grid.py``'s.
"""
import json
import os

import mpdem
from mpdem import config, footprint
from mpdem.io import checkpoint

SETS = ["box.L_x=5.0", "box.L_y=5.0", "pour.N=120", "pour.phi_i=0.3", "run.max_steps=600",
        "output.progress_every=100000"]


def test_without_the_bulk_at_the_end_the_summary_has_the_digest_and_says_how_to_measure(tmp_path):
    a = mpdem.run(config.load(None, SETS), tmp_path / "a", quiet=True)
    b = mpdem.run(config.load(None, SETS + ["output.bulk_at_end=false"]), tmp_path / "b", quiet=True)
    sa = json.loads((tmp_path / "a" / "summary.json").read_text())
    sb = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert a.digest == b.digest == sa["digest"] == sb["digest"]
    # the digest is the final state file's (written first, then the digest of the rows that it holds)
    assert checkpoint.digest(checkpoint.read_state(str(tmp_path / "b" / "final.h5"))[0]) == sb["digest"]
    assert "bulk" in sa and "bulk" not in sb
    log = (tmp_path / "b" / "log.txt").read_text()
    said = "bulk: not measured at the end (output.bulk_at_end = false): `python -m mpdem analyze"
    assert f"{said} {tmp_path / 'b'}`" in log
    assert os.path.exists(tmp_path / "b" / "final.h5")


def test_the_end_s_estimate_does_not_grow_with_the_pile():
    """``footprint``: rank 0's end is a chunk of the digest and its own rows, the same at twice the pile on
    twice the ranks, with the bulk measurement (each rank's contact search over its rows and ghosts) or
    without it."""
    def end(n, ranks, at_end):
        cfg = config.load(None, ["box.L_x=100.0", "box.L_y=100.0", f"pour.N={n}", "run.max_steps=10",
                                 f"output.bulk_at_end={str(at_end).lower()}"])
        return footprint.of_config(cfg, ranks).end
    assert end(2_000_000, 8, False) < 1.02 * end(1_000_000, 4, False)
    assert end(1_000_000, 4, True) > end(1_000_000, 4, False)
    assert end(2_000_000, 8, True) < 1.02 * end(1_000_000, 4, True)
