"""The unbalanced-force ratio of a pile: exact sums of resultant and contact forces.

The ratio (YADE's "unbalanced force") is the mean magnitude of the resultant
force on the mobile spheres over the mean magnitude of a contact force:

    R = ( sum_i |f_i| / N ) / ( sum_i sum_{c of i} |F_c| / sum_i n_i )

over the mobile rows i a rank owns and their contacts c (a pair counts once
for each mobile sphere it touches). It tends to 0 as a pile comes to rest.
Each row's terms are added to fixed-point accumulators (``exactsum``), so
the sums, and a stop decision taken on them, are the same bits on any number
of ranks and threads. Spheres in flight are counted too: under gravity a
sphere without a contact is not at rest, so a pile is static only with none.
"""
import math

import numpy as np
from numba import njit, prange

from .chunks import chunk_bounds
from .exactsum import NLIMBS, add_exact
from .history import slot_of, stamp_of


@njit(cache=True, parallel=True)
def force_balance(n_own, particles, near, slots, epoch, nchunk):
    """Exact sums of the resultant and the contact forces of the owned mobile rows.

    Parameters
    ----------
    particles : Particles; ``f`` (n, 3), the forces of the last evaluation (contacts and gravity)
        [m g], and ``fixed`` are read
    near : Near; ``start``, ``link`` and ``cslot`` (the rows' near entries, their near slots and
        those slots' slots) are read: every contact is a near entry
    slots : Slots; ``pair`` (K_near, 6) forces by near slot (columns 0-2 the contact force [m g]) and
        ``stamp`` are read
    epoch : int, the last evaluation
    nchunk : int, chunks of rows (the sums do not depend on it)

    Returns
    -------
    (4, NLIMBS) int64 accumulators: sum |f_i|, sum |F_c| over the rows' contacts, their number,
    and the mobile rows without a contact
    """
    f, fixed = particles.f, particles.fixed
    start, link, cslot = near.start, near.link, near.cslot
    pair, stamp = slots.pair, slots.stamp
    now = stamp_of(epoch)
    part = np.zeros((nchunk, 4, NLIMBS), np.int64)
    for c in prange(nchunk):
        lo, hi = chunk_bounds(c, n_own, nchunk)
        for i in range(lo, hi):
            if fixed[i]:
                continue
            add_exact(part[c, 0], math.sqrt(f[i, 0] ** 2 + f[i, 1] ** 2 + f[i, 2] ** 2))
            m = 0
            for k in range(start[i], start[i + 1]):
                e = slot_of(link[k])
                if stamp[cslot[e]] == now:
                    add_exact(part[c, 1], math.sqrt(pair[e, 0] ** 2 + pair[e, 1] ** 2 + pair[e, 2] ** 2))
                    m += 1
            add_exact(part[c, 2], float(m))
            if m == 0:
                add_exact(part[c, 3], 1.0)
    acc = np.zeros((4, NLIMBS), np.int64)
    for c in range(nchunk):
        acc += part[c]
    return acc
