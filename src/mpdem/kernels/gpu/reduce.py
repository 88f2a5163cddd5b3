"""Reductions over a block's threads and into global slots, exact whatever order the blocks run in:
max, min, and integer sums (an integer sum kept in float64 is exact below 2**53).

One value a tree (``max_into``, ``min_into``, ``sum_into``: log2(block) + 2 barriers each), or a
step's values in one tree (``drift_into``: the drift's three extremes; ``contact_into``: the forces'
largest overlap and contact count), the same results with fewer than half the barriers; or the same
two by warp shuffles (``drift_into_warp``, ``contact_into_warp``: two barriers each). The fused ones
need ``ROOM`` float64 of shared room.

A block has at most ``BLOCK_MAX`` threads, a power of two; every thread of the block calls these
(they wait at the block's barriers). They read ``cuda``, so they are ``runtime.device_cuda``.
"""
import numpy as np

from .runtime import cuda, device_cuda, shfl

BLOCK_MAX = 1024
# shared float64 slots of the fused reductions: three values a thread
ROOM = 3 * BLOCK_MAX


@device_cuda
def block_max(value, room):
    """The max of ``value`` over the block's threads, in thread 0 (others: undefined); every thread
    of the block must call it. ``room`` (BLOCK_MAX,) float64 shared."""
    t = cuda.threadIdx.x
    room[t] = value
    cuda.syncthreads()
    s = cuda.blockDim.x // 2
    while s > 0:
        if t < s and room[t + s] > room[t]:
            room[t] = room[t + s]
        cuda.syncthreads()
        s //= 2
    out = room[0]
    cuda.syncthreads()
    return out


@device_cuda
def block_sum(value, room):
    """The sum of the int ``value`` over the block's threads, in thread 0; as ``block_max`` (``room``
    float64: the integer sums are exact below 2**53, so the order does not matter)."""
    t = cuda.threadIdx.x
    room[t] = np.float64(value)
    cuda.syncthreads()
    s = cuda.blockDim.x // 2
    while s > 0:
        if t < s:
            room[t] += room[t + s]
        cuda.syncthreads()
        s //= 2
    out = room[0]
    cuda.syncthreads()
    return out


@device_cuda
def max_into(red, k, value, room):
    """red[k] = max(red[k], the block's ``value``s) (every thread of the block calls it)."""
    value = block_max(value, room)
    if cuda.threadIdx.x == 0:
        cuda.atomic.max(red, k, value)


@device_cuda
def min_into(red, k, value, room):
    """red[k] = min(red[k], the block's ``value``s)."""
    value = -block_max(-value, room)
    if cuda.threadIdx.x == 0:
        cuda.atomic.min(red, k, value)


@device_cuda
def sum_into(red, k, value, room):
    """red[k] += the sum of the block's int ``value``s (as float64: exact below 2**53); ``room`` float64,
    the same a ``max_into`` before it used (each ends at a barrier)."""
    value = block_sum(value, room)
    if cuda.threadIdx.x == 0 and value != 0.0:
        cuda.atomic.add(red, k, value)


@device_cuda
def _tree(room, t, n, k_max, k_sum):
    """Reduce ``room``'s first ``k_max`` columns (of BLOCK_MAX slots each) by max and the next ``k_sum``
    by sum over the block's ``n`` threads into slot 0 of each column, in one tree (every thread calls)."""
    cuda.syncthreads()
    s = n // 2
    while s > 0:
        if t < s:
            for k in range(k_max):
                o = k * BLOCK_MAX + t
                if room[o + s] > room[o]:
                    room[o] = room[o + s]
            for k in range(k_max, k_max + k_sum):
                o = k * BLOCK_MAX + t
                room[o] += room[o + s]
        cuda.syncthreads()
        s //= 2


@device_cuda
def _drift_out(red, k_d2, k_hi, k_lo, room, t):
    """Thread 0 puts the block's drift extremes (``room``'s slot 0 of its first three columns: d2, z_hi and
    -z_lo) into ``red`` by atomics; then a barrier, every thread calling."""
    if t == 0:
        cuda.atomic.max(red, k_d2, room[0])
        cuda.atomic.max(red, k_hi, room[BLOCK_MAX])
        cuda.atomic.min(red, k_lo, -room[2 * BLOCK_MAX])
    cuda.syncthreads()


@device_cuda
def _contact_out(red, k_max, k_sum, room, t):
    """Thread 0 puts the block's largest overlap and contact count (``room``'s slot 0 of its first two
    columns) into ``red`` by atomics; then a barrier, every thread calling."""
    if t == 0:
        cuda.atomic.max(red, k_max, room[0])
        if room[BLOCK_MAX] != 0.0:
            cuda.atomic.add(red, k_sum, room[BLOCK_MAX])
    cuda.syncthreads()


