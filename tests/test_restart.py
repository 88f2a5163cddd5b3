"""Exact restart (ARCHITECTURE.md, "Invariants"): a run split into segments, on any rank counts,
gives the digest of the straight run; signals, wall time and a crash in the
middle of a checkpoint write lose nothing.

The pile (200 spheres, K0 = 5, 5 x 5 box) lands, bounces and converges at a
stop rule with a 10-sample window; checkpoints at K = 40000 steps fall before
convergence (about 90 000 steps), so the window straddles each restart.

By default (``pytest``) the straight run, its restart on 2 ranks, the wall-time stops (three
segments on one rank) and the stricter stop rule; the rest (3 ranks, a final state, the signals,
the kill in a checkpoint write) takes minutes and is marked ``validation`` (``pytest -m
validation``, ``make test``).
"""
import json
import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest

from helpers import child_env, mpdem, mpdem_argv

K = 40000
PILE = ["box.L_x=5.0", "box.L_y=5.0", "pour.N=200", "pour.phi_i=0.3", "pour.K0=5.0",
        "stop.sample_interval=0.01", "stop.window=0.1", "stop.E_stop=0.05",
        "run.max_steps=400000", f"output.checkpoint_every={K}", "output.progress_every=2000"]


def sets(*extra):
    return [a for kv in PILE + list(extra) for a in ("--set", kv)]


def digest(path):
    return mpdem("info", "--digest", path, check=0).stdout.strip()


def summary(run):
    return json.loads((run / "summary.json").read_text())


def rewind(src, dst, keep):
    """A copy of run directory src as it was when checkpoint number ``keep`` was the newest."""
    shutil.copytree(src, dst)
    for p in (dst / "checkpoints").glob("ckpt-*.h5"):
        if int(p.stem.split("-")[1]) > keep:
            p.unlink()
    for name in ("final.h5", "final.xmf", "summary.json"):
        (dst / name).unlink(missing_ok=True)
    return dst


def thermo(run):
    """Thermo rows without the wall-clock and rebuild columns."""
    return [ln.split(",")[:9] for ln in (run / "thermo.csv").read_text().splitlines()]


# seconds the straight run's process took (set by the fixture): wall-time limits are fractions of it
STRAIGHT_SECONDS = {}


@pytest.fixture(scope="module")
def straight(tmp_path_factory):
    """The straight run on one rank: (run dir, digest, converged step)."""
    run = tmp_path_factory.mktemp("straight") / "run"
    t = time.monotonic()
    mpdem("run", *sets(), "--out", run, "--quiet", check=0)
    STRAIGHT_SECONDS["run"] = time.monotonic() - t
    s = summary(run)
    assert s["converged"] and s["steps"] > 2 * K, "the pile must converge after two checkpoints"
    assert digest(run / "final.h5") == s["digest"]
    return run, s["digest"], s["steps"]


@pytest.mark.parametrize("n_first,n_second", [(1, 2), pytest.param(3, 1, marks=pytest.mark.validation)])
def test_restart_on_other_rank_counts_gives_the_straight_digest(straight, tmp_path, n_first, n_second):
    run, ref, steps = straight
    first = tmp_path / "first"
    if n_first == 1:
        first = run
        more = ()
    else:
        # the first segment alone on n_first ranks, to the checkpoint at step K: the restart on
        # n_second ranks reaches the straight digest only if that segment had the one rank's bits
        mpdem("run", *sets(f"run.max_steps={K}"), "--out", first, "--quiet", n=n_first, check=3)
        more = ("--set", "run.max_steps=400000")
    again = rewind(first, tmp_path / "again", keep=0)   # the checkpoint at step K
    mpdem("restart", again, *more, "--quiet", n=n_second, check=0)
    s = summary(again)
    assert (s["digest"], s["steps"], s["segments"]) == (ref, steps, 2)
    # a restart leaves config.toml as it was, byte for byte (derived defaults stay marked), but what it was told
    before, after = ((d / "config.toml").read_text().splitlines() for d in (first, again))
    assert [(a, b) for a, b in zip(before, after) if a != b] == ([(f"max_steps = {K}", "max_steps = 400000")]
                                                                 if more else [])
    if n_second == 1:   # the counters add up over segments: all here are the first segment's
        import h5py
        with h5py.File(again / "checkpoints" / "ckpt-00000.h5") as f:
            rs = json.loads(f.attrs["run_state"])["history"]
        assert (s["migrated"], s["rebalances"]) == (rs["migrated"], rs["rebalances"])
        assert rs["migrated"] > 0
    assert thermo(again) == thermo(run)                  # the table continues, no row twice
    # file numbering continues: the restarted run wrote checkpoint 1 at step 2K again
    assert (again / "checkpoints" / "ckpt-00001.h5").exists()


