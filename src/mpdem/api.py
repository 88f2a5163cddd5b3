"""The Python API: ``import mpdem`` (docs/python.md). The command line is built on it.

::

    cfg = mpdem.load_config(**{"pour.N": 200, "run.max_steps": 20000})
    r = mpdem.run(cfg, out="runs/small")          # serially, or one rank of an mpiexec launch
    r.status, r.steps, r.digest, r.final
    s = mpdem.read_state(r.final)                 # s["x"], s["id_i"], s["F_n"], s.attrs ...
    a = mpdem.analyze(r.final)                    # a["z"], a["arrays"]["g_r"] ...

Every function raises an exception of ``mpdem.errors`` (``MpdemError`` and its
kinds) on bad input or a damaged file; nothing exits the process. Under
mpiexec, ``run`` and ``restart`` are collective: every rank calls them with
the same arguments.
"""
from __future__ import annotations

import os
import signal
import time
from dataclasses import dataclass, field

from .errors import EXIT_NOT_CONVERGED, EXIT_OK, EXIT_RESTART, AgreedError, MpdemError

# the public API (``mpdem.API``; docs/reference.md documents each); ``lock``, ``check_out`` are the CLI's
__all__ = ["load_config", "run", "restart", "stiffen_config", "read_state", "analyze", "collect", "RunRecord",
           "StateArrays"]

# a run's status -> the exit status of ``python -m mpdem``
EXIT_OF = {"converged": EXIT_OK, "max_steps": EXIT_NOT_CONVERGED, "interrupted": EXIT_RESTART}


@dataclass
class RunRecord:
    """What a run or restart came to.

    Attributes
    ----------
    status : str
        "converged" (the stop rule held), "max_steps" (at run.max_steps without converging) or
        "interrupted" (wall time or a stop signal: a checkpoint was written; ``restart`` goes on).
    steps : int
        Time steps taken in all (of ``integration.dt`` [tau] each).
    digest : str or None
        SHA-256 of the final state (sorted by id; equal for any rank count, thread count, engine and
        restarts); None when interrupted.
    final : str or None
        Path of the final state file (``out/final.h5``); None when interrupted.
    out : str
        The run directory.
    summary : dict
        The run's summary.json (on every rank): steps, wall time [s], digest and the bulk's z, phi,
        P(z); {} when interrupted.
    """
    status: str
    steps: int
    digest: str | None
    final: str | None
    out: str
    summary: dict = field(default_factory=dict, repr=False)

    @property
    def exit_status(self):
        """The exit status ``python -m mpdem`` gives this result (0, 3 or 75)."""
        return EXIT_OF[self.status]


class StateArrays(dict):
    """The arrays of a state file by name, sorted by id, with the file's attributes in ``.attrs``.

    Particles (n of them, bed included): ``x`` (n, 3) positions [d], ``v`` (n, 3) velocities
    [sqrt(g d)], ``omega`` (n, 3) angular velocities [1/tau], ``f`` (n, 3) forces [m g], ``torque``
    (n, 3) [m g d], ``id`` (n,), ``fixed`` (n,) (1 for a frozen bed sphere), and the contact slots
    the engine keeps (``count``, ``partner``, ``ds``). Contacts (m of them, where the file has a
    contact list): ``id_i``, ``id_j`` (m,) the pair's ids, ``delta`` (m,) overlap [d], ``F_n`` (m,)
    normal force [m g] (compressive > 0), ``F_t`` (m, 3) tangential force [m g], ``ds_i`` (m, 3)
    tangential spring [d]. The box: ``L_x``, ``L_y`` [d] (floats).
    """

    def __init__(self, arrays, attrs):
        super().__init__(arrays)
        self["L_x"], self["L_y"] = float(attrs["L_x"]), float(attrs["L_y"])
        self.attrs = dict(attrs)


