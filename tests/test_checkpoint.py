"""State files: round trip, integrity checks, restart fallback and refusals,
and the contact list of snapshots."""
import json
import os

import h5py
import numpy as np
import pytest

from mpdem.io import checkpoint
from mpdem.io import rundir
from mpdem.__main__ import main
from mpdem.io.checkpoint import StateFileError
from mpdem.pairs import contact_pairs

SMALL = ["box.L_x=5.0", "box.L_y=5.0", "pour.N=60", "pour.phi_i=0.3", "pour.K0=5.0", "bed.settle_time=10.0",
         "output.progress_every=1000", "stop.sample_interval=0.005", "stop.E_stop=1e-30",
         "run.max_steps=20000", "output.checkpoint_every=5000"]


def sets(*extra):
    return [a for kv in SMALL + list(extra) for a in ("--set", kv)]


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    """A 20000-step run with checkpoints every 5000 steps (the newest 3 kept) and its digest."""
    out = tmp_path_factory.mktemp("ck") / "run"
    assert main(["run", *sets(), "--out", str(out), "--quiet"]) == 3
    return out, json.loads((out / "summary.json").read_text())["digest"]


def copy_run(src, dst):
    import shutil
    shutil.copytree(src, dst)
    for name in ("final.h5", "final.xmf", "summary.json"):
        (dst / name).unlink()
    return dst


def test_round_trip_any_row_order(tmp_path):
    rng = np.random.default_rng(3)
    n = 40
    a = {"id": rng.permutation(n).astype(np.int64), "x": rng.random((n, 3)), "v": rng.random((n, 3)),
         "omega": rng.random((n, 3)), "f": rng.random((n, 3)), "torque": rng.random((n, 3)),
         "fixed": (rng.random(n) < 0.2).astype(np.uint8), "count": rng.integers(0, 4, n)}
    m = int(a["count"].sum())
    a["partner"], a["ds"] = rng.integers(0, n, m), rng.random((m, 3))
    checkpoint.write(str(tmp_path / "s.h5"), a, {"kind": "checkpoint", "step": 7, "time": 0.5})
    b, attrs = checkpoint.read_state(str(tmp_path / "s.h5"))
    assert attrs["step"] == 7 and np.array_equal(b["id"], np.arange(n))
    assert checkpoint.digest(b) == checkpoint.digest(checkpoint.sort_by_id(a))
    # the slots travelled with their particles
    k = int(np.flatnonzero(a["id"] == 5)[0])
    start = int(a["count"][:k].sum())
    s = int(b["count"][:5].sum())
    assert np.array_equal(b["partner"][s:s + a["count"][k]], a["partner"][start:start + a["count"][k]])


def _damage(path, how):
    with h5py.File(path, "r+") as f:
        if how == "flip":
            x = f["particles/x"][()]
            x[3, 1] = np.nextafter(x[3, 1], np.inf)       # one ulp of one coordinate
            f["particles/x"][...] = x
        elif how == "slot":
            d = f["contacts/ds"][()]
            d[0, 0] += 1e-3
            f["contacts/ds"][...] = d
        elif how == "missing":
            del f["contacts/ds"]
        elif how == "version":
            f.attrs["version"] = 99


@pytest.mark.parametrize("how,message", [
    ("flip", "checksum mismatch in /particles"), ("slot", "checksum mismatch in /contacts"),
    ("missing", "missing dataset /contacts/ds"), ("version", "format version 99 is not supported"),
    ("truncate", "cannot open as HDF5"), ("text", "cannot open as HDF5")])
def test_damaged_files_are_refused(small_run, tmp_path, how, message):
    run, _ = small_run
    p = tmp_path / "c.h5"
    p.write_bytes((run / "checkpoints" / "ckpt-00001.h5").read_bytes())
    if how == "truncate":
        p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
    elif how == "text":
        p.write_text("not a state file\n")
    else:
        _damage(p, how)
    with pytest.raises(StateFileError, match=message):
        checkpoint.read_state(str(p))


