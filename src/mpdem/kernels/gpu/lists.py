"""Neighbour lists built on the GPU, the contact history carried from the old lists to the new.

The lists are those of ``kernels.neighbours.build_neighbours``: for each owned mobile row, every
row within ``r_list`` (bed rows included), sorted by partner id. The cells are at least
``r_list`` wide across the periodic box and ``r_list`` tall, z hashed modulo ``nz`` above a
bound on the grid (as the CPU's). A cell's rows land in it in whatever order the atomics give,
which changes nothing: each row's partners are sorted by id before they are used.

The build, each step a launch:

1. ``z_range``: the lowest and highest centre of all rows;
2. ``bin_rows``: each row's cell, and the cells' counts;
3. ``scan``: counts to offsets (one block);
4. ``fill_cells``: the rows by cell;
5. ``count_partners``, ``scan``: each row's list length, then the lists' offsets;
6. ``write_partners``: each row's partners, sorted by id in place;
7. ``carry_history``: each new entry takes the history and stamp of the old entry with the same
   partner (both lists sorted by id: one merge a row), a new pair a stale stamp.

Only while the rows keep their places (one rank, no migration, no reordering): the old and the new
lists name partners by the same row indices.

The same build with no host round trip (``engine.gpu_rebuild = "device"``: the ``*_in`` kernels) reads
what the host would have sized from the GPU's own arrays: ``grid_depth`` turns the z range into the
grid's z layers (``dims``, at most the capacity of the cells' arrays; fewer layers only hash more rows
into a cell, the lists are the same), and the lists go into arrays of a fixed capacity
(``write_partners_in``), the entries counted into the record ``red`` with a flag when they do not fit;
then nothing is written past the capacity and the host, which reads ``red`` anyway after the forces
(whose kernels do nothing on the flag), builds the lists again with room.
"""
import math

import numpy as np

from ..neighbours import _next_cell
from .reduce import BLOCK_MAX, max_into, min_into
from .rounded import min_image, norm2
from .runtime import cuda, device, device_cuda

# the slots of a rebuild without the host in the step's reduction records (``step.RED_D2`` .. ``RED_CONTACTS``
# before them; the engine's ``red`` has ``RED_SLOTS``, and so do ``rec``'s rows with rebuilds inside the launch):
# the new lists' entries (exact below 2**53; -1.0 in a row of ``rec``: no rebuild that step), and 1.0 when they
# did not fit the lists' capacity (nothing written past it)
RED_ENTRIES, RED_OVERFLOW = 6, 7
RED_SLOTS = 8


@cuda.jit
def z_range(n_rows, x, out):
    """out[0] = min(out[0], the rows' z), out[1] = max(out[1], the rows' z) [d]; out starts at
    (inf, -inf)."""
    room = cuda.shared.array(BLOCK_MAX, np.float64)
    lo = math.inf
    hi = -math.inf
    for i in range(cuda.grid(1), n_rows, cuda.gridsize(1)):
        z = x[i, 2]
        lo = min(lo, z)
        hi = max(hi, z)
    min_into(out, 0, lo, room)
    max_into(out, 1, hi, room)


@device
def _cell_of(i, x, nx, ny, nz, cx, cy, zmin, r_list):
    """The cell of row i: columns of cx x cy [d] across the box, layers r_list [d] tall from zmin
    hashed modulo nz."""
    ix = min(int(x[i, 0] / cx), nx - 1)
    iy = min(int(x[i, 1] / cy), ny - 1)
    iz = int((x[i, 2] - zmin) / r_list) % nz
    return (iz * ny + iy) * nx + ix


@cuda.jit
def bin_rows(n_rows, x, nx, ny, nz, cx, cy, zmin, r_list, cell, count):
    """cell[i]: the cell of row i; count[c + 1] += 1 for each row of cell c (count zeroed before)."""
    for i in range(cuda.grid(1), n_rows, cuda.gridsize(1)):
        c = _cell_of(i, x, nx, ny, nz, cx, cy, zmin, r_list)
        cell[i] = c
        cuda.atomic.add(count, c + 1, 1)


