"""A pile run: start (new or restarted), step with its schedules, finish.

Owns the run directory (``rundir`` gives its layout) and the time-step loop
of ARCHITECTURE.md. What happens between steps is in ``schedule`` (checks,
stop rule and thermo, progress, checkpoints, snapshots); the initial state
is ``initial``'s, the arithmetic of a step ``engine``'s, the files
``checkpoint``'s, and continuing from a state file ``restart``'s.
"""
from __future__ import annotations

import json
import math
import os
import signal
import time
from dataclasses import asdict, dataclass

import numpy as np

from . import build, checkpoint, initial, rundir, summary
from .config import collision_time
from .decomp import Domain
from .engine import Engine, Physics
from .errors import EXIT_RESTART
from .pairs import contact_pairs
from .schedule import (Checkpoints, Checks, Logger, Progress, RunError, Snapshots, StopRule,  # noqa: F401
                       Thermo)

# the signals that stop a run early with a checkpoint and exit status EXIT_RESTART
# ("not finished, restart me", EX_TEMPFAIL)
STOP_SIGNALS = (signal.SIGTERM, signal.SIGUSR1)


@dataclass
class History:
    """Restart record of the run as a whole: its segments and counters so far."""
    segments: int = 1
    wall_seconds: float = 0.0       # loop wall time of all segments [s]
    n_rebuilds: int = 0
    max_overlap: float = 0.0        # of the last force evaluation [d]
    migrated: int = 0               # particles moved between ranks (summed over ranks)
    rebalances: int = 0


