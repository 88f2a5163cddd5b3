"""The paper's fits: eq. 7 (stiffness), eq. 9 (initial density), the default window of eq. 6
(its estimate: ``nearcontact``), and z against the overlap (docs/model.md 6.6).

Each returns its parameters with standard errors. Weighted fits use
sigma as absolute errors (chi^2 reported); without sigma the fit is
unweighted and the errors are scaled by the residuals.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import curve_fit
from scipy.stats import chi2 as chi2_dist
from scipy.stats import f as f_dist

K_REF = 2e5    # k_n of the paper's softest runs; eq. 7 is fitted in k_n / K_REF


def fit_window(xi_hi=5e-2, xi_lo=1e-3):
    """The default window of the eq. 6 estimate (docs/model.md 6.5): (xi_lo, xi_hi), the same for
    every k_n and mu. ``xi_lo`` -1 (older configs, where it followed k_n) is 1e-3."""
    return (1e-3 if xi_lo < 0 else float(xi_lo)), float(xi_hi)


def eq7(k_n, z_inf, a, alpha_n):
    """z(k_n) = z_inf + a (k_n / K_REF)^(-alpha_n) (paper eq. 7, k_n in m g / d)."""
    return z_inf + a * (np.asarray(k_n, float) / K_REF) ** (-alpha_n)


def eq9(phi_i, A, B, C):
    """phi_f(phi_i) = A + B exp(-C phi_i) (paper eq. 9)."""
    return A + B * np.exp(-C * np.asarray(phi_i, float))


def _fit(model, x, y, sigma, p0, names):
    x, y = np.asarray(x, float), np.asarray(y, float)
    if len(x) < len(p0):
        raise ValueError(f"{len(x)} points cannot fix {len(p0)} parameters ({', '.join(names)})")
    weighted = sigma is not None and np.all(np.asarray(sigma, float) > 0)
    s = np.asarray(sigma, float) if weighted else None
    p, cov = curve_fit(model, x, y, p0=p0, sigma=s, absolute_sigma=weighted, maxfev=20000)
    err = np.sqrt(np.diag(cov)) if np.all(np.isfinite(cov)) else np.full(len(p), math.nan)
    res = (y - model(x, *p)) / (s if weighted else 1.0)
    out = {n: float(v) for n, v in zip(names, p)}
    out.update({f"{n}_err": float(e) for n, e in zip(names, err)})
    out.update(n_points=int(len(x)), weighted=bool(weighted), chi2=float(res @ res),
               dof=int(len(x) - len(p)), correlation=_largest_correlation(cov))
    # parameters the points cannot tell apart (a correlation of +-1 to 9 digits): no values to report
    out["determined"] = bool(np.all(np.isfinite(err)) and out["correlation"] < 1.0 - 1e-9)
    out["p_value"] = p_value(out["chi2"], out["dof"]) if weighted else math.nan
    return out, cov


def _largest_correlation(cov):
    """The largest |correlation| between two parameters of a fit's covariance (nan if not finite)."""
    cov = np.asarray(cov, float)
    if not np.all(np.isfinite(cov)) or np.any(np.diag(cov) <= 0):
        return math.nan
    sd = np.sqrt(np.diag(cov))
    rho = np.abs(cov / np.outer(sd, sd))
    np.fill_diagonal(rho, 0.0)
    return float(rho.max()) if rho.size > 1 else 0.0


def p_value(chi2, dof):
    """Probability of a chi^2 at least this large with ``dof`` degrees of freedom (nan for dof < 1)."""
    return float(chi2_dist.sf(chi2, dof)) if dof >= 1 else math.nan


def pooled_scatter(groups):
    """The seed-to-seed standard deviation pooled over groups (sets) of one family.

    Parameters
    ----------
    groups : list of sequences of values (one per set; a set with one value adds nothing)

    Returns
    -------
    (s, dof): s = sqrt(sum over sets of sum (x - mean)^2 / sum (n - 1)); nan with no dof.
    A set's standard error is then s / sqrt(n): two seeds give a poor error of
    their own, and the scatter of one N is the same at every k_n.
    """
    ss, dof = 0.0, 0
    for g in groups:
        v = np.asarray([x for x in g if x is not None and math.isfinite(x)], float)
        if v.size >= 2:
            ss += float(((v - v.mean()) ** 2).sum())
            dof += v.size - 1
    return (math.sqrt(ss / dof) if dof else math.nan), dof