@cuda.jit
def grid_depth(zr, nx, ny, nz_cap, r_list, dims):
    """The cell grid's z layers from the rows' z range, on the GPU (one thread does it).

    Parameters
    ----------
    zr : (3,) float64
        In: the rows' lowest and highest z [d] in zr[0], zr[1] (``z_range``'s). Out: the lowest in
        zr[2], and zr[0], zr[1] back to (inf, -inf) for the next ``z_range``.
    nx, ny : int
        The grid's columns across the box.
    nz_cap : int
        The most z layers the cells' arrays hold (``nx * ny * nz_cap + 1`` counts).
    r_list : float
        A layer's height [d].
    dims : (2,) int64, out
        The z layers nz (as the host's build: one a layer of the range, at most ``nz_cap``) and the
        cells nx * ny * nz.
    """
    if cuda.grid(1) == 0:
        q = (zr[1] - zr[0]) / r_list
        nz = nz_cap
        if q >= 0.0 and q < nz_cap - 1:
            nz = int(q) + 1
        dims[0] = nz
        dims[1] = nx * ny * nz
        zr[2] = zr[0]
        zr[0] = math.inf
        zr[1] = -math.inf


@cuda.jit
def zero_cells(count, dims):
    """count[0..dims[1]] = 0 (the cells' counts of ``grid_depth``'s grid; ``count`` int32)."""
    for c in range(cuda.grid(1), dims[1] + 1, cuda.gridsize(1)):
        count[c] = 0


@cuda.jit
def bin_rows_in(n_rows, x, nx, ny, cx, cy, zr, dims, r_list, cell, count):
    """``bin_rows`` with the grid's z layers dims[0] and its lowest z zr[2] [d] read on the GPU
    (``grid_depth``)."""
    nz = dims[0]
    zmin = zr[2]
    for i in range(cuda.grid(1), n_rows, cuda.gridsize(1)):
        c = _cell_of(i, x, nx, ny, nz, cx, cy, zmin, r_list)
        cell[i] = c
        cuda.atomic.add(count, c + 1, 1)


@cuda.jit
def scan(a, n):
    """a[1..n] counts -> a[0..n] offsets in place (a[0] = 0; a[k] = the sum of the counts before k):
    one block, each thread a stretch of the array."""
    part = cuda.shared.array(BLOCK_MAX, np.int64)
    _scan(a, n, part, a, False)


@cuda.jit
def scan_in(a, b, dims):
    """``scan`` of the cells' counts a[1..dims[1]] (``grid_depth``'s cells), the offsets also copied to
    b[0..dims[1]] (``fill_cells`` consumes that copy); one block."""
    part = cuda.shared.array(BLOCK_MAX, np.int64)
    _scan(a, dims[1], part, b, True)


@device_cuda
def _scan(a, n, part, b, copy):
    """The body of ``scan`` (every thread of the one block calls it; ``part`` (BLOCK_MAX,) int64 shared),
    each offset also written to ``b`` with ``copy``."""
    t = cuda.threadIdx.x
    threads = cuda.blockDim.x
    stretch = (n + threads - 1) // threads
    lo = 1 + t * stretch
    hi = min(lo + stretch, n + 1)
    total = 0
    for k in range(lo, hi):
        total += a[k]
    part[t] = total
    cuda.syncthreads()
    if t == 0:
        run = 0
        for u in range(threads):
            here = part[u]
            part[u] = run
            run += here
    cuda.syncthreads()
    run = part[t]
    for k in range(lo, hi):
        run += a[k]
        a[k] = run
        if copy:
            b[k] = run
    if t == 0:
        a[0] = 0
        if copy:
            b[0] = 0


@cuda.jit
def fill_cells(n_rows, cell, fill, order):
    """order[fill[c]...]: the rows of cell c (``fill`` a copy of the cells' offsets, consumed)."""
    for i in range(cuda.grid(1), n_rows, cuda.gridsize(1)):
        at = cuda.atomic.add(fill, cell[i], 1)
        order[at] = i


# the a-th of the cells i - 1, i, i + 1 along a periodic axis of n cells: the CPU build's function
_around = device(_next_cell.py_func)


