"""A pile run: built new or from a state file, stepped with its schedules, finished.

Owns the run directory (``rundir`` gives its layout) and the time-step loop
of ARCHITECTURE.md. A restart is a run built from a file: ``Run.new`` and
``Run.from_file`` differ only in where the rows and the restart records
(``runstate.RunState``) come from (``new_start``, ``file_start``). What
happens between steps is in ``schedule`` (checks, stop rule and thermo,
progress, checkpoints, snapshots); the initial state is ``initial``'s, the
arithmetic of a step ``engine``'s, the files ``checkpoint``'s, choosing the
file to restart from ``resume``'s, and the closing summary ``summary``'s.
"""
from __future__ import annotations

import dataclasses
import math
import os
import signal
import threading
import time
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .. import flowarrest, initial, memory, stiffen, threads
from ..watch import Watch
from ..io import tables
from ..io import checkpoint
from . import spin, summary
from ..io import rundir
from ..config import collision_time
from ..decomp import Domain
from ..engine import gpu_options, make_engine
from ..engine import require as require_device
from ..engine.base import Physics
from .._version import __version__
from ..errors import EXIT_RESTART, WriteError
from ..pairs import contact_pairs
from .runstate import History, RunState
from .schedule import Checkpoints, Checks, Logger, Progress, Snapshots, StopRule, Thermo, quiet_span
from ..state import State

# the signals that stop a stepping run early with a checkpoint and exit status EXIT_RESTART
# ("not finished, restart me", EX_TEMPFAIL); SIGINT (Ctrl-C) among them, a second one stops at once
STOP_SIGNALS = (signal.SIGTERM, signal.SIGUSR1, signal.SIGINT)
# steps an engine may run in one go between the driver's looks at signals and the wall clock (``run_quiet``)
QUIET_MOST = 2000
# and at most this many sphere-steps of this rank's rows (a few seconds: a stop signal is honoured
# within seconds however large the pile)
QUIET_ROW_STEPS = 40_000_000


class StepFlags(NamedTuple):
    """This rank's requests at a step, agreed by max over ranks in the step's one allreduce
    (``Engine.step`` returns the agreed record in ``StepInfo.flags``)."""
    signal: float = 0.0         # the highest stop signal number received (0: none)
    walltime: float = 0.0       # 1: the wall time is near: stop with a checkpoint
    clock: float = 0.0          # 1: a clock checkpoint (output.checkpoint_seconds) is due


@dataclass
class Start:
    """Where a run begins (``new_start``, ``file_start``).

    Attributes
    ----------
    state : State
        This rank's rows, at the first step.
    n_mobile, n_bed : int
        Spheres of the whole pile.
    records : runstate.RunState
        The restart records: a new run's defaults, or a state file's (segments counted on).
    from_file : bool
        The rows carry the forces, torques and contact histories of a state file.
    """
    state: State
    n_mobile: int
    n_bed: int
    records: RunState
    from_file: bool


def new_start(cfg, out, domain, log, lammps_initial=None, watch=None):
    """A new run: build or read the initial state, check it, write config.toml and bed.txt.

    ``lammps_initial``: a LAMMPS ``run.initial_file`` already read (``lammps.initial_for``).
    ``watch``: the set-up's ``watch.Watch`` (progress lines, stop signals).
    Returns a Start.
    """
    watch = watch or Watch(log, domain.net)
    for w in cfg.warnings:
        log.warn(w)
    if domain.rank == 0:
        rundir.write_atomic(os.path.join(out, "config.toml"), cfg.to_toml())
        rundir.clear(out)
    init = initial.initial_state(cfg, domain.net, log, lammps_initial, watch=watch)
    w = init.whole
    if init.n_bed and domain.rank == 0:
        if init.shared:     # a tiled pour's bed: ids after the N mobile spheres', in the bed's order
            tables.write_table(os.path.join(out, "bed.txt"), init.n_mobile + np.arange(init.n_bed, dtype=np.int64),
                               init.bed.x, fixed=np.ones(init.n_bed, np.uint8))
        else:
            bed = w["fixed"] == 1
            tables.write_table(os.path.join(out, "bed.txt"), w["id"][bed], w["x"][bed], fixed=w["fixed"][bed])
    watch(everywhere=True)
    watch.begin("the distribution of the rows",
                f"set-up: {init.n_mobile + init.n_bed} spheres to {domain.size} rank(s)")
    if init.shared:     # each rank holds a share: the rows travel to their owners
        st = domain.distribute(w, cfg.box.L_x, cfg.box.L_y)
    else:
        st = domain.scatter(w, cfg.box.L_x, cfg.box.L_y)
    return Start(st, init.n_mobile, init.n_bed, RunState(pile=init.pile), False)


