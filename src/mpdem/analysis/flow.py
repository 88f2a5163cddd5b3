"""Profiles of a flowing layer along the bed's normal (the chute diagnostics of docs/model.md 5.5): the
mean velocity, the granular temperature and the flux of the mobile spheres in bins of height, for a
state with velocities (a snapshot of a flow down ``box.incline`` or in a run's flow phase,
``flow.incline``; or any state: a static pile gives zeros).

The bins are those of the packing-fraction profile (``bulk.Packing.region``: ``edges``), so
phi(z) and v_x(z) share them; x is downslope (the incline tilts gravity about y).
"""
from __future__ import annotations

import math

import numpy as np


def profile(z, v, edges):
    """Per bin of height: spheres, mean velocity and granular temperature.

    Parameters
    ----------
    z : (n,) float
        Heights of the mobile spheres [d].
    v : (n, 3) float
        Their velocities [sqrt(g d)].
    edges : (B + 1,) float
        Bin edges in z [d], increasing.

    Returns
    -------
    dict of (B,) arrays: ``n``, ``v_x``, ``v_y``, ``v_z`` (means [sqrt(g d)], nan in an empty bin)
    and ``T``, the granular temperature <|v - <v>_bin|^2> / 3 [g d] (nan with fewer than 2 spheres).
    """
    z, v = np.asarray(z, float), np.asarray(v, float).reshape(-1, 3)
    b = np.searchsorted(edges, z, side="right") - 1
    inside = (b >= 0) & (b < len(edges) - 1)
    b, vv = b[inside], v[inside]
    nb = len(edges) - 1
    n = np.bincount(b, minlength=nb)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.stack([np.bincount(b, vv[:, a], minlength=nb) / n for a in range(3)], axis=1)
        dev2 = np.sum((vv - mean[b]) ** 2, axis=1)
        T = np.where(n >= 2, np.bincount(b, dev2, minlength=nb) / np.maximum(n, 1) / 3.0, math.nan)
    return {"n": n, "v_x": mean[:, 0], "v_y": mean[:, 1], "v_z": mean[:, 2], "T": T}


def flux(v_x, L_x, L_y):
    """The solid-volume flux downslope per unit width [d sqrt(g d)]: sum of v_x times a sphere's
    volume pi/6, over the cell's area L_x L_y (the integral of phi v_x over the height)."""
    return float(np.sum(v_x) * (math.pi / 6.0) / (L_x * L_y))
