"""What a run does between steps, each on its own schedule.

``Checks`` (every step), ``StopRule`` with ``Thermo`` (every sample),
``Progress`` (every ``output.progress_every`` steps), ``Checkpoints`` and
``Snapshots`` (their ``output`` cadences). Each object that a restart must
continue serialises its state into a typed record (a dataclass, ``record``);
the run stores each record under its own name in the ``run_state`` attribute
of every state file (``runstate.RunState``), and a run built from a file gives
each object its record back (``restore``).
All ranks call every object at the same steps; only rank 0 writes text.
"""
from __future__ import annotations

import collections
import math
import os
import sys
import time
from dataclasses import dataclass, field, fields

from ..io import rundir
from ..errors import RunError


def from_dict(cls, d):
    """A record of type ``cls`` from the fields of ``d`` it names (others ignored, missing ones default)."""
    return cls(**{f.name: d[f.name] for f in fields(cls) if f.name in d})


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

    def note(self, msg):
        """``msg`` in the log file only (what the command line says on stderr besides)."""
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


def next_multiple(step, every):
    """The first step after ``step`` that is a multiple of ``every`` (None if ``every`` is 0: never)."""
    return (step // every + 1) * every if every else None


def quiet_span(step, max_steps, schedules, most):
    """The steps after ``step`` before the first at which one of ``schedules`` (each with a
    ``next_due(step)``: a step, or None for never) is due, short of ``max_steps``; at most ``most``."""
    due = [d for d in (sch.next_due(step) for sch in schedules) if d is not None]
    return max(0, min(most, max_steps - step - 1, *(d - step - 1 for d in due)))


def fmt_seconds(s):
    """``1h02m`` or ``3m05s``; ``?`` for an unknown duration."""
    if not math.isfinite(s) or s < 0:
        return "?"
    s = int(s)
    return f"{s // 3600}h{s % 3600 // 60:02d}m" if s >= 3600 else f"{s // 60}m{s % 60:02d}s"


class Checks:
    """Run-time checks of docs/model.md section 8, at every step.

    Parameters
    ----------
    cfg : Config
        ``checks.*`` and ``bed.wall``.
    pile : initial.Pile
    n_bed : int
    log : Logger
    """

    def __init__(self, cfg, pile, n_bed, log):
        self.c, self.wall, self.log = cfg.checks, cfg.bed.wall, log
        self.under = pile.z_bed_mean if n_bed and not cfg.bed.wall else -math.inf
        self.escape = pile.z_bed + 1.0 + pile.h_insert + cfg.checks.escape_margin
        self.escaped, self.warned_at = False, -10**18

    def fatal(self, info, step):
        """Raise RunError for a NaN position or an overlap beyond ``checks.overlap_error``."""
        if math.isnan(info.z_min):
            raise RunError(f"step {step}: a position became NaN or infinite (check dt and k_n)")
        if info.max_overlap > self.c.overlap_error:
            raise RunError(f"step {step}: overlap {info.max_overlap:.4g} d exceeds "
                           f"checks.overlap_error = {self.c.overlap_error:g} (dt too large or k_n too small "
                           f"for the impact speeds)")

    def __call__(self, info, step):
        """All checks of one step: errors raise RunError, warnings are logged (overlaps at most every 10^4 steps)."""
        self.fatal(info, step)
        if info.max_overlap > self.c.overlap_warn and step - self.warned_at >= 10000:
            self.warned_at = step
            self.log.warn(f"step {step}: overlap {info.max_overlap:.4g} d exceeds "
                          f"checks.overlap_warn = {self.c.overlap_warn:g}")
        if info.z_min < self.under:
            raise RunError(f"step {step}: a mobile sphere fell through the bed "
                           f"(z = {info.z_min:.4g} below the mean bed height {self.under:.4g}); "
                           f"under a sparse bed, bed.wall = true puts a wall plane at z = 0 to rest on")
        if info.z_max > self.escape and not self.escaped:
            self.escaped = True
            self.log.warn(f"step {step}: a sphere escaped upwards to z = {info.z_max:.4g}")


@dataclass
class StopRecord:
    """Restart state of the stop rule: its window of E_k/N samples [m g d] and the energy they measure."""
    stop_samples: list = field(default_factory=list)
    stop_energy: str = "total"


class StopRule:
    """Stop rule of docs/model.md 5.4 on samples every n_sample steps: the kinetic energy (of the
    total or the translational energy: ``stop.energy``) over a window or at one sample, or the
    unbalanced-force ratio at one sample (``stop.rule = "force"``)."""

    def __init__(self, E_stop, rule, window, sample_interval, dt, energy="total", force_ratio=0.01):
        self.E_stop, self.rule, self.energy, self.ratio_stop = E_stop, rule, energy, force_ratio
        self.n_sample = max(1, int(round(sample_interval / dt)))
        self.size = max(1, int(round(window / (self.n_sample * dt))))
        self.samples = collections.deque(maxlen=self.size)
        self.trans = collections.deque(maxlen=self.size)   # the translational part of the same samples
        self.hinted = False             # the spinner hint (``spin_hint``) said once in this segment
        self.ratio = math.nan           # the newest sample's unbalanced-force ratio
        self.in_flight = -1             # and its mobile spheres without a contact
        self.latest = math.inf          # the newest sample, kept when a ramp or a flow phase clears the window

    @classmethod
    def from_config(cls, cfg, dt):
        s = cfg.stop
        return cls(s.E_stop, s.rule, s.window, s.sample_interval, dt, s.energy, s.force_ratio)

    def due(self, step):
        return step % self.n_sample == 0

    def next_due(self, step):
        """The first step after ``step`` that is ``due``."""
        return next_multiple(step, self.n_sample)

    def add(self, e_trans, e_rot, N, ratio=math.nan, in_flight=-1):
        """A sample: of the translational and rotational kinetic energy [m g d] of N
        particles, the part ``energy`` names, per particle; the unbalanced-force ratio and the
        mobile spheres without a contact."""
        self.latest = (e_trans if self.energy == "translational" else e_trans + e_rot) / N
        self.samples.append(self.latest)
        self.trans.append(e_trans / N)
        self.ratio, self.in_flight = ratio, in_flight

    def clear(self):
        """Empty the window (a ramp or a flow phase: the pile is not yet the one to settle)."""
        self.samples.clear()
        self.trans.clear()

    def spin_hint(self):
        """Once, a message when the window rule on the total energy is held up by rotation alone: a
        full window whose translational mean is below E_stop while the total's is not, the spin at
        least 10 times the translation (a sphere spinning about two contacts, docs/model.md 5.4).
        None otherwise, and after the first message."""
        if (self.hinted or self.energy != "total" or self.rule != "window" or len(self.samples) < self.size
                or len(self.trans) < self.size):
            return None
        total, trans = self.mean, sum(self.trans) / len(self.trans)
        if not (trans < self.E_stop <= total and total - trans >= 10 * trans):
            return None
        self.hinted = True
        return (f"E_k/N is {total:.3g} over the stop window, but its translational part is {trans:.3g}, below "
                f"stop.E_stop = {self.E_stop:.3g}: rotation alone holds the run (a sphere spinning about two "
                f"contacts, which nothing damps: docs/model.md 5.4). The pile may be at rest; "
                f"`mpdem restart RUN --set stop.energy=translational` stops on the translational energy")

    @property
    def last(self):
        """The newest sample (inf before the first of this segment), also while a ramp or a flow
        phase keeps the window empty."""
        if math.isfinite(self.latest) or not self.samples:
            return self.latest
        return self.samples[-1]         # a restarted window, before this segment's first sample

    @property
    def mean(self):
        return sum(self.samples) / len(self.samples) if self.samples else math.inf

    def satisfied(self):
        if self.rule == "force":
            # under gravity a sphere without a contact is not at rest: a pouring pile's ratio is small too
            return self.in_flight == 0 and self.ratio < self.ratio_stop
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

    def record(self):
        return StopRecord(list(self.samples), self.energy)

    def restore(self, rec):
        # a restart that changes stop.energy starts a new window (the old samples measure the other energy)
        if rec.stop_energy == self.energy:
            self.samples.extend(rec.stop_samples)


class Thermo:
    """RUN/thermo.csv: one line per stop-rule sample (rank 0 writes; a restart truncates it first).

    ``v_x``: the mean velocity of the mobile spheres along x (downslope on an incline, docs/model.md
    5.5), from their momentum summed exactly; flat while a chute flow is steady."""

    HEADER = ("step,time,ek,ek_trans,ek_rot,ek_window,max_overlap,contacts_per_particle,"
              "z_max,rebuilds,wall_seconds,force_ratio,v_x\n")

    def __init__(self, out_dir, rank):
        self.fh = None
        self.columns = 13
        # opened at the first line, so that a run that fails before its first sample leaves no table
        self.path = os.path.join(out_dir, "thermo.csv") if rank == 0 else None

    def _open(self):
        new = not os.path.exists(self.path) or os.path.getsize(self.path) == 0
        if not new:
            # a table begun before the force_ratio (12th) or v_x (13th) column keeps its columns
            with open(self.path) as fh:
                self.columns = min(13, len(fh.readline().rstrip("\n").split(",")))
        self.fh = open(self.path, "a")
        if new:
            self.fh.write(self.HEADER)

    def write(self, st, et, er, N, stop, info, rebuilds, wall, p_x=0.0):
        """One line: energies per mobile particle, the stop window's mean, the step's figures, the
        unbalanced-force ratio, the mean v_x (``p_x``: the momentum along x [m sqrt(g d)])."""
        if self.path is None:
            return
        if self.fh is None:
            self._open()
        cols = [f"{st.step}", f"{st.time:.10g}", f"{(et + er) / N:.6e}", f"{et / N:.6e}", f"{er / N:.6e}",
                f"{stop.mean:.6e}", f"{info.max_overlap:.6e}", f"{info.n_contacts / N:.5f}", f"{info.z_max:.6g}",
                f"{rebuilds}", f"{wall:.3f}", f"{stop.ratio:.6e}", f"{p_x / N:.6e}"]
        self.fh.write(",".join(cols[:self.columns]) + "\n")

    def flush(self):
        if self.fh:
            self.fh.flush()

    def close(self):
        if self.fh:
            self.fh.close()


class Progress:
    """A progress line every ``output.progress_every`` steps: rate, E_k, overlap, ETAs."""

    def __init__(self, every, log, domain, dt, max_steps, N, step, t0):
        self.every, self.log, self.domain, self.dt = every, log, domain, dt
        self.max_steps, self.N = max_steps, N
        self.t0 = t0                    # the loop's start (communication share) [perf_counter s]
        self.t_last, self.s_last = time.perf_counter(), step

    def due(self, step):
        return step % self.every == 0

    def next_due(self, step):
        """The first step after ``step`` that is ``due``."""
        return next_multiple(step, self.every)

    def line(self, st, info, stop):
        """Log the line (collective: every rank calls it at the same steps)."""
        now = time.perf_counter()
        rate = (st.step - self.s_last) / max(now - self.t_last, 1e-9)
        self.t_last, self.s_last = now, st.step
        t_stop = stop.time_to_stop(self.dt) / self.dt / rate
        par = ""
        if self.domain.parallel:
            # a collective: every rank computes it, rank 0 prints it
            imbalance = self.domain.imbalance(st)
            share = self.domain.comm_seconds / max(now - self.t0, 1e-9)
            par = f"  imbalance {imbalance:4.2f}  comm {100 * share:3.0f}%"
        # no E_k before the first sample: a dash, not "inf"
        ek = stop.last
        ek_text = f"{ek:9.3e}" if math.isfinite(ek) else f"{'-':>9}"
        fr_text = f"{stop.ratio:8.2e}" if math.isfinite(stop.ratio) else f"{'-':>8}"
        self.log(f"step {st.step:>9d}  t {st.time:9.3f}  E_k/N {ek_text}  F_unbal {fr_text}  "
                 f"max_delta {info.max_overlap:8.2e}  contacts/N {info.n_contacts / self.N:5.2f}  "
                 f"{rate:7.0f} steps/s{par}  eta cap {fmt_seconds((self.max_steps - st.step) / rate)}  "
                 f"stop ~{fmt_seconds(t_stop)}")


@dataclass
class CheckpointRecord:
    """Restart state of the checkpoints: how many were written (numbers the next)."""
    n_checkpoints: int = 0


class Checkpoints:
    """RUN/checkpoints/ckpt-NNNNN.h5 every ``output.checkpoint_every`` steps or
    ``output.checkpoint_seconds`` of wall time, and at an early stop; the newest
    ``output.checkpoint_keep`` are kept.

    Parameters
    ----------
    out_dir : str
    output : config section ``output``
    write : callable(path, kind)
        Writes the state file (collective).
    domain : Domain
    log : Logger
    """

    def __init__(self, out_dir, output, write, domain, log):
        self.out, self.o, self._write, self.domain, self.log = out_dir, output, write, domain, log
        self.n = 0
        self.last_write = 0.0           # seconds the last write took (slowest rank)
        self.start_clock()

    def start_clock(self):
        """The clock schedule counts from now (the loop's start, and each write)."""
        self.next_clock = time.monotonic() + self.o.checkpoint_seconds

    def clock_due(self, now):
        """This rank's clock says a checkpoint is due (agreed over ranks in the step's allreduce)."""
        return self.o.checkpoint_seconds > 0 and now >= self.next_clock

    def due(self, step, clock):
        return bool(self.o.checkpoint_every and step % self.o.checkpoint_every == 0) or bool(clock)

    def next_due(self, step):
        """The first step after ``step`` that is ``due`` by the step count (None: none is)."""
        return next_multiple(step, self.o.checkpoint_every)

    def write(self, step):
        """Write the next checkpoint (collective); returns its path."""
        t = time.perf_counter()
        path = rundir.checkpoint_path(self.out, self.n)
        self.n += 1
        self._write(path, "checkpoint")
        if self.domain.rank == 0:
            rundir.prune(self.out, self.o.checkpoint_keep)
        self.last_write = self.domain.max(time.perf_counter() - t)
        self.start_clock()
        self.log(f"checkpoint: {path} at step {step} ({self.last_write:.2f} s)")
        return path

    def record(self):
        return CheckpointRecord(self.n)

    def restore(self, rec):
        self.n = rec.n_checkpoints


@dataclass
class SnapshotRecord:
    """Restart state of the snapshots: how many were written (numbers the next)."""
    n_snapshots: int = 0


class Snapshots:
    """RUN/snapshots/snap-NNNNN.h5 every ``output.snapshot_every`` steps, with the files of
    ``io.export.SIDECARS`` beside each (XDMF, the contact network, the time series).

    ``write`` takes the same callable as ``Checkpoints``.
    """

    def __init__(self, out_dir, every, write, rank):
        self.out, self.every, self._write, self.rank = out_dir, every, write, rank
        self.n = 0

    def due(self, step):
        return bool(self.every) and step % self.every == 0

    def next_due(self, step):
        """The first step after ``step`` that is ``due`` (None: none is)."""
        return next_multiple(step, self.every)

    def write(self, final=False):
        """Write the next snapshot, or RUN/final.h5 (collective); returns its path."""
        from ..io.export import SIDECARS
        if final:
            path = rundir.final_path(self.out)
        else:
            path = rundir.snapshot_path(self.out, self.n)
            self.n += 1
            if self.rank == 0:
                os.makedirs(os.path.dirname(path), exist_ok=True)
        self._write(path, "final" if final else "snapshot")
        if self.rank == 0:
            for sidecar in SIDECARS:
                sidecar.write(path, self.out, final)
        return path

    def record(self):
        return SnapshotRecord(self.n)

    def restore(self, rec):
        self.n = rec.n_snapshots
