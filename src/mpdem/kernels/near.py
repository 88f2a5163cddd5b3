"""The near lists: the entries of the neighbour lists within a shorter reach.

The force kernel screens every computed entry of the Verlet lists (reach
1 + skin) and sums every entry of a row. Most of them are out of contact.
Between two list rebuilds the near lists keep only the entries within
1 + near_skin (near_skin <= skin); they are filtered again whenever a
particle has moved near_skin/2 since the last filtering, so a pair they
leave out cannot touch. Such a pair would only add zeros to its rows' sums
(+0.0 or -0.0 added to a sum that is never -0.0), so the force kernel over
the near lists gives the same bits as over the whole lists, whenever and on
whichever rank they were filtered (docs/computing.md, "The near lists").
"""
from numba import njit

from .geometry import min_image
from .history import slot_of


@njit(cache=True, error_model="numpy")
def near_lists(n_own, x, fixed, box, lists, r2_near, near, g2e):
    """Filter the computed and the taken entries of the owned rows to the near reach.

    A computed entry is kept when its pair's squared distance is below ``r2_near``;
    an entry that takes its pair is kept when the computing entry was, so the two
    views of a pair are kept or left out together.

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
        ``cslot`` int32, written up to their lengths.
    g2e : (K,) int32, scratch
        One per slot of ``lists``: its near slot, or -1.

    Returns
    -------
    K_near, E_near : int
        Near computed entries and near entries. If either exceeds the length of
        its arrays, those were not all written: grow them and call again.
    """
    nbr_start, link, comp_start, comp_list = lists.nbr_start, lists.link, lists.comp_start, lists.comp_list
    start, nlink, cstart, cj, cslot = near.start, near.link, near.cstart, near.cj, near.cslot
    L_x, L_y, hx, hy = box
    cap_c = len(cj)
    cap_e = len(nlink)
    # first the computed entries of every row, so that a taking entry finds its slot's fate
    e = 0
    cstart[0] = 0
    for i in range(n_own):
        if fixed[i]:
            for g in range(comp_start[i], comp_start[i + 1]):
                g2e[g] = -1
            cstart[i + 1] = e
            continue
        xi = x[i, 0]
        yi = x[i, 1]
        zi = x[i, 2]
        for g in range(comp_start[i], comp_start[i + 1]):
            j = comp_list[g]
            dx = min_image(xi - x[j, 0], L_x, hx)
            dy = min_image(yi - x[j, 1], L_y, hy)
            dz = zi - x[j, 2]
            if dx * dx + dy * dy + dz * dz < r2_near:
                if e < cap_c:
                    cj[e] = j
                    cslot[e] = g
                g2e[g] = e
                e += 1
            else:
                g2e[g] = -1
        cstart[i + 1] = e
    k = 0
    start[0] = 0
    for i in range(n_own):
        if not fixed[i]:
            for a in range(nbr_start[i], nbr_start[i + 1]):
                lk = link[a]
                t = g2e[slot_of(lk)]
                if t >= 0:
                    if k < cap_e:
                        nlink[k] = t if lk >= 0 else ~t
                    k += 1
        start[i + 1] = k
    return e, k