@device_cuda
def drift_into(red, k_d2, d2, k_hi, z_hi, k_lo, z_lo, room):
    """red[k_d2] = max(red[k_d2], the block's ``d2``), red[k_hi] likewise with ``z_hi``, red[k_lo] =
    min(red[k_lo], the block's ``z_lo``): ``max_into``, ``max_into``, ``min_into`` in one tree.
    ``room`` (ROOM,) float64 shared."""
    t = cuda.threadIdx.x
    room[t] = d2
    room[BLOCK_MAX + t] = z_hi
    room[2 * BLOCK_MAX + t] = -z_lo
    _tree(room, t, cuda.blockDim.x, 3, 0)
    _drift_out(red, k_d2, k_hi, k_lo, room, t)


@device_cuda
def contact_into(red, k_max, value, k_sum, count, room):
    """red[k_max] = max(red[k_max], the block's ``value``s), red[k_sum] += the sum of its int ``count``s:
    ``max_into`` and ``sum_into`` in one tree (the counts as float64, exact below 2**53)."""
    t = cuda.threadIdx.x
    room[t] = value
    room[BLOCK_MAX + t] = np.float64(count)
    _tree(room, t, cuda.blockDim.x, 1, 1)
    _contact_out(red, k_max, k_sum, room, t)


@device_cuda
def _warp_extreme(value, w, mask, sums):
    """The max (or with ``sums`` the sum) of ``value`` over the ``w`` lanes of this thread's group of its
    warp (``w`` a power of two up to 32, the group the lanes of ``mask``), in every lane: ``log2(w)``
    exchanges by warp shuffles, each lane with the lane whose index differs by one bit."""
    off = w // 2
    while off > 0:
        other = shfl(mask, value, cuda.laneid ^ off)
        if sums:
            value += other
        elif other > value:
            value = other
        off //= 2
    return value


@device_cuda
def _warps(room, t, n, k_max, k_sum):
    """Reduce the per-warp values in ``room``'s first ``k_max`` columns (of BLOCK_MAX slots) by max and the
    next ``k_sum`` by sum into slot 0 of each column, in thread 0 (``n`` threads, so n / 32 warps, or one
    warp of n < 32 threads); every thread calls it (one barrier before)."""
    cuda.syncthreads()
    if t == 0:
        for j in range(1, max(n // 32, 1)):
            for k in range(k_max):
                o = k * BLOCK_MAX
                if room[o + j] > room[o]:
                    room[o] = room[o + j]
            for k in range(k_max, k_max + k_sum):
                o = k * BLOCK_MAX
                room[o] += room[o + j]


@device_cuda
def _group():
    """(w, mask, this thread's warp index): the lanes of a warp the block fills (32, or the whole block
    of fewer threads) and their mask."""
    n = cuda.blockDim.x
    w = min(n, 32)
    mask = 0xFFFFFFFF if w == 32 else (1 << w) - 1
    return w, mask, cuda.threadIdx.x // w


@device_cuda
def drift_into_warp(red, k_d2, d2, k_hi, z_hi, k_lo, z_lo, room):
    """``drift_into`` by warp shuffles: each warp's extremes in its lanes (no barrier), one value a warp
    into ``room``, then thread 0 over the warps: two block barriers instead of a tree's log2(block) + 2
    (engine.gpu_reductions = "warp"). The same extremes, so the same results."""
    t = cuda.threadIdx.x
    w, mask, j = _group()
    a = _warp_extreme(d2, w, mask, False)
    b = _warp_extreme(z_hi, w, mask, False)
    c = _warp_extreme(-z_lo, w, mask, False)
    if t % w == 0:
        room[j] = a
        room[BLOCK_MAX + j] = b
        room[2 * BLOCK_MAX + j] = c
    _warps(room, t, cuda.blockDim.x, 3, 0)
    _drift_out(red, k_d2, k_hi, k_lo, room, t)


@device_cuda
def contact_into_warp(red, k_max, value, k_sum, count, room):
    """``contact_into`` by warp shuffles (as ``drift_into_warp``: two block barriers); the counts as float64,
    exact below 2**53, so their sum does not depend on the order."""
    t = cuda.threadIdx.x
    w, mask, j = _group()
    a = _warp_extreme(value, w, mask, False)
    b = _warp_extreme(np.float64(count), w, mask, True)
    if t % w == 0:
        room[j] = a
        room[BLOCK_MAX + j] = b
    _warps(room, t, cuda.blockDim.x, 1, 1)
    _contact_out(red, k_max, k_sum, room, t)
