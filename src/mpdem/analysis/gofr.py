"""g(r) of the bulk slab, normalised without edge corrections (docs/model.md 6.4).

Reference spheres are the mobile ones whose centres lie at least r_max inside
the bulk slab [z1, z2], so every shell up to r_max is complete; partners are
all mobile spheres, minimum image in x and y; rho is the number density of
mobile centres in the slab.
"""
from __future__ import annotations

import math

import numpy as np

from ..kernels.bundles import make_box
from ..kernels.pairdist import cell_grid, pair_histograms, wrap


def _shell(ra, rb):
    return 4.0 * math.pi / 3.0 * (rb ** 3 - ra ** 3)


def radial_distribution(xm, L_x, L_y, z1, z2, r_max, dr=0.01, xi_min=1e-6, per_decade=10):
    """g(r) on linear bins in r and on logarithmic bins in xi = r/d - 1.

    Parameters
    ----------
    xm : (n, 3) positions of the mobile spheres [d]
    L_x, L_y : box [d]; z1, z2 : bulk slab [d]
    r_max : range [d], below L/2; dr : linear bin width [d]
    xi_min, per_decade : logarithmic bins from xi_min to 1

    Returns
    -------
    dict with
      ``r_lo, r_hi, count, g`` (n_lin,) linear bins [d], ordered pair counts, g;
      ``xi_lo, xi_hi, count_xi, g_xi`` (n_log,) logarithmic bins in xi
      (g_xi is nan in bins reaching beyond r_max);
      ``n_ref`` reference spheres, ``rho`` [1/d^3], ``r_max``,
      ``n_overlap`` ordered pairs with r < d (contacts, outside the xi bins).
    """
    if not r_max < 0.5 * min(L_x, L_y):
        raise ValueError(f"g(r) range r_max = {r_max:g} d must be below half the box ({0.5 * min(L_x, L_y):g} d)")
    xm = wrap(xm, L_x, L_y)
    z = xm[:, 2]
    rho = float(((z >= z1) & (z <= z2)).sum()) / (L_x * L_y * (z2 - z1))
    refs = np.flatnonzero((z >= z1 + r_max) & (z <= z2 - r_max)).astype(np.int64)
    n_lin = int(round(r_max / dr))
    n_log = int(round(-math.log10(xi_min) * per_decade))
    if refs.size == 0:
        raise ValueError(f"no reference spheres: the bulk slab [{z1:.3g}, {z2:.3g}] is thinner than "
                         f"2 r_max = {2 * r_max:g} d")
    grid = cell_grid(xm, L_x, L_y, r_max)
    lin, lg, n_over = pair_histograms(xm, refs, make_box(L_x, L_y), r_max, dr, n_lin, xi_min,
                                      float(per_decade), n_log, grid)
    r_lo, r_hi = dr * np.arange(n_lin), dr * np.arange(1, n_lin + 1)
    xi_lo = xi_min * 10.0 ** (np.arange(n_log) / per_decade)
    xi_hi = xi_min * 10.0 ** (np.arange(1, n_log + 1) / per_decade)
    norm = refs.size * rho
    g = lin / (norm * _shell(r_lo, r_hi))
    g_xi = lg / (norm * _shell(1.0 + xi_lo, 1.0 + xi_hi))
    # bins reaching past r_max were not (fully) counted: unknown, not zero
    g_xi[1.0 + xi_hi > r_max] = np.nan
    return {"r_lo": r_lo, "r_hi": r_hi, "count": lin, "g": g,
            "xi_lo": xi_lo, "xi_hi": xi_hi, "count_xi": lg, "g_xi": g_xi,
            "n_ref": int(refs.size), "rho": rho, "r_max": float(r_max), "n_overlap": int(n_over)}
