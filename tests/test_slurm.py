"""The job templates as shipped, on a real Slurm that this test starts on this machine
(tools/local-slurm.sh: munged, slurmctld and slurmd, one node with this machine's cores).

A chain submitted as jobs/README.md shows it, from a directory outside the repository,
with only the time and task count on the sbatch command line: at least two segments
(exit 75, resubmitted, then 0) and the straight run's digest. The first job gets Slurm's
early-warning signal from the test (scancel --signal=USR1 --batch), so that the chain has
two segments on a machine of any speed. Then a two-row sweep array
that finishes. Where Slurm cannot run here (not root, no slurm-wlm), the test says why.
"""
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from helpers import mpdem

# minutes of real jobs: run with -m validation (make test-validation), not by default
pytestmark = [pytest.mark.slurm, pytest.mark.validation]
ROOT = Path(__file__).resolve().parents[1]
TOOL = ROOT / "tools" / "local-slurm.sh"
MPIEXEC = Path(sys.executable).parent / "mpiexec"
# a pile that settles in about 47 s of 2 ranks on the 2-core development VM (488 000 steps; 600 spheres
# took 104 s); later segments of about 65 s (a 2-minute job less a 50 s margin, MPDEM_MARGIN) if the run
# outlasts the second
PILE = "pour.N=300 box.L_x=5 box.L_y=5 run.max_steps=2000000 output.progress_every=50000"
MARGIN = "50"
# the last line of a jobs.log that ends a chain
ENDS = ("finished (exit", "error:", "stop:", "not converged:")
SMALL = "pour.N=150 box.L_x=4 box.L_y=4 run.max_steps=2000000 output.progress_every=50000"


@pytest.fixture(scope="module")
def slurm(tmp_path_factory):
    """A running single-node Slurm: the environment to talk to it (SLURM_CONF)."""
    # os.environ, not the C environment: an earlier test may have made this process an MPI singleton
    why = subprocess.run(["bash", str(TOOL), "check"], capture_output=True, text=True, env=dict(os.environ))
    if why.returncode != 0:
        pytest.skip(f"no real Slurm here: {why.stdout.strip() or why.stderr.strip()} "
                    f"(make test installs slurm-wlm and munge as root on Debian)")
    d = tmp_path_factory.mktemp("slurm")
    p = subprocess.run(["bash", str(TOOL), "start", str(d)], capture_output=True, text=True, timeout=180,
                       env=dict(os.environ))
    assert p.returncode == 0, p.stdout + p.stderr
    env = {k: v for k, v in os.environ.items() if not k.startswith(("MPDEM_", "SLURM_", "OMPI_", "PMI"))}
    env["SLURM_CONF"] = str(d / "slurm.conf")
    try:
        yield env
    finally:
        subprocess.run(["bash", str(TOOL), "stop", str(d)], capture_output=True, timeout=120, env=dict(os.environ))


