"""Depth profiles and the normal-force distribution P(f) (docs/model.md 6.6, 6.10).

A pile under gravity carries a load that grows with depth, so one pile spans
a decade of pressure and overlap. The profile cuts it into bands of
``width`` below the free surface h (band 0 is [h - width, h]) down to the bed,
and gives per band: spheres, z over all of them and over the backbone, the
rattler fraction, phi, the mean and median overlap and the mean normal force
of the contacts whose midpoint lies in the band, sigma_zz from the contact
forces, and the crystal-like fraction.

sigma_zz of a band is sum over its contacts of b_z F_z / (L_x L_y width),
b = x_i - x_j the branch vector and F the force on i from j: the contact part
of the stress (spheres at rest carry no kinetic part). At depth D it is close
to the weight above, rho_p g int phi dz (rho_p = 6 / pi).
"""
from __future__ import annotations

import math

import numpy as np

from .bulk import slab_volume
from .contacts import band_index, n_bands

F_BIN = 0.1      # bin width of P(f), f = F_n / band mean
F_MAX = 8.0      # P(f) runs over [0, F_MAX); beyond counts as the tail
TAIL_FROM = 1.0  # the large-f tail: exponential decay rate of f beyond this (maximum likelihood)
SMALL_F = 0.1    # the small-f weight: fraction of contacts with f below this


def depth_profile(pk, cf, backbone_kept, backbone_counts, crystal, h, width, z1, z2):
    """Per-band table of a pile.

    Parameters
    ----------
    pk : Packing; cf : ContactForces of its contacts
    backbone_kept : (n,) bool; backbone_counts : (n,) int backbone contacts per sphere
    crystal : (n,) bool crystal-like spheres (or None)
    h : free surface [d]; width : band width [d]; z1, z2 : the bulk slab [d]

    Returns
    -------
    dict of (B,) lists: depth_lo, depth_hi, z_lo, z_hi, in_bulk (the band lies
    inside [z1, z2]), n_particles, z, z_backbone, rattler_fraction, phi,
    overlap_mean, overlap_median, F_n_mean, sigma_zz, crystal_fraction, n_contacts
    """
    B = n_bands(h, pk.z_bed, width)
    z_lo = h - width * (np.arange(B) + 1)
    z_hi = h - width * np.arange(B)
    zc = pk.x[:, 2]
    mob = pk.mobile & (zc <= h) & (zc >= h - width * B)
    band = band_index(zc, h, width, B)

    def cnt(w=None, sel=mob):
        return np.bincount(band[sel], weights=None if w is None else w[sel], minlength=B)

    n = cnt()
    kept = mob & backbone_kept
    nk = cnt(sel=kept)
    i, j = pk.pairs[:, 0], pk.pairs[:, 1]
    mid = 0.5 * (zc[i] + zc[j])
    cb = band_index(mid, h, width, B)
    inside = (mid <= h) & (mid >= h - width * B)
    nc = np.bincount(cb[inside], minlength=B)
    dsum = np.bincount(cb[inside], weights=cf.delta[inside], minlength=B)
    fsum = np.bincount(cb[inside], weights=cf.F_n[inside], minlength=B)
    szz = np.bincount(cb[inside], weights=(cf.branch[:, 2] * cf.force[:, 2])[inside], minlength=B)
    med = np.array([np.median(cf.delta[inside & (cb == k)]) if nc[k] else np.nan for k in range(B)])
    vol = np.array([slab_volume(zc[pk.mobile], z_lo[k], z_hi[k]).sum() for k in range(B)])
    area = pk.L_x * pk.L_y
    with np.errstate(invalid="ignore", divide="ignore"):
        out = {
            "depth_lo": h - z_hi, "depth_hi": h - z_lo, "z_lo": z_lo, "z_hi": z_hi,
            "in_bulk": (z_lo >= z1) & (z_hi <= z2), "n_particles": n,
            "z": cnt(pk.counts.astype(float)) / n,
            "z_backbone": cnt(backbone_counts.astype(float), kept) / nk,
            "rattler_fraction": 1.0 - nk / n,
            "phi": vol / (area * width),
            "overlap_mean": dsum / nc, "overlap_median": med, "F_n_mean": fsum / nc,
            "sigma_zz": szz / (area * width),
            "crystal_fraction": (cnt(sel=mob & crystal) / n) if crystal is not None else np.full(B, np.nan),
            "n_contacts": nc,
        }
    return {k: np.asarray(v).tolist() for k, v in out.items()}


def force_distribution(f):
    """P(f) of normal forces already divided by their local mean.

    Parameters
    ----------
    f : (K,) F_n / <F_n>_band of the bulk contacts (compressive ones)

    Returns
    -------
    dict: ``counts`` on bins of F_BIN over [0, F_MAX) (and ``n_beyond``), ``n``,
    ``small_f_fraction`` (f < SMALL_F), ``tail_rate`` beta of P ~ exp(-beta f)
    for f > TAIL_FROM (maximum likelihood: 1 / mean(f - TAIL_FROM)) with its
    error beta / sqrt(n_tail), and the sums that pool across runs.
    """
    f = np.asarray(f, float)
    nb = int(round(F_MAX / F_BIN))
    idx = np.floor(f / F_BIN).astype(np.int64)
    counts = np.bincount(idx[(idx >= 0) & (idx < nb)], minlength=nb)
    tail = f[f > TAIL_FROM] - TAIL_FROM
    out = {"n": int(f.size), "counts": counts.tolist(), "n_beyond": int((idx >= nb).sum()),
           "n_small": int((f < SMALL_F).sum()), "n_tail": int(tail.size), "tail_sum": float(tail.sum())}
    return dict(out, **tail_and_small(out))


def tail_and_small(d):
    """small_f_fraction, tail_rate and tail_rate_err from pooled sums (``force_distribution`` keys)."""
    beta = d["n_tail"] / d["tail_sum"] if d["tail_sum"] > 0 else math.nan
    return {"small_f_fraction": d["n_small"] / d["n"] if d["n"] else math.nan,
            "tail_rate": beta, "tail_rate_err": beta / math.sqrt(d["n_tail"]) if d["n_tail"] else math.nan}


def density(counts, n):
    """P(f) as a density on the F_BIN bins: counts / (n F_BIN)."""
    return (np.asarray(counts, float) / (max(n, 1) * F_BIN)).tolist()
