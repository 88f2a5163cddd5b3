"""A pile run: prepare or resume, step with monitors and schedules, finish.

Owns the run directory (``rundir`` gives its layout) and everything that
happens between steps: run-time checks (docs/model.md section 8), kinetic-energy
sampling and the stop rule (5.4), checkpoints and snapshots on their
schedules, wall-time and signal stops, progress lines. The arithmetic of a
step is ``engine``'s; files are written by ``checkpoint``.
"""
from __future__ import annotations

import collections
import json
import math
import os
import signal
import sys
import time

import numpy as np

from . import analysis, build, checkpoint, lammps, rundir
from .config import collision_time
from .decomp import Domain
from .errors import MpdemError
from .engine import Engine, Physics
from .pairs import contact_pairs

# exit status of a run that stopped early on purpose (wall time, SIGTERM,
# SIGUSR1) after writing a checkpoint: "not finished, restart me" (EX_TEMPFAIL)
EXIT_RESTART = 75
STOP_SIGNALS = (signal.SIGTERM, signal.SIGUSR1)


class RunError(MpdemError, RuntimeError):
    """The run cannot go on (NaN, excessive overlap, a particle under the bed)."""


class Logger:
    """Lines to stdout and the run's log file (rank 0 only)."""

    def __init__(self, path=None, quiet=False, rank=0):
        self.rank, self.quiet = rank, quiet
        self.fh = open(path, "a") if (path and rank == 0) else None

    def __call__(self, msg):
        if self.rank != 0:
            return
        if not self.quiet:
            print(msg, flush=True)
        if self.fh:
            self.fh.write(msg + "\n")
            self.fh.flush()

    def warn(self, msg):
        if self.rank == 0:
            print(f"warning: {msg}", file=sys.stderr, flush=True)
            if self.fh:
                self.fh.write(f"warning: {msg}\n")
                self.fh.flush()

    def close(self):
        if self.fh:
            self.fh.close()


def _fmt_seconds(s):
    if not math.isfinite(s) or s < 0:
        return "?"
    s = int(s)
    return f"{s // 3600}h{s % 3600 // 60:02d}m" if s >= 3600 else f"{s // 60}m{s % 60:02d}s"


class StopRule:
    """Kinetic-energy stop rule of docs/model.md 5.4 on samples every n_sample steps."""

    def __init__(self, E_stop, rule, window, sample_interval, dt):
        self.E_stop, self.rule = E_stop, rule
        self.n_sample = max(1, int(round(sample_interval / dt)))
        self.size = max(1, int(round(window / (self.n_sample * dt))))
        self.samples = collections.deque(maxlen=self.size)

    def add(self, ek):
        self.samples.append(ek)

    @property
    def mean(self):
        return sum(self.samples) / len(self.samples) if self.samples else math.inf

    def satisfied(self):
        if self.rule == "instantaneous":
            return bool(self.samples) and self.samples[-1] < self.E_stop
        return len(self.samples) == self.size and self.mean < self.E_stop

    def time_to_stop(self, dt):
        """Rough simulated time until the stop, from the log-decay over the window [tau]."""
        if len(self.samples) < 2 or min(self.samples) <= 0:
            return math.nan
        rate = (math.log(self.samples[0]) - math.log(self.samples[-1])) / ((len(self.samples) - 1) * self.n_sample * dt)
        if rate <= 0:
            return math.nan
        return max(0.0, math.log(self.mean / self.E_stop) / rate)


