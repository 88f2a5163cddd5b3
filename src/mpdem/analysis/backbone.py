"""The force-bearing backbone of a pile under gravity (docs/model.md 6.2).

A count threshold (d + 1 = 4 contacts) is the rattler rule of packings without
gravity. In a pile a sphere's weight is one more constraint: a frictionless
sphere rests on 3 contacts, a frictional one on fewer. The backbone is found
from forces and force balance instead:

1. contacts whose normal force is below ``force_fraction`` of the mean normal
   force of their depth band (the load grows with depth) are dropped;
2. then, repeatedly, a mobile sphere that cannot balance its own weight with
   the contacts it has left is removed with its contacts, and its partners are
   tested again.

"Can balance its weight": some non-negative contact forces along the remaining
contacts' directions (at mu = 0: along the normals; at mu > 0: inside each
Coulomb cone, approximated from inside by a pyramid of ``CONE_SIDES`` edges)
sum to m g up (non-negative least squares, residual below ``BALANCE_TOL``).
It needs no force values, only directions, so it holds for any load from
above. The bed is never removed, nor is a plane the pile rests on (the wall
under a sparse bed, ``bulk.Packing.planes``): a sphere's contact with one is a
support like a contact with a bed sphere (and dropped by the same force cut).
Without those supports a frictionless pile that rests on the wall loses its
lowest layer, and then, layer by layer, every sphere.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import nnls

CONE_SIDES = 16       # edges of the inner pyramid of a Coulomb cone (cos(pi/16) = 0.98 of its radius)
BALANCE_TOL = 1e-9    # residual |sum f u - z_hat| below which the weight counts as balanced [m g]
UP = np.array([0.0, 0.0, 1.0])


def _generators(u, mu):
    """(3, k) directions whose non-negative combinations are the forces contacts along ``u`` can push with.

    ``u`` (k, 3): unit normals pointing into the sphere. At mu = 0 the normals
    themselves; at mu > 0 the edges of a pyramid inscribed in each cone of
    half-angle atan(mu).
    """
    if mu <= 0:
        return u.T
    ref = np.where(np.abs(u[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(u, ref)
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = np.cross(u, e1)
    phi = 2.0 * math.pi * np.arange(CONE_SIDES) / CONE_SIDES
    g = (u[:, None, :] + mu * (np.cos(phi)[None, :, None] * e1[:, None, :]
                               + np.sin(phi)[None, :, None] * e2[:, None, :]))
    return g.reshape(-1, 3).T


def balances_weight(u, mu, up=UP):
    """True if contacts along unit normals ``u`` (k, 3), pointing into the sphere, can hold its weight.

    Parameters
    ----------
    u : (k, 3) unit vectors from each partner's centre towards the sphere's
    mu : friction coefficient (0: normal forces only)
    up : (3,) the direction opposite to gravity
    """
    if len(u) == 0:
        return False
    A = _generators(np.asarray(u, float), mu)
    _, res = nnls(A, np.asarray(up, float))
    return res < BALANCE_TOL


def directions(s, order, start, sign, which, live, nrm, s_start, s_nrm):
    """(k, 3) unit normals into sphere ``s`` of its live contacts, then of its supports.

    ``order[start[s]:start[s + 1]]`` index its entries in ``which`` (the contact) and ``sign`` (+1 where
    ``s`` is the contact's first end, whose normal ``nrm`` points into it); ``live`` (M,) bool; its
    supports' normals are ``s_nrm[s_start[s]:s_start[s + 1]]``.
    """
    mine = order[start[s]:start[s + 1]]
    c = which[mine]
    on = live[c]
    u = sign[mine][on, None] * nrm[c[on]]
    if s_start[s + 1] > s_start[s]:
        u = np.concatenate([u, s_nrm[s_start[s]:s_start[s + 1]]])
    return u


def backbone(n_rows, pairs, nrm, F_n, ref_force, removable, mu, force_fraction=0.01, up=UP, supports=None):
    """Spheres and contacts that carry the pile's weight.

    Parameters
    ----------
    n_rows : int
    pairs : (M, 2) int row indices of the contacts; nrm : (M, 3) unit normal from pairs[:, 1] to pairs[:, 0]
    F_n : (M,) normal forces [m g]; ref_force : (M,) the mean normal force each is compared with
        (its depth band's)
    removable : (n_rows,) bool, False for spheres never removed (the bed)
    mu : friction coefficient
    force_fraction : contacts with F_n < force_fraction x ref_force are dropped first
    supports : (rows (A,), nrm (A, 3), F_n (A,), ref_force (A,)) or None
        Contacts of spheres with fixed boundaries (planes), never removed: unit normals into the
        sphere, their forces and reference forces (the same cut).

    Returns
    -------
    kept : (n_rows,) bool, spheres of the backbone (and every sphere not removable)
    live : (M,) bool, contacts of the backbone (both ends kept, force above the cut)
    counts : (n_rows,) int, backbone contacts per sphere
    weak : (M,) bool, the contacts dropped by the force cut
    """
    pairs = np.asarray(pairs, np.int64)
    weak = ~(np.asarray(F_n) >= force_fraction * np.asarray(ref_force))
    kept = np.ones(n_rows, bool)
    M = len(pairs)
    # each sphere's contacts: (contact, direction into the sphere)
    ends = np.concatenate([pairs[:, 0], pairs[:, 1]])
    which = np.concatenate([np.arange(M), np.arange(M)])
    sign = np.concatenate([np.ones(M), -np.ones(M)])
    order = np.argsort(ends, kind="stable")
    start = np.searchsorted(ends[order], np.arange(n_rows + 1))
    # each sphere's supports that pass the cut (rows sorted, their normals alike)
    if supports is None:
        s_rows, s_nrm = np.zeros(0, np.int64), np.zeros((0, 3))
    else:
        s_rows, s_nrm, s_F, s_ref = supports
        strong = np.asarray(s_F) >= force_fraction * np.asarray(s_ref)
        by = np.argsort(np.asarray(s_rows)[strong], kind="stable")
        s_rows, s_nrm = np.asarray(s_rows, np.int64)[strong][by], np.asarray(s_nrm)[strong][by]
    s_start = np.searchsorted(s_rows, np.arange(n_rows + 1))
    todo = np.flatnonzero(removable)
    while todo.size:
        live = ~weak & kept[pairs[:, 0]] & kept[pairs[:, 1]]
        drop = []
        for s in todo:
            if not kept[s]:
                continue
            u = directions(s, order, start, sign, which, live, nrm, s_start, s_nrm)
            if not balances_weight(u, mu, up):
                drop.append(s)
        if not drop:
            break
        drop = np.asarray(drop, np.int64)
        kept[drop] = False
        # the partners of removed spheres are tested again
        sel = np.concatenate([order[start[s]:start[s + 1]] for s in drop])
        other = np.where(ends[sel] == pairs[which[sel], 0], pairs[which[sel], 1], pairs[which[sel], 0])
        todo = np.unique(other[kept[other] & removable[other]])
    live = ~weak & kept[pairs[:, 0]] & kept[pairs[:, 1]]
    counts = np.bincount(pairs[live].ravel(), minlength=n_rows)
    return kept, live, counts, weak


def of_packing(pk, cf, h, band_width, force_fraction):
    """``backbone`` of a Packing, each contact's force compared with the mean of its depth band.

    Parameters
    ----------
    pk : Packing; cf : its ContactForces; h : free surface [d]; band_width : [d]

    The contacts with ``pk.planes`` (``Packing.plane_contacts``) are supports, their elastic forces
    (cf.k_n, cf.model) compared with the mean of the pairs' forces in the band at the sphere's height.

    Returns
    -------
    dict: kept, live, counts, weak (as ``backbone``) and ref_force (M,) [m g]
    """
    from ..kernels.exactsum import bin_sums
    from .contacts import band_index, elastic_normal, n_bands
    B = n_bands(h, pk.z_bed, band_width)
    mid = 0.5 * (pk.x[pk.pairs[:, 0], 2] + pk.x[pk.pairs[:, 1], 2])
    band = band_index(mid, h, band_width, B)
    # exact sums, as the ranks of a run make them at its end (``bulkpar``): the same bits in any order
    with np.errstate(invalid="ignore", divide="ignore"):
        means = bin_sums(band, cf.F_n, B) / np.bincount(band, minlength=B)
    ref = means[band]
    rows, nrm, delta = pk.plane_contacts()
    supports = None
    if len(rows):
        # a band without pair contacts sets no bar (mean 0) for a plane contact in it
        s_ref = np.nan_to_num(means[band_index(pk.x[rows, 2], h, band_width, B)], nan=0.0)
        supports = (rows, nrm, elastic_normal(delta, cf.k_n, cf.model), s_ref)
    kept, live, counts, weak = backbone(len(pk.x), pk.pairs, cf.nrm, cf.F_n, ref, pk.mobile, pk.mu, force_fraction,
                                        supports=supports)
    return {"kept": kept, "live": live, "counts": counts, "weak": weak, "ref_force": ref}
