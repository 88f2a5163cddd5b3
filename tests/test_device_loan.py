"""tools/device_loan.sh: ladder rungs packed for a lent machine (small files and the newest checkpoint),
stepped there until the call's time (a converged rung stiffened tenfold into the next), and put back here.
The GPU's part is the engine's own (`--device`): here the rungs run on the CPU, the probe and the scaling
left out."""
import json
import os
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path

from helpers import MPIEXEC, settled_table

ROOT = Path(__file__).resolve().parents[1]


def checkout(tmp_path):
    """A copy of the script beside the project's sources (its .ladder/ and .devdata/ land in tmp_path)."""
    (tmp_path / "tools").mkdir()
    shutil.copy(ROOT / "tools" / "device_loan.sh", tmp_path / "tools")
    (tmp_path / "src").symlink_to(ROOT / "src")
    return tmp_path


def loan(repo, *args, **env):
    e = dict(os.environ, PATH=f"{Path(sys.executable).parent}:{os.environ['PATH']}", RUNS_ROOT=str(repo / "runs"),
             **env)
    return subprocess.run(["bash", str(repo / "tools" / "device_loan.sh"), *args], cwd=repo, env=e,
                          capture_output=True, text=True, timeout=600)


def write(path, text="x"):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def test_pack_takes_a_rungs_small_files_and_its_newest_checkpoint_only(tmp_path):
    repo = checkout(tmp_path)
    rung = repo / "runs" / "ladder-x" / "mu0_s1" / "kn2e7"
    for f in ("config.toml", "log.txt", "thermo.csv", ".lock"):
        write(rung / f)
    write(rung / "checkpoints" / "ckpt-00003.h5", "old")
    write(rung / "checkpoints" / "ckpt-00004.h5", "new")
    p = loan(repo, "pack", str(rung))
    assert p.returncode == 0, p.stderr
    got = {str(q.relative_to(repo / ".ladder")) for q in (repo / ".ladder").rglob("*") if q.is_file()}
    r = "ladder-x/mu0_s1/kn2e7"
    assert got == {f"{r}/config.toml", f"{r}/log.txt", f"{r}/thermo.csv", f"{r}/checkpoints/ckpt-00004.h5", "order"}
    # a rung without a checkpoint is refused, naming it
    write(repo / "runs" / "ladder-x" / "mu0_s1" / "kn2e8" / "config.toml")
    p = loan(repo, "pack", str(repo / "runs" / "ladder-x" / "mu0_s1" / "kn2e8"))
    assert p.returncode == 2 and "kn2e8 has no checkpoint (and has not converged)" in p.stderr


def test_a_converged_rung_travels_as_what_it_is_stiffened_from(tmp_path):
    """A converged rung goes to be stiffened into the next there: a frictionless pile as its committed
    packing (not its final.h5, which git does not keep), a frictional one with its final.h5; a frictional
    one without a final state is refused."""
    repo = checkout(tmp_path)
    done = json.dumps({"status": "converged"})
    ice = repo / "runs" / "ladder-x" / "mu0_s2" / "kn2e8"
    write(ice / "config.toml", "[contact]\nmu = 0.0\n")
    for f, text in (("summary.json", done), ("packing.npz", "p"), ("final.h5", "f"), ("final.xmf", "x")):
        write(ice / f, text)
    grip = repo / "runs" / "ladder-x" / "mu0.5_s1" / "kn2e8"
    write(grip / "config.toml", "[contact]\nmu = 0.5\n")
    for f, text in (("summary.json", done), ("packing.npz", "p"), ("final.h5", "f")):
        write(grip / f, text)
    p = loan(repo, "pack", str(ice), str(grip))
    assert p.returncode == 0, p.stderr
    got = {str(q.relative_to(repo / ".ladder")) for q in (repo / ".ladder").rglob("*") if q.is_file()}
    assert got == {"ladder-x/mu0_s2/kn2e8/config.toml", "ladder-x/mu0_s2/kn2e8/summary.json",
                   "ladder-x/mu0_s2/kn2e8/packing.npz", "ladder-x/mu0.5_s1/kn2e8/config.toml",
                   "ladder-x/mu0.5_s1/kn2e8/summary.json", "ladder-x/mu0.5_s1/kn2e8/packing.npz",
                   "ladder-x/mu0.5_s1/kn2e8/final.h5", "order"}
    # the call steps them in the order named (the paper's top rung first here), not of their paths
    assert (repo / ".ladder" / "order").read_text().split() == ["ladder-x/mu0_s2/kn2e8", "ladder-x/mu0.5_s1/kn2e8"]
    assert p.stdout.count("converged: it is stiffened into the next rung there") == 2
    (grip / "final.h5").unlink()
    p = loan(repo, "pack", str(grip))
    assert p.returncode == 2 and "converged with friction but has no final.h5" in p.stderr


