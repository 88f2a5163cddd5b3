"""Contact forces and torques (docs/model.md section 2).

Per row, two passes: the row computes its own pairs (a pair within a chunk
once, by its lower row), then sums all its entries in partner-id order, so
the result has the same bits for any ranks, threads and chunks (see
docs/computing.md, "The force sum: two passes per row"). The contact
history is read and written in place in the list slots (docs/computing.md,
"The contact history's two homes"); a contact whose stamp is not the
previous evaluation's is new and its Delta s starts from zero (docs/model.md
2.4). Stored zeros are +0.0 (``x + 0.0``).
"""
import numpy as np
from numba import njit, prange

from .chunks import chunk_bounds
from .geometry import min_image
from .history import slot_of, stamp_of
from .law import (PLANE_FLOOR, PLANE_ROUGH, approach, contact_force, contact_torque, dot, normal, normal_force, norm2,
                  plane_contact, slip, spin, tangential)
from .prefetch import prefetch_row


@njit(cache=True, parallel=True, error_model="numpy")
def contact_forces(n_own, particles, near, slots, epoch, box, law, increment, scratch):
    """Forces and torques on owned rows, updating the contact history in place.

    Parameters
    ----------
    n_own : int
        Owned rows ``0..n_own-1`` get forces; other rows are read-only ghosts.
    particles : Particles
        ``x``, ``v``, ``omega`` (n_rows, 3) float64: position [d], velocity
        [sqrt(g d)], angular velocity [sqrt(g/d)], v and omega the half-step
        values of velocity Verlet; ``fixed`` (n_rows,) uint8: 1 for bed
        particles (never moved; zero force and torque here); ``f``, ``torque``
        (n_rows, 3) float64, out: force [m g] including gravity, torque [m g d].
    near : Near
        The entries of the full neighbour lists within the near reach
        (``near.near_lists``; each row's sorted by partner id), each entry's
        place in the pair store ``link`` and the K_near entries the rows
        compute with their slots ``cslot`` and places ``cpair``; every pair in
        contact is among them.
    slots : Slots
        ``hist`` (K, 3) float64, in/out: Delta s [d] of each slot's pair (the
        computing row's view), read only if the pair was in contact at the
        previous evaluation; ``stamp`` (K,) uint32, in/out: set to ``epoch``
        for the contacts of this evaluation; ``pair`` (places, 6) float64,
        out, by place (``Near.cpair``): the computing row's contact force
        [m g] and torque [m g d] (zeros out of contact; the torque only with
        friction), valid after the pass only where no entry reused the place.
    epoch : int
        The number of this evaluation (the previous one is ``epoch - 1``).
    box : Box
        Periodic box [d].
    law : Law
    increment : bool
        False on the set-up evaluation at t = 0 (no history increment).
    scratch : Scratch
        Per chunk of rows (C >= 1 chunks; any C gives the same result): the
        largest overlap, the contacts, and room for the computed contacts of
        a block of rows (W >= the longest list of a row).

    Returns
    -------
    max_overlap : float
        Largest overlap delta [d] over owned contacts.
    n_contacts : int
        Contacts counted from owned mobile particles (bed partners included).
    """
    # fields by attribute before the loop, never unpacked as a tuple (bundles.py: numba's prange)
    chunk_max, chunk_count = scratch.chunk_max, scratch.chunk_count
    found, sep, tangent = scratch.found, scratch.sep, scratch.tangent
    nchunk = len(chunk_max)
    for c in prange(nchunk):
        lo, hi = chunk_bounds(c, n_own, nchunk)
        mo, nc = _rows(lo, hi, particles, near, slots, epoch, box, law, increment, (found[c], sep[c], tangent[c]))
        chunk_max[c] = mo
        chunk_count[c] = nc
    max_overlap = 0.0
    n_contacts = 0
    for c in range(nchunk):
        max_overlap = max(max_overlap, chunk_max[c])
        n_contacts += chunk_count[c]
    return max_overlap, n_contacts


