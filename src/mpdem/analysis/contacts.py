"""The contacts of a packing with their normals and forces (docs/model.md 6.2, 6.10).

``Packing`` finds the contacts from positions (r < d); this module gives each
of them its unit normal, overlap and force: the file's contact list (/pairs:
F_n, F_t as the last step applied them) where it holds the pair, else the
elastic normal force of the contact law (k_n delta, or the Hertz form), which
is what a static contact carries once the dashpot has nothing left to damp.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..kernels.models import overlap_scale
from ..kernels.pairdist import separations


@dataclass
class ContactForces:
    """Forces on the contacts of a ``Packing`` (pairs i < j, rows sorted by id).

    Attributes
    ----------
    nrm : (M, 3) unit normal from j to i
    branch : (M, 3) x_i - x_j, minimum image [d]
    delta : (M,) overlap d - r [d]
    F_n : (M,) normal force along ``nrm`` on i [m g] (compressive > 0)
    F_t : (M, 3) tangential force on i [m g] (zero where the file has none)
    zeta : (M,) |F_t| / (mu F_n); nan at mu = 0 or F_n <= 0
    from_file : (M,) bool, the pair's forces came from the file's contact list
    k_n : float, model : str
        The law the elastic forces were made with (a plane's contacts are made with it too).
    """
    nrm: np.ndarray
    branch: np.ndarray
    delta: np.ndarray
    F_n: np.ndarray
    F_t: np.ndarray
    zeta: np.ndarray
    from_file: np.ndarray
    k_n: float = 2e5
    model: str = "hooke"

    @property
    def force(self):
        """(M, 3) total contact force on i from j [m g]."""
        return self.F_n[:, None] * self.nrm + self.F_t


def elastic_normal(delta, k_n, model="hooke"):
    """The static normal force of an overlap: k_n delta (Hooke) or sqrt(delta) k_n delta (Hertz) [m g]."""
    f = k_n * delta
    return f * overlap_scale(model, delta)


def contact_forces(pk, arrays, k_n, mu, model="hooke"):
    """The normal, overlap and forces of every contact of ``pk``.

    Parameters
    ----------
    pk : Packing built from ``arrays["x"]`` (rows in ``arrays["id"]`` order, ascending)
    arrays : the state (``checkpoint.read_state``); its ``id_i, id_j, F_n, F_t`` are used when present
    k_n : normal stiffness [m g / d]; mu : friction; model : 'hooke' or 'hertz'

    Returns
    -------
    ContactForces
    """
    i, j = pk.pairs[:, 0], pk.pairs[:, 1]
    branch = separations(pk.x, i, j, pk.L_x, pk.L_y)
    r = np.sqrt(np.einsum("ij,ij->i", branch, branch))
    nrm = branch / r[:, None]
    delta = 1.0 - r
    F_n = elastic_normal(delta, k_n, model)
    F_t = np.zeros_like(branch)
    from_file = np.zeros(len(i), bool)
    if "id_i" in arrays and len(i):
        ids = np.asarray(arrays["id"])
        a = np.searchsorted(ids, arrays["id_i"])
        b = np.searchsorted(ids, arrays["id_j"])
        n = np.int64(len(ids))
        want = i.astype(np.int64) * n + j
        have = np.minimum(a, b).astype(np.int64) * n + np.maximum(a, b)
        order = np.argsort(have, kind="stable")
        pos = np.searchsorted(have[order], want)
        pos = np.minimum(pos, len(order) - 1)
        hit = have[order][pos] == want
        src = order[pos[hit]]
        F_n[hit] = np.asarray(arrays["F_n"])[src]
        # the file's F_t acts on its id_i: on our row i it is +F_t when id_i is row i, else -F_t
        sign = np.where(a[src] == i[hit], 1.0, -1.0)
        F_t[hit] = sign[:, None] * np.asarray(arrays["F_t"])[src]
        from_file = hit
    with np.errstate(invalid="ignore", divide="ignore"):
        ft = np.sqrt(np.einsum("ij,ij->i", F_t, F_t))
        zeta = np.where((F_n > 0) & (mu > 0), ft / (mu * F_n), np.nan) if mu > 0 else np.full(len(i), np.nan)
    return ContactForces(nrm, branch, delta, F_n, F_t, zeta, from_file, float(k_n), model)


def n_bands(h, z_bed, width):
    """Depth bands of ``width`` from the surface h down to the bed."""
    return max(1, int(math.ceil((h - z_bed) / width)))


def band_index(z, h, width, n_bands):
    """Depth band of heights ``z``: 0 for the top ``width`` below the surface h, clipped to [0, n_bands - 1]."""
    k = np.floor((h - np.asarray(z, float)) / width).astype(np.int64)
    return np.clip(k, 0, n_bands - 1)


def band_means(values, band, n_bands):
    """(n_bands,) the mean of ``values`` in each band (nan in a band without entries)."""
    s = np.bincount(band, weights=values, minlength=n_bands)
    c = np.bincount(band, minlength=n_bands)
    with np.errstate(invalid="ignore", divide="ignore"):
        return s / c


def local_mean(values, band, n_bands):
    """(len(values),) the mean of ``values`` over the entries of the same band."""
    return band_means(values, band, n_bands)[band]
