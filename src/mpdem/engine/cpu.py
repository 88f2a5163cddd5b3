"""The CPU engine: one velocity-Verlet time step over a rank's particles with numba's njit kernels
and threads (the interface in ``engine/__init__.py``). Arrays and kernels only: no files, no
logging, no stop rules (``simulation``); the pile's, the bed-making settle's and the tests'.
"""
from __future__ import annotations

import math
import time
from typing import NamedTuple

import numpy as np

from .. import threads
from ..kernels.balance import force_balance
from ..kernels.bundles import Scratch
from ..kernels.calls import Bound
from ..kernels.exactsum import new_accumulator, to_float
from ..kernels.forces import contact_forces, contact_forces_serial, plane_forces
from ..kernels.integrate import kick, kick_drift, kick_drift_serial, kick_serial, kinetic_energy
from ..kernels.quiet import REC_COLUMNS, REC_CONTACTS, REC_OVERLAP, REC_ZMAX, REC_ZMIN, quiet_steps
from .base import NO_FLAGS, EngineBase, StepInfo
from .lists import NeighbourLists
from .pairstore import PairStore

# the force pass's block of rows: room for this many computed entries (or a row's longest list), in
# which the contact law runs over a whole block's contacts (116 kB a chunk; 256 and 1024 time alike)
FORCE_BLOCK = 1024
# steps of one ``quiet_steps`` call at most (``run_quiet``): its record is this many rows
QUIET_CALL = 1000


def _finite_max(v):
    """A value as the step's max reduction gives it: NaN becomes +inf (``Domain.max_many``)."""
    return math.inf if math.isnan(v) else v


class Kernels(NamedTuple):
    """The step's kernels, each called through the overload numba chose (``kernels.calls.Bound``)."""
    contact_forces: Bound
    kick_drift: Bound
    kick: Bound
    plane_forces: Bound
    quiet_steps: Bound


