"""One velocity-Verlet time step over a rank's particles (design.md section 3).

The engine is arrays and kernels only: no files, no logging, no stop rules
(those are in ``simulation``). It is used for the pile, for the bed-making
settle and by the verification tests.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .kernels.forces import MODEL_HERTZ, MODEL_HOOKE, contact_forces, floor_forces
from .kernels.integrate import kick, kick_drift, kinetic_energy
from .kernels.neighbours import build_neighbours, mirror_entries
from .kernels.exactsum import new_accumulator, to_float


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
    gravity: float = 1.0
    model: str = "hooke"
    limit_damping: bool = False
    rescale_history: bool = False
    floor: bool = False         # temporary frictionless floor at z = 0 (bed making)

    @classmethod
    def from_config(cls, cfg):
        c = cfg.contact
        return cls(k_n=c.k_n, k_t=c.k_t, gamma_n=c.gamma_n, gamma_t=c.gamma_t, mu=c.mu,
                   dt=cfg.integration.dt, skin=cfg.integration.skin, gravity=cfg.box.gravity,
                   model=c.model, limit_damping=c.limit_damping,
                   rescale_history=(c.history == "rotate"))


@dataclass
class StepInfo:
    """What one step reports to the monitors (already reduced over ranks)."""
    max_overlap: float = 0.0
    n_contacts: int = 0
    z_min: float = math.inf
    z_max: float = -math.inf
    flags: tuple = ()



class Engine:
    """Advance a State with a Physics over a Domain.

    Parameters
    ----------
    state : State
    physics : Physics
    domain : Domain
    reuse_pairs : bool
        Compute a pair of owned mobile particles once and give the second
        partner the exact negation (same bits as computing both views).
    """

    def __init__(self, state, physics, domain, reuse_pairs=True):
        self.state, self.phys, self.domain = state, physics, domain
        self.reuse_pairs = reuse_pairs
        self.model = MODEL_HERTZ if physics.model == "hertz" else MODEL_HOOKE
        self.r_list = 1.0 + physics.skin
        self.nbr_start = np.zeros(state.capacity + 1, np.int64)
        self._alloc_lists(max(64, 16 * state.capacity))
        self.n_rebuilds = 0
        self.sort_every = 20
        self.info = StepInfo()
        self._overlap = 0.0      # this rank's largest overlap of the last force evaluation
        self._contacts = 0       # this rank's contacts of the last force evaluation
        # the driver's per-rank flags (signal, wall time), agreed by max in each step's allreduce
        self.flags = []

    def _alloc_lists(self, size):
        self.nbr_list = np.zeros(size, np.int64)
        self.rev = np.full(size, -1, np.int64)
        self.pair_on = np.zeros(size, np.uint8)
        self.pair_val = np.zeros((size, 9))

    # -- neighbour lists --
    def rebuild(self):
        """Migrate/halo (domain), then cell and neighbour lists; reset x_ref."""
        s = self.state
        if self.n_rebuilds % self.sort_every == 0:
            self._sort_rows()
        self.domain.rebuild(s)
        if len(self.nbr_start) < s.n_own + 1:
            self.nbr_start = np.zeros(s.capacity + 1, np.int64)
        while True:
            need = build_neighbours(s.x, s.n_rows, s.n_own, s.fixed, s.ids, s.L_x, s.L_y,
                                    self.r_list, self.nbr_start, self.nbr_list)
            if need <= len(self.nbr_list):
                break
            self._alloc_lists(int(need * 1.25) + 64)
        if self.reuse_pairs:
            mirror_entries(s.n_own, s.fixed, s.ids, self.nbr_start, self.nbr_list, self.rev)
        s.x_ref[:s.n_rows] = s.x[:s.n_rows]
        self.n_rebuilds += 1

    def _sort_rows(self):
        """Order owned rows by cell so neighbours are near in memory.

        Sums run in partner-id order, so row order changes no result bit.
        """
        s = self.state
        n = s.n_own
        if n < 2:
            return
        c = 1.0 + self.phys.skin
        x = s.x[:n]
        key = (np.floor((x[:, 2] - x[:, 2].min()) / c) * (s.L_y // c + 1)
               + np.floor(x[:, 1] / c)) * (s.L_x // c + 1) + np.floor(x[:, 0] / c)
        s.permute(np.argsort(key, kind="stable"))

    # -- forces --
    def forces(self, increment=True):
        """Contact forces on owned rows; grows contact slots on overflow."""
        s, p = self.state, self.phys
        while True:
            max_ov, n_c, needed = contact_forces(
                s.n_own, s.x, s.v, s.omega, s.fixed, s.ids, self.nbr_start, self.nbr_list,
                        self.rev, self.pair_on, self.pair_val, s.slot_n, s.slot_id, s.slot_ds,
                s.slot_n_new, s.slot_id_new, s.slot_ds_new,
                s.f, s.torque, s.L_x, s.L_y, p.gravity, p.k_n, p.k_t, p.gamma_n, p.gamma_t,
                p.mu, self.model, p.limit_damping, p.rescale_history, p.dt, increment)
            if needed <= s.n_slots:
                break
            s.grow(slots=needed + 4)
        if p.floor:
            floor_forces(s.n_own, s.x, s.v, s.fixed, s.f, p.k_n, p.gamma_n)
        s.swap_slots()
        return max_ov, n_c

    def setup(self):
        """Neighbour lists and the set-up force evaluation (no history increment)."""
        self.rebuild()
        self._overlap, self._contacts = self.forces(increment=False)
        self.info = StepInfo(self.domain.max(self._overlap), self.contacts())
        return self.info

    def resume(self, max_overlap=0.0):
        """Set-up for a state read from a checkpoint: lists only.

        Forces, torques and contact slots come from the file (they carry the
        half-step velocities of the damping terms), so nothing is recomputed
        and the next step is bit for bit the one the straight run takes.
        """
        s = self.state
        self.rebuild()
        self._overlap = max_overlap
        self._contacts = int(s.slot_n[:s.n_own][s.fixed[:s.n_own] == 0].sum())
        self.info = StepInfo(self.domain.max(self._overlap), self.contacts())
        return self.info

    def step(self):
        """One velocity-Verlet step; returns the StepInfo (reduced over ranks).

        ``info.max_overlap`` is that of the previous force evaluation: it
        travels in the one allreduce of the step, with the displacement that
        decides the rebuild. ``info.n_contacts`` is updated by ``contacts()``.
        """
        s, p, dom = self.state, self.phys, self.domain
        d2, z_min, z_max = kick_drift(s.n_own, s.x, s.v, s.omega, s.f, s.torque, s.fixed,
                                      s.x_ref, p.dt, s.L_x, s.L_y)
        # one exact max: the same rebuild decision on every rank count (NaN -> inf)
        d2, overlap, neg_z_min, z_max, *flags = dom.max_many([d2, self._overlap, -z_min, z_max] + self.flags)
        rebuilt = not d2 < 0.25 * p.skin * p.skin
        if rebuilt:
            self.rebuild()
        else:
            dom.refresh(s)
        self._overlap, self._contacts = self.forces(increment=True)
        kick(s.n_own, s.v, s.omega, s.f, s.torque, s.fixed, p.dt)
        s.step += 1
        s.time = s.step * p.dt
        info = self.info
        info.max_overlap = overlap
        info.z_min, info.z_max = -neg_z_min, z_max
        info.flags = tuple(flags)
        if math.isinf(d2):
            info.z_min = math.nan          # a position became NaN or infinite
        return info

    def contacts(self):
        """Global number of contacts (counted from both partners) of the last evaluation."""
        n = int(self.domain.sum_int(np.array([self._contacts]))[0])
        self.info.n_contacts = n
        return n

    def run(self, n):
        """Advance n steps (no monitors); returns the last StepInfo."""
        info = self.info
        for _ in range(n):
            info = self.step()
        return info

    def kinetic(self):
        """Global (translational, rotational) kinetic energy sums [m g d], exact."""
        s = self.state
        acc = new_accumulator(2)
        kinetic_energy(s.n_own, s.v, s.omega, s.fixed, acc[0], acc[1])
        acc = self.domain.sum_int(acc)
        return to_float(acc[0]), to_float(acc[1])
