"""Profiles of a flowing layer along the bed's normal (the chute diagnostics of docs/model.md 5.5): the
mean velocity, the granular temperature and the flux of the mobile spheres in bins of height, for a
state with velocities (a snapshot of a flow down ``box.incline`` or in a run's flow phase,
``flow.incline``; or any state: a static pile gives zeros).

The bins are those of the packing-fraction profile (``bulk.Packing.region``: ``edges``), so
phi(z) and v_x(z) share them; x is downslope (the incline tilts gravity about y).
"""
from __future__ import annotations

import csv
import math
import os

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


def steady(t, y, window, tolerance=0.02):
    """Whether a flow's time series is flat over its last ``window``: the steady-state test of the
    flow-arrest recipe (docs/model.md 5.5: flux and kinetic energy flat over some 100 tau).

    The last ``window`` of the series is cut in two halves; the flow counts as steady when their means
    differ by less than ``tolerance`` of the window's mean magnitude. The standard error of that change
    (the halves' scatter over the square root of their sample counts; the samples are correlated, so it
    is a lower bound) is reported beside it, to tell a drift from the flow's own fluctuation. A series
    shorter than the window is not judged.

    Parameters
    ----------
    t, y : (n,) float
        Sample times [tau] (increasing) and values (e.g. thermo.csv's v_x or ek).
    window : float
        The span judged [tau].
    tolerance : float
        The largest relative change of the mean between the halves.

    Returns
    -------
    dict: ``steady`` (True, False, or None when the series is shorter than ``window``), ``first`` and
    ``second`` (the halves' means), ``change`` (second - first over the window's mean magnitude),
    ``sigma`` (the standard error of that change, relative too), ``window`` and ``n`` (samples used).
    """
    t, y = np.asarray(t, float), np.asarray(y, float)
    out = {"steady": None, "first": math.nan, "second": math.nan, "change": math.nan, "sigma": math.nan,
           "window": float(window), "n": 0}
    if len(t) < 4 or t[-1] - t[0] < window:
        return out
    keep = t >= t[-1] - window
    tt, yy = t[keep], y[keep]
    half = tt < tt[0] + 0.5 * (tt[-1] - tt[0])
    a, b = yy[half], yy[~half]
    if len(a) < 2 or len(b) < 2:
        return out
    scale = max(abs(float(np.mean(yy))), 1e-300)
    change = (float(np.mean(b)) - float(np.mean(a))) / scale
    sigma = math.sqrt(np.var(a, ddof=1) / len(a) + np.var(b, ddof=1) / len(b)) / scale
    out.update(first=float(np.mean(a)), second=float(np.mean(b)), change=change, sigma=sigma, n=int(keep.sum()),
               steady=bool(abs(change) < tolerance))
    return out


def steadiness(run_dir, cfg):
    """The steady-state test (``steady``) of a flow-arrest run's flow phase, from its thermo.csv: the mean
    v_x and E_k over the last ``analysis.steady_window`` before the switch (``flow.time``).

    Returns
    -------
    dict or None: None without a flow phase or a thermo table; else ``until`` (the switch [tau]) and
    ``v_x``, ``ek`` (each ``steady``'s dict; v_x absent from a table begun before its column), and
    ``steady``: both steady (None where either is not judged).
    """
    path = os.path.join(run_dir, "thermo.csv")
    if cfg.flow.incline <= 0 or not os.path.exists(path):
        return None
    with open(path) as fh:
        rows = list(csv.DictReader(fh))
    until = cfg.flow.time
    rows = [r for r in rows if float(r["time"]) <= until]
    t = np.array([float(r["time"]) for r in rows])
    a = cfg.analysis
    out = {"until": until, "window": a.steady_window, "tolerance": a.steady_tolerance}
    for col in ("v_x", "ek"):
        if rows and col in rows[0]:
            out[col] = steady(t, [float(r[col]) for r in rows], a.steady_window, a.steady_tolerance)
    verdicts = [out[c]["steady"] for c in ("v_x", "ek") if c in out]
    out["steady"] = None if not verdicts or None in verdicts else all(verdicts)
    return out


def bagnold(z, v_x, n, z_bed, h, exponents=np.arange(1.0, 2.501, 0.01)):
    """The Bagnold profile of a steady chute flow (docs/model.md 5.5; Silbert et al. 2001) fitted to
    binned mean velocities: v_x(y) = A (H^(3/2) - (H - y)^(3/2)), y = z - z_bed the height above the bed
    and H = h - z_bed the layer's; A by least squares weighted by the spheres of each bin, and the
    exponent let free as well (scanned over ``exponents``: 3/2 is Bagnold's).

    Parameters
    ----------
    z, v_x, n : (B,) float
        Bin centres [d], the bins' mean v_x [sqrt(g d)] (nan in empty bins) and sphere counts.
    z_bed, h : float
        The bed's top and the surface [d].

    Returns
    -------
    dict: ``A`` and ``rms`` (the weighted rms residual over the weighted rms of v_x) at exponent 3/2,
    ``exponent`` (the best), ``A_free`` and ``rms_free`` there, and ``bins`` used; None with fewer
    than 3 usable bins or no flow.
    """
    z, v, w = (np.asarray(a, float) for a in (z, v_x, n))
    H = h - z_bed
    y = z - z_bed
    use = np.isfinite(v) & (w > 0) & (y > 0) & (y < H)
    if use.sum() < 3 or H <= 0:
        return None
    y, v, w = y[use], v[use], w[use]
    scale = math.sqrt(np.sum(w * v * v) / np.sum(w))
    if scale == 0.0:
        return None

    def fit(p):
        f = H ** p - (H - y) ** p
        A = float(np.sum(w * f * v) / np.sum(w * f * f))
        return A, math.sqrt(np.sum(w * (v - A * f) ** 2) / np.sum(w)) / scale

    A, rms = fit(1.5)
    best = min(exponents, key=lambda p: fit(p)[1])
    A_free, rms_free = fit(best)
    return {"A": A, "rms": rms, "exponent": float(best), "A_free": A_free, "rms_free": rms_free,
            "bins": int(use.sum())}
