"""Pair distances of a static packing: contact lists and g(r) histograms.

The analysis kernels. Points are binned into cells at least ``r_max / 2``
wide by ``cell_grid``; every search then scans the 5 x 5 x 5 block of cells
around a point, or a whole row when an axis has fewer than 5 cells. Cells
are periodic in x and y; in z the cell index is taken modulo a number of
layers that keeps the grid O(N) (a sphere flown far away must not make a
huge grid): a wrapped cell only adds candidates that the distance test
rejects, as z is never periodic. Points come wrapped into [0, L) in x and
y (``wrap``), so the kernels take the minimum image with the simulation's
``geometry.min_image``, and each partner is met once when r_max < L / 2.

Histograms are integer counts, accumulated per chunk of reference points
in parallel (numba threads) and summed: the result does not depend on the
number of threads.
"""
import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from .bundles import make_box
from .chunks import chunk_bounds
from .geometry import min_image

REACH = 2          # cells scanned either side of a point's own cell
N_CHUNKS = 64      # work units of the parallel loops (integer results, any thread count)


def wrap(x, L_x, L_y):
    """(n, 3) contiguous float64 copy of positions with x and y wrapped into [0, L) [d]."""
    w = np.array(x, dtype=np.float64, order="C")
    w[:, 0] %= L_x
    w[:, 1] %= L_y
    return w


def separations(x, i, j, L_x, L_y):
    """(M, 3) x[i] - x[j], minimum image in x and y, for positions in any image [d]."""
    d = x[i] - x[j]
    d[:, 0] -= L_x * np.round(d[:, 0] / L_x)
    d[:, 1] -= L_y * np.round(d[:, 1] / L_y)
    return d


class Grid(NamedTuple):
    """Points binned into cells (``cell_grid``).

    order : (n,) int64 point indices sorted by cell
    start : (n_cells + 1,) int64 CSR offsets of each cell in ``order``
    dims : (3,) int64 cells along x, y, z
    geo : (4,) float64 cell widths along x, y, z and the lowest z [d]
    """
    order: np.ndarray
    start: np.ndarray
    dims: np.ndarray
    geo: np.ndarray


