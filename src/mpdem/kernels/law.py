"""The contact law and the integrator's updates, written once for both engines (docs/model.md 2, 4.1).

Each function here is the arithmetic of one part of the model on scalars: the
overlap and normal of a pair, its relative velocities, the normal force
(Hooke or Hertz), the tangential history and the Coulomb cap, a plane's slip,
the force and torque a contact applies, and the half-kick and drift of
velocity Verlet. The CPU kernels (``forces``, ``integrate``) call them as
numba functions inlined where they are called; the GPU kernels
(``kernels/gpu``) call twins made from the same source with every float64
add, multiply, divide and square root an explicitly rounded operation
(``gpu/rounded.py``), so that the GPU compilers cannot fuse a multiply and
an add into one FMA and both engines give the same bits
(docs/computing.md, "One law, two targets").

Rules for this file: scalars and tuples of scalars in and out, no arrays,
no loops; a function may call the functions above it; float arithmetic
only through the operators ``+ - * /``, ``math.sqrt``, ``abs`` and unary
minus (the twins translate those and nothing else: an integer operation
would be translated too, so none appears here).
"""
import math
from typing import NamedTuple

from numba import njit

from .models import MODELS
from .particle import INV_I, R

# the kernels' ids of the models whose forces they branch on (models.MODELS)
MODEL_HOOKE = MODELS["hooke"].kernel
MODEL_HERTZ = MODELS["hertz"].kernel
# the kinds of plane (planes.Plane): the bed-making floor (a frictionless Hookean spring of the pile's
# k_n and gamma_n), a smooth plane (the pile's normal law), a rough one (the pile's law, with history)
PLANE_FLOOR = 0
PLANE_SMOOTH = 1
PLANE_ROUGH = 2
# |F_t|^2 < SURE_STICK bound^2 implies sqrt(|F_t|^2) <= bound in floating point
SURE_STICK = 1.0 - 1e-9


class Law(NamedTuple):
    """The contact law and step, as one record for the kernels (reduced units).

    k_n, k_t : spring constants [m g / d]; gamma_n, gamma_t : damping rates
    [sqrt(g/d)]; mu : Coulomb coefficient; g_x, g_y, g_z : the gravity vector [g] (the force on a
    sphere of mass 1, where each row's force sum starts); dt : time step [tau];
    model : MODEL_HOOKE or MODEL_HERTZ; limit_damping, rescale_history : the
    options of docs/model.md 2.2 and 2.4 (off in the reference model); ds_scale : the factor on
    each stored Delta s before an evaluation, k_t of the previous evaluation / this one's (1.0 but
    at a step of the stiffening ramp, ``stiffen``: F_t = -k_t Delta s stays continuous; x * 1.0
    is x to the bit).
    """
    k_n: float
    k_t: float
    gamma_n: float
    gamma_t: float
    mu: float
    g_x: float
    g_y: float
    g_z: float
    dt: float
    model: int
    limit_damping: bool
    rescale_history: bool
    ds_scale: float = 1.0


def gravity_vector(gravity, incline):
    """(g_x, g_y, g_z) [g] of gravity of magnitude ``gravity`` tilted by ``incline`` degrees about y:
    gravity (sin, 0, -cos). Untilted it is (0.0, 0.0, -gravity) exactly, zeros +0.0 (a row's sum
    starts there: a -0.0 would change the bits of a row without contacts)."""
    theta = math.radians(incline)
    return gravity * math.sin(theta) + 0.0, 0.0, -(gravity * math.cos(theta))


def make_law(k_n, k_t, gamma_n, gamma_t, mu, dt, gravity=1.0, incline=0.0, model="hooke",
             limit_damping=False, rescale_history=False, ds_scale=1.0):
    """The kernels' ``Law`` from the values as the config names them: ``model`` a name of
    ``models.MODELS``, gravity of magnitude ``gravity`` [g] tilted by ``incline`` degrees about y
    (``gravity_vector``)."""
    return Law(float(k_n), float(k_t), float(gamma_n), float(gamma_t), float(mu),
               *gravity_vector(float(gravity), float(incline)), float(dt), MODELS[model].kernel,
               bool(limit_damping), bool(rescale_history), float(ds_scale))


@njit(cache=True, inline="always")
def norm2(dx, dy, dz):
    """dx^2 + dy^2 + dz^2, summed left to right."""
    return dx * dx + dy * dy + dz * dz


@njit(cache=True, inline="always")
def dot(ax, ay, az, bx, by, bz):
    """a . b, summed left to right."""
    return ax * bx + ay * by + az * bz


