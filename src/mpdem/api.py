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
import time
from dataclasses import dataclass, field

from .errors import EXIT_NOT_CONVERGED, EXIT_OK, EXIT_RESTART, AgreedError, MpdemError

# a run's status -> the exit status of ``python -m mpdem``
EXIT_OF = {"converged": EXIT_OK, "max_steps": EXIT_NOT_CONVERGED, "interrupted": EXIT_RESTART}


@dataclass
class RunRecord:
    """What a run or restart came to.

    Attributes
    ----------
    status : "converged", "max_steps" (at run.max_steps without converging) or
        "interrupted" (wall time or a stop signal: a checkpoint was written)
    steps : time steps taken in all
    digest : SHA-256 of the final state (sorted by id); None when interrupted
    final : path of the final state file (RUN/final.h5); None when interrupted
    out : the run directory
    summary : the run's summary.json as a dict (on every rank); {} when interrupted
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
    """The arrays of a state file by name (``x``, ``v``, ``omega``, ``id``, ``fixed`` (n, ...),
    sorted by id; ``id_i``, ``id_j``, ``delta``, ``F_n``, ``F_t`` of the contact list where the
    file has one; ``L_x``, ``L_y``), with the file's attributes in ``.attrs``."""

    def __init__(self, arrays, attrs):
        super().__init__(arrays)
        self["L_x"], self["L_y"] = float(attrs["L_x"]), float(attrs["L_y"])
        self.attrs = dict(attrs)


def load_config(path=None, **sets):
    """A resolved, validated config: the TOML file ``path``, or the built-in example without one.

    ``sets``: keys as in ``--set``, e.g. ``load_config(**{"contact.mu": 0.3})``.

    Raises
    ------
    ConfigError naming the key, the value and what is accepted.
    """
    from . import config
    return config.load_run_config(path, [f"{k}={config.toml_value(v)}" for k, v in sets.items()])


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
                          f"pass --force")


def run(config, out, threads=1, *, force=False, quiet=True, walltime=None, walltime_margin=None, net=None,
        t_start=None, signals=None):
    """A new run of ``config`` in directory ``out``, in this process (one rank of an mpiexec launch).

    Parameters
    ----------
    config : Config (``load_config``)
    out : run directory (created)
    threads : numba threads of this process
    force : reuse an ``out`` that holds a run
    quiet : progress to RUN/log.txt only (else also to stdout)
    walltime, walltime_margin : seconds; stop with a checkpoint before the limit
    net : mpi4py communicator or ``parallel.Channel``; default MPI's COMM_WORLD

    Returns
    -------
    RunRecord
    """
    from . import config as config_mod
    from .io import lammps
    from .build import InputError
    from .driver.schedule import Logger
    from .driver.simulation import Run
    _threads(threads)
    net = _net(net)
    from .initial import check_file
    try:
        cfg, initial = lammps.initial_for(config)
        check_file(cfg)
    except (config_mod.ConfigError, InputError) as e:   # the same inputs on every rank: the same error
        raise AgreedError(str(e)) from None
    if cfg.engine.device == "gpu":
        from .engine import gpu
        gpu.require()       # no GPU here: one line, before the run directory is made

    def go(held):
        if held is not None and held.taken_over:
            say = Logger(os.path.join(out, "log.txt"), quiet, net.rank)
            say.warn(held.taken_over)
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

    ``sets``: restart keys (``run.max_steps``, ``stop.*``, ``output.*``, ...) by name, e.g.
    ``**{"run.max_steps": 4000000}``; ``set_items``: the same as ``--set`` texts.
    A run with nothing to do (converged; final at its cap) returns its result unchanged.

    Returns
    -------
    RunRecord
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
        say = Logger(os.path.join(t.run_dir, "log.txt"), quiet, net.rank)
        if held is not None and held.taken_over:
            say.warn(held.taken_over)
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
    s = net.on_root(read) or {}
    name = "converged" if status == EXIT_OK else "max_steps"
    return RunRecord(name, int(s.get("steps", t.attrs["step"])), s.get("digest"), t.path, t.run_dir, s)


def read_state(path):
    """The arrays and attributes of a state file (or a packing file), on one process.

    Returns
    -------
    StateArrays: a dict of arrays sorted by id, with ``.attrs``

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
    state_or_path : a StateArrays (``read_state``), a state or packing file, or a run directory
    write : also write the summary and tables (and ``plots``) as ``mpdem analyze`` does, into ``out``
        (default RUN/analysis)
    sets : ``analysis.*`` keys, e.g. ``**{"analysis.margin_bottom": 5}``

    Returns
    -------
    dict: the summary (as RUN/analysis/summary.json) and ``arrays``: ``g_r`` (r, g),
    ``g_xi`` (xi, g), ``P_z`` (n, P), ``P_zeta`` (zeta, P) where measured, ``bands`` (the depth profile)
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

    ``out``: also keep the files (CSV, JSON, figures, README.md) there; without it they are made in a
    temporary directory and removed.

    Returns
    -------
    dict: ``runs`` and ``sets`` (one dict per row of runs.csv and sets.csv), ``fits`` (fits.json),
    ``skipped`` (runs left out, with the reason)
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
