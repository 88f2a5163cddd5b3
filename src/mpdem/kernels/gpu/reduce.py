"""Reductions over a block's threads and into global slots, exact whatever order the blocks run in:
max, min, and integer sums (an integer sum kept in float64 is exact below 2**53).

A block has at most ``BLOCK_MAX`` threads, a power of two; every thread of the block calls these
(they wait at the block's barriers). They read ``cuda``, so they are ``runtime.device_cuda``.
"""
import numpy as np

from .runtime import cuda, device_cuda

BLOCK_MAX = 1024


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
    """The sum of the int64 ``value`` over the block's threads, in thread 0; as ``block_max``."""
    t = cuda.threadIdx.x
    room[t] = value
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
    """red[k] += the sum of the block's int64 ``value``s (as float64: exact below 2**53)."""
    value = block_sum(value, room)
    if cuda.threadIdx.x == 0 and value != 0:
        cuda.atomic.add(red, k, np.float64(value))
