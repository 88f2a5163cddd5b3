"""The near lists: the entries of the neighbour lists within a shorter reach.

Over the Verlet lists (reach 1 + skin) the force kernel would screen every
computed entry and sum every entry of a row, most of them out of contact.
Between two list rebuilds the near lists keep only the entries within
1 + near_skin (near_skin <= skin); they are filtered again whenever a
particle has moved near_skin/2 since the last filtering, so a pair they
leave out cannot touch. Such a pair would only add zeros to its rows' sums
(+0.0 or -0.0 added to a sum that is never -0.0), so the force kernel over
the near lists gives the same bits as over the whole lists, whenever and on
whichever rank they were filtered (docs/computing.md, "The near lists").
"""
import numpy as np
from numba import njit, prange

from .chunks import chunk_bounds
from .geometry import min_image
from .history import slot_of


@njit(cache=True, parallel=True, error_model="numpy")
def near_lists(n_own, x, fixed, box, lists, r2_near, near, g2e, nchunk):
    """Filter the computed and the taken entries of the owned rows to the near reach.

    A computed entry is kept when its pair's squared distance is below ``r2_near``;
    an entry that takes its pair is kept when the computing entry was, so the two
    views of a pair are kept or left out together (an entry takes its pair from a
    lower row of its own chunk, ``neighbours.link_entries``).

    Parameters
    ----------
    n_own : int
        Rows ``0..n_own-1`` have lists.
    x : (n_rows, 3) float64
        Positions [d], ghosts included and current.
    fixed : (n_rows,) uint8
        1 for bed rows (they compute nothing: their near lists are empty).
    box : Box
    lists : Lists
        The Verlet lists with their links (``neighbours.link_entries``), read.
    r2_near : float
        (1 + near_skin)^2 [d^2].
    near : Near, out
        ``start`` and ``cstart`` (>= n_own + 1,) int64; ``link`` int32 and ``cj``,
        ``cslot`` int32, written if they have room for all and one spare element.
    g2e : (K,) int32, scratch
        One per slot of ``lists``: its near slot within its chunk, or -1.
    nchunk : int
        The chunks of the lists' links (the near lists do not depend on it otherwise).

    Returns
    -------
    K_near, E_near : int
        Near computed entries and near entries. If ``cj`` is not longer than K_near or
        ``link`` not longer than E_near, only ``start`` and ``cstart`` were written: grow
        them and call again.
    """
    # fields by attribute before the loops, never unpacked as a tuple (bundles.py: numba's prange)
    nbr_start, nbr_list, link = lists.nbr_start, lists.nbr_list, lists.link
    start, nlink, cstart, cj, cslot = near.start, near.link, near.cstart, near.cj, near.cslot
    L_x, L_y, hx, hy = box.L_x, box.L_y, box.half_x, box.half_y
    # per chunk, in row order: each row's kept entries counted, each slot numbered within its chunk
    # (without a branch on the outcome; the branch on computed / taken was the faster here)
    for c in prange(nchunk):
        lo, hi = chunk_bounds(c, n_own, nchunk)
        e = 0
        # unsigned rows and entries: numba adds no negative-index wrap-around to them (2.3 -> 2.0 ms on the 20k pile)
        for i in range(np.uint64(lo), np.uint64(hi)):
            kc = 0
            ke = 0
            if not fixed[i]:
                xi = x[i, 0]
                yi = x[i, 1]
                zi = x[i, 2]
                for a in range(np.uint64(nbr_start[i]), np.uint64(nbr_start[i + 1])):
                    lk = link[a]
                    g = np.uint64(slot_of(lk))
                    # a computed slot gets its number or -1; a taken one was numbered by its lower row
                    if lk >= 0:
                        j = np.uint64(nbr_list[a])
                        dx = min_image(xi - x[j, 0], L_x, hx)
                        dy = min_image(yi - x[j, 1], L_y, hy)
                        dz = zi - x[j, 2]
                        keep = dx * dx + dy * dy + dz * dz < r2_near
                        g2e[g] = e + kc if keep else -1
                        kc += keep
                    ke += g2e[g] >= 0
            e += kc
            cstart[i + 1] = kc
            start[i + 1] = ke
    cstart[0] = 0
    start[0] = 0
    for i in range(n_own):
        cstart[i + 1] += cstart[i]
        start[i + 1] += start[i]
    k_near = cstart[n_own]
    e_near = start[n_own]
    if k_near >= len(cj) or e_near >= len(nlink):
        return k_near, e_near
    # each entry is written at the row's next place, which only a kept one takes; past the row's
    # end (or a taken entry's cj), into the spare last element, so no other row's is touched
    spare_c = len(cj) - 1
    spare_e = len(nlink) - 1
    for c in prange(nchunk):
        lo, hi = chunk_bounds(c, n_own, nchunk)
        base = cstart[lo]
        for i in range(np.uint64(lo), np.uint64(hi)):
            pc = cstart[i]
            end_c = cstart[i + 1]
            pe = start[i]
            end_e = start[i + 1]
            for a in range(np.uint64(nbr_start[i]), np.uint64(nbr_start[i + 1])):
                lk = link[a]
                g = np.uint64(slot_of(lk))
                t = g2e[g]
                kept = t >= 0
                computed = lk >= 0
                w = pc if computed and pc < end_c else spare_c
                cj[w] = nbr_list[a]
                cslot[w] = g
                pc += kept & computed
                w = pe if pe < end_e else spare_e
                nlink[w] = base + t if computed else ~(base + t)
                pe += kept
    return k_near, e_near
