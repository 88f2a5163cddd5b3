"""Steps in one call: velocity-Verlet steps of one rank's rows on one chunk (one thread), as many
as need no list work, without a return to Python between them (the CPU engine's ``run_quiet``).

Each step is the one ``Engine.step(defer_kick=True)`` takes on one rank: the first half-kick (with
the previous step's deferred second half-kick) and drift (``integrate._kick_drift_rows``), the
contact forces (``forces._rows``) and the planes' (``forces._plane_rows``); the same functions in the
same order, so the same bits. A step whose displacement needs a list rebuild or a new filtering of
the near lists (or has a position that is not finite) stops the call after its drift; the engine
finishes it on its usual path.
"""
import math

from numba import njit

from .forces import _plane_rows, _rows
from .integrate import _kick_drift_rows

# the columns of ``quiet_steps``'s record of each step
REC_D2, REC_ZMIN, REC_ZMAX, REC_OVERLAP, REC_CONTACTS = range(5)
REC_COLUMNS = 5


@njit(cache=True)
def quiet_steps(m, n_own, particles, x_ref, dt, box, pending, near, slots, epoch, law, scratch, planes, kinds,
                plane_ds, moved, half_skin, near_limit2, rec):
    """Up to ``m`` steps of rows ``0..n_own-1`` (one rank, one chunk); returns the whole steps taken.

    Parameters
    ----------
    m : int
        Steps at most.
    n_own, particles, x_ref, dt, box, pending :
        As ``integrate.kick_drift``; ``pending`` for the first step only (each later step applies
        the previous one's deferred half-kick).
    near, slots, law, scratch :
        As ``forces.contact_forces`` (``scratch`` of one chunk); evaluation ``epoch + k + 1`` at
        step k, with the history increment.
    epoch : int
        The last force evaluation's number.
    planes, kinds, plane_ds :
        As ``forces.plane_forces``; none if ``kinds`` is empty.
    moved : float
        The displacement the near lists' filterings since the last build have added [d]
        (``NeighbourLists.moved``).
    half_skin : float
        skin / 2 [d]: a step whose displacement plus ``moved`` is not below it needs a rebuild.
    near_limit2 : float
        (near_skin / 2)^2 [d^2]: a step whose squared displacement is not below it needs a new
        filtering of the near lists.
    rec : (>= m, 5) float64, out
        Each step's squared displacement since ``x_ref`` [d^2] (NaN if a position is not finite),
        lowest and highest mobile centre [d], and, for whole steps, the largest overlap [d] and the
        contacts of its force evaluation (columns ``REC_*``).

    Returns
    -------
    int : k, the whole steps (forces evaluated). If k < m, step k has drifted (its first three
    columns are set) and its forces are left to the engine: it needs list work or is not finite.
    """
    room = (scratch.found[0], scratch.sep[0], scratch.tangent[0])
    for k in range(m):
        d2, z_min, z_max = _kick_drift_rows(0, n_own, particles, x_ref, dt, box, pending or k > 0)
        rec[k, REC_D2] = d2
        rec[k, REC_ZMIN] = z_min
        rec[k, REC_ZMAX] = z_max
        # the engine's tests of ``step``, the same operations (NaN fails both)
        if not (math.sqrt(d2) + moved < half_skin and d2 < near_limit2):
            return k
        max_ov, n_c = _rows(0, n_own, particles, near, slots, epoch + k + 1, box, law, True, room)
        if len(kinds):
            max_ov = max(max_ov, _plane_rows(0, n_own, particles, planes, kinds, plane_ds, law, True))
        rec[k, REC_OVERLAP] = max_ov
        rec[k, REC_CONTACTS] = n_c
    return m