class Run:
    """One pile run in ``out_dir``: a new one (``prepare``) or a continued one (``resume``).

    Parameters
    ----------
    cfg : Config
    out_dir : str
        The run directory (``rundir``).
    comm : mpi4py communicator or None
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

    def __init__(self, cfg, out_dir, comm=None, quiet=False, walltime=None, margin=None, t_start=None,
                 signals=None):
        self.cfg, self.out = cfg, out_dir
        self.domain = Domain(comm, r_list=1.0 + cfg.integration.skin,
                             tolerance=cfg.decomp.balance_tolerance, damping=cfg.decomp.balance_damping)
        self.comm, self.rank = comm, self.domain.rank
        if self.rank == 0:
            for d in (out_dir, os.path.join(out_dir, rundir.CKPT_DIR)):
                os.makedirs(d, exist_ok=True)
        self.log = Logger(os.path.join(out_dir, "log.txt"), quiet, self.rank)
        self.physics = Physics.from_config(cfg)
        self.t_start = time.monotonic() if t_start is None else t_start
        self.t_end = None if walltime is None else self.t_start + walltime
        self.margin = (min(60.0, walltime / 20) if margin is None else margin) if walltime else 0.0
        self.last_write = 0.0
        self.state = None
        self.status = None          # "converged", "max_steps" or "interrupted"
        self.wall = 0.0
        self.signals = [] if signals is None else signals
        # what a restart needs besides the particles (saved in every state file)
        self.cont = {"stop_samples": [], "n_rebuilds": 0, "wall_seconds": 0.0, "n_checkpoints": 0,
                     "n_snapshots": 0, "segments": 1, "max_overlap": 0.0}

    @property
    def converged(self):
        return self.status == "converged"

    # -- a new run --
    def prepare(self, lammps_initial=None):
        """Build or read the initial state, check it, write config and bed files.

        ``lammps_initial``: the particles of a LAMMPS ``run.initial_file``
        (``lammps.initial_for``), when read already.
        """
        cfg, log = self.cfg, self.log
        self._lammps_initial = lammps_initial
        for w in cfg.warnings:
            log.warn(w)
        if self.rank == 0:
            rundir.write_atomic(os.path.join(self.out, "config.toml"), cfg.to_toml())
            rundir.clear(self.out)
        L_x, L_y = cfg.box.L_x, cfg.box.L_y
        slots = None
        if cfg.run.initial_file:
            ids, x, v, omega, fixed = self._read_initial(cfg.run.initial_file)
            slots = self._initial_slots
            z_bed = float(x[fixed == 1, 2].max()) if fixed.any() else -math.inf
            bed = build.Bed(x[fixed == 1].copy(), note=f"from {cfg.run.initial_file}")
            self.h_insert = float(x[fixed == 0, 2].max() - max(z_bed, x[fixed == 0, 2].min())) if (fixed == 0).any() else 0.0
        else:
            bed = self._bed()
            z_bed = bed.z_top
            N = cfg.pour.N
            H = build.insertion_height(N, L_x, L_y, cfg.pour.phi_i)
            self.h_insert = H
            log(f"pour: inserting {N} spheres at phi_i = {cfg.pour.phi_i:g} in "
                f"z in [{z_bed + 1:.3f}, {z_bed + 1 + H:.3f}]")
            xm = build.insert_random(build.rng(cfg.run.seed, build.STREAM_POUR), N, L_x, L_y,
                                     z_bed + 1.0, z_bed + 1.0 + H, obstacles=bed.x)
            vm = build.initial_velocities(build.rng(cfg.run.seed, build.STREAM_VELOCITY), N, cfg.pour.K0)
            nb = len(bed.x)
            ids = np.arange(N + nb, dtype=np.int64)
            x = np.concatenate([xm, bed.x])
            v = np.concatenate([vm, np.zeros((nb, 3))])
            omega = np.zeros_like(x)
            fixed = np.concatenate([np.zeros(N, np.uint8), np.ones(nb, np.uint8)])
        self.z_bed, self.n_bed = z_bed, len(bed.x)
        self.z_bed_mean = bed.z_mean if self.n_bed else -math.inf
        z_floor = bed.z_mean if cfg.run.initial_file else z_bed + 0.5
        build.check_initial(ids, x, fixed, L_x, L_y, z_floor, allow_overlap=slots is not None,
                            overlap_warn=cfg.checks.overlap_warn, warn=log.warn, wall=cfg.bed.wall)
        if self.n_bed and self.rank == 0:
            build.write_table(os.path.join(self.out, "bed.txt"), ids[fixed == 1], x[fixed == 1],
                              fixed=fixed[fixed == 1])
        self.n_mobile = int((fixed == 0).sum())
        # every rank holds the whole initial state (built identically); each keeps its slab
        whole = {"id": ids, "x": x, "v": v, "omega": omega, "fixed": fixed}
        if cfg.bed.wall and getattr(self, "_initial_wall", None) is not None:
            whole["wall_ds"] = self._initial_wall
        if slots is not None:
            whole.update(zip(("count", "partner", "ds"), slots))
        self.state = self.domain.scatter(whole, L_x, L_y)
        self._describe()

    def _describe(self):
        p, cfg = self.physics, self.cfg
        t_col = collision_time(p.gamma_n, p.k_n)
        self.log(f"mpdem: {self.n_mobile} mobile + {self.n_bed} bed spheres, box {cfg.box.L_x:g} x {cfg.box.L_y:g}, "
                 f"{cfg.contact.model} k_n = {p.k_n:g}, k_t = {p.k_t:g}, gamma_n = {p.gamma_n:.6g} "
                 f"(epsilon = {cfg.contact.epsilon:.4g}), gamma_t = {p.gamma_t:g}, mu = {p.mu:g}")
        self.log(f"mpdem: dt = {p.dt:.6g} (t_col / dt = {t_col / p.dt:.1f}), skin = {p.skin:g}, "
                 f"E_stop = {cfg.stop.E_stop:.3g} ({cfg.stop.rule}), max_steps = {cfg.run.max_steps}, "
                 f"seed = {cfg.run.seed}, ranks = {self.domain.size}")

    def _bed(self):
        cfg = self.cfg
        if cfg.bed.file:
            ids, x, v, omega, fixed = self._read_initial(cfg.bed.file, all_fixed=True)
            bed = build.Bed(x.copy(), note=f"from {cfg.bed.file}")
        else:
            # rank 0 makes the bed; the others receive the same positions
            bed = build.make_bed(cfg, progress=self.log) if self.rank == 0 else None
            if self.domain.parallel:
                bed = self.domain.comm.bcast(bed, root=0)
        dens = len(bed.x) / (cfg.box.L_x * cfg.box.L_y)
        self.log(f"bed: {len(bed.x)} frozen spheres, {dens:.3f} per d^2, z_bed = {bed.z_top:.4f}; {bed.note}")
        if not cfg.bed.density_min <= dens <= cfg.bed.density_max:
            self.log.warn(f"bed areal density {dens:.3f} per d^2 is outside "
                          f"[{cfg.bed.density_min:g}, {cfg.bed.density_max:g}]")
        return bed

    def _read_initial(self, path, all_fixed=False):
        """Particles of a text table or state file; a state file's contact
        histories go to ``self._initial_slots`` (None for a table)."""
        self._initial_slots = self._initial_wall = None
        if not os.path.exists(path):
            raise build.InputError(f"initial file {path}: no such file")
        if checkpoint.is_state_file(path):
            a, _ = checkpoint.read_state(path)
            ids, x, v, omega, fixed = a["id"], a["x"], a["v"], a["omega"], a["fixed"]
            self._initial_slots = (a["count"], a["partner"], a["ds"])
            self._initial_wall = a.get("wall_ds")
        elif lammps.kind(path):
            t = getattr(self, "_lammps_initial", None)
            if t is None or all_fixed:
                t = lammps.read(path, () if all_fixed else self.cfg.run.fixed_types,
                                what="bed.file" if all_fixed else "run.initial_file")
            self.log(f"read {path}: {t['note']}; {int(t['fixed'].sum())} bed spheres "
                     f"(types {list(self.cfg.run.fixed_types)})" if not all_fixed else f"read {path}: {t['note']}")
            ids, x, v, omega, fixed = t["ids"], t["x"], t["v"], t["omega"], t["fixed"]
        else:
            t = build.read_table(path)
            ids, x, v, omega, fixed = t["ids"], t["x"], t["v"], t["omega"], t["fixed"]
        if all_fixed:
            fixed = np.ones(len(ids), np.uint8)
        return ids, x, v, omega, fixed

    # -- a continued run --
    def resume(self, path, local, attrs):
        """Continue from a state file: ``local`` is this rank's share (``checkpoint.read``)."""
        cfg = self.cfg
        rs = json.loads(attrs["run_state"])
        self.cont.update(rs)
        self.cont["segments"] += 1
        self.n_mobile, self.n_bed = int(attrs["n_mobile"]), int(attrs["n_bed"])
        self.z_bed, self.z_bed_mean, self.h_insert = rs["z_bed"], rs["z_bed_mean"], rs["h_insert"]
        st = self.state = self.domain.distribute(local, float(attrs["L_x"]), float(attrs["L_y"]))
        st.step, st.time = int(attrs["step"]), float(attrs["time"])
        if self.rank == 0:
            rundir.write_atomic(os.path.join(self.out, "config.toml"), cfg.to_toml())
            rundir.truncate_thermo(os.path.join(self.out, "thermo.csv"), st.step)
        self.log(f"restart: from {path} at step {st.step} (t = {st.time:.6g}), segment {self.cont['segments']}, "
                 f"{self.domain.size} ranks (written by {attrs.get('ranks', '?')})")
        for w in cfg.warnings:
            self.log.warn(w)
        self._describe()

    # -- the loop --
    def run(self):
        """Step until the stop rule, max_steps, the wall time or a signal.

        Returns the status: "converged", "max_steps" or "interrupted" (a
        checkpoint was written; restart to go on).
        """
        cfg, log, st = self.cfg, self.log, self.state
        out = cfg.output
        eng = self.engine = Engine(st, self.physics, self.domain)
        stop = self.stop = StopRule(cfg.stop.E_stop, cfg.stop.rule, cfg.stop.window,
                                    cfg.stop.sample_interval, self.physics.dt)
        stop.samples.extend(self.cont["stop_samples"])
        thermo = self._open_thermo()
        self.t0 = t0 = time.perf_counter()
        self._first_step = st.step
        resumed = self.cont["segments"] > 1
        info = eng.resume(self.cont["max_overlap"]) if resumed else eng.setup()
        if resumed:
            eng.n_rebuilds = self.cont["n_rebuilds"]      # the straight run's count (no rebuild here)
        self._check(info)
        N = max(self.n_mobile, 1)
        max_steps = cfg.run.max_steps
        every = out.progress_every
        t_last, s_last = time.perf_counter(), st.step
        escape = self.z_bed + 1.0 + self.h_insert + cfg.checks.escape_margin
        warned = {"escape": False, "overlap": -10**18}
        ek = stop.samples[-1] if stop.samples else math.inf
        # per-rank flags agreed in each step's one allreduce: signal, wall time, clock checkpoint
        flags = eng.flags = [0.0, 0.0, 0.0]
        next_clock = time.monotonic() + out.checkpoint_seconds
        old_handlers = {s: signal.signal(s, self._on_signal) for s in STOP_SIGNALS}
        try:
            while self.status is None and st.step < max_steps:
                now = time.monotonic()
                flags[0] = float(max(self.signals, default=0))
                flags[1] = float(self.t_end is not None and now + self.margin + 2 * self.last_write >= self.t_end)
                flags[2] = float(out.checkpoint_seconds > 0 and now >= next_clock)
                info = eng.step()
                self._check(info, warned, escape)
                if st.step % stop.n_sample == 0 or st.step % every == 0:
                    eng.contacts()
                if st.step % stop.n_sample == 0:
                    et, er = eng.kinetic()
                    ek = (et + er) / N
                    stop.add(ek)
                    if thermo:
                        thermo.write(f"{st.step},{st.time:.10g},{ek:.6e},{et / N:.6e},{er / N:.6e},"
                                     f"{stop.mean:.6e},{info.max_overlap:.6e},{info.n_contacts / N:.5f},"
                                     f"{info.z_max:.6g},{eng.n_rebuilds},{self._wall_total():.3f}\n")
                    if stop.satisfied():
                        self.status = "converged"
                        break
                sig, late, clock = info.flags
                if out.snapshot_every and st.step % out.snapshot_every == 0:
                    self.write_snapshot()
                if (sig or late) and st.step < max_steps:
                    if thermo:
                        thermo.flush()
                    path = self.write_checkpoint()
                    why = f"signal {signal.Signals(int(sig)).name}" if sig else "the wall time"
                    log(f"stop: {why} at step {st.step}; wrote {path}. Not finished: continue with "
                        f"`python -m mpdem restart {self.out}` (exit status {EXIT_RESTART})")
                    self.status = "interrupted"
                    break
                if (out.checkpoint_every and st.step % out.checkpoint_every == 0) or clock:
                    if thermo:
                        thermo.flush()
                    self.write_checkpoint()
                    next_clock = time.monotonic() + out.checkpoint_seconds
                if st.step % every == 0:
                    now = time.perf_counter()
                    rate = (st.step - s_last) / max(now - t_last, 1e-9)
                    t_last, s_last = now, st.step
                    t_stop = stop.time_to_stop(self.physics.dt) / self.physics.dt / rate
                    par = ""
                    if self.domain.parallel:
                        comm_share = self.domain.comm_seconds / max(now - t0, 1e-9)
                        par = f"  imbalance {self.domain.imbalance(st):4.2f}  comm {100 * comm_share:3.0f}%"
                    # no E_k before the first sample: a dash, not "inf"
                    ek_text = f"{ek:9.3e}" if math.isfinite(ek) else f"{'-':>9}"
                    log(f"step {st.step:>9d}  t {st.time:9.3f}  E_k/N {ek_text}  "
                        f"max_delta {info.max_overlap:8.2e}  contacts/N {info.n_contacts / N:5.2f}  "
                        f"{rate:7.0f} steps/s{par}  eta cap {_fmt_seconds((max_steps - st.step) / rate)}  "
                        f"stop ~{_fmt_seconds(t_stop)}")
        finally:
            for s, h in old_handlers.items():
                signal.signal(s, h)
            if thermo:
                thermo.close()
        if self.status is None:
            self.status = "max_steps"
        self.wall = time.perf_counter() - t0
        et, er = eng.kinetic()
        self.ek = (et + er) / N
        return self.status

    def _on_signal(self, signum, frame):
        self.signals.append(int(signum))

    def _open_thermo(self):
        if self.rank != 0:
            return None
        path = os.path.join(self.out, "thermo.csv")
        new = not os.path.exists(path) or os.path.getsize(path) == 0
        fh = open(path, "a")
        if new:
            fh.write("step,time,ek,ek_trans,ek_rot,ek_window,max_overlap,contacts_per_particle,"
                     "z_max,rebuilds,wall_seconds\n")
        return fh

    def _wall_total(self):
        return self.cont["wall_seconds"] + time.perf_counter() - self.t0

    def _check(self, info, warned=None, escape=math.inf):
        cfg, st = self.cfg, self.state
        if math.isnan(info.z_min):
            raise RunError(f"step {st.step}: a position became NaN or infinite (check dt and k_n)")
        if info.max_overlap > cfg.checks.overlap_error:
            raise RunError(f"step {st.step}: overlap {info.max_overlap:.4g} d exceeds "
                           f"checks.overlap_error = {cfg.checks.overlap_error:g} (dt too large or k_n too small "
                           f"for the impact speeds)")
        if warned is None:
            return
        if info.max_overlap > cfg.checks.overlap_warn and st.step - warned["overlap"] >= 10000:
            warned["overlap"] = st.step
            self.log.warn(f"step {st.step}: overlap {info.max_overlap:.4g} d exceeds "
                          f"checks.overlap_warn = {cfg.checks.overlap_warn:g}")
        if self.n_bed and info.z_min < self.z_bed_mean and not cfg.bed.wall:
            raise RunError(f"step {st.step}: a mobile sphere fell through the bed "
                           f"(z = {info.z_min:.4g} below the mean bed height {self.z_bed_mean:.4g}); "
                           f"under a sparse bed, bed.wall = true puts a wall plane at z = 0 to rest on")
        if info.z_max > escape and not warned["escape"]:
            warned["escape"] = True
            self.log.warn(f"step {st.step}: a sphere escaped upwards to z = {info.z_max:.4g}")

    # -- files --
    def _attrs(self, kind):
        """Attributes of a state file: identical on every rank (collective)."""
        st, cfg = self.state, self.cfg
        # one reduction: the last overlap, and one wall-clock reading for all ranks (attributes must agree)
        overlap, wall = self.domain.max_many([self.engine._overlap, self._wall_total()])
        migrated, rebalances = self._counters()
        rs = dict(self.cont, stop_samples=list(self.stop.samples), n_rebuilds=self.engine.n_rebuilds,
                  wall_seconds=float(wall), max_overlap=float(overlap), migrated=migrated, rebalances=rebalances,
                  z_bed=self.z_bed, z_bed_mean=self.z_bed_mean, h_insert=self.h_insert)
        return {"kind": kind, "step": st.step, "time": st.time, "n": self.n_mobile + self.n_bed,
                "n_mobile": self.n_mobile, "n_bed": self.n_bed, "L_x": st.L_x, "L_y": st.L_y,
                "z_bed": self.z_bed, "converged": self.converged, "ranks": self.domain.size,
                "seed": cfg.run.seed, "rng": "numpy PCG64 streams keyed by (run.seed, purpose); used at set-up only",
                "mpdem_version": __import__("mpdem").__version__,
                "config": cfg.to_toml(), "run_state": json.dumps(rs)}

    def _counters(self):
        """Migrations (summed over ranks) and rebalances of the whole run: the earlier
        segments' (restart state) and this one's (collective)."""
        seg = int(self.domain.sum_int(np.array([self.domain.n_migrated]))[0])
        return (int(self.cont.get("migrated", 0)) + seg,
                int(self.cont.get("rebalances", 0)) + int(self.domain.n_rebalances))

    def write_checkpoint(self):
        """Write RUN/checkpoints/ckpt-NNNNN.h5 collectively; keep the newest few."""
        t = time.perf_counter()
        k = self.cont["n_checkpoints"]
        self.cont["n_checkpoints"] = k + 1
        path = rundir.checkpoint_path(self.out, k)
        checkpoint.write(path, checkpoint.gather_state(self.state), self._attrs("checkpoint"), self.comm)
        if self.rank == 0:
            rundir.prune(self.out, self.cfg.output.checkpoint_keep)
        self.last_write = self.domain.max(time.perf_counter() - t)
        self.log(f"checkpoint: {path} at step {self.state.step} ({self.last_write:.2f} s)")
        return path

    def write_snapshot(self, final=False):
        """Write a snapshot (particles, contact slots and the contact list) and its XDMF sidecar."""
        from . import export
        if final:
            path = rundir.final_path(self.out)
        else:
            k = self.cont["n_snapshots"]
            self.cont["n_snapshots"] = k + 1
            path = rundir.snapshot_path(self.out, k)
            if self.rank == 0:
                os.makedirs(os.path.dirname(path), exist_ok=True)
        local = checkpoint.gather_state(self.state)
        local.update(contact_pairs(self.state, self.physics))
        checkpoint.write(path, local, self._attrs("final" if final else "snapshot"), self.comm)
        if self.rank == 0:
            export.write_xdmf(path)
            if not final:
                export.write_xdmf_series([p for _, p in rundir.snapshots(self.out)],
                                         os.path.join(self.out, rundir.SNAP_DIR, "series.xmf"))
        return path

    # -- the end --
    def finish(self):
        """Write RUN/final.h5 (with the contact list) and summary.json; print bulk z and phi."""
        cfg, st, log = self.cfg, self.state, self.log
        arrays = self.domain.gather_arrays(checkpoint.gather_state(st))
        migrated, rebalances = self._counters()
        path = self.write_snapshot(final=True)
        if self.rank != 0:
            log.close()
            return None
        steps = st.step
        seg_steps = steps - self._first_step
        ns = 1e9 * self.wall / max(seg_steps * max(self.n_mobile, 1), 1)
        summary = {"steps": steps, "time": st.time, "converged": self.converged, "status": self.status,
                   "E_k_per_particle": self.ek, "wall_seconds": self._wall_total(),
                   "segments": self.cont["segments"],
                   "ns_per_particle_step": ns, "ranks": self.domain.size,
                   "comm_share": self.domain.comm_seconds / max(self.wall, 1e-9),
                   "migrated": migrated, "rebalances": rebalances,
                   "digest": checkpoint.digest(arrays)}
        par = ""
        if self.domain.parallel:
            par = (f"; {self.domain.size} ranks, communication {100 * summary['comm_share']:.0f}%, "
                   f"{migrated} migrations, {rebalances} rebalances")
        log(f"end: {'converged' if self.converged else 'NOT CONVERGED (hit run.max_steps)'} after "
            f"{steps} steps, t = {st.time:.4g}, E_k/N = {self.ek:.3e}, wall {self.wall:.1f} s "
            f"({ns:.0f} ns per particle-step{par})")
        try:
            a = cfg.analysis
            bulk = analysis.bulk_summary(arrays["x"], arrays["fixed"], st.L_x, st.L_y, cfg.contact.mu,
                                         a.margin_bottom, a.margin_top, a.n_min, a.profile_bin, a.tall_pile)
            summary["bulk"] = bulk
            log(f"bulk: z = {bulk['z']:.3f} (without rattlers {bulk['z_no_rattlers']:.3f}, "
                f"rattlers {100 * bulk['rattler_fraction']:.1f}%), phi = {bulk['phi']:.4f}, "
                f"{bulk['n_bulk']} particles in z in [{bulk['z1']:.2f}, {bulk['z2']:.2f}], "
                f"surface h = {bulk['h']:.2f}")
        except ValueError as e:
            log.warn(f"no bulk measurement: {e}")
        rundir.write_atomic(os.path.join(self.out, "summary.json"), json.dumps(summary, indent=1))
        log(f"wrote {path}")
        if not self.converged:
            # the exit code that follows is a result, not a crash (mpiexec reports it at length)
            log(f"exit status 3: the run reached run.max_steps = {cfg.run.max_steps} before the stop rule held; "
                f"not an error, and not used for comparisons. Go on with `python -m mpdem restart {self.out} "
                f"--set run.max_steps=...`")
        log.close()
        return summary

