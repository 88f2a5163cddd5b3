"""The split of rows into chunks, one thread's work each.

Rows 0..n-1 are cut into ``nchunk`` consecutive chunks, chunk c holding rows
[c n // C, (c + 1) n // C). Every parallel kernel loops over its chunks with
``chunk_bounds``, and ``link_entries`` asks which chunk a partner row is in
with ``chunk_of``: the two must agree, or a pair would be computed by no row
or by two (tests/test_kernels.py checks them against each other).
"""
from numba import njit


@njit(cache=True, inline="always")
def chunk_bounds(c, n, nchunk):
    """Rows [lo, hi) of chunk c of ``nchunk`` when rows 0..n-1 are split: (c n // C, (c + 1) n // C)."""
    return c * n // nchunk, (c + 1) * n // nchunk


@njit(cache=True, inline="always")
def chunk_of(i, n, nchunk):
    """The chunk of row i (0 <= i < n) under ``chunk_bounds``: the c with c n // C <= i < (c + 1) n // C."""
    return ((i + 1) * nchunk - 1) // n