def one_way_anova(groups):
    """One-way analysis of variance of the values in ``groups``.

    Parameters
    ----------
    groups : list of sequences of floats, one per set (a set may hold one value)

    Returns
    -------
    dict: ``F``, ``dof`` [S - 1, n - S], ``p`` (the F distribution's upper tail), ``scatter``
    (the pooled within-set standard deviation); F and p nan where n - S < 1 or the scatter is 0.
    """
    g = [np.asarray(v, float) for v in groups if len(v)]
    n, S = sum(len(v) for v in g), len(g)
    allv = np.concatenate(g) if g else np.zeros(0)
    within = sum(float(((v - v.mean()) ** 2).sum()) for v in g)
    between = sum(len(v) * float((v.mean() - allv.mean()) ** 2) for v in g)
    d1, d2 = S - 1, n - S
    res = {"F": math.nan, "dof": [d1, d2], "p": math.nan,
           "scatter": math.sqrt(within / d2) if d2 > 0 else math.nan}
    if d1 >= 1 and d2 >= 1 and within > 0:
        F = (between / d1) / (within / d2)
        res.update(F=F, p=float(f_dist.sf(F, d1, d2)))
    return res


def two_way_anova(table):
    """Two-way analysis of variance without replication: does the column (a seed, say) shift every row
    (a set) alike?

    Parameters
    ----------
    table : (a, b) array of floats, a >= 2 rows (blocks) by b >= 2 columns (treatments), complete

    Returns
    -------
    dict: ``F``, ``dof`` [b - 1, (a - 1)(b - 1)], ``p`` (the F distribution's upper tail) for the columns'
    effect against the rows-by-columns residual, which holds any interaction; ``effects`` (b,): the
    columns' means less the grand mean; ``scatter``: the residual's standard deviation. F and p nan
    when the residual is 0.
    """
    Y = np.asarray(table, float)
    a, b = Y.shape
    if a < 2 or b < 2 or not np.all(np.isfinite(Y)):
        raise ValueError(f"a complete table of >= 2 x 2 finite values is needed, not {a} x {b}")
    grand = Y.mean()
    rows, cols = Y.mean(axis=1, keepdims=True), Y.mean(axis=0, keepdims=True)
    resid = float(((Y - rows - cols + grand) ** 2).sum())
    between = a * float(((cols - grand) ** 2).sum())
    d1, d2 = b - 1, (a - 1) * (b - 1)
    res = {"F": math.nan, "dof": [d1, d2], "p": math.nan, "effects": (cols[0] - grand).tolist(),
           "scatter": math.sqrt(resid / d2)}
    if resid > 0:
        F = (between / d1) / (resid / d2)
        res.update(F=F, p=float(f_dist.sf(F, d1, d2)))
    return res


def fit_eq7_fixed(k_n, z, sigma, alpha_n=0.5):
    """Eq. 7 with the exponent fixed: z = z_inf + a (k_n / K_REF)^(-alpha_n), linear in (z_inf, a).

    Returns
    -------
    dict: z_inf, a, a_tilde and errors, alpha_n (fixed), chi2, dof, p_value, n_points.
    """
    k_n, z, s = np.asarray(k_n, float), np.asarray(z, float), np.asarray(sigma, float)
    if len(k_n) < 3:
        raise ValueError(f"{len(k_n)} points: a fixed-exponent fit of 2 parameters needs 3 for a chi^2")
    X = np.stack([np.ones_like(k_n), (k_n / K_REF) ** (-alpha_n)], axis=1) / s[:, None]
    coef, *_ = np.linalg.lstsq(X, z / s, rcond=None)
    cov = np.linalg.inv(X.T @ X)
    res = z / s - X @ coef
    chi2 = float(res @ res)
    dof = len(k_n) - 2
    a_tilde = float(coef[1]) * K_REF ** alpha_n
    return {"z_inf": float(coef[0]), "z_inf_err": float(math.sqrt(cov[0, 0])), "a": float(coef[1]),
            "a_err": float(math.sqrt(cov[1, 1])), "a_tilde": a_tilde,
            "a_tilde_err": float(math.sqrt(cov[1, 1])) * K_REF ** alpha_n, "alpha_n": float(alpha_n),
            "alpha_n_fixed": True, "chi2": chi2, "dof": dof, "p_value": p_value(chi2, dof),
            "n_points": int(len(k_n)), "weighted": True}


