"""Random sequential addition of non-overlapping unit spheres.

The placed spheres (the obstacles, then every accepted centre) are kept in cell lists of unit
cells, singly linked chains (a head per cell, a next per sphere), made once (``rsa_cells``) and
extended by every batch of candidates (``rsa_batch``). A batch costs its own candidates only, so
an insertion can be cut into short batches (a caller looks at signals and the clock between them)
with the same result: candidates are consumed in order, and whether one is accepted depends only
on the spheres placed before it, never on the order of a chain.
"""
import numpy as np
from numba import njit

from .geometry import min_image


@njit(cache=True)
def rsa_cells(obstacles, n_want, box, z_lo, z_hi):
    """The cell lists of an insertion, holding the obstacles.

    Parameters
    ----------
    obstacles : (K, 3) float64
        Fixed spheres to avoid (the bed), centres [d].
    n_want : int
        Spheres to insert (room is made for them).
    box : Box
        The periodic box [d].
    z_lo, z_hi : float
        Centres go in [z_lo, z_hi] [d].

    Returns
    -------
    head : (nx ny nz,) int64
        First sphere of each cell's chain (-1: none).
    nxt : (K + n_want,) int64
        Next sphere of each sphere's chain (-1: the end).
    pos : (K + n_want, 3) float64
        Centres of the spheres in the chains [d].
    m : int
        Spheres in the chains (obstacles outside the cells' z range are left out).
    geo : (4,) float64
        nx, ny, nz and the bottom of the lowest cell z0 [d].
    """
    L_x, L_y = box[0], box[1]
    nx = max(int(L_x // 1.0), 1)
    ny = max(int(L_y // 1.0), 1)
    cx = L_x / nx
    cy = L_y / ny
    z0 = min(z_lo, obstacles[:, 2].min() if obstacles.shape[0] else z_lo) - 1.0
    nz = int((z_hi - z0) // 1.0) + 3
    n_all = obstacles.shape[0] + n_want
    head = np.full(nx * ny * nz, -1, np.int64)
    nxt = np.full(n_all, -1, np.int64)
    pos = np.empty((n_all, 3))
    m = 0
    for i in range(obstacles.shape[0]):
        p = obstacles[i]
        iz = int((p[2] - z0) // 1.0)
        if iz < 0 or iz >= nz:
            continue
        c = (iz * ny + min(int(p[1] / cy), ny - 1)) * nx + min(int(p[0] / cx), nx - 1)
        pos[m] = p
        nxt[m] = head[c]
        head[c] = m
        m += 1
    geo = np.array([float(nx), float(ny), float(nz), z0])
    return head, nxt, pos, m, geo


@njit(cache=True)
def rsa_batch(cand, out, n_done, head, nxt, pos, m, geo, box, lo, span):
    """Accept the candidate centres of one batch that overlap nothing placed so far.

    Parameters
    ----------
    cand : (B, 3) float64
        Uniform numbers in [0, 1), scaled to the region ``lo + cand * span`` here.
    out : (N, 3) float64, in/out
        Accepted centres; rows ``0..n_done-1`` are already placed.
    n_done : int
    head, nxt, pos, m, geo
        The cell lists of ``rsa_cells``, in/out (``m``: spheres in them).
    box : Box
        The periodic box [d] (of the cells and the minimum image).
    lo, span : (3,) float64
        Centres go in [lo, lo + span] [d], within the box in x and y: (0, 0, z_lo) and
        (L_x, L_y, z_hi - z_lo) for the whole box.

    Returns
    -------
    n_done : int
        Centres placed after this batch.
    m : int
        Spheres in the cell lists after this batch.
    """
    L_x, L_y, hx, hy = box
    n_want = out.shape[0]
    nx, ny, nz, z0 = int(geo[0]), int(geo[1]), int(geo[2]), geo[3]
    cx = L_x / nx
    cy = L_y / ny
    for k in range(cand.shape[0]):
        if n_done >= n_want:
            break
        px = lo[0] + cand[k, 0] * span[0]
        py = lo[1] + cand[k, 1] * span[1]
        pz = lo[2] + cand[k, 2] * span[2]
        ix = min(int(px / cx), nx - 1)
        iy = min(int(py / cy), ny - 1)
        iz = int((pz - z0) // 1.0)
        ok = True
        for a in range(-1, 2):
            jz = iz + a
            if jz < 0 or jz >= nz or not ok:
                continue
            for b in range(-1, 2):
                jy = (iy + b) % ny
                for e in range(-1, 2):
                    jx = (ix + e) % nx
                    q = head[(jz * ny + jy) * nx + jx]
                    while q >= 0:
                        dx = min_image(px - pos[q, 0], L_x, hx)
                        dy = min_image(py - pos[q, 1], L_y, hy)
                        dz = pz - pos[q, 2]
                        if dx * dx + dy * dy + dz * dz < 1.0:
                            ok = False
                            break
                        q = nxt[q]
                    if not ok:
                        break
                if not ok:
                    break
        if ok:
            out[n_done, 0] = px
            out[n_done, 1] = py
            out[n_done, 2] = pz
            c = (iz * ny + iy) * nx + ix
            pos[m, 0] = px
            pos[m, 1] = py
            pos[m, 2] = pz
            nxt[m] = head[c]
            head[c] = m
            m += 1
            n_done += 1
    return n_done, m