@njit(cache=True)
def contact_forces_serial(n_own, particles, near, slots, epoch, box, law, increment, scratch):
    """``contact_forces`` with one chunk (``scratch`` of C = 1), without the parallel
    wrapper: the same arithmetic in the same order, so the same bits, and 2-3 % faster
    on one thread (docs/performance.md). Arguments and returns as ``contact_forces``."""
    found, sep, tangent = scratch.found, scratch.sep, scratch.tangent
    return _rows(0, n_own, particles, near, slots, epoch, box, law, increment, (found[0], sep[0], tangent[0]))


@njit(cache=True, error_model="numpy")
def _rows(lo, hi, particles, near, slots, epoch, box, law, increment, room):
    """Rows lo..hi-1 of ``contact_forces``; returns (max overlap, contacts).

    ``room`` is the chunk's (found (W, 3) int32, sep (W, 4) float64, tangent
    (W, 9) float64) of ``Scratch``. Slots: e indexes ``near.cj``,
    ``near.cslot`` and ``near.cpair``; g = cslot[e] the history, p = cpair[e]
    the place in ``pair`` (``kernels.pairstore``).

    The rows go in blocks: as many consecutive rows as have their computed
    entries fit in the W places of ``room`` (at least one: W >= the longest
    list of a row). For a block:

    1. A screening pass over the entries its rows compute records the
       contacts (slot, partner, row) in ``found`` and their separations in
       ``sep`` (kept for the law, not read or computed again), without a
       branch on the outcome (about half the entries are contacts, in no
       predictable order, so a branch there is mispredicted often).
    2. The normal law over all the block's contacts; with friction, what the
       tangential law needs is left in ``tangent`` and
    3. the tangential law over them. Each contact's result is left in its
       slot of ``pair``. Short loops over the whole block, not the 2-3
       contacts of a row, let the CPU overlap contacts (docs/performance.md).
    4. One pass over each row's entries in partner-id order sums their
       slots, again without a branch on the outcome: a slot out of contact
       holds zeros (adding +0.0 or -0.0 to a sum that started at a component
       of gravity, +0.0 or not zero, leaves it as it is).

    Every slot a row sums is computed by the row itself or by a lower row of
    the chunk, so of its own block or an earlier one. Each value is the same
    arithmetic on the same operands as with one row at a time: the same bits.
    """
    x, v, omega, f, torque, fixed = particles
    start, link, cstart, cj, cslot, cpair = near
    hist, stamp, pair = slots
    L_x, L_y, hx, hy = box
    found, sep, tangent = room
    room_w = np.uint64(len(found))
    friction = law.mu > 0.0
    now = stamp_of(epoch)
    before = stamp_of(epoch - 1)
    max_overlap = 0.0
    n_contacts = 0
    one = np.uint64(1)
    row_hi = np.uint64(hi)
    # unsigned rows, counters and entries: numba adds no negative-index wrap-around to them (5-7 % in all)
    b0 = np.uint64(lo)
    while b0 < row_hi:
        m = np.uint64(0)
        b = b0
        e_first = np.uint64(cstart[b0])
        while b < row_hi:
            c0 = np.uint64(cstart[b])
            c1 = np.uint64(cstart[b + one])
            # the block's computed entries, not only its contacts, fit: the ring store relies on it
            if c1 - e_first > room_w:
                if b == b0:
                    # never with the engine's scratch (W >= a row's longest list); not an endless loop
                    raise ValueError("force scratch narrower than a row's computed entries")
                break
            if not fixed[b]:
                xi = x[b, 0]
                yi = x[b, 1]
                zi = x[b, 2]
                for e in range(c0, c1):
                    j = np.uint64(cj[e])
                    # the law reads the partner's v and omega after the block's screening: ask for
                    # them now, as the partners a layer of cells up are not cached on a large pile
                    prefetch_row(v, j)
                    if friction:
                        prefetch_row(omega, j)
                    dx = min_image(xi - x[j, 0], L_x, hx)
                    dy = min_image(yi - x[j, 1], L_y, hy)
                    dz = zi - x[j, 2]
                    r2 = norm2(dx, dy, dz)
                    on = np.uint8(r2 < 1.0)
                    found[m, 0] = e
                    found[m, 1] = j
                    found[m, 2] = b
                    sep[m, 0] = dx
                    sep[m, 1] = dy
                    sep[m, 2] = dz
                    sep[m, 3] = r2
                    m += np.uint64(on)
                    # out of contact, the place adds zeros (the law overwrites a contact's)
                    p = np.uint64(cpair[e])
                    pair[p, 0] = 0.0
                    pair[p, 1] = 0.0
                    pair[p, 2] = 0.0
                    if friction:
                        pair[p, 3] = 0.0
                        pair[p, 4] = 0.0
                        pair[p, 5] = 0.0
            b += one
        for q in range(np.uint64(0), m):
            e = np.uint64(found[q, 0])
            j = np.uint64(found[q, 1])
            i = np.uint64(found[q, 2])
            # the higher row of a pair within the chunk counts it too
            n_contacts += 1 + (lo <= found[q, 1] < hi and not fixed[j])
            dx = sep[q, 0]
            dy = sep[q, 1]
            dz = sep[q, 2]
            delta, nx, ny, nz = approach(dx, dy, dz, sep[q, 3])
            if delta > max_overlap:
                max_overlap = delta
            meff = 1.0 if fixed[j] else 0.5
            vrx = v[i, 0] - v[j, 0]
            vry = v[i, 1] - v[j, 1]
            vrz = v[i, 2] - v[j, 2]
            vn = dot(vrx, vry, vrz, nx, ny, nz)
            fn, scale = normal(delta, vn, meff, law)
            if friction:
                wx, wy, wz = spin(omega[i, 0], omega[i, 1], omega[i, 2], omega[j, 0], omega[j, 1], omega[j, 2])
                tangent[q, 0], tangent[q, 1], tangent[q, 2] = slip(vrx, vry, vrz, vn, nx, ny, nz, wx, wy, wz)
                tangent[q, 3] = nx
                tangent[q, 4] = ny
                tangent[q, 5] = nz
                tangent[q, 6] = fn
                tangent[q, 7] = scale
                tangent[q, 8] = meff
            else:
                stamp[np.uint64(cslot[e])] = now
                p = np.uint64(cpair[e])
                # the partner's view is the exact negative (n flips sign, fn is the same)
                pair[p, 0], pair[p, 1], pair[p, 2] = normal_force(fn, nx, ny, nz)
        if friction:
            for q in range(np.uint64(0), m):
                e = np.uint64(found[q, 0])
                g = np.uint64(cslot[e])
                # in contact at the previous evaluation too, or a new contact (history from zero)
                was = stamp[g] == before
                stamp[g] = now
                nx = tangent[q, 3]
                ny = tangent[q, 4]
                nz = tangent[q, 5]
                fn = tangent[q, 6]
                sx, sy, sz, ftx, fty, ftz = tangential(
                    (hist[g, 0] if was else 0.0, hist[g, 1] if was else 0.0, hist[g, 2] if was else 0.0),
                    (tangent[q, 0], tangent[q, 1], tangent[q, 2]), (nx, ny, nz), tangent[q, 7], tangent[q, 8],
                    abs(fn), law, increment)
                # + 0.0 stores a zero as +0.0 whichever way it was reached
                hist[g, 0] = sx + 0.0
                hist[g, 1] = sy + 0.0
                hist[g, 2] = sz + 0.0
                p = np.uint64(cpair[e])
                # the partner's view is the exact negative (n and F_t flip sign, fn is the same)
                pair[p, 0], pair[p, 1], pair[p, 2] = contact_force(fn, nx, ny, nz, ftx, fty, ftz)
                # T_i += -R n x F_t (the same for both partners)
                pair[p, 3], pair[p, 4], pair[p, 5] = contact_torque(nx, ny, nz, ftx, fty, ftz)
        for i in range(b0, b):
            if fixed[i]:
                for a in range(3):
                    f[i, a] = 0.0
                    torque[i, a] = 0.0
                continue
            # the sums start at the force of gravity (``law.gravity_vector``)
            fx = law.g_x
            fy = law.g_y
            fz = law.g_z
            tx = 0.0
            ty = 0.0
            tz = 0.0
            for k in range(np.uint64(start[i]), np.uint64(start[i + one])):
                lk = link[k]
                p = np.uint64(slot_of(lk))
                # -1.0 * the force of a taken pair, without a branch (they come in no predictable order)
                sign = 1.0 + 2.0 * (lk >> 31)
                fx += sign * pair[p, 0]
                fy += sign * pair[p, 1]
                fz += sign * pair[p, 2]
                if friction:
                    tx += pair[p, 3]
                    ty += pair[p, 4]
                    tz += pair[p, 5]
            f[i, 0] = fx
            f[i, 1] = fy
            f[i, 2] = fz
            torque[i, 0] = tx
            torque[i, 1] = ty
            torque[i, 2] = tz
        b0 = b
    return max_overlap, n_contacts