def pile_covariance(pile, s_total, s_within):
    """The covariance of runs that may be the same pile again (a stiffening ladder's rungs are its base's
    piles, stiffened): a pile keeps its own offset from rung to rung, so two runs of one pile share
    s_b^2 = s_total^2 - s_within^2 of their scatter and each run has s_within^2 of its own.

    Parameters
    ----------
    pile : (n,) the pile of each run (any hashable labels)
    s_total : float, the scatter of one run about the mean of its k_n (independent piles' seed scatter)
    s_within : float, the scatter of one pile's run about its own offset (its noise from rung to rung)

    Returns
    -------
    (n, n) array: s_b^2 [pile_i == pile_j] + s_within^2 [i == j]; where s_within > s_total (a pile's
    noise measured above the piles' scatter) s_b^2 is 0 and each run's variance s_within^2
    """
    lab = {v: i for i, v in enumerate(dict.fromkeys(pile))}
    g = np.array([lab[v] for v in pile])
    s_b2 = max(float(s_total) ** 2 - float(s_within) ** 2, 0.0)
    return s_b2 * (g[:, None] == g[None, :]) + float(s_within) ** 2 * np.eye(len(g))


def fit_eq7_piles(k_n, z, pile, s_total, s_within, alpha_n=None, s_within_dof=None):
    """Eq. 7 over the runs of a stiffening ladder by generalized least squares (``pile_covariance``).

    A ladder's rungs are the same piles again, each keeping its offset from the others (docs/model.md 6.6):
    fitted as independent sets, their points would count each pile's offset again at every rung. Here every
    run is a point, and two runs of one pile covary by its offset's variance: the exponent comes from how
    each pile changes from rung to rung, the level from all the piles.

    Parameters
    ----------
    k_n, z : (n,) each run's stiffness and z
    pile : (n,) each run's pile
    s_total, s_within : ``pile_covariance``'s
    alpha_n : None (free: z_inf, a, alpha_n) or the fixed exponent (z_inf, a)
    s_within_dof : the degrees of freedom s_within was measured from (None: taken as known)

    Returns
    -------
    dict: z_inf, a, alpha_n, a_tilde with errors, chi2 (r^T C^-1 r), dof, ``p_value`` (of chi2 with the
    noise s_within taken as known), ``p_noise`` (of chi2 / dof against F(dof, s_within_dof): the noise is
    itself measured, nan without s_within_dof), n_points, n_piles, s_total, s_within, ``s_b_clamped``
    (s_within above s_total), ``scale``: where chi2 / dof > 1 the errors are widened by sqrt(chi2 / dof)
    (the noise s_within comes from a few degrees of freedom; a chi^2 above them says the fit or the noise
    is off, and the errors never narrow for it), ``determined`` and ``correlation`` as ``fit_eq7``
    """
    k_n, z = np.asarray(k_n, float), np.asarray(z, float)
    C = pile_covariance(list(pile), s_total, s_within)
    L = np.linalg.cholesky(C)
    free = alpha_n is None
    if len(k_n) < (4 if free else 3):
        raise ValueError(f"{len(k_n)} runs cannot fix eq. 7's {3 if free else 2} parameters with a chi^2")
    if free:
        p, cov = curve_fit(eq7, k_n, z, p0=_eq7_start(k_n, z), sigma=C, absolute_sigma=True, maxfev=20000)
        names = ("z_inf", "a", "alpha_n")
    else:
        X = np.stack([np.ones_like(k_n), (k_n / K_REF) ** (-alpha_n)], axis=1)
        Xw, zw = np.linalg.solve(L, X), np.linalg.solve(L, z)
        p = np.linalg.lstsq(Xw, zw, rcond=None)[0]
        cov = np.linalg.inv(Xw.T @ Xw)
        names = ("z_inf", "a")
    model = eq7(k_n, *p) if free else eq7(k_n, p[0], p[1], alpha_n)
    w = np.linalg.solve(L, z - model)
    chi2, dof = float(w @ w), int(len(z) - len(p))
    scale = math.sqrt(chi2 / dof) if dof >= 1 and chi2 > dof else 1.0
    err = np.sqrt(np.diag(cov)) * scale if np.all(np.isfinite(cov)) else np.full(len(p), math.nan)
    out = {n: float(v) for n, v in zip(names, p)}
    out.update({f"{n}_err": float(e) for n, e in zip(names, err)})
    if not free:
        out.update(alpha_n=float(alpha_n), alpha_n_fixed=True)
    if free:
        _a_tilde(out, cov, scale)
    else:
        out["a_tilde"] = out["a"] * K_REF ** out["alpha_n"]
        out["a_tilde_err"] = out["a_err"] * K_REF ** out["alpha_n"]
    p_noise = (float(f_dist.sf(chi2 / dof, dof, s_within_dof)) if s_within_dof and dof >= 1 else math.nan)
    out.update(chi2=chi2, dof=dof, p_value=p_value(chi2, dof), p_noise=p_noise, scale=scale,
               n_points=int(len(z)), n_piles=int(len(set(pile))), s_total=float(s_total), s_within=float(s_within),
               s_b_clamped=bool(s_within > s_total), weighted=True, covariance="piles",
               correlation=_largest_correlation(cov))
    out["determined"] = bool(np.all(np.isfinite(err)) and out["correlation"] < 1.0 - 1e-9)
    return out


