"""The cluster job scripts in jobs/: segments chained by mpdem's exit code, sweeps, signals.

Stand-ins, no MPI and no scheduler: a fake mpdem (also installed as srun and
mpiexec) that follows a plan of exit codes and writes checkpoints, and fake
sbatch and qsub that record each submission and run the job at once, from a
copy of the script as a scheduler does, with the scheduler's variables.
"""
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

JOBS = Path(__file__).resolve().parents[1] / "jobs"
SCRIPTS = ["mpdem-segment.sh", "slurm/chain.sbatch", "slurm/sweep.sbatch", "pbs/chain.pbs", "pbs/sweep.pbs"]
CHAIN = {"slurm": "jobs/slurm/chain.sbatch", "pbs": "jobs/pbs/chain.pbs"}
SWEEP = {"slurm": "jobs/slurm/sweep.sbatch", "pbs": "jobs/pbs/sweep.pbs"}
OURS = ("MPDEM_", "SLURM_", "PBS_")

FAKE_MPDEM = r'''#!{python}
"""Stand-in for `[launcher] python -m mpdem run|restart`: the n-th call on a run
directory does the n-th action of LOG/plan (the last one from then on)."""
import json, os, signal, sys, time
from pathlib import Path
LOG = Path({log!r})
argv = sys.argv[1:]
i = next(k for k, a in enumerate(argv) if a in ("run", "restart"))
sub, rest = argv[i], argv[i + 1:]
run_dir = Path(rest[rest.index("--out") + 1] if sub == "run" else rest[0])
calls = run_dir / ".fake-calls"
n = int(calls.read_text()) if calls.exists() else 0
calls.write_text(str(n + 1))
plan = (LOG / "plan").read_text().split()
act = plan[min(n, len(plan) - 1)]
ck = run_dir / "checkpoints"
rec = dict(exe=Path(sys.argv[0]).name, prefix=argv[:i], sub=sub, args=rest, cwd=os.getcwd(),
           run_dir=str(run_dir), act=act, env={{k: v for k, v in os.environ.items() if k.startswith({ours!r})}})

def done(code, **extra):
    rec.update(extra, rc=code)
    with open(LOG / "calls.jsonl", "a") as f:
        f.write(json.dumps(rec) + "\n")
    sys.exit(code)

def checkpoint():
    ck.mkdir(exist_ok=True)
    (ck / f"ckpt-{{len(list(ck.glob('ckpt-*.h5'))):05d}}.h5").write_text("")

if sub == "run":
    if (run_dir / "config.toml").exists() and "--force" not in rest:
        done(1, why="config.toml exists")
    (run_dir / "config.toml").write_text("")
elif not (run_dir / "final.h5").exists() and not list(ck.glob("*.h5")):
    done(1, why="nothing to restart")
if act.startswith("wait"):  # until a signal, then checkpoint and exit 75 (wait1: exit 1)
    got = []
    for s in (signal.SIGUSR1, signal.SIGTERM):
        signal.signal(s, lambda s, f: got.append(signal.Signals(s).name))
    (LOG / "waiting").write_text(str(os.getpid()))
    end = time.time() + 10
    while not got and time.time() < end:
        time.sleep(0.01)
    checkpoint()
    done(int(act[4:] or 75), signals=got)
if act == "ckpt75":
    checkpoint()
    done(75)
if act == "noprog75":
    done(75)
if act == "int75":  # SIGINT reached the ranks: checkpoint, the log's stop line, exit 75
    checkpoint()
    with open(run_dir / "log.txt", "a") as f:
        f.write("step 100\nstop: signal SIGINT at step 100; wrote ckpt. Not finished\n")
    done(75)
if act.startswith("noisy"):  # a launcher's report of a non-zero exit on stderr (noisyN: exit N)
    sys.stderr.write("srun: error: node1: tasks 0-1: Exited with exit code " + act[5:] + "\n" + "-" * 74 + "\n"
                     "Primary job  terminated normally, but 1 process returned\n"
                     "a non-zero exit code. Per user-direction, the job has been aborted.\n" + "-" * 74 + "\n"
                     + "-" * 74 + "\nmpiexec detected that one or more processes exited with non-zero status\n\n"
                     "  Process name: [[4059,1],0]\n  Exit code:    " + act[5:] + "\n" + "-" * 74 + "\n"
                     "mpdem: a line of its own\n")
    checkpoint()
    done(int(act[5:]))
if act.startswith("final"):
    (run_dir / "final.h5").write_text("")
    (run_dir / "summary.json").write_text("{{}}")
    done(int(act[5:]))
done(int(act[4:]))  # exitN
'''