def load_config(path=None, **sets):
    """A resolved, validated config: the TOML file ``path``, or the built-in example without one.

    Parameters
    ----------
    path : str or None
        A TOML config file (docs/config.md: every key, its default and its unit); None: the built-in
        example (``src/mpdem/example.toml``: 1500 spheres in a 10 d x 10 d box, mu = 0.5).
    **sets
        Keys as ``--set`` takes them, by name, over the file's: ``load_config(**{"contact.mu": 0.3,
        "pour.N": 200, "run.max_steps": 1_000_000})``. Values in reduced units (lengths [d], times
        [tau], spring constants [m g / d], energies [m g d]).

    Returns
    -------
    Config
        Every key resolved (derived ones such as ``contact.k_t`` and ``integration.dt`` filled in);
        read as attributes, ``cfg.contact.mu``.

    Raises
    ------
    ConfigError
        Naming the key, the value and what is accepted (an unknown key, a value out of range).
    """
    from . import config
    try:
        return config.load_run_config(path, [f"{k}={config.toml_value(v)}" for k, v in sets.items()])
    except config.ConfigError as e:
        # the keys came as keywords, not as the command line's --set items: say so
        if str(e).startswith("--set "):
            raise config.ConfigError(f"load_config key {str(e)[len('--set '):]}") from None
        raise


def _net(net):
    from .parallel import channel, world
    return world() if net is None else channel(net)


def _threads(n):
    """Use ``n`` numba threads here (None: leave them); a count numba's pool cannot give is a ThreadsError."""
    if n is not None:
        from .threads import configure
        configure(n)


def _result(run, summary):
    """The RunRecord of a Run after ``run()`` (and ``finish()``), on every rank."""
    net = run.domain.net
    summary = net.bcast(summary if run.rank == 0 else None)
    if run.status == "interrupted":
        return RunRecord("interrupted", int(run.state.step), None, None, run.out, {})
    from .io import rundir
    return RunRecord(run.status, int(summary["steps"]), summary["digest"], rundir.final_path(run.out),
                     run.out, summary)


def _go(run):
    """Run to the end (final state) or to an early stop (checkpoint); the RunRecord."""
    if run.run() == "interrupted":
        run.log.close()
        if run.stop_signal == signal.SIGINT and run.python_caller:
            # Python's word for Ctrl-C, after the checkpoint: a loop over runs stops here too
            raise KeyboardInterrupt(f"{run.out}: stopped by SIGINT at step {run.state.step} with a checkpoint; "
                                    f"mpdem.restart({run.out!r}) goes on")
        return _result(run, None)
    return _result(run, run.finish())


def lock(run_dir, net):
    """The run directory's lock (``rundir.RunLock``), taken by rank 0 for every rank.

    Raises
    ------
    AgreedError on every rank, naming the holder, when another process writes ``run_dir``.
    """
    from .io.rundir import RunLock
    held = RunLock(run_dir) if net.rank == 0 else None
    why = net.on_root(lambda: held.acquire())
    if why:
        raise AgreedError(f"{run_dir}: {why}")
    return held


def _locked(run_dir, net, go):
    """``go(lock)`` with the run directory locked; the lock released however it ends."""
    held = lock(run_dir, net)
    try:
        return go(held)
    finally:
        if held is not None:
            held.release()


def check_out(out, net, force=False):
    """Refuse a run directory that cannot be written, or that holds a run (unless ``force``).

    Rank 0 looks, before any rank can write there; every rank raises the same AgreedError.
    """
    from .io.rundir import writable
    held, why = net.on_root(lambda: (os.path.exists(os.path.join(out, "config.toml")), writable(out)))
    if why:
        raise AgreedError(f"--out {out}: {why}")
    if held and not force:
        raise AgreedError(f"--out {out}: already holds a run (config.toml); choose another directory or "
                          f"overwrite it (--force; force=True from Python)")