def fit_overlap(delta, z, group, n_boot=2000, seed=12345, exponent=0.5, level=None, sample=None):
    """z - z_c = A (delta / d)^exponent over depth bands of many runs (docs/model.md 6.6).

    Parameters
    ----------
    delta : (K,) mean overlap of each band [d]; z : (K,) its z
    group : (K,) the run each band comes from
    exponent : 1/2 for Hookean contacts
    level : (K,) or None
        The k_n of each band's run: with two levels or more, whether the bands of all
        levels collapse on the one curve (``collapse``).
    sample : (K,) or None
        The independent sample each band's run belongs to (a pile: a ladder's rungs are its
        piles again); the bootstrap resamples these, each with every band of its runs.
        None: each run is a sample of its own.

    Returns
    -------
    dict: z_c, A (least squares, every band weighted alike), z_c_err and A_err
    (standard deviations over samples resampled with replacement), n_bands, n_runs,
    n_samples, rms (residual), delta_min, delta_max, and with ``level`` the ``collapse`` test
    """
    delta, z, group = np.asarray(delta, float), np.asarray(z, float), np.asarray(group)
    sample = group if sample is None else np.asarray(sample)
    if sample.shape != group.shape:
        raise ValueError(f"sample has shape {sample.shape}, the bands {group.shape}: one sample per band")
    ok = np.isfinite(delta) & np.isfinite(z) & (delta > 0)
    delta, z, group, sample = delta[ok], z[ok], group[ok], sample[ok]
    level = None if level is None else np.asarray(level, float)[ok]
    runs, units = np.unique(group), np.unique(sample)
    if len(z) < 3:
        raise ValueError(f"{len(z)} bands: the overlap fit needs at least 3")
    xs = delta ** exponent

    c = np.linalg.lstsq(np.stack([np.ones(len(z)), xs], axis=1), z, rcond=None)[0]
    out = {"z_c": float(c[0]), "A": float(c[1]), "exponent": exponent, "n_bands": int(len(z)),
           "n_runs": int(len(runs)), "n_samples": int(len(units)),
           "rms": float(np.sqrt(np.mean((z - c[0] - c[1] * xs) ** 2))),
           "delta_min": float(delta.min()), "delta_max": float(delta.max()),
           "z_c_err": math.nan, "A_err": math.nan}
    if len(units) >= 2:
        rng = np.random.default_rng(seed)
        members = [np.flatnonzero(sample == u) for u in units]
        boot = []
        for pick in rng.integers(0, len(units), (n_boot, len(units))):
            idx = np.concatenate([members[p] for p in pick])
            if np.unique(xs[idx]).size < 2:
                continue
            X = np.stack([np.ones(len(idx)), xs[idx]], axis=1)
            boot.append(np.linalg.lstsq(X, z[idx], rcond=None)[0])
        if len(boot) > 1:
            b = np.array(boot)
            out["z_c_err"], out["A_err"] = float(b[:, 0].std(ddof=1)), float(b[:, 1].std(ddof=1))
    if level is not None:
        out["collapse"] = collapse(xs, z, level)
    return out


