"""Crystal-like local order: Steinhardt q6 bond order and solid-like bonds (docs/model.md 6.10).

Monodisperse spheres can order in part, and an ordered fraction raises z.
For each sphere i, with its neighbours j within ``cutoff`` (centre distance):

    q6m(i) = (1 / N_i) sum_j Y6m(r_ij / |r_ij|),   m = -6 .. 6

A bond i-j is solid-like when the normalised product
d6(i, j) = Re sum_m q6m(i) q6m(j)* / (|q6(i)| |q6(j)|) exceeds ``bond``, and a
sphere is crystal-like with at least ``bonds`` solid-like bonds (ten Wolde,
Ruiz-Montero and Frenkel, J. Chem. Phys. 104, 9932 (1996)). Also reported:
the local Q6(i) = sqrt(4 pi / 13 sum_m |q6m(i)|^2) (fcc 0.575, hcp 0.485,
a dense random packing about 0.37 with a 1.4 d shell).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.special import sph_harm_y

from ..kernels.pairdist import close_pairs, separations

L = 6


def q6_vectors(x, L_x, L_y, cutoff):
    """q6m of every sphere and its neighbour bonds.

    Parameters
    ----------
    x : (n, 3) positions [d]; L_x, L_y : box [d]; cutoff : neighbour distance [d]

    Returns
    -------
    q : (n, 7) complex, q6m for m = 0 .. 6 (m < 0 follow from q6,-m = (-1)^m conj(q6m))
    pairs : (B, 2) int64 neighbour pairs i < j
    n_nb : (n,) int neighbours per sphere
    """
    pairs = close_pairs(x, L_x, L_y, cutoff)
    d = separations(np.asarray(x, float), pairs[:, 0], pairs[:, 1], L_x, L_y)
    r = np.sqrt(np.einsum("ij,ij->i", d, d))
    theta = np.arccos(np.clip(d[:, 2] / r, -1.0, 1.0))
    phi = np.arctan2(d[:, 1], d[:, 0])
    n = len(x)
    q = np.zeros((n, L + 1), complex)
    for m in range(L + 1):
        y = sph_harm_y(L, m, theta, phi)
        # the bond seen from j points the other way: Y6m(-r) = (-1)^6 Y6m(r) = Y6m(r)
        for w, part in ((1.0, y.real), (1j, y.imag)):
            q[:, m] += w * (np.bincount(pairs[:, 0], weights=part, minlength=n)
                            + np.bincount(pairs[:, 1], weights=part, minlength=n))
    n_nb = np.bincount(pairs.ravel(), minlength=n)
    q /= np.maximum(n_nb, 1)[:, None]
    return q, pairs, n_nb


def _dot(a, b):
    """Re sum_{m=-6..6} a_m conj(b_m) from the m >= 0 halves."""
    return (a[..., 0] * np.conj(b[..., 0])).real + 2.0 * (a[..., 1:] * np.conj(b[..., 1:])).real.sum(axis=-1)


def crystal_order(x, L_x, L_y, cutoff=1.4, bond=0.7, bonds=8):
    """Local Q6 and crystal-like spheres.

    Parameters
    ----------
    x : (n, 3) positions [d] (every sphere: neighbours may be bed spheres)
    cutoff : neighbour shell [d]; bond : d6 above which a bond is solid-like;
    bonds : solid-like bonds that make a sphere crystal-like

    Returns
    -------
    Q6 : (n,) local bond order (nan without neighbours)
    crystal : (n,) bool
    solid_bonds : (n,) int
    """
    q, pairs, n_nb = q6_vectors(x, L_x, L_y, cutoff)
    norm2 = _dot(q, q)
    Q6 = np.where(n_nb > 0, np.sqrt(4.0 * math.pi / 13.0 * np.maximum(norm2, 0.0)), np.nan)
    norm = np.sqrt(np.maximum(norm2, 1e-300))
    d6 = _dot(q[pairs[:, 0]], q[pairs[:, 1]]) / (norm[pairs[:, 0]] * norm[pairs[:, 1]])
    solid = d6 > bond
    nsb = np.bincount(pairs[solid].ravel(), minlength=len(x))
    return Q6, nsb >= bonds, nsb
