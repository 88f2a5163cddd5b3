"""Velocity Verlet for translation and rotation (docs/model.md section 4.1)."""
import math

import numpy as np
from numba import njit, prange

from .chunks import chunk_bounds
from .exactsum import NLIMBS, add_exact
from .geometry import min_image
from .law import drift, kicks, norm2
from .particle import HALF_I


@njit(cache=True, inline="always")
def _half_kick(i, v, omega, f, torque, h):
    """v += h F / m and omega += h T / I for row i (m = 1, I = ``particle.INERTIA``); h [tau]."""
    for a in range(3):
        fa, ta = kicks(f[i, a], torque[i, a], h)
        v[i, a] += fa
        omega[i, a] += ta


@njit(cache=True, parallel=True)
def kick_drift(n_own, particles, x_ref, dt, box, scratch, pending):
    """First half-kick and drift of owned mobile rows; wrap x and y.

    With ``pending``, the previous step's second half-kick, which the engine
    deferred, is applied first in the same pass (the same operations in the
    same order as ``kick`` then this, so the same bits; one pass over the rows
    less).

    Parameters
    ----------
    n_own : int
        Rows ``0..n_own-1`` move (those with ``fixed`` 0).
    particles : Particles
        ``x`` [d], ``v`` [sqrt(g d)] and ``omega`` [sqrt(g/d)] (n_rows, 3)
        are updated in place from ``f`` [m g] and ``torque`` [m g d]
        (m = 1, I = ``particle.INERTIA``).
    x_ref : (>= n_own, 3) float64
        Positions the displacement is measured from [d] (the engine's: those of the
        last filtering of the near lists, ``near.near_lists``).
    dt : float
        Time step [tau].
    box : Box
        Periodic box [d]; x and y are wrapped into [0, L_x) x [0, L_y).
    scratch : (C, 3) float64
        One row per chunk of rows for the threads (any C >= 1, same result).
    pending : bool
        Apply the previous step's second half-kick first (``f`` and ``torque``
        are still that step's).

    Returns
    -------
    max_disp2 : float
        Largest squared displacement since ``x_ref`` [d^2] (NaN if any
        coordinate is not finite).
    z_min, z_max : float
        Lowest and highest mobile centre [d] (inf / -inf if none).
    """
    nchunk = scratch.shape[0]
    for c in prange(nchunk):
        lo, hi = chunk_bounds(c, n_own, nchunk)
        d2, zlo, zhi = _kick_drift_rows(lo, hi, particles, x_ref, dt, box, pending)
        scratch[c, 0] = d2
        scratch[c, 1] = zlo
        scratch[c, 2] = zhi
    max_d2 = 0.0
    z_min = math.inf
    z_max = -math.inf
    bad = False
    for c in range(nchunk):
        if math.isnan(scratch[c, 0]):
            bad = True
        elif scratch[c, 0] > max_d2:
            max_d2 = scratch[c, 0]
        z_min = min(z_min, scratch[c, 1])
        z_max = max(z_max, scratch[c, 2])
    if bad:
        max_d2 = math.nan
    return max_d2, z_min, z_max


@njit(cache=True)
def kick_drift_serial(n_own, particles, x_ref, dt, box, scratch, pending):
    """``kick_drift`` on one chunk, without the parallel wrapper, whose loop over the rows
    runs a third slower on one thread; the same bits. Arguments and returns as
    ``kick_drift``; ``scratch`` is not needed with one chunk and is left as it is."""
    return _kick_drift_rows(0, n_own, particles, x_ref, dt, box, pending)


@njit(cache=True)
def _kick_drift_rows(lo, hi, particles, x_ref, dt, box, pending):
    """Rows lo..hi-1 of ``kick_drift``; returns (max d^2 or NaN, z_min, z_max)."""
    x, v, omega, f, torque, fixed = particles
    L_x, L_y, hx, hy = box
    h = 0.5 * dt
    max_d2 = 0.0
    z_min = math.inf
    z_max = -math.inf
    bad = False
    # an unsigned row index: numba adds no negative-index wrap-around to it (7.1 -> 6.3 ns a row on the 20k pile)
    for i in range(np.uint64(lo), np.uint64(hi)):
        if fixed[i]:
            continue
        # in registers: v, f and x are distinct arrays, which the compiler cannot know
        for a in range(3):
            fa, ta = kicks(f[i, a], torque[i, a], h)
            va = v[i, a]
            wa = omega[i, a]
            if pending:
                va += fa
                wa += ta
            va += fa
            wa += ta
            v[i, a] = va
            omega[i, a] = wa
            x[i, a] = drift(x[i, a], va, dt)
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
        d2 = norm2(dx, dy, dz)
        if d2 > max_d2:
            max_d2 = d2
    if bad:
        max_d2 = math.nan
    return max_d2, z_min, z_max


@njit(cache=True, parallel=True)
def kick(n_own, particles, dt):
    """Second half-kick of owned mobile rows: ``particles.v`` and ``omega`` from ``f`` and ``torque``
    (m = 1, I = ``particle.INERTIA``); dt the time step [tau]."""
    v, omega, f, torque, fixed = particles.v, particles.omega, particles.f, particles.torque, particles.fixed
    h = 0.5 * dt
    for i in prange(n_own):
        if not fixed[i]:
            _half_kick(i, v, omega, f, torque, h)


@njit(cache=True)
def kick_serial(n_own, particles, dt):
    """``kick`` without the parallel wrapper (one thread): the same rows, the same bits."""
    v, omega, f, torque, fixed = particles.v, particles.omega, particles.f, particles.torque, particles.fixed
    h = 0.5 * dt
    for i in range(n_own):
        if not fixed[i]:
            _half_kick(i, v, omega, f, torque, h)


@njit(cache=True, parallel=True)
def kinetic_energy(n_own, particles, acc, nchunk):
    """Kinetic energies (and the downslope momentum) of owned mobile rows as exact fixed-point sums.

    Parameters
    ----------
    particles : Particles
        ``v`` [sqrt(g d)], ``omega`` [sqrt(g/d)] and ``fixed`` are read.
    acc : (2, NLIMBS) or (3, NLIMBS) int64, out
        ``acc[0]`` gets sum(1/2 m v^2) and ``acc[1]`` sum(1/2 I omega^2), and ``acc[2]`` (when
        there) sum(m v_x), the momentum along x (downslope on an incline), each an exact integer sum
        (see ``exactsum``), so the totals do not depend on how particles are split over ranks or threads.
    nchunk : int
        Chunks of rows for the threads.
    """
    v, omega, fixed = particles.v, particles.omega, particles.fixed
    na = acc.shape[0]
    part = np.zeros((nchunk, na, NLIMBS), np.int64)
    for c in prange(nchunk):
        lo, hi = chunk_bounds(c, n_own, nchunk)
        for i in range(lo, hi):
            if fixed[i]:
                continue
            et = 0.5 * (v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2])
            er = HALF_I * (omega[i, 0] * omega[i, 0] + omega[i, 1] * omega[i, 1]
                         + omega[i, 2] * omega[i, 2])
            add_exact(part[c, 0], et)
            add_exact(part[c, 1], er)
            if na > 2:
                add_exact(part[c, 2], v[i, 0])
    for c in range(nchunk):
        for a in range(na):
            for k in range(NLIMBS):
                acc[a, k] += part[c, a, k]
