"""The CPU engine's pair store: where the force pass leaves each near pair's force and torque for
its partner row's sum (``kernels.pairstore``; docs/computing.md, "The pair store").

Two kinds, the same values in either: a ring per chunk, reused by the rows (the step's), or a store
of one place per near slot that keeps every pair's force after the pass (``keep``: the force
ratio's evaluations).
"""
from __future__ import annotations

import numpy as np

from ..kernels.pairstore import pair_places

# room in the ring store, a fraction of its places: its far places drift up by a few between
# filterings, and a new array's first touch stalls the force pass (page faults, which the other
# ranks wait out)
PAIR_ROOM = 0.01
# places of each chunk's ring (384 kB, within a core's L2), raised to a power of two of at least
# 4 blocks of the force pass
PAIR_RING = 8192


class PairStore:
    """The pair store of one engine.

    Attributes
    ----------
    pair : (places, 6) float64
        The store of the last force evaluation: the ring, a kept store, or empty once freed.
    kept : bool
        ``pair`` is a kept store of every near pair of the last evaluation.
    pair_ring : int
        Places of each chunk's ring.
    """

    def __init__(self):
        self.pair = np.zeros((0, 6))
        self.kept = False
        self.pair_ring = 0
        self._ring = np.zeros((0, 6))
        self._placed_for = None     # (filtering, block room, chunks) of the ring's places

    def ring(self, lists, room):
        """The near lists with the ring's places (``lists.near_places()``) and the ring, for a force
        pass of blocks of ``room`` entries; the places made again after a filtering."""
        key = (lists.n_filters, room, lists.nchunk)
        if key != self._placed_for:
            self._place(lists, room)
            self._placed_for = key
        self.pair, self.kept = self._ring, False
        return lists.near_places(), self.pair

    def keep(self, lists):
        """The near lists and a store of one place per near slot, kept after the pass (its first
        touch costs some 2 ms on the 20k pile)."""
        near = lists.near()._replace(cpair=np.arange(lists.k_near + 1, dtype=np.int32))
        self.pair, self.kept = np.empty((lists.k_near + 1, 6)), True
        return near, self.pair

    def kept_pairs(self, lists):
        """The kept store of the last evaluation, or None (not kept, or freed since)."""
        return self.pair if self.kept and len(self.pair) >= lists.k_near else None

    def free(self):
        """Free a kept store (scratch of one evaluation) while the history is packed: the peak
        memory then holds the history once."""
        self.pair = np.zeros((0, 6))

    def _place(self, lists, room):
        n, nchunk = lists.state.n_own, lists.nchunk
        # PAIR_RING places, or 4 blocks of the pass if more; never more than a chunk's entries
        most = max(int(lists.near_cstart[(c + 1) * n // nchunk] - lists.near_cstart[c * n // nchunk])
                   for c in range(nchunk))
        ring = 1 << max(PAIR_RING - 1, 4 * room - 1).bit_length()
        ring = min(ring, 1 << max(most - 1, 0).bit_length())
        self.pair_ring = ring
        places = int(pair_places(n, lists.near(), room, ring, nchunk, lists.near_cpair, lists.near_plink))
        if len(self._ring) < places:
            # freed first, so that its memory can serve the new one
            self._ring = None
            self._ring = np.empty((int(places * (1.0 + PAIR_ROOM)) + 64, 6))

    def nbytes(self):
        """Bytes of the ring and of a kept store."""
        return self._ring.nbytes + (self.pair.nbytes if self.pair is not self._ring else 0)
