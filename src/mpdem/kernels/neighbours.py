"""Cell binning and Verlet neighbour lists.

Positions are wrapped into [0, L_x) x [0, L_y); z is open. Cells are at
least ``r_list`` wide. In z the cell index is hashed modulo ``nz`` when the
pile is very tall or a particle flies far away, so memory stays O(N); a hashed
cell only adds candidates that the distance test rejects.

Lists are built in one pass over the rows, each chunk of rows (a thread's)
into its own share of the list array, then moved together; a row's list
depends only on the positions, so the lists are the same for any thread
count. A row's candidates are read from a copy of the positions in cell
order, the three cells along x as one run where they are consecutive, and
its partners sorted by id in a scratch before they are written.
"""
import numpy as np
from numba import njit, prange

from .chunks import chunk_bounds, chunk_of
from .geometry import min_image


@njit(cache=True)
def cell_axis(length, r_list):
    """Cells of the list build along a periodic axis of ``length`` [d]: as many as are at least
    ``r_list`` wide, and at least one (``order.sort_rows`` orders rows by the same cells)."""
    n = int(length // r_list)
    return max(n, 1)


@njit(cache=True)
def _bin(x, n_rows, box, r_list):
    """Counting sort of rows into cells of at least r_list [d].

    Returns the plain tuple ``cells`` = (nx, ny, nz, cell (n_rows,) each row's cell, count (ncell + 1,)
    CSR offsets of the cells, order (n_rows,) the rows by cell); a plain tuple, as it is read in a
    prange loop (bundles.py).
    """
    L_x, L_y = box.L_x, box.L_y
    nx = cell_axis(L_x, r_list)
    ny = cell_axis(L_y, r_list)
    cx = L_x / nx
    cy = L_y / ny
    zmin = np.inf
    zmax = -np.inf
    for i in range(n_rows):
        z = x[i, 2]
        if z < zmin:
            zmin = z
        if z > zmax:
            zmax = z
    nz_true = int((zmax - zmin) / r_list) + 1 if n_rows > 0 else 1
    # bound the grid to O(rows): hash z cells beyond that (see module doc)
    nz_cap = max(3, 4 * (n_rows // (nx * ny)) + 8)
    nz = min(nz_true, nz_cap)
    ncell = nx * ny * nz
    cell = np.empty(n_rows, np.int32)
    count = np.zeros(ncell + 1, np.int32)
    for i in range(n_rows):
        ix = min(int(x[i, 0] / cx), nx - 1)
        iy = min(int(x[i, 1] / cy), ny - 1)
        iz = int((x[i, 2] - zmin) / r_list) % nz
        c = (iz * ny + iy) * nx + ix
        cell[i] = c
        count[c + 1] += 1
    for c in range(ncell):
        count[c + 1] += count[c]
    order = np.empty(n_rows, np.int32)
    fill = count[:-1].copy()
    for i in range(n_rows):
        c = cell[i]
        order[fill[c]] = i
        fill[c] += 1
    return nx, ny, nz, cell, count, order


@njit(cache=True, inline="always")
def _next_cell(i, a, n):
    """The a-th (0, 1, 2) of the cells around cell i along an axis of n cells, periodic
    ((i + a - 1) mod n; a itself when n < 3), without an integer division."""
    if n < 3:
        return a
    j = i + a - 1
    if j < 0:
        return j + n
    if j >= n:
        return j - n
    return j


@njit(cache=True)
def _sorted_positions(x, cells):
    """(n_rows, 3) float64: the positions in cell order (``cells``' ``order``), so a
    cell's candidates are read in sequence."""
    order = cells[5]
    xs = np.empty((len(order), 3))
    for k in range(len(order)):
        j = order[k]
        xs[k, 0] = x[j, 0]
        xs[k, 1] = x[j, 1]
        xs[k, 2] = x[j, 2]
    return xs


@njit(cache=True, inline="always")
def _x_runs(row, ix, nx):
    """The cells ix - 1, ix, ix + 1 (periodic; all nx if nx < 3) of the x-row of cells starting
    at cell ``row``, as at most two runs of consecutive cells: (a0, a1, b0, b1)."""
    if nx < 3:
        return row, row + nx, row, row
    if ix == 0:
        return row, row + 2, row + nx - 1, row + nx
    if ix == nx - 1:
        return row + nx - 2, row + nx, row, row + 1
    return row + ix - 1, row + ix + 2, row, row


@njit(cache=True)
def _scan_row(i, x, xs, ids, box, r2, cells, buf_id, buf_j, nbr_list, first, limit):
    """Partners of row i within the list cutoff (squared distance r2 [d^2]) in the ``cells`` of ``_bin``
    (``xs``: the positions in cell order, ``_sorted_positions``); sorted by id in the row's scratch
    ``buf_id``, ``buf_j`` (length >= the rows), then written from ``first`` if they end at or below
    index ``limit`` (``limit`` 0: only counted).

    Returns the number of partners.
    """
    L_x, L_y, hx, hy = box
    nx, ny, nz, cell, count, order = cells
    c = cell[i]
    ix = c % nx
    iy = (c // nx) % ny
    iz = c // (nx * ny)
    xi = x[i, 0]
    yi = x[i, 1]
    zi = x[i, 2]
    # distinct neighbouring cells along y and z (all cells if fewer than 3); along x in runs
    oy = 3 if ny >= 3 else ny
    oz = 3 if nz >= 3 else nz
    write = limit > 0
    m = 0
    for a in range(oz):
        jz = _next_cell(iz, a, nz)
        for b in range(oy):
            jy = _next_cell(iy, b, ny)
            a0, a1, b0, b1 = _x_runs((jz * ny + jy) * nx, ix, nx)
            for run in range(2):
                c0 = a0 if run == 0 else b0
                c1 = a1 if run == 0 else b1
                for kk in range(count[c0], count[c1]):
                    dx = min_image(xi - xs[kk, 0], L_x, hx)
                    dy = min_image(yi - xs[kk, 1], L_y, hy)
                    dz = zi - xs[kk, 2]
                    if dx * dx + dy * dy + dz * dz < r2:
                        j = order[kk]
                        if j == i:
                            continue
                        if write:
                            # insertion sort by partner id in the row's scratch
                            p = m
                            jid = ids[j]
                            while p > 0 and buf_id[p - 1] > jid:
                                buf_id[p] = buf_id[p - 1]
                                buf_j[p] = buf_j[p - 1]
                                p -= 1
                            buf_id[p] = jid
                            buf_j[p] = j
                        m += 1
    if write and first + m <= limit:
        for p in range(m):
            nbr_list[first + p] = buf_j[p]
    return m


@njit(cache=True)
def _offsets(start, n):
    """Counts in start[1..n] to CSR offsets in place (start[0] = 0); returns the total."""
    for i in range(n):
        start[i + 1] += start[i]
    return start[n]


@njit(cache=True, parallel=True)
def build_neighbours(x, n_rows, n_own, fixed, ids, box, r_list, nbr_start, nbr_list, nchunk):
    """Full neighbour lists of the owned mobile rows, each sorted by partner id.

    In one pass over the rows: each chunk of rows writes its rows' lists one
    after the other into its own share of ``nbr_list`` (chunk c from
    c * len(nbr_list) // nchunk), then the shares are moved together.

    Parameters
    ----------
    x : (n_rows_cap, 3) float64
        Positions [d]; rows ``0..n_rows-1`` are used (owned, then ghosts).
    n_rows, n_own : int
        Rows present; rows ``0..n_own-1`` are owned.
    fixed : (n_rows_cap,) uint8
        1 for a bed (frozen) particle. Bed rows get no list; bed-bed pairs
        are never listed.
    ids : (n_rows_cap,) int64
        Particle ids; each list is sorted by the partners' ids.
    box : Box
        Periodic box [d].
    r_list : float
        List cutoff, contact distance plus skin [d].
    nbr_start : (n_own + 1,) int64, out
        CSR offsets into ``nbr_list``.
    nbr_list : (cap,) int32, out
        Partner rows.
    nchunk : int
        Chunks of rows for the threads (any value gives the same lists).

    Returns
    -------
    int
        The entries, if they were written; else (a chunk's share was too short) the
        length ``nbr_list`` needs, larger than it is: grow it and call again.
    """
    cells = _bin(x, n_rows, box, r_list)
    xs = _sorted_positions(x, cells)
    r2 = r_list * r_list
    cap = len(nbr_list)
    share = cap // nchunk
    # each chunk's entries (then, summed, where each chunk's entries go)
    total = np.zeros(nchunk + 1, np.int64)
    for c in prange(nchunk):
        lo, hi = chunk_bounds(c, n_own, nchunk)
        first = c * share
        # the chunk's scratch for one row's partners
        buf_id = np.empty(max(n_rows, 1), np.int64)
        buf_j = np.empty(max(n_rows, 1), np.int32)
        t = 0
        for i in range(lo, hi):
            m = 0
            if not fixed[i]:
                # past the share, rows are only counted (limit 0)
                limit = first + share if t <= share else 0
                m = _scan_row(i, x, xs, ids, box, r2, cells, buf_id, buf_j, nbr_list, first + t, limit)
            t += m
            # for now relative to the chunk's first entry
            nbr_start[i + 1] = t
        total[c + 1] = t
    longest = 0
    for c in range(nchunk):
        longest = max(longest, total[c + 1])
        total[c + 1] += total[c]
    if longest > share:
        return longest * nchunk
    # the shares moved together in chunk order (each moves down, never over one not yet moved)
    nbr_start[0] = 0
    for c in range(nchunk):
        lo, hi = chunk_bounds(c, n_own, nchunk)
        src = c * share
        dst = total[c]
        if dst != src:
            for k in range(total[c + 1] - dst):
                nbr_list[dst + k] = nbr_list[src + k]
        for i in range(lo, hi):
            nbr_start[i + 1] += dst
    return total[nchunk]


@njit(cache=True, inline="always")
def _mirror_entry(nbr_start, nbr_list, j, i):
    """The entry of row j's list whose partner is row i (lists are symmetric: there is one).

    A scan of the short list for the row index: one or two cache lines, where a bisection
    by id loaded the id of each probed partner."""
    k = nbr_start[j]
    while nbr_list[k] != i:
        k += 1
    return k


@njit(cache=True, inline="always")
def _linked(j, n_own, fixed, nchunk, c):
    """True if partner row j of a row of chunk c is an owned mobile row of that chunk."""
    return j < n_own and not fixed[j] and chunk_of(j, n_own, nchunk) == c


@njit(cache=True, parallel=True)
def link_entries(n_own, fixed, lists, nchunk):
    """Split the entries into those a row computes and those it takes, and give each its slot.

    Of a pair of two owned mobile rows of one chunk the lower row computes the
    contact once and the higher row takes it; every other entry (ghost, bed
    or other-chunk partner) is computed by its row (why: docs/computing.md,
    "The force sum: two passes per row"). The computed entries of row i
    are the slots ``comp_start[i]..comp_start[i + 1] - 1`` (in partner-id
    order), numbered chunk after chunk and row after row, so a row reads and
    writes its slots in sequence; slot g holds that contact's history.
    ``link[k]`` is the slot of entry k: ``g`` for an entry its row computes,
    ``~g`` (negative) for one it takes, whose slot keeps Delta s as seen from
    the lower row. Lists are symmetric (the distance test is mirror-exact),
    so the mirror entry is found by a scan of the partner's list.

    Parameters
    ----------
    n_own : int
        Rows ``0..n_own-1`` have lists.
    fixed : (n_rows,) uint8
        1 for bed rows.
    lists : Lists
        ``nbr_start`` and ``nbr_list`` are read (``build_neighbours``);
        ``link`` (len(nbr_list),) int32 and ``comp_start`` (>= n_own + 1,) int64
        are written.
    nchunk : int
        The chunks of rows of ``contact_forces`` (``chunks.chunk_bounds``).

    Returns
    -------
    K : int
        Computed entries (slots).
    """
    # fields by attribute before the loops, never unpacked as a tuple (bundles.py: numba's prange)
    nbr_start, nbr_list, link = lists.nbr_start, lists.nbr_list, lists.link
    comp_start = lists.comp_start
    comp_start[0] = 0
    for c in prange(nchunk):
        lo, hi = chunk_bounds(c, n_own, nchunk)
        for i in range(lo, hi):
            m = 0
            for k in range(nbr_start[i], nbr_start[i + 1]):
                j = nbr_list[k]
                m += j > i or not _linked(j, n_own, fixed, nchunk, c)
            comp_start[i + 1] = m
    total = _offsets(comp_start, n_own)
    for c in prange(nchunk):
        lo, hi = chunk_bounds(c, n_own, nchunk)
        for i in range(lo, hi):
            g = comp_start[i]
            for k in range(nbr_start[i], nbr_start[i + 1]):
                j = nbr_list[k]
                if not _linked(j, n_own, fixed, nchunk, c):
                    link[k] = g
                    g += 1
                elif j > i:
                    # the higher row's entry of this pair is set here, before that row is reached
                    link[k] = g
                    link[_mirror_entry(nbr_start, nbr_list, j, i)] = ~g
                    g += 1
    return total