def test_restart_falls_back_past_a_damaged_checkpoint(small_run, tmp_path, capsys):
    run, ref = small_run
    again = copy_run(run, tmp_path / "again")
    (again / "checkpoints" / "ckpt-00003.h5").unlink()          # the run "died" after 15000
    _damage(again / "checkpoints" / "ckpt-00002.h5", "flip")     # and its newest file is bad
    assert main(["restart", str(again), "--quiet"]) == 3
    err = capsys.readouterr().err
    assert "checksum mismatch" in err and "falling back to" in err and "ckpt-00001.h5" in err
    assert json.loads((again / "summary.json").read_text())["digest"] == ref


def test_restart_from_a_damaged_file_is_an_error(small_run, tmp_path, capsys):
    run, _ = small_run
    again = copy_run(run, tmp_path / "again")
    bad = again / "checkpoints" / "ckpt-00001.h5"
    _damage(bad, "flip")
    with pytest.raises(SystemExit) as e:
        main(["restart", str(bad)])
    assert e.value.code == 1 and "checksum mismatch in /particles" in capsys.readouterr().err


def test_restart_refuses_a_config_that_does_not_match(small_run, tmp_path, capsys):
    run, _ = small_run
    again = copy_run(run, tmp_path / "again")
    cfg = (again / "config.toml").read_text()
    (again / "config.toml").write_text(cfg.replace("mu = 0.5", "mu = 0.3"))
    with pytest.raises(SystemExit):
        main(["restart", str(again / "checkpoints" / "ckpt-00002.h5")])
    err = capsys.readouterr().err
    assert "does not match" in err and "contact.mu = 0.5 in the checkpoint, 0.3 in the run directory" in err


def test_restart_set_may_not_change_physics(small_run, tmp_path, capsys):
    run, _ = small_run
    again = copy_run(run, tmp_path / "again")
    with pytest.raises(SystemExit):
        main(["restart", str(again), "--set", "contact.mu=0.2"])
    err = capsys.readouterr().err
    assert "--set contact.mu" in err and "run.initial_file=" in err


def test_checkpoints_are_numbered_and_pruned(small_run, tmp_path):
    run, _ = small_run
    out = tmp_path / "keep"
    assert main(["run", *sets("output.checkpoint_every=2500", "output.checkpoint_keep=2"),
                 "--out", str(out), "--quiet"]) == 3
    assert [k for k, _ in rundir.checkpoints(str(out))] == [6, 7]
    steps = [checkpoint.read_attrs(p)["step"] for _, p in rundir.checkpoints(str(out))]
    assert steps == [17500, 20000]


def test_clock_checkpoints_and_a_restart_from_one_give_the_straight_digest(small_run, tmp_path):
    """output.checkpoint_seconds alone (no step schedule): checkpoints land on the clock,
    and continuing from the oldest kept one ends with the straight run's digest."""
    _, digest = small_run
    out = tmp_path / "clock"
    # a tiny interval: a checkpoint every few steps, whatever the machine's speed
    assert main(["run", *sets("output.checkpoint_every=0", "output.checkpoint_seconds=0.05",
                              "output.checkpoint_keep=2"), "--out", str(out), "--quiet"]) == 3
    kept = rundir.checkpoints(str(out))
    assert len(kept) == 2 and kept[-1][0] >= 2
    steps = [checkpoint.read_attrs(p)["step"] for _, p in kept]
    assert 0 < steps[0] < steps[1] < 20000
    # restart from the older one: the newer one and the final state go
    for name in ("final.h5", "final.xmf", "summary.json"):
        (out / name).unlink()
    os.remove(kept[-1][1])
    assert main(["restart", str(out), "--quiet"]) == 3
    assert json.loads((out / "summary.json").read_text())["digest"] == digest


def _pair_forces_sum(st, phys, pairs):
    """Per-row force rebuilt from the contact list: gravity + sum of pair forces."""
    row = {int(i): k for k, i in enumerate(st.id[:st.n_rows])}
    f = np.zeros((st.n_own, 3))
    f[:, 2] = phys.law.g_z
    for a in range(len(pairs["id_i"])):
        i, j = row[int(pairs["id_i"][a])], row[int(pairs["id_j"][a])]
        d = st.x[i] - st.x[j]
        d[:2] -= np.array([st.L_x, st.L_y]) * np.round(d[:2] / [st.L_x, st.L_y])
        fc = pairs["F_n"][a] * d / np.linalg.norm(d) + pairs["F_t"][a]
        assert abs(1 - np.linalg.norm(d) - pairs["delta"][a]) < 1e-12
        if i < st.n_own:
            f[i] += fc
        if j < st.n_own:
            f[j] -= fc
    return f


