"""Mobilisation of friction at the contacts: P(zeta), zeta = |F_t| / (mu F_n) (docs/model.md 6.7)."""
from __future__ import annotations

import numpy as np


def bulk_contacts(pairs, ids, z, z1, z2):
    """(P,) bool: contacts of a contact list whose midpoint lies in [z1, z2].

    Parameters
    ----------
    pairs : dict with ``id_i, id_j`` (P,) (the file's /pairs)
    ids : (n,) sorted particle ids; z : (n,) their heights [d]
    """
    zi = z[np.searchsorted(ids, pairs["id_i"])]
    zj = z[np.searchsorted(ids, pairs["id_j"])]
    mid = 0.5 * (zi + zj)
    return (mid >= z1) & (mid <= z2)


def force_ratios(F_n, F_t, mu, bins=50, mobilised=0.99):
    """P(zeta) normalised by its largest bin, and F_t/F_n for mu >= 1.

    Parameters
    ----------
    F_n : (P,) normal forces [m g] (compressive > 0); F_t : (P, 3) [m g]
    mu : friction coefficient (> 0)
    bins : number of bins on [0, 1]; mobilised : zeta counted as fully mobilised

    Returns
    -------
    dict with ``edges`` (bins + 1,), ``P_zeta`` (bins,) (max bin = 1),
    ``count`` (bins,), ``n_contacts`` (with F_n > 0), ``n_tensile`` (F_n <= 0,
    left out), ``mobilised_fraction`` (zeta > mobilised), ``n_above_one`` (zeta > 1
    beyond rounding: the Coulomb limit broken), ``zeta_mean``,
    ``zeta_max``, and for mu >= 1 ``P_ratio`` / ``count_ratio`` of F_t/F_n on
    the same bins with ``n_ratio_above_one``, the contacts beyond them.
    """
    ft = np.sqrt(np.einsum("ij,ij->i", F_t, F_t)) if len(F_t) else np.zeros(0)
    ok = F_n > 0
    ratio = ft[ok] / F_n[ok]
    zeta = ratio / mu
    edges = np.linspace(0.0, 1.0, bins + 1)
    # zeta = 1 to rounding (sliding contacts) belongs in the last bin
    count = np.bincount(np.minimum((zeta * bins).astype(np.int64), bins - 1)[zeta <= 1 + 1e-9],
                        minlength=bins)
    out = {"edges": edges, "count": count, "P_zeta": count / max(count.max(), 1),
           "n_contacts": int(ok.sum()), "n_tensile": int((~ok).sum()),
           "mobilised_fraction": float((zeta > mobilised).mean()) if zeta.size else float("nan"),
           "n_above_one": int((zeta > 1 + 1e-9).sum()),
           "zeta_mean": float(zeta.mean()) if zeta.size else float("nan"),
           "zeta_max": float(zeta.max()) if zeta.size else float("nan")}
    if mu >= 1:
        cr = np.bincount(np.minimum((ratio * bins).astype(np.int64), bins)[ratio < 1.0],
                         minlength=bins)[:bins]
        out["count_ratio"], out["P_ratio"] = cr, cr / max(cr.max(), 1)
        out["n_ratio_above_one"] = int((ratio >= 1.0).sum())
    return out
