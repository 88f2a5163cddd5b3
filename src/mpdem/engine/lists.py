"""The CPU engine's neighbour lists: each owned row's partners within reach, the contact history of
the entries it computes, and the near lists the force pass reads (docs/computing.md).

Three layers, each made from the one above it:

- the lists (``kernels.neighbours``): cells, each row's partners within 1 + skin sorted by
  partner id; built at a rebuild, after the domain migrated rows and made the ghosts;
- the slots: one per computed entry (``link_entries``), holding the contact history ``hist``
  and the stamp of the last evaluation that found the pair in contact; between rebuilds, and
  whenever a reader needs the state current, the history lives in the state's compact slots
  instead (``pack`` / ``unpack``; docs/computing.md, "The contact history's two homes");
- the near lists (``kernels.near``): the entries within 1 + near_skin, filtered again whenever
  a particle moved near_skin / 2 since the last filtering.

Arrays only; the engine decides when to build and filter, and times it.
"""
from __future__ import annotations

import numpy as np

from ..kernels import history
from ..kernels.bundles import Lists, Near, Slots, make_box
from ..kernels.near import near_lists
from ..kernels.neighbours import build_neighbours, link_entries
from .order import sort_rows

# no pair store: the history's kernels read only the slots' history and stamps
_NO_PAIRS = np.zeros((0, 6))


