"""The stop rule's samples on the GPU: the kinetic energies and the force balance as exact fixed-point sums.

The CPU kernels (``kernels.integrate.kinetic_energy``, ``kernels.balance.force_balance``) add each
row's terms to accumulators of 32-bit limbs in int64 (``kernels.exactsum``); integer addition is
associative, so the GPU's threads add the same terms, computed with the same explicitly rounded
operations, to the same limbs with integer atomics in any order and give the same integers, to the
bit. A sample then copies a few kilobytes back (the limbs), not every row and every entry's force.

Kernels take arrays and scalars only; any grid (each thread takes rows i, i + threads, ...).
"""
import math

import numpy as np

from ..exactsum import EMIN, MASK
from ..particle import HALF_I
from .rounded import mul, norm2, sqrt
from .runtime import cuda, device_cuda


@device_cuda
def add_exact(acc, a, value):
    """acc[a] += ``value`` exactly (``exactsum.add_exact`` by integer atomics; NaN and inf add nothing)."""
    if value == 0.0 or not math.isfinite(value):
        return
    sign = np.int64(1)
    if value < 0.0:
        sign = np.int64(-1)
        value = -value
    mant, e = math.frexp(value)
    m = np.int64(math.ldexp(mant, 53))
    p = e - 53 - EMIN
    k = p >> 5
    s = p & 31
    lo = (m & MASK) << s
    hi = (m >> 32) << s
    cuda.atomic.add(acc, (a, k), sign * (lo & MASK))
    cuda.atomic.add(acc, (a, k + 1), sign * ((lo >> 32) + (hi & MASK)))
    cuda.atomic.add(acc, (a, k + 2), sign * (hi >> 32))


@cuda.jit
def kinetic_sums(n_own, v, omega, fixed, acc):
    """``kinetic_energy``'s sums of the owned mobile rows into ``acc`` (na, NLIMBS) int64 (zeroed):
    sum(1/2 m v^2), sum(1/2 I omega^2), and with na = 3 sum(m v_x)."""
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        if fixed[i]:
            continue
        et = mul(0.5, norm2(v[i, 0], v[i, 1], v[i, 2]))
        er = mul(HALF_I, norm2(omega[i, 0], omega[i, 1], omega[i, 2]))
        add_exact(acc, 0, et)
        add_exact(acc, 1, er)
        if acc.shape[0] > 2:
            add_exact(acc, 2, v[i, 0])


@cuda.jit
def balance_sums(n_own, f, fixed, start, stamp, pair, now, acc):
    """``force_balance``'s sums of the owned mobile rows into ``acc`` (4, NLIMBS) int64 (zeroed): sum |f_i|,
    sum |F_c| over each row's entries stamped ``now`` (in contact at the last evaluation, whose forces
    ``pair`` (K, 6) kept), their number, and the rows with none."""
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        if fixed[i]:
            continue
        add_exact(acc, 0, sqrt(norm2(f[i, 0], f[i, 1], f[i, 2])))
        m = 0
        for e in range(start[i], start[i + 1]):
            if stamp[e] == now:
                add_exact(acc, 1, sqrt(norm2(pair[e, 0], pair[e, 1], pair[e, 2])))
                m += 1
        add_exact(acc, 2, float(m))
        if m == 0:
            add_exact(acc, 3, 1.0)


@cuda.jit
def zero(acc):
    """acc[...] = 0 ((na, NLIMBS) int64)."""
    for j in range(cuda.grid(1), acc.size, cuda.gridsize(1)):
        acc[j // acc.shape[1], j % acc.shape[1]] = 0