@njit(cache=True, inline="always")
def approach(dx, dy, dz, r2):
    """Overlap and unit normal of a pair in contact from its separation.

    (dx, dy, dz) = x_i - x_j [d] (minimum image), r2 its squared length [d^2];
    returns delta = 1 - r [d] and n = (x_i - x_j) / r.
    """
    r = math.sqrt(r2)
    delta = 1.0 - r
    rinv = 1.0 / r
    return delta, dx * rinv, dy * rinv, dz * rinv


@njit(cache=True, inline="always")
def spin(oix, oiy, oiz, ojx, ojy, ojz):
    """R omega_i + R omega_j [sqrt(g d)]: a symmetric sum, the same bits in both partners' views."""
    return R * oix + R * ojx, R * oiy + R * ojy, R * oiz + R * ojz


@njit(cache=True, inline="always")
def slip(vrx, vry, vrz, vn, nx, ny, nz, wx, wy, wz):
    """Tangential relative velocity at the contact point [sqrt(g d)]: v_r - v_n n - w x n,
    with v_r = v_i - v_j, v_n = v_r . n and w = ``spin``."""
    return (vrx - vn * nx - (wy * nz - wz * ny),
            vry - vn * ny - (wz * nx - wx * nz),
            vrz - vn * nz - (wx * ny - wy * nx))


@njit(cache=True, inline="always")
def normal(delta, vn, meff, law):
    """Normal force of docs/model.md 2.2 (Hooke) or 2.7 (Hertz), and the Hertz scale sqrt(delta).

    fn = k_n delta - m_eff gamma_n v_n, times sqrt(delta) for Hertz (1 for Hooke:
    1.0 * y == y, so the multiplication is left out); clipped at 0 with ``limit_damping``.
    """
    scale = 1.0
    fn = law.k_n * delta - meff * law.gamma_n * vn
    if law.model == MODEL_HERTZ:
        scale = math.sqrt(delta)
        fn = scale * fn
    if law.limit_damping and fn < 0.0:
        fn = 0.0
    return fn, scale


@njit(cache=True, inline="always")
def tangential(ds, vt, nrm, scale, meff, fn_mag, law, increment):
    """History update, projection and Coulomb truncation of docs/model.md 2.4.

    Parameters
    ----------
    ds : (3,) tuple of float
        Delta s before this step [d] (zeros for a new contact), as stored: times ``law.ds_scale``
        first.
    vt : (3,) tuple of float
        Tangential relative velocity at the contact point [sqrt(g d)].
    nrm : (3,) tuple of float
        Unit normal n.
    scale : float
        sqrt(delta) for Hertz (``normal``); not read for Hooke.
    meff : float
        Effective mass [m].
    fn_mag : float
        |f_n| [m g], the Coulomb bound's normal force.
    law : Law
    increment : bool
        False on the set-up evaluation (no history increment).

    Returns the new Delta s (3) [d] and the tangential force on i (3) [m g].
    """
    sx, sy, sz = ds
    vtx, vty, vtz = vt
    nx, ny, nz = nrm
    k_t, gamma_t, mu, dt = law.k_t, law.gamma_t, law.mu, law.dt
    # the spring the history was stored with, to this evaluation's k_t (1.0 but on the stiffening ramp)
    q = law.ds_scale
    sx = sx * q
    sy = sy * q
    sz = sz * q
    rescale_history = law.rescale_history
    if increment:
        sx += vtx * dt
        sy += vty * dt
        sz += vtz * dt
    s_old = 0.0
    if rescale_history:
        # the length the projection must not change: that of the incremented history
        s_old = math.sqrt(sx * sx + sy * sy + sz * sz)
    sn = sx * nx + sy * ny + sz * nz
    sx -= sn * nx
    sy -= sn * ny
    sz -= sn * nz
    if rescale_history:
        s_new = math.sqrt(sx * sx + sy * sy + sz * sz)
        if s_new > 0.0 and s_old > 0.0:
            r = s_old / s_new
            sx *= r
            sy *= r
            sz *= r
    if law.model == MODEL_HERTZ:
        ftx = -scale * (k_t * sx + meff * gamma_t * vtx)
        fty = -scale * (k_t * sy + meff * gamma_t * vty)
        ftz = -scale * (k_t * sz + meff * gamma_t * vtz)
    else:
        # Hooke's scale is 1: -1.0 * y == -y
        ftx = -(k_t * sx + meff * gamma_t * vtx)
        fty = -(k_t * sy + meff * gamma_t * vty)
        ftz = -(k_t * sz + meff * gamma_t * vtz)
    ft2 = ftx * ftx + fty * fty + ftz * ftz
    bound = mu * fn_mag
    # |F_t|^2 well below bound^2 means sticking; only near or past the bound is the exact
    # test sqrt(ft2) > bound needed (the margin covers the rounding of both sides, ~1e-16)
    if ft2 >= SURE_STICK * (bound * bound) and math.sqrt(ft2) > bound:
        ft_mag = math.sqrt(ft2)
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
    return sx, sy, sz, ftx, fty, ftz