class Engine(EngineBase):
    """Advance a State with a Physics over a Domain: the force pass and the step, over the rank's
    neighbour lists (``lists.NeighbourLists``) and pair store (``pairstore.PairStore``).

    It sets no process-wide state: numba's threads (``threads.apply``; it splits the rows into
    ``threads.requested()`` chunks) and the allocator (``memory``) are the run's and the bench's.

    Parameters
    ----------
    state : State
    physics : Physics
    domain : Domain

    Attributes
    ----------
    lists : NeighbourLists
    store : PairStore
    timers : dict of float
        Seconds spent in "forces", "lists" (rebuilds, communication excluded)
        and "integration"; communication is ``domain.comm_seconds``.
    """

    def __init__(self, state, physics, domain):
        self.state, self.phys, self.domain = state, physics, domain
        state.wall = physics.wall
        self.plane_arrays()     # the floor, the wall and any other plane (planes.py): checked here
        # one chunk a thread: more balance nothing, and pairs across a border are computed twice
        # (4 chunks a thread computed 8 % more pairs on the 20k pile)
        self.lists = NeighbourLists(state, physics.skin, physics.near_skin, threads.requested())
        self.store = PairStore()
        self._epoch = 0           # force evaluations so far (the contacts' stamps count them)
        # the second half-kick of the last step, left for the next step's first pass (``step(defer_kick=True)``)
        self._kick_due = False
        self._reduce = np.zeros(4)
        self._rec = np.zeros((0, REC_COLUMNS))    # ``run_quiet``'s record of its steps
        self.info = StepInfo()    # the newest step's (each step makes a new one)
        self.n_contacts = 0       # contacts of the whole pile at the last count (``contacts``)
        self.timers = {"forces": 0.0, "lists": 0.0, "integration": 0.0}
        self._work_mark = 0.0    # the sum of ``timers`` at the last rebuild
        self.last_overlap = 0.0  # this rank's largest overlap of the last force evaluation
        self._contacts = 0       # this rank's contacts of the last force evaluation
        state.sync = self.sync_state
        self.set_chunks(self.lists.nchunk)

    @property
    def nchunk(self):
        """Chunks of rows, one a thread (``set_chunks``)."""
        return self.lists.nchunk

    @property
    def n_rebuilds(self):
        """List rebuilds of the run (a restart's continue the straight run's count)."""
        return self.lists.n_builds

    @n_rebuilds.setter
    def n_rebuilds(self, n):
        self.lists.n_builds = n

    def set_chunks(self, nchunk):
        """Split the rows into ``nchunk`` chunks for the threads (one a thread: numba's static schedule
        makes more balance nothing); any count gives the same bits."""
        built = self.lists.built
        if built:
            self.sync_slots()      # the links of the old chunks say where the history is
        self.lists.nchunk = nchunk = int(nchunk)
        # one chunk (one thread): the serial twins, the same bits without numba's parallel wrapper;
        # each called through the overload numba chose at its first call after a reallocation
        self._kernels = Kernels(Bound(contact_forces if nchunk > 1 else contact_forces_serial),
                                Bound(kick_drift if nchunk > 1 else kick_drift_serial),
                                Bound(kick if nchunk > 1 else kick_serial), Bound(plane_forces), Bound(quiet_steps))
        self._drift = np.zeros((nchunk, 3))
        self._scratch(2 * self.lists.longest())
        if built:
            self.lists.relink(self._epoch, self.law.mu == 0.0)
            self.lists.filter()

    def _scratch(self, width):
        """Per-chunk scratch of the force kernel (``kernels.bundles.Scratch``) for rows of up to
        ``width`` entries, and at least FORCE_BLOCK."""
        nchunk, room = self.nchunk, max(width, FORCE_BLOCK)
        self._work = Scratch(np.zeros(nchunk), np.zeros(nchunk, np.int64), np.zeros((nchunk, room, 3), np.int32),
                             np.zeros((nchunk, room, 4)), np.zeros((nchunk, room, 9)))
        self._rebind()

    def _rebind(self):
        """Let numba choose the kernels' overloads again at their next calls: arrays were reallocated."""
        for k in self._kernels:
            k.reset()

    def sync_state(self):
        """Bring the state's arrays current for a reader (``State.sync``): the deferred
        half-kick (``complete``), then the contact history into the compact slots."""
        self.complete()
        self.sync_slots()

    def sync_slots(self):
        """Pack the history of the last force evaluation into the state's compact slots."""
        if not self.state.slots_current:
            self.store.free()
            self.lists.pack(self._epoch)

    def rebuild(self):
        """Migrate/halo (domain), then cell and neighbour lists; reset x_ref."""
        t, c0 = time.perf_counter(), self.domain.comm_seconds
        if self.lists.built:
            self.sync_slots()
        # the slabs may be balanced by the compute seconds since the last rebuild (``Domain.rebuild``)
        spent = sum(self.timers.values())
        self.lists.build(self.domain, self.work_since_rebuild(), self._epoch, self.law.mu == 0.0)
        self._work_mark = spent
        if self.lists.longest() > self._work.found.shape[1]:
            self._scratch(2 * self.lists.longest())
        self._rebind()
        self.timers["lists"] += time.perf_counter() - t - (self.domain.comm_seconds - c0)

    def forces(self, increment=True, keep_pairs=False):
        """Contact forces on owned rows, history updated in place; returns (max overlap, contacts).
        With ``keep_pairs`` every pair's force stays in a kept pair store (for ``force_ratio``),
        otherwise in the ring the rows reuse (``engine.pairstore``); the same values either way."""
        t = time.perf_counter()
        s, law, work = self.state, self.law, self._work
        near, pair = self.store.keep(self.lists) if keep_pairs else self.store.ring(self.lists, work.found.shape[1])
        self._epoch += 1
        part = self._particles()
        k = self._kernels
        max_ov, n_c = k.contact_forces(s.n_own, part, near, self.lists.slots(pair), self._epoch, self.lists.box(),
                                     law, increment, work)
        geo, kinds = self.plane_arrays()
        if len(kinds):
            # the rough plane's history is the state's wall_ds
            max_ov = max(max_ov, k.plane_forces(s.n_own, part, geo, kinds, s.wall_ds, law, increment,
                                              work.chunk_max))
        s.slots_current = False
        self.timers["forces"] += time.perf_counter() - t
        return max_ov, n_c

    def step(self, flags=NO_FLAGS, defer_kick=False, keep_pairs=False):
        """One velocity-Verlet step; returns a new StepInfo (reduced over ranks). The promises of
        ``flags``, ``defer_kick`` and ``keep_pairs`` are the interface's (``engine/__init__.py``);
        the deferred half-kick is applied in the next step's first pass (``kick_drift``'s
        ``pending``): the same operations in the same order, one pass over the rows less a step."""
        s, p = self.state, self.phys
        t = time.perf_counter()
        drifted = self._kernels.kick_drift(s.n_own, self._particles(), s.x_ref, p.dt, self.lists.box(), self._drift,
                                           self._kick_due)
        self._kick_due = False
        self.timers["integration"] += time.perf_counter() - t
        return self._after_drift(*drifted, flags, defer_kick, keep_pairs)

    def _after_drift(self, n2, z_min, z_max, flags, defer_kick, keep_pairs):
        """The rest of ``step`` after its kick and drift, which gave this rank's largest squared
        displacement ``n2`` [d^2] (NaN: a position is not finite) and lowest and highest mobile
        centre [d]: the step's one reduction, list work, forces, the second half-kick."""
        s, p, dom = self.state, self.phys, self.domain
        # one exact max: the same decisions on every rank count (NaN -> inf)
        red = self._reduce
        if len(red) != 4 + len(flags):
            red = self._reduce = np.zeros(4 + len(flags))
        # whole slices, and the result back as Python floats: numpy scalars cost microseconds a step
        red[:4] = (n2, self.last_overlap, -z_min, z_max)
        if flags:
            red[4:] = flags
        n2, overlap, neg_z_min, z_max, *agreed = dom.max_many(red).tolist()
        if math.isinf(n2):
            return self._not_finite(overlap, z_max, flags._make(agreed))
        # the displacement since the last filtering plus those before bounds every one since the build
        # (rebuilding early changes no bit: sums run in partner-id order and left-out pairs add zeros)
        moved, lists = math.sqrt(n2), self.lists
        if not moved + lists.moved < 0.5 * p.skin or dom.rebalance_due(self.work_since_rebuild):
            self.rebuild()
        else:
            dom.refresh(s)
            # a pair left out of the near lists may come within reach once a particle moved near_skin/2
            if not n2 < self._near_limit2():
                t = time.perf_counter()
                lists.moved += moved
                if lists.filter():
                    self._rebind()
                self.timers["lists"] += time.perf_counter() - t
        self.last_overlap, self._contacts = self.forces(increment=True, keep_pairs=keep_pairs)
        self._kick_due = True
        if not defer_kick:
            self.complete()
        s.step += 1
        s.time = s.step * p.dt
        self.info = StepInfo(overlap, self.n_contacts, -neg_z_min, z_max, flags._make(agreed))
        return self.info

    def _near_limit2(self):
        """(near_skin / 2)^2 [d^2]: a squared displacement not below it needs a new filtering."""
        return 0.25 * self.lists.near_skin * self.lists.near_skin

    @property
    def steps_in_one_call(self):
        """``run_quiet`` runs its steps in kernel calls (one rank, one thread), not one by one."""
        return not self.domain.parallel and self.nchunk == 1

    def run_quiet(self, n, flags=NO_FLAGS):
        """``n`` steps that nothing reads between (no sample, no file, no progress line), each as
        ``step(flags, defer_kick=True)``; returns their StepInfos, with ``flags`` for all.

        On one rank and one chunk (one thread) the steps that need no list work run in one kernel
        call (``kernels.quiet.quiet_steps``), with none of a step's Python; a step that needs a
        rebuild or a new filtering (or has a position that is not finite) is finished on ``step``'s
        path. The same arithmetic in the same order, so the same bits. Otherwise (several ranks
        or threads) they are steps one by one. The seconds of a kernel call count as "forces"."""
        if not self.steps_in_one_call or self.state.n_own == 0:
            return [self.step(flags, defer_kick=True) for _ in range(n)]
        s, p, lists = self.state, self.phys, self.lists
        if len(self._rec) < min(n, QUIET_CALL):
            self._rec = np.zeros((min(n, QUIET_CALL), REC_COLUMNS))
        rec, infos = self._rec, []
        while len(infos) < n:
            m = min(n - len(infos), QUIET_CALL)
            t = time.perf_counter()
            # the scratch of this call: a rebuild on the host's path may have made a wider one
            work = self._work
            near, pair = self.store.ring(lists, work.found.shape[1])
            geo, kinds = self.plane_arrays()
            whole = self._kernels.quiet_steps(m, s.n_own, self._particles(), s.x_ref, p.dt, lists.box(),
                                              self._kick_due, near, lists.slots(pair), self._epoch, self.law,
                                              work, geo, kinds, s.wall_ds, lists.moved, 0.5 * p.skin,
                                              self._near_limit2(), rec)
            self.timers["forces"] += time.perf_counter() - t
            overlap = self.last_overlap
            for r in rec[:whole].tolist():
                infos.append(StepInfo(_finite_max(overlap), self.n_contacts, r[REC_ZMIN], r[REC_ZMAX], flags))
                overlap = r[REC_OVERLAP]
            if whole:
                self._kick_due = True
                s.slots_current = False
                self._epoch += whole
                s.step += whole
                s.time = s.step * p.dt
                self.last_overlap, self._contacts = overlap, int(rec[whole - 1, REC_CONTACTS])
                self.info = infos[-1]
            if whole < m:
                # the step the call ended at has drifted: its list work and forces on ``step``'s path
                self._kick_due = False
                d2, z_min, z_max = rec[whole, :3].tolist()
                infos.append(self._after_drift(d2, z_min, z_max, flags, True, False))
        return infos

    def complete(self):
        """Apply the second half-kick that ``step(defer_kick=True)`` left (nothing if none)."""
        if self._kick_due:
            t = time.perf_counter()
            # a new bundle: a rebuild may have reallocated the rows
            self._kernels.kick(self.state.n_own, self._particles(), self.phys.dt)
            self._kick_due = False
            self.timers["integration"] += time.perf_counter() - t

    def kinetic(self, momentum=False):
        """Global (translational, rotational) kinetic energy sums [m g d], exact; with ``momentum``
        also the momentum along x summed over the mobile spheres [m sqrt(g d)]."""
        self.complete()
        s = self.state
        acc = new_accumulator(3 if momentum else 2)
        kinetic_energy(s.n_own, self._particles(), acc, self.nchunk)
        acc = self.domain.sum_int(acc)
        return tuple(to_float(a) for a in acc)

    def force_ratio(self):
        """(unbalanced-force ratio, mobile spheres without a contact) of the last force evaluation
        (``kernels.balance``; ``EngineBase._ratio``); (nan, -1) before any evaluation of this segment, after
        one that did not keep its pairs' forces, or once they were freed (a state file written since)."""
        pair = self.store.kept_pairs(self.lists)
        if self._epoch == 0 or pair is None:
            return math.nan, -1
        return self._ratio(self.domain.sum_int(force_balance(self.state.n_own, self._particles(), self.lists.near(),
                                                             self.lists.slots(pair), self._epoch, self.nchunk)))

    def memory_bytes(self):
        """Bytes held by the particle arrays and the lists with their history."""
        return self.state.nbytes() + self.lists.nbytes() + self.store.nbytes()