@njit(cache=True, parallel=True, error_model="numpy")
def plane_forces(n_own, particles, planes, kinds, plane_ds, law, increment, chunk_max):
    """Add the contacts of each owned mobile sphere with the planes (``planes.Plane``, ``law.plane_contact``).

    Each plane is a partner at rest of infinite mass (m_eff = m = 1): the bed-making floor, the wall
    under the bed (``bed.wall``, as LAMMPS's ``wall/gran hooke/history ... zplane 0``), a lid.
    Added after the pair contacts, plane by plane in the order given, so the sum order does not
    depend on ranks or threads.

    Parameters
    ----------
    particles : Particles
        ``x``, ``v``, ``omega``: position [d], half-step velocity [sqrt(g d)] and angular velocity
        [sqrt(g/d)]; the planes' forces [m g] and torques [m g d] are added to ``f`` and ``torque``.
    planes : (P, 4) float64
        Each plane's unit normal and offset [d].
    kinds : (P,) int64
        Each plane's kind (``law.PLANE_*``); at most one is ``PLANE_ROUGH``.
    plane_ds : (n_rows, 3) float64, in/out
        Delta s of each sphere's contact with the rough plane [d] (+0.0 out of contact; not read
        without one).
    law : Law
    increment : bool
        False on the set-up evaluation (no history increment).
    chunk_max : (C,) float64, scratch
        One slot per chunk of rows (any C gives the same result).

    Returns
    -------
    float : the largest overlap with a plane other than the floor [d] (0 if none).
    """
    nchunk = len(chunk_max)
    for c in prange(nchunk):
        lo, hi = chunk_bounds(c, n_own, nchunk)
        chunk_max[c] = _plane_rows(lo, hi, particles, planes, kinds, plane_ds, law, increment)
    deepest = 0.0
    for c in range(nchunk):
        deepest = max(deepest, chunk_max[c])
    return deepest


