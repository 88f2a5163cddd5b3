"""What every engine shares: the run's numerics (``Physics``), the record a step reports (``StepInfo``),
and the methods both engines run alike (``EngineBase``)."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from .. import planes
from ..kernels.bundles import Particles
from ..kernels.exactsum import to_float
from ..kernels.law import Law, make_law


@dataclass(frozen=True)
class Physics:
    """A run's contact law, as the kernels take it, and the numerics and boundaries around it.

    Attributes
    ----------
    law : kernels.law.Law
        The contact law, gravity vector and time step (reduced units), built once
        (``from_config``, ``of``).
    skin, near_skin : float
        Reach of the neighbour lists beyond contact, and of the near lists [d].
    floor : bool
        The temporary frictionless floor at z = 0 (bed making).
    wall : bool
        The wall plane z = 0 under the bed (``bed.wall``).
    planes : tuple of planes.Plane
        Further planes (a lid, a side wall), after those two.
    """
    law: Law
    skin: float = 0.2
    near_skin: float = 0.03
    floor: bool = False
    wall: bool = False
    planes: tuple = ()

    @property
    def dt(self):
        """The time step [tau] (the law's: the kernels take it there)."""
        return self.law.dt

    @classmethod
    def of(cls, *, skin=0.2, near_skin=0.03, floor=False, wall=False, planes=(), **law):
        """Physics of the law's values by the names of ``kernels.law.make_law`` (k_n, k_t, gamma_n,
        gamma_t, mu, dt, gravity, incline, model, limit_damping, rescale_history) and the numerics."""
        return cls(make_law(**law), skin, near_skin, floor, wall, tuple(planes))

    def with_law(self, law):
        """The same numerics and boundaries with another ``Law`` (the stiffening ramp's, ``stiffen``)."""
        return replace(self, law=law)

    @classmethod
    def from_config(cls, cfg):
        c = cfg.contact
        return cls.of(k_n=c.k_n, k_t=c.k_t, gamma_n=c.gamma_n, gamma_t=c.gamma_t, mu=c.mu,
                      dt=cfg.integration.dt, skin=cfg.integration.skin, near_skin=cfg.integration.near_skin,
                      gravity=cfg.box.gravity, incline=cfg.box.incline, model=c.model,
                      limit_damping=c.limit_damping, rescale_history=(c.history == "rotate"), wall=cfg.bed.wall)


class NoFlags(NamedTuple):
    """The flags of a step that no driver watches (bed making, benchmarks, tests): none."""


NO_FLAGS = NoFlags()


class StepInfo(NamedTuple):
    """What one step reports to the monitors, already reduced over ranks; a new record every step.

    Attributes
    ----------
    max_overlap : float
        Largest overlap of the previous force evaluation [d].
    n_contacts : int
        Contacts of the whole pile (counted from both partners) as of the last ``Engine.contacts()``.
    z_min, z_max : float
        Height range of the owned mobile rows after the drift [d]; z_min is NaN when a
        position became NaN or infinite.
    flags : NamedTuple of float
        The driver's flags given to ``Engine.step``, each the max over ranks, as a record of the
        same type (``simulation.StepFlags`` in a run; ``NoFlags`` without a driver).
    """
    max_overlap: float = 0.0
    n_contacts: int = 0
    z_min: float = math.inf
    z_max: float = -math.inf
    flags: tuple = NO_FLAGS


class EngineBase:
    """The parts of the engine interface (``engine/__init__.py``) that both engines run alike, on
    top of their own ``rebuild``, ``forces``, ``step`` and ``complete``; an engine sets ``state``,
    ``domain``, ``info``, ``n_rebuilds``, ``last_overlap``, ``n_contacts`` and ``_contacts``."""

    def start(self):
        """Neighbour lists and the set-up force evaluation (no history increment)."""
        self.rebuild()
        self.last_overlap, self._contacts = self.forces(increment=False)
        self.info = StepInfo(self.domain.max(self.last_overlap), self.contacts())
        return self.info

    def start_from_file(self, max_overlap=0.0, n_rebuilds=0):
        """Set-up for a state read from a state file: lists only.

        Forces, torques and contact slots come from the file (they carry the
        half-step velocities of the damping terms), so nothing is recomputed
        and the next step is bit for bit the one the straight run takes.
        ``max_overlap`` and ``n_rebuilds`` are the straight run's (this
        set-up's rebuild is not counted).
        """
        s = self.state
        self._contacts = int(s.count[:s.n_own][s.fixed[:s.n_own] == 0].sum())
        self.rebuild()
        self.n_rebuilds = n_rebuilds
        self.last_overlap = max_overlap
        self.info = StepInfo(self.domain.max(self.last_overlap), self.contacts())
        return self.info

    @property
    def law(self):
        """The kernels' ``Law`` (``phys.law``)."""
        return self.phys.law

    def plane_arrays(self):
        """The kernels' arrays of the planes of ``phys`` (``planes.arrays`` of ``planes.of_physics``):
        made again when ``phys`` is replaced by one with other boundaries (bed making and tests swap
        in a floor), else kept (the same object: a law swapped in by the ramp copies nothing)."""
        p = self.phys
        key = (p.floor, p.wall, p.planes)
        made = getattr(self, "_planes", None)
        if made is None or made[0] != key:
            made = self._planes = (key, planes.arrays(planes.of_physics(p)))
        return made[1]

    def contacts(self):
        """Global number of contacts (counted from both partners) of the last evaluation."""
        n = self.n_contacts = int(self.domain.sum_int(np.array([self._contacts]))[0])
        self.info = self.info._replace(n_contacts=n)
        return n

    def advance(self, n):
        """Advance n steps (no monitors; each step's second half-kick deferred to the next
        step's first pass, the last one's applied); returns the last StepInfo. The steps run
        as the engine's ``run_quiet`` runs them."""
        infos = self.run_quiet(n) if n > 0 else ()
        self.complete()
        return infos[-1] if len(infos) else self.info

    def work_since_rebuild(self):
        """This rank's compute seconds since its last list rebuild (``timers``, communication left out): what
        the slabs balance with ``decomp.balance_by = "work"``."""
        return sum(self.timers.values()) - self._work_mark

    def _not_finite(self, overlap, z_max, flags):
        """End a step whose drift made a position NaN or infinite (an infinite displacement in the
        step's reduction, the same on every rank): no list work or forces on such rows (a cell index
        of a NaN reads anywhere); its StepInfo has z_min NaN, which stops a run (``Checks.fatal``)."""
        s = self.state
        s.step += 1
        s.time = s.step * self.phys.dt
        self.info = StepInfo(overlap, self.n_contacts, math.nan, z_max, flags)
        return self.info

    def _particles(self):
        """The host State's rows as the kernels' ``Particles``."""
        s = self.state
        return Particles(s.x, s.v, s.omega, s.f, s.torque, s.fixed)

    def _ratio(self, acc):
        """(unbalanced-force ratio, mobile spheres without a contact) from ``kernels.balance``'s
        sums over all ranks (``force_ratio``): the ratio is the mean |resultant| over the mobile spheres
        over the mean |contact force| (inf without contacts), exact on any number of ranks."""
        s = self.state
        res, con, n_c, free = (to_float(a) for a in acc)
        n_mob = self.domain.sum_int(np.array([int(np.sum(s.fixed[:s.n_own] == 0))], np.int64))[0]
        # no contact, or contacts that carry no force yet (the first evaluation of a touching pair)
        return ((res / max(int(n_mob), 1)) / (con / n_c) if con > 0 else math.inf), int(free)
