"""analysis/sweeps/paper/queue.sh: the campaign's jobs in order, JOBS at a time, a job after the one it waits
for, and a signal to the queue passed to every running job's processes (the jobs here are stand-ins:
QUEUE_DEFS)."""
import os
import signal
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
QUEUE = os.path.join(ROOT, "analysis", "sweeps", "paper", "queue.sh")

# each job appends "start NAME t" and "end NAME t" to a journal; its run (a python under a nested bash, as a
# ladder's run is under ladder.sh) says "ready NAME" once it answers SIGTERM, which it does as a run does:
# it takes a while (its checkpoint), then says "term NAME" and exits with 75
DEFS = """
JOB_LIST=(
  "a|first|job a 1.0|"
  "b|second|job b 2.5|"
  "c|waits for b|job c 0.2|b"
  "d|fourth|job d 0.2|"
)
job() {{
    echo "start $1 $(date +%s.%N)" >> {journal}
    bash -c '"$0" "$@"; rc=$?; exit $rc' {py} {sleeper} {journal} "$1" "$2"
    local rc=$?
    echo "end $1 $(date +%s.%N)" >> {journal}
    return $rc
}}
"""
SLEEPER = """import signal, sys, time
journal, name, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
def term(*a):
    time.sleep(1.0)
    open(journal, "a").write(f"term {{name}}\\n")
    sys.exit(75)
signal.signal(signal.SIGTERM, term)
open(journal, "a").write(f"ready {{name}}\\n")
time.sleep(seconds)
"""


def _queue(tmp_path, env_extra=None, **popen):
    journal = tmp_path / "journal"
    defs = tmp_path / "defs.sh"
    sleeper = tmp_path / "sleeper.py"
    sleeper.write_text(SLEEPER.format())
    defs.write_text(DEFS.format(journal=journal, py=sys.executable, sleeper=sleeper))
    env = dict(os.environ, QUEUE_DEFS=str(defs), LOGS=str(tmp_path / "logs"), PY=sys.executable)
    env.update(env_extra or {})
    return subprocess.Popen(["bash", QUEUE], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, **popen), journal


def _events(journal):
    out = []
    for line in journal.read_text().splitlines():
        kind, name, *t = line.split()
        out.append((kind, name, float(t[0]) if t else None))
    return out


def test_the_jobs_run_in_order_two_at_a_time_and_one_waits_for_its_own(tmp_path):
    p, journal = _queue(tmp_path, {"JOBS": "2"})
    out, _ = p.communicate(timeout=60)
    assert p.returncode == 0, out
    ev = _events(journal)
    started = [ln.split()[4] for ln in out.splitlines() if ln.startswith("queue: ") and " start " in ln]
    assert started == ["a", "b", "d", "c"]                             # d took a's slot while c waited for b
    t = {(k, n): v for k, n, v in ev}
    assert t[("start", "d")] < t[("end", "b")] <= t[("start", "c")]
    for n in "abcd":                                                  # never more than two at once
        inside = [m for m in "abcd" if t[("start", m)] <= t[("start", n)] < t[("end", m)]]
        assert len(inside) <= 2, (n, inside)
    assert "nothing more to start" in out
    assert "ended with exit status 0" in (tmp_path / "logs" / "a.log").read_text()


def test_only_runs_the_named_jobs(tmp_path):
    p, journal = _queue(tmp_path, {"ONLY": "d"})
    out, _ = p.communicate(timeout=60)
    assert p.returncode == 0, out
    assert [n for k, n, _ in _events(journal) if k == "start"] == ["d"]


def test_a_signal_reaches_every_running_job_and_nothing_more_starts(tmp_path):
    p, journal = _queue(tmp_path, {"JOBS": "2"})
    deadline = time.time() + 30
    while time.time() < deadline and not (journal.exists() and journal.read_text().count("ready") >= 2):
        time.sleep(0.05)                                              # both sleepers' handlers are set
    p.send_signal(signal.SIGTERM)
    out, _ = p.communicate(timeout=30)
    ev = _events(journal)                                             # read once the queue has ended:
    assert ("term", "a", None) in ev and ("term", "b", None) in ev, (ev, out)   # both runs' checkpoints
    assert not any(k == "start" and n in ("c", "d") for k, n, _ in ev)
    assert "stopped by a signal" in out
    assert "stopping" in out


def test_bad_settings_are_refused_before_any_job(tmp_path):
    p, journal = _queue(tmp_path, {"JOBS": "two"})
    out, _ = p.communicate(timeout=30)
    assert p.returncode == 2 and "JOBS=two" in out and not journal.exists()
    p, journal = _queue(tmp_path, {"QUEUE_DEFS": str(tmp_path / "nothing.sh")})
    out, _ = p.communicate(timeout=30)
    assert p.returncode == 2 and "cannot be read" in out and not journal.exists()
