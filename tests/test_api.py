"""The Python API (docs/python.md): the functions the command line is built on."""
import json
import os
import re
from pathlib import Path

import numpy as np
import pytest

import mpdem
from mpdem.io import checkpoint
from mpdem.config import ConfigError
from mpdem.analysis.report import AnalysisError
from mpdem.errors import MpdemError

from helpers import mpdem as cli

ROOT = Path(__file__).resolve().parents[1]
SMALL = {"pour.N": 200, "box.L_x": 5.0, "box.L_y": 5.0, "pour.phi_i": 0.3, "pour.K0": 5.0,
         "stop.sample_interval": 0.01, "run.max_steps": 30000}


def test_load_config_takes_keys_by_name_and_raises_on_bad_values():
    cfg = mpdem.load_config(**{"contact.mu": 0.3, "analysis.alpha_windows": [1e-3, 1e-2]})
    assert cfg.contact.mu == 0.3 and cfg.analysis.alpha_windows == (1e-3, 1e-2)
    assert cfg.pour.N == 1500                               # the built-in example underneath
    with pytest.raises(ConfigError, match=r"contact.mu = -1.0: accepted"):
        mpdem.load_config(**{"contact.mu": -1.0})
    with pytest.raises(ConfigError, match=r"^load_config key contact\.muu: unknown key \(did you mean contact\.mu\?\)"):
        mpdem.load_config(**{"contact.muu": 1.0})


def test_dir_lists_the_lazily_loaded_api():
    """Tab completion and dir(mpdem) show the functions ``import mpdem`` loads on first use."""
    names = dir(mpdem)
    assert set(mpdem.API) <= set(names) and "__version__" in names


def test_a_run_called_from_another_thread_runs(tmp_path):
    """Only the main thread may set signal handlers: a run from another thread (a GUI's, a notebook
    extension's) steps without them (it stops on its cap, its stop rule or its wall time)."""
    import threading
    got = {}

    def go():
        try:
            got["run"] = mpdem.run(mpdem.load_config(**dict(SMALL, **{"run.max_steps": 300})), str(tmp_path / "t"))
        except BaseException as e:      # noqa: BLE001 (handed to the test's thread)
            got["error"] = e
    t = threading.Thread(target=go)
    t.start()
    t.join(300)
    assert "error" not in got, repr(got.get("error"))
    assert got["run"].status == "max_steps" and got["run"].steps == 300


def test_run_read_analyze_and_restart_as_the_command_line_does(tmp_path):
    cfg = mpdem.load_config(**SMALL)
    r = mpdem.run(cfg, str(tmp_path / "api"))
    assert r.status == "max_steps" and r.steps == 30000 and r.exit_status == 3
    assert r.final == str(tmp_path / "api" / "final.h5") and os.path.exists(r.final)
    assert r.digest == checkpoint.digest(checkpoint.read_state(r.final)[0]) == r.summary["digest"]
    # the command line, same config: same digest
    p = cli("run", "--out", tmp_path / "cli", "--quiet", *sum((["--set", f"{k}={v}"] for k, v in SMALL.items()), []))
    assert p.returncode == 3, p.stderr
    assert checkpoint.digest(checkpoint.read_state(str(tmp_path / "cli" / "final.h5"))[0]) == r.digest
    # a directory that holds a run is refused unless forced
    with pytest.raises(MpdemError, match="already holds a run"):
        mpdem.run(cfg, str(tmp_path / "api"))
    s = mpdem.read_state(r.final)
    assert s["x"].shape == (len(s["id"]), 3) and np.all(np.diff(s["id"]) > 0)
    assert len(s["id_i"]) == len(s["F_n"]) > 0 and s["L_x"] == 5.0 and s.attrs["step"] == 30000
    a = mpdem.analyze(r.final)
    b = mpdem.analyze(s)
    assert a["z"] == b["z"] and a["backbone"] == b["backbone"] and a["phi"] == b["phi"]
    n, P = a["arrays"]["P_z"]
    assert P.sum() == pytest.approx(1.0) and len(n) == 13
    assert not (tmp_path / "api" / "analysis").exists()     # no files unless asked
    a = mpdem.analyze(str(tmp_path / "api"), write=True, **{"analysis.margin_bottom": 3.0})
    assert (tmp_path / "api" / "analysis" / "summary.json").exists() and a["margin_bottom"] == 3.0
    # at the cap: nothing to do; a higher cap goes on to the straight run's state
    again = mpdem.restart(str(tmp_path / "api"))
    assert again.status == "max_steps" and again.digest == r.digest and again.steps == 30000
    # a run that ended before its summary was written: the restart with nothing to do writes it from final.h5
    written = json.loads((tmp_path / "api" / "summary.json").read_text())
    os.remove(tmp_path / "api" / "summary.json")
    again = mpdem.restart(str(tmp_path / "api"))
    back = json.loads((tmp_path / "api" / "summary.json").read_text())
    assert again.digest == back["digest"] == r.digest and "recovered" in back
    assert {k: back[k] for k in ("steps", "time", "status", "converged", "E_k_per_particle", "segments")} == {
        k: written[k] for k in ("steps", "time", "status", "converged", "E_k_per_particle", "segments")}
    more = mpdem.restart(str(tmp_path / "api"), **{"run.max_steps": 40000})
    straight = mpdem.run(mpdem.load_config(**dict(SMALL, **{"run.max_steps": 40000})), str(tmp_path / "straight"))
    assert more.steps == straight.steps == 40000 and more.digest == straight.digest
    with pytest.raises(AnalysisError, match="no usable runs"):
        mpdem.collect([str(tmp_path / "api")])