def collapse(xs, z, level):
    """Whether bands at several levels (k_n) lie on one line z = z_c + A xs: the F test of the one
    line against a line of the same slope with an offset of its own for each level (nested least
    squares; the residual scatter is estimated from the data, the bands taken as independent).

    Returns
    -------
    dict: levels, F, dof (numerator, denominator), p (of F this large with one line), and each
    level's mean residual from the one line with its standard error (``residual``,
    ``residual_err``; the units of z), or status "not tested" with why
    """
    levels = np.unique(level)
    g, n = len(levels), len(z)
    if g < 2 or n - g - 1 < 1:
        return {"status": "not tested", "reason": f"{g} levels and {n} bands (needs 2 levels and {g + 2} bands)",
                "levels": levels.tolist()}
    one = np.stack([np.ones(n), xs], axis=1)
    each = np.concatenate([xs[:, None]] + [(level == v).astype(float)[:, None] for v in levels], axis=1)
    res = z - one @ np.linalg.lstsq(one, z, rcond=None)[0]
    rss_one = float(np.sum(res ** 2))
    rss_each = float(np.sum((z - each @ np.linalg.lstsq(each, z, rcond=None)[0]) ** 2))
    d1, d2 = g - 1, n - g - 1
    F = ((rss_one - rss_each) / d1) / (rss_each / d2) if rss_each > 0 else math.inf
    mean = [float(res[level == v].mean()) for v in levels]
    err = [float(res[level == v].std(ddof=1) / math.sqrt((level == v).sum())) if (level == v).sum() > 1 else math.nan
           for v in levels]
    return {"status": "tested", "levels": levels.tolist(), "F": float(F), "dof": [d1, d2],
            "p": float(f_dist.sf(F, d1, d2)), "residual": mean, "residual_err": err}


def fit_eq7(k_n, z, sigma=None):
    """Weighted fit of eq. 7 to z(k_n); returns z_inf, a, alpha_n with errors.

    ``a_tilde``, the paper's prefactor of (k_n d / m g)^(-alpha_n), is
    a K_REF^alpha_n; its error is propagated with the covariance of a and
    alpha_n.
    """
    k_n, z = np.asarray(k_n, float), np.asarray(z, float)
    out, cov = _fit(eq7, k_n, z, sigma, _eq7_start(k_n, z), ("z_inf", "a", "alpha_n"))
    _a_tilde(out, cov)
    return out


def _eq7_start(k_n, z):
    """The free eq. 7 fit's starting point (z_inf, a, alpha_n): z_inf just below the lowest z."""
    lo = int(np.argmin(k_n))
    z0 = float(np.min(z)) - 0.01
    return [z0, max(float(z[lo]) - z0, 1e-3), 0.5]


def _a_tilde(out, cov, scale=1.0):
    """The paper's prefactor a_tilde = a K_REF^alpha_n into ``out``, its error from the covariance of (a,
    alpha_n) (gradient (K^alpha_n, a_tilde ln K)) times ``scale``; nan where the covariance is not finite."""
    out["a_tilde"] = out["a"] * K_REF ** out["alpha_n"]
    cov = np.asarray(cov, float)
    if not np.all(np.isfinite(cov)):
        out["a_tilde_err"] = math.nan
        return
    grad = np.array([K_REF ** out["alpha_n"], out["a_tilde"] * math.log(K_REF)])
    out["a_tilde_err"] = float(math.sqrt(max(grad @ cov[1:, 1:] @ grad, 0.0))) * scale


def fit_eq9(phi_i, phi_f, sigma=None):
    """Weighted fit of eq. 9 to phi_f(phi_i); returns A, B, C with errors."""
    phi_i, phi_f = np.asarray(phi_i, float), np.asarray(phi_f, float)
    p0 = [float(phi_f.min()) - 0.01, float(phi_f.max() - phi_f.min()) + 0.01, 4.0]
    return _fit(eq9, phi_i, phi_f, sigma, p0, ("A", "B", "C"))[0]