def flatten_run_state(path):
    """Rewrite the ``run_state`` of state file ``path`` as mpdem wrote it before its namespaces (issue 24):
    one JSON object with the fields of every record, in the records' order."""
    import h5py
    with h5py.File(path, "r+") as f:
        flat = {}
        for record in json.loads(f.attrs["run_state"]).values():
            flat.update(record)
        f.attrs["run_state"] = json.dumps(flat)
    return flat


def test_run_state_keeps_each_record_under_its_name_and_reads_the_flat_layout():
    from mpdem.initial import Pile
    from mpdem.driver.runstate import History, RunState
    from mpdem.driver.schedule import CheckpointRecord, SnapshotRecord, StopRecord
    rec = RunState(History(3, 12.5, 40, 0.01, 7, 2), Pile(4.5, 3.75, 20.0), StopRecord([0.5, 0.25], "translational"),
                   CheckpointRecord(5), SnapshotRecord(9))
    text = rec.dumps()
    assert list(json.loads(text)) == ["history", "pile", "stop", "checkpoints", "snapshots"]
    assert RunState.loads(text) == rec
    flat = {}
    for part in json.loads(text).values():
        flat.update(part)
    assert RunState.loads(json.dumps(flat)) == rec
    # a field of one record does not reach another that has the same name
    clash = json.loads(text)
    clash["pile"]["n_checkpoints"] = 99
    assert RunState.loads(json.dumps(clash)).checkpoints.n_checkpoints == 5
    assert RunState.loads("{}") == RunState()


def test_a_checkpoint_with_the_flat_run_state_of_earlier_versions_restarts_exactly(straight, tmp_path):
    """A state file written before run_state had a namespace per record (issue 24) still restarts to the
    straight run: segments, file numbers and the stop-rule window come back from its flat record."""
    run, ref, steps = straight
    old = rewind(run, tmp_path / "old", keep=0)
    flat = flatten_run_state(old / "checkpoints" / "ckpt-00000.h5")
    assert flat["n_checkpoints"] == 1 and flat["segments"] == 1 and len(flat["stop_samples"]) > 0
    mpdem("restart", old, "--quiet", check=0)
    s = summary(old)
    assert (s["digest"], s["steps"], s["segments"]) == (ref, steps, 2)
    assert thermo(old) == thermo(run)
    assert (old / "checkpoints" / "ckpt-00001.h5").exists()


@pytest.mark.validation
def test_restart_from_a_final_state_with_more_steps(straight, tmp_path):
    """2 ranks stop at run.max_steps = K (exit 3); one rank continues from the final state with a larger
    cap (the restarts across rank counts from a checkpoint are the test above's)."""
    run, ref, steps = straight
    short = tmp_path / "short"
    mpdem("run", *sets(f"run.max_steps={K}"), "--out", short, "--quiet", n=2, check=3)
    assert summary(short)["status"] == "max_steps"
    p = mpdem("restart", short, n=2, check=3)                     # nothing to do at the cap
    assert "raise it with --set run.max_steps" in p.stdout + p.stderr
    before = (short / "config.toml").read_text().splitlines()
    mpdem("restart", short, "--set", "run.max_steps=400000", "--quiet", check=0)
    assert summary(short)["digest"] == ref
    after = (short / "config.toml").read_text().splitlines()
    assert [(a, b) for a, b in zip(before, after) if a != b] == [(f"max_steps = {K}", "max_steps = 400000")]
    assert len(before) == len(after)
    p = mpdem("restart", short, check=0)                          # finished: nothing to do
    assert "nothing to do" in p.stdout


def test_a_converged_run_goes_on_under_a_stricter_stop_rule(straight, tmp_path):
    """restart --set stop.E_stop=... on a converged run continues it from final.h5 until
    the new rule holds (without a stop.* change there is nothing to do)."""
    run, ref, steps = straight
    more = tmp_path / "more"
    shutil.copytree(run, more)
    p = mpdem("restart", more, "--set", "stop.E_stop=0.005", check=0)
    assert "going on under the changed stop rule (stop.E_stop = 0.005)" in p.stdout
    s = summary(more)
    assert s["converged"] and s["steps"] > steps and s["segments"] == 2 and s["digest"] != ref
    assert s["E_k_per_particle"] < summary(run)["E_k_per_particle"]


def _pids_of(run, n):
    """PIDs of the n rank processes of the run writing to ``run``."""
    out = subprocess.run(["pgrep", "-f", f"mpdem run .*--out {run}"], capture_output=True, text=True).stdout
    pids = [int(p) for p in out.split() if int(p) != os.getpid()]
    # the mpiexec process matches too: keep the python ones
    def program(p):
        return Path(f"/proc/{p}/cmdline").read_bytes().decode(errors="replace").split("\0")[0]
    return [p for p in pids if "python" in program(p)][:n]


