"""The GPU engine's step: half-kick and drift, contact forces, half-kick (numba-cuda kernels).

One thread a row (``forces``), or a thread an entry then a thread a row
(``entry_forces`` and ``row_sums``: more threads for the GPU, the entries'
forces through its memory). Each row's entries are those of its full
neighbour list, in partner-id order, summed in that order: the pair's law from i's
side is the exact negative of the law from j's side (``kernels/law.py``:
mirror-exact separations, symmetric sums), so the row's sum is the CPU
engine's sum of the same values in the same order, to the bit. Each entry
keeps its own contact history (``hist``, ``stamp``), the mirror of its
partner's. The float arithmetic is the law's rounded twins
(``rounded.py``) and the sums' explicitly rounded adds.

The numbers that steer the run (largest displacement, height range, the
largest overlap, the contact count) are reduced in each block, then once
per block with an atomic max, min or integer add: exact and independent of
the order the blocks run in.

Kernels take arrays and scalars only (``law`` is the ``law.Law`` record).
``reduce.BLOCK_MAX`` threads per block at most, a power of two.
"""
import math

import numpy as np

from .reduce import (BLOCK_MAX, ROOM, contact_into, contact_into_warp, drift_into, drift_into_warp, max_into, min_into,
                     sum_into)
from .runtime import cuda, device, device_cuda, shfl
from .rounded import (add, approach, contact_force, contact_torque, dot, drift, kicks, min_image, normal,
                      normal_force, norm2, plane_contact, slip, spin, sqrt, tangential)
from ..law import PLANE_FLOOR, PLANE_ROUGH, Law
from .lists import RED_ENTRIES, RED_OVERFLOW, RED_SLOTS, rebuild_phases, sort_phases

# the slots of the step's reductions ``red`` (float64: the counts are integers, exact below 2**53, so
# their atomic sums do not depend on the order): those of ``kick_drift``, then those of ``forces``
RED_D2, RED_ZMIN, RED_ZMAX, RED_BAD, RED_OVERLAP, RED_CONTACTS = range(6)
# ``fused`` of the launches' reductions by warp shuffles (engine.gpu_reductions = "warp"; only as a pinned kernel's
# constant: a kernel's bool ``fused`` is never equal to it, so the compiler drops that code there)
WARP = 2
# their values before any row adds to them; each kernel sets the other's back to these for its next launch
NEUTRAL = (0.0, math.inf, -math.inf, 0.0, 0.0, 0.0)
# two slots after those of the engine's own ``red`` (the step's kernels launched one by one) and of ``rec``'s
# rows with rebuilds inside the launch, written by a list rebuild on the GPU with no host round trip
# (``lists.RED_ENTRIES``, ``lists.RED_OVERFLOW``; engine.gpu_rebuild = "device"): the new lists' entries,
# and 1.0 when they did not fit the lists' capacity. The forces' kernels then do nothing (``_overflowed``):
# the host reads both with the forces' reductions and builds the lists again with room for them.


@device_cuda
def _reset_drift_slots(red):
    """The first thread of the grid sets ``red``'s slots of ``kick_drift`` to ``NEUTRAL`` (the forces'
    kernels do it for the next step's drift)."""
    if cuda.grid(1) == 0:
        red[RED_D2] = NEUTRAL[RED_D2]
        red[RED_ZMIN] = NEUTRAL[RED_ZMIN]
        red[RED_ZMAX] = NEUTRAL[RED_ZMAX]
        red[RED_BAD] = NEUTRAL[RED_BAD]


@device
def _overflowed(red):
    """Whether the list rebuild before this evaluation ran out of room (``red[RED_OVERFLOW]``, a
    ``RED_SLOTS`` record): the forces' kernels launched one by one then return at once, every thread
    alike (no barrier waits), leaving the rows, the history and ``red`` as they were."""
    return red[RED_OVERFLOW] != 0.0


@device
def _kick_drift_row(i, x, v, omega, xo, vo, wo, f, torque, x_ref, dt, L_x, L_y, hx, hy, pending):
    """Row i of ``kick_drift`` from x, v, omega into xo, vo, wo (the same arrays in place, or the other
    buffer of ``advance``'s fused drift); returns (d^2 since x_ref [d^2], z [d], 1 if x is not finite
    else 0)."""
    h = 0.5 * dt
    for a in range(3):
        fa, ta = kicks(f[i, a], torque[i, a], h)
        va = v[i, a]
        wa = omega[i, a]
        if pending:
            va = add(va, fa)
            wa = add(wa, ta)
        va = add(va, fa)
        wa = add(wa, ta)
        vo[i, a] = va
        wo[i, a] = wa
        xo[i, a] = drift(x[i, a], va, dt)
    # one correction suffices: nothing moves a box length in one step
    if xo[i, 0] >= L_x:
        xo[i, 0] -= L_x
    elif xo[i, 0] < 0.0:
        xo[i, 0] += L_x
        if xo[i, 0] >= L_x:  # -tiny + L rounds to L
            xo[i, 0] = 0.0
    if xo[i, 1] >= L_y:
        xo[i, 1] -= L_y
    elif xo[i, 1] < 0.0:
        xo[i, 1] += L_y
        if xo[i, 1] >= L_y:
            xo[i, 1] = 0.0
    z = xo[i, 2]
    if not (math.isfinite(xo[i, 0]) and math.isfinite(xo[i, 1]) and math.isfinite(z)):
        return 0.0, z, 1
    dx = min_image(xo[i, 0] - x_ref[i, 0], L_x, hx)
    dy = min_image(xo[i, 1] - x_ref[i, 1], L_y, hy)
    return norm2(dx, dy, z - x_ref[i, 2]), z, 0


@device
def _drift_row(i, x, v, omega, nxt, f, torque, x_ref, dt, L_x, L_y, hx, hy, pending, d2, z_lo, z_hi, bad):
    """Row i (mobile) kicked and drifted from x, v, omega into ``nxt`` (xo, vo, wo), its values added to
    this thread's extremes so far; returns the new (d2 [d^2], z_lo, z_hi [d], bad)."""
    di, z, b = _kick_drift_row(i, x, v, omega, nxt[0], nxt[1], nxt[2], f, torque, x_ref, dt, L_x, L_y, hx, hy,
                               pending)
    if b:
        return d2, z_lo, z_hi, bad + 1
    return max(d2, di), min(z_lo, z), max(z_hi, z), bad