@njit(cache=True, error_model="numpy")
def _plane_rows(lo, hi, particles, planes, kinds, plane_ds, law, increment):
    """Rows lo..hi-1 of ``plane_forces``; returns their largest overlap with a plane other than
    the floor [d] (0 if none)."""
    x, v, omega, fixed = particles.x, particles.v, particles.omega, particles.fixed
    f, torque = particles.f, particles.torque
    deepest = 0.0
    for i in range(lo, hi):
        if fixed[i]:
            continue
        for k in range(len(kinds)):
            kind = kinds[k]
            rough = kind == PLANE_ROUGH
            ds = (plane_ds[i, 0], plane_ds[i, 1], plane_ds[i, 2]) if rough else (0.0, 0.0, 0.0)
            delta, fx, fy, fz, tx, ty, tz, sx, sy, sz = plane_contact(
                x[i, 0], x[i, 1], x[i, 2], v[i, 0], v[i, 1], v[i, 2], omega[i, 0], omega[i, 1], omega[i, 2],
                ds, planes[k, 0], planes[k, 1], planes[k, 2], planes[k, 3], kind, law, increment)
            if rough:
                plane_ds[i, 0] = sx
                plane_ds[i, 1] = sy
                plane_ds[i, 2] = sz
            if not delta > 0.0:
                continue
            if kind != PLANE_FLOOR:
                deepest = max(deepest, delta)
            f[i, 0] += fx
            f[i, 1] += fy
            f[i, 2] += fz
            torque[i, 0] += tx
            torque[i, 1] += ty
            torque[i, 2] += tz
    return deepest
