"""The near-contact power law g(r) ~ xi^(-alpha), xi = r/d - 1, by maximum likelihood (paper eq. 6;
docs/model.md 6.5).

The gaps of every pair with a reference sphere at one end at least, each
pair once, with xi in a window [a, b] are a sample of the density

    p(xi) = xi^(-alpha) (1 + xi)^2 / Z(alpha),   Z = int_a^b xi^(-alpha) (1 + xi)^2 dxi

(g times the shell area 4 pi r^2). A pair with both ends references is one
gap, not two: counted twice (as g(r) counts it, and as this module did before
2026-11-26) it would make the Fisher error too small by up to sqrt(2). g(r)'s
own normalisation (``prefactor``) counts ordered pairs, ``n_ordered``.
Its log-likelihood depends on the data
only through n and S = sum ln xi, so a run stores (n, S) per window and seeds
pool by adding them. The estimate solves <ln xi>_alpha = S / n; its standard
error is 1 / sqrt(n Var_alpha(ln xi)) (the Fisher information). No bins: a
log-log least-squares fit on bins, where a sparse bin with few or no counts
biases the slope, is what this replaces.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from ..kernels.pairdist import close_pairs, separations

N_MIN = 10              # fewer gaps in a window: no estimate
ALPHA_RANGE = (-10.0, 10.0)
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(96)
SLOPE_PER_DECADE = 10   # centres of the local-slope windows per decade
SLOPE_HALF_WIDTH = 0.25  # half-width of a local-slope window [decades]
SLOPE_RANGE = (1e-5, 1e-1)  # the local-slope windows lie inside this range of xi


def gaps(xm, refs, L_x, L_y, xi_max):
    """xi of every pair with a reference at one end at least and 0 < xi < xi_max, each pair once.

    Parameters
    ----------
    xm : (n, 3) positions of the spheres (partners: all of them) [d]
    refs : (n,) bool, the reference spheres
    xi_max : largest gap [d]

    Returns
    -------
    xi : (K,) float64 gaps, one per pair (the likelihood's sample)
    w : (K,) int64, the pair's references (1 or 2): its count among the ordered (reference,
        partner) pairs, as g(r) counts them
    """
    pairs = close_pairs(xm, L_x, L_y, 1.0 + xi_max)
    d = separations(np.asarray(xm, float), pairs[:, 0], pairs[:, 1], L_x, L_y)
    xi = np.sqrt(np.einsum("ij,ij->i", d, d)) - 1.0
    w = refs[pairs[:, 0]].astype(np.int64) + refs[pairs[:, 1]]
    ok = (xi > 0) & (xi < xi_max) & (w > 0)
    return xi[ok], w[ok]


def _moments(alpha, a, b):
    """Mean and variance of ln xi under p(xi) on [a, b] (Gauss-Legendre in u = ln xi)."""
    ua, ub = math.log(a), math.log(b)
    u = 0.5 * (ub - ua) * _NODES + 0.5 * (ub + ua)
    logw = (1.0 - alpha) * u + 2.0 * np.log1p(np.exp(u))
    w = _WEIGHTS * np.exp(logw - logw.max())
    w /= w.sum()
    m = float(w @ u)
    return m, float(w @ (u - m) ** 2)


def prefactor(st, n_ref, rho):
    """C of g = C xi^(-alpha) that gives a window's gap count: n = n_ref rho 4 pi C Z(alpha)."""
    a, b, al = st["xi_lo"], st["xi_hi"], st["alpha"]
    ua, ub = math.log(a), math.log(b)
    u = 0.5 * (ub - ua) * _NODES + 0.5 * (ub + ua)
    Z = 0.5 * (ub - ua) * float(_WEIGHTS @ np.exp((1.0 - al) * u + 2.0 * np.log1p(np.exp(u))))
    return st.get("n_ordered", st["n"]) / (n_ref * rho * 4.0 * math.pi * Z)


def ml_alpha(n, S, a, b):
    """The maximum-likelihood alpha of n gaps in [a, b] with sum of ln xi S.

    Returns
    -------
    (alpha, alpha_err): nan when n < N_MIN or the mean lies outside what any alpha in ALPHA_RANGE gives
    """
    if n < N_MIN or not (0 < a < b):
        return math.nan, math.nan
    target = S / n

    def f(al):
        return _moments(al, a, b)[0] - target

    lo, hi = ALPHA_RANGE
    if not f(lo) > 0 > f(hi):
        return math.nan, math.nan
    al = brentq(f, lo, hi, xtol=1e-12)
    return float(al), float(1.0 / math.sqrt(n * _moments(al, a, b)[1]))


