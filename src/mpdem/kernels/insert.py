"""Random sequential addition of non-overlapping unit spheres."""
import numpy as np
from numba import njit

from .geometry import min_image


@njit(cache=True)
def rsa_insert(cand, obstacles, out, n_done, box, z_lo, z_hi):
    """Accept candidate centres that overlap nothing placed so far.

    Candidates are consumed in order, so the result depends only on the
    random stream, never on how it was cut into batches.

    Parameters
    ----------
    cand : (B, 3) float64
        Uniform numbers in [0, 1), scaled to the box here.
    obstacles : (K, 3) float64
        Fixed spheres to avoid (the bed), centres [d].
    out : (N, 3) float64, in/out
        Accepted centres; rows ``0..n_done-1`` are already placed.
    n_done : int
    box : Box
        The periodic box [d]: centres go in [0, L_x) x [0, L_y).
    z_lo, z_hi : float
        Centres go in [z_lo, z_hi] [d].

    Returns
    -------
    n_done : int
        Number of centres placed after this batch.
    """
    L_x, L_y, hx, hy = box
    n_want = out.shape[0]
    nx = max(int(L_x // 1.0), 1)
    ny = max(int(L_y // 1.0), 1)
    cx = L_x / nx
    cy = L_y / ny
    z0 = min(z_lo, obstacles[:, 2].min() if obstacles.shape[0] else z_lo) - 1.0
    nz = int((z_hi - z0) // 1.0) + 3
    # cell lists as singly linked chains (head per cell, next per sphere)
    n_all = obstacles.shape[0] + n_want
    head = np.full(nx * ny * nz, -1, np.int64)
    nxt = np.full(n_all, -1, np.int64)
    pos = np.empty((n_all, 3))
    m = 0
    for i in range(obstacles.shape[0] + n_done):
        p = obstacles[i] if i < obstacles.shape[0] else out[i - obstacles.shape[0]]
        iz = int((p[2] - z0) // 1.0)
        if iz < 0 or iz >= nz:
            continue
        c = (iz * ny + min(int(p[1] / cy), ny - 1)) * nx + min(int(p[0] / cx), nx - 1)
        pos[m] = p
        nxt[m] = head[c]
        head[c] = m
        m += 1
    for k in range(cand.shape[0]):
        if n_done >= n_want:
            break
        px = cand[k, 0] * L_x
        py = cand[k, 1] * L_y
        pz = z_lo + cand[k, 2] * (z_hi - z_lo)
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
    return n_done