def test_a_call_steps_a_rung_to_its_stop_stiffens_the_next_and_unpack_puts_both_back(tmp_path):
    repo = checkout(tmp_path)
    rung = repo / "runs" / "ladder-t" / "mu0_s1" / "kn2e5"
    # a small frictionless pile stopped by its wall time with checkpoints: a rung left unfinished
    p = subprocess.run([sys.executable, "-m", "mpdem", "run", "--set", "pour.N=60", "--set", "box.L_x=4",
                        "--set", "box.L_y=4", "--set", "contact.k_n=2e5", "--set", "output.checkpoint_every=1000",
                        "--set", "run.max_steps=400000", "--out", str(rung), "--force", "--quiet", "--walltime", "2"],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert p.returncode == 75, p.stdout + p.stderr
    assert loan(repo, "pack", str(rung)).returncode == 0
    out = repo / "out"
    out.mkdir()
    p = loan(repo, "call", OUT=str(out), UNTIL="240", PROBE_BUDGET="0", SCALING_RANKS="none", LADDER_DEVICE="cpu",
             LADDER_CORE="0", LADDER_TOP="2e6")
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    log = (out / "loan.log").read_text()
    assert "kn2e5 converged; stiffened into" in log and "kn2e6" in log
    parts = sorted(out.glob("ladder.tgz.*"))
    assert parts and not (out / "probe.tgz").exists() and not (out / "scaling.tgz").exists()
    whole = tmp_path / "ladder.tgz"
    whole.write_bytes(b"".join(q.read_bytes() for q in parts))
    with tarfile.open(whole) as tf:
        names = tf.getnames()
    # converged rungs come back without checkpoints, with their final state (the next rung's start)
    assert ".ladder/ladder-t/mu0_s1/kn2e5/final.h5" in names
    assert not any("checkpoints/ckpt-" in n for n in names if "/kn2e5/" in n)
    # unpack replaces the rungs here (the old checkpoints gone) and adds the new one
    write(rung / "checkpoints" / "ckpt-00099.h5", "stale")
    p = loan(repo, "unpack", str(whole))
    assert p.returncode == 0, p.stderr
    for k in ("kn2e5", "kn2e6"):
        d = repo / "runs" / "ladder-t" / "mu0_s1" / k
        assert json.loads((d / "summary.json").read_text())["status"] == "converged"
        assert not list((d / "checkpoints").glob("ckpt-*.h5"))
    assert "DEVICE=cpu" in p.stdout


def test_a_call_times_a_pour_from_nothing_and_says_how_it_ended(tmp_path):
    """POUR=S: a pour of POUR_CONFIG with POUR_SETS from nothing, its end (here the step cap of a few spheres on
    the CPU), steps and digest in loan.log; no rungs, probe or scaling."""
    repo = checkout(tmp_path)
    small = tmp_path / "small.toml"
    small.write_text("[box]\nL_x = 4.0\nL_y = 4.0\n[pour]\nN = 12\n")
    out = repo / "out"
    out.mkdir()
    p = loan(repo, "call", OUT=str(out), PROBE_BUDGET="0", SCALING_RANKS="none", POUR="240", POUR_CONFIG=str(small),
             POUR_SETS="run.max_steps=300", POUR_DEVICE="cpu")
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    log = (out / "loan.log").read_text()
    line = next(ln for ln in log.splitlines() if ln.startswith("pour: exit status"))
    assert "max_steps at step 300" in line and "digest" in line, log[-2000:]


def test_a_call_times_two_ranks_with_each_way_of_exchanging_rows(tmp_path):
    """EXCHANGE=S: the bench's table on two ranks with engine.gpu_exchange = host, then device (here the CPU
    engine, which takes neither, on a small settled table), each run's exit status and bench lines in
    loan.log."""
    repo = checkout(tmp_path)
    settled_table(tmp_path / "t.txt")
    out = repo / "out"
    out.mkdir()
    p = loan(repo, "call", OUT=str(out), PROBE_BUDGET="0", SCALING_RANKS="none", EXCHANGE="400", EXCHANGE_DEVICE="cpu",
             EXCHANGE_STEPS="20", EXCHANGE_TABLE=str(tmp_path / "t.txt"), EXCHANGE_MPIEXEC=str(MPIEXEC),
             EXCHANGE_SETS="--set box.L_x=6.0 --set box.L_y=6.0")
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    log = (out / "loan.log").read_text()
    for x in ("host", "device"):
        assert f"exchange {x}: exit status 0" in log, log[-3000:]
        assert f"exchange {x}: bench: 2 rank(s)" in log and f"exchange {x}: ns_per_atom_step=" in log, log[-3000:]
