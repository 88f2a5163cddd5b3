"""The fabric of the contact network: how the contact normals are oriented (docs/model.md 6.10).

The fabric tensor of a set of contacts with unit normals n_c is

    R = (1/M) sum_c n_c n_c^T,        trace R = 1,

isotropic (every direction alike) R = I / 3. Its force-weighted form, R_f = sum_c F_c n_c n_c^T /
sum_c F_c with F_c the normal force, is the normal part of the contact stress over its trace. Reported:

- the eigenvalues (descending) and the anisotropy a = sqrt(3/2 R':R'), R' = R - I/3: 0 for an
  isotropic fabric, 1 when every contact lies along one axis;
- R_zz (1/3 isotropic; above it, more contacts along the bed's normal, gravity's of a poured pile)
  and R_xz, the shear part in the flow's plane (x downslope);
- the angle of the major principal direction of the x-z part from the bed's normal, toward +x:
  0.5 atan2(2 R_xz, R_zz - R_xx) [degrees]. A pile poured under gravity along -z has it near 0;
  a flow along +x leaves it tilted.

Errors by the jackknife over lateral columns (``jackknife``), each contact in the column of its
midpoint.
"""
from __future__ import annotations

import math

import numpy as np

QUANTITIES = ("anisotropy", "R_zz", "R_xz", "angle")


def tensor(nrm, weight=None):
    """The fabric tensor of unit normals.

    Parameters
    ----------
    nrm : (M, 3) float unit normals (the sign does not matter)
    weight : (M,) float or None, each contact's weight (the normal force for R_f); None: 1 each

    Returns
    -------
    (3, 3) float64, trace 1; nan with no contacts (or zero total weight)
    """
    nrm = np.asarray(nrm, float)
    w = np.ones(len(nrm)) if weight is None else np.asarray(weight, float)
    tot = w.sum()
    if len(nrm) == 0 or tot == 0:
        return np.full((3, 3), math.nan)
    return np.einsum("c,ci,cj->ij", w, nrm, nrm) / tot


def describe(R):
    """The numbers of one fabric tensor ``R`` (3, 3): anisotropy, R_zz, R_xz, angle [degrees]."""
    R = np.asarray(R, float)
    if not np.all(np.isfinite(R)):
        return {q: math.nan for q in QUANTITIES}
    dev = R - np.trace(R) / 3.0 * np.eye(3)
    return {"anisotropy": float(math.sqrt(1.5 * np.sum(dev * dev))), "R_zz": float(R[2, 2]),
            "R_xz": float(R[0, 2]), "angle": math.degrees(0.5 * math.atan2(2.0 * R[0, 2], R[2, 2] - R[0, 0]))}


def of_contacts(nrm, groups, K, weight=None):
    """The fabric of contacts with its jackknife errors over ``K`` groups.

    Parameters
    ----------
    nrm : (M, 3) unit normals
    groups : (M,) int in 0..K-1, each contact's lateral column
    K : int number of columns
    weight : (M,) float or None (see ``tensor``); ``n`` counts every contact, weighted or not

    Returns
    -------
    dict: n (contacts), eigenvalues (3, descending), R (3 x 3 nested list), and each of QUANTITIES with
    its ``_err`` (the jackknife over the columns holding contacts; nan with fewer than 2)
    """
    nrm = np.asarray(nrm, float)
    w = np.ones(len(nrm)) if weight is None else np.asarray(weight, float)
    groups = np.asarray(groups, np.int64)
    # per-column sums of w n n^T and of w: the tensor without column c is (S - S_c) / (W - W_c)
    S = np.zeros((K, 3, 3))
    np.add.at(S, groups, w[:, None, None] * nrm[:, :, None] * nrm[:, None, :])
    W = np.bincount(groups, weights=w, minlength=K)
    R = tensor(nrm, w)
    out = {"n": int(len(nrm)), "R": R.tolist(),
           "eigenvalues": (np.sort(np.linalg.eigvalsh(R))[::-1].tolist() if np.all(np.isfinite(R))
                           else [math.nan] * 3)}
    out.update(describe(R))
    used = np.flatnonzero(W != 0)
    if len(used) < 2:
        out.update({f"{q}_err": math.nan for q in QUANTITIES})
        return out
    loo = [describe((S.sum(axis=0) - S[c]) / (W.sum() - W[c])) for c in used]
    k = len(used)
    for q in QUANTITIES:
        v = np.array([d[q] for d in loo])
        if q == "angle" and math.isfinite(out[q]):
            # an axis: -89 and +89 degrees are 2 apart; each leave-one-out angle taken within 90 of the estimate
            v = out[q] + (v - out[q] + 90.0) % 180.0 - 90.0
        out[f"{q}_err"] = float(math.sqrt((k - 1) / k * np.sum((v - v.mean()) ** 2)))
    return out