@njit(cache=True, inline="always")
def normal_force(fn, nx, ny, nz):
    """The force of a frictionless contact on i [m g]: fn n (the partner's is its exact negative)."""
    return fn * nx, fn * ny, fn * nz


@njit(cache=True, inline="always")
def contact_force(fn, nx, ny, nz, ftx, fty, ftz):
    """The force of a frictional contact on i [m g]: fn n + F_t (the partner's is its exact negative)."""
    return fn * nx + ftx, fn * ny + fty, fn * nz + ftz


@njit(cache=True, inline="always")
def contact_torque(nx, ny, nz, ftx, fty, ftz):
    """The torque of a contact on i [m g d]: -R n x F_t (the same for both partners)."""
    return -(R * (ny * ftz - nz * fty)), -(R * (nz * ftx - nx * ftz)), -(R * (nx * fty - ny * ftx))


@njit(cache=True, inline="always")
def floor_force(delta, vz, k_n, gamma_n):
    """The bed-making floor's frictionless force k_n delta - gamma_n v_z [m g] (m_eff = m)."""
    return k_n * delta - gamma_n * vz


@njit(cache=True, inline="always")
def plane_contact(x, y, z, vx, vy, vz, ox, oy, oz, ds, nx, ny, nz, offset, kind, law, increment):
    """The contact of a sphere with a plane (``planes.Plane``): the points p with n . p = offset, the
    spheres on the side n points to; the plane at rest, of infinite mass (m_eff = m = 1).

    The overlap is delta = R - (n . x - offset) [d]. A ``PLANE_FLOOR`` pushes with the bed-making
    floor's frictionless spring (``floor_force``); a ``PLANE_SMOOTH`` with the pile's normal law; a
    ``PLANE_ROUGH`` with the pile's whole law, its tangential history ``ds`` carried per sphere
    (a pair's functions with the plane as the partner: ``slip`` with the sphere's own spin,
    ``tangential``, ``contact_force``, ``contact_torque``). For the plane z = 0 (n = +z) these are,
    bit for bit, the floor and the wall of before.

    Parameters
    ----------
    x, y, z, vx, vy, vz, ox, oy, oz : float
        The sphere's position [d], half-step velocity [sqrt(g d)] and angular velocity [sqrt(g/d)].
    ds : (3,) tuple of float
        Its Delta s with the plane [d] (read by a rough plane only).
    nx, ny, nz, offset : float
        The plane's unit normal and offset [d].
    kind : int
        PLANE_FLOOR, PLANE_SMOOTH or PLANE_ROUGH.
    law : Law
    increment : bool

    Returns
    -------
    delta, fx, fy, fz, tx, ty, tz, sx, sy, sz : float
        The overlap [d] (not positive: no contact, and zeros after it), the force [m g] and torque
        [m g d] on the sphere, and its new Delta s (+0.0 out of contact; unchanged without friction).
    """
    delta = R - (dot(x, y, z, nx, ny, nz) - offset)
    sx, sy, sz = ds
    if not delta > 0.0:
        return delta, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    vn = dot(vx, vy, vz, nx, ny, nz)
    if kind == PLANE_FLOOR:
        fx, fy, fz = normal_force(floor_force(delta, vn, law.k_n, law.gamma_n), nx, ny, nz)
        return delta, fx, fy, fz, 0.0, 0.0, 0.0, sx, sy, sz
    fn, scale = normal(delta, vn, 1.0, law)
    if kind == PLANE_ROUGH and law.mu > 0.0:
        vtx, vty, vtz = slip(vx, vy, vz, vn, nx, ny, nz, R * ox, R * oy, R * oz)
        sx, sy, sz, ftx, fty, ftz = tangential((sx, sy, sz), (vtx, vty, vtz), (nx, ny, nz), scale, 1.0, abs(fn),
                                               law, increment)
        fx, fy, fz = contact_force(fn, nx, ny, nz, ftx, fty, ftz)
        tx, ty, tz = contact_torque(nx, ny, nz, ftx, fty, ftz)
        return delta, fx, fy, fz, tx, ty, tz, sx + 0.0, sy + 0.0, sz + 0.0
    fx, fy, fz = normal_force(fn, nx, ny, nz)
    return delta, fx, fy, fz, 0.0, 0.0, 0.0, sx, sy, sz


@njit(cache=True, inline="always")
def kicks(f, t, h):
    """The half-kicks of one axis: h F / m [sqrt(g d)] and h T / I [sqrt(g/d)] (m = 1); h [tau]."""
    return h * f, h * INV_I * t


@njit(cache=True, inline="always")
def drift(x, v, dt):
    """x + dt v [d]."""
    return x + dt * v
