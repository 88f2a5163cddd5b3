"""What every engine shares: the run's numerics (``Physics``) and the record a step reports (``StepInfo``)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple


@dataclass(frozen=True)
class Physics:
    """Scalars of the force law and integrator (reduced units)."""
    k_n: float
    k_t: float
    gamma_n: float
    gamma_t: float
    mu: float
    dt: float
    skin: float = 0.2
    near_skin: float = 0.03
    gravity: float = 1.0
    incline: float = 0.0        # tilt about y [degrees]: gravity along (sin, 0, -cos)
    model: str = "hooke"
    limit_damping: bool = False
    rescale_history: bool = False
    floor: bool = False         # temporary frictionless floor at z = 0 (bed making)
    wall: bool = False          # the wall plane z = 0 under the bed (bed.wall)

    @classmethod
    def from_config(cls, cfg):
        c = cfg.contact
        return cls(k_n=c.k_n, k_t=c.k_t, gamma_n=c.gamma_n, gamma_t=c.gamma_t, mu=c.mu,
                   dt=cfg.integration.dt, skin=cfg.integration.skin, near_skin=cfg.integration.near_skin,
                   gravity=cfg.box.gravity, incline=cfg.box.incline,
                   model=c.model, limit_damping=c.limit_damping,
                   rescale_history=(c.history == "rotate"), wall=cfg.bed.wall)


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
