"""Contact history between its two homes: list slots and compact per-row slots.

The list slots (``Slots``: ``hist`` Delta s [d] in the computing row's view,
``stamp`` the last evaluation in contact; entry k reaches slot g through
``link[k]`` = g, or ~g for an entry that takes its pair) hold it between
rebuilds; the compact slots (partner ids ascending, Delta s [d]) at a
rebuild, a migration and a checkpoint. Both are sorted by partner id, so
each direction is one merge per row. See docs/computing.md, "The contact
history's two homes".
"""
import numpy as np
from numba import njit, prange

from .chunks import chunk_bounds


@njit(cache=True, inline="always")
def stamp_of(epoch):
    """The stamp of force evaluation number ``epoch``: its value mod 2**32 (uint32)."""
    return np.uint32(epoch & 0xFFFFFFFF)


@njit(cache=True, inline="always")
def slot_of(lk):
    """The slot of a ``link`` value: g for g >= 0, and g for ~g (branch-free)."""
    return lk ^ (lk >> 31)


@njit(cache=True, parallel=True)
def count_contacts(n_own, lists, slots, epoch, slot_n, nchunk):
    """slot_n[i] = entries of row i in contact, for the owned rows.

    Parameters
    ----------
    n_own : int
    lists : Lists
        ``nbr_start`` and ``link`` are read.
    slots : Slots
        ``stamp`` is read.
    epoch : int
        The number of the last force evaluation.
    slot_n : (n_own,) int32, out
    nchunk : int
        Chunks of rows for the threads.

    Returns
    -------
    int : total contacts.
    """
    nbr_start, link, stamp = lists.nbr_start, lists.link, slots.stamp
    now = stamp_of(epoch)
    for c in prange(nchunk):
        lo, hi = chunk_bounds(c, n_own, nchunk)
        for i in range(lo, hi):
            m = 0
            for k in range(nbr_start[i], nbr_start[i + 1]):
                m += stamp[slot_of(link[k])] == now
            slot_n[i] = m
    total = 0
    for i in range(n_own):
        total += slot_n[i]
    return total


@njit(cache=True, parallel=True)
def entries_to_slots(n_own, ids, lists, slots, epoch, slot_start, slot_id, slot_ds, nchunk):
    """Pack the entries in contact into compact slots.

    An entry that takes its pair from the lower row (``link < 0``) holds
    minus the slot's Delta s, +0.0 for zero.

    Parameters
    ----------
    ids : (n_rows,) int64
    lists : Lists
        ``nbr_start``, ``nbr_list`` and ``link`` are read.
    slots : Slots
        ``hist`` [d] and ``stamp`` are read.
    epoch : int
        The number of the last force evaluation.
    slot_start : (n_own + 1,) int64
        Offsets of each row's slots (prefix sum of ``count_contacts``).
    slot_id : (M,) int64, slot_ds : (M, 3) float64, out
    """
    nbr_start, nbr_list, link = lists.nbr_start, lists.nbr_list, lists.link
    hist, stamp = slots.hist, slots.stamp
    now = stamp_of(epoch)
    for c in prange(nchunk):
        lo, hi = chunk_bounds(c, n_own, nchunk)
        for i in range(lo, hi):
            p = slot_start[i]
            for k in range(nbr_start[i], nbr_start[i + 1]):
                lk = link[k]
                h = slot_of(lk)
                if stamp[h] == now:
                    slot_id[p] = ids[nbr_list[k]]
                    if lk < 0:
                        for a in range(3):
                            slot_ds[p, a] = -hist[h, a] + 0.0
                    else:
                        for a in range(3):
                            slot_ds[p, a] = hist[h, a]
                    p += 1


@njit(cache=True, parallel=True)
def slots_to_entries(n_own, ids, lists, slot_start, slot_id, slot_ds, slots, epoch, nchunk):
    """Unpack compact slots onto the slots of new neighbour lists.

    A compact slot whose partner is not in the new list is dropped: the pair
    is beyond the list cutoff, so not in contact. Zeros are stored as +0.0.
    Each list slot is written by the row that computes its pair, from that
    row's view (the other row's is exactly its negative).

    Parameters
    ----------
    ids : (n_rows,) int64
    lists : Lists
        ``nbr_start``, ``nbr_list`` and ``link`` are read.
    slot_start : (n_own + 1,) int64, slot_id : (M,) int64, slot_ds : (M, 3) float64
        The compact slots (partner ids, Delta s [d]).
    slots : Slots
        ``hist`` (K, 3) float64 [d] and ``stamp`` (K,) uint32 are written.
    epoch : int
        The number of the last force evaluation: the slot of a pair in contact
        gets it as its stamp, any other ``epoch - 1``.
    """
    nbr_start, nbr_list, link = lists.nbr_start, lists.nbr_list, lists.link
    hist, stamp = slots.hist, slots.stamp
    now = stamp_of(epoch)
    old = stamp_of(epoch - 1)
    for c in prange(nchunk):
        lo, hi = chunk_bounds(c, n_own, nchunk)
        for i in range(lo, hi):
            p = slot_start[i]
            pe = slot_start[i + 1]
            for k in range(nbr_start[i], nbr_start[i + 1]):
                h = link[k]
                if h < 0:
                    continue
                jid = ids[nbr_list[k]]
                while p < pe and slot_id[p] < jid:
                    p += 1
                if p < pe and slot_id[p] == jid:
                    stamp[h] = now
                    for a in range(3):
                        hist[h, a] = slot_ds[p, a] + 0.0
                else:
                    stamp[h] = old
                    for a in range(3):
                        hist[h, a] = 0.0
