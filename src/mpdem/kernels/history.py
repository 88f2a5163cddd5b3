"""Contact history between its two homes: list entries and compact slots.

Between rebuilds the history of row i's contact with partner j is with the
neighbour-list entry k of that pair: ``stamp[k]``, the number of the last
force evaluation that found it in contact (``contact_forces``), and Delta s in
the slot ``hist[link[k]]``, which the two entries of a pair within a chunk
share (``neighbours.link_entries``). An entry is in contact now if its stamp
is the last evaluation's number, ``epoch``. At a rebuild,
a migration or a checkpoint it is in compact per-row slots (partner ids
ascending, Delta s), which travel with the particle (ARCHITECTURE.md).
Both are sorted by partner id, so each direction is one merge per row.
"""
import numpy as np
from numba import njit, prange


@njit(cache=True, inline="always")
def stamp_of(epoch):
    """The stamp of force evaluation number ``epoch``: its value mod 2**32 (uint32)."""
    return np.uint32(epoch & 0xFFFFFFFF)


@njit(cache=True, parallel=True)
def count_contacts(n_own, nbr_start, stamp, epoch, slot_n, nchunk):
    """slot_n[i] = entries of row i in contact, for the owned rows.

    Parameters
    ----------
    nbr_start : (n_own + 1,) int64; stamp : (E,) uint32; epoch : int
    slot_n : (n_own,) int32, out
    nchunk : int
        Chunks of rows for the threads.

    Returns
    -------
    int : total contacts.
    """
    now = stamp_of(epoch)
    for c in prange(nchunk):
        for i in range(c * n_own // nchunk, (c + 1) * n_own // nchunk):
            m = 0
            for k in range(nbr_start[i], nbr_start[i + 1]):
                m += stamp[k] == now
            slot_n[i] = m
    total = 0
    for i in range(n_own):
        total += slot_n[i]
    return total


@njit(cache=True, parallel=True)
def entries_to_slots(n_own, ids, nbr_start, nbr_list, link, n_pairs, hist, stamp, epoch, slot_start, slot_id,
                     slot_ds, nchunk):
    """Pack the entries in contact into compact slots.

    The higher row of a pair within a chunk (``link_entries``) shares the
    pair's history slot, which holds the lower row's Delta s: its own is
    the negative, +0.0 for zero.

    Parameters
    ----------
    ids : (n_rows,) int64
    nbr_start : (n_own + 1,) int64, nbr_list : (E,) int32, link : (E,) int32
    n_pairs : int
        History slots below this are shared by the two entries of a pair.
    hist : (n_pairs + U, 3) float64, stamp : (E,) uint32, epoch : int
    slot_start : (n_own + 1,) int64
        Offsets of each row's slots (prefix sum of ``count_contacts``).
    slot_id : (M,) int64, slot_ds : (M, 3) float64, out
    """
    now = stamp_of(epoch)
    for c in prange(nchunk):
        for i in range(c * n_own // nchunk, (c + 1) * n_own // nchunk):
            p = slot_start[i]
            for k in range(nbr_start[i], nbr_start[i + 1]):
                if stamp[k] == now:
                    j = nbr_list[k]
                    h = link[k]
                    slot_id[p] = ids[j]
                    if h < n_pairs and j < i:
                        for a in range(3):
                            slot_ds[p, a] = -hist[h, a] + 0.0
                    else:
                        for a in range(3):
                            slot_ds[p, a] = hist[h, a]
                    p += 1


@njit(cache=True, parallel=True)
def slots_to_entries(n_own, ids, nbr_start, nbr_list, link, n_pairs, slot_start, slot_id, slot_ds, hist,
                     stamp, epoch, nchunk):
    """Unpack compact slots onto the entries of new neighbour lists.

    A slot whose partner is not in the new list is dropped: the pair is
    beyond the list cutoff, so not in contact. Zeros are stored as +0.0. A
    shared pair slot (``link_entries``) is written from its lower row's
    view, which is exactly minus the higher row's.

    Parameters
    ----------
    link : (E,) int32, n_pairs : int
    slot_start : (n_own + 1,) int64, slot_id : (M,) int64, slot_ds : (M, 3) float64
    hist : (n_pairs + U, 3) float64, stamp : (E,) uint32, out
    epoch : int
        The number of the last force evaluation: a slot's entry gets it as its
        stamp (in contact then), any other entry ``epoch - 1``.
    """
    now = stamp_of(epoch)
    old = stamp_of(epoch - 1)
    for c in prange(nchunk):
        for i in range(c * n_own // nchunk, (c + 1) * n_own // nchunk):
            p = slot_start[i]
            pe = slot_start[i + 1]
            for k in range(nbr_start[i], nbr_start[i + 1]):
                j = nbr_list[k]
                jid = ids[j]
                h = link[k]
                own = h >= n_pairs or j > i
                while p < pe and slot_id[p] < jid:
                    p += 1
                if p < pe and slot_id[p] == jid:
                    stamp[k] = now
                    if own:
                        for a in range(3):
                            hist[h, a] = slot_ds[p, a] + 0.0
                else:
                    stamp[k] = old
                    if own:
                        for a in range(3):
                            hist[h, a] = 0.0
