"""A pile run: prepare, step with monitors and the stop rule, finish.

Owns the run directory (resolved config, log, thermo table, bed table,
final state, summary) and everything that happens between steps: run-time
checks (physics.md section 8), kinetic-energy sampling and the stop rule
(5.4), progress lines. The arithmetic of a step is ``engine``'s.
"""
from __future__ import annotations

import collections
import json
import math
import os
import sys
import time

import numpy as np

from . import analysis, build, checkpoint
from .config import collision_time
from .decomp import Domain
from .engine import Engine, Physics


class RunError(RuntimeError):
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
    """Kinetic-energy stop rule of physics.md 5.4 on samples every n_sample steps."""

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
    """One pile run in ``out_dir`` from a resolved Config.

    Parameters
    ----------
    cfg : Config
    out_dir : str
    comm : mpi4py communicator or None
    quiet : bool
        No progress on stdout (the log file still gets it).
    """

    def __init__(self, cfg, out_dir, comm=None, quiet=False):
        self.cfg, self.out = cfg, out_dir
        self.domain = Domain(comm, r_list=1.0 + cfg.integration.skin,
                             tolerance=cfg.decomp.balance_tolerance, damping=cfg.decomp.balance_damping)
        self.rank = self.domain.rank
        if self.rank == 0:
            os.makedirs(out_dir, exist_ok=True)
        self.log = Logger(os.path.join(out_dir, "log.txt"), quiet, self.rank)
        self.physics = Physics.from_config(cfg)
        self.state = None
        self.bed = None
        self.converged = False
        self.wall = 0.0

    # -- preparation --
    def prepare(self):
        """Build or read the initial state, check it, write config and bed files."""
        cfg, log = self.cfg, self.log
        for w in cfg.warnings:
            log.warn(w)
        if self.rank == 0:
            with open(os.path.join(self.out, "config.toml"), "w") as fh:
                fh.write(cfg.to_toml())
        L_x, L_y = cfg.box.L_x, cfg.box.L_y
        slots = None
        if cfg.run.initial_file:
            ids, x, v, omega, fixed = self._read_initial(cfg.run.initial_file)
            slots = self._initial_slots
            z_bed = float(x[fixed == 1, 2].max()) if fixed.any() else -math.inf
            self.bed = build.Bed(x[fixed == 1].copy(), note=f"from {cfg.run.initial_file}")
            self.h_insert = float(x[fixed == 0, 2].max() - max(z_bed, x[fixed == 0, 2].min())) if (fixed == 0).any() else 0.0
        else:
            self.bed = self._bed()
            z_bed = self.bed.z_top
            N = cfg.pour.N
            H = build.insertion_height(N, L_x, L_y, cfg.pour.phi_i)
            self.h_insert = H
            log(f"pour: inserting {N} spheres at phi_i = {cfg.pour.phi_i:g} in "
                f"z in [{z_bed + 1:.3f}, {z_bed + 1 + H:.3f}]")
            xm = build.insert_random(build.rng(cfg.run.seed, build.STREAM_POUR), N, L_x, L_y,
                                     z_bed + 1.0, z_bed + 1.0 + H, obstacles=self.bed.x)
            vm = build.initial_velocities(build.rng(cfg.run.seed, build.STREAM_VELOCITY), N, cfg.pour.K0)
            nb = len(self.bed.x)
            ids = np.arange(N + nb, dtype=np.int64)
            x = np.concatenate([xm, self.bed.x])
            v = np.concatenate([vm, np.zeros((nb, 3))])
            omega = np.zeros_like(x)
            fixed = np.concatenate([np.zeros(N, np.uint8), np.ones(nb, np.uint8)])
        self.z_bed = z_bed
        z_floor = self.bed.z_mean if cfg.run.initial_file else z_bed + 0.5
        build.check_initial(ids, x, fixed, L_x, L_y, z_floor, allow_overlap=slots is not None)
        if len(self.bed.x) and self.rank == 0:
            build.write_table(os.path.join(self.out, "bed.txt"), ids[fixed == 1], x[fixed == 1],
                              fixed=fixed[fixed == 1])
        self.n_mobile = int((fixed == 0).sum())
        # every rank holds the whole initial state (built identically); each keeps its slab
        whole = {"id": ids, "x": x, "v": v, "omega": omega, "fixed": fixed}
        if slots is not None:
            whole.update(zip(("count", "partner", "ds"), slots))
        self.state = self.domain.scatter(whole, L_x, L_y, slots=cfg.integration.contact_slots)
        p = self.physics
        t_col = collision_time(p.gamma_n, p.k_n)
        log(f"mpdem: {self.n_mobile} mobile + {len(self.bed.x)} bed spheres, box {L_x:g} x {L_y:g}, "
            f"{cfg.contact.model} k_n = {p.k_n:g}, k_t = {p.k_t:g}, gamma_n = {p.gamma_n:.6g} "
            f"(epsilon = {cfg.contact.epsilon:.4g}), gamma_t = {p.gamma_t:g}, mu = {p.mu:g}")
        log(f"mpdem: dt = {p.dt:.6g} (t_col / dt = {t_col / p.dt:.1f}), skin = {p.skin:g}, "
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
        self._initial_slots = None
        if not os.path.exists(path):
            raise build.InputError(f"initial file {path}: no such file")
        if checkpoint.is_state_file(path):
            a, _ = checkpoint.read_state(path)
            ids, x, v, omega, fixed = a["id"], a["x"], a["v"], a["omega"], a["fixed"]
            self._initial_slots = (a["count"], a["partner"], a["ds"])
        else:
            t = build.read_table(path)
            ids, x, v, fixed = t["ids"], t["x"], t["v"], t["fixed"]
            omega = np.zeros_like(x)
        if all_fixed:
            fixed = np.ones(len(ids), np.uint8)
        return ids, x, v, omega, fixed

    # -- the loop --
    def run(self):
        """Step until the stop rule or max_steps; then write the final state."""
        cfg, log, st = self.cfg, self.log, self.state
        eng = self.engine = Engine(st, self.physics, self.domain)
        stop = StopRule(cfg.stop.E_stop, cfg.stop.rule, cfg.stop.window,
                        cfg.stop.sample_interval, self.physics.dt)
        thermo = open(os.path.join(self.out, "thermo.csv"), "w") if self.rank == 0 else None
        if thermo:
            thermo.write("step,time,ek,ek_trans,ek_rot,ek_window,max_overlap,contacts_per_particle,"
                         "z_max,rebuilds,wall_seconds\n")
        t0 = time.perf_counter()
        info = eng.setup()
        self._check(info)
        N = max(self.n_mobile, 1)
        max_steps = cfg.run.max_steps
        every = cfg.output.progress_every
        t_last, s_last = time.perf_counter(), st.step
        rate = math.nan
        escape = self.z_bed + 1.0 + self.h_insert + cfg.checks.escape_margin
        warned = {"escape": False, "overlap": -10**18}
        ek = math.inf
        while st.step < max_steps:
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
                                 f"{info.z_max:.6g},{eng.n_rebuilds},{time.perf_counter() - t0:.3f}\n")
                if stop.satisfied():
                    self.converged = True
                    break
            if st.step % every == 0:
                now = time.perf_counter()
                rate = (st.step - s_last) / max(now - t_last, 1e-9)
                t_last, s_last = now, st.step
                t_stop = stop.time_to_stop(self.physics.dt) / self.physics.dt / rate
                par = ""
                if self.domain.parallel:
                    comm_share = self.domain.comm_seconds / max(now - t0, 1e-9)
                    par = f"  imbalance {self.domain.imbalance(st):4.2f}  comm {100 * comm_share:3.0f}%"
                log(f"step {st.step:>9d}  t {st.time:9.3f}  E_k/N {ek:9.3e}  "
                    f"max_delta {info.max_overlap:8.2e}  contacts/N {info.n_contacts / N:5.2f}  "
                    f"{rate:7.0f} steps/s{par}  eta cap {_fmt_seconds((max_steps - st.step) / rate)}  "
                    f"stop ~{_fmt_seconds(t_stop)}")
        self.wall = time.perf_counter() - t0
        if thermo:
            thermo.close()
        et, er = eng.kinetic()
        self.ek = (et + er) / N
        return self.converged

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
        if len(self.bed.x) and info.z_min < self.bed.z_mean:
            raise RunError(f"step {st.step}: a mobile sphere fell through the bed "
                           f"(z = {info.z_min:.4g} below the mean bed height {self.bed.z_mean:.4g})")
        if info.z_max > escape and not warned["escape"]:
            warned["escape"] = True
            self.log.warn(f"step {st.step}: a sphere escaped upwards to z = {info.z_max:.4g}")

    # -- the end --
    def finish(self):
        """Write RUN/final.h5 and summary.json; print bulk z and phi."""
        cfg, st, log = self.cfg, self.state, self.log
        arrays = self.domain.gather_arrays(checkpoint.gather_state(st))
        migrated = int(self.domain.sum_int(np.array([self.domain.n_migrated]))[0])
        if self.rank != 0:
            log.close()
            return None
        attrs = {"kind": "final", "step": st.step, "time": st.time, "n_mobile": self.n_mobile,
                 "n_bed": len(self.bed.x), "L_x": st.L_x, "L_y": st.L_y, "z_bed": self.z_bed,
                 "converged": self.converged, "config": cfg.to_toml()}
        path = os.path.join(self.out, "final.h5")
        checkpoint.write_state(path, arrays, attrs)
        steps = st.step
        ns = 1e9 * self.wall / max(steps * max(self.n_mobile, 1), 1)
        summary = {"steps": steps, "time": st.time, "converged": self.converged,
                   "E_k_per_particle": self.ek, "wall_seconds": self.wall,
                   "ns_per_particle_step": ns, "ranks": self.domain.size,
                   "comm_share": self.domain.comm_seconds / max(self.wall, 1e-9),
                   "migrated": migrated, "rebalances": self.domain.n_rebalances,
                   "digest": checkpoint.digest(arrays)}
        par = ""
        if self.domain.parallel:
            par = (f"; {self.domain.size} ranks, communication {100 * summary['comm_share']:.0f}%, "
                   f"{migrated} migrations, {self.domain.n_rebalances} rebalances")
        log(f"end: {'converged' if self.converged else 'NOT CONVERGED (hit run.max_steps)'} after "
            f"{steps} steps, t = {st.time:.4g}, E_k/N = {self.ek:.3e}, wall {self.wall:.1f} s "
            f"({ns:.0f} ns per particle-step{par})")
        try:
            a = cfg.analysis
            bulk = analysis.bulk_summary(arrays["x"], arrays["fixed"], st.L_x, st.L_y, cfg.contact.mu,
                                         a.margin_bottom, a.margin_top, a.n_min, a.profile_bin)
            summary["bulk"] = bulk
            log(f"bulk: z = {bulk['z']:.3f} (without rattlers {bulk['z_no_rattlers']:.3f}, "
                f"rattlers {100 * bulk['rattler_fraction']:.1f}%), phi = {bulk['phi']:.4f}, "
                f"{bulk['n_bulk']} particles in z in [{bulk['z1']:.2f}, {bulk['z2']:.2f}], "
                f"surface h = {bulk['h']:.2f}")
        except ValueError as e:
            log.warn(f"no bulk measurement: {e}")
        with open(os.path.join(self.out, "summary.json"), "w") as fh:
            json.dump(summary, fh, indent=1)
        log(f"wrote {path}")
        log.close()
        return summary