@pytest.mark.parametrize("model,gamma_t", [("hooke", 0.0), ("hertz", 0.0), ("hooke", 10.0)])
def test_contact_list_reproduces_the_step_forces(engine_factory, model, gamma_t):
    """A squeezed 4 x 4 x 3 block with random spins, on a bed row, after 20 steps:
    the contact list's forces add up to every particle's force."""
    rng = np.random.default_rng(5)
    g = np.stack(np.meshgrid(np.arange(4), np.arange(4), np.arange(3), indexing="ij"), -1).reshape(-1, 3)
    x = 0.995 * g + [1.0, 1.0, 1.5] + 0.001 * rng.standard_normal(g.shape)
    bed = np.stack(np.meshgrid(np.arange(5), np.arange(5), indexing="ij"), -1).reshape(-1, 2) * 0.995
    x = np.concatenate([x, np.column_stack([bed + 0.5, np.full(len(bed), 0.505)])])
    fixed = np.r_[np.zeros(len(g), np.uint8), np.ones(len(bed), np.uint8)]
    # spins from 1 to 300: some contacts stick, some slide
    spin = rng.standard_normal(x.shape) * 10 ** rng.uniform(0, 2.5, (len(x), 1))
    omega = np.where(fixed[:, None] == 0, spin, 0.0)
    eng = engine_factory(x, omega=omega, fixed=fixed, L=6.0, mu=0.5, gravity=1.0, model=model,
                         gamma_t=gamma_t)
    eng.advance(20)
    st, phys = eng.state, eng.phys
    pairs = contact_pairs(st, phys)
    mobile = st.fixed[:st.n_own] == 0
    ft, fn = np.linalg.norm(pairs["F_t"], axis=1), np.abs(pairs["F_n"])
    # many contacts, some sliding (|F_t| = mu |F_n|) and some sticking
    assert len(pairs["id_i"]) > 60 and np.any(ft > 0.999 * phys.law.mu * fn) and np.any(ft < 0.9 * phys.law.mu * fn)
    f = _pair_forces_sum(st, phys, pairs)
    assert np.allclose(f[mobile], st.f[:st.n_own][mobile], rtol=0, atol=1e-10 * np.abs(st.f).max())
    assert np.all(ft <= phys.law.mu * fn * (1 + 1e-9) + 1e-12)        # Coulomb, to rounding
    # each contact once, and as many as the slots hold (mobile-mobile pairs in two slots)
    assert len(set(zip(pairs["id_i"].tolist(), pairs["id_j"].tolist()))) == len(pairs["id_i"])
    n_bed = int(np.sum(pairs["id_j"] >= len(g)))          # bed ids follow the block's
    assert 2 * (len(pairs["id_i"]) - n_bed) + n_bed == st.count[:st.n_own][mobile].sum()