def file_start(t, out, domain, log):
    """The next segment of a run from state file ``t`` (``resume.Target``).

    Distributes the file's rows to the slab owners, counts the segment on,
    rewrites config.toml (a --set may have changed it) and cuts thermo.csv
    back to the file's step. Returns a Start.
    """
    attrs, rec = t.attrs, t.records
    rec = dataclasses.replace(rec, history=dataclasses.replace(rec.history, segments=rec.history.segments + 1))
    st = domain.distribute(t.local, float(attrs["L_x"]), float(attrs["L_y"]))
    st.step, st.time = int(attrs["step"]), float(attrs["time"])
    if domain.rank == 0:
        rundir.write_atomic(os.path.join(out, "config.toml"), t.cfg.to_toml())
        rundir.truncate_thermo(os.path.join(out, "thermo.csv"), st.step)
    log(f"restart: from {t.path} at step {st.step} (t = {st.time:.6g}), segment {rec.history.segments}, "
        f"{domain.size} rank(s) (written by {attrs.get('ranks', '?')})")
    for w in t.cfg.warnings:
        log.warn(w)
    return Start(st, int(attrs["n_mobile"]), int(attrs["n_bed"]), rec, True)


class Run:
    """One pile run in ``out_dir``: a new one (``Run.new``) or the next segment of one (``Run.from_file``).

    Parameters
    ----------
    cfg : Config
    out_dir : str
        The run directory (``rundir``).
    net : parallel.Channel, mpi4py communicator or None
    target : resume.Target or None
        The state file to go on from (``resume.open_target``); None for a new run of ``cfg``.
    lammps_initial : dict or None
        A new run's LAMMPS ``run.initial_file``, already read (``lammps.initial_for``).
    quiet : bool
        No progress on stdout (the log file still gets it).
    walltime : float or None
        Seconds this process may run, counted from ``t_start``; the run
        writes a checkpoint and stops (status "interrupted") before it.
    margin : float or None
        Seconds kept free before the wall time, besides twice the last
        checkpoint's write time; default min(60, walltime / 20).
    t_start : float or None
        ``time.monotonic()`` at the start of the program.
    signals : list or None
        Stop signals received so far (the CLI records them from its start);
        the run appends the ones it receives.
    """

    def __init__(self, cfg, out_dir, net=None, *, target=None, lammps_initial=None, quiet=False, walltime=None,
                 margin=None, t_start=None, signals=None):
        self.cfg, self.out = cfg, out_dir
        # a device that cannot run is one line before any work
        require_device(cfg.engine.device)
        # the process's threads and allocator, for this run's engines (the bed's and the pile's)
        threads.apply()
        memory.return_freed_memory()
        self.domain = Domain.from_config(net, cfg)
        self.rank = self.domain.rank
        if self.rank == 0:
            for d in (out_dir, os.path.join(out_dir, rundir.CKPT_DIR)):
                os.makedirs(d, exist_ok=True)
        self.log = Logger(os.path.join(out_dir, "log.txt"), quiet, self.rank)
        self.physics = Physics.from_config(cfg)
        t_start = time.monotonic() if t_start is None else t_start
        self.t_end = None if walltime is None else t_start + walltime
        self.margin = (min(60.0, walltime / 20) if margin is None else margin) if walltime else 0.0
        self.signals = [] if signals is None else signals
        # a Python caller (no command line's signal list) gets KeyboardInterrupt after a Ctrl-C's checkpoint
        self.python_caller = signals is None
        # the signal the ranks agreed to stop on (0: none, or the wall time)
        self.stop_signal = 0
        # the set-up's watch (``watch``): progress lines and stop signals until the first step
        again = (f"restart it again (`python -m mpdem restart {out_dir}`)" if target is not None
                 else "start the run again (with --force to reuse its directory)")
        self.watch = Watch(self.log, self.domain.net, self.signals, again=again).__enter__()
        try:
            self._set_up(cfg, out_dir, target, lammps_initial)
        except BaseException:
            self.watch.__exit__()
            raise

    def _set_up(self, cfg, out_dir, target, lammps_initial):
        """The constructor's part that makes the rows, the schedules and the engine (under the watch)."""
        start = (file_start(target, out_dir, self.domain, self.log) if target is not None
                 else new_start(cfg, out_dir, self.domain, self.log, lammps_initial, self.watch))
        rec = start.records
        self.state, self.n_mobile, self.n_bed = start.state, start.n_mobile, start.n_bed
        self.from_file = start.from_file
        self.first_step = self.state.step   # this segment's first step
        self.pile = rec.pile
        self.history = rec.history          # the earlier segments' (this one's are added by ``records``)
        self.stop = StopRule.from_config(cfg, self.physics.dt)
        self.stop.restore(rec.stop)
        self.checkpoints = Checkpoints(out_dir, cfg.output, self._write, self.domain, self.log)
        self.checkpoints.restore(rec.checkpoints)
        self.snapshots = Snapshots(out_dir, cfg.output.snapshot_every, self._write, self.rank)
        self.snapshots.restore(rec.snapshots)
        self.checks = Checks(cfg, self.pile, self.n_bed, self.log)
        self.thermo = Thermo(out_dir, self.rank)
        self.engine = make_engine(self.state, self.physics, self.domain, cfg.engine.device,
                                  **gpu_options(cfg.engine))
        # laws that change with the step: a stiffening ramp (``stiffen``) or a flow phase (``flowarrest``; the
        # config allows one of them), None without; the engine's law is the step's
        self.schedule = (stiffen.Ramp.from_config(cfg, self.physics.law)
                         or flowarrest.FlowPhase.from_config(cfg, self.physics.law))
        self._law_at(self.state.step)
        self.status = None          # "converged", "max_steps" or "interrupted"
        self.t0 = time.perf_counter()   # the loop's clock (started again when the loop starts)
        self.wall = 0.0             # the loop's wall time [s]
        self.comm_seconds = 0.0     # the loop's seconds in communication [s]
        self.ek = math.nan          # E_k per mobile sphere at the end of the loop [m g d]
        self.force_ratio = math.nan  # the unbalanced-force ratio of the last sample (summary.json)
        self._describe()

    @classmethod
    def new(cls, cfg, out_dir, net=None, lammps_initial=None, **options):
        """A new run of ``cfg`` in ``out_dir`` (its initial state built or read; config.toml written).

        ``options``: the keywords of ``Run`` (quiet, walltime, margin, t_start, signals).
        """
        return cls(cfg, out_dir, net, lammps_initial=lammps_initial, **options)

    @classmethod
    def from_file(cls, target, net=None, **options):
        """The next segment of the run of state file ``target`` (``resume.Target``), in its run directory."""
        return cls(target.cfg, target.run_dir, net, target=target, **options)

    @property
    def converged(self):
        return self.status == "converged"

    def _describe(self):
        """The log lines that describe the run."""
        p, law, cfg = self.physics, self.physics.law, self.cfg
        t_col = collision_time(law.gamma_n, law.k_n)
        self.log(f"mpdem: {self.n_mobile} mobile + {self.n_bed} bed spheres, box {cfg.box.L_x:g} x {cfg.box.L_y:g}, "
                 f"{cfg.contact.model} k_n = {law.k_n:g}, k_t = {law.k_t:g}, gamma_n = {law.gamma_n:.6g} "
                 f"(epsilon = {cfg.contact.epsilon:.4g}), gamma_t = {law.gamma_t:g}, mu = {law.mu:g}")
        self.log(f"mpdem: dt = {p.dt:.6g} (t_col / dt = {t_col / p.dt:.1f}), skin = {p.skin:g}, "
                 f"E_stop = {cfg.stop.E_stop:.3g} ({cfg.stop.rule}), max_steps = {cfg.run.max_steps}, "
                 f"seed = {cfg.run.seed}, ranks = {self.domain.size}"
                 + (f" (grid {' x '.join(map(str, self.domain.grid))})" if self.domain.parallel else "")
                 + (", each bound to its own core(s)" if threads.BOUND else ""))
        if self.schedule:
            self.log(self.schedule.describe(p.dt))

    def _law_at(self, step):
        """Give the engine the law of the force evaluation at ``step`` (the schedule's; the config's
        without one or past it). A new Physics only when the law changes."""
        if self.schedule is None:
            return
        law = self.schedule.law(step)
        if law != self.engine.phys.law:
            self.engine.phys = self.physics.with_law(law)

    # -- the loop --
    def run(self):
        """Step until the stop rule, max_steps, the wall time or a signal.

        Returns the status: "converged", "max_steps" or "interrupted" (a
        checkpoint was written; restart to go on).
        """
        st, max_steps, N = self.state, self.cfg.run.max_steps, max(self.n_mobile, 1)
        eng, handlers = self.engine, {}
        try:
            try:
                info = self._start()
            finally:
                self.watch.__exit__()
            self.checks.fatal(info, st.step)
            progress = Progress(self.cfg.output.progress_every, self.log, self.domain, self.physics.dt, max_steps,
                                N, st.step, self.t0)
            # a SIGINT ignored by whoever started us (a background job of a script) stays ignored; only the
            # main thread may set handlers (a run called from another thread stops on the wall time alone)
            main = threading.current_thread() is threading.main_thread()
            handlers = {s: signal.signal(s, self._on_stop_signal) for s in STOP_SIGNALS
                        if main and not (s == signal.SIGINT and signal.getsignal(s) == signal.SIG_IGN)}
            quiet_runs = hasattr(eng, "run_quiet")
            while self.status is None and st.step < max_steps:
                if quiet_runs:
                    # the steps before the next that something reads after, in one go (``run_quiet``),
                    # all of one law
                    s0 = st.step
                    quiet = self._quiet_steps(s0, max_steps, progress)
                    if self.schedule:
                        quiet = min(quiet, self.schedule.room(s0))
                        self._law_at(s0 + 1)
                    for k, q in enumerate(eng.run_quiet(quiet, self._flags_now())):
                        self.checks(q, s0 + k + 1)
                self._law_at(st.step + 1)
                # the step's second half-kick joins the next step's first pass; whatever reads the
                # rows below (the stop sample, a state file) has the engine apply it first
                # a stop sample after the step reads every pair's force of its evaluation
                info = eng.step(self._flags_now(), defer_kick=True, keep_pairs=self.stop.due(st.step + 1))
                self.checks(info, st.step)
                sample, show = self.stop.due(st.step), progress.due(st.step)
                if sample or show:
                    info = info._replace(n_contacts=eng.contacts())
                if sample and self._sample(info, N):
                    self.status = "converged"
                    break
                if self.snapshots.due(st.step):
                    self.snapshots.write()
                flags = info.flags
                if (flags.signal or flags.walltime) and st.step < max_steps:
                    self._interrupt(flags.signal)
                    break
                # a clock checkpoint at the last step would only repeat the final state written next
                if self.checkpoints.due(st.step, flags.clock and st.step < max_steps):
                    self.thermo.flush()
                    self.checkpoints.write(st.step)
                if show:
                    progress.line(st, info, self.stop)
        finally:
            for s, h in handlers.items():
                signal.signal(s, h)
            self.thermo.close()
        self.status = self.status or "max_steps"
        eng.complete()
        self.wall = time.perf_counter() - self.t0
        self.comm_seconds = self.domain.comm_seconds     # the loop's (not the end's collectives)
        et, er = eng.kinetic()
        self.ek = (et + er) / N
        # the last sample's (a checkpoint at the last step has freed the slot forces since)
        self.force_ratio = self.stop.ratio
        return self.status

    def _start(self):
        """Set the engine up (a state file's forces kept); start the loop's clocks. Returns the StepInfo."""
        self.t0 = time.perf_counter()
        self.checkpoints.start_clock()
        w = self.watch
        w(everywhere=True)
        w.begin("the first neighbour-list build", f"set-up: first neighbour lists and forces of "
                                                   f"{self.n_mobile + self.n_bed} spheres")
        if self.from_file:
            info = self.engine.start_from_file(self.history.max_overlap, self.history.n_rebuilds)
        else:
            info = self.engine.start()
        w(everywhere=True)
        w.say("set-up: done; stepping")
        return info

    def _quiet_steps(self, step, max_steps, progress, most=QUIET_MOST):
        """Steps after ``step`` that no schedule reads after (no stop sample, progress line,
        snapshot, step checkpoint; short of ``max_steps``), up to ``most`` and to ``QUIET_ROW_STEPS``
        sphere-steps of a rank's share of the pile: the engine may run them without stopping
        (``run_quiet``). Their flags are those of the first of them. The same on every rank (the
        steps after them are collective)."""
        share = (self.n_mobile + self.n_bed) // self.domain.size
        most = min(most, max(1, QUIET_ROW_STEPS // max(share, 1)))
        return quiet_span(step, max_steps, (self.stop, progress, self.snapshots, self.checkpoints), most)

    def _flags_now(self):
        """This rank's StepFlags for the step's allreduce."""
        now = time.monotonic()
        late = self.t_end is not None and now + self.margin + 2 * self.checkpoints.last_write >= self.t_end
        return StepFlags(float(max(self.signals, default=0)), float(late), float(self.checkpoints.clock_due(now)))

    def _sample(self, info, N):
        """A stop-rule sample and its thermo line; True if the rule holds."""
        et, er, p_x = self.engine.kinetic(momentum=True)
        self.stop.add(et, er, N, *self.engine.force_ratio())
        self.thermo.write(self.state, et, er, N, self.stop, info, self.engine.n_rebuilds, self.wall_total(), p_x)
        if self.schedule and self.schedule.active(self.state.step):
            # on the ramp or in the flow the pile is not yet the one to settle: the rule's window starts at its end
            self.stop.clear()
            return False
        if self.stop.satisfied():
            return True
        hint = self.stop.spin_hint()
        if hint:
            self.log.warn(f"{hint}. {spin.describe(*spin.spinners(self.state, self.domain))}")
        return False

    def _on_stop_signal(self, signum, frame):
        """Record a stop signal for the next step's flags; a second SIGINT (Ctrl-C twice) stops at once,
        without the checkpoint (KeyboardInterrupt: ``mpdem: interrupted``, exit 1)."""
        if signum == signal.SIGINT and int(signal.SIGINT) in self.signals:
            raise KeyboardInterrupt
        if signum == signal.SIGINT:
            # os.write, not the log's buffered file: the handler may run in the middle of its write
            os.write(2, b"mpdem: SIGINT: a checkpoint at the next look, then a stop (Ctrl-C again: at once, "
                        b"without it)\n")
        self.signals.append(int(signum))

    def _interrupt(self, sig):
        """Checkpoint and stop early (a signal or the wall time): status "interrupted"."""
        self.thermo.flush()
        path = self.checkpoints.write(self.state.step)
        self.stop_signal = int(sig)
        why = f"signal {signal.Signals(int(sig)).name}" if sig else "the wall time"
        self.log(f"stop: {why} at step {self.state.step}; wrote {path}. Not finished: continue with "
                 f"`python -m mpdem restart {self.out}` (exit status {EXIT_RESTART})")
        self.status = "interrupted"

    def wall_total(self):
        """Loop wall time of all segments so far [s]."""
        return self.history.wall_seconds + time.perf_counter() - self.t0

    # -- files --
    def records(self):
        """The restart records of the run and its schedules, as of now (collective); a RunState."""
        # one reduction: the last overlap, and one wall-clock reading for all ranks (attributes must agree)
        overlap, wall = self.domain.max_many([self.engine.last_overlap, self.wall_total()])
        migrated, rebalances = self.counters()
        h = History(self.history.segments, float(wall), self.engine.n_rebuilds, float(overlap), migrated, rebalances)
        return RunState(h, self.pile, self.stop.record(), self.checkpoints.record(), self.snapshots.record())

    def _attrs(self, kind):
        """Attributes of a state file: identical on every rank (collective)."""
        st, cfg = self.state, self.cfg
        return {"kind": kind, "step": st.step, "time": st.time, "n": self.n_mobile + self.n_bed,
                "n_mobile": self.n_mobile, "n_bed": self.n_bed, "L_x": st.L_x, "L_y": st.L_y,
                "z_bed": self.pile.z_bed, "converged": self.converged, "ranks": self.domain.size,
                "seed": cfg.run.seed, "rng": "numpy PCG64 streams keyed by (run.seed, purpose); used at set-up only",
                "mpdem_version": __version__,
                "config": cfg.to_toml(), "run_state": self.records().dumps()}

    def _write(self, path, kind):
        """Write a state file of ``kind`` (collective); snapshots and the final state carry the contact list."""
        local = checkpoint.gather_state(self.state)
        if kind != "checkpoint":
            # the forces of the law in use (the schedule's: a ramp's or a flow's)
            local.update(contact_pairs(self.state, self.engine.phys))
        try:
            checkpoint.write(path, local, self._attrs(kind), self.domain.net)
        except WriteError as e:     # raised on every rank: say where the run can go on from
            raise WriteError(f"{e}. {resume_hint(self.out, path)}", agreed=True) from None

    def counters(self):
        """Migrations (summed over ranks) and rebalances of the whole run: the earlier
        segments' (restart record) and this one's (collective)."""
        seg = int(self.domain.sum_int(np.array([self.domain.n_migrated]))[0])
        return self.history.migrated + seg, self.history.rebalances + int(self.domain.n_rebalances)

    # -- the end --
    def finish(self):
        """Write RUN/final.h5 (with the contact list) and summary.json; log bulk z and phi (collective).

        Returns
        -------
        dict or None
            The summary on rank 0 (also in RUN/summary.json), None elsewhere.
        """
        # collectives first, in the same order on every rank: the final state file (first: what ends the
        # process after it leaves the run whole), the digest by chunks of ids (no rank holds the whole
        # state), the bulk measurement where it is made (each rank on its rows and ghosts)
        path = self.snapshots.write(final=True)
        part = checkpoint.gather_state(self.state)
        digest = checkpoint.digest_parts(part, self.domain.net)
        del part
        bulk = summary.measure_bulk(self.state, self.domain, self.cfg) if self.cfg.output.bulk_at_end else None
        migrated, rebalances = self.counters()
        try:
            if self.rank != 0:
                return None
            return summary.write(self.end(migrated, rebalances), digest, bulk, self.cfg, self.out, path,
                                 self.log)
        finally:
            self.log.close()

    def end(self, migrated, rebalances):
        """What the run came to (``summary.End``), with the whole run's ``migrated`` and ``rebalances``."""
        st, dom = self.state, self.domain
        return summary.End(self.status, st.step, st.step - self.first_step, st.time, self.n_mobile, st.L_x, st.L_y,
                           self.ek, self.force_ratio, self.wall, self.wall_total(), self.history.segments, dom.size,
                           self.comm_seconds, dom.parallel, migrated, rebalances)


def resume_hint(out, failed):
    """Where a run whose state file ``failed`` could not be written can go on from, in words.

    Names the newest checkpoint without opening it: after a write the HDF5 library failed to flush,
    it may not open another file safely (``checkpoint.HELD``).
    """
    done = [p for _, p in rundir.checkpoints(out) if p != failed]
    if not done:
        return ("No checkpoint of this run was written yet: make room, then start it again "
                "(`python -m mpdem run ... --force`)")
    return f"The run is whole at its last checkpoint, {done[-1]}: make room, then `python -m mpdem restart {out}`"