def cell_grid(x, L_x, L_y, r_max):
    """Bin points into cells at least r_max / REACH wide.

    Parameters
    ----------
    x : (n, 3) float64 positions [d], wrapped (``wrap``)
    L_x, L_y : float box lengths [d]
    r_max : float largest distance searched [d]

    Returns
    -------
    Grid : (order, start, dims, geo)
    """
    w = r_max / REACH
    nx, ny = max(1, int(L_x // w)), max(1, int(L_y // w))
    z0 = float(x[:, 2].min()) if len(x) else 0.0
    z1 = float(x[:, 2].max()) if len(x) else 0.0
    # z layers, folded (modulo) beyond about two cells per point
    nz = min(int((z1 - z0) // w) + 1, max(2 * REACH + 1, -(-2 * len(x) // (nx * ny))))
    dims = np.array([nx, ny, nz], np.int64)
    geo = np.array([L_x / nx, L_y / ny, w, z0])
    cell = np.empty(len(x), np.int64)
    _cells(x, L_x, L_y, dims, geo, cell)
    order = np.argsort(cell, kind="stable").astype(np.int64)
    start = np.zeros(nx * ny * nz + 1, np.int64)
    np.cumsum(np.bincount(cell, minlength=nx * ny * nz), out=start[1:])
    return Grid(order, start, dims, geo)


@njit(cache=True)
def _cell_of(p, L_x, L_y, dims, geo):
    ix = min(int((p[0] % L_x) // geo[0]), dims[0] - 1)
    iy = min(int((p[1] % L_y) // geo[1]), dims[1] - 1)
    iz = max(int((p[2] - geo[3]) // geo[2]), 0) % dims[2]
    return ix, iy, iz


@njit(cache=True)
def _cells(x, L_x, L_y, dims, geo, cell):
    # the searches locate a point's cell with this same function
    for i in range(x.shape[0]):
        ix, iy, iz = _cell_of(x[i], L_x, L_y, dims, geo)
        cell[i] = (iz * dims[1] + iy) * dims[0] + ix


@njit(cache=True)
def _span(c, n):
    """Cells to scan along an axis of n cells taken modulo n: (first offset, count)."""
    if n < 2 * REACH + 1:
        return -c, n
    return -REACH, 2 * REACH + 1


@njit(cache=True)
def _cells_around(p, box, grid, out):
    """The cells of ``grid`` that can hold points within r_max of p: fills ``out``, returns how many (<= 125)."""
    dims = grid.dims
    ix, iy, iz = _cell_of(p, box.L_x, box.L_y, dims, grid.geo)
    ox, nx = _span(ix, dims[0])
    oy, ny = _span(iy, dims[1])
    oz, nz = _span(iz, dims[2])
    k = 0
    for bz in range(nz):
        az = (iz + oz + bz) % dims[2]
        for by in range(ny):
            cy = (iy + oy + by) % dims[1]
            for bx in range(nx):
                out[k] = (az * dims[1] + cy) * dims[0] + (ix + ox + bx) % dims[0]
                k += 1
    return k


@njit(cache=True)
def _dist2(x, i, j, box):
    dx = min_image(x[i, 0] - x[j, 0], box.L_x, box.half_x)
    dy = min_image(x[i, 1] - x[j, 1], box.L_y, box.half_y)
    dz = x[i, 2] - x[j, 2]
    return dx * dx + dy * dy + dz * dz


@njit(cache=True, parallel=True)
def pair_histograms(x, refs, box, r_max, dr, n_lin, xi_min, per_decade, n_log, grid):
    """Histograms of the distances from reference points to all other points.

    Parameters
    ----------
    x : (n, 3) float64 positions [d], wrapped (``wrap``); the partners: all of them
    refs : (n_ref,) int64 indices of the reference points in ``x``
    box : Box (``bundles.make_box``) [d]
    r_max : float counted distances are r < r_max [d]
    dr : float width of the linear bins [d]; bin k is [k dr, (k+1) dr)
    n_lin : int number of linear bins
    xi_min, per_decade, n_log : logarithmic bins in xi = r - 1 > 0, bin k is
        [xi_min 10^(k/per_decade), xi_min 10^((k+1)/per_decade))
    grid : Grid, ``cell_grid(x, box.L_x, box.L_y, r_max)``

    Returns
    -------
    lin : (n_lin,) int64 ordered pair counts per linear bin
    log : (n_log,) int64 ordered pair counts per logarithmic bin
    n_overlap : int ordered pairs with r < 1 (contacts)
    """
    n_ref = refs.shape[0]
    order, start = grid.order, grid.start
    lin = np.zeros((N_CHUNKS, n_lin), np.int64)
    lg = np.zeros((N_CHUNKS, n_log), np.int64)
    over = np.zeros(N_CHUNKS, np.int64)
    r2max = r_max * r_max
    lx0 = math.log10(xi_min)
    for c in prange(N_CHUNKS):
        cells = np.empty((2 * REACH + 1) ** 3, np.int64)
        lo, hi = chunk_bounds(c, n_ref, N_CHUNKS)
        for k in range(lo, hi):
            i = refs[k]
            for q in range(_cells_around(x[i], box, grid, cells)):
                for s in range(start[cells[q]], start[cells[q] + 1]):
                    j = order[s]
                    if j == i:
                        continue
                    d2 = _dist2(x, i, j, box)
                    if d2 >= r2max:
                        continue
                    r = math.sqrt(d2)
                    b = int(r / dr)
                    if b < n_lin:
                        lin[c, b] += 1
                    if r < 1.0:
                        over[c] += 1
                    elif r > 1.0 and n_log > 0:
                        t = int(math.floor((math.log10(r - 1.0) - lx0) * per_decade))
                        if 0 <= t < n_log:
                            lg[c, t] += 1
    return lin.sum(axis=0), lg.sum(axis=0), over.sum()


@njit(cache=True, parallel=True)
def _contact_counts(x, box, r_c, grid, counts, out_i, out_j, fill):
    """Pairs i < j closer than r_c [d]: per point i, their number into ``counts`` (``fill`` False), or the
    pairs into ``out_i``, ``out_j`` from offset ``counts[i]`` (``fill`` True)."""
    n = x.shape[0]
    order, start = grid.order, grid.start
    r2c = r_c * r_c
    for c in prange(N_CHUNKS):
        cells = np.empty((2 * REACH + 1) ** 3, np.int64)
        lo, hi = chunk_bounds(c, n, N_CHUNKS)
        for i in range(lo, hi):
            m = 0
            base = counts[i] if fill else 0
            for q in range(_cells_around(x[i], box, grid, cells)):
                for s in range(start[cells[q]], start[cells[q] + 1]):
                    j = order[s]
                    if j > i and _dist2(x, i, j, box) < r2c:
                        if fill:
                            out_i[base + m] = i
                            out_j[base + m] = j
                        m += 1
            if not fill:
                counts[i] = m


def close_pairs(x, L_x, L_y, r_c=1.0):
    """All pairs i < j closer than r_c (strict), minimum image in x and y.

    Parameters
    ----------
    x : (n, 3) float64 positions [d], in any image
    r_c : float [d]; needs r_c < L / 2

    Returns
    -------
    pairs : (M, 2) int64, sorted by i then by the cell scan order of j
    """
    x = wrap(x, L_x, L_y)
    n = len(x)
    if n == 0:
        return np.zeros((0, 2), np.int64)
    grid = cell_grid(x, L_x, L_y, r_c)
    box = make_box(L_x, L_y)
    counts = np.zeros(n + 1, np.int64)
    empty = np.zeros(0, np.int64)
    _contact_counts(x, box, r_c, grid, counts, empty, empty, False)
    offs = np.zeros(n + 1, np.int64)
    np.cumsum(counts[:n], out=offs[1:])
    pi, pj = np.empty(offs[-1], np.int64), np.empty(offs[-1], np.int64)
    _contact_counts(x, box, r_c, grid, offs, pi, pj, True)
    return np.stack([pi, pj], axis=1)
