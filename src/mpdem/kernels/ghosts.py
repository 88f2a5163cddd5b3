"""Copying ghost rows to and from the contiguous buffers of a ghost exchange (``parallel.GhostPlan``)."""
from numba import njit


@njit(cache=True)
def gather_rows(fields, rows, out):
    """Copy rows of each field into a block of a send buffer.

    Parameters
    ----------
    fields : tuple of F (n_rows_cap, 3) float64
        E.g. x, v, omega.
    rows : (m,) intp
        The rows sent, in the order the receiver stores them.
    out : (F, m, 3) float64, out
        ``out[f, k] = fields[f][rows[k]]``.
    """
    for f in range(len(fields)):
        a = fields[f]
        for k in range(len(rows)):
            r = rows[k]
            out[f, k, 0] = a[r, 0]
            out[f, k, 1] = a[r, 1]
            out[f, k, 2] = a[r, 2]


@njit(cache=True)
def scatter_rows(fields, start, block):
    """Copy a received block into consecutive ghost rows of each field.

    Parameters
    ----------
    fields : tuple of F (n_rows_cap, 3) float64, in/out
    start : int
        The first ghost row of the block.
    block : (F, m, 3) float64
        ``fields[f][start + k] = block[f, k]``.
    """
    for f in range(len(fields)):
        a = fields[f]
        for k in range(block.shape[1]):
            a[start + k, 0] = block[f, k, 0]
            a[start + k, 1] = block[f, k, 1]
            a[start + k, 2] = block[f, k, 2]
