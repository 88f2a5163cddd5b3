"""The paper's fits: eq. 6 (near-contact power law), eq. 7 (stiffness), eq. 9 (initial density).

Each returns its parameters with standard errors. Weighted fits use
sigma as absolute errors (chi^2 reported); without sigma the fit is
unweighted and the errors are scaled by the residuals.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import curve_fit

K_REF = 2e5    # k_n of the paper's softest runs; eq. 7 is fitted in k_n / K_REF


def fit_window(k_n, overlap_median, xi_hi=5e-2, xi_lo=-1.0):
    """The default window of the eq. 6 fit (docs/model.md 6.5): (xi_lo, xi_hi)."""
    if xi_lo < 0:
        xi_lo = max(1e-3 * math.sqrt(K_REF / k_n), 20.0 * overlap_median)
    return float(xi_lo), float(xi_hi)


def power_law(xi, g, xi_lo, xi_hi):
    """Fit log g = c - alpha log xi on the bins inside [xi_lo, xi_hi] (eq. 6).

    Parameters
    ----------
    xi : (nb,) bin centres (geometric) in xi = r/d - 1; g : (nb,) g(r) there
    xi_lo, xi_hi : fit window

    Returns
    -------
    dict: alpha, alpha_err, c (natural log of the prefactor), n_bins used,
    xi_lo, xi_hi; alpha is nan when fewer than 3 bins with g > 0 fall inside.
    """
    xi, g = np.asarray(xi, float), np.asarray(g, float)
    use = (xi >= xi_lo) & (xi <= xi_hi) & (g > 0)
    out = {"alpha": math.nan, "alpha_err": math.nan, "c": math.nan, "n_bins": int(use.sum()),
           "xi_lo": float(xi_lo), "xi_hi": float(xi_hi)}
    if use.sum() < 3:
        return out
    X, Y = np.log(xi[use]), np.log(g[use])
    A = np.stack([np.ones_like(X), -X], axis=1)
    coef, *_ = np.linalg.lstsq(A, Y, rcond=None)
    resid = Y - A @ coef
    dof = max(len(X) - 2, 1)
    cov = np.linalg.inv(A.T @ A) * float(resid @ resid) / dof
    out.update(alpha=float(coef[1]), alpha_err=float(math.sqrt(cov[1, 1])), c=float(coef[0]))
    return out


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
               dof=int(len(x) - len(p)))
    return out, cov


def fit_eq7(k_n, z, sigma=None):
    """Weighted fit of eq. 7 to z(k_n); returns z_inf, a, alpha_n with errors.

    ``a_tilde``, the paper's prefactor of (k_n d / m g)^(-alpha_n), is
    a K_REF^alpha_n; its error is propagated with the covariance of a and
    alpha_n.
    """
    k_n, z = np.asarray(k_n, float), np.asarray(z, float)
    lo = int(np.argmin(k_n))
    z0 = float(z.min()) - 0.01
    p0 = [z0, max(float(z[lo]) - z0, 1e-3), 0.5]
    out, cov = _fit(eq7, k_n, z, sigma, p0, ("z_inf", "a", "alpha_n"))
    out["a_tilde"] = out["a"] * K_REF ** out["alpha_n"]
    # a_tilde = a K^alpha_n: gradient (K^alpha_n, a_tilde ln K) in (a, alpha_n), with their covariance
    grad = np.array([K_REF ** out["alpha_n"], out["a_tilde"] * math.log(K_REF)])
    out["a_tilde_err"] = float(math.sqrt(max(grad @ cov[1:, 1:] @ grad, 0.0))) if np.all(np.isfinite(cov)) else math.nan
    return out


def fit_eq9(phi_i, phi_f, sigma=None):
    """Weighted fit of eq. 9 to phi_f(phi_i); returns A, B, C with errors."""
    phi_i, phi_f = np.asarray(phi_i, float), np.asarray(phi_f, float)
    p0 = [float(phi_f.min()) - 0.01, float(phi_f.max() - phi_f.min()) + 0.01, 4.0]
    return _fit(eq9, phi_i, phi_f, sigma, p0, ("A", "B", "C"))[0]
