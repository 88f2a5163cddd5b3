"""Contact forces and torques (physics.md section 2).

Each owned mobile particle computes every one of its contacts itself, from a
full neighbour list sorted by partner id, and sums them in that order
(design.md, invariant 1). Its partner computes the mirror view; all operations
are arranged so that the two views are exact negatives in IEEE arithmetic
(raw difference, then minimum image; symmetric sums of partner quantities).

Because the two views are exact negatives, a pair of two owned mobile
particles is computed once, by the first row met, and the second row takes
the stored result negated (``rev`` maps an entry to its mirror entry): the
bits are those of computing both views, at half the cost.

Contact history lives in per-particle slots sorted by partner id: ``old_*``
is read, ``new_*`` is written (double buffering), so a slot overflow can be
repaired by growing the buffers and calling again.
"""
import math

from numba import njit

from .geometry import min_image

R = 0.5          # particle radius [d]
INV_I = 10.0     # 1 / moment of inertia, I = (2/5) m R^2 = 0.1 [m d^2]

MODEL_HOOKE = 0
MODEL_HERTZ = 1


@njit(cache=True, error_model="numpy")
def contact_forces(n_own, x, v, omega, fixed, ids, nbr_start, nbr_list, rev,
                   pair_on, pair_val,
                   old_n, old_id, old_ds, new_n, new_id, new_ds, f, torque,
                   L_x, L_y, gravity, k_n, k_t, gamma_n, gamma_t, mu,
                   model, limit_damping, rescale_history, dt, increment):
    """Forces and torques on owned rows, updating the contact slots.

    Parameters
    ----------
    n_own : int
        Owned rows ``0..n_own-1`` get forces; other rows are read-only ghosts.
    x, v, omega : (n_rows, 3) float64
        Position [d], velocity [sqrt(g d)], angular velocity [sqrt(g/d)];
        v and omega are the half-step values of velocity Verlet.
    fixed : (n_rows,) uint8
        1 for bed particles (never moved; zero force and torque here).
    ids : (n_rows,) int64
        Particle ids.
    nbr_start, nbr_list : int64 arrays
        Full neighbour lists in CSR form, each sorted by partner id.
    rev : (len(nbr_list),) int64
        Mirror entry of each entry (``mirror_entries``); -1 for ghost or bed
        partners. All -1 computes every view itself (same bits, twice the work).
    pair_on : (len(nbr_list),) uint8, pair_val : (len(nbr_list), 9) float64
        Scratch: the result of a pair computed by its first row (contact
        flag; force, torque and Delta s of that row).
    old_n, old_id, old_ds : (n_rows,), (n_rows, C), (n_rows, C, 3)
        Contact slots before this step: count, partner ids (ascending),
        tangential displacement Delta s [d].
    new_n, new_id, new_ds : same shapes, out
        Contact slots after this step.
    f, torque : (n_rows, 3) float64, out
        Force [m g] including gravity, torque [m g d].
    L_x, L_y, gravity : float
    k_n, k_t : float
        Spring constants [m g / d].
    gamma_n, gamma_t : float
        Damping rates [sqrt(g/d)].
    mu : float
        Coulomb friction coefficient.
    model : int
        MODEL_HOOKE or MODEL_HERTZ.
    limit_damping, rescale_history : bool
        Options of physics.md 2.2 and 2.4 (both off in the reference model).
    dt : float
        Time step [tau].
    increment : bool
        False on the set-up evaluation at t = 0 (no history increment).

    Returns
    -------
    max_overlap : float
        Largest overlap delta [d] over owned contacts.
    n_contacts : int
        Contacts counted from owned mobile particles (bed partners included).
    needed : int
        Largest slot count any particle needed; above C the slots overflowed
        and nothing should be used: grow C and call again.
    """
    cap = new_id.shape[1]
    hx = 0.5 * L_x
    hy = 0.5 * L_y
    max_overlap = 0.0
    n_contacts = 0
    needed = 0
    for i in range(n_own):
        if fixed[i]:
            for a in range(3):
                f[i, a] = 0.0
                torque[i, a] = 0.0
            new_n[i] = 0
            continue
        fx = 0.0
        fy = 0.0
        fz = -gravity
        tx = 0.0
        ty = 0.0
        tz = 0.0
        p = 0
        n_old = old_n[i]
        c = 0
        for k in range(nbr_start[i], nbr_start[i + 1]):
            j = nbr_list[k]
            m = rev[k]
            if m >= 0 and j < i:
                # the partner computed this pair already: take its view negated
                if pair_on[m]:
                    if c < cap:
                        new_id[i, c] = ids[j]
                        new_ds[i, c, 0] = -pair_val[m, 6]
                        new_ds[i, c, 1] = -pair_val[m, 7]
                        new_ds[i, c, 2] = -pair_val[m, 8]
                    c += 1
                    fx += -pair_val[m, 0]
                    fy += -pair_val[m, 1]
                    fz += -pair_val[m, 2]
                    tx += pair_val[m, 3]
                    ty += pair_val[m, 4]
                    tz += pair_val[m, 5]
                continue
            dx = min_image(x[i, 0] - x[j, 0], L_x, hx)
            dy = min_image(x[i, 1] - x[j, 1], L_y, hy)
            dz = x[i, 2] - x[j, 2]
            r2 = dx * dx + dy * dy + dz * dz
            if not r2 < 1.0:
                if m >= 0:
                    pair_on[k] = 0
                continue
            r = math.sqrt(r2)
            delta = 1.0 - r
            if delta > max_overlap:
                max_overlap = delta
            rinv = 1.0 / r
            nx = dx * rinv
            ny = dy * rinv
            nz = dz * rinv
            meff = 1.0 if fixed[j] else 0.5
            vrx = v[i, 0] - v[j, 0]
            vry = v[i, 1] - v[j, 1]
            vrz = v[i, 2] - v[j, 2]
            vn = vrx * nx + vry * ny + vrz * nz
            # R_i omega_i + R_j omega_j: a symmetric sum, the same in both views
            wx = R * omega[i, 0] + R * omega[j, 0]
            wy = R * omega[i, 1] + R * omega[j, 1]
            wz = R * omega[i, 2] + R * omega[j, 2]
            vtx = vrx - vn * nx - (wy * nz - wz * ny)
            vty = vry - vn * ny - (wz * nx - wx * nz)
            vtz = vrz - vn * nz - (wx * ny - wy * nx)
            scale = math.sqrt(delta) if model == MODEL_HERTZ else 1.0
            fn = scale * (k_n * delta - meff * gamma_n * vn)
            if limit_damping and fn < 0.0:
                fn = 0.0
            fn_mag = abs(fn)

            # history of this pair: both slot lists are in ascending partner id
            jid = ids[j]
            while p < n_old and old_id[i, p] < jid:
                p += 1
            sx = 0.0
            sy = 0.0
            sz = 0.0
            ftx = 0.0
            fty = 0.0
            ftz = 0.0
            if mu > 0.0:
                if p < n_old and old_id[i, p] == jid:
                    sx = old_ds[i, p, 0]
                    sy = old_ds[i, p, 1]
                    sz = old_ds[i, p, 2]
                s_old = 0.0
                if rescale_history:
                    s_old = math.sqrt(sx * sx + sy * sy + sz * sz)
                if increment:
                    sx += vtx * dt
                    sy += vty * dt
                    sz += vtz * dt
                sn = sx * nx + sy * ny + sz * nz
                sx -= sn * nx
                sy -= sn * ny
                sz -= sn * nz
                if rescale_history:
                    s_new = math.sqrt(sx * sx + sy * sy + sz * sz)
                    if s_new > 0.0 and s_old > 0.0:
                        q = s_old / s_new
                        sx *= q
                        sy *= q
                        sz *= q
                ftx = -scale * (k_t * sx + meff * gamma_t * vtx)
                fty = -scale * (k_t * sy + meff * gamma_t * vty)
                ftz = -scale * (k_t * sz + meff * gamma_t * vtz)
                ft_mag = math.sqrt(ftx * ftx + fty * fty + ftz * ftz)
                bound = mu * fn_mag
                if ft_mag > bound:
                    if sx == 0.0 and sy == 0.0 and sz == 0.0:
                        ftx = 0.0
                        fty = 0.0
                        ftz = 0.0
                    else:
                        s = bound / ft_mag
                        ftx *= s
                        fty *= s
                        ftz *= s
                        if k_t > 0.0:
                            # history that reproduces the truncated force exactly
                            cg = meff * gamma_t / k_t
                            sx = s * (sx + cg * vtx) - cg * vtx
                            sy = s * (sy + cg * vty) - cg * vty
                            sz = s * (sz + cg * vtz) - cg * vtz
                        else:
                            sx *= s
                            sy *= s
                            sz *= s
            if c < cap:
                new_id[i, c] = jid
                new_ds[i, c, 0] = sx
                new_ds[i, c, 1] = sy
                new_ds[i, c, 2] = sz
            c += 1
            fcx = fn * nx + ftx
            fcy = fn * ny + fty
            fcz = fn * nz + ftz
            # T_i += -R n x F_t (the same for both partners)
            tcx = -(R * (ny * ftz - nz * fty))
            tcy = -(R * (nz * ftx - nx * ftz))
            tcz = -(R * (nx * fty - ny * ftx))
            fx += fcx
            fy += fcy
            fz += fcz
            tx += tcx
            ty += tcy
            tz += tcz
            if m >= 0:
                pair_on[k] = 1
                pair_val[k, 0] = fcx
                pair_val[k, 1] = fcy
                pair_val[k, 2] = fcz
                pair_val[k, 3] = tcx
                pair_val[k, 4] = tcy
                pair_val[k, 5] = tcz
                pair_val[k, 6] = sx
                pair_val[k, 7] = sy
                pair_val[k, 8] = sz
        f[i, 0] = fx
        f[i, 1] = fy
        f[i, 2] = fz
        torque[i, 0] = tx
        torque[i, 1] = ty
        torque[i, 2] = tz
        new_n[i] = min(c, cap)
        n_contacts += c
        if c > needed:
            needed = c
    return max_overlap, n_contacts, needed


@njit(cache=True)
def floor_forces(n_own, x, v, fixed, f, k_n, gamma_n):
    """Add a flat frictionless floor at z = 0 (only for building the bed).

    Hookean normal force k_n delta - m gamma_n v_z on owned mobile rows with
    delta = R - z > 0 (m_eff = m, as for any fixed partner).
    """
    for i in range(n_own):
        if fixed[i]:
            continue
        delta = R - x[i, 2]
        if delta > 0.0:
            f[i, 2] += k_n * delta - gamma_n * v[i, 2]
