"""The grid of domains: which rank owns which box, and which boxes reach which (``decomp``).

The ranks form a Px x Py x Pz grid: Px x Py columns of equal widths in x and y (the box is periodic
there), each cut into Pz slabs along z whose bounds ``decomp.Domain`` balances column by column.
Rank r is (ix, iy, iz) with r = (ix Py + iy) Pz + iz: the slabs of a column are consecutive ranks,
and Px = Py = 1 is the slab decomposition of one column.

Everything here is arithmetic on bounds that every rank holds alike, so a sender and its receiver
always agree on who sends what. Positions keep their coordinates in [0, L): a ghost that lies across
a periodic face is an exact copy of its owner's row, and the force kernels' minimum image joins it
to its partners, as they do on one rank (so no shift of a coordinate can change a bit).
"""
from __future__ import annotations

import math

import numpy as np

from .errors import AgreedError

# the packing fraction that estimates a pile's settled height from its sphere count, for the choice of a
# grid alone (``choose``; no effect on results)
SETTLED_PHI = 0.6


def coords(rank, grid):
    """(ix, iy, iz) of ``rank`` (int or int array) in ``grid`` = (Px, Py, Pz)."""
    _, Py, Pz = grid
    col, iz = np.divmod(rank, Pz)
    ix, iy = np.divmod(col, Py)
    return ix, iy, iz


def axis_bounds(L, n):
    """The n + 1 bounds of n equal intervals of [0, L) [d]: L i / n, the last exactly L."""
    b = np.array([L * i / n for i in range(n + 1)])
    b[-1] = L
    return b


def in_periodic(x, lo, hi, L):
    """Mask of the coordinates ``x`` (in [0, L)) inside [lo, hi) or one of its images shifted by +-L.

    Parameters
    ----------
    x : (n,) float64 [d]
    lo, hi : float
        A widened interval, lo >= -L and hi <= 2 L [d].
    L : float
        The period [d].
    """
    if hi - lo >= L:
        return np.ones(len(x), bool)
    return ((x >= lo) & (x < hi)) | ((x + L >= lo) & (x + L < hi)) | ((x - L >= lo) & (x - L < hi))


def overlap_periodic(a0, a1, b0, b1, L):
    """Whether [a0, a1) meets [b0, b1) or one of its images shifted by +-L (elementwise, broadcast)."""
    hit = np.zeros(np.broadcast(a0, a1, b0, b1).shape, bool)
    for k in (-1.0, 0.0, 1.0):
        hit |= (a0 < b1 + k * L) & (b0 + k * L < a1)
    return hit


def check(grid, ranks):
    """``grid`` as a tuple (Px, Py, Pz) whose product is ``ranks``; an AgreedError (every rank raises it) if not."""
    grid = tuple(int(g) for g in grid)
    if len(grid) != 3 or min(grid) < 1 or math.prod(grid) != ranks:
        raise AgreedError(f"decomp.grid = {list(grid)}: {math.prod(grid) if len(grid) == 3 else '?'} domains for "
                          f"{ranks} ranks; accepted: three integers >= 1 [Px, Py, Pz] whose product is the number of "
                          f"ranks, or [] (chosen from the ranks and the box)")
    return grid


def divisors(n):
    return [d for d in range(1, n + 1) if n % d == 0]


def ghost_volume(grid, L_x, L_y, height, r_list):
    """The volume of one rank's halo [d^3]: its box widened by ``r_list`` on each face it shares with
    another rank, less the box (a column of the whole width has no face in that axis)."""
    widths = (L_x / grid[0], L_y / grid[1], max(height, r_list) / grid[2])
    outer = math.prod(w + 2 * r_list if p > 1 else w for w, p in zip(widths, grid))
    return outer - math.prod(widths)


def choose(ranks, L_x, L_y, height, r_list):
    """The grid of ``ranks`` domains with the least halo a rank (``ghost_volume``) for a pile ``height``
    [d] tall on an L_x x L_y bed: a tall narrow pile stays all slabs, a wide low one gets columns. Ties
    go to fewer columns, then to more columns along x.

    Returns
    -------
    (Px, Py, Pz) : tuple of int
    """
    best = None
    for Px in divisors(ranks):
        for Py in divisors(ranks // Px):
            g = (Px, Py, ranks // (Px * Py))
            # the volume rounded to a millionth of a d^3, so that mirror grids tie exactly
            key = (round(ghost_volume(g, L_x, L_y, height, r_list), 6), Px * Py, -Px)
            if best is None or key < best[0]:
                best = (key, g)
    return best[1]


def settled_height(n_mobile, L_x, L_y, z_range):
    """A pile's height for ``choose`` [d]: its mobile spheres' height range ``z_range``, or, if lower,
    the height they fill at ``SETTLED_PHI`` (a pour's loose start settles to that)."""
    packed = n_mobile * (math.pi / 6.0) / (L_x * L_y * SETTLED_PHI)
    return max(min(z_range, packed), 0.0)