FAKE_SUBMIT = r'''#!{python}
"""Stand-in for sbatch / qsub: records the call, then runs the job (each array task) now."""
import json, os, re, shutil, subprocess, sys
from pathlib import Path
LOG = Path({log!r})
tool, args = Path(sys.argv[0]).name, sys.argv[1:]
opts, i = {{}}, 0
while args[i].startswith("-"):
    if "=" in args[i]:
        k, v = args[i].split("=", 1); i += 1
    elif tool == "qsub":
        k, v = args[i], args[i + 1]; i += 2
    else:
        k, v = args[i], ""; i += 1
    opts[k] = v
script = Path(args[i])
with open(LOG / "submits.jsonl", "a") as f:
    f.write(json.dumps(dict(tool=tool, argv=args, cwd=os.getcwd(),
                            env={{k: v for k, v in os.environ.items() if k.startswith("MPDEM_")}})) + "\n")
text = script.read_text()
array = opts.get("--array") or opts.get("-J") or opts.get("-t")
if array is None:
    m = re.search(r"^#(?:SBATCH --array=|PBS -J )(\S+)", text, re.M)
    array = m and m.group(1)
tasks = [None]
if array:
    tasks = []
    for part in array.split("%")[0].split(","):
        a, _, b = part.partition("-")
        tasks += range(int(a), int(b or a) + 1)
first = None
for t in tasks:
    counter = LOG / "jobid"
    jid = int(counter.read_text()) + 1 if counter.exists() else 100
    counter.write_text(str(jid))
    if jid > 160:
        sys.exit("fake " + tool + ": too many jobs, a runaway chain")
    first = first or jid
    spool = LOG / "spool" / str(jid)
    spool.mkdir(parents=True)
    copy = spool / "job_script"
    shutil.copy(script, copy)
    if tool == "sbatch":  # the submitter's environment, this job's SLURM_* variables
        env = {{k: v for k, v in os.environ.items() if not k.startswith("SLURM_")}}
        env.update(SLURM_JOB_ID=str(jid), SLURM_SUBMIT_DIR=os.getcwd())
        if t is not None:
            env.update(SLURM_ARRAY_JOB_ID=str(first), SLURM_ARRAY_TASK_ID=str(t))
        cwd, out = os.getcwd(), f"slurm-{{jid}}.out"
    else:  # only -v variables; starts in HOME
        env = dict(PATH=os.environ["PATH"], HOME=str(LOG / "home"), PBS_O_WORKDIR=os.getcwd(),
                   PBS_JOBID=f"{{jid}}.fake" if t is None else f"{{first}}[{{t}}].fake")
        for item in filter(None, opts.get("-v", "").split(",")):
            k, eq, v = item.partition("=")
            env[k] = v if eq else os.environ.get(k, "")
        if t is not None:
            env["PBS_ARRAY_INDEX"] = str(t)
        cwd, out = str(LOG / "home"), f"mpdem.o{{jid}}"
    with open(Path(os.getcwd()) / out, "w") as o:
        rc = subprocess.call(["bash", str(copy)], env=env, cwd=cwd, stdout=o, stderr=subprocess.STDOUT)
    with open(LOG / "jobs.jsonl", "a") as f:
        f.write(json.dumps(dict(tool=tool, job=jid, task=t, rc=rc)) + "\n")
print(f"Submitted batch job {{first}}" if tool == "sbatch" else f"{{first}}.fake")
'''


