"""Measurements on a static packing (physics.md section 6).

This module holds the bulk-region, contact and packing-fraction measurements
that every run reports at its end; the full analysis stage (g(r), power-law
fits, P(zeta), across-run tables) builds on them.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

R = 0.5


def slab_volume(zc, a, b, radius=R):
    """Volume of spheres of centre height zc inside the slab a <= z <= b [d^3].

    Parameters
    ----------
    zc : array of float
    a, b : float or arrays broadcastable with zc

    V = pi [R^2 u - u^3 / 3] between u = clamp(a - zc) and clamp(b - zc), with
    clamp to [-R, R] (the exact sphere-slab intersection).
    """
    ua = np.clip(a - zc, -radius, radius)
    ub = np.clip(b - zc, -radius, radius)
    return math.pi * ((radius ** 2 * ub - ub ** 3 / 3) - (radius ** 2 * ua - ua ** 3 / 3))


def phi_profile(z, L_x, L_y, z0, z1, width=0.5):
    """Horizontally averaged packing fraction phi(z) of spheres at heights z.

    Returns
    -------
    edges : (nb + 1,) bin edges [d] from z0 to at least z1
    phi : (nb,) packing fraction per bin (exact sphere-slab volumes)
    """
    nb = max(1, int(math.ceil((z1 - z0) / width)))
    edges = z0 + width * np.arange(nb + 1)
    vol = np.zeros(nb)
    base = np.floor((z - z0) / width).astype(np.int64)
    reach = int(math.ceil(R / width))
    for k in range(-reach, reach + 1):
        b = base + k
        ok = (b >= 0) & (b < nb)
        np.add.at(vol, b[ok], slab_volume(z[ok], edges[b[ok]], edges[b[ok] + 1]))
    return edges, vol / (L_x * L_y * width)


def find_contacts(x, L_x, L_y):
    """All overlapping pairs (r < d, strict) with minimum image in x and y.

    Returns
    -------
    pairs : (M, 2) int64 row indices, i < j
    r : (M,) centre distances [d]
    """
    pts = np.array(x, float)
    pts[:, 0] %= L_x
    pts[:, 1] %= L_y
    pts[:, 2] -= pts[:, 2].min()
    span = pts[:, 2].max() + 10.0
    tree = cKDTree(pts, boxsize=[L_x, L_y, 2 * span])
    pairs = tree.query_pairs(1.0, output_type="ndarray").astype(np.int64)
    if len(pairs) == 0:
        return np.zeros((0, 2), np.int64), np.zeros(0)
    d = pts[pairs[:, 0]] - pts[pairs[:, 1]]
    d[:, 0] -= L_x * np.round(d[:, 0] / L_x)
    d[:, 1] -= L_y * np.round(d[:, 1] / L_y)
    r = np.sqrt(np.einsum("ij,ij->i", d, d))
    keep = r < 1.0
    return pairs[keep], r[keep]


def remove_rattlers(n_rows, pairs, removable, n_min):
    """Iteratively remove particles with fewer than n_min contacts.

    Parameters
    ----------
    n_rows : int
    pairs : (M, 2) int contacts
    removable : (n_rows,) bool, False for particles never removed (the bed)
    n_min : int

    Returns
    -------
    kept : (n_rows,) bool
    counts : (n_rows,) int contacts among kept particles
    """
    kept = np.ones(n_rows, bool)
    while True:
        live = kept[pairs[:, 0]] & kept[pairs[:, 1]]
        counts = np.bincount(pairs[live].ravel(), minlength=n_rows)
        drop = kept & removable & (counts < n_min)
        if not drop.any():
            return kept, counts
        kept &= ~drop


def bulk_summary(x, fixed, L_x, L_y, mu, margin_bottom=-1.0, margin_top=-1.0, n_min=-1,
                 profile_bin=0.5):
    """Bulk z, z without rattlers, rattler fraction and phi_f of a packing.

    Parameters
    ----------
    x : (n, 3) positions [d]; fixed : (n,) 1 for bed spheres
    mu : friction (sets the default rattler threshold)
    margin_bottom, margin_top : bulk margins [d]; -1 = automatic (6.1)
    n_min : rattler threshold; -1 = 4 for mu = 0, 2 for mu > 0

    Returns
    -------
    dict with z, z_no_rattlers, rattler_fraction, phi, n_bulk, z1, z2, h,
    z_bed, margins, P(z), overlap statistics.
    """
    fixed = np.asarray(fixed).astype(bool)
    mob = ~fixed
    zm = x[mob, 2]
    if zm.size == 0:
        raise ValueError("no mobile particles to analyse")
    z_bed = float(x[fixed, 2].max()) if fixed.any() else float(zm.min()) - R
    top = float(zm.max()) + 1.0
    edges, phi = phi_profile(zm, L_x, L_y, z_bed, top, profile_bin)
    centres = 0.5 * (edges[:-1] + edges[1:])
    # plateau window of physics.md 6.1, shrunk for piles shorter than the paper's
    h_nominal = zm.size * math.pi / 6 / (L_x * L_y * 0.6)
    lo, hi = z_bed + min(10.0, 0.25 * h_nominal), z_bed + min(30.0, 0.75 * h_nominal)
    win = (centres >= lo) & (centres <= hi)
    plateau = float(np.median(phi[win])) if win.any() else float(phi.max())
    above = np.flatnonzero(phi >= 0.5 * plateau)
    h = float(centres[above[-1]]) if above.size else top
    auto = min(max(0.2 * (h - z_bed), 3.0), 10.0)
    mb = auto if margin_bottom < 0 else margin_bottom
    mt = mb if margin_top < 0 else margin_top
    z1, z2 = z_bed + mb, h - mt
    if not z2 > z1:
        raise ValueError(f"pile too short for a bulk region: z_bed = {z_bed:.3g}, h = {h:.3g}, "
                         f"margins {mb:.3g} and {mt:.3g}")
    bulk = mob & (x[:, 2] >= z1) & (x[:, 2] <= z2)
    pairs, r = find_contacts(x, L_x, L_y)
    n = len(x)
    counts = np.bincount(pairs.ravel(), minlength=n)
    nmin = (4 if mu == 0 else 2) if n_min < 0 else n_min
    kept, counts_nr = remove_rattlers(n, pairs, mob, nmin)
    nb = int(bulk.sum())
    bulk_kept = bulk & kept
    phi_f = float(slab_volume(zm, z1, z2).sum() / (L_x * L_y * (z2 - z1)))
    in_bulk = bulk[pairs[:, 0]] | bulk[pairs[:, 1]]
    overl = 1.0 - r[in_bulk]
    pz = np.bincount(counts[bulk], minlength=13)
    return {
        "z": float(counts[bulk].mean()) if nb else math.nan,
        "z_no_rattlers": float(counts_nr[bulk_kept].mean()) if bulk_kept.any() else math.nan,
        "rattler_fraction": float(1.0 - bulk_kept.sum() / nb) if nb else math.nan,
        "phi": phi_f,
        "n_bulk": nb,
        "z1": z1, "z2": z2, "h": h, "z_bed": z_bed,
        "margin_bottom": mb, "margin_top": mt, "n_min": nmin,
        "phi_plateau": plateau,
        "P_z": (pz / max(nb, 1)).tolist(),
        "overlap_median": float(np.median(overl)) if overl.size else 0.0,
        "overlap_max": float(overl.max()) if overl.size else 0.0,
    }