def run(config, out, threads=1, *, force=False, quiet=True, walltime=None, walltime_margin=None, net=None,
        t_start=None, signals=None):
    """A new run of ``config`` in directory ``out``, in this process (one rank of an mpiexec launch).

    The bed is made (or taken from the bed cache), the spheres poured and stepped until the stop
    rule holds (``status`` "converged") or ``run.max_steps`` (``status`` "max_steps"); the final
    state, its summary and the run's log are written into ``out`` (README.md, the run directory).

    Parameters
    ----------
    config : Config
        From ``load_config`` (or ``stiffen_config``).
    out : str
        The run directory; made if missing.
    threads : int or None
        Numba threads of this process (None: leave them as they are).
    force : bool
        Reuse an ``out`` that holds a run (its files are overwritten).
    quiet : bool
        Progress to ``out/log.txt`` only (else also to stdout).
    walltime : float or None
        Wall-clock limit [s] counted from the call (or from ``t_start``): a checkpoint is written and
        the run returns "interrupted" before it.
    walltime_margin : float or None
        Seconds kept free before ``walltime`` besides twice the last checkpoint write [s]
        (default min(60, walltime / 20)).
    net : mpi4py communicator, ``parallel.Channel`` or None
        The ranks of the run; None: MPI's COMM_WORLD (one rank when not launched by mpiexec).
    t_start : float or None
        ``time.monotonic()`` at which ``walltime`` starts counting (default: now).
    signals : object or None
        The command line's signal flags (SIGTERM, SIGUSR1: checkpoint and stop); None: none.

    Returns
    -------
    RunRecord

    Raises
    ------
    MpdemError
        A directory that holds a run (without ``force``) or cannot be written, an initial file that
        cannot be used, ``engine.device = "gpu"`` without a usable GPU (``DeviceError``): before any
        work, leaving no run directory behind.
    """
    from . import config as config_mod
    from .build import InputError
    from .driver.schedule import Logger
    from .driver.simulation import Run
    _threads(threads)
    net = _net(net)
    from .errors import PackingFileError, StateFileError
    from .initial import check_file, config_for
    try:
        cfg, initial = config_for(config, net)
        check_file(cfg)
    except (config_mod.ConfigError, InputError, StateFileError, PackingFileError) as e:
        # the same inputs on every rank: the same error
        raise AgreedError(str(e)) from None
    if cfg.engine.device == "gpu":
        from .engine import gpu
        gpu.require()       # no GPU here: one line, before the run directory is made
    # a grid that is not these ranks', or a run that cannot fit in memory: one line on every rank, before
    # the run directory is made
    from . import domains, footprint
    if cfg.decomp.grid:
        domains.check(cfg.decomp.grid, net.size)
    memory_line = footprint.check(cfg, net, footprint.initial_count(cfg, initial))

    def go(held):
        say = Logger(os.path.join(out, "log.txt"), quiet, net.rank)
        if held is not None and held.taken_over:
            say.warn(held.taken_over)
        say(memory_line)
        say.close()
        r = Run.new(cfg, out, net, lammps_initial=initial, quiet=quiet, walltime=walltime, margin=walltime_margin,
                    t_start=time.monotonic() if t_start is None else t_start, signals=signals)
        return _go(r)
    existed = net.on_root(os.path.exists, out)
    try:
        check_out(out, net, force)
        return _locked(out, net, go)
    except BaseException:
        if not existed and net.rank == 0:
            _remove_bare(out)
        raise


def _remove_bare(out):
    """Remove the run directory ``out`` that this call made if a refusal left nothing in it but its
    lock: a run refused before it starts leaves nothing behind (a log, or anything more, stays)."""
    try:
        if set(os.listdir(out)) <= {".lock"}:
            for name in os.listdir(out):
                os.remove(os.path.join(out, name))
            os.rmdir(out)
    except OSError:
        pass