class Cluster:
    """A repository root with jobs/, fake tools on PATH, and what they recorded."""

    def __init__(self, tmp):
        self.work, self.log, self.bin = tmp / "work", tmp / "log", tmp / "bin"
        shutil.copytree(JOBS, self.work / "jobs")
        for d in (self.log / "home", self.bin):
            d.mkdir(parents=True)
        for name, src in [("fake-mpdem", FAKE_MPDEM), ("srun", FAKE_MPDEM), ("mpiexec", FAKE_MPDEM),
                          ("sbatch", FAKE_SUBMIT), ("qsub", FAKE_SUBMIT)]:
            p = self.bin / name
            p.write_text(src.format(python=sys.executable, log=str(self.log), ours=OURS))
            p.chmod(0o755)
        self.mpdem = str(self.bin / "fake-mpdem")
        self.env = {k: v for k, v in os.environ.items() if not k.startswith(OURS)}
        self.env["PATH"] = f"{self.bin}:{os.environ['PATH']}"
        self.plan("ckpt75", "ckpt75", "final0")

    def tool(self, name, body):
        """A stand-in command on the PATH (a bash script)."""
        p = self.bin / name
        p.write_text("#!/bin/bash\n" + body)
        p.chmod(0o755)

    def plan(self, *acts):
        (self.log / "plan").write_text(" ".join(acts))

    def run(self, *cmd, **env):
        return subprocess.run(list(cmd), cwd=self.work, env={**self.env, **env},
                              capture_output=True, text=True, timeout=60)

    def submit(self, sched, script, *opts, **env):
        """Submit as a user would: sbatch passes the environment, qsub only -v."""
        if sched == "slurm":
            return self.run(str(self.bin / "sbatch"), *opts, script, **env)
        v = ",".join(f"{k}={x}" for k, x in env.items())
        return self.run(str(self.bin / "qsub"), *opts, *(["-v", v] if v else []), script)

    def helper(self, *args, **env):
        return self.run("bash", "jobs/mpdem-segment.sh", *args, **env)

    def records(self, name):
        p = self.log / name
        return [json.loads(line) for line in p.read_text().splitlines()] if p.exists() else []

    calls = property(lambda self: self.records("calls.jsonl"))
    submits = property(lambda self: self.records("submits.jsonl"))
    jobs = property(lambda self: sorted(self.records("jobs.jsonl"), key=lambda j: j["job"]))  # by start

    def joblog(self, run_dir):
        return (self.work / run_dir / "jobs.log").read_text()


@pytest.fixture
def cl(tmp_path):
    return Cluster(tmp_path)


def secs(hms):
    h, m, s = map(int, hms.split(":"))
    return 3600 * h + 60 * m + s


def walltime(call):
    a = call["args"]
    return secs(a[a.index("--walltime") + 1])


@pytest.mark.parametrize("script", SCRIPTS)
def test_scripts_parse(script):
    path = JOBS / script
    assert subprocess.run(["bash", "-n", str(path)]).returncode == 0

@pytest.mark.parametrize("script", SCRIPTS)
def test_scripts_pass_shellcheck(script):
    if not shutil.which("shellcheck"):
        pytest.skip("shellcheck is not installed (tools/setup.sh installs it where apt is allowed)")
    p = subprocess.run(["shellcheck", "-s", "bash", str(JOBS / script)], capture_output=True, text=True)
    assert p.returncode == 0, p.stdout


@pytest.mark.parametrize("sched", ["slurm", "pbs"])
def test_chain_runs_until_finished(cl, sched):
    """run, exit 75, resubmit; restart, 75, resubmit; restart, exit 0: done."""
    (cl.work / "cfg.toml").write_text("")
    p = cl.submit(sched, CHAIN[sched], MPDEM_CMD=cl.mpdem, MPDEM_RUN_DIR="runs/c", MPDEM_CONFIG="cfg.toml",
                  MPDEM_SET="run.max_steps=1000 contact.mu=0.3", MPDEM_WALLTIME="01:00:00")
    assert p.returncode == 0, p.stderr
    calls = cl.calls
    assert [c["sub"] for c in calls] == ["run", "restart", "restart"]
    assert calls[0]["args"][:7] == ["cfg.toml", "--out", "runs/c", "--set", "run.max_steps=1000",
                                    "--set", "contact.mu=0.3"]
    assert "--force" not in calls[0]["args"]
    assert [c["args"][:1] for c in calls[1:]] == [["runs/c"], ["runs/c"]]
    assert all("--set" not in c["args"] for c in calls[1:])  # restart uses the run's own config
    for c in calls:
        assert 3600 - 300 - 5 <= walltime(c) <= 3600 - 300
        assert c["cwd"] == str(cl.work)  # PBS starts in HOME: the script must cd
    ids = [c["env"].get("SLURM_JOB_ID") or c["env"].get("PBS_JOBID") for c in calls]
    assert len(set(ids)) == 3  # one segment per job
    subs = cl.submits
    assert len(subs) == 3  # ours, then exactly two resubmissions
    for s in subs[1:]:
        assert s["argv"][-1] == CHAIN[sched]
        if sched == "slurm":
            assert s["argv"] == ["--export=ALL", CHAIN[sched]]
        else:  # PBS passes no environment: the MPDEM_* variables go with -v
            v = dict(x.split("=", 1) for x in s["argv"][s["argv"].index("-v") + 1].split(","))
            assert v["MPDEM_RUN_DIR"] == "runs/c" and v["MPDEM_CMD"] == cl.mpdem
    assert [j["rc"] for j in cl.jobs] == [0, 0, 0]
    run = cl.work / "runs/c"
    assert (run / "final.h5").exists() and (run / "jobs.segments").read_text().strip() == "3"
    log = cl.joblog("runs/c")
    assert log.count("segment ") == 3 and log.count("resubmitting") == 2
    assert log.splitlines()[-1].endswith("finished (exit 0)")