def test_snapshots_on_schedule_and_info(tmp_path, capsys):
    out = tmp_path / "snap"
    assert main(["run", *sets("output.snapshot_every=10000"), "--out", str(out), "--quiet"]) == 3
    snaps = rundir.snapshots(str(out))
    assert [k for k, _ in snaps] == [0, 1]
    a, attrs = checkpoint.read_state(snaps[1][1], pairs=True)
    assert attrs["kind"] == "snapshot" and attrs["step"] == 20000 and len(a["id_i"]) > 0
    assert (out / "snapshots" / "snap-00000.xmf").exists() and (out / "snapshots" / "series.xmf").exists()
    assert (out / "final.xmf").exists()
    # the contact network beside every snapshot and the final state, and in the series as a second collection
    import h5py
    import xml.etree.ElementTree as ET
    # in a directory of their own: the state files' globs (snapshots/*.h5, RUN/*.h5) list state files only
    assert sorted(p.name for p in (out / "snapshots").glob("*.h5")) == ["snap-00000.h5", "snap-00001.h5"]
    assert [p.name for p in out.glob("*.h5")] == ["final.h5"]
    for d, name in ((out / "snapshots", "snap-00000"), (out / "snapshots", "snap-00001"), (out, "final")):
        stem = d / "contacts" / name
        with h5py.File(f"{stem}.contacts.h5") as f:
            pairs, _ = checkpoint.read_state(f"{d / name}.h5", pairs=True)
            P = len(pairs["id_i"])
            assert int(f.attrs["n_contacts"]) == P and f["cells/F_n"].shape == (2 * P,)
        assert ET.parse(f"{stem}.contacts.xmf").getroot().find("Domain/Grid/Topology").get("TopologyType") == "Polyline"
    cols = ET.parse(out / "snapshots" / "series.xmf").getroot().findall("Domain/Grid")
    assert [c.get("Name") for c in cols] == ["series", "contacts"]
    assert [g.get("Name") for g in cols[1].findall("Grid")] == ["snap-00000.contacts", "snap-00001.contacts"]
    assert [g.find("Time").get("Value") for g in cols[1]] == [g.find("Time").get("Value") for g in cols[0]]
    capsys.readouterr()
    assert main(["info", str(out / "final.h5")]) == 0
    text = capsys.readouterr().out
    assert "kind final" in text and "step 20000" in text and "contact list:" in text and "mu 0.5" in text
    assert main(["export", str(out / "final.h5"), "--format", "xyz"]) == 0
    assert (out / "final.xyz").read_text().splitlines()[0].strip() == str(attrs["n"])


def test_info_into_a_closed_pipe_stops_quietly():
    """`mpdem info FILE | head -1`: the reader leaves after one line; no traceback, exit 0."""
    import subprocess
    import sys
    from helpers import child_env
    src = os.path.join(os.path.dirname(__file__), "data", "state_v2.h5")
    p = subprocess.run(f"'{sys.executable}' -m mpdem info '{src}' | head -c 10", shell=True, capture_output=True,
                       text=True, env=child_env(), timeout=120, executable="/bin/bash")
    assert len(p.stdout) == 10 and p.stderr == "", p.stderr
    p = subprocess.run(f"set -o pipefail; '{sys.executable}' -m mpdem info '{src}' | head -c 10 >/dev/null",
                       shell=True, capture_output=True, text=True, env=child_env(), timeout=120,
                       executable="/bin/bash")
    assert p.returncode == 0, p.stderr


def test_a_new_sidecar_is_one_entry_in_the_table(tmp_path, monkeypatch):
    """A file added to ``export.SIDECARS`` alone is written beside every snapshot and final.h5."""
    from mpdem.io import export
    seen = []

    def steps(path, run_dir, final):
        seen.append((os.path.basename(path), final))
        export.write_atomic(path[:-len(".h5")] + ".step", [f"{checkpoint.read_attrs(path)['step']}\n"])
    monkeypatch.setattr(export, "SIDECARS", export.SIDECARS + (export.Sidecar("step", "the step", steps),))
    out = tmp_path / "side"
    assert main(["run", *sets("output.snapshot_every=10000"), "--out", str(out), "--quiet"]) == 3
    assert seen == [("snap-00000.h5", False), ("snap-00001.h5", False), ("final.h5", True)]
    assert (out / "snapshots" / "snap-00001.step").read_text() == "20000\n"
    assert (out / "final.xmf").exists() and (out / "snapshots" / "series.xmf").exists()


def test_a_missing_file_or_a_run_directory_is_named_before_hdf5_tries_it(tmp_path):
    """``mpdem info``, ``export`` and every reader: one short line, not HDF5's error stack."""
    for read in (checkpoint.read_state, checkpoint.read_attrs):
        with pytest.raises(StateFileError, match=r"nope\.h5: no such file$"):
            read(str(tmp_path / "nope.h5"))
        with pytest.raises(StateFileError, match=r"a directory, not a state file \(a finished run's is .*final\.h5\)"):
            read(str(tmp_path))