class NeighbourLists:
    """One rank's neighbour lists, their slots of contact history and the near lists.

    Parameters
    ----------
    state : State
        The rank's rows (read; ``x_ref`` is set at each filtering, the compact slots at
        ``pack`` / ``unpack``).
    skin, near_skin : float
        Reach of the lists, 1 + skin, and of the near lists, 1 + min(near_skin, skin) [d].
    nchunk : int
        Chunks of rows (one a thread); any count gives the same bits.

    Attributes
    ----------
    nbr_start, nbr_list, link, comp_start : arrays
        The lists (``kernels.bundles.Lists``).
    hist : (K, 3) float64 ; stamp : (K,) uint32
        Each slot's Delta s [d] and the stamp of its last contact (``kernels.bundles.Slots``).
    near_start, near_link, near_cstart, near_cj, near_cslot, near_cpair, near_plink : arrays
        The near lists (``kernels.bundles.Near``); ``near_plink`` the entries' places in the
        ring pair store (``engine.pairstore``).
    k_near : int
        Near computed entries.
    moved : float
        A bound of every displacement since the build, up to the last filtering [d] (the
        same on all ranks).
    n_builds, n_filters : int
        Builds and filterings (a build filters too) so far.
    built : bool
        Whether the lists exist (after the first build).
    sort_every : int
        Every this many builds, the owned rows are first ordered by cell (``order.sort_rows``).
    """

    def __init__(self, state, skin, near_skin, nchunk):
        self.state = state
        self.r_list = 1.0 + skin
        self.near_skin = min(near_skin, skin)
        self.nchunk = int(nchunk)
        self.nbr_start = np.zeros(state.capacity + 1, np.int64)
        self.nbr_list = np.zeros(0, np.int32)
        self.link = np.zeros(0, np.int32)
        self.comp_start = np.zeros(state.capacity + 1, np.int64)
        self.hist = np.zeros((0, 3))
        self.stamp = np.zeros(0, np.uint32)
        self.near_start = np.zeros(state.capacity + 1, np.int64)
        self.near_cstart = np.zeros(state.capacity + 1, np.int64)
        self.near_link = np.zeros(0, np.int32)
        self.near_cj = np.zeros(0, np.int32)
        self.near_cslot = np.zeros(0, np.int32)
        self.near_cpair = np.zeros(0, np.int32)
        self.near_plink = np.zeros(0, np.int32)
        self.k_near = 0
        self.moved = 0.0
        self.n_builds = 0
        self.n_filters = 0
        self.built = False
        self.sort_every = 20
        self._box = None

    # -- the kernels' bundles, made for each call (arrays are reallocated at builds) --
    def lists(self):
        return Lists(self.nbr_start, self.nbr_list, self.link, self.comp_start)

    def near(self):
        return Near(self.near_start, self.near_link, self.near_cstart, self.near_cj, self.near_cslot,
                    self.near_cpair)

    def near_places(self):
        """The near lists as the force pass reads them with the ring store: places for slots."""
        return Near(self.near_start, self.near_plink, self.near_cstart, self.near_cj, self.near_cslot,
                    self.near_cpair)

    def slots(self, pair=_NO_PAIRS):
        """The slots with the pair store ``pair`` (``kernels.bundles.Slots``)."""
        return Slots(self.hist, self.stamp, pair)

    def box(self):
        """The state's periodic box (``kernels.bundles.Box``), made again when its lengths change."""
        b, s = self._box, self.state
        if b is None or b.L_x != s.L_x or b.L_y != s.L_y:
            b = self._box = make_box(s.L_x, s.L_y)
        return b

    def longest(self):
        """Entries of the longest row's list."""
        return int(np.diff(self.nbr_start[:self.state.n_own + 1]).max(initial=0))

    # -- the contact history between the slots and the state's compact slots --
    def pack(self, epoch):
        """Move the history of the evaluation ``epoch`` into the state's compact slots."""
        s = self.state
        total = history.count_contacts(s.n_own, self.lists(), self.slots(), epoch, s.count, self.nchunk)
        start = s.slot_offsets()
        s.alloc_slots(total)
        history.entries_to_slots(s.n_own, s.id, self.lists(), self.slots(), epoch, start, s.partner, s.ds,
                                 self.nchunk)
        s.slots_current = True

    def unpack(self, epoch, frictionless):
        """Move the state's compact slots into the slots, stamped ``epoch``; the compact slots are dropped.
        ``frictionless``: Delta s is 0 (docs/model.md 2.6), whatever a state file held."""
        s = self.state
        history.slots_to_entries(s.n_own, s.id, self.lists(), s.slot_offsets(), s.partner, s.ds, self.slots(),
                                 epoch, self.nchunk)
        if frictionless:
            self.hist[:] = 0.0
        s.drop_slots()

    # -- building and filtering (the history in the compact slots: ``pack`` first) --
    def build(self, domain, work, epoch, frictionless):
        """Migrate and make the ghosts (``domain.rebuild`` with this rank's ``work`` seconds), then the
        lists, their slots with the history and the near lists; ``x_ref`` = x."""
        s = self.state
        # the history is in the compact slots: freed until the new slots, so the peak memory holds it once
        self.hist = np.zeros((0, 3))
        if self.n_builds % self.sort_every == 0:
            sort_rows(s, self.r_list)
        domain.rebuild(s, work)
        if len(self.nbr_start) < s.n_own + 1:
            self.nbr_start = np.zeros(s.capacity + 1, np.int64)
        # a list buffer too short for a chunk's share is grown and the build run again
        while True:
            need = build_neighbours(s.x, s.n_rows, s.n_own, s.fixed, s.id, self.box(), self.r_list,
                                    self.nbr_start, self.nbr_list, self.nchunk)
            if need <= len(self.nbr_list):
                break
            self.nbr_list = np.zeros(int(need * 1.1) + 64, np.int32)
            self.link = np.zeros(len(self.nbr_list), np.int32)
        self.relink(epoch, frictionless)
        self.built = True
        s.x_ref[:s.n_rows] = s.x[:s.n_rows]
        self.moved = 0.0
        self.filter()
        self.n_builds += 1

    def relink(self, epoch, frictionless):
        """The computed and taken entries of the chunks (``link_entries``), new slots, and the
        history from the compact slots into them."""
        s = self.state
        if len(self.comp_start) < s.n_own + 1:
            self.comp_start = np.zeros(s.capacity + 1, np.int64)
        k = int(link_entries(s.n_own, s.fixed, self.lists(), self.nchunk))
        self.hist = np.empty((k, 3))
        self.stamp = np.empty(k, np.uint32)
        self.unpack(epoch, frictionless)

    def filter(self):
        """The near lists from the lists (``near.near_lists``), and ``x_ref`` = x: the steps measure
        displacements from the last filtering (``moved`` bounds those before). Returns whether arrays
        were reallocated (the engine's kernels then choose their overloads again, ``kernels.calls``)."""
        s = self.state
        n = s.n_own
        if len(self.near_start) < n + 1:
            self.near_start = np.zeros(s.capacity + 1, np.int64)
            self.near_cstart = np.zeros(s.capacity + 1, np.int64)
        r2 = (1.0 + self.near_skin) ** 2
        # one entry per slot, only while filtering
        g2e = np.empty(len(self.hist), np.int32)
        kc, ke = near_lists(n, s.x, s.fixed, self.box(), self.lists(), r2, self.near(), g2e, self.nchunk)
        # the kernel needs one spare element past the entries
        if kc >= len(self.near_cj) or ke >= len(self.near_link):
            if kc >= len(self.near_cj):
                self.near_cj = np.zeros(int(kc * 1.1) + 64, np.int32)
                self.near_cslot = np.zeros(len(self.near_cj), np.int32)
                self.near_cpair = np.zeros(len(self.near_cj), np.int32)
            if ke >= len(self.near_link):
                self.near_link = np.zeros(int(ke * 1.1) + 64, np.int32)
                self.near_plink = np.zeros(len(self.near_link), np.int32)
            near_lists(n, s.x, s.fixed, self.box(), self.lists(), r2, self.near(), g2e, self.nchunk)
            grown = True
        else:
            grown = False
        self.k_near = kc
        s.x_ref[:n] = s.x[:n]
        self.n_filters += 1
        return grown

    def nbytes(self):
        """Bytes held by the lists, the slots and the near lists."""
        return sum(a.nbytes for a in (self.nbr_start, self.nbr_list, self.link, self.comp_start, self.hist,
                                      self.stamp, self.near_start, self.near_cstart, self.near_link, self.near_cj,
                                      self.near_cslot, self.near_cpair, self.near_plink))