STOPS = {  # plan: (segments, exit codes of the jobs, words in jobs.log)
    "not-converged": (("final3",), ["run"], [3], "not converged"),
    "error": (("ckpt75", "exit1"), ["run", "restart"], [0, 1], "error: exit 1; not resubmitting"),
    "usage-error": (("exit2",), ["run"], [2], "error: exit 2; not resubmitting"),
    # a launcher that exits 0 without having started mpdem (srun after "task 0 launch failed")
    "launch-failed": (("ckpt75", "exit0"), ["run", "restart"], [0, 1], "exit 0 but no runs/c/summary.json"),
    "no-progress": (("ckpt75", "noprog75"), ["run", "restart"], [0, 1], "no new checkpoint"),
    "no-first-checkpoint": (("noprog75",), ["run"], [1], "no new checkpoint"),
    "interrupted": (("ckpt75", "int75"), ["run", "restart"], [0, 75], "got SIGINT (an interrupt)"),
}


@pytest.mark.parametrize("sched", ["slurm", "pbs"])
@pytest.mark.parametrize("case", STOPS)
def test_chain_stops_without_resubmitting(cl, sched, case):
    plan, subs, rcs, words = STOPS[case]
    cl.plan(*plan)
    cl.submit(sched, CHAIN[sched], MPDEM_CMD=cl.mpdem, MPDEM_RUN_DIR="runs/c")
    assert [c["sub"] for c in cl.calls] == subs
    assert len(cl.submits) == len(subs)  # ours plus one per segment that went on
    assert [j["rc"] for j in cl.jobs] == rcs
    last = cl.joblog("runs/c").splitlines()[-1]
    assert words in last and "resubmitting:" not in last


@pytest.mark.parametrize("sched", ["slurm", "pbs"])
def test_segment_cap(cl, sched):
    cl.plan("ckpt75")  # never finishes
    env = dict(MPDEM_CMD=cl.mpdem, MPDEM_RUN_DIR="runs/c", MPDEM_MAX_SEGMENTS="2")
    cl.submit(sched, CHAIN[sched], **env)
    assert [c["sub"] for c in cl.calls] == ["run", "restart"]
    assert len(cl.submits) == 2 and [j["rc"] for j in cl.jobs] == [0, 1]
    assert "2 segments = MPDEM_MAX_SEGMENTS" in cl.joblog("runs/c")
    # submitted again by hand: refuses before running anything
    cl.submit(sched, CHAIN[sched], **env)
    assert len(cl.calls) == 2 and cl.jobs[-1]["rc"] == 1
    assert "not running" in cl.joblog("runs/c").splitlines()[-1]


def test_helper_by_hand_run_force_restart(cl):
    """No resubmit command: exit 75 is handed back; the run/restart/--force choice."""
    rcs = []
    while not rcs or rcs[-1] == 75:
        rcs.append(cl.helper("runs/h", "", "run.seed=3", MPDEM_CMD=cl.mpdem).returncode)
        assert len(rcs) < 5
    assert rcs == [75, 75, 0]
    calls = cl.calls
    assert [c["sub"] for c in calls] == ["run", "restart", "restart"]
    assert calls[0]["args"] == ["--out", "runs/h", "--set", "run.seed=3"]  # no CONFIG, no --walltime
    assert calls[1]["args"] == ["runs/h"]
    assert "no resubmit command" in cl.joblog("runs/h")
    # config.toml but no checkpoint (a first segment that died early): run --force
    (cl.work / "runs/f").mkdir(parents=True)
    (cl.work / "runs/f/config.toml").write_text("")
    cl.helper("runs/f", "", MPDEM_CMD=cl.mpdem)
    assert cl.calls[-1]["sub"] == "run" and cl.calls[-1]["args"][-1] == "--force"
    # a checkpoint, or final.h5 alone: restart
    for name, f in [("k", "checkpoints/ckpt-00007.h5"), ("d", "final.h5")]:
        (cl.work / "runs" / name / f).parent.mkdir(parents=True, exist_ok=True)
        (cl.work / "runs" / name / f).write_text("")
        cl.helper(f"runs/{name}", "cfg.toml", MPDEM_CMD=cl.mpdem)
        assert cl.calls[-1]["sub"] == "restart" and cl.calls[-1]["args"] == [f"runs/{name}"]