class Run:
    """One pile run in ``out_dir``: a new one (``prepare``) or a continued one (``resume.resume``).

    Parameters
    ----------
    cfg : Config
    out_dir : str
        The run directory (``rundir``).
    net : parallel.Channel, mpi4py communicator or None
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

    def __init__(self, cfg, out_dir, net=None, quiet=False, walltime=None, margin=None, t_start=None,
                 signals=None):
        self.cfg, self.out = cfg, out_dir
        self.domain = Domain(net, r_list=1.0 + cfg.integration.skin,
                             tolerance=cfg.decomp.balance_tolerance, damping=cfg.decomp.balance_damping)
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
        self.state = self.engine = None
        self.status = None          # "converged", "max_steps" or "interrupted"
        self.wall = 0.0
        self.force_ratio = math.nan  # the unbalanced-force ratio of the last sample (summary.json)
        self.history = History()
        self.stop = StopRule.from_config(cfg, self.physics.dt)
        self.checkpoints = Checkpoints(out_dir, cfg.output, self._write, self.domain, self.log)
        self.snapshots = Snapshots(out_dir, cfg.output.snapshot_every, self._write, self.rank)
        self._flags = np.zeros(3)   # per-rank: stop signal, wall time near, clock checkpoint due

    @property
    def converged(self):
        return self.status == "converged"

    def prepare(self, lammps_initial=None):
        """A new run: build or read the initial state, check it, write config.toml and bed.txt.

        ``lammps_initial``: a LAMMPS ``run.initial_file`` already read (``lammps.initial_for``).
        """
        cfg = self.cfg
        for w in cfg.warnings:
            self.log.warn(w)
        if self.rank == 0:
            rundir.write_atomic(os.path.join(self.out, "config.toml"), cfg.to_toml())
            rundir.clear(self.out)
        init = initial.initial_state(cfg, self.domain.net, self.log, lammps_initial)
        w = init.whole
        bed = w["fixed"] == 1
        if init.n_bed and self.rank == 0:
            build.write_table(os.path.join(self.out, "bed.txt"), w["id"][bed], w["x"][bed], fixed=w["fixed"][bed])
        self.begin(self.domain.scatter(w, cfg.box.L_x, cfg.box.L_y), init.pile, init.n_mobile, init.n_bed)

    def begin(self, state, pile, n_mobile, n_bed):
        """Take this rank's ``state`` and the pile's geometry (``initial.Pile``); describe the run."""
        self.state, self.pile, self.n_mobile, self.n_bed = state, pile, n_mobile, n_bed
        p, cfg = self.physics, self.cfg
        t_col = collision_time(p.gamma_n, p.k_n)
        self.log(f"mpdem: {n_mobile} mobile + {n_bed} bed spheres, box {cfg.box.L_x:g} x {cfg.box.L_y:g}, "
                 f"{cfg.contact.model} k_n = {p.k_n:g}, k_t = {p.k_t:g}, gamma_n = {p.gamma_n:.6g} "
                 f"(epsilon = {cfg.contact.epsilon:.4g}), gamma_t = {p.gamma_t:g}, mu = {p.mu:g}")
        self.log(f"mpdem: dt = {p.dt:.6g} (t_col / dt = {t_col / p.dt:.1f}), skin = {p.skin:g}, "
                 f"E_stop = {cfg.stop.E_stop:.3g} ({cfg.stop.rule}), max_steps = {cfg.run.max_steps}, "
                 f"seed = {cfg.run.seed}, ranks = {self.domain.size}")

    # -- the loop --
    def run(self):
        """Step until the stop rule, max_steps, the wall time or a signal.

        Returns the status: "converged", "max_steps" or "interrupted" (a
        checkpoint was written; restart to go on).
        """
        st, max_steps, N = self.state, self.cfg.run.max_steps, max(self.n_mobile, 1)
        eng = self._start()
        checks = Checks(self.cfg, self.pile, self.n_bed, self.log)
        checks.fatal(eng.info, st.step)
        progress = Progress(self.cfg.output.progress_every, self.log, self.domain, self.physics.dt, max_steps, N,
                            st.step, self.t0)
        self.thermo = Thermo(self.out, self.rank)
        handlers = {s: signal.signal(s, lambda signum, frame: self.signals.append(int(signum))) for s in STOP_SIGNALS}
        try:
            while self.status is None and st.step < max_steps:
                info = eng.step(self._flags_now())
                checks(info, st.step)
                sample, show = self.stop.due(st.step), progress.due(st.step)
                if sample or show:
                    eng.contacts()
                if sample and self._sample(info, N):
                    self.status = "converged"
                    break
                if self.snapshots.due(st.step):
                    self.snapshots.write()
                sig, late, clock = info.flags
                if (sig or late) and st.step < max_steps:
                    self._interrupt(sig)
                    break
                if self.checkpoints.due(st.step, clock):
                    self.thermo.flush()
                    self.checkpoints.write(st.step)
                if show:
                    progress.line(st, info, self.stop)
        finally:
            for s, h in handlers.items():
                signal.signal(s, h)
            self.thermo.close()
        self.status = self.status or "max_steps"
        self.wall = time.perf_counter() - self.t0
        et, er = eng.kinetic()
        self.ek = (et + er) / N
        # the last sample's (a checkpoint at the last step has freed the slot forces since)
        self.force_ratio = self.stop.ratio
        return self.status

    def _start(self):
        """The engine, set up for a new or a continued run; starts the loop's clock."""
        eng = self.engine = Engine(self.state, self.physics, self.domain)
        self.t0, self.first_step, h = time.perf_counter(), self.state.step, self.history
        self.checkpoints.start_clock()
        if h.segments > 1:
            eng.start_from_file(h.max_overlap, h.n_rebuilds)
        else:
            eng.start()
        return eng

    def _flags_now(self):
        """This rank's flags for the step's allreduce: stop signal, wall time near, clock checkpoint."""
        now, f = time.monotonic(), self._flags
        f[0] = float(max(self.signals, default=0))
        f[1] = float(self.t_end is not None and now + self.margin + 2 * self.checkpoints.last_write >= self.t_end)
        f[2] = float(self.checkpoints.clock_due(now))
        return f

    def _sample(self, info, N):
        """A stop-rule sample and its thermo line; True if the rule holds."""
        et, er = self.engine.kinetic()
        self.stop.add(et, er, N, *self.engine.force_ratio())
        self.thermo.write(self.state, et, er, N, self.stop, info, self.engine.n_rebuilds, self.wall_total())
        return self.stop.satisfied()

    def _interrupt(self, sig):
        """Checkpoint and stop early (a signal or the wall time): status "interrupted"."""
        self.thermo.flush()
        path = self.checkpoints.write(self.state.step)
        why = f"signal {signal.Signals(int(sig)).name}" if sig else "the wall time"
        self.log(f"stop: {why} at step {self.state.step}; wrote {path}. Not finished: continue with "
                 f"`python -m mpdem restart {self.out}` (exit status {EXIT_RESTART})")
        self.status = "interrupted"

    def wall_total(self):
        return self.history.wall_seconds + time.perf_counter() - self.t0

    # -- files --
    def records(self):
        """The restart records of the run and its schedules, as of now (collective)."""
        # one reduction: the last overlap, and one wall-clock reading for all ranks (attributes must agree)
        overlap, wall = self.domain.max_many([self.engine.last_overlap, self.wall_total()])
        migrated, rebalances = self.counters()
        h = History(self.history.segments, float(wall), self.engine.n_rebuilds, float(overlap), migrated, rebalances)
        return [h, self.pile, self.stop.record(), self.checkpoints.record(), self.snapshots.record()]

    def _attrs(self, kind):
        """Attributes of a state file: identical on every rank (collective)."""
        st, cfg = self.state, self.cfg
        rs = {}
        for rec in self.records():
            rs.update(asdict(rec))
        return {"kind": kind, "step": st.step, "time": st.time, "n": self.n_mobile + self.n_bed,
                "n_mobile": self.n_mobile, "n_bed": self.n_bed, "L_x": st.L_x, "L_y": st.L_y,
                "z_bed": self.pile.z_bed, "converged": self.converged, "ranks": self.domain.size,
                "seed": cfg.run.seed, "rng": "numpy PCG64 streams keyed by (run.seed, purpose); used at set-up only",
                "mpdem_version": __import__("mpdem").__version__,
                "config": cfg.to_toml(), "run_state": json.dumps(rs)}

    def _write(self, path, kind):
        """Write a state file of ``kind`` (collective); snapshots and the final state carry the contact list."""
        local = checkpoint.gather_state(self.state)
        if kind != "checkpoint":
            local.update(contact_pairs(self.state, self.physics))
        checkpoint.write(path, local, self._attrs(kind), self.domain.net)

    def counters(self):
        """Migrations (summed over ranks) and rebalances of the whole run: the earlier
        segments' (restart record) and this one's (collective)."""
        seg = int(self.domain.sum_int(np.array([self.domain.n_migrated]))[0])
        return self.history.migrated + seg, self.history.rebalances + int(self.domain.n_rebalances)

    # -- the end --
    def finish(self):
        """Write RUN/final.h5 (with the contact list) and summary.json; log bulk z and phi (``summary``)."""
        return summary.finish(self)
