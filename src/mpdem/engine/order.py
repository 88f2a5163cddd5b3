"""The order of a rank's owned rows: by cell, so that neighbours are near in memory (both engines)."""
import numpy as np

from ..kernels.neighbours import cell_axis

# the width of the columns of cells the rows are ordered by (``sort_rows``), in cells (about)
SORT_COLUMN = 16


def sort_rows(s, r_list):
    """Order owned rows by cell so neighbours are near in memory: columns of about
    ``SORT_COLUMN`` x ``SORT_COLUMN`` cells (the list build's), one after the
    other, z-major inside each.

    Sums run in partner-id order, so row order changes no result bit
    (docs/computing.md, "The force sum: two passes per row").

    Returns
    -------
    (n_own,) int64 or None
        The order applied (new row i was row order[i]); None for fewer than two rows (none).
    """
    n = s.n_own
    if n < 2:
        return None
    c = r_list
    x = s.x[:n]
    # the cells of the list build (neighbours._bin): nx x ny across the box, c tall
    nx, ny = cell_axis(s.L_x, c), cell_axis(s.L_y, c)
    ix = np.minimum(np.floor(x[:, 0] * (nx / s.L_x)), nx - 1).astype(np.int64)
    iy = np.minimum(np.floor(x[:, 1] * (ny / s.L_y)), ny - 1).astype(np.int64)
    iz = np.floor((x[:, 2] - x[:, 2].min()) / c).astype(np.int64)
    # columns of about SORT_COLUMN x SORT_COLUMN cells (as many along an axis as fit, all
    # about as wide: a thin column's rows would have their partners far away), each z-major
    # inside: a row's partners stay within a few hundred rows of it however wide the pile
    # (z-major over the whole layer put them a layer of cells away)
    cx = max(int(round(nx / SORT_COLUMN)), 1)
    cy = max(int(round(ny / SORT_COLUMN)), 1)
    column = (iy * cy // ny) * cx + ix * cx // nx
    nz = int(iz.max()) + 1
    key = ((column * nz + iz) * ny + iy) * nx + ix
    order = np.argsort(key, kind="stable")
    s.permute(order)
    return order
