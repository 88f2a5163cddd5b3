"""Stiffening a settled pile (docs/model.md 6.6): a new run from a pile settled at a softer spring, with
k_n raised smoothly from that stiffness to the config's before the pile relaxes by the stop rule.

The stored overlaps are those of the softer spring: met at once by the stiffer one, they would hold
ten times the elastic energy and launch the pile. So a run with ``stiffen.k_n_from`` > 0 (the k_n
its ``run.initial_file`` was settled at) steps through a ramp: the law changes every ``tread``
steps (``stiffen.update_interval`` [tau], rounded to whole steps), and tread m of M (M treads over
``stiffen.ramp_time``) has

    k_n(m) = k_n_from (k_n / k_n_from)^(m / M),
    k_t(m) = k_t k_n(m) / k_n, gamma_n(m) from contact.epsilon at k_n(m) (``config.gamma_n_from_epsilon``),
    gamma_t(m) = gamma_t gamma_n(m) / gamma_n,

the config's law itself from tread M on (the step ``end``). At the first evaluation of each tread
every stored Delta s is multiplied by k_t(m - 1) / k_t(m) (``Law.ds_scale``), so that the tangential
spring force k_t Delta s is continuous; the normal overlaps relax as the spring stiffens. dt is the
config's (derived from the final k_n) throughout. The stop rule starts its window at ``end``.

The law of a step is a function of the step alone, so a restart inside the ramp goes on with the
same laws, and every rank and engine computes the same ones on the host (Python floats).
"""
from __future__ import annotations

import math
import os

from . import config
from .errors import InputError
from .io import checkpoint, packing, rundir
from .io.pilefile import file_facts