def test_default_command_and_walltime_sources(cl):
    cl.plan("final0")
    # the default command: MPDEM_LAUNCH MPDEM_PYTHON -m mpdem; a Slurm whose srun offers no
    # pmix (the stand-in srun lists none) gets mpiexec, and no venv here: python3
    cl.submit("slurm", CHAIN["slurm"], MPDEM_RUN_DIR="runs/a")
    cl.submit("pbs", CHAIN["pbs"], MPDEM_RUN_DIR="runs/b", MPDEM_PYTHON="/opt/py/bin/python")
    cl.helper("runs/c", "", MPDEM_LAUNCH="mpiexec -n 3")
    assert [(c["exe"], c["prefix"]) for c in cl.calls] == [
        ("mpiexec", ["python3", "-m", "mpdem"]), ("mpiexec", ["/opt/py/bin/python", "-m", "mpdem"]),
        ("mpiexec", ["-n", "3", "python3", "-m", "mpdem"])]
    assert "launcher: mpiexec (on the PATH; Slurm offers no pmix)" in cl.joblog("runs/a")
    # Slurm's time left unknown (no squeue answer): no --walltime; PBS's template default 12 h
    assert "--walltime" not in cl.calls[0]["args"] and walltime(cl.calls[1]) > 12 * 3600 - 310
    # the sooner end wins: Slurm's own end time; days; the margin
    cl.helper("runs/d", "", MPDEM_CMD=cl.mpdem, MPDEM_WALLTIME="12:00:00",
              SLURM_JOB_END_TIME=str(int(time.time()) + 1000))
    assert 1000 - 100 - 5 <= walltime(cl.calls[-1]) <= 1000 - 100   # margin: a tenth
    cl.helper("runs/e", "", MPDEM_CMD=cl.mpdem, MPDEM_WALLTIME="1-00:00:00", MPDEM_MARGIN="60")
    assert 86400 - 60 - 5 <= walltime(cl.calls[-1]) <= 86400 - 60
    # the margin follows the job: a tenth of the time left, 20 s to 300 s
    cl.helper("runs/e5", "", MPDEM_CMD=cl.mpdem, MPDEM_WALLTIME="00:05:00")
    assert 300 - 30 - 5 <= walltime(cl.calls[-1]) <= 300 - 30
    n = len(cl.calls)
    p = cl.helper("runs/f", "", MPDEM_CMD=cl.mpdem, MPDEM_WALLTIME="00:00:45")  # 20 s + 30 s needed
    assert p.returncode == 1 and "left in the job" in cl.joblog("runs/f")
    p = cl.helper("runs/g", "", MPDEM_CMD=cl.mpdem, MPDEM_WALLTIME="90")
    assert p.returncode == 2 and "MPDEM_WALLTIME" in p.stderr
    p = cl.helper("runs/g", "", MPDEM_CMD=cl.mpdem, MPDEM_SET="a=1,2", MPDEM_RESUBMIT="qsub x.pbs")
    assert p.returncode == 2 and "comma" in p.stderr  # caught before running, not at resubmission
    assert len(cl.calls) == n


def sweep_rows():
    lines = [ln.split() for ln in (JOBS / "sweep.example.tsv").read_text().splitlines()]
    assert lines[0] == ["mu", "epsilon", "k_n", "phi_i", "seed"]
    return lines[1:]


