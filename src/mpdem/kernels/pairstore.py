"""Where each near computed entry leaves its pair's force for the row sums: the pair store.

A computed entry's contact force and torque live from the force pass's block
that computes them to the row sum of its partner, a row later in the same
chunk, usually within a few layers of cells. So a store of one place per
near slot (K_near places, 48 bytes each) is mostly dead and, for a large
pile, streams from main memory every step. Instead each chunk reuses a ring
of ``ring`` places: entry e of a chunk whose first entry is e0 goes to place
``c ring + ((e - e0) mod ring)``. An entry whose partner sums it too late for
that (its place is written again first) gets a place of its own past the
rings: the pairs across the row order's columns and the periodic boundaries,
some 5 % of a large pile's. Which places the entries use changes no value, so
no bit (docs/computing.md, "The pair store").
"""
import numpy as np
from numba import njit, prange

from .chunks import chunk_bounds
from .history import slot_of


@njit(cache=True, parallel=True)
def pair_places(n_own, near, width, ring, nchunk, cpair, plink):
    """Each near computed entry's place in the pair store, and the near links to places.

    The force pass writes an entry's place while screening the block of rows whose
    computed entries fit its ``width`` places of scratch (``forces._rows``), and a
    partner row j reads it in its own block's sum. Between the two, the pass writes
    the entries up to at most ``cstart[j] + width``. An entry e read by row j keeps a
    ring place if that is no more than ``ring`` entries past e, and gets its own
    place otherwise.

    Parameters
    ----------
    n_own : int
    near : Near
        ``start``, ``link`` (near slots e, ~e for a taken entry) and ``cstart``, read.
    width : int
        The force pass's block scratch ``W`` (``Scratch.found.shape[1]``).
    ring : int
        Places of each chunk's ring, a power of two: longer than ``width`` (the engine
        makes it at least 4 widths), or at least as long as every chunk's entries, which
        then all keep their ring places.
    nchunk : int
        The chunks of the near lists' links.
    cpair : (>= K_near,) int32, out
        The place of each near computed entry.
    plink : (>= E_near,) int32, out
        ``link`` with each e replaced by its place (~place for a taken entry).

    Returns
    -------
    int : places the store needs (``nchunk * ring`` and those of the far entries).
    """
    start, link, cstart = near.start, near.link, near.cstart
    mask = ring - 1
    far = np.zeros(nchunk + 1, np.int64)
    for c in prange(nchunk):
        lo, hi = chunk_bounds(c, n_own, nchunk)
        e0 = cstart[lo]
        for e in range(e0, cstart[hi]):
            cpair[e] = c * ring + ((e - e0) & mask)
        # an entry taken too late for the ring: marked, then numbered in e order below (with
        # no more entries than places, none is written twice)
        for j in range(lo, hi if cstart[hi] - e0 > ring else lo):
            for k in range(start[j], start[j + 1]):
                lk = link[k]
                if lk < 0:
                    e = slot_of(lk)
                    if cstart[j] + width - e > ring:
                        cpair[e] = -1
        m = 0
        for e in range(e0, cstart[hi]):
            m += cpair[e] < 0
        far[c + 1] = m
    for c in range(nchunk):
        far[c + 1] += far[c]
    for c in prange(nchunk):
        lo, hi = chunk_bounds(c, n_own, nchunk)
        p = nchunk * ring + far[c]
        for e in range(cstart[lo], cstart[hi]):
            if cpair[e] < 0:
                cpair[e] = p
                p += 1
        for k in range(start[lo], start[hi]):
            lk = link[k]
            q = cpair[slot_of(lk)]
            plink[k] = q if lk >= 0 else ~q
    return nchunk * ring + far[nchunk]