@device_cuda
def _drift_reduce(red, d2, z_lo, z_hi, bad, room, fused):
    """This thread's drift extremes and bad rows into ``red``'s slots RED_D2, RED_ZMAX, RED_ZMIN and
    RED_BAD (every thread of the block calls it); ``fused``: one tree (``reduce.drift_into``), or with 2
    (``WARP``) warp shuffles (``reduce.drift_into_warp``)."""
    if fused == WARP:
        drift_into_warp(red, RED_D2, d2, RED_ZMAX, z_hi, RED_ZMIN, z_lo, room)
    elif fused:
        drift_into(red, RED_D2, d2, RED_ZMAX, z_hi, RED_ZMIN, z_lo, room)
    else:
        max_into(red, RED_D2, d2, room)
        max_into(red, RED_ZMAX, z_hi, room)
        min_into(red, RED_ZMIN, z_lo, room)
    if bad:
        cuda.atomic.add(red, RED_BAD, np.float64(bad))


@cuda.jit
def kick_drift(n_own, x, v, omega, f, torque, fixed, x_ref, dt, L_x, L_y, hx, hy, pending, red):
    """First half-kick (after the previous step's second, with ``pending``) and drift of the owned
    mobile rows, x and y wrapped; as ``kernels.integrate.kick_drift``.

    Reduces into ``red`` the largest squared displacement since ``x_ref`` [d^2] (RED_D2), the mobile
    rows' lowest and highest z [d] (RED_ZMIN, RED_ZMAX), and counts the rows whose position is not
    finite (RED_BAD); sets the slots of ``forces`` to ``NEUTRAL``. Any grid: each thread takes rows
    i, i + threads, ...
    """
    room = cuda.shared.array(BLOCK_MAX, np.float64)
    if cuda.grid(1) == 0:
        red[RED_OVERLAP] = NEUTRAL[RED_OVERLAP]
        red[RED_CONTACTS] = NEUTRAL[RED_CONTACTS]
    _drift_phase(n_own, x, v, omega, f, torque, fixed, x_ref, dt, L_x, L_y, hx, hy, pending, red, room, False)


@device_cuda
def _drift_phase(n_own, x, v, omega, f, torque, fixed, x_ref, dt, L_x, L_y, hx, hy, pending, red, room, fused):
    """This thread's rows of ``kick_drift`` (i, i + threads, ...) in place, their reductions into
    ``red``'s slots RED_D2, RED_ZMIN, RED_ZMAX and RED_BAD (every thread of the block calls it);
    ``fused``: the three extremes in one tree (``reduce.drift_into``)."""
    d2 = 0.0
    z_lo = math.inf
    z_hi = -math.inf
    bad = 0
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        if not fixed[i]:
            d2, z_lo, z_hi, bad = _drift_row(i, x, v, omega, (x, v, omega), f, torque, x_ref, dt, L_x, L_y, hx, hy,
                                             pending, d2, z_lo, z_hi, bad)
    _drift_reduce(red, d2, z_lo, z_hi, bad, room, fused)


@cuda.jit
def kick(n_own, v, omega, f, torque, fixed, dt):
    """Second half-kick of the owned mobile rows (``kernels.integrate.kick``); any grid."""
    h = 0.5 * dt
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        if not fixed[i]:
            for a in range(3):
                fa, ta = kicks(f[i, a], torque[i, a], h)
                v[i, a] = add(v[i, a], fa)
                omega[i, a] = add(omega[i, a], ta)


@device
def _contact(i, e, xi, yi, zi, x, v, omega, fixed, nbr, hist, stamp, now, before, L_x, L_y, hx, hy, law, increment):
    """Entry e of mobile row i (at xi, yi, zi [d]): (1 if in contact else 0, the overlap [d], the
    contact's force on i [m g] (3), its torque on i [m g d] (3)); in contact, the entry's history
    is advanced and its stamp set to ``now``. The torque is zero without friction."""
    j = nbr[e]
    dx = min_image(xi - x[j, 0], L_x, hx)
    dy = min_image(yi - x[j, 1], L_y, hy)
    dz = zi - x[j, 2]
    r2 = norm2(dx, dy, dz)
    if not r2 < 1.0:
        return 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    delta, nx, ny, nz = approach(dx, dy, dz, r2)
    meff = 1.0 if fixed[j] else 0.5
    vrx = v[i, 0] - v[j, 0]
    vry = v[i, 1] - v[j, 1]
    vrz = v[i, 2] - v[j, 2]
    vn = dot(vrx, vry, vrz, nx, ny, nz)
    fn, scale = normal(delta, vn, meff, law)
    if law.mu > 0.0:
        wx, wy, wz = spin(omega[i, 0], omega[i, 1], omega[i, 2], omega[j, 0], omega[j, 1], omega[j, 2])
        vtx, vty, vtz = slip(vrx, vry, vrz, vn, nx, ny, nz, wx, wy, wz)
        was = stamp[e] == before
        sx, sy, sz, ftx, fty, ftz = tangential(
            (hist[e, 0] if was else 0.0, hist[e, 1] if was else 0.0, hist[e, 2] if was else 0.0),
            (vtx, vty, vtz), (nx, ny, nz), scale, meff, abs(fn), law, increment)
        # + 0.0 stores a zero as +0.0 whichever way it was reached
        hist[e, 0] = sx + 0.0
        hist[e, 1] = sy + 0.0
        hist[e, 2] = sz + 0.0
        cfx, cfy, cfz = contact_force(fn, nx, ny, nz, ftx, fty, ftz)
        ctx, cty, ctz = contact_torque(nx, ny, nz, ftx, fty, ftz)
    else:
        cfx, cfy, cfz = normal_force(fn, nx, ny, nz)
        ctx = 0.0
        cty = 0.0
        ctz = 0.0
    stamp[e] = now
    return 1, delta, cfx, cfy, cfz, ctx, cty, ctz


@device
def _keep(pair, e, cfx, cfy, cfz, ctx, cty, ctz):
    """pair[e] = the entry's force [m g] and torque [m g d]."""
    pair[e, 0] = cfx
    pair[e, 1] = cfy
    pair[e, 2] = cfz
    pair[e, 3] = ctx
    pair[e, 4] = cty
    pair[e, 5] = ctz


@device
def _added(friction, fx, fy, fz, tx, ty, tz, cfx, cfy, cfz, ctx, cty, ctz):
    """A row's sums of force [m g] (fx .. fz) and torque [m g d] (tx .. tz) with one more contact's (cfx ..
    ctz) added, each explicitly rounded (the torque's only with ``friction``): the CPU's adds, in its order."""
    if friction:
        tx = add(tx, ctx)
        ty = add(ty, cty)
        tz = add(tz, ctz)
    return add(fx, cfx), add(fy, cfy), add(fz, cfz), tx, ty, tz