class Ramp:
    """The laws of a stiffening run, step by step.

    Parameters
    ----------
    cfg : Config
        ``stiffen.*``, ``contact.*`` and ``integration.dt``.
    law : kernels.law.Law
        The config's law (``Physics.law``): the one from ``end`` on.

    Attributes
    ----------
    tread : int
        Steps of one tread (the law is the same within it).
    treads : int
        M, the treads of the ramp.
    end : int
        The first step with the config's law; the stop rule counts from there.
    """

    def __init__(self, cfg, law):
        s, c = cfg.stiffen, cfg.contact
        dt = cfg.integration.dt
        self.final = law
        self.k_from, self.k_to = s.k_n_from, c.k_n
        self.epsilon, self.gamma_t_ratio = c.epsilon, (c.gamma_t / c.gamma_n if c.gamma_n > 0 else 0.0)
        self.k_t_ratio = c.k_t / c.k_n
        self.tread = max(1, int(round(s.update_interval / dt)))
        self.treads = max(1, math.ceil(s.ramp_time / (self.tread * dt) - 1e-9))
        self.end = self.treads * self.tread
        self._cache = {}

    @classmethod
    def from_config(cls, cfg, law):
        """The ramp of ``cfg``, or None when it stiffens nothing (``stiffen.k_n_from`` = 0)."""
        return cls(cfg, law) if cfg.stiffen.k_n_from > 0 else None

    def active(self, step):
        """Whether the law of ``step`` is still a ramp's (step < end)."""
        return step < self.end

    def k_n(self, m):
        """k_n of tread ``m`` [m g / d] (the config's from tread M on)."""
        if m >= self.treads:
            return self.final.k_n
        return self.k_from * (self.k_to / self.k_from) ** (m / self.treads)

    def _tread_law(self, m):
        """The law of tread ``m`` with ds_scale 1."""
        if m >= self.treads:
            return self.final
        law = self._cache.get(m)
        if law is None:
            k_n = self.k_n(m)
            gamma_n = config.gamma_n_from_epsilon(self.epsilon, k_n)
            law = self.final._replace(k_n=k_n, k_t=self.k_t_ratio * k_n, gamma_n=gamma_n,
                                      gamma_t=self.gamma_t_ratio * gamma_n)
            self._cache = {m: law}      # the treads come one after the other
        return law

    def law(self, step):
        """The ``Law`` of the force evaluation at ``step`` (the step's end): its tread's, with
        ``ds_scale`` = k_t(previous tread) / k_t(this one) at a tread's first step."""
        m = step // self.tread
        law = self._tread_law(m)
        if step % self.tread == 0 and 0 < m <= self.treads and law.k_t > 0.0:
            law = law._replace(ds_scale=self._tread_law(m - 1).k_t / law.k_t)
        return law

    def room(self, step):
        """Steps after ``step`` that share the law of ``step + 1`` (none if that is a tread's first
        step, whose law rescales the history); unbounded (a large number) past the ramp."""
        first = step + 1
        if first > self.end:
            return 1 << 62
        if first % self.tread == 0:     # the ramp's end too: its first step rescales the history
            return 0
        return (first // self.tread + 1) * self.tread - first

    def describe(self, dt):
        """One log line."""
        return (f"stiffen: k_n from {self.k_from:g} to {self.k_to:g} over {self.end} steps ({self.end * dt:g} tau), "
                f"{self.treads} treads of {self.tread} steps (x {(self.k_to / self.k_from) ** (1 / self.treads):.6f} "
                f"each); the stop rule from step {self.end}")


def check_initial(cfg, path):
    """Refuse a new run that would meet an mpdem state or packing file's contacts with a stiffer spring
    without the ramp, or whose ramp starts from another stiffness than the file's.

    Raises
    ------
    InputError
        Naming the file, both stiffnesses and what to set.
    """
    if checkpoint.is_state_file(path):
        attrs = checkpoint.read_attrs(path)
    elif packing.is_packing(path):
        attrs = packing.read(path)[1]
    else:
        return      # a table or a LAMMPS file says nothing of its stiffness: stiffen.k_n_from is trusted
    if "config" not in attrs:
        return
    try:
        made = config.resolve(config.raw_from_toml(attrs["config"], origin=path))
    except config.ConfigError:
        return
    was, now, ramp = made.contact.k_n, cfg.contact.k_n, cfg.stiffen.k_n_from
    if ramp > 0 and ramp != was:
        raise InputError(f"stiffen.k_n_from = {ramp:g}: run.initial_file {path} was made at contact.k_n = "
                         f"{was:g}; accepted: stiffen.k_n_from = {was:g}")
    if ramp == 0 and now > was:
        raise InputError(f"contact.k_n = {now:g}: run.initial_file {path} was settled at contact.k_n = {was:g}, "
                         f"and its overlaps met at once by the stiffer spring would launch the pile; set "
                         f"stiffen.k_n_from = {was:g} (a ramp over stiffen.ramp_time, at most a decade a rung) "
                         f"or use `mpdem stiffen`")


def rung_config(run, k_n, sets=()):
    """The config of a rung that stiffens the finished run ``run`` to ``k_n`` (``mpdem stiffen``): the
    run's own keys (those derived from k_n derived again), contact.k_n = ``k_n``, stiffen.k_n_from =
    the run's k_n, run.initial_file = RUN/final.h5 (without one, the packing the run kept, RUN/packing.npz:
    frictionless piles only, ``initial.from_packing``), then ``sets`` (``--set`` texts).

    Raises
    ------
    InputError
        Neither final.h5 nor packing.npz in ``run``, or ``k_n`` not above the run's by at most ten times
        (naming --k_n).
    ConfigError
        From the config's own checks. (A frictional pile's packing is refused when the run starts,
        ``initial.check_file``, before any work.)
    """
    if not os.path.isdir(run):
        raise InputError(f"{run}: no such run directory; stiffen accepts a finished run's directory")
    final = rundir.final_path(run)
    if not os.path.exists(final):
        final = os.path.join(run, "packing.npz")
    if not os.path.exists(final):
        raise InputError(f"{run}: neither final.h5 nor packing.npz; stiffen accepts a finished run's directory")
    with open(os.path.join(run, "config.toml")) as fh:
        raw = config.raw_from_toml(fh.read(), origin=os.path.join(run, "config.toml"))
    # the pile's box and count are its final state's (``initial.config_for``): a run started from a file
    # may have recorded the config's, which need not be the pile's
    raw.update(file_facts(final))
    # the rung starts from a state or packing file, whose own flags say which spheres are bed: a LAMMPS
    # file's bed types, which the run needed, are not the rung's (lammps.initial_for refuses them then)
    raw.pop("run.fixed_types", None)
    was = config.resolve(raw).contact.k_n
    if not 1 < k_n / was <= config.MAX_RISE:
        raise InputError(f"--k_n {k_n:g}: {run} was run at contact.k_n = {was:g}; accepted above it by at most ten "
                         f"times (up to {10 * was:g}; stiffen the result again for more)")
    ours = [f"contact.k_n={k_n!r}", f"stiffen.k_n_from={was!r}", f"run.initial_file={config.toml_value(final)}"]
    return config.load(None, ours + list(sets), base=raw)