def test_the_python_page_runs_as_written(tmp_path, monkeypatch):
    """docs/python.md, its code blocks in order, in a fresh directory."""
    text = (ROOT / "docs" / "python.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) >= 5
    monkeypatch.chdir(tmp_path)
    scope = {}
    for code in blocks:
        exec(compile(code, "docs/python.md", "exec"), scope)
    r = scope["r"]
    assert r.status == "converged" and (tmp_path / "runs" / "small" / "pile.png").exists()
    assert float(scope["tables"]["runs"][0]["z"]) == pytest.approx(scope["a"]["z"])


def test_the_unbalanced_force_ratio_and_its_stop_rule(tmp_path):
    """The ratio (mean |resultant| over mean |contact force|) in thermo.csv, the progress line and
    summary.json equals a brute-force sum over the final file's contact list; stop.rule = 'force'
    waits until no sphere is in flight (a pouring pile has a small ratio too)."""
    cfg = mpdem.load_config(**{"pour.N": 200, "box.L_x": 4.0, "box.L_y": 4.0, "run.max_steps": 1_000_000,
                               "stop.rule": "force", "stop.force_ratio": 0.02, "output.progress_every": 1000})
    r = mpdem.run(cfg, str(tmp_path / "f"))
    assert r.status == "converged" and r.summary["force_ratio"] < 0.02
    s = mpdem.read_state(r.final)
    mob = s["fixed"] == 0
    rows_i, rows_j = np.searchsorted(s["id"], s["id_i"]), np.searchsorted(s["id"], s["id_j"])
    b = s["x"][rows_i] - s["x"][rows_j]
    b[:, :2] -= 4.0 * np.round(b[:, :2] / 4.0)
    F = np.linalg.norm(s["F_n"][:, None] * b / np.linalg.norm(b, axis=1)[:, None] + s["F_t"], axis=1)
    w = mob[rows_i].astype(int) + mob[rows_j]                 # a pair counts for each mobile sphere it touches
    brute = np.linalg.norm(s["f"][mob], axis=1).mean() / ((F * w).sum() / w.sum())
    assert r.summary["force_ratio"] == pytest.approx(brute, rel=1e-9)
    # every sphere has landed: each mobile sphere has a contact
    assert np.all(np.bincount(np.concatenate([rows_i, rows_j]), minlength=len(mob))[mob] > 0)
    rows = (tmp_path / "f" / "thermo.csv").read_text().splitlines()
    assert rows[0].split(",")[11] == "force_ratio"
    assert float(rows[-1].split(",")[11]) == pytest.approx(r.summary["force_ratio"])
    assert float(rows[1].split(",")[11]) == float("inf")      # the first sample: no contact yet
    assert " F_unbal " in (tmp_path / "f" / "log.txt").read_text()
    # the energy rule (default) of the same pile stops later, and reports the ratio as well
    e = mpdem.run(mpdem.load_config(**{k: v for k, v in cfg.values.items()
                                       if k in ("pour.N", "box.L_x", "box.L_y", "run.max_steps")}), str(tmp_path / "e"))
    assert e.status == "converged" and e.steps > r.steps and 0 < e.summary["force_ratio"] < r.summary["force_ratio"]