@device
def _entry(i, e, x, v, omega, fixed, nbr, hist, stamp, pair, keep, now, before, L_x, L_y, hx, hy, law, increment):
    """Entry e of row i a thread an entry: its contact's force and torque into pair[e] (zeros out of
    contact with ``keep``); returns (1 if in contact else 0, its overlap [d], 0 out of contact). A bed
    row's entries are not computed (0, 0.0)."""
    if fixed[i]:
        return 0, 0.0
    c, delta, cfx, cfy, cfz, ctx, cty, ctz = _contact(i, e, x[i, 0], x[i, 1], x[i, 2], x, v, omega, fixed, nbr, hist,
                                                      stamp, now, before, L_x, L_y, hx, hy, law, increment)
    if c:
        _keep(pair, e, cfx, cfy, cfz, ctx, cty, ctz)
    elif keep:
        _keep(pair, e, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    return c, delta


@device
def _force_row(i, x, v, omega, f, torque, fixed, start, nbr, hist, stamp, pair, keep, wall_ds, planes, kinds,
               now, before, L_x, L_y, hx, hy, law, increment):
    """Row i (mobile) of ``forces``: its entries computed and summed in order, then the planes;
    returns (its largest overlap [d], its contacts)."""
    deepest = 0.0
    contacts = 0
    friction = law.mu > 0.0
    xi = x[i, 0]
    yi = x[i, 1]
    zi = x[i, 2]
    fx = law.g_x
    fy = law.g_y
    fz = law.g_z
    tx = 0.0
    ty = 0.0
    tz = 0.0
    for e in range(start[i], start[i + 1]):
        c, delta, cfx, cfy, cfz, ctx, cty, ctz = _contact(i, e, xi, yi, zi, x, v, omega, fixed, nbr, hist, stamp,
                                                          now, before, L_x, L_y, hx, hy, law, increment)
        if c == 0:
            if keep:
                _keep(pair, e, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            continue
        contacts += 1
        if delta > deepest:
            deepest = delta
        fx, fy, fz, tx, ty, tz = _added(friction, fx, fy, fz, tx, ty, tz, cfx, cfy, cfz, ctx, cty, ctz)
        if keep:
            _keep(pair, e, cfx, cfy, cfz, ctx, cty, ctz)
    return _finish_row(i, x, v, omega, f, torque, wall_ds, planes, kinds, law, increment, deepest,
                       fx, fy, fz, tx, ty, tz), contacts


@device
def _finish_row(i, x, v, omega, f, torque, wall_ds, planes, kinds, law, increment, deepest, fx, fy, fz, tx, ty, tz):
    """Row i's contacts with the planes added to its sums of gravity and its entries (fx .. tz), and
    the whole stored in f[i] and torque[i]; returns the largest overlap of the row's entries
    (``deepest`` [d]) and planes but the floor."""
    for k in range(len(kinds)):
        kind = kinds[k]
        rough = kind == PLANE_ROUGH
        if rough:
            ds = (wall_ds[i, 0], wall_ds[i, 1], wall_ds[i, 2])
        else:
            ds = (0.0, 0.0, 0.0)
        delta, pfx, pfy, pfz, ptx, pty, ptz, sx, sy, sz = plane_contact(
            x[i, 0], x[i, 1], x[i, 2], v[i, 0], v[i, 1], v[i, 2], omega[i, 0], omega[i, 1], omega[i, 2], ds,
            planes[k, 0], planes[k, 1], planes[k, 2], planes[k, 3], kind, law, increment)
        if rough:
            wall_ds[i, 0] = sx
            wall_ds[i, 1] = sy
            wall_ds[i, 2] = sz
        if delta > 0.0:
            if kind != PLANE_FLOOR and delta > deepest:
                deepest = delta
            fx = add(fx, pfx)
            fy = add(fy, pfy)
            fz = add(fz, pfz)
            tx = add(tx, ptx)
            ty = add(ty, pty)
            tz = add(tz, ptz)
    f[i, 0] = fx
    f[i, 1] = fy
    f[i, 2] = fz
    torque[i, 0] = tx
    torque[i, 1] = ty
    torque[i, 2] = tz
    return deepest


@device
def _sum_row(i, x, v, omega, f, torque, start, stamp, pair, wall_ds, planes, kinds, now, law, increment):
    """Row i (mobile) of ``row_sums``: gravity and the forces its entries left in ``pair`` (those
    in contact: stamped ``now``), in the entries' order, then the planes; returns the largest
    overlap of its planes but the floor [d]. The sums of ``_force_row``, so its bits."""
    friction = law.mu > 0.0
    fx = law.g_x
    fy = law.g_y
    fz = law.g_z
    tx = 0.0
    ty = 0.0
    tz = 0.0
    for e in range(start[i], start[i + 1]):
        if stamp[e] != now:
            continue
        fx, fy, fz, tx, ty, tz = _added(friction, fx, fy, fz, tx, ty, tz, pair[e, 0], pair[e, 1], pair[e, 2],
                                        pair[e, 3], pair[e, 4], pair[e, 5])
    return _finish_row(i, x, v, omega, f, torque, wall_ds, planes, kinds, law, increment, 0.0, fx, fy, fz, tx, ty, tz)


@cuda.jit
def forces(n_own, x, v, omega, f, torque, fixed, start, nbr, hist, stamp, pair, keep, wall_ds, planes, kinds,
           epoch, L_x, L_y, hx, hy, law, increment, red):
    """Forces (gravity included) and torques on the owned rows, the contact history in place.

    As ``kernels.forces.contact_forces``, then ``plane_forces`` over ``planes`` and ``kinds`` (the
    floor, the wall, a lid: ``planes.arrays``), each row in one thread (any grid: a thread takes rows i,
    i + threads, ...).

    Parameters
    ----------
    start : (n_own + 1,) int64, nbr : (K,) int32
        Full neighbour lists, each row's sorted by partner id (ghost and bed partners included).
    hist : (K, 3) float64, stamp : (K,) uint32
        Each entry's Delta s [d] (the row's view) and the evaluation it was last in contact
        (mod 2**32); a contact whose stamp is not ``epoch - 1`` starts from zero.
    pair : (K, 6) float64, out when ``keep``
        Each entry's contact force on the row [m g] and torque [m g d] (zeros out of contact).
    wall_ds : (n_own, 3) float64
        Each row's Delta s with the rough plane [d] (read and written only with one).
    planes : (P, 4) float64, kinds : (P,) int64
        The planes' normals and offsets [d] and kinds (``law.PLANE_*``).
    red : (RED_SLOTS,) float64
        The step's reductions: the largest overlap [d] (RED_OVERLAP) and the contacts of the
        owned mobile rows (RED_CONTACTS); the slots of ``kick_drift`` are set to ``NEUTRAL``. With
        ``red[RED_OVERFLOW]`` set (a list rebuild on the GPU out of room) the kernel does nothing;
        so do ``entry_forces`` and ``row_sums``.
    """
    if _overflowed(red):
        return
    room = cuda.shared.array(BLOCK_MAX, np.float64)
    _reset_drift_slots(red)
    _force_phase(n_own, x, v, omega, f, torque, fixed, start, nbr, hist, stamp, pair, keep, wall_ds, planes, kinds,
                 np.uint32(epoch & 0xFFFFFFFF), np.uint32((epoch - 1) & 0xFFFFFFFF), L_x, L_y, hx, hy, law,
                 increment, red, room, False, False, (x, v, omega), x, red)


@device_cuda
def _force_phase(n_own, x, v, omega, f, torque, fixed, start, nbr, hist, stamp, pair, keep, wall_ds, planes, kinds,
                 now, before, L_x, L_y, hx, hy, law, increment, red, room, fused, then, nxt, x_ref, drec):
    """This thread's rows of ``forces`` (i, i + threads, ...) with the stamps ``now`` and ``before``,
    their reductions into ``red``'s slots RED_OVERLAP and RED_CONTACTS (every thread of the block
    calls it). With ``then`` each row is then kicked and drifted into ``nxt`` (the next step's drift,
    ``advance``'s fused drift: x_ref the lists' positions, the reductions into ``drec``)."""
    deepest = 0.0
    contacts = 0
    d2 = 0.0
    z_lo = math.inf
    z_hi = -math.inf
    bad = 0
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        if fixed[i]:
            for a in range(3):
                f[i, a] = 0.0
                torque[i, a] = 0.0
            continue
        d, c = _force_row(i, x, v, omega, f, torque, fixed, start, nbr, hist, stamp, pair, keep, wall_ds, planes,
                          kinds, now, before, L_x, L_y, hx, hy, law, increment)
        deepest = max(deepest, d)
        contacts += c
        if then:
            d2, z_lo, z_hi, bad = _drift_row(i, x, v, omega, nxt, f, torque, x_ref, law.dt, L_x, L_y, hx, hy, True,
                                             d2, z_lo, z_hi, bad)
    _contact_reduce(red, deepest, contacts, room, fused)
    if then:
        _drift_reduce(drec, d2, z_lo, z_hi, bad, room, fused)


@device_cuda
def _contact_reduce(red, deepest, contacts, room, fused):
    """This thread's largest overlap and contact count into ``red``'s slots RED_OVERLAP and RED_CONTACTS
    (every thread of the block calls it); ``fused``: one tree (``reduce.contact_into``), or with 2 (``WARP``)
    warp shuffles (``reduce.contact_into_warp``)."""
    if fused == WARP:
        contact_into_warp(red, RED_OVERLAP, deepest, RED_CONTACTS, contacts, room)
    elif fused:
        contact_into(red, RED_OVERLAP, deepest, RED_CONTACTS, contacts, room)
    else:
        max_into(red, RED_OVERLAP, deepest, room)
        sum_into(red, RED_CONTACTS, contacts, room)


@device
def _shfl_contact(mask, src, c, cfx, cfy, cfz, ctx, cty, ctz, friction):
    """Lane ``src``'s entry of the group ``mask`` (one row's lanes, every one calling): (1 if in contact else 0,
    its force [m g] (3) and torque [m g d] (3)); the torque's zeros without ``friction``."""
    ck = shfl(mask, c, src)
    if ck == 0:
        return 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    fx = shfl(mask, cfx, src)
    fy = shfl(mask, cfy, src)
    fz = shfl(mask, cfz, src)
    if not friction:
        return 1, fx, fy, fz, 0.0, 0.0, 0.0
    return 1, fx, fy, fz, shfl(mask, ctx, src), shfl(mask, cty, src), shfl(mask, ctz, src)


@device_cuda
def _lane_phase(n_own, x, v, omega, f, torque, fixed, start, nbr, hist, stamp, wall_ds, planes, kinds, now, before,
                L_x, L_y, hx, hy, law, increment, red, room, fused, then, nxt, x_ref, drec, lanes):
    """``_force_phase`` with ``lanes`` threads a row (engine.gpu_threads = "lanes2" .. "lanes16"; a power of two
    up to 32 that divides the block): the row's lanes compute its entries ``lanes`` at a time, lane k the
    round's k-th, and every lane adds the round's contacts to the row's sums in list order, taking each
    from its lane by a warp shuffle: the order of ``_force_row``'s sums, so its bits. Lane 0 then adds the
    planes, stores the row and drifts it (``then``). A row's lanes are one group of a warp (the block a
    multiple of ``lanes``), which share the row's loop bounds and so reach every shuffle together.
    Every thread of the block calls it; the arguments as ``_force_phase``'s (no ``pair``: the launches keep
    no entry's force)."""
    first = cuda.grid(1)
    lane = first % lanes
    # the lanes of this thread's group within its warp
    mask = ((1 << lanes) - 1) << (cuda.laneid - lane)
    base = cuda.laneid - lane
    friction = law.mu > 0.0
    deepest = 0.0
    contacts = 0
    d2 = 0.0
    z_lo = math.inf
    z_hi = -math.inf
    bad = 0
    for i in range(first // lanes, n_own, cuda.gridsize(1) // lanes):
        if fixed[i]:
            if lane == 0:
                for a in range(3):
                    f[i, a] = 0.0
                    torque[i, a] = 0.0
            continue
        xi = x[i, 0]
        yi = x[i, 1]
        zi = x[i, 2]
        fx = law.g_x
        fy = law.g_y
        fz = law.g_z
        tx = 0.0
        ty = 0.0
        tz = 0.0
        end = start[i + 1]
        for e0 in range(start[i], end, lanes):
            e = e0 + lane
            c = 0
            cfx = cfy = cfz = ctx = cty = ctz = 0.0
            if e < end:
                c, delta, cfx, cfy, cfz, ctx, cty, ctz = _contact(i, e, xi, yi, zi, x, v, omega, fixed, nbr, hist,
                                                                  stamp, now, before, L_x, L_y, hx, hy, law, increment)
                if c:
                    contacts += 1
                    deepest = max(deepest, delta)
            for k in range(min(lanes, end - e0)):
                ck, kfx, kfy, kfz, ktx, kty, ktz = _shfl_contact(mask, base + k, c, cfx, cfy, cfz, ctx, cty, ctz,
                                                                 friction)
                if ck:
                    fx, fy, fz, tx, ty, tz = _added(friction, fx, fy, fz, tx, ty, tz, kfx, kfy, kfz, ktx, kty, ktz)
        if lane == 0:
            deepest = max(deepest, _finish_row(i, x, v, omega, f, torque, wall_ds, planes, kinds, law, increment, 0.0,
                                               fx, fy, fz, tx, ty, tz))
            if then:
                d2, z_lo, z_hi, bad = _drift_row(i, x, v, omega, nxt, f, torque, x_ref, law.dt, L_x, L_y, hx, hy,
                                                 True, d2, z_lo, z_hi, bad)
    _contact_reduce(red, deepest, contacts, room, fused)
    if then:
        _drift_reduce(drec, d2, z_lo, z_hi, bad, room, fused)


@cuda.jit
def entry_forces(n_entries, row, x, v, omega, fixed, nbr, hist, stamp, pair, keep, epoch, L_x, L_y, hx, hy, law,
                 increment, red):
    """The first half of ``forces`` a thread an entry: each entry's contact force and torque on its
    row into ``pair`` (and its history, in place); ``row_sums`` then sums them a thread a row.

    ``row`` (K,) int32: each entry's row. ``pair`` (K, 6) float64 holds every entry in contact
    (stamped with this evaluation), every entry with ``keep`` (zeros out of contact). Reduces the
    largest overlap [d] (RED_OVERLAP) and the contacts (RED_CONTACTS) into ``red``; sets the slots
    of ``kick_drift`` to ``NEUTRAL``. Other arguments as ``forces``'s; any grid.
    """
    if _overflowed(red):
        return
    room = cuda.shared.array(BLOCK_MAX, np.float64)
    _reset_drift_slots(red)
    _entry_phase(n_entries, row, x, v, omega, fixed, nbr, hist, stamp, pair, keep, np.uint32(epoch & 0xFFFFFFFF),
                 np.uint32((epoch - 1) & 0xFFFFFFFF), L_x, L_y, hx, hy, law, increment, red, room, False)


@device_cuda
def _entry_phase(n_entries, row, x, v, omega, fixed, nbr, hist, stamp, pair, keep, now, before, L_x, L_y, hx, hy,
                 law, increment, red, room, fused):
    """This thread's entries of ``entry_forces`` (e, e + threads, ...), their reductions into
    ``red`` (every thread of the block calls it)."""
    deepest = 0.0
    contacts = 0
    for e in range(cuda.grid(1), n_entries, cuda.gridsize(1)):
        c, delta = _entry(row[e], e, x, v, omega, fixed, nbr, hist, stamp, pair, keep, now, before, L_x, L_y, hx, hy,
                          law, increment)
        contacts += c
        deepest = max(deepest, delta)
    _contact_reduce(red, deepest, contacts, room, fused)


@cuda.jit
def row_sums(n_own, x, v, omega, f, torque, fixed, start, stamp, pair, wall_ds, planes, kinds, epoch, law,
             increment, red):
    """The second half of ``forces`` after ``entry_forces``: each owned row's force and torque, a
    thread a row (gravity, its entries' in order, the planes'); the largest plane overlap into
    ``red[RED_OVERLAP]``. Any grid."""
    if _overflowed(red):
        return
    room = cuda.shared.array(BLOCK_MAX, np.float64)
    _sum_phase(n_own, x, v, omega, f, torque, fixed, start, stamp, pair, wall_ds, planes, kinds,
               np.uint32(epoch & 0xFFFFFFFF), law, increment, red, room, False, (x, v, omega), x, 0.0, 0.0, 0.0, 0.0,
               red, False)


@device_cuda
def _sum_phase(n_own, x, v, omega, f, torque, fixed, start, stamp, pair, wall_ds, planes, kinds, now, law, increment,
               red, room, then, nxt, x_ref, L_x, L_y, hx, hy, drec, fused):
    """This thread's rows of ``row_sums`` (i, i + threads, ...) and their reduction (every thread of
    the block calls it); ``then`` ... ``fused`` as ``_force_phase``'s (the box L_x .. hy [d] for the
    drift)."""
    deepest = 0.0
    d2 = 0.0
    z_lo = math.inf
    z_hi = -math.inf
    bad = 0
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        if fixed[i]:
            for a in range(3):
                f[i, a] = 0.0
                torque[i, a] = 0.0
            continue
        deepest = max(deepest, _sum_row(i, x, v, omega, f, torque, start, stamp, pair, wall_ds, planes, kinds, now,
                                        law, increment))
        if then:
            d2, z_lo, z_hi, bad = _drift_row(i, x, v, omega, nxt, f, torque, x_ref, law.dt, L_x, L_y, hx, hy, True,
                                             d2, z_lo, z_hi, bad)
    max_into(red, RED_OVERLAP, deepest, room)
    if then:
        _drift_reduce(drec, d2, z_lo, z_hi, bad, room, fused)


@device_cuda
def _go_on(red, half_skin, room):
    """Whether every row of ``red``'s step moved less than ``half_skin`` [d] since ``x_ref`` with a
    finite position; the same answer in every thread. The block's first thread reads the step's
    reductions through atomics (from the GPU's L2 cache, where the blocks' atomics left them) and
    hands them on through ``room``."""
    t = cuda.threadIdx.x
    if t == 0:
        room[0] = cuda.atomic.add(red, RED_BAD, 0.0)
        room[1] = cuda.atomic.max(red, RED_D2, 0.0)
    cuda.syncthreads()
    go = room[0] == 0.0 and sqrt(room[1]) < half_skin
    cuda.syncthreads()
    return go


@device_cuda
def _why(red, half_skin, room):
    """``_go_on`` with the reason when not: 0 go on, 1 a row moved ``half_skin`` [d] or more since x_ref (the
    lists must be rebuilt), 2 a position is not finite; the same answer in every thread."""
    t = cuda.threadIdx.x
    if t == 0:
        room[0] = cuda.atomic.add(red, RED_BAD, 0.0)
        room[1] = cuda.atomic.max(red, RED_D2, 0.0)
    cuda.syncthreads()
    why = 2 if room[0] != 0.0 else (0 if sqrt(room[1]) < half_skin else 1)
    cuda.syncthreads()
    return why


@cuda.jit
def advance(n_own, x, v, omega, f, torque, fixed, x_ref, start, nbr, hist, stamp, pair, wall_ds, planes, kinds,
            epoch, L_x, L_y, hx, hy, law, pending, half_skin, n_steps, rec, by_entry, n_entries, row, fused,
            xb, vb, wb, one):
    """Up to ``n_steps`` whole steps in one launch (a cooperative grid: every block resident, the
    phases parted by grid-wide barriers), as ``kick_drift`` then ``forces`` once a step.

    Step s: the half-kicks and drift (the previous step's second half-kick first, from the
    second step on, or with ``pending``), the step's reductions into ``rec[s]`` (the slots of
    ``NEUTRAL``); then, unless a row moved ``half_skin`` [d] or more since ``x_ref`` (the lists
    must be rebuilt first) or a position is not finite, the forces of evaluation ``epoch + s + 1``.
    A step that needs a rebuild ends the launch after its drift: the rows of steps 0..s-1 are
    whole, step s has drifted, and its ``rec[s]`` says why (the caller finishes it). ``rec`` is
    (>= n_steps, 6) float64; its rows are set to ``NEUTRAL`` here. With ``by_entry`` the forces are
    ``entry_forces`` then ``row_sums`` (``pair`` has room for every one of the ``n_entries``
    entries, ``row`` their rows), a grid barrier between. With ``fused`` each phase's reductions take
    one tree (``reduce.drift_into``, ``reduce.contact_into``) instead of one a value. With ``one``
    (``advance_one``, ``pinned_advance``; ``advance`` itself ignores it and compiles without its code)
    the next step's half-kicks and drift are done by the thread that has just summed a row's forces
    (one grid barrier a step fewer): the rows then alternate between x, v, omega and xb, vb, wb (arrays
    shaped as x), the step's forces reading one while the drift writes the other, and end in x, v,
    omega. The same results, so the same bits.
    """
    room = cuda.shared.array(ROOM, np.float64)
    # ``one`` as a constant: the fused drift's code is not in this kernel (``advance_one`` has it); nor is a
    # rebuild's (``advance_lists`` has it)
    _steps(n_own, x, v, omega, f, torque, fixed, x_ref, start, nbr, hist, stamp, pair, wall_ds, planes, kinds, epoch,
           L_x, L_y, hx, hy, law, pending, half_skin, n_steps, rec, n_entries, row, (xb, vb, wb), by_entry, fused,
           False, room, False, _no_lists(start, nbr, hist, stamp, x_ref, fixed), 0, 0)


@cuda.jit
def advance_one(n_own, x, v, omega, f, torque, fixed, x_ref, start, nbr, hist, stamp, pair, wall_ds, planes, kinds,
                epoch, L_x, L_y, hx, hy, law, pending, half_skin, n_steps, rec, by_entry, n_entries, row, fused,
                xb, vb, wb, one):
    """``advance`` with ``one`` true whatever the argument says (the next step's drift fused into the forces'
    phase; engine.gpu_drift = "fused")."""
    room = cuda.shared.array(ROOM, np.float64)
    _steps(n_own, x, v, omega, f, torque, fixed, x_ref, start, nbr, hist, stamp, pair, wall_ds, planes, kinds, epoch,
           L_x, L_y, hx, hy, law, pending, half_skin, n_steps, rec, n_entries, row, (xb, vb, wb), by_entry, fused,
           True, room, False, _no_lists(start, nbr, hist, stamp, x_ref, fixed), 0, 0)


def _lists_kernel(sort_on, by_entry, name, doc):
    """``advance`` (``one`` read from its argument) with up to ``budget`` list rebuilds inside the launch
    (engine.gpu_rebuild = "launch"), a thread a row or (``by_entry``) a thread an entry; the kernel ``name``.

    A step whose drift moved a row ``half_skin`` [d] or more since ``x_ref`` rebuilds the lists as phases of
    the launch (``lists.rebuild_phases``) and goes on, its forces from the new lists; the lists alternate
    between (start, nbr, hist, stamp) and (start2, nbr2, hist2, stamp2), the second set's from the first
    rebuild's. ``rec`` is (>= n_steps, RED_SLOTS): each step's rec[s, RED_ENTRIES] is the entries of the
    lists it built (-1.0: none). The launch ends, as ``advance``'s, at a step that needs a rebuild past
    ``budget`` or whose lists do not fit their set's capacity (rec[s, RED_OVERFLOW] = 1.0, rec[s,
    RED_ENTRIES] the entries they need: the current lists are untouched). ``ids`` (n_own,) int64; ``zr`` ..
    ``order`` and ``nx`` .. ``r2`` as ``rebuild_phases``'s ``cells`` and ``grid_shape``. The argument
    ``sort_on`` is not read: with the factory's ``sort_on`` (engine.gpu_sort = "device") every ``every``-th
    rebuild (counting ``done`` before the launch) orders the rows by cell first (``lists.sort_phases``, its
    spares ``sx`` .. ``smoved``, ``perm`` and the columns ``col_*``; ``moved`` (n,) int32 each row's row in
    the host's State, permuted with the rows; the rows put back and the launch ended if the lists then do not
    fit), and without it that code is not compiled in. With ``by_entry`` (engine.gpu_threads = "entry")
    ``n_entries`` is the current lists' entries and ``row`` their rows, with room for the lists' capacity
    (len(nbr2)) as well as for them; a rebuild inside the launch writes the new lists' rows into ``row`` and
    goes on with their entries (``pair`` has room for the capacity too). The same results as the host's
    rebuilds between launches, so the same bits."""
    SORT_ON, BY_ENTRY = bool(sort_on), bool(by_entry)

    def kernel(n_own, x, v, omega, f, torque, fixed, x_ref, start, nbr, hist, stamp, pair, wall_ds, planes, kinds,
               epoch, L_x, L_y, hx, hy, law, pending, half_skin, n_steps, rec, n_entries, row, fused, xb, vb, wb, one,
               ids, zr, count, fill, cell, order, start2, nbr2, hist2, stamp2, nx, ny, nz_cap, cx, cy, r_list, r2,
               budget, sort_on, every, done, moved, sx, sv, sw, sf, st, swall, sfixed, sids, smoved, perm, col_base,
               col_size, col_local):
        room = cuda.shared.array(ROOM, np.float64)
        part = cuda.shared.array(BLOCK_MAX, np.int64)
        lists = (ids, (start2, nbr2, hist2, stamp2), (zr, count, fill, cell, order),
                 (nx, ny, nz_cap, cx, cy, r_list, r2), part,
                 (SORT_ON, every, done, moved, (sx, sv, sw, sf, st, swall, sfixed, sids, smoved), perm,
                  (col_base, col_size, col_local)))
        _steps(n_own, x, v, omega, f, torque, fixed, x_ref, start, nbr, hist, stamp, pair, wall_ds, planes, kinds,
               epoch, L_x, L_y, hx, hy, law, pending, half_skin, n_steps, rec, n_entries, row, (xb, vb, wb), BY_ENTRY,
               fused, one, room, True, lists, budget, 0)
    kernel.__name__ = kernel.__qualname__ = name
    kernel.__doc__ = doc
    return cuda.jit(kernel)


# the four of ``_lists_kernel`` (engine.gpu_rebuild = "launch", not pinned)
advance_lists = _lists_kernel(False, False, "advance_lists", "``_lists_kernel``'s: a thread a row, no ordering "
                              "of the rows inside the launch.")
advance_lists_sorted = _lists_kernel(True, False, "advance_lists_sorted", "``_lists_kernel``'s: a thread a row, "
                                     "every ``every``-th rebuild ordering the rows (engine.gpu_sort = \"device\").")
advance_lists_entry = _lists_kernel(False, True, "advance_lists_entry", "``_lists_kernel``'s: a thread an entry "
                                    "(engine.gpu_threads = \"entry\").")
advance_lists_entry_sorted = _lists_kernel(True, True, "advance_lists_entry_sorted", "``_lists_kernel``'s: a thread "
                                           "an entry, every ``every``-th rebuild ordering the rows.")


@device
def _no_lists(start, nbr, hist, stamp, x_ref, fixed):
    """``_steps``'s ``lists`` where no rebuild is compiled in: arrays of the right kinds, never read."""
    return (start, (start, nbr, hist, stamp), (x_ref[0], nbr, nbr, nbr, nbr), (1, 1, 1, 1.0, 1.0, 1.0, 1.0), start,
            (False, 1, 0, nbr, (x_ref, x_ref, x_ref, x_ref, x_ref, x_ref, fixed, start, nbr), nbr,
             (start, start, start)))


# the kernels ``pinned_advance`` made, by their constants
_PINNED = {}


def pinned_advance(by_entry, fused, one, model, friction, limit_damping, rescale_history, rebuild=0, lanes=0):
    """``advance`` compiled for one run's options (``engine.gpu_pinned``; docs/gpu.md): the forces' layout
    (``by_entry``), the reductions (``fused``), the drift (``one``) and the law's
    model, whether it has friction, ``limit_damping`` and ``rescale_history`` as constants of the
    code, so that the compiler drops the branches the run never takes (and their registers). Its
    arguments are ``advance``'s; those it was made for are read from the constants, the law's
    numbers (k_n .. dt, ds_scale) from ``law``. Only for a law with those options (``Engine`` makes
    the key from its own law); the same arithmetic, so the same bits. One kernel a set of constants. With
    ``rebuild`` 1 it is ``advance_lists`` so compiled, 2 ``advance_lists_sorted`` (with ``by_entry``:
    ``advance_lists_entry``, ``advance_lists_entry_sorted``), with ``advance_lists``'s arguments. ``lanes`` (2 to
    32, a power of two; 0 none): the forces with that many threads a row (``_lane_phase``; engine.gpu_threads =
    "lanesL"), ``by_entry`` false; the grid then ``lanes`` threads a row. ``fused`` 0, 1 or ``WARP``
    (2: the reductions by warp shuffles, engine.gpu_reductions = "warp")."""
    key = (bool(by_entry), int(fused), bool(one), int(model), bool(friction), bool(limit_damping),
           bool(rescale_history), int(rebuild), int(lanes))
    if key in _PINNED:
        return _PINNED[key]
    BY_ENTRY, FUSED, ONE, MODEL, FRICTION, LIMIT, RESCALE, REBUILD, LANES = key
    if LANES and (BY_ENTRY or LANES & (LANES - 1) or not 2 <= LANES <= 32):
        raise ValueError(f"lanes = {LANES} (by_entry {BY_ENTRY}): accepted 0, or a power of two from 2 to 32 "
                         "without by_entry")
    if REBUILD:
        SORTED = REBUILD == 2

        def pinned_lists(n_own, x, v, omega, f, torque, fixed, x_ref, start, nbr, hist, stamp, pair, wall_ds, planes,
                         kinds, epoch, L_x, L_y, hx, hy, law, pending, half_skin, n_steps, rec, n_entries, row,
                         fused, xb, vb, wb, one, ids, zr, count, fill, cell, order, start2, nbr2, hist2,
                         stamp2, nx, ny, nz_cap, cx, cy, r_list, r2, budget, sort_on, every, done, moved, sx, sv, sw,
                         sf, st, swall, sfixed, sids, smoved, perm, col_base, col_size, col_local):
            room = cuda.shared.array(ROOM, np.float64)
            part = cuda.shared.array(BLOCK_MAX, np.int64)
            constant = Law(law.k_n, law.k_t, law.gamma_n, law.gamma_t, law.mu if FRICTION else 0.0, law.g_x, law.g_y,
                           law.g_z, law.dt, MODEL, LIMIT, RESCALE, law.ds_scale)
            lists = (ids, (start2, nbr2, hist2, stamp2), (zr, count, fill, cell, order),
                     (nx, ny, nz_cap, cx, cy, r_list, r2), part,
                     (SORTED, every, done, moved, (sx, sv, sw, sf, st, swall, sfixed, sids, smoved), perm,
                      (col_base, col_size, col_local)))
            _steps(n_own, x, v, omega, f, torque, fixed, x_ref, start, nbr, hist, stamp, pair, wall_ds, planes, kinds,
                   epoch, L_x, L_y, hx, hy, constant, pending, half_skin, n_steps, rec, n_entries, row, (xb, vb, wb),
                   BY_ENTRY, FUSED, ONE, room, True, lists, budget, LANES)
        pinned_lists.__name__ = pinned_lists.__qualname__ = ("advance_lists_entry_pinned" if BY_ENTRY else
                                                             f"advance_lists_lanes{LANES}_pinned" if LANES else
                                                             "advance_lists_pinned")
        _PINNED[key] = cuda.jit(pinned_lists)
    else:
        def pinned(n_own, x, v, omega, f, torque, fixed, x_ref, start, nbr, hist, stamp, pair, wall_ds, planes, kinds,
                   epoch, L_x, L_y, hx, hy, law, pending, half_skin, n_steps, rec, by_entry, n_entries, row, fused, xb,
                   vb, wb, one):
            room = cuda.shared.array(ROOM, np.float64)
            constant = Law(law.k_n, law.k_t, law.gamma_n, law.gamma_t, law.mu if FRICTION else 0.0, law.g_x, law.g_y,
                           law.g_z, law.dt, MODEL, LIMIT, RESCALE, law.ds_scale)
            _steps(n_own, x, v, omega, f, torque, fixed, x_ref, start, nbr, hist, stamp, pair, wall_ds, planes, kinds,
                   epoch, L_x, L_y, hx, hy, constant, pending, half_skin, n_steps, rec, n_entries, row, (xb, vb, wb),
                   BY_ENTRY, FUSED, ONE, room, False, _no_lists(start, nbr, hist, stamp, x_ref, fixed), 0, LANES)
        pinned.__name__ = pinned.__qualname__ = f"advance_lanes{LANES}_pinned" if LANES else "advance_pinned"
        _PINNED[key] = cuda.jit(pinned)
    return _PINNED[key]


@device_cuda
def _neutral(rec, s, n_steps):
    """rec[s] = NEUTRAL if s < n_steps, by the grid's first thread; in a row of RED_SLOTS, no rebuild."""
    if cuda.grid(1) == 0 and s < n_steps:
        for a in range(6):
            rec[s, a] = NEUTRAL[a]
        if rec.shape[1] >= RED_SLOTS:
            rec[s, RED_ENTRIES] = -1.0
            rec[s, RED_OVERFLOW] = 0.0


@device_cuda
def _steps(n_own, x, v, omega, f, torque, fixed, x_ref, start, nbr, hist, stamp, pair, wall_ds, planes, kinds, epoch,
           L_x, L_y, hx, hy, law, pending, half_skin, n_steps, rec, n_entries, row, nxt, by_entry, fused, one,
           room, rebuild, lists, budget, lanes):
    """``advance``'s steps (every thread of the grid calls it; ``room`` the block's (ROOM,) float64 shared
    room, ``nxt`` the tuple (xb, vb, wb)): the other arguments as ``advance``'s. With ``rebuild`` (a
    constant; ``advance_lists``) up to ``budget`` list rebuilds inside, ``lists`` the tuple (ids, the
    second set of lists, the cells, the grid's shape, the block's int64 shared room) of ``advance_lists``'s
    arguments (with ``by_entry`` each rebuild also writes the new entries' rows into ``row``, whose room is the
    lists' capacity, and takes their count for ``n_entries``); without, ``lists`` is not read. ``lanes`` (a
    constant; 0 but in ``pinned_advance``'s kernels): the forces with that many threads a row
    (``_lane_phase``), else as ``by_entry`` says."""
    grid = cuda.cg.this_grid()
    first = cuda.grid(1)
    here = (x, v, omega)
    # the lists in ``lists``'s second set (after an odd number of rebuilds here)
    flip = False
    # the rebuilds so far in this launch, and before it since the last ordering of the rows (``lists``'s)
    done = lists[5][2]
    if one:
        # the rows no drift writes (the bed's) in the other buffer as well
        for i in range(first, x.shape[0], cuda.gridsize(1)):
            for a in range(3):
                nxt[0][i, a] = x[i, a]
                nxt[1][i, a] = v[i, a]
                nxt[2][i, a] = omega[i, a]
    _neutral(rec, 0, n_steps)
    grid.sync()
    odd = False
    for s in range(n_steps):
        if s == 0 or not one:
            _drift_phase(n_own, x, v, omega, f, torque, fixed, x_ref, law.dt, L_x, L_y, hx, hy, pending or s > 0,
                         rec[s], room, fused)
            _neutral(rec, s + 1, n_steps)
            grid.sync()
        xs, vs, ws = nxt if odd else here
        if rebuild:
            why = _why(rec[s], half_skin, room)
            if why == 2 or (why == 1 and budget == 0):
                break
            if why == 1:
                ids, second, cells, shape, part, order = lists
                sort_on, every, _, moved, spares, perm, columns = order
                cur = second if flip else (start, nbr, hist, stamp)
                new = (start, nbr, hist, stamp) if flip else second
                stale = np.uint32((epoch + s - 1) & 0xFFFFFFFF)
                if sort_on and done % every == 0:
                    # this rebuild orders the rows by cell first (``lists.sort_phases``): the lists built from
                    # the rows in their new order, the ids in theirs (spares[7]) until the old lists are read
                    other = here if odd else nxt
                    rows = (xs, vs, ws, f, torque, wall_ds, fixed, ids, moved, other[0], other[1], other[2])
                    sort_phases(n_own, rows, spares, perm, cells, shape, columns, room, part, False)
                    if not rebuild_phases(n_own, xs, x_ref, spares[7], fixed, L_x, L_y, hx, hy, cur, new, stale, cells,
                                          shape, rec[s], room, part, ids, perm, True):
                        # no room: the rows back where they were, the launch ends at this step
                        sort_phases(n_own, rows, spares, perm, cells, shape, columns, room, part, True)
                        break
                    for i in range(first, n_own, cuda.gridsize(1)):
                        ids[i] = spares[7][i]
                    grid.sync()
                elif not rebuild_phases(n_own, xs, x_ref, ids, fixed, L_x, L_y, hx, hy, cur, new, stale, cells, shape,
                                        rec[s], room, part, ids, perm, False):
                    break
                flip = not flip
                budget -= 1
                done += 1
                if by_entry:
                    # a thread an entry: each new entry's row, into ``row`` (room for the lists' capacity, one array
                    # for both sets: the old lists' rows are not read again), and the new lists' entries
                    ns = new[0]
                    for i in range(first, n_own, cuda.gridsize(1)):
                        for e in range(ns[i], ns[i + 1]):
                            row[e] = i
                    n_entries = ns[n_own]
                    grid.sync()
        elif not _go_on(rec[s], half_skin, room):
            break
        ls, ln, lh, lt = lists[1] if flip else (start, nbr, hist, stamp)
        now = np.uint32((epoch + s + 1) & 0xFFFFFFFF)
        before = np.uint32((epoch + s) & 0xFFFFFFFF)
        # with ``one``: the forces from one buffer, the next step's drift into the other
        then = one and s + 1 < n_steps
        if then:
            _neutral(rec, s + 2, n_steps)
        there = here if odd else nxt
        drec = rec[s + 1] if then else rec[s]
        if lanes:
            _lane_phase(n_own, xs, vs, ws, f, torque, fixed, ls, ln, lh, lt, wall_ds, planes, kinds, now, before, L_x,
                        L_y, hx, hy, law, True, rec[s], room, fused, then, there, x_ref, drec, lanes)
        elif by_entry:
            _entry_phase(n_entries, row, xs, vs, ws, fixed, ln, lh, lt, pair, False, now, before, L_x, L_y,
                         hx, hy, law, True, rec[s], room, fused)
            grid.sync()
            _sum_phase(n_own, xs, vs, ws, f, torque, fixed, ls, lt, pair, wall_ds, planes, kinds, now, law, True,
                       rec[s], room, then, there, x_ref, L_x, L_y, hx, hy, drec, fused)
        else:
            _force_phase(n_own, xs, vs, ws, f, torque, fixed, ls, ln, lh, lt, pair, False, wall_ds, planes,
                         kinds, now, before, L_x, L_y, hx, hy, law, True, rec[s], room, fused, then, there, x_ref, drec)
        grid.sync()
        if then:
            odd = not odd
    if odd:
        # the last drift wrote ``nxt`` (the barrier after it passed): the rows back where the host reads them
        for i in range(first, n_own, cuda.gridsize(1)):
            for a in range(3):
                x[i, a] = nxt[0][i, a]
                v[i, a] = nxt[1][i, a]
                omega[i, a] = nxt[2][i, a]