def jobs_log_until(path, words, timeout, env):
    """The lines of a jobs.log once its last line holds one of ``words`` and no job is queued."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        lines = path.read_text().splitlines() if path.exists() else []
        queued = subprocess.run(["squeue", "-h"], env=env, capture_output=True, text=True).stdout.strip()
        if lines and any(w in lines[-1] for w in words) and not queued:
            return lines
        time.sleep(2)
    q = subprocess.run(["squeue"], env=env, capture_output=True, text=True).stdout
    raise AssertionError(f"timed out; queue:\n{q}\njobs.log:\n" + (path.read_text() if path.exists() else "(none)"))


def digest(path):
    return mpdem("info", "--digest", path, timeout=120, check=0).stdout.strip()


def test_a_chain_as_shipped_converges_over_segments_bit_identical(slurm, tmp_path):
    sub = tmp_path / "elsewhere"                  # not the repository root
    sub.mkdir()
    env = dict(slurm, MPDEM_RUN_DIR="runs/chain", MPDEM_SET=PILE, MPDEM_MARGIN=MARGIN)
    p = subprocess.run(["sbatch", "--time=2", "--ntasks=2", str(ROOT / "jobs/slurm/chain.sbatch")], cwd=sub,
                       env=env, capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    job = p.stdout.split()[-1]
    # meanwhile, the straight run on one rank
    ref = {}
    straight = threading.Thread(target=lambda: ref.update(p=mpdem(
        "run", "--out", tmp_path / "straight", "--quiet", *sum((["--set", kv] for kv in PILE.split()), []),
        timeout=1800)))
    straight.start()
    # the first job gets Slurm's early-warning signal by hand once its run is pouring (every rank
    # has its handlers then), the path of --signal=B:USR1@60: two segments at least, whatever
    # the machine's speed or clock
    mlog, jlog = sub / "runs/chain/log.txt", sub / "runs/chain/jobs.log"
    t0 = time.monotonic()
    while not (mlog.exists() and "\npour: " in mlog.read_text()):
        lines = jlog.read_text().splitlines() if jlog.exists() else []
        ended = bool(lines) and any(w in lines[-1] for w in ENDS)
        assert time.monotonic() - t0 < 600 and not ended, "the first segment did not pour:\n" + (
            jlog.read_text() if jlog.exists() else "(no jobs.log)") + (mlog.read_text() if mlog.exists() else "")
        time.sleep(0.2)
    sig = subprocess.run(["scancel", "--signal=USR1", "--batch", job], env=slurm, capture_output=True, text=True)
    # (it may have stopped on its own meanwhile)
    assert sig.returncode == 0 or "resubmitting" in jlog.read_text(), sig.stderr
    log = jobs_log_until(jlog, ENDS, 1800, slurm)
    straight.join()
    assert ref["p"].returncode == 0, ref["p"].stderr
    text = "\n".join(log)
    segs = [ln for ln in log if ": segment " in ln]
    assert len(segs) >= 2, text
    assert "launcher: srun --mpi=pmix (Slurm offers pmix" in text
    resub = [ln for ln in log if "checkpointed, resubmitting (mpdem exit 75" in ln]
    assert len(resub) == len(segs) - 1 and log[-1].endswith("finished (exit 0)"), text
    # each resubmission asked for what the first job got on its command line
    assert all("--ntasks=2" in ln and "--time=00:02:00" in ln for ln in resub), text
    run = sub / "runs/chain"
    assert (run / "summary.json").exists(), text + "\n" + mlog.read_text()
    s = json.loads((run / "summary.json").read_text())
    assert s["converged"] and s["segments"] == len(segs)
    assert digest(run / "final.h5") == digest(tmp_path / "straight" / "final.h5") == s["digest"]
    # no launcher noise for the planned stops, in any job's output
    out = "\n".join(f.read_text() for f in sub.glob("mpdem-chain-*.out"))
    assert "Exited with exit code 75" not in out and "non-zero" not in out


def test_a_sweep_array_finishes(slurm, tmp_path):
    table = tmp_path / "two.tsv"
    table.write_text("mu\tseed\n0.5\t1\n0.5\t2\n")
    env = dict(slurm, MPDEM_SWEEP=str(table), MPDEM_SWEEP_DIR="runs/sweep", MPDEM_SET=SMALL)
    p = subprocess.run(["sbatch", "--array=1-2", "--time=3", "--ntasks=1", str(ROOT / "jobs/slurm/sweep.sbatch")],
                       cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    array = p.stdout.split()[-1]
    for row, name in ((1, "mu0.5_s1"), (2, "mu0.5_s2")):
        run = tmp_path / "runs/sweep" / name
        log = jobs_log_until(run / "jobs.log", ENDS, 900, slurm)
        assert log[-1].endswith("finished (exit 0)"), "\n".join(log)
        assert f" job {array}_{row} (id " in log[0]            # named as its output file
        resub = [ln for ln in log if "resubmitting" in ln]
        assert all(ln.count("--ntasks=1") == 1 and f"--array={row}" in ln for ln in resub), resub
        assert (tmp_path / f"mpdem-sweep-{array}_{row}.out").exists()
        s = json.loads((run / "summary.json").read_text())
        assert s["converged"] and s["segments"] >= 1
