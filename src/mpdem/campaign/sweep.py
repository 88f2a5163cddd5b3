"""``mpdem sweep``: the rows of sweep tables run on this machine, then collected.

A sweep table (``jobs/sweep.example.tsv``, ``analysis/sweeps/``) has a header
of columns ``mu epsilon k_n phi_i seed`` or any ``section.key``, one run per
line, ``#`` lines and blank lines skipped. Row values become ``--set`` items
and the run directory's name, e.g. ``mu0.5_eps0.88_kn2e5_phi0.13_s1``: the
same names as ``jobs/mpdem-segment.sh --sweep``, so a sweep begun on a
cluster can be finished here and the other way round.

Each row is an ``mpdem run`` (or ``mpdem restart`` from its newest
checkpoint) in its own process group, J at a time, then ``mpdem analyze``
(which keeps the row's packing, ``RUN/packing.npz``, for analyses after
the state files are gone).
A row is finished when its directory holds ``final.h5`` or
``analysis/summary.json``; finished rows are skipped, so a sweep resumes
where it stopped. SIGINT and SIGTERM are passed on as SIGUSR1: every running
row writes a checkpoint and the sweep exits 75.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field

from .. import config, initial
from ..io import rundir
from ..errors import EXIT_RESTART, InputError, PackingFileError, StateFileError, SweepError

# table column -> (config key, the short name used in run directory names)
COLUMNS = {"mu": ("contact.mu", "mu"), "epsilon": ("contact.epsilon", "eps"), "k_n": ("contact.k_n", "kn"),
           "phi_i": ("pour.phi_i", "phi"), "seed": ("run.seed", "s"),
           "bed.seed": ("bed.seed", "bed")}     # "s1_bed101", not "s1_seed101"
VALUE = re.compile(r"^[A-Za-z0-9.+-]+$")
SUMMARY = os.path.join("analysis", "summary.json")


@dataclass
class Row:
    """One line of a sweep table.

    Attributes
    ----------
    table : str        the table's path
    line : int         row number in the table, 1 = the first after the header
    sets : list[str]   ``section.key=value`` items, in column order
    name : str         run directory name made from the values
    """
    table: str
    line: int
    sets: list
    name: str
    cost: float = 1.0          # relative wall time: spheres x steps per simulated time (N / dt)
    state: str = "todo"        # todo | running | done | not converged | failed | stopped
    reason: str = ""
    started: float = 0.0
    seconds: float = 0.0
    proc: object = field(default=None, repr=False)
    stage: str = ""            # "run" or "analyze" while running


def read_table(path):
    """The rows of one sweep table.

    Returns
    -------
    list of Row (cost 1; ``plan`` sets it from each row's config).

    Raises
    ------
    SweepError naming the table, the row and the value when a line does not fit the header.
    """
    try:
        with open(path) as fh:
            lines = [ln.rstrip("\r\n") for ln in fh]
    except OSError as e:
        raise SweepError(f"sweep table {path}: {e.strerror}") from None
    lines = [ln for ln in lines if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise SweepError(f"sweep table {path}: no header line (columns mu epsilon k_n phi_i seed, or section.key)")
    header = lines[0].split()
    keys, short = [], []
    for col in header:
        if col in COLUMNS:
            k, t = COLUMNS[col]
        elif "." in col:
            k, t = col, col.split(".", 1)[1]
        else:
            raise SweepError(f"sweep table {path}: unknown column {col!r} (mu epsilon k_n phi_i seed, or section.key)")
        if k not in config.KEYS:
            raise SweepError(f"sweep table {path}: column {col!r} is no config key; "
                             f"known keys: {', '.join(config.KEYS)}")
        keys.append(k)
        short.append(t)
    rows = []
    for n, ln in enumerate(lines[1:], start=1):
        vals = ln.split()
        if len(vals) != len(header):
            raise SweepError(f"sweep table {path} row {n}: {len(vals)} values for {len(header)} columns "
                             f"({ln.strip()!r})")
        for col, v in zip(header, vals):
            if not VALUE.match(v):
                raise SweepError(f"sweep table {path} row {n}: value {v!r} of {col}: "
                                 f"accepted letters, digits and . + -")
        rows.append(Row(path, n, [f"{k}={v}" for k, v in zip(keys, vals)],
                        "_".join(t + v for t, v in zip(short, vals))))
    if not rows:
        raise SweepError(f"sweep table {path}: a header but no rows")
    return rows


def plan(tables, config_path=None, sets=(), out=None):
    """Every row of ``tables``, checked against the config, cheapest first.

    Each row's config (``config_path`` or the built-in example, then ``sets``,
    then the row's values; an initial file's box and count, ``initial.config_for``) is resolved now, so a
    bad value stops the sweep before any run starts. Two rows naming the same run directory are an error.

    Parameters
    ----------
    out : str or None
        The sweep's directory of run directories. A row whose directory there is finished or has a
        checkpoint never reads its initial file again (it is analysed or restarted), so that file is not
        judged: a sweep goes on where the file has gone (moved, another machine).

    Returns
    -------
    list of Row, sorted by cost (N / dt) and then table order.
    """
    rows, seen = [], {}
    for t in tables:
        for r in read_table(t):
            if r.name in seen:
                raise SweepError(f"sweep: row {r.line} of {t} and row {seen[r.name][1]} of {seen[r.name][0]} "
                                 f"both make run directory {r.name}")
            seen[r.name] = (t, r.line)
            d = os.path.join(out, r.name) if out is not None else None
            begun = d is not None and (finished(d) or bool(rundir.checkpoints(d)))
            try:
                cfg = config.load_run_config(config_path, list(sets) + r.sets)
                if not begun:
                    # an initial file's box and count are the row's (a disagreement is refused now, not at the row)
                    cfg, _ = initial.config_for(cfg)
            except (config.ConfigError, InputError, StateFileError, PackingFileError) as e:
                raise SweepError(f"sweep table {t} row {r.line} ({r.name}): {e}") from None
            r.cost = ((ran_count(d) if begun else None) or cfg.pour.N) / cfg.integration.dt
            rows.append(r)
    return sorted(rows, key=lambda r: r.cost)


def ran_count(run_dir):
    """The sphere count a begun row's run recorded (its config.toml, written after its initial file's count
    was taken), or None where it is unreadable."""
    try:
        with open(os.path.join(run_dir, "config.toml")) as fh:
            return int(config.raw_from_toml(fh.read(), origin=fh.name)["pour.N"])
    except (OSError, KeyError, ValueError, config.ConfigError):
        return None


def finished(run_dir):
    """True when a run directory holds a finished run (final.h5 or its analysis)."""
    return os.path.exists(rundir.final_path(run_dir)) or os.path.exists(os.path.join(run_dir, SUMMARY))


def hms(sec):
    """Seconds as ``H:MM:SS``."""
    sec = int(round(sec))
    return f"{sec // 3600}:{sec // 60 % 60:02d}:{sec % 60:02d}"


def cores():
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


class Sweep:
    """Runs rows J at a time, each with R ranks of T threads, and reports progress.

    Parameters
    ----------
    rows : list of Row (from ``plan``)
    out : str              directory of the run directories
    config_path : str or None   config of the first segment of each row (None: the built-in example)
    sets : list of str     ``--set`` items before each row's own
    jobs, ranks, threads : int
    progress : float       seconds between progress lines while nothing else is said
    log : callable(str)
    """

    def __init__(self, rows, out, config_path=None, sets=(), jobs=1, ranks=1, threads=1,
                 progress=300.0, log=print):
        self.rows, self.out, self.config_path, self.sets = rows, out, config_path, list(sets)
        self.jobs, self.ranks, self.threads = jobs, ranks, threads
        self.progress, self.log = progress, log
        self.stopping = False
        self.t0 = time.monotonic()

    # ------------------------------------------------------------ commands
    def mpdem(self):
        """The command that starts mpdem: python, or the venv's mpiexec for R > 1 ranks."""
        py = [sys.executable, "-m", "mpdem"]
        if self.ranks == 1:
            return py
        here = os.path.join(os.path.dirname(sys.executable), "mpiexec")
        launcher = here if os.access(here, os.X_OK) else "mpiexec"
        return [launcher, "-n", str(self.ranks)] + py

    def command(self, row):
        """(stage, argv) of the next thing a row needs: run, restart or analyze."""
        d = self.dir(row)
        if finished(d):
            return "analyze", [sys.executable, "-m", "mpdem", "analyze", d, "--no-plots", "--quiet", "--packing"]
        # rows side by side are separate launches: each would bind its ranks to the same first cores
        threads = ["--threads", str(self.threads), "--quiet"] + (["--bind", "none"] if self.jobs > 1 else [])
        if rundir.checkpoints(d):
            # a restart keeps its run's config; the sweep's engine.device (if set) moves it, e.g. from a GPU to the CPU
            dev = [s.split("=", 1)[1].strip("\"'") for s in self.sets if s.split("=", 1)[0].strip() == "engine.device"]
            return "run", self.mpdem() + ["restart", d] + (["--device", dev[-1]] if dev else []) + threads
        argv = self.mpdem() + ["run"] + ([self.config_path] if self.config_path else []) + ["--out", d]
        for s in self.sets + row.sets:
            argv += ["--set", s]
        if os.path.exists(os.path.join(d, "config.toml")):
            argv.append("--force")   # a first segment that died before its first checkpoint
        return "run", argv + threads

    def dir(self, row):
        return os.path.join(self.out, row.name)

    # ------------------------------------------------------------ running
    def start(self, row):
        row.stage, argv = self.command(row)
        os.makedirs(self.dir(row), exist_ok=True)
        env = dict(os.environ, NUMBA_NUM_THREADS=str(self.threads))
        with open(os.path.join(self.dir(row), "sweep.log"), "a") as fh:
            fh.write(f"# {time.strftime('%Y-%m-%d %H:%M:%S')} {' '.join(argv)}\n")
            fh.flush()
            # its own session: a Ctrl-C at the terminal reaches the sweep only, which passes on a SIGUSR1
            row.proc = subprocess.Popen(argv, stdout=fh, stderr=subprocess.STDOUT, env=env,
                                        start_new_session=True)
        if not row.started:
            row.started = time.monotonic()
        row.state = "running"
        what = "restart from its checkpoint" if "restart" in argv else row.stage
        self.log(f"sweep: {row.name}: {what}")

    def reap(self, row, rc):
        """A row's process ended with exit code ``rc``: the row's next state."""
        row.proc = None
        if row.stage == "run" and rc in (0, 3) and not self.stopping:
            self.start(row)                     # on to its analysis
            return
        row.seconds = time.monotonic() - row.started
        if row.stage == "analyze" and rc == 0:
            row.state = "done" if self.converged(row) else "not converged"
        elif rc == EXIT_RESTART or (self.stopping and rc in (0, 3)):
            row.state = "stopped"
            row.reason = "checkpoint written" if rc == EXIT_RESTART else "not yet analysed"
        else:
            row.state, row.reason = "failed", self.why(row, rc)
        self.log(f"sweep: {row.name}: {row.state}" + (f" ({row.reason})" if row.reason else "")
                 + f" after {hms(row.seconds)}")

    def converged(self, row):
        import json
        try:
            with open(os.path.join(self.dir(row), SUMMARY)) as fh:
                return bool(json.load(fh).get("converged"))
        except (OSError, ValueError):
            return False

    def why(self, row, rc):
        """The reason a row failed: mpdem's error line from its sweep.log, else the exit code."""
        try:
            with open(os.path.join(self.dir(row), "sweep.log")) as fh:
                tail = fh.read()[-20000:].splitlines()
        except OSError:
            tail = []
        errs = [ln.strip() for ln in tail if "error" in ln.lower() and not ln.startswith("#")]
        what = f"{row.stage} exit {rc}" if rc >= 0 else f"{row.stage} killed by signal {-rc}"
        return f"{what}: {errs[-1]}" if errs else f"{what}; see {os.path.join(self.dir(row), 'sweep.log')}"

    def stop(self, signum, frame):
        if not self.stopping:
            self.log(f"sweep: {signal.Signals(signum).name}: stopping the running rows (each writes a checkpoint)")
        self.stopping = True
        for r in self.rows:
            if r.proc is not None and r.stage == "run":
                try:
                    os.killpg(r.proc.pid, signal.SIGUSR1)
                except ProcessLookupError:
                    pass

    def report(self):
        """One progress line: rows done, running, failed, to go, and an ETA from the rows finished so far."""
        states = ("done", "not converged", "running", "failed", "todo", "stopped")
        n = {s: sum(r.state == s for r in self.rows) for s in states}
        ran = [r for r in self.rows if r.seconds and r.state in ("done", "not converged")]
        left = [r for r in self.rows if r.state in ("todo", "running")]
        eta = "ETA after the first row"
        if ran:
            per_cost = sum(r.seconds for r in ran) / sum(r.cost for r in ran)
            rest = sum(r.cost for r in left if r.state == "todo")
            # a running row past its estimate still has some way to go: a tenth of it, say
            rest += sum(max(r.cost - (time.monotonic() - r.started) / per_cost, 0.1 * r.cost)
                        for r in left if r.state == "running")
            eta = f"ETA {hms(per_cost * rest / self.jobs)}"
        self.log(f"sweep: {n['done'] + n['not converged']}/{len(self.rows)} finished "
                 f"({n['not converged']} not converged), {n['running']} running, {n['failed']} failed, "
                 f"{n['todo']} to go" + (f", {n['stopped']} stopped" if n["stopped"] else "")
                 + f"; {hms(time.monotonic() - self.t0)} elapsed, {eta}")

    def run(self):
        """Run every row that is not finished. Returns 0, 1 (a row failed) or 75 (a row stopped
        with a checkpoint: run the sweep again to go on)."""
        for r in self.rows:
            if finished(self.dir(r)) and os.path.exists(os.path.join(self.dir(r), SUMMARY)):
                r.state = "done" if self.converged(r) else "not converged"
        skipped = sum(r.state != "todo" for r in self.rows)
        self.log(f"sweep: {len(self.rows)} rows in {self.out}, {skipped} already finished; "
                 f"{self.jobs} at a time, {self.ranks} rank(s) x {self.threads} thread(s) each")
        old = {s: signal.signal(s, self.stop) for s in (signal.SIGINT, signal.SIGTERM)}
        last = time.monotonic()
        try:
            while True:
                running = [r for r in self.rows if r.proc is not None]
                for r in running:
                    rc = r.proc.poll()
                    if rc is not None:
                        self.reap(r, rc)
                        last = 0.0
                if not self.stopping:
                    for r in self.rows:
                        if sum(q.proc is not None for q in self.rows) >= self.jobs:
                            break
                        if r.state == "todo":
                            self.start(r)
                if not any(r.proc is not None for r in self.rows):
                    break
                if time.monotonic() - last >= self.progress:
                    self.report()
                    last = time.monotonic()
                time.sleep(0.5)
        finally:
            for s, h in old.items():
                signal.signal(s, h)
        self.report()
        for r in self.rows:
            if r.state == "failed":
                self.log(f"sweep: failed: {r.name} ({r.table} row {r.line}): {r.reason}")
        if self.stopping or any(r.state == "stopped" for r in self.rows):
            return EXIT_RESTART
        return 1 if any(r.state == "failed" for r in self.rows) else 0


def default_jobs(ranks, threads):
    """J = cores / (R T), at least 1."""
    return max(1, cores() // (ranks * threads))
