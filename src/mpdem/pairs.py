"""The contact list of a snapshot: every contact once, with its forces.

Computed from the contact slots after a step, with the contact law of
docs/model.md 2 evaluated as the step did: positions of the step, velocities of
the half step (owned rows: v - f dt / 2; ghost rows already hold the half-step
values they were sent with), the slot's Delta s. The forces are those the
step applied, to rounding (the sum over a particle's pairs plus gravity gives
its force to about 1e-15 relative).
"""
from __future__ import annotations

import numpy as np

from .kernels.models import overlap_scale
from .kernels.particle import INV_I, R
from .kernels.pairdist import separations


def contact_pairs(state, phys):
    """This rank's share of the contact list (pairs i < j, or j in the bed).

    Parameters
    ----------
    state : State
        After a step: owned rows, ghost rows and contact slots current.
    phys : Physics

    Returns
    -------
    dict with ``id_i, id_j`` (P,) int64, ``delta`` (P,) overlap [d],
    ``F_n`` (P,) normal force along n = (x_i - x_j)/r [m g], ``F_t`` (P, 3)
    tangential force on i [m g], ``ds_i`` (P, 3) Delta s of i [d].
    """
    s, n, m = state, state.n_own, state.n_rows
    counts, jid, ds, order_own = s.contacts_flat()
    ids = s.id[:m]
    i = np.repeat(order_own, counts)
    order = np.argsort(ids, kind="stable")
    j = order[np.searchsorted(ids[order], jid)]
    fixed = s.fixed[:m]
    keep = (fixed[j] == 1) | (ids[i] < jid)
    i, j, jid, ds = i[keep], j[keep], jid[keep], ds[keep]
    # half-step velocities, as the force evaluation saw them
    vh, wh = s.v[:m].copy(), s.omega[:m].copy()
    vh[:n] -= 0.5 * phys.dt * s.f[:n]
    wh[:n] -= 0.5 * phys.dt * INV_I * s.torque[:n]
    d = separations(s.x, i, j, s.L_x, s.L_y)
    r = np.sqrt((d * d).sum(axis=1))
    delta = 1.0 - r
    nrm = d / r[:, None]
    meff = np.where(fixed[j] == 1, 1.0, 0.5)
    vr = vh[i] - vh[j]
    vn = (vr * nrm).sum(axis=1)
    w = R * wh[i] + R * wh[j]
    vt = vr - vn[:, None] * nrm - np.cross(w, nrm)
    law = phys.law
    scale = overlap_scale(law.model, delta)
    F_n = scale * (law.k_n * delta - meff * law.gamma_n * vn)
    if law.limit_damping:
        F_n = np.maximum(F_n, 0.0)
    if law.mu > 0.0:
        F_t = -scale[:, None] * (law.k_t * ds + (meff * law.gamma_t)[:, None] * vt)
    else:
        F_t = np.zeros_like(ds)
    return {"id_i": ids[i], "id_j": jid, "delta": delta, "F_n": F_n, "F_t": F_t, "ds_i": ds}