def _wait_for(path, text, timeout=120):
    t = time.monotonic()
    while time.monotonic() - t < timeout:
        if path.exists() and text in path.read_text():
            return
        time.sleep(0.2)
    raise AssertionError(f"{text!r} never appeared in {path}")


@pytest.mark.validation
@pytest.mark.parametrize("sig,n,rank", [(signal.SIGUSR1, 2, 1), (signal.SIGTERM, 1, 0), (signal.SIGINT, 1, 0)])
def test_signal_on_one_rank_checkpoints_and_restart_matches(straight, tmp_path, sig, n, rank):
    run, ref, steps = straight
    out = tmp_path / "sig"
    proc = subprocess.Popen(mpdem_argv("run", *sets(), "--out", out, n=n), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=child_env())
    _wait_for(out / "log.txt", "step      2000")
    pids = _pids_of(out, n)
    assert len(pids) == n
    os.kill(sorted(pids)[rank], sig)      # one rank only; the others must agree
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 75, stdout[-2000:] + stderr[-2000:]
    assert f"signal {signal.Signals(sig).name}" in (out / "log.txt").read_text()
    assert not (out / "final.h5").exists()
    mpdem("restart", out, "--quiet", n=2, check=0)
    s = summary(out)
    assert (s["digest"], s["steps"]) == (ref, steps)


def test_a_second_ctrl_c_stops_at_once_and_other_signals_only_add_up():
    """Ctrl-C once while stepping is a stop with a checkpoint (above); twice, KeyboardInterrupt at once
    (``mpdem: interrupted``), for a user who will not wait for the checkpoint. SIGTERM and SIGUSR1 again
    only record themselves."""
    from types import SimpleNamespace
    from mpdem.driver.simulation import STOP_SIGNALS, Run
    assert signal.SIGINT in STOP_SIGNALS
    run = SimpleNamespace(signals=[])
    for sig in (signal.SIGTERM, signal.SIGUSR1, signal.SIGTERM, signal.SIGINT):
        Run._on_stop_signal(run, sig, None)
    assert run.signals == [signal.SIGTERM, signal.SIGUSR1, signal.SIGTERM, signal.SIGINT]
    with pytest.raises(KeyboardInterrupt):
        Run._on_stop_signal(run, signal.SIGINT, None)


@pytest.mark.validation
def test_ctrl_c_in_python_raises_keyboardinterrupt_after_the_checkpoint(straight, tmp_path):
    """``mpdem.run`` stopped by SIGINT (a notebook's interrupt): the checkpoint is written, then Python's
    KeyboardInterrupt (a loop over runs stops too), and ``mpdem.restart`` ends on the straight run's bits."""
    import sys
    run, ref, steps = straight
    out = tmp_path / "py"
    items = [kv.split("=", 1) for kv in PILE + ["output.progress_every=2000"]]
    script = (f"import mpdem, tomllib\n"
              f"cfg = mpdem.load_config(**{{k: tomllib.loads('v = ' + v)['v'] for k, v in {items!r}}})\n"
              f"try:\n    mpdem.run(cfg, {str(out)!r})\n    print('returned')\n"
              f"except KeyboardInterrupt as e:\n    print('KeyboardInterrupt:', e)\n")
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=child_env())
    _wait_for(out / "log.txt", "step      2000")
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=300)
    assert "KeyboardInterrupt:" in stdout and "with a checkpoint" in stdout, stdout + stderr
    assert "mpdem: SIGINT: a checkpoint" in stderr
    assert "stop: signal SIGINT" in (out / "log.txt").read_text() and not (out / "final.h5").exists()
    mpdem("restart", out, "--quiet", check=0)
    assert (summary(out)["digest"], summary(out)["steps"]) == (ref, steps)


