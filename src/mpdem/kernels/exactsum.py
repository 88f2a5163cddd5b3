"""Exact, order-independent sums of doubles as fixed-point integers.

A double is M * 2^e with an integer mantissa M < 2^53. It is added to an
int64 array of 32-bit limbs, limb k weighing 2^(32 k + EMIN). Integer addition
is associative, so the limbs of several ranks can be summed with an integer
allreduce in any order and give the same bits; ``to_float`` then rounds the
exact total once. Each limb takes up to 2^31 additions before it could
overflow, far beyond the particles of one rank.
"""
import math

import numpy as np
from numba import njit

EMIN = -1152           # weight of bit 0 of limb 0 (below 2^-1074 * 2^-53)
NLIMBS = 72            # covers up to 2^(32*72 + EMIN) > largest double
MASK = 0xFFFFFFFF


def new_accumulator(n=1):
    """Zeroed accumulator(s): shape (NLIMBS,) or (n, NLIMBS) int64."""
    return np.zeros(NLIMBS if n == 1 else (n, NLIMBS), np.int64)


@njit(cache=True)
def add_exact(acc, value):
    """Add a finite double exactly to ``acc`` (NaN/inf add nothing; check first)."""
    if value == 0.0 or not math.isfinite(value):
        return
    sign = 1
    if value < 0.0:
        sign = -1
        value = -value
    mant, e = math.frexp(value)          # value = mant * 2^e, 0.5 <= mant < 1
    m = np.int64(math.ldexp(mant, 53))  # exact 53-bit integer
    p = e - 53 - EMIN                    # bit position of m's lowest bit
    k = p >> 5
    s = p & 31
    lo = (m & MASK) << s                 # < 2^63
    hi = (m >> 32) << s                  # < 2^52
    acc[k] += sign * (lo & MASK)
    acc[k + 1] += sign * ((lo >> 32) + (hi & MASK))
    acc[k + 2] += sign * (hi >> 32)


def to_float(acc):
    """The exact total of an accumulator, rounded once to the nearest double."""
    total = 0
    for k in range(len(acc) - 1, -1, -1):
        total = (total << 32) + int(acc[k])
    return total / (1 << -EMIN) if total else 0.0


@njit(cache=True)
def bin_limbs(bins, values, n_bins):
    """(n_bins, NLIMBS) accumulators of the exact sums of ``values`` by ``bins`` (entries outside
    [0, n_bins) left out): sum them over ranks as integers, round each once (``to_float``)."""
    acc = np.zeros((n_bins, NLIMBS), np.int64)
    for k in range(len(values)):
        b = bins[k]
        if 0 <= b < n_bins:
            add_exact(acc[b], values[k])
    return acc


def bin_sums(bins, values, n_bins):
    """(n_bins,) float64: the exact sums of ``values`` by ``bins``, each rounded once (any order alike)."""
    acc = bin_limbs(np.asarray(bins, np.int64), np.asarray(values, np.float64), n_bins)
    return np.array([to_float(acc[b]) for b in range(n_bins)])
