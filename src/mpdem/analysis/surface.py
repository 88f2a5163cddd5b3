"""The free surface of a pile: its height field, roughness and local slopes (docs/model.md 6.10).

The box is split into square-ish cells of about ``cell`` d along x and y; a cell's surface height is
the top of its highest mobile sphere (centre + 1/2). In a box periodic in x and y the mean surface
is parallel to the bed (the heights at x = 0 and x = L_x are one), so its tilt to gravity is the
pile's own ``box.incline``; what is left to measure is how rough it is: the rms of the cell heights
about their mean, and the rms slope along x (downslope) and y, from differences of neighbouring
cells across the periodic seams.
"""
from __future__ import annotations

import math

import numpy as np


def heights(x, L_x, L_y, cell):
    """(n_x, n_y) surface height of each cell [d]: the highest centre in it + 1/2; nan if empty.

    Parameters
    ----------
    x : (n, 3) float positions of the mobile spheres [d]
    L_x, L_y : float box [d]
    cell : float wanted cell side [d]; the cells are L / round(L / cell) wide (at least 1 per axis)
    """
    x = np.asarray(x, float)
    nx, ny = max(1, round(L_x / cell)), max(1, round(L_y / cell))
    ix = np.minimum((np.mod(x[:, 0], L_x) * (nx / L_x)).astype(np.int64), nx - 1)
    iy = np.minimum((np.mod(x[:, 1], L_y) * (ny / L_y)).astype(np.int64), ny - 1)
    top = np.full(nx * ny, -np.inf)
    np.maximum.at(top, ix * ny + iy, x[:, 2])
    top = np.where(np.isfinite(top), top + 0.5, math.nan)
    return top.reshape(nx, ny)


def roughness(h, L_x, L_y):
    """The roughness of a height field ``h`` (n_x, n_y) on the periodic L_x x L_y box.

    Returns
    -------
    dict: h_mean, h_rms [d]; slope_x_rms, slope_y_rms [degrees] (atan of the rms difference quotient of
    neighbouring cells along x and along y, periodic; nan with one cell along the axis); cells, empty
    """
    h = np.asarray(h, float)
    nx, ny = h.shape
    ok = np.isfinite(h)
    out = {"cells": int(h.size), "empty": int(h.size - ok.sum())}
    if not ok.any():
        return dict(out, h_mean=math.nan, h_rms=math.nan, slope_x_rms=math.nan, slope_y_rms=math.nan)
    out["h_mean"] = float(h[ok].mean())
    out["h_rms"] = float(h[ok].std())
    for axis, n, L, name in ((0, nx, L_x, "slope_x_rms"), (1, ny, L_y, "slope_y_rms")):
        if n < 2:
            out[name] = math.nan
            continue
        g = (np.roll(h, -1, axis=axis) - h) / (L / n)
        g = g[np.isfinite(g)]
        out[name] = math.degrees(math.atan(math.sqrt(np.mean(g * g)))) if len(g) else math.nan
    return out