def power_law_cdf(x, alpha, a, b):
    """The CDF on [a, b] of the gaps' density of the likelihood, xi^(-alpha) (1 + xi)^2 (g(r) ~ xi^-alpha
    on the shell 4 pi r^2 dr, r = 1 + xi)."""
    x = np.asarray(x, float)

    def integral(x):
        # the integral from a to x of xi^-alpha (1 + 2 xi + xi^2), term by term
        total = 0.0
        for c, p in ((1.0, -alpha), (2.0, 1.0 - alpha), (1.0, 2.0 - alpha)):
            q = p + 1.0
            total = total + c * (np.log(x / a) if abs(q) < 1e-12 else (x ** q - a ** q) / q)
        return total
    return integral(x) / integral(b)


def goodness(sel, alpha, a, b):
    """(KS statistic, p) of the gaps ``sel`` in [a, b) against the truncated power law of ``alpha``.

    alpha is fitted to the same gaps, so the p-value (Kolmogorov's, for a law given in advance) is
    too large: a small p rejects the single power law on the window, a large one does not confirm it.
    (nan, nan) without an estimate.
    """
    if not math.isfinite(alpha) or sel.size < N_MIN:
        return math.nan, math.nan
    from scipy.stats import kstest
    r = kstest(sel, lambda x: power_law_cdf(x, alpha, a, b))
    return float(r.statistic), float(r.pvalue)


def window_stats(xi, a, b, w=None):
    """{'xi_lo', 'xi_hi', 'n', 'n_ordered', 'sum_log_xi', 'alpha', 'alpha_err', 'ks', 'ks_p'} of the gaps
    in [a, b): ``n`` gaps (pairs), ``n_ordered`` the ordered pairs they are (``w``, from ``gaps``; n
    without it); ``ks``, ``ks_p`` the goodness of fit of the power law (``goodness``)."""
    inside = (xi >= a) & (xi < b)
    sel = xi[inside]
    n, S = int(sel.size), float(np.log(sel).sum())
    n_ordered = int(w[inside].sum()) if w is not None else n
    al, err = ml_alpha(n, S, a, b)
    ks, p = goodness(sel, al, a, b)
    return {"xi_lo": float(a), "xi_hi": float(b), "n": n, "n_ordered": n_ordered, "sum_log_xi": S, "alpha": al,
            "alpha_err": err, "ks": ks, "ks_p": p}


def windows_of(edges):
    """Windows from edges e0 < e1 < ... < ek: each [e_i, e_i+1], then [e0, ek] (if k > 1)."""
    e = [float(v) for v in edges]
    out = [(e[i], e[i + 1]) for i in range(len(e) - 1)]
    if len(e) > 2:
        out.append((e[0], e[-1]))
    return out


def slope_centres(xi_lo, xi_hi):
    """Centres of the local-slope windows: SLOPE_PER_DECADE per decade, each window inside [xi_lo, xi_hi]."""
    k0 = math.ceil((math.log10(xi_lo) + SLOPE_HALF_WIDTH) * SLOPE_PER_DECADE - 1e-9)
    k1 = math.floor((math.log10(xi_hi) - SLOPE_HALF_WIDTH) * SLOPE_PER_DECADE + 1e-9)
    return [10.0 ** (k / SLOPE_PER_DECADE) for k in range(k0, k1 + 1)]


def local_slope(xi, centres, w=None):
    """alpha on half-decade windows around each centre: the local slope -d ln g / d ln xi as a curve."""
    f = 10.0 ** SLOPE_HALF_WIDTH
    return [dict(window_stats(xi, c / f, c * f, w), xi=float(c)) for c in centres]


def pooled(stats):
    """alpha of several runs' window stats of one window, pooled: n and S add."""
    n = sum(s["n"] for s in stats)
    S = sum(s["sum_log_xi"] for s in stats)
    a, b = stats[0]["xi_lo"], stats[0]["xi_hi"]
    al, err = ml_alpha(n, S, a, b)
    return {"xi_lo": a, "xi_hi": b, "n": n, "n_ordered": sum(s.get("n_ordered", s["n"]) for s in stats),
            "sum_log_xi": S, "alpha": al, "alpha_err": err}


def bootstrap(stats, n_boot=2000, seed=12345):
    """Standard deviation of the pooled alpha over runs resampled with replacement (nan for < 2 runs)."""
    if len(stats) < 2:
        return math.nan
    rng = np.random.default_rng(seed)
    n = np.array([s["n"] for s in stats])
    S = np.array([s["sum_log_xi"] for s in stats])
    a, b = stats[0]["xi_lo"], stats[0]["xi_hi"]
    pick = rng.integers(0, len(stats), (n_boot, len(stats)))
    al = np.array([ml_alpha(int(n[p].sum()), float(S[p].sum()), a, b)[0] for p in pick])
    al = al[np.isfinite(al)]
    return float(al.std(ddof=1)) if al.size > 1 else math.nan