@pytest.mark.parametrize("sched", ["slurm", "pbs"])
def test_sweep_gives_each_task_its_row_and_dir(cl, sched):
    rows = sweep_rows()
    assert len(rows) == 6 and len({r[0] for r in rows}) >= 3 and {r[4] for r in rows} == {"1", "2"}
    cl.plan("ckpt75", "final0")
    env = dict(MPDEM_CMD=cl.mpdem, MPDEM_SET="run.max_steps=100")
    if sched == "slurm":
        p = cl.submit(sched, SWEEP[sched], **env)  # --array=1-6 from the script
    else:
        p = cl.submit(sched, SWEEP[sched], "-J", "1-6", **env)
    assert p.returncode == 0, p.stderr
    calls = cl.calls
    by_dir = {}
    for c in calls:
        by_dir.setdefault(c["run_dir"], []).append(c)
    expect = {f"runs/sweep/mu{mu}_eps{eps}_kn{kn}_phi{phi}_s{s}": (mu, eps, kn, phi, s)
              for mu, eps, kn, phi, s in rows}
    assert "runs/sweep/mu0.5_eps0.88_kn2e5_phi0.13_s1" in expect
    assert set(by_dir) == set(expect)
    for d, (mu, eps, kn, phi, s) in expect.items():
        run, restart = by_dir[d]  # each row: its own run, then one restart, in its own job
        assert (run["sub"], restart["sub"]) == ("run", "restart")
        assert run["args"][:2] == ["--out", d] and restart["args"][0] == d
        assert run["args"][2:14] == ["--set", "run.max_steps=100", "--set", f"contact.mu={mu}",
                                     "--set", f"contact.epsilon={eps}", "--set", f"contact.k_n={kn}",
                                     "--set", f"pour.phi_i={phi}", "--set", f"run.seed={s}"]
        assert (cl.work / d / "final.h5").exists()
    resubs = cl.submits[1:]
    assert len(resubs) == 6  # one per task, each for its own row only
    if sched == "slurm":
        assert sorted(tuple(s["argv"]) for s in resubs) == [
            ("--export=ALL", f"--array={n}", SWEEP[sched]) for n in range(1, 7)]
    else:
        tasks = []
        for s in resubs:
            assert "-J" not in s["argv"] and s["argv"][-1] == SWEEP[sched]
            v = dict(x.split("=", 1) for x in s["argv"][s["argv"].index("-v") + 1].split(","))
            tasks.append(int(v["MPDEM_TASK"]))
        assert sorted(tasks) == list(range(1, 7))
    assert all(j["rc"] == 0 for j in cl.jobs) and len(cl.jobs) == 12


def test_sweep_row_errors(cl):
    for task, words in [("7", "no row 7"), ("", "not a positive"), ("0", "not a positive")]:
        p = cl.run("bash", SWEEP["slurm"], MPDEM_CMD=cl.mpdem, MPDEM_TASK=task)
        assert p.returncode == 2 and words in p.stderr
    (cl.work / "bad.tsv").write_text("mu\tcolour\n0.5\tred\n")
    p = cl.run("bash", SWEEP["slurm"], MPDEM_CMD=cl.mpdem, MPDEM_TASK="1", MPDEM_SWEEP="bad.tsv")
    assert p.returncode == 2 and "unknown column 'colour'" in p.stderr
    (cl.work / "dotted.tsv").write_text("# comment\n\nseed\tstop.E_stop\r\n4\t1e-9\r\n")
    cl.plan("final0")
    p = cl.run("bash", SWEEP["slurm"], MPDEM_CMD=cl.mpdem, MPDEM_TASK="1", MPDEM_SWEEP="dotted.tsv")
    assert p.returncode == 0, p.stderr
    assert cl.calls[0]["args"] == ["--out", "runs/sweep/s4_E_stop1e-9", "--set", "run.seed=4",
                                   "--set", "stop.E_stop=1e-9"]   # no time limit known: no --walltime