def restart(out, threads=1, *, quiet=True, walltime=None, walltime_margin=None, net=None, t_start=None,
            signals=None, set_items=(), **sets):
    """Go on with the run in directory (or from state file) ``out``, from its newest valid file.

    A restart continues exactly: K steps, restart, K more give the digest of 2K straight, on any
    rank count and either engine. A run with nothing to do (converged; final at its cap) returns its
    result unchanged.

    Parameters
    ----------
    out : str
        A run directory (its newest valid checkpoint or final state), or a state file in one.
    threads, quiet, walltime, walltime_margin, net, t_start, signals
        As for ``run``.
    set_items : sequence of str
        Restart keys as ``--set`` texts, ``["run.max_steps=4000000"]``.
    **sets
        Restart keys by name (``run.max_steps``, ``stop.*``, ``output.*``, ``engine.device``, ...:
        the keys marked "restart" in docs/config.md), e.g. ``**{"run.max_steps": 4_000_000}``.

    Returns
    -------
    RunRecord

    Raises
    ------
    MpdemError
        No state file to go on from, a key that a restart may not change, a run directory that
        another process writes (its ``.lock``).
    """
    from . import config
    from .driver import resume as rs
    from .driver.schedule import Logger
    from .driver.simulation import Run
    _threads(threads)
    net = _net(net)
    items = list(set_items) + [f"{k}={config.toml_value(v)}" for k, v in sets.items()]
    run_dir = net.on_root(rs.run_dir_of, out, catch=MpdemError)

    def go(held):
        # the files are chosen and read under the lock: no other writer can change them meanwhile
        t = rs.open_target(out, net, items)
        rs.check_room(t, net)
        # a grid that is not these ranks', or a pile that cannot fit on them: one line on every rank, before
        # its arrays are made
        from . import domains, footprint
        if t.cfg.decomp.grid:
            domains.check(t.cfg.decomp.grid, net.size)
        n = int(t.attrs["n"])
        memory_line = footprint.check(t.cfg, net, n, label=f"{n} spheres of {t.path}")
        say = Logger(os.path.join(t.run_dir, "log.txt"), quiet, net.rank)
        if held is not None and held.taken_over:
            say.warn(held.taken_over)
        say(memory_line)
        status = rs.verdict(t, say)
        say.close()
        if status is not None:
            return _finished(t, status, net)
        r = Run.from_file(t, net, quiet=quiet, walltime=walltime, margin=walltime_margin,
                          t_start=time.monotonic() if t_start is None else t_start, signals=signals)
        return _go(r)
    return _locked(run_dir, net, go)


def _finished(t, status, net):
    """The RunRecord of a run with nothing left to do (``resume.verdict``'s exit ``status``):
    its summary.json, or, without one, what its state file says."""
    import json

    def read():
        try:
            with open(os.path.join(t.run_dir, "summary.json")) as fh:
                return json.load(fh)
        except (OSError, ValueError):
            return None
    name = "converged" if status == EXIT_OK else "max_steps"
    s = net.on_root(read)
    if s is None and t.attrs.get("kind") == "final":
        # the run ended between its final state and its summary: written now, from the state
        from .driver import summary
        s = net.on_root(lambda: summary.recover(t.run_dir, t.path, name))
    s = s or {}
    return RunRecord(name, int(s.get("steps", t.attrs["step"])), s.get("digest"), t.path, t.run_dir, s)


def stiffen_config(run, k_n, **sets):
    """The config that stiffens the finished run ``run`` to the stiffer ``k_n`` (``mpdem stiffen``).

    The new run starts from ``run``'s final state; k_n rises geometrically from the run's to ``k_n``
    over ``stiffen.ramp_time`` (k_t, gamma_n and each tangential spring following), then the stop
    rule settles the pile again (docs/model.md 6.6). Run it with ``run(cfg, out)``.

    Parameters
    ----------
    run : str
        A finished run's directory (its ``config.toml`` and ``final.h5``; or ``packing.npz``, for a
        frictionless pile).
    k_n : float
        The new ``contact.k_n`` [m g / d], above the run's by at most ten times (a rung; stiffen the
        result again for more).
    **sets
        Keys by name over the run's own, as for ``load_config``: ``run.max_steps``,
        ``stiffen.ramp_time`` [tau], ``stop.E_stop`` [m g d], ...

    Returns
    -------
    Config

    Raises
    ------
    InputError
        ``run`` without a final state, or ``k_n`` not above the run's by at most ten times.
    ConfigError
        From the config's own checks.
    """
    from . import config, stiffen
    items = [f"{k}={config.toml_value(v)}" for k, v in sets.items()]
    return stiffen.rung_config(os.fspath(run), float(k_n), items)


def read_state(path):
    """The arrays and attributes of a state file (or a packing file), on one process.

    Parameters
    ----------
    path : str
        An mpdem state file (``final.h5``, a checkpoint or snapshot) or a run's ``packing.npz``.

    Returns
    -------
    StateArrays
        A dict of arrays sorted by id (positions [d], velocities [sqrt(g d)], ...), with ``.attrs``.

    Raises
    ------
    StateFileError (or PackingFileError) naming the file when it is damaged or not one.
    """
    from .io import checkpoint, packing
    if packing.is_packing(path):
        return StateArrays(*packing.read(path))
    return StateArrays(*checkpoint.read_state(path, pairs=True))


