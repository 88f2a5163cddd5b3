"""Errors of one pile from its own lateral columns: the delete-one-group jackknife (docs/model.md 6.10).

A pile's numbers (z, z without rattlers, phi) are ratios of sums over its spheres. Neighbouring
spheres are correlated, so the error of such a ratio is not its spheres' scatter over sqrt(n).
The box is split into k x k lateral columns, each a group of whole spheres (by centre); the
jackknife leaves out one column at a time:

    theta_(i) = (N - n_i) / (D - d_i),   err^2 = (K - 1) / K * sum_i (theta_(i) - mean theta_(.))^2,

with N, D the pile's sums and n_i, d_i column i's. For a plain mean of equal columns this is the
standard error of the columns' means, exactly, and it holds the correlations within a column. It
assumes independent columns: a pile's columns are anticorrelated (its mean z fluctuates less than
independent columns would), and on piles with 5 seeds it came out 1.6-2.1 times the scatter
between piles, so it is an upper bound that one pile gives (docs/model.md 6.10).
"""
from __future__ import annotations

import math

import numpy as np


def columns(x, L_x, L_y, k):
    """The lateral column of each position, 0 .. k*k - 1 (the box split into k x k columns).

    Parameters
    ----------
    x : (n, 3) float64 positions [d] (wrapped into the box or not)
    L_x, L_y : float box [d]
    k : int columns along each of x and y, >= 2

    Returns
    -------
    (n,) int64
    """
    if k < 2:
        raise ValueError(f"jackknife columns k = {k}: accepted k >= 2")
    ix = np.minimum((np.mod(x[:, 0], L_x) * (k / L_x)).astype(np.int64), k - 1)
    iy = np.minimum((np.mod(x[:, 1], L_y) * (k / L_y)).astype(np.int64), k - 1)
    return ix * k + iy


def ratio(num, den):
    """(sum num / sum den, its jackknife error) over groups, deleting one group at a time.

    Parameters
    ----------
    num, den : (K,) float per-group sums; a group with den = 0 adds nothing and is left out

    Returns
    -------
    (float, float) : the estimate and its error; (nan, nan) with fewer than 2 groups
    """
    num, den = np.asarray(num, float), np.asarray(den, float)
    keep = den != 0
    num, den = num[keep], den[keep]
    K = len(num)
    if K < 2:
        return math.nan, math.nan
    N, D = num.sum(), den.sum()
    loo = (N - num) / (D - den)
    return float(N / D), float(math.sqrt((K - 1) / K * np.sum((loo - loo.mean()) ** 2)))


def mean(values, groups, K):
    """(mean of ``values``, its jackknife error) over the groups 0..K-1 ``groups`` assigns."""
    values = np.asarray(values, float)
    return ratio(np.bincount(groups, weights=values, minlength=K), np.bincount(groups, minlength=K))
