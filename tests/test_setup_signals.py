"""SIGTERM and SIGINT during a new run's set-up (issue 57, item 6): honoured within seconds, with
one line, exit status 128 + the signal, no traceback and no state file (``mpdem.watch``)."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def start(tmp_path, sets, env=None):
    """``python -m mpdem run`` in a process of its own, with a progress line after every short call."""
    args = [sys.executable, "-m", "mpdem", "run", "--out", str(tmp_path / "run")]
    for s in sets + ["run.max_steps=10"]:
        args += ["--set", s]
    e = dict(os.environ, PYTHONPATH=str(ROOT / "src"), MPDEM_SETUP_PROGRESS="0", MPDEM_BED_CACHE=str(tmp_path / "beds"),
             **(env or {}))
    return subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=e, cwd=tmp_path)


def stop_at(proc, marker, sig, limit=120):
    """Send ``sig`` once a stdout line starts with ``marker`` (work under way: the kernels compiled);
    the seconds from the signal to the exit, and stdout and stderr."""
    t_end = time.monotonic() + limit
    seen = []
    for line in proc.stdout:
        seen.append(line)
        if line.startswith(marker):
            break
        assert time.monotonic() < t_end, "".join(seen)
    else:
        pytest.fail(f"no line {marker!r} before the run ended: {''.join(seen)}{proc.stderr.read()}")
    t = time.monotonic()
    proc.send_signal(sig)
    try:
        out, err = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail(f"{sig.name} not honoured within 30 s")
    return time.monotonic() - t, "".join(seen) + out, err


def assert_clean_stop(tmp_path, seconds, err, rc, sig, phase):
    assert seconds < 5.0, f"{seconds:.1f} s from {sig.name} to the exit"
    assert rc == 128 + sig
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert lines[-1].startswith(f"mpdem: stopped by {sig.name} during {phase}, before the first step: nothing "
                                f"was saved")
    # nothing under a state file's name, and no bed kept from a bed not finished
    assert not list((tmp_path / "run").rglob("*.h5"))
    if phase == "the making of the bed":
        assert not (tmp_path / "beds").exists() or not list((tmp_path / "beds").glob("bed-*.npz"))
    assert f"stopped by {sig.name}" in (tmp_path / "run" / "log.txt").read_text()


def test_sigterm_while_the_bed_is_made_stops_the_run_within_seconds(tmp_path):
    # a 24 d x 24 d bed: 4608 spheres settled for 40 tau, minutes of work in calls of about a second
    proc = start(tmp_path, ["box.L_x=24.0", "box.L_y=24.0", "pour.N=100"])
    seconds, out, err = stop_at(proc, "bed: settling", signal.SIGTERM)
    assert_clean_stop(tmp_path, seconds, err, proc.returncode, signal.SIGTERM, "the making of the bed")


def test_sigint_during_the_insertion_stops_the_run_within_seconds(tmp_path):
    # a small bed, made quickly, under a pour of 3e6 spheres (tens of seconds of insertion)
    proc = start(tmp_path, ["box.L_x=6.0", "box.L_y=6.0", "bed.settle_time=1.0", "pour.N=3000000"])
    seconds, out, err = stop_at(proc, "pour: ", signal.SIGINT)
    assert_clean_stop(tmp_path, seconds, err, proc.returncode, signal.SIGINT, "the pour's insertion")


GUARDED = """
import os, signal, sys, time
from mpdem import watch
from mpdem.watch import Watch
watch.ENDS_PROCESS = True       # as the command line's process
with Watch(print) as w:
    w.begin("a long compile")
    print("ready", flush=True)
    t = time.monotonic()
    while time.monotonic() - t < 30:      # Python work without a look, as numba's compiler is
        sum(range(1000))
print("not stopped")
"""


def test_a_stop_that_no_look_takes_ends_the_process_after_the_grace(tmp_path):
    from mpdem.watch import GRACE
    proc = subprocess.Popen([sys.executable, "-c", GUARDED], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, PYTHONPATH=str(ROOT / "src")))
    assert proc.stdout.readline().strip() == "ready"
    t = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=30)
    seconds = time.monotonic() - t
    assert GRACE <= seconds < GRACE + 2.0
    assert proc.returncode == 128 + signal.SIGTERM and "not stopped" not in out
    assert err.strip() == ("mpdem: stopped by SIGTERM during a long compile, before the first step: nothing was saved; "
                           "start the run again (with --force to reuse its directory)")


def test_the_watch_says_a_line_when_its_time_has_come_and_stops_on_a_stop_signal():
    from mpdem.errors import Interrupted
    from mpdem.watch import Watch
    now, lines, signals = [0.0], [], []
    w = Watch(lines.append, signals=signals, every=20.0, clock=lambda: now[0])
    w.begin("the pour's insertion")
    for t in range(0, 61, 2):       # a look every 2 s of work
        now[0] = float(t)
        w(lambda: f"placed at {now[0]:.0f}")
    assert lines == ["placed at 20 (20 s)", "placed at 40 (40 s)", "placed at 60 (60 s)"]
    signals.append(int(signal.SIGUSR1))      # a batch system's warning: the first step's checkpoint
    w("ignored")
    signals.append(int(signal.SIGINT))
    with pytest.raises(Interrupted, match="^stopped by SIGINT during the pour's insertion, before the first step") as e:
        w("not said")
    assert e.value.status == 130 and e.value.agreed


def test_the_set_up_leaves_a_sigint_its_parent_ignored_ignored():
    """A background job of a script starts with SIGINT ignored: the terminal's Ctrl-C must not stop its
    set-up (the stepping run keeps it ignored too: tests/test_restart.py); SIGTERM is still the set-up's."""
    from mpdem.watch import Watch
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        w = Watch(lambda msg: None).__enter__()
        try:
            assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN
            assert signal.getsignal(signal.SIGTERM) == w._record
        finally:
            w.__exit__()
        assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, old)