@pytest.mark.validation
def test_a_run_started_with_sigint_ignored_keeps_ignoring_it(tmp_path):
    """A background job of a script starts with SIGINT ignored: the terminal's Ctrl-C must not stop it."""
    out = tmp_path / "bg"
    # a stop rule that never holds: the run is still stepping when the signals come
    proc = subprocess.Popen(mpdem_argv("run", *sets("stop.E_stop=1e-30"), "--out", out), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=child_env(),
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    _wait_for(out / "log.txt", "step      2000")
    proc.send_signal(signal.SIGINT)
    time.sleep(3)
    assert proc.poll() is None, "SIGINT, ignored by the parent, stopped the run"
    proc.send_signal(signal.SIGTERM)
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 75 and "signal SIGTERM" in (out / "log.txt").read_text(), stdout + stderr


def test_walltime_stops_with_a_checkpoint_and_restart_matches(straight, tmp_path):
    run, ref, steps = straight
    out = tmp_path / "wall"
    # a quarter of the straight run's time: the limit falls inside the run however fast the machine is, also
    # when the straight run was timed under more load than this one (tests share the cores with pytest-xdist)
    limit = max(1.0, 0.25 * STRAIGHT_SECONDS["run"])
    t = time.monotonic()
    mpdem("run", *sets(), "--out", out, "--walltime", f"{limit:.2f}", "--walltime-margin", "0", "--quiet", check=75)
    assert time.monotonic() - t < limit + 30     # stopped at the limit, not at the end of the run
    log = (out / "log.txt").read_text()
    assert "stop: the wall time" in log and "restart" in log
    # a second short segment, then the rest: three segments in all
    mpdem("restart", out, "--walltime", "4", "--walltime-margin", "0", "--quiet")
    mpdem("restart", out, "--quiet", check=0)
    s = summary(out)
    assert (s["digest"], s["steps"]) == (ref, steps)
    assert s["segments"] >= 2


@pytest.mark.validation
def test_kill_during_checkpoint_write_then_restart(straight, tmp_path):
    """SIGKILL in the middle of writing the second checkpoint: no file under its real
    name is half-written, and the restart falls back to the first and finishes right."""
    run, ref, steps = straight
    out = tmp_path / "killed"
    p = mpdem("run", *sets(), "--out", out, "--quiet", n=2, env={"MPDEM_TEST_KILL_IN_WRITE": "2"})
    assert p.returncode != 0
    names = sorted(q.name for q in (out / "checkpoints").iterdir())
    assert names == ["ckpt-00000.h5", "ckpt-00001.h5.tmp"], names
    mpdem("restart", out, "--quiet", n=2, check=0)
    assert summary(out)["digest"] == ref
    assert not list((out / "checkpoints").glob("*.tmp"))


def test_one_writer_per_run_directory(straight, tmp_path):
    """A second restart of a run directory while the first runs is refused with one line naming the
    holder; the first is unharmed (the straight digest). A lock left by a process that died is taken
    over, and said (issue 26)."""
    run, ref, steps = straight
    again = rewind(run, tmp_path / "again", keep=0)
    first = subprocess.Popen(mpdem_argv("restart", again, "--quiet"), env=child_env(), stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    lock = again / ".lock"
    t = time.monotonic()
    while not (lock.exists() and lock.read_text().strip()) and time.monotonic() - t < 60:
        time.sleep(0.05)
    assert f"pid {first.pid}" in lock.read_text()
    p = mpdem("restart", again, check=1)
    line = p.stderr.strip()
    assert len(line.splitlines()) == 1 and f"in use by pid {first.pid} on " in line and " since " in line
    # reading is no writing: analyze and info need no lock
    mpdem("info", str(again / "checkpoints" / "ckpt-00000.h5"), check=0)
    out, err = first.communicate(timeout=300)
    assert first.returncode == 0, err
    assert summary(again)["digest"] == ref and lock.read_text() == ""
    # a dead holder's lock (its file says who, no process holds it): taken over, with a line
    stale = rewind(run, tmp_path / "stale", keep=0)
    (stale / ".lock").write_text("pid 999999 on elsewhere since 2026-01-01 00:00:00\n")
    p = mpdem("restart", stale, check=0)
    assert "taking over the lock of pid 999999 on elsewhere" in p.stdout + p.stderr
    assert summary(stale)["digest"] == ref


def test_a_run_whose_epsilon_does_not_survive_gamma_n_restarts(tmp_path):
    """epsilon = 0.1 comes back from its gamma_n as 0.09999999999999998: config.toml (epsilon and the
    gamma_n made from it) must still read as the checkpoint's config, and the restart give the straight
    digest (before 2026-11-27, late night, such a restart was refused: "does not match")."""
    small = ["box.L_x=4", "box.L_y=4", "pour.N=40", "contact.epsilon=0.1", "output.checkpoint_every=150"]
    args = [a for kv in small for a in ("--set", kv)]
    mpdem("run", *args, "--set", "run.max_steps=300", "--out", tmp_path / "straight", "--quiet", check=3)
    mpdem("run", *args, "--set", "run.max_steps=150", "--out", tmp_path / "split", "--quiet", check=3)
    mpdem("restart", tmp_path / "split", "--set", "run.max_steps=300", "--quiet", check=3)
    assert summary(tmp_path / "split")["digest"] == summary(tmp_path / "straight")["digest"]
    assert summary(tmp_path / "split")["segments"] == 2