def analyze(state_or_path, *, write=False, out=None, plots=False, **sets):
    """The measurements of ``mpdem analyze`` (docs/analysis.md) of one packing.

    Parameters
    ----------
    state_or_path : StateArrays or str
        A StateArrays (``read_state``), a state or packing file, or a run directory.
    write : bool
        Also write the summary and tables (and ``plots``) as ``mpdem analyze`` does, into ``out``.
    out : str or None
        Where ``write`` writes (default RUN/analysis).
    plots : bool
        With ``write``: the figures too (PNG by default, ``analysis.figure_format``).
    **sets
        ``analysis.*`` keys by name, e.g. ``**{"analysis.margin_bottom": 5}`` (lengths [d]).

    Returns
    -------
    dict
        The summary (as RUN/analysis/summary.json: ``z``, the mean contacts per sphere of the bulk;
        ``phi``, its packing fraction; ``h``, the free surface [d]; ``backbone``, ``alpha``, ...
        docs/analysis.md) and ``arrays``: ``g_r`` (r [d], g), ``g_xi`` (xi = r/d - 1, g), ``P_z``
        (n, P), ``P_zeta`` (zeta, P) where measured, ``bands`` (the depth profile: ``depth_lo``,
        ``depth_hi`` [d], ``z``, ``phi``, ... per band).

    Raises
    ------
    AnalysisError
        A packing too small or too short for what is asked, a file that is not a state.
    """
    from .analysis import report
    from .config import toml_value
    items = [f"{k}={toml_value(v)}" for k, v in sets.items()]
    if isinstance(state_or_path, StateArrays):
        if write:
            raise MpdemError("analyze(write=True) needs a file or a run directory, not a StateArrays")
        arrays = {k: v for k, v in state_or_path.items() if k not in ("L_x", "L_y")}
        attrs = state_or_path.attrs
        s, tables = report.summarise(arrays, attrs, report.file_config(attrs, "the state", items), "a StateArrays")
    else:
        path, where = report.locate(str(state_or_path), out)
        arrays, attrs, cfg = report.read(path, items)
        s, tables = report.summarise(arrays, attrs, cfg, os.path.abspath(path))
        if write:
            report.write(where, s, tables, plots, log=lambda m: None)
    return dict(s, arrays=report.arrays_of(s, tables))


def collect(paths, out=None):
    """The tables of ``mpdem collect`` over the runs in ``paths``, as lists of dicts.

    Runs of one parameter set (equal physics but the seed) are pooled: mean and standard error of
    z, phi, ... over the seeds; a run without an analysis is analysed first.

    Parameters
    ----------
    paths : str or sequence of str
        Run directories, or directories holding them (a sweep's ``--out``).
    out : str or None
        Also keep the files (CSV, JSON, the paper's figures such as ``fig2_z_vs_mu.png``,
        README.md) there; None: they are made in a temporary directory and removed.

    Returns
    -------
    dict
        ``runs`` and ``sets`` (one dict per row of runs.csv and sets.csv, values as text: e.g.
        ``float(row["z_mean"])``), ``fits`` (fits.json), ``skipped`` (runs left out, with the reason).

    Raises
    ------
    AnalysisError
        No usable runs in ``paths``.
    """
    import csv
    import json
    import tempfile
    from .campaign import collect as co
    paths = [paths] if isinstance(paths, (str, os.PathLike)) else list(paths)
    with tempfile.TemporaryDirectory() as tmp:
        where = out or tmp
        res = co.collect([str(p) for p in paths], where, analyze_missing=True, log=lambda m: None)
        tables = {}
        for name in ("runs", "sets"):
            with open(os.path.join(where, f"{name}.csv"), newline="") as fh:
                tables[name] = list(csv.DictReader(fh))
        with open(os.path.join(where, "fits.json")) as fh:
            tables["fits"] = json.load(fh)
    return dict(tables, skipped=res["skipped"])