def start_job(cl, sched):
    """The chain script as the batch shell, as the scheduler starts it."""
    if sched == "slurm":
        env = dict(cl.env, SLURM_JOB_ID="7", SLURM_SUBMIT_DIR=str(cl.work))
        cwd = cl.work
    else:
        env = dict(PATH=cl.env["PATH"], PBS_JOBID="7.fake", PBS_O_WORKDIR=str(cl.work))
        cwd = cl.log / "home"
    env.update(MPDEM_CMD=cl.mpdem, MPDEM_RUN_DIR="runs/c")
    p = subprocess.Popen(["bash", str(cl.work / CHAIN[sched])], cwd=cwd, env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    end = time.time() + 20
    while not (cl.log / "waiting").exists():
        assert time.time() < end and p.poll() is None, p.communicate()[0]
        time.sleep(0.01)
    return p


@pytest.mark.parametrize("sched", ["slurm", "pbs"])
def test_usr1_to_the_batch_shell_reaches_mpdem_and_chains(cl, sched):
    """Slurm's --signal=B:USR1 (or qsig -s USR1) hits only the batch shell: it must forward."""
    cl.plan("wait", "final0")
    p = start_job(cl, sched)
    p.send_signal(signal.SIGUSR1)
    out = p.communicate(timeout=30)[0]
    assert p.returncode == 0, out
    calls = cl.calls
    assert calls[0]["signals"] == ["SIGUSR1"] and calls[0]["rc"] == 75
    assert [c["sub"] for c in calls] == ["run", "restart"] and len(cl.submits) == 1
    assert cl.joblog("runs/c").splitlines()[-1].endswith("finished (exit 0)")


@pytest.mark.parametrize("sched", ["slurm", "pbs"])
@pytest.mark.parametrize("act, rc", [("wait", 75), ("wait1", 1)])  # Open MPI's mpiexec: 1
def test_sigterm_to_the_batch_shell_checkpoints_but_does_not_resubmit(cl, sched, act, rc):
    """scancel / qdel: mpdem checkpoints and exits 75, the job does not come back."""
    cl.plan(act, "final0")
    p = start_job(cl, sched)
    p.send_signal(signal.SIGTERM)
    out = p.communicate(timeout=30)[0]
    assert p.returncode == rc, out
    assert [c.get("signals") for c in cl.calls] == [["SIGTERM"]]
    assert cl.submits == [] and (cl.work / "runs/c/checkpoints/ckpt-00000.h5").exists()
    assert "got SIGTERM" in cl.joblog("runs/c").splitlines()[-1]


PMIX_SRUN = 'if [[ $1 == --mpi=list ]]; then printf "MPI plugin types are...\\n\\tnone\\n\\tpmix\\n"; exit 0; fi\n' \
            'exec "{mpdem}" "$@"\n'


def test_launcher_and_python_chosen_to_work(cl):
    """In a Slurm job whose srun offers pmix: srun --mpi=pmix; else the repository's venv
    mpiexec (and its python, found from the helper's own path); each said in jobs.log."""
    cl.plan("final0")
    cl.tool("srun", PMIX_SRUN.format(mpdem=cl.mpdem))
    cl.helper("runs/a", "", SLURM_JOB_ID="41")
    assert (cl.calls[-1]["exe"], cl.calls[-1]["prefix"]) == ("fake-mpdem", ["--mpi=pmix", "python3", "-m", "mpdem"])
    assert "launcher: srun --mpi=pmix (Slurm offers pmix (srun --mpi=list))" in cl.joblog("runs/a")
    venv = cl.work / ".venv" / "bin"
    venv.mkdir(parents=True)
    for name in ("mpiexec", "python"):
        shutil.copy(cl.bin / "mpiexec", venv / name)
    cl.helper("runs/b", "")                               # no Slurm: the venv's mpiexec
    assert (cl.calls[-1]["exe"], cl.calls[-1]["prefix"]) == ("mpiexec", [str(venv / "python"), "-m", "mpdem"])
    assert f"launcher: {venv / 'mpiexec'} (the project's venv)" in cl.joblog("runs/b")
    cl.helper("runs/c", "", SLURM_JOB_ID="42", MPDEM_LAUNCH="srun")   # said by the user: as said
    assert cl.calls[-1]["prefix"] == [str(venv / "python"), "-m", "mpdem"]   # srun as given, no --mpi
    assert "launcher: srun (MPDEM_LAUNCH)" in cl.joblog("runs/c")


@pytest.mark.parametrize("left, expect", [("1:30", 90 - 20), ("45:00", 2700 - 270), ("1-00:00:00", 86400 - 300)])
def test_time_left_read_from_slurm(cl, left, expect):
    """squeue -o %L gives the time left (Slurm 22.05 sets no SLURM_JOB_END_TIME)."""
    cl.plan("final0")
    cl.tool("squeue", f'[[ "$*" == *"-o %L"* ]] && echo "{left}"\n')
    cl.helper("runs/t", "", MPDEM_CMD=cl.mpdem, SLURM_JOB_ID="43")
    assert expect - 5 <= walltime(cl.calls[-1]) <= expect


SCONTROL = """if [[ $1 == -o ]]; then
  # an array's other task first: only this job's record counts
  echo "JobId=9${@: -1} JobName=other NumTasks=8 TimeLimit=09:00:00 Partition=long"
  echo "JobId=${@: -1} JobName=mpdem-chain UserId=u(1) Account=(null) QOS=normal Partition=short \\
TimeLimit=00:03:00 NumNodes=1 NumCPUs=2 NumTasks=2 CPUs/Task=1 Command=$MPDEM_FAKE_COMMAND WorkDir=/x"
else
  printf '   JobId=%s JobName=mpdem-chain\\n   Command=%s\\n' "${@: -1}" "$MPDEM_FAKE_COMMAND"
fi
"""


def test_resubmission_keeps_the_jobs_options_from_any_directory(cl):
    """Options given on the first sbatch line (read back with scontrol) go with every
    resubmission; the script is found from the path it was submitted by, from any directory."""
    cl.tool("scontrol", SCONTROL)
    sub = cl.work / "elsewhere"
    sub.mkdir()
    env = {**cl.env, "MPDEM_CMD": cl.mpdem, "MPDEM_FAKE_COMMAND": "../jobs/slurm/chain.sbatch"}
    p = subprocess.run([str(cl.bin / "sbatch"), "--ntasks=2", "--time=3", "../jobs/slurm/chain.sbatch"], cwd=sub,
                       env=env, capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert [c["sub"] for c in cl.calls] == ["run", "restart", "restart"]
    assert all(c["cwd"] == str(sub) and c["run_dir"] == "runs/chain" for c in cl.calls)
    script = str(sub / "../jobs/slurm/chain.sbatch")
    for s in cl.submits[1:]:
        assert sorted(s["argv"][:-2]) == ["--cpus-per-task=1", "--job-name=mpdem-chain", "--nodes=1", "--ntasks=2",
                                          "--partition=short", "--qos=normal", "--time=00:03:00"], s["argv"]
        assert s["argv"][-2:] == ["--export=ALL", script]
    assert [j["rc"] for j in cl.jobs] == [0, 0, 0]
    log = (sub / "runs/chain/jobs.log").read_text()
    assert log.count("checkpointed, resubmitting (mpdem exit 75") == 2


def test_a_resubmission_slurm_will_never_start_is_an_error(cl):
    """A resubmitted job pending for a reason that never clears (PartitionConfig) is taken
    back with scancel and logged as an error, not left to pend for ever."""
    cl.plan("ckpt75")
    cl.tool("squeue", '[[ "$*" == *"-o %r"* ]] && echo PartitionConfig\n')
    cl.tool("scancel", 'echo "$*" >> "{}"\n'.format(cl.log / "scancel"))
    cl.tool("sbatch", 'echo "Submitted batch job 999"\n')
    p = cl.helper("runs/p", "", "--", "sbatch", "chain.sbatch", MPDEM_CMD=cl.mpdem, SLURM_JOB_ID="44")
    assert p.returncode == 1
    assert "Slurm will not start job 999 (PartitionConfig); cancelled it" in cl.joblog("runs/p").splitlines()[-1]
    assert (cl.log / "scancel").read_text().split() == ["999"]


def test_array_task_logged_by_its_output_file_name(cl):
    cl.plan("final0")
    cl.submit("slurm", SWEEP["slurm"], "--array=2", MPDEM_CMD=cl.mpdem)
    d = cl.calls[0]["run_dir"]
    assert " job 100_2 (id 100): segment 1/50" in cl.joblog(d)


@pytest.mark.parametrize("rc", [75, 1])
def test_the_launchers_report_of_exit_75_is_dropped(cl, rc):
    """Exit 75 is a checkpoint, not a crash: the launcher's 'exit code 75' lines and blocks are
    dropped (one log line says what happened); for any other code they stay."""
    cl.plan(f"noisy{rc}", "final0")
    p = cl.helper("runs/n", "", "--", "true", MPDEM_CMD=cl.mpdem)
    noise = ("Exited with exit code", "Primary job", "non-zero status", "Exit code:")
    assert "mpdem: a line of its own" in p.stderr
    if rc == 75:
        assert not any(w in p.stderr for w in noise), p.stderr
        assert "checkpointed, resubmitting" in p.stderr
    else:
        assert all(w in p.stderr for w in noise), p.stderr
