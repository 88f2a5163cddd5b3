"""Velocity Verlet for translation and rotation (physics.md section 4.1)."""
import math

from numba import njit

from .geometry import min_image

from .exactsum import add_exact
from .forces import INV_I


@njit(cache=True, inline="always")
def _half_kick(i, v, omega, f, torque, h):
    """v += h F / m and omega += h T / I for row i (m = 1, I = 0.1)."""
    for a in range(3):
        v[i, a] += h * f[i, a]
        omega[i, a] += h * INV_I * torque[i, a]


@njit(cache=True)
def kick_drift(n_own, x, v, omega, f, torque, fixed, x_ref, dt, L_x, L_y):
    """First half-kick and drift of owned mobile rows; wrap x and y.

    Parameters
    ----------
    x, v, omega, f, torque : (n_rows, 3) float64
        Updated in place (m = 1, I = 0.1).
    x_ref : (n_rows, 3) float64
        Positions at the last neighbour-list build.
    dt : float
        Time step [tau].

    Returns
    -------
    max_disp2 : float
        Largest squared displacement since ``x_ref`` [d^2] (NaN if any
        coordinate is not finite).
    z_min, z_max : float
        Lowest and highest mobile centre [d] (inf / -inf if none).
    """
    h = 0.5 * dt
    hx = 0.5 * L_x
    hy = 0.5 * L_y
    max_d2 = 0.0
    z_min = math.inf
    z_max = -math.inf
    bad = False
    for i in range(n_own):
        if fixed[i]:
            continue
        _half_kick(i, v, omega, f, torque, h)
        for a in range(3):
            x[i, a] += dt * v[i, a]
        # one correction suffices: nothing moves a box length in one step
        if x[i, 0] >= L_x:
            x[i, 0] -= L_x
        elif x[i, 0] < 0.0:
            x[i, 0] += L_x
            if x[i, 0] >= L_x:  # -tiny + L rounds to L
                x[i, 0] = 0.0
        if x[i, 1] >= L_y:
            x[i, 1] -= L_y
        elif x[i, 1] < 0.0:
            x[i, 1] += L_y
            if x[i, 1] >= L_y:
                x[i, 1] = 0.0
        z = x[i, 2]
        if not (math.isfinite(x[i, 0]) and math.isfinite(x[i, 1]) and math.isfinite(z)):
            bad = True
        if z < z_min:
            z_min = z
        if z > z_max:
            z_max = z
        dx = min_image(x[i, 0] - x_ref[i, 0], L_x, hx)
        dy = min_image(x[i, 1] - x_ref[i, 1], L_y, hy)
        dz = z - x_ref[i, 2]
        d2 = dx * dx + dy * dy + dz * dz
        if d2 > max_d2:
            max_d2 = d2
    if bad:
        max_d2 = math.nan
    return max_d2, z_min, z_max


@njit(cache=True)
def kick(n_own, v, omega, f, torque, fixed, dt):
    """Second half-kick of owned mobile rows (m = 1, I = 0.1)."""
    h = 0.5 * dt
    for i in range(n_own):
        if not fixed[i]:
            _half_kick(i, v, omega, f, torque, h)


@njit(cache=True)
def kinetic_energy(n_own, v, omega, fixed, acc_trans, acc_rot):
    """Add the kinetic energies of owned mobile rows to exact accumulators.

    ``acc_trans`` gets sum(1/2 m v^2) and ``acc_rot`` sum(1/2 I omega^2), each
    as an exact fixed-point integer sum (see ``exactsum``), so the total is
    independent of how particles are split over ranks.
    """
    for i in range(n_own):
        if fixed[i]:
            continue
        et = 0.5 * (v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2])
        er = 0.05 * (omega[i, 0] * omega[i, 0] + omega[i, 1] * omega[i, 1]
                     + omega[i, 2] * omega[i, 2])
        add_exact(acc_trans, et)
        add_exact(acc_rot, er)