@device
def _partners(i, x, ids, cell, start, order, nx, ny, nz, L_x, L_y, hx, hy, r2, out, first, write):
    """Row i's partners within sqrt(r2) [d] in the 27 cells around its own (fewer where an axis has
    fewer than 3 cells); written from out[first] and sorted by id when ``write``. Returns how many."""
    c = cell[i]
    ix = c % nx
    iy = (c // nx) % ny
    iz = c // (nx * ny)
    xi = x[i, 0]
    yi = x[i, 1]
    zi = x[i, 2]
    m = 0
    for a in range(min(nz, 3)):
        jz = _around(iz, a, nz)
        for b in range(min(ny, 3)):
            jy = _around(iy, b, ny)
            for e in range(min(nx, 3)):
                jc = (jz * ny + jy) * nx + _around(ix, e, nx)
                for k in range(start[jc], start[jc + 1]):
                    j = order[k]
                    if j == i:
                        continue
                    dx = min_image(xi - x[j, 0], L_x, hx)
                    dy = min_image(yi - x[j, 1], L_y, hy)
                    if norm2(dx, dy, zi - x[j, 2]) < r2:
                        if write:
                            # insertion by partner id
                            p = first + m
                            jid = ids[j]
                            while p > first and ids[out[p - 1]] > jid:
                                out[p] = out[p - 1]
                                p -= 1
                            out[p] = j
                        m += 1
    return m


@cuda.jit
def count_partners(n_own, x, ids, fixed, cell, start, order, nx, ny, nz, L_x, L_y, hx, hy, r2, counts):
    """counts[i + 1] = row i's partners (0 for a bed row)."""
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        m = 0
        if not fixed[i]:
            m = _partners(i, x, ids, cell, start, order, nx, ny, nz, L_x, L_y, hx, hy, r2, counts, 0, False)
        counts[i + 1] = m


@cuda.jit
def write_partners(n_own, x, ids, fixed, cell, start, order, nx, ny, nz, L_x, L_y, hx, hy, r2, nbr_start, nbr):
    """nbr[nbr_start[i]...nbr_start[i + 1]]: row i's partners, sorted by id."""
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        if not fixed[i]:
            _partners(i, x, ids, cell, start, order, nx, ny, nz, L_x, L_y, hx, hy, r2, nbr, nbr_start[i], True)


@cuda.jit
def count_partners_in(n_own, x, ids, fixed, cell, start, order, nx, ny, dims, L_x, L_y, hx, hy, r2, counts):
    """``count_partners`` with the grid's z layers dims[0] read on the GPU (``grid_depth``)."""
    nz = dims[0]
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        m = 0
        if not fixed[i]:
            m = _partners(i, x, ids, cell, start, order, nx, ny, nz, L_x, L_y, hx, hy, r2, counts, 0, False)
        counts[i + 1] = m


@cuda.jit
def write_partners_in(n_own, x, ids, fixed, cell, start, order, nx, ny, dims, L_x, L_y, hx, hy, r2, nbr_start, nbr,
                      red):
    """``write_partners`` into lists of a fixed capacity, the grid's z layers dims[0] read on the GPU.

    Parameters
    ----------
    nbr_start : (n_own + 1,) int64
        The lists' offsets (``count_partners_in``, ``scan``); nbr_start[n_own] the entries K.
    nbr : (C,) int32, out
        Room for C entries (the capacity); written only when K <= C.
    red : (RED_SLOTS,) float64, out
        red[RED_ENTRIES] = K, red[RED_OVERFLOW] = 1.0 if K > C else 0.0 (by the grid's first thread;
        the forces' kernels do nothing on the flag, the host builds the lists again).
    """
    k = nbr_start[n_own]
    over = k > nbr.shape[0]
    if cuda.grid(1) == 0:
        red[RED_ENTRIES] = np.float64(k)
        red[RED_OVERFLOW] = 1.0 if over else 0.0
    if over:
        return
    nz = dims[0]
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        if not fixed[i]:
            _partners(i, x, ids, cell, start, order, nx, ny, nz, L_x, L_y, hx, hy, r2, nbr, nbr_start[i], True)


@device
def _carry_row(i, ids, old_start, old_nbr, old_hist, old_stamp, new_start, new_nbr, new_hist, new_stamp, stale):
    """Row i's new entries' Delta s and stamps (``carry_history``): a merge of its two lists by partner id."""
    p = old_start[i]
    pe = old_start[i + 1]
    for k in range(new_start[i], new_start[i + 1]):
        j = new_nbr[k]
        jid = ids[j]
        while p < pe and ids[old_nbr[p]] < jid:
            p += 1
        if p < pe and old_nbr[p] == j:
            for a in range(3):
                new_hist[k, a] = old_hist[p, a]
            new_stamp[k] = old_stamp[p]
        else:
            for a in range(3):
                new_hist[k, a] = 0.0
            new_stamp[k] = stale


@cuda.jit
def carry_history(n_own, ids, old_start, old_nbr, old_hist, old_stamp, new_start, new_nbr, new_hist, new_stamp,
                  stale):
    """Each new entry's Delta s and stamp: the old entry's with the same partner, else zeros and
    ``stale`` (a stamp that says: not in contact at the last evaluation)."""
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        _carry_row(i, ids, old_start, old_nbr, old_hist, old_stamp, new_start, new_nbr, new_hist, new_stamp, stale)


@cuda.jit
def carry_history_in(n_own, ids, old_start, old_nbr, old_hist, old_stamp, new_start, new_nbr, new_hist, new_stamp,
                     stale):
    """``carry_history`` into lists of a fixed capacity (new_nbr's length, as new_hist's and new_stamp's):
    nothing when the new lists did not fit (new_start[n_own] past it; ``write_partners_in``)."""
    if new_start[n_own] > new_nbr.shape[0]:
        return
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        _carry_row(i, ids, old_start, old_nbr, old_hist, old_stamp, new_start, new_nbr, new_hist, new_stamp, stale)


@cuda.jit
def copy_rows(n, src, dst):
    """dst[:n] = src[:n] for (n, 3) arrays."""
    for i in range(cuda.grid(1), n, cuda.gridsize(1)):
        for a in range(3):
            dst[i, a] = src[i, a]


@cuda.jit
def zero(n, a):
    """a[:n] = 0 (a 1-d integer array)."""
    for i in range(cuda.grid(1), n, cuda.gridsize(1)):
        a[i] = 0


@cuda.jit
def gather_rows(rows, x, v, omega, out):
    """out[0, k], out[1, k], out[2, k] = x, v, omega of row rows[k] (the ghost refresh's sources)."""
    for k in range(cuda.grid(1), rows.size, cuda.gridsize(1)):
        i = rows[k]
        for a in range(3):
            out[0, k, a] = x[i, a]
            out[1, k, a] = v[i, a]
            out[2, k, a] = omega[i, a]


@cuda.jit
def pack_ghosts(rows, at, stride, x, v, omega, buf):
    """The ghost refresh's send buffer on the GPU (``parallel.GhostPlan.layout``): row rows[t]'s x, v and
    omega at buf[at[t] + f * stride[t] + a] for f = 0, 1, 2."""
    for t in range(cuda.grid(1), rows.size, cuda.gridsize(1)):
        i = rows[t]
        b = at[t]
        s = stride[t]
        for a in range(3):
            buf[b + a] = x[i, a]
            buf[b + s + a] = v[i, a]
            buf[b + 2 * s + a] = omega[i, a]


@cuda.jit
def unpack_ghosts(rows, at, stride, buf, x, v, omega):
    """The ghost rows rows[t]'s x, v and omega from the refresh's receive buffer (``pack_ghosts``' layout)."""
    for t in range(cuda.grid(1), rows.size, cuda.gridsize(1)):
        i = rows[t]
        b = at[t]
        s = stride[t]
        for a in range(3):
            x[i, a] = buf[b + a]
            v[i, a] = buf[b + s + a]
            omega[i, a] = buf[b + 2 * s + a]


@cuda.jit
def count_contacts_of(rows, start, stamp, now, counts):
    """counts[t]: the entries of row rows[t] in contact at the last evaluation (stamp ``now``): the
    compact slots ``kernels.history.count_contacts`` gives the rows that leave at a migration."""
    for t in range(cuda.grid(1), rows.size, cuda.gridsize(1)):
        i = rows[t]
        m = 0
        for k in range(start[i], start[i + 1]):
            if stamp[k] == now:
                m += 1
        counts[t] = m


@cuda.jit
def pack_contacts_of(rows, offsets, ids, start, nbr, hist, stamp, now, slot_id, slot_ds):
    """Row rows[t]'s entries in contact as compact slots from offsets[t] on (partner ids ascending, Delta s
    [d] in the row's view): ``kernels.history.entries_to_slots`` for some rows (entry k is slot k here)."""
    for t in range(cuda.grid(1), rows.size, cuda.gridsize(1)):
        i = rows[t]
        p = offsets[t]
        for k in range(start[i], start[i + 1]):
            if stamp[k] == now:
                slot_id[p] = ids[nbr[k]]
                for a in range(3):
                    slot_ds[p, a] = hist[k, a]
                p += 1


@cuda.jit
def permute_kept3(n_rows, origin, src, dst):
    """dst[i, :] = src[origin[i], :] for the rows with origin[i] >= 0 ((n, 3) arrays; the others are the
    rows that arrived at a migration, which the host fills: ``scatter_rows3``)."""
    for i in range(cuda.grid(1), n_rows, cuda.gridsize(1)):
        j = origin[i]
        if j >= 0:
            for a in range(3):
                dst[i, a] = src[j, a]


@cuda.jit
def scatter_rows3(rows, src, dst):
    """dst[rows[k], :] = src[k, :] for (n, 3) arrays (the rows that arrived at a migration, from the host)."""
    for k in range(cuda.grid(1), rows.size, cuda.gridsize(1)):
        i = rows[k]
        for a in range(3):
            dst[i, a] = src[k, a]


@cuda.jit
def carry_history_migrated(n_own, origin, old_ids, ids, old_start, old_nbr, old_hist, old_stamp, arr_start, arr_id,
                           arr_ds, new_start, new_nbr, new_hist, new_stamp, stale, now):
    """Each new entry's Delta s and stamp after a migration: new row i was old row origin[i] (>= 0), whose
    entries it merges with by partner id (``carry_history_moved``), or arrived from another rank as
    arrival a = -1 - origin[i], whose compact slots (arr_id ascending, arr_ds +0.0 for zero, from
    arr_start[a]) it merges with as ``kernels.history.slots_to_entries`` does: a slot's partner in the new
    list gets it and the stamp ``now``; any other entry zeros and ``stale``."""
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        o = origin[i]
        if o >= 0:
            _carry_row_moved(i, origin, old_ids, ids, old_start, old_nbr, old_hist, old_stamp, new_start, new_nbr,
                             new_hist, new_stamp, stale)
            continue
        a = -1 - o
        p = arr_start[a]
        pe = arr_start[a + 1]
        for k in range(new_start[i], new_start[i + 1]):
            jid = ids[new_nbr[k]]
            while p < pe and arr_id[p] < jid:
                p += 1
            if p < pe and arr_id[p] == jid:
                for c in range(3):
                    new_hist[k, c] = arr_ds[p, c]
                new_stamp[k] = now
            else:
                for c in range(3):
                    new_hist[k, c] = 0.0
                new_stamp[k] = stale


@cuda.jit
def entry_rows(n_own, start, row):
    """row[e] = i for every entry e of row i's list (``start``: the lists' (n_own + 1,) offsets)."""
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        for e in range(start[i], start[i + 1]):
            row[e] = i


@cuda.jit
def sort_cells_of(n_rows, x, nx, ny, cx, cy, zr, dims, r_list, col_base, col_size, col_local, cell, count):
    """The rows' cells in the order the rows are sorted by (``engine.order.sort_rows``'s: columns of about
    ``SORT_COLUMN`` x ``SORT_COLUMN`` cells one after the other, z-major inside each), for a counting sort
    on the GPU (engine.gpu_sort = "device").

    Parameters
    ----------
    n_rows : int
    x : (n_rows, 3) float64
        Positions [d].
    nx, ny, cx, cy, zr, dims, r_list
        The list build's grid, as ``bin_rows_in``'s (``grid_depth``'s dims and zr).
    col_base, col_size, col_local : (nx * ny,) int64
        For the column of cells (ix, iy) at ix + nx iy: the cells across the columns before its own,
        those across its own, and its place among them (``engine.gpu.sort_columns``).
    cell : (n_rows,) int32, out
        Each row's rank of cell: col_base nz + iz col_size + col_local (a permutation of the cells).
    count : int32, in and out
        count[c + 1] += 1 for each row of ranked cell c (zeroed before).
    """
    nz = dims[0]
    zmin = zr[2]
    for i in range(cuda.grid(1), n_rows, cuda.gridsize(1)):
        c = _cell_of(i, x, nx, ny, nz, cx, cy, zmin, r_list)
        xy = c % (nx * ny)
        iz = c // (nx * ny)
        r = col_base[xy] * nz + iz * col_size[xy] + col_local[xy]
        cell[i] = r
        cuda.atomic.add(count, r + 1, 1)


@cuda.jit
def sort_within_cells(dims, start, order, ids):
    """Each cell's rows (order[start[c]:start[c + 1]], in whatever order the atomics left them) sorted by
    id, a thread a cell: the permutation is the same whichever the threads' order."""
    for c in range(cuda.grid(1), dims[1], cuda.gridsize(1)):
        lo = start[c]
        for k in range(lo + 1, start[c + 1]):
            r = order[k]
            key = ids[r]
            p = k
            while p > lo and ids[order[p - 1]] > key:
                order[p] = order[p - 1]
                p -= 1
            order[p] = r


@cuda.jit
def permute_rows(n_rows, perm, src, dst):
    """dst[i] = src[perm[i]] for the first n_rows rows (1-d arrays of any type; ``permute_rows3`` for (n, 3))."""
    for i in range(cuda.grid(1), n_rows, cuda.gridsize(1)):
        dst[i] = src[perm[i]]


@cuda.jit
def permute_rows3(n_rows, perm, src, dst):
    """dst[i, :] = src[perm[i], :] for (n, 3) arrays."""
    for i in range(cuda.grid(1), n_rows, cuda.gridsize(1)):
        j = perm[i]
        for a in range(3):
            dst[i, a] = src[j, a]


@cuda.jit
def carry_history_moved(n_own, perm, old_ids, ids, old_start, old_nbr, old_hist, old_stamp, new_start, new_nbr,
                        new_hist, new_stamp, stale):
    """``carry_history_in`` across a reordering of the rows: new row i was old row perm[i]; its new
    entries merge with that row's old ones by partner id (``old_ids`` the rows' ids in the old order,
    ``ids`` in the new). Nothing when the new lists did not fit their capacity."""
    if new_start[n_own] > new_nbr.shape[0]:
        return
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        o = perm[i]
        p = old_start[o]
        pe = old_start[o + 1]
        for k in range(new_start[i], new_start[i + 1]):
            jid = ids[new_nbr[k]]
            while p < pe and old_ids[old_nbr[p]] < jid:
                p += 1
            if p < pe and old_ids[old_nbr[p]] == jid:
                for a in range(3):
                    new_hist[k, a] = old_hist[p, a]
                new_stamp[k] = old_stamp[p]
            else:
                for a in range(3):
                    new_hist[k, a] = 0.0
                new_stamp[k] = stale


@cuda.jit
def entry_rows_in(n_own, start, row):
    """``entry_rows`` into a fixed capacity (``row``'s length): nothing when the lists did not fit."""
    if start[n_own] > row.shape[0]:
        return
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        for e in range(start[i], start[i + 1]):
            row[e] = i


@device_cuda
def rebuild_phases(n_own, x, x_ref, ids, fixed, L_x, L_y, hx, hy, old, new, stale, cells, grid_shape, red, room, part,
                   old_ids, perm, moved):
    """A list rebuild as phases of a cooperative launch (``step.advance_lists``; engine.gpu_rebuild =
    "launch"): every thread of the grid calls it, the phases parted by grid barriers. The build of the
    ``*_in`` kernels, one phase each: the z range (and the cells' counts zeroed), the rows binned, the
    cells' offsets (one block), the rows by cell (and the z range set back), each row's partners counted,
    the lists' offsets (one block), the partners written sorted by id, the history carried and x_ref = x.

    Parameters
    ----------
    n_own : int
        Rows (one rank: no ghosts).
    x : (n_own, 3) float64
        The positions the lists are built from [d]; copied into ``x_ref`` (n_own, 3).
    ids : (n_own,) int64, fixed : (n_own,) uint8
        The rows' ids (the lists' order) and whether a row is the bed's (no list).
    L_x, L_y, hx, hy : float
        The periodic box and its halves [d].
    old, new : tuples (start, nbr, hist, stamp)
        The current lists ((n_own + 1,) int64 offsets, (K,) int32 partners, (K, 3) float64 Delta s [d],
        (K,) uint32 stamps) and the arrays the new ones go into (their capacity: len(new nbr), as new
        hist's and stamp's).
    stale : uint32
        The stamp of a new pair (not in contact at the last evaluation).
    cells : tuple (zr, count, fill, cell, order)
        (3,) float64 z range, (inf, -inf) between builds; (C + 1,) int32 counts and their copy, room for
        ``grid_shape``'s nx * ny * nz_cap cells; (n_own,) int32 each row's cell and the rows by cell.
    grid_shape : tuple (nx, ny, nz_cap, cx, cy, r_list, r2)
        The grid's columns, its most z layers, a column's sides [d], a layer's height r_list [d] and
        r_list**2 [d^2] (pairs closer than sqrt(r2) are listed).
    red : float64 (>= RED_SLOTS,)
        The step's record: red[RED_ENTRIES] = the new lists' entries K; red[RED_OVERFLOW] = 1.0 when K is
        past the capacity (nothing written to the new lists then).
    room : float64 shared (>= BLOCK_MAX,), part : int64 shared (BLOCK_MAX,)
        The block's room for its reductions and for the scans.
    old_ids, perm, moved
        With ``moved`` the rows were just reordered (``sort_phases``): new row i was old row perm[i]
        ((n_own,) int32) and ``old_ids`` (n_own,) int64 are the rows' ids in the old order, which the old
        lists name (the history carried by partner id, ``carry_history_moved``); else not read.

    Returns
    -------
    bool
        True when the lists were built (the same answer in every thread), False on an overflow.
    """
    grid = cuda.cg.this_grid()
    first = cuda.grid(1)
    threads = cuda.gridsize(1)
    zr, count, fill, cell, order = cells
    nx, ny, nz_cap, cx, cy, r_list, r2 = grid_shape
    o_start, o_nbr, o_hist, o_stamp = old
    n_start, n_nbr, n_hist, n_stamp = new
    lo = math.inf
    hi = -math.inf
    for i in range(first, n_own, threads):
        lo = min(lo, x[i, 2])
        hi = max(hi, x[i, 2])
    for c in range(first, count.shape[0], threads):
        count[c] = 0
    min_into(zr, 0, lo, room)
    max_into(zr, 1, hi, room)
    grid.sync()
    # the grid's z layers as ``grid_depth``'s, in every thread alike
    q = (zr[1] - zr[0]) / r_list
    nz = nz_cap
    if q >= 0.0 and q < nz_cap - 1:
        nz = int(q) + 1
    zmin = zr[0]
    for i in range(first, n_own, threads):
        c = _cell_of(i, x, nx, ny, nz, cx, cy, zmin, r_list)
        cell[i] = c
        cuda.atomic.add(count, c + 1, 1)
    grid.sync()
    if cuda.blockIdx.x == 0:
        _scan(count, nx * ny * nz, part, fill, True)
    grid.sync()
    for i in range(first, n_own, threads):
        at = cuda.atomic.add(fill, cell[i], 1)
        order[at] = i
    if first == 0:
        zr[0] = math.inf
        zr[1] = -math.inf
    grid.sync()
    for i in range(first, n_own, threads):
        m = 0
        if not fixed[i]:
            m = _partners(i, x, ids, cell, count, order, nx, ny, nz, L_x, L_y, hx, hy, r2, n_start, 0, False)
        n_start[i + 1] = m
    grid.sync()
    if cuda.blockIdx.x == 0:
        _scan(n_start, n_own, part, n_start, False)
    grid.sync()
    k = n_start[n_own]
    if first == 0:
        red[RED_ENTRIES] = np.float64(k)
    if k > n_nbr.shape[0]:
        if first == 0:
            red[RED_OVERFLOW] = 1.0
        return False
    for i in range(first, n_own, threads):
        if not fixed[i]:
            _partners(i, x, ids, cell, count, order, nx, ny, nz, L_x, L_y, hx, hy, r2, n_nbr, n_start[i], True)
    grid.sync()
    for i in range(first, n_own, threads):
        if moved:
            _carry_row_moved(i, perm, old_ids, ids, o_start, o_nbr, o_hist, o_stamp, n_start, n_nbr, n_hist, n_stamp,
                             stale)
        else:
            _carry_row(i, ids, o_start, o_nbr, o_hist, o_stamp, n_start, n_nbr, n_hist, n_stamp, stale)
        for a in range(3):
            x_ref[i, a] = x[i, a]
    grid.sync()
    return True


@device
def _carry_row_moved(i, perm, old_ids, ids, old_start, old_nbr, old_hist, old_stamp, new_start, new_nbr, new_hist,
                     new_stamp, stale):
    """Row i's new entries' Delta s and stamps (``carry_history_moved``): new row i was old row perm[i]."""
    o = perm[i]
    p = old_start[o]
    pe = old_start[o + 1]
    for k in range(new_start[i], new_start[i + 1]):
        jid = ids[new_nbr[k]]
        while p < pe and old_ids[old_nbr[p]] < jid:
            p += 1
        if p < pe and old_ids[old_nbr[p]] == jid:
            for a in range(3):
                new_hist[k, a] = old_hist[p, a]
            new_stamp[k] = old_stamp[p]
        else:
            for a in range(3):
                new_hist[k, a] = 0.0
            new_stamp[k] = stale


@device_cuda
def _gather3(n_own, perm, src, dst):
    """dst[i] = src[perm[i]] for this thread's rows of (n, 3) arrays."""
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        j = perm[i]
        for a in range(3):
            dst[i, a] = src[j, a]


@device_cuda
def _copy3(n_own, src, dst, scatter, perm):
    """dst[i] = src[i] (or, ``scatter``, dst[perm[i]] = src[i]) for this thread's rows of (n, 3) arrays."""
    for i in range(cuda.grid(1), n_own, cuda.gridsize(1)):
        j = perm[i] if scatter else i
        for a in range(3):
            dst[j, a] = src[i, a]


@device_cuda
def sort_phases(n_own, rows, spares, perm, cells, grid_shape, columns, room, part, undo):
    """The rows ordered by cell as phases of a cooperative launch (``engine.gpu_sort = "device"`` with
    engine.gpu_rebuild = "launch"; every thread of the grid calls it, the phases parted by grid barriers):
    the cells ranked in ``engine.order.sort_rows``'s order (``sort_cells_of``), a counting sort by them,
    each cell's rows by id (``sort_within_cells``), then every row array gathered into its spare and copied
    back; the ids are gathered into their spare only (the history's carry reads the old ones; the caller
    copies them back). With ``undo``, instead, the permutation ``perm`` of the last call taken back (the
    spares still hold the gathered rows): each row scattered to where it was.

    Parameters
    ----------
    rows : tuple (x, v, omega, f, torque, wall_ds, fixed, ids, moved, xo, vo, wo)
        The rows' current arrays ((n, 3) float64; wall_ds permuted only when it has a row a row;
        (n,) uint8 and int64; (n,) int32 each row's row in the host's State, permuted with them), and
        the fused drift's other buffer of x, v, omega (the rows copied there as well; the same arrays as
        x, v, omega without it).
    spares : tuple
        Arrays shaped as ``rows``'s first nine, written.
    perm : (n,) int32, out
        New row i is old row perm[i].
    cells, grid_shape : as ``rebuild_phases``'s
    columns : tuple (col_base, col_size, col_local)
        ``engine.gpu.sort_columns``'s (nx * ny,) int64 arrays.
    """
    grid = cuda.cg.this_grid()
    first = cuda.grid(1)
    threads = cuda.gridsize(1)
    x, v, omega, f, torque, wall_ds, fixed, ids, moved, xo, vo, wo = rows
    sx, sv, sw, sf, st, swall, sfixed, sids, smoved = spares
    wall = wall_ds.shape[0] >= n_own
    if not undo:
        zr, count, fill, cell, order = cells
        nx, ny, nz_cap, cx, cy, r_list, r2 = grid_shape
        col_base, col_size, col_local = columns
        lo = math.inf
        hi = -math.inf
        for i in range(first, n_own, threads):
            lo = min(lo, x[i, 2])
            hi = max(hi, x[i, 2])
        for c in range(first, count.shape[0], threads):
            count[c] = 0
        min_into(zr, 0, lo, room)
        max_into(zr, 1, hi, room)
        grid.sync()
        q = (zr[1] - zr[0]) / r_list
        nz = nz_cap
        if q >= 0.0 and q < nz_cap - 1:
            nz = int(q) + 1
        zmin = zr[0]
        for i in range(first, n_own, threads):
            c = _cell_of(i, x, nx, ny, nz, cx, cy, zmin, r_list)
            xy = c % (nx * ny)
            r = col_base[xy] * nz + (c // (nx * ny)) * col_size[xy] + col_local[xy]
            cell[i] = r
            cuda.atomic.add(count, r + 1, 1)
        grid.sync()
        ncell = nx * ny * nz
        if cuda.blockIdx.x == 0:
            _scan(count, ncell, part, fill, True)
        grid.sync()
        for i in range(first, n_own, threads):
            at = cuda.atomic.add(fill, cell[i], 1)
            perm[at] = i
        if first == 0:
            zr[0] = math.inf
            zr[1] = -math.inf
        grid.sync()
        for c in range(first, ncell, threads):
            lo_c = count[c]
            for k in range(lo_c + 1, count[c + 1]):
                r = perm[k]
                key = ids[r]
                p = k
                while p > lo_c and ids[perm[p - 1]] > key:
                    perm[p] = perm[p - 1]
                    p -= 1
                perm[p] = r
        grid.sync()
        _gather3(n_own, perm, x, sx)
        _gather3(n_own, perm, v, sv)
        _gather3(n_own, perm, omega, sw)
        _gather3(n_own, perm, f, sf)
        _gather3(n_own, perm, torque, st)
        if wall:
            _gather3(n_own, perm, wall_ds, swall)
        for i in range(first, n_own, threads):
            j = perm[i]
            sfixed[i] = fixed[j]
            sids[i] = ids[j]
            smoved[i] = moved[j]
        grid.sync()
    # the gathered rows back into the rows' own arrays (where they stand, or, undone, where they were)
    _copy3(n_own, sx, x, undo, perm)
    _copy3(n_own, sv, v, undo, perm)
    _copy3(n_own, sw, omega, undo, perm)
    _copy3(n_own, sx, xo, undo, perm)
    _copy3(n_own, sv, vo, undo, perm)
    _copy3(n_own, sw, wo, undo, perm)
    _copy3(n_own, sf, f, undo, perm)
    _copy3(n_own, st, torque, undo, perm)
    if wall:
        _copy3(n_own, swall, wall_ds, undo, perm)
    for i in range(first, n_own, threads):
        j = perm[i] if undo else i
        fixed[j] = sfixed[i]
        moved[j] = smoved[i]
    grid.sync()
