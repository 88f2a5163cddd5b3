"""The CPU engine: one velocity-Verlet time step over a rank's particles with numba's
njit kernels and threads (ARCHITECTURE.md; the interface in ``engine/__init__.py``).

The engine is arrays and kernels only: no files, no logging, no stop rules
(those are in ``simulation``). It is used for the pile, for the bed-making
settle and by the verification tests.
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..kernels import history
from ..kernels.balance import force_balance
from ..kernels.bundles import Lists, Near, Scratch, Slots, make_box
from ..kernels.calls import Bound
from ..kernels.exactsum import new_accumulator, to_float
from ..kernels.forces import contact_forces, contact_forces_serial, plane_forces
from ..kernels.integrate import kick, kick_drift, kick_drift_serial, kick_serial, kinetic_energy
from ..kernels.law import law_of
from ..kernels.near import near_lists
from ..kernels.pairstore import pair_places
from ..kernels.neighbours import build_neighbours, link_entries
from .base import NO_FLAGS, EngineBase, StepInfo
from .order import sort_rows


# room in the ring store, a fraction of its places: its far places drift up by a few between
# filterings, and a new array's first touch stalls the force pass (page faults, which the other
# ranks wait out)
PAIR_ROOM = 0.01
# the force pass's block of rows: room for this many computed entries (or a row's longest list), in
# which the contact law runs over a whole block's contacts (116 kB a chunk; 256 and 1024 time alike)
FORCE_BLOCK = 1024
# places of each chunk's ring in the pair store (kernels/pairstore.py; 384 kB, within a core's L2),
# raised to a power of two of at least 4 blocks of the force pass
PAIR_RING = 8192


class Engine(EngineBase):
    """Advance a State with a Physics over a Domain.

    The contact history lives in ``hist`` and ``stamp`` (one slot per
    computed pair) between rebuilds, and ``sync_slots`` / ``_unpack_slots``
    move it to and from the state's compact slots (see docs/computing.md,
    "The contact history's two homes").

    Parameters
    ----------
    state : State
    physics : Physics
    domain : Domain

    Attributes
    ----------
    timers : dict of float
        Seconds spent in "forces", "lists" (rebuilds, communication excluded)
        and "integration"; communication is ``domain.comm_seconds``.
    """

    def __init__(self, state, physics, domain):
        from .. import memory, threads
        memory.return_freed_memory()
        self.state, self.phys, self.domain = state, physics, domain
        state.wall = physics.wall
        self.law = law_of(physics)
        self.plane_arrays()     # the floor, the wall and any other plane (planes.py): checked here
        self.r_list = 1.0 + physics.skin
        self.nbr_start = np.zeros(state.capacity + 1, np.int64)
        self.nbr_list = np.zeros(0, np.int32)
        self.link = np.zeros(0, np.int32)
        self.comp_start = np.zeros(state.capacity + 1, np.int64)
        self.hist = np.zeros((0, 3))
        self.pair = np.zeros((0, 6))
        self.stamp = np.zeros(0, np.uint32)
        # the near lists (kernels/near.py): the force kernel's entries, filtered from the lists
        self.near_skin = min(physics.near_skin, physics.skin)
        self.near_start = np.zeros(state.capacity + 1, np.int64)
        self.near_cstart = np.zeros(state.capacity + 1, np.int64)
        self.near_link = np.zeros(0, np.int32)
        self.near_cj = np.zeros(0, np.int32)
        self.near_cslot = np.zeros(0, np.int32)
        self.k_near = 0           # near computed entries
        # the pair store's places of the near entries (kernels/pairstore.py), made anew when stale
        self.near_cpair = np.zeros(0, np.int32)
        self.near_plink = np.zeros(0, np.int32)
        self._ring = np.zeros((0, 6))
        self._places_stale = True
        self.pair_ring = 0        # places of each chunk's ring (``_place_pairs``)
        self._pairs_kept = False  # ``pair`` holds every pair of the last evaluation (``step(keep_pairs=True)``)
        # a bound of every displacement since the build, up to the last filtering [d] (the same on all ranks)
        self._moved = 0.0
        self.n_filters = 0
        self._epoch = 0           # force evaluations so far (the contacts' stamps count them)
        self.has_lists = False
        self._width = 64          # scratch for rows of up to this many entries (grown at rebuilds)
        self._box_made = None
        # the second half-kick of the last step, left for the next step's first pass (``step(defer_kick=True)``)
        self._kick_due = False
        state.sync = self.sync_state
        t = threads.apply()
        # one chunk per thread: numba's prange hands each thread an equal share of the chunks in one
        # piece (a static schedule), so more chunks balance nothing, and pairs across a border are
        # computed twice (4 chunks a thread computed 8 % more pairs on the 20k pile)
        self.set_chunks(t)
        self._reduce = np.zeros(4)
        self.n_rebuilds = 0
        self.sort_every = 20
        self.info = StepInfo()    # the newest step's (each step makes a new one)
        self.n_contacts = 0       # contacts of the whole pile at the last count (``contacts``)
        self.timers = {"forces": 0.0, "lists": 0.0, "integration": 0.0}
        self._work_mark = 0.0    # the sum of ``timers`` at the last rebuild
        self.last_overlap = 0.0  # this rank's largest overlap of the last force evaluation
        self._contacts = 0       # this rank's contacts of the last force evaluation

    def set_chunks(self, nchunk):
        """Split the rows into ``nchunk`` chunks for the threads (the engine uses one a
        thread: numba's static schedule makes more balance nothing); any count gives the
        same bits."""
        if self.has_lists:
            self.sync_slots()      # the links of the old chunks say where the history is
        self.nchunk = int(nchunk)
        # one chunk (one thread): the serial twins, the same bits without numba's parallel wrapper;
        # each called through the overload numba chose at its first call after a reallocation
        self._bound = (Bound(contact_forces if self.nchunk > 1 else contact_forces_serial),
                       Bound(kick_drift if self.nchunk > 1 else kick_drift_serial),
                       Bound(kick if self.nchunk > 1 else kick_serial), Bound(plane_forces))
        self._contact_forces, self._kick_drift, self._kick, self._plane_forces = self._bound
        self._scratch(self._width)
        self._chunk_max = np.zeros(self.nchunk)
        self._chunk_count = np.zeros(self.nchunk, np.int64)
        self._drift = np.zeros((self.nchunk, 3))
        if self.has_lists:
            self._link()
            self._unpack_slots()
            self._filter()

    def _scratch(self, width):
        """Per-chunk scratch of the force kernel for rows of up to ``width`` entries."""
        self._width = width
        room = max(width, FORCE_BLOCK)
        self._found = np.zeros((self.nchunk, room, 3), np.int32)
        self._sep = np.zeros((self.nchunk, room, 4))
        self._tangent = np.zeros((self.nchunk, room, 9))
        # the places depend on the block's room
        self._places_stale = True
        self._rebind()

    def _rebind(self):
        """Let numba choose the step's kernels' overloads again at their next calls
        (``kernels.calls``): arrays were reallocated."""
        for k in self._bound:
            k.reset()

    # -- the kernels' bundles, made for each call (arrays are reallocated at rebuilds) --
    def _lists(self):
        return Lists(self.nbr_start, self.nbr_list, self.link, self.comp_start)

    def _near(self):
        return Near(self.near_start, self.near_link, self.near_cstart, self.near_cj, self.near_cslot,
                    self.near_cpair)

    def _near_places(self):
        """The near lists as the force pass reads them with the ring store: places for slots."""
        return Near(self.near_start, self.near_plink, self.near_cstart, self.near_cj, self.near_cslot,
                    self.near_cpair)

    def _slots(self):
        return Slots(self.hist, self.stamp, self.pair)

    def _box(self):
        b, s = self._box_made, self.state
        if b is None or b.L_x != s.L_x or b.L_y != s.L_y:
            b = self._box_made = make_box(s.L_x, s.L_y)
        return b

    def sync_state(self):
        """Bring the state's arrays current for a reader (``State.sync``): the deferred
        half-kick (``complete``), then the contact history into the compact slots."""
        self.complete()
        self.sync_slots()

    # -- contact history: list entries <-> compact slots --
    def sync_slots(self):
        """Pack the history of the last force evaluation into the state's compact slots."""
        s = self.state
        if s.slots_current:
            return
        # a kept pair store (one place per near slot) is scratch of one force evaluation: freed
        # while the slots are made, so the peak memory holds the history once
        self.pair = np.zeros((0, 6))
        n = s.n_own
        total = history.count_contacts(n, self._lists(), self._slots(), self._epoch, s.count, self.nchunk)
        start = s.slot_offsets()
        s.alloc_slots(total)
        history.entries_to_slots(n, s.id, self._lists(), self._slots(), self._epoch, start, s.partner, s.ds,
                                 self.nchunk)
        s.slots_current = True

    def _unpack_slots(self):
        s = self.state
        history.slots_to_entries(s.n_own, s.id, self._lists(), s.slot_offsets(), s.partner, s.ds,
                                 self._slots(), self._epoch, self.nchunk)
        if self.law.mu == 0.0:
            # frictionless: Delta s is 0 (docs/model.md 2.6), whatever an initial file held
            self.hist[:] = 0.0
        s.drop_slots()

    # -- neighbour lists --
    def rebuild(self):
        """Migrate/halo (domain), then cell and neighbour lists; reset x_ref."""
        t = time.perf_counter()
        c0 = self.domain.comm_seconds
        s = self.state
        if self.has_lists:
            self.sync_slots()
        # the history is in the slots now: freed until the new lists, so the peak memory
        # holds the history once
        self.hist = np.zeros((0, 3))
        if self.n_rebuilds % self.sort_every == 0:
            self._sort_rows()
        # the slabs may be balanced by the compute seconds since the last rebuild (``Domain.rebuild``)
        spent = sum(self.timers.values())
        self.domain.rebuild(s, spent - self._work_mark)
        self._work_mark = spent
        if len(self.nbr_start) < s.n_own + 1:
            self.nbr_start = np.zeros(s.capacity + 1, np.int64)
        # a list buffer too short for a chunk's share is grown and the build run again
        while True:
            need = build_neighbours(s.x, s.n_rows, s.n_own, s.fixed, s.id, self._box(), self.r_list,
                                    self.nbr_start, self.nbr_list, self.nchunk)
            if need <= len(self.nbr_list):
                break
            self._alloc_lists(int(need * 1.1) + 64)
        longest = int(np.diff(self.nbr_start[:s.n_own + 1]).max(initial=0))
        if longest > self._width:
            self._scratch(2 * longest)
        self._link()
        self._unpack_slots()
        self.has_lists = True
        s.x_ref[:s.n_rows] = s.x[:s.n_rows]
        self._moved = 0.0
        self._filter()
        self._rebind()
        self.n_rebuilds += 1
        self.timers["lists"] += time.perf_counter() - t - (self.domain.comm_seconds - c0)

    def _link(self):
        """Computed and taken entries and their slots (``link_entries``); a new
        ``hist`` and ``stamp`` for the slots.

        Only when the history is in the compact slots (``sync_slots``).
        """
        s = self.state
        if len(self.comp_start) < s.n_own + 1:
            self.comp_start = np.zeros(s.capacity + 1, np.int64)
        k = int(link_entries(s.n_own, s.fixed, self._lists(), self.nchunk))
        self.hist = np.empty((k, 3))
        self.stamp = np.empty(k, np.uint32)

    def _filter(self):
        """The near lists from the lists (``near.near_lists``), and ``x_ref`` = x: the steps
        measure displacements from the last filtering (``_moved`` bounds those before)."""
        s = self.state
        n = s.n_own
        if len(self.near_start) < n + 1:
            self.near_start = np.zeros(s.capacity + 1, np.int64)
            self.near_cstart = np.zeros(s.capacity + 1, np.int64)
        r2 = (1.0 + self.near_skin) ** 2
        # one entry per slot, only while filtering
        g2e = np.empty(len(self.hist), np.int32)
        kc, ke = near_lists(n, s.x, s.fixed, self._box(), self._lists(), r2, self._near(), g2e, self.nchunk)
        # the kernel needs one spare element past the entries
        if kc >= len(self.near_cj) or ke >= len(self.near_link):
            if kc >= len(self.near_cj):
                self.near_cj = np.zeros(int(kc * 1.1) + 64, np.int32)
                self.near_cslot = np.zeros(len(self.near_cj), np.int32)
                self.near_cpair = np.zeros(len(self.near_cj), np.int32)
            if ke >= len(self.near_link):
                self.near_link = np.zeros(int(ke * 1.1) + 64, np.int32)
                self.near_plink = np.zeros(len(self.near_link), np.int32)
            near_lists(n, s.x, s.fixed, self._box(), self._lists(), r2, self._near(), g2e, self.nchunk)
            self._rebind()
        self.k_near = kc
        self._places_stale = True
        s.x_ref[:n] = s.x[:n]
        self.n_filters += 1

    def _place_pairs(self):
        """Each near entry's place in the ring store (``kernels.pairstore``); the store grown if short."""
        n = self.state.n_own
        room = self._found.shape[1]
        # PAIR_RING places, or 4 blocks of the pass if more; never more than a chunk's entries
        most = max(int(self.near_cstart[(c + 1) * n // self.nchunk] - self.near_cstart[c * n // self.nchunk])
                   for c in range(self.nchunk))
        ring = 1 << max(PAIR_RING - 1, 4 * room - 1).bit_length()
        ring = min(ring, 1 << max(most - 1, 0).bit_length())
        self.pair_ring = ring
        places = int(pair_places(n, self._near(), room, ring, self.nchunk, self.near_cpair, self.near_plink))
        if len(self._ring) < places:
            # freed first, so that its memory can serve the new one
            self._ring = None
            self._ring = np.empty((int(places * (1.0 + PAIR_ROOM)) + 64, 6))
        self._places_stale = False

    def _alloc_lists(self, size):
        # the history moved to the slots before the lists were rebuilt: nothing to keep
        self.nbr_list = np.zeros(size, np.int32)
        self.link = np.zeros(size, np.int32)

    def _sort_rows(self):
        """Order owned rows by cell (``order.sort_rows``): neighbours near in memory, no bit changed."""
        sort_rows(self.state, self.r_list)

    # -- forces --
    def forces(self, increment=True, keep_pairs=False):
        """Contact forces on owned rows, history updated in place; returns (max overlap, contacts).

        With ``keep_pairs`` every pair's force stays in ``pair`` after the pass, one place per
        near slot (for ``force_ratio``); otherwise the pass leaves them in the ring store
        (``kernels.pairstore``), which the rows reuse. The same values either way.
        """
        t = time.perf_counter()
        s = self.state
        if keep_pairs:
            # a store of its own, made for this pass (its first touch costs some 2 ms on the 20k pile)
            near = self._near()._replace(cpair=np.arange(self.k_near + 1, dtype=np.int32))
            self.pair = np.empty((self.k_near + 1, 6))
        else:
            if self._places_stale:
                self._place_pairs()
            near = self._near_places()
            self.pair = self._ring
        self._pairs_kept = keep_pairs
        self._epoch += 1
        part = self._particles()
        scratch = Scratch(self._chunk_max, self._chunk_count, self._found, self._sep, self._tangent)
        max_ov, n_c = self._contact_forces(s.n_own, part, near, self._slots(), self._epoch, self._box(),
                                           self.law, increment, scratch)
        geo, kinds = self.plane_arrays()
        if len(kinds):
            # the rough plane's history is the state's wall_ds
            max_ov = max(max_ov, self._plane_forces(s.n_own, part, geo, kinds, s.wall_ds, self.law, increment,
                                                    self._chunk_max))
        s.slots_current = False
        self.timers["forces"] += time.perf_counter() - t
        return max_ov, n_c

    def step(self, flags=NO_FLAGS, defer_kick=False, keep_pairs=False):
        """One velocity-Verlet step; returns a new StepInfo (reduced over ranks).

        With ``defer_kick`` the step's second half-kick is left for the next step's first
        pass over the rows (``kick_drift``'s ``pending``): the same operations in the same
        order, so the same bits, with one pass over the rows less a step. Until then ``v``
        and ``omega`` are the half-step values; ``complete`` applies the kick, and every
        reader of the state's rows (``State.sync``) and ``kinetic`` call it first.

        ``info.max_overlap`` is that of the previous force evaluation: it
        travels in the one allreduce of the step, with the displacement that
        decides the rebuild. ``info.n_contacts`` is the last ``contacts()`` count.

        Parameters
        ----------
        flags : NamedTuple of float
            The driver's per-rank flags (``simulation.StepFlags``: signal, wall
            time, clock checkpoint), agreed by max in the same allreduce;
            ``info.flags`` is the agreed record, of the same type.
        keep_pairs : bool
            Keep every pair's force of this step's evaluation for ``force_ratio``
            (``forces``); the same bits either way.
        """
        s, p, dom = self.state, self.phys, self.domain
        t = time.perf_counter()
        n2, z_min, z_max = self._kick_drift(s.n_own, self._particles(), s.x_ref, p.dt, self._box(), self._drift,
                                            self._kick_due)
        self._kick_due = False
        self.timers["integration"] += time.perf_counter() - t
        # one exact max: the same decisions on every rank count (NaN -> inf)
        red = self._reduce
        if len(red) != 4 + len(flags):
            red = self._reduce = np.zeros(4 + len(flags))
        # whole slices, and the result back as Python floats: numpy scalars cost microseconds a step
        red[:4] = (n2, self.last_overlap, -z_min, z_max)
        if flags:
            red[4:] = flags
        n2, overlap, neg_z_min, z_max, *agreed = dom.max_many(red).tolist()
        # the displacement since the last filtering plus those before bounds every one since the build
        # (rebuilding early changes no bit: sums run in partner-id order and left-out pairs add zeros)
        moved = math.sqrt(n2)
        rebuilt = not moved + self._moved < 0.5 * p.skin
        if rebuilt:
            self.rebuild()
        else:
            dom.refresh(s)
            # a pair left out of the near lists may come within reach once a particle moved near_skin/2
            if not n2 < 0.25 * self.near_skin * self.near_skin:
                t = time.perf_counter()
                self._moved += moved
                self._filter()
                self.timers["lists"] += time.perf_counter() - t
        self.last_overlap, self._contacts = self.forces(increment=True, keep_pairs=keep_pairs)
        self._kick_due = True
        if not defer_kick:
            self.complete()
        s.step += 1
        s.time = s.step * p.dt
        # an infinite displacement: a position became NaN or infinite
        self.info = StepInfo(overlap, self.n_contacts, math.nan if math.isinf(n2) else -neg_z_min, z_max,
                             flags._make(agreed))
        return self.info

    def complete(self):
        """Apply the second half-kick that ``step(defer_kick=True)`` left (nothing if none)."""
        if self._kick_due:
            t = time.perf_counter()
            # a new bundle: a rebuild may have reallocated the rows
            self._kick(self.state.n_own, self._particles(), self.phys.dt)
            self._kick_due = False
            self.timers["integration"] += time.perf_counter() - t

    def kinetic(self):
        """Global (translational, rotational) kinetic energy sums [m g d], exact."""
        self.complete()
        s = self.state
        acc = new_accumulator(2)
        kinetic_energy(s.n_own, self._particles(), acc, self.nchunk)
        acc = self.domain.sum_int(acc)
        return to_float(acc[0]), to_float(acc[1])

    def force_ratio(self):
        """(ratio, in flight) of the last force evaluation (``kernels.balance``), exact on any number of
        ranks: the unbalanced-force ratio, mean |resultant| over the mobile spheres / mean |contact
        force| (inf without contacts), and the mobile spheres without a contact. (nan, -1) before any
        evaluation of this segment, after one that did not keep its pairs' forces (``step``'s
        ``keep_pairs``), or once they are freed (``sync_slots``)."""
        if self._epoch == 0 or not self._pairs_kept:
            return math.nan, -1
        s = self.state
        if len(self.pair) < self.k_near:
            # the slot forces were freed when the history was packed (a state file written since)
            return math.nan, -1
        return self._ratio(self.domain.sum_int(force_balance(s.n_own, self._particles(), self._near(),
                                                             self._slots(), self._epoch, self.nchunk)))

    def memory_bytes(self):
        """Bytes held by the particle arrays and the lists with their history."""
        arrays = (self.nbr_start, self.nbr_list, self.link, self.comp_start, self.hist, self.stamp,
                  self.near_start, self.near_cstart, self.near_link, self.near_cj, self.near_cslot,
                  self.near_cpair, self.near_plink, self._ring)
        # the pair store is the ring or a kept store of its own
        kept = self.pair.nbytes if self.pair is not self._ring else 0
        return self.state.nbytes() + sum(a.nbytes for a in arrays) + kept
