"""Decomposition into a grid of domains: where particles live and how ranks agree.

The only module that moves particles between ranks (ARCHITECTURE.md).
The ranks form a Px x Py x Pz grid (``domains``): Px x Py columns of equal
widths in x and y, each cut into Pz slabs along z. The rank of slab k of a
column owns the particles of the column with z in [b_k, b_{k+1}), b_0 = -inf,
b_Pz = +inf; each column balances its own slab bounds. Px = Py = 1 is the
slab decomposition. At neighbour-list rebuilds (``rebuild``):

1. migrate: owned particles that left the domain go to their owner, with
   force, torque and contact slots;
2. rebalance: in each column where max/mean over its ranks of the balanced
   measure exceeds ``1 + tolerance``, the inner bounds move (damped) toward
   the heights that split it equally, every rank learns the new bounds, and
   particles migrate again. The measure is the owned
   mobile particles, or with ``by_work`` each rank's compute seconds since
   the last rebuild (the engine's, without communication): the bounds then
   split all mobile heights into equal sums of each particle's share of its
   rank's work (a rank's seconds over its particles). No rank sees the
   others' heights: each counts its own in ``HIST_BINS`` bins over the
   column's height range, the counts are summed over the column's ranks (or
   gathered, to weight each rank's by its work), and the bounds fall where
   the sums reach k / Pz, within a bin (the pile's height / HIST_BINS) of the
   exact quantiles;
3. halo: every rank receives the particles within ``r_list`` of its box
   (periodic in x and y) from the ranks whose boxes reach that far (not only
   the next ones, so a domain thinner than the halo still gets its ghosts
   right); the plan is kept and ``refresh`` re-sends x, v, omega of the same
   rows on the other steps.

Rows travel as contiguous numpy arrays through ``parallel.Channel``: counts
first, then data only between ranks that have something to send.

Nothing here changes arithmetic: forces depend only on ids and positions, so
the state is bit-identical for any number of ranks and any grid. Reductions
are exact (max, integer sums). Ghosts keep their owners' coordinates in
[0, L): the minimum image of the force kernels joins them across a periodic
face, as it joins the rows of one rank.
"""
from __future__ import annotations

import math

import numpy as np

from . import domains
from .parallel import channel
from .state import FIELDS, PARTICLE, State, concat_rows, select_rows

# what travels with a particle that changes rank: per-particle fields, then per-contact ones
MOVING = tuple(f for f in FIELDS if f.migrates)

# bins of the mobile heights' histogram the bounds are cut from (``Domain.histogram_bounds``): a bound falls within
# (height range / HIST_BINS) of the exact quantile, and a rank sends these counts, not its heights
HIST_BINS = 4096

# point-to-point tags of the rebuild exchanges (the refresh uses parallel.TAG_GHOSTS)
TAG_MIGRATE = 11
TAG_HALO_COUNT = 21
TAG_HALO_ROWS = 23


class Domain:
    """Decomposition of the particles over the ranks of a Channel (``parallel``).

    Parameters
    ----------
    net : parallel.Channel, mpi4py communicator or None
        None runs on one rank without MPI.
    r_list : float
        Halo width: contact distance plus skin [d].
    tolerance, damping : float
        Rebalance a column when max/mean of the measure over its ranks > 1 + tolerance; move its
        bounds by this fraction of the way to the balanced ones.
    by_work : bool
        Balance the measured work (``rebuild``'s ``work``), not the counts.
    balance_every : int
        With ``by_work``, ask every this many steps since the last rebuild whether the work is uneven
        (``rebalance_due``); 0 = only at the rebuilds the particles' motion calls for.
    balance_seconds : float
        Seconds the slowest rank has measured at least before such a check may rebalance [s].
    grid : None, "auto" or (Px, Py, Pz)
        The grid of domains (``domains``): None is all slabs (1, 1, P); "auto" is chosen from the
        ranks, the box and the pile's height when the particles are first placed (``scatter``,
        ``distribute``).

    Attributes
    ----------
    grid : (Px, Py, Pz)
    zb : (Px Py, Pz + 1) float64
        Every column's slab bounds [d]; ``bounds`` is this rank's column's row (a view).
    """

    def __init__(self, net=None, r_list=1.2, tolerance=0.1, damping=0.5, by_work=False, grid=None,
                 balance_every=0, balance_seconds=0.5):
        self.net = channel(net)
        self.size, self.rank = self.net.size, self.net.rank
        self.r_list, self.tolerance, self.damping = r_list, tolerance, damping
        self.by_work, self.balance_every, self.balance_seconds = by_work, int(balance_every), balance_seconds
        self._since_rebuild = 0     # steps since the last rebuild (``rebalance_due``)
        # max/mean of the ranks' work at the last rebuild (None: not balancing work, or not measured)
        self.work_imbalance = None
        self.n_migrated = 0
        self.n_rebalances = 0
        self.n_balance_rebuilds = 0     # rebuilds ``rebalance_due`` asked for
        self._plan = None
        # where the ghost refresh's flat buffers come from (``GhostPlan``'s ``alloc``; None: new numpy arrays)
        self.buffer_alloc = None
        self.L_x = self.L_y = None
        self.auto = isinstance(grid, str) and grid == "auto"
        self.col_net = self.net
        self._set_grid((1, 1, self.size) if grid is None or self.auto else domains.check(grid, self.size))

    def _set_grid(self, grid):
        """Take the grid (Px, Py, Pz): this rank's column and slab, the column's Channel (a split of
        ``net``, collective, when there are several columns), every column's bounds unset."""
        Px, Py, Pz = self.grid = tuple(grid)
        self.n_columns = Px * Py
        self.col, self.iz = divmod(self.rank, Pz)
        self.ix, self.iy = divmod(self.col, Py)
        self.zb = np.tile(np.array([-math.inf] + [math.inf] * Pz), (self.n_columns, 1))
        self.col_net = self.net if self.n_columns == 1 else self.net.split(self.col, self.iz)
        self._set_box(self.L_x, self.L_y)

    def _set_box(self, L_x, L_y):
        """The box's periods [d] and the columns' bounds in x and y."""
        self.L_x, self.L_y = L_x, L_y
        if L_x is not None:
            self.xb = domains.axis_bounds(L_x, self.grid[0])
            self.yb = domains.axis_bounds(L_y, self.grid[1])

    def _place(self, L_x, L_y, n_mobile, z_range):
        """Before the particles are first placed: the box, and the grid where it is chosen ("auto") from
        ``n_mobile`` mobile spheres spanning ``z_range`` [d] (the same numbers on every rank)."""
        self._set_box(L_x, L_y)
        if self.auto:
            self.auto = False
            height = domains.settled_height(n_mobile, L_x, L_y, z_range)
            grid = domains.choose(self.size, L_x, L_y, height, self.r_list)
            if grid != self.grid:
                self._set_grid(grid)

    @property
    def bounds(self):
        """This rank's column's slab bounds, (Pz + 1,) float64 [d] (a view of ``zb``)."""
        return self.zb[self.col]

    @bounds.setter
    def bounds(self, value):
        self.zb[self.col] = value

    @property
    def parallel(self):
        return self.size > 1

    @property
    def comm_seconds(self):
        """Wall seconds spent communicating so far [s] (refresh and reductions included)."""
        return self.net.seconds + (self.col_net.seconds if self.col_net is not self.net else 0.0)

    @property
    def sent(self):
        """Bytes this rank has sent so far by kind (``Channel.sent``), its column's Channel included."""
        if self.col_net is self.net:
            return dict(self.net.sent)
        return {k: v + self.col_net.sent[k] for k, v in self.net.sent.items()}

    # -- exact reductions (order independent, so rank-count independent) --
    def max_many(self, values):
        """Element-wise global max of a float array; NaN becomes +inf first.

        Returns a read-only (k,) float64 buffer that the next call of the same
        length overwrites (``Channel.max_many``).
        """
        return self.net.max_many(values)

    def max(self, value):
        return float(self.net.max_many((value,))[0])

    def sum_int(self, arr):
        """Exact global sum of an int64 array (fixed-point accumulators, counts).

        Returns a read-only buffer that the next call of the same shape overwrites.
        """
        return self.net.sum_int(arr)

    def allgather(self, obj):
        return self.net.allgather(obj)

    # -- bounds --
    def column_of(self, x):
        """Column (ix Py + iy) of each position, (n,) int64; x : (n, 3) [d]."""
        if self.n_columns == 1:
            return np.zeros(len(x), np.int64)
        ix = np.searchsorted(self.xb[1:-1], x[:, 0], side="right")
        iy = np.searchsorted(self.yb[1:-1], x[:, 1], side="right")
        return ix * self.grid[1] + iy

    def owner_of(self, x):
        """Rank owning each position, (n,) int64; x : (n, 3) [d]."""
        Pz = self.grid[2]
        if self.n_columns == 1:
            return np.searchsorted(self.zb[0, 1:-1], x[:, 2], side="right")
        col = self.column_of(x)
        iz = np.zeros(len(x), np.int64)
        for c in np.unique(col):
            at = col == c
            iz[at] = np.searchsorted(self.zb[c, 1:-1], x[at, 2], side="right")
        return col * Pz + iz

    @classmethod
    def from_config(cls, net, cfg):
        """The Domain of a run's Config: halo 1 + ``integration.skin``, the ``decomp`` keys."""
        d = cfg.decomp
        return cls(net, r_list=1.0 + cfg.integration.skin, tolerance=d.balance_tolerance,
                   damping=d.balance_damping, by_work=d.balance_by == "work", grid=tuple(d.grid) or "auto",
                   balance_every=d.balance_every, balance_seconds=d.balance_seconds)

    def balanced_bounds(self, z_mobile_all, cost=None):
        """Inner bounds splitting the mobile heights (of one column) into Pz equal counts, or equal sums
        of ``cost`` (one positive value per height) if given."""
        n, P = len(z_mobile_all), self.grid[2]
        if cost is None:
            z = np.sort(z_mobile_all)
            below = [(r * n) // P for r in range(1, P)]
        else:
            order = np.argsort(z_mobile_all, kind="stable")
            z = z_mobile_all[order]
            total = np.cumsum(cost[order])
            # the fewest lowest heights whose cost reaches r / P of the whole
            below = [int(np.searchsorted(total, total[-1] * r / P)) + 1 if n else 0 for r in range(1, P)]
        inner = []
        for k in below:
            if n == 0:
                inner.append(0.0)
            elif k <= 0:
                inner.append(z[0])
            elif k >= n:
                inner.append(z[-1] + 1e-9)
            else:
                inner.append(0.5 * (z[k - 1] + z[k]))
        return np.array(inner)

    def histogram_bounds(self, z_mobile, works=None):
        """Inner slab bounds of this rank's column splitting its ranks' mobile heights into equal counts,
        or, with ``works`` (each of the column's ranks' seconds, (Pz,) float), into equal sums of each
        particle's share of its rank's seconds; from this rank's heights ``z_mobile`` [d] alone (every
        rank of the column calls it; on one column, every rank).

        The column's height range (one max reduction), then each rank's counts in ``HIST_BINS`` equal
        bins over it: summed exactly (``sum_int``), or gathered (Pz x HIST_BINS integers) and weighted
        by works[k] / (rank k's count) in rank order, so every rank computes the same bounds; a bound
        is where the cumulative sum reaches k / Pz, placed linearly within its bin. Messages of a few
        tens of kB whatever the particle count (``balanced_bounds`` takes every height)."""
        net = self.col_net
        n = len(z_mobile)
        ext = net.max_many(np.array([-z_mobile.min() if n else -math.inf, z_mobile.max() if n else -math.inf]))
        lo, hi = -float(ext[0]), float(ext[1])
        P = net.size
        if not lo <= hi:
            return np.zeros(P - 1)
        width = (hi - lo) / HIST_BINS if hi > lo else 1.0
        idx = np.minimum(((z_mobile - lo) / width).astype(np.int64), HIST_BINS - 1)
        counts = np.bincount(idx, minlength=HIST_BINS).astype(np.int64)
        if works is None:
            hist = np.array(net.sum_int(counts), dtype=float)
        else:
            parts = net.allgather(counts)
            hist = np.zeros(HIST_BINS)
            for part, w in zip(parts, works):
                m = int(part.sum())
                if m:
                    hist += part * (float(w) / m)
        cum = np.cumsum(hist)
        inner = []
        for r in range(1, P):
            target = cum[-1] * r / P
            b = min(int(np.searchsorted(cum, target)), HIST_BINS - 1)
            before = cum[b - 1] if b else 0.0
            frac = (target - before) / hist[b] if hist[b] > 0 else 0.0
            inner.append(lo + (b + min(max(frac, 0.0), 1.0)) * width)
        return np.array(inner)

    def set_bounds(self, x_mobile_all):
        """Initial slab bounds of every column at the quantiles of its mobile heights; x_mobile_all :
        (n, 3) positions of all mobile particles [d]."""
        col = self.column_of(x_mobile_all)
        for c in range(self.n_columns):
            self.zb[c, 1:-1] = self.balanced_bounds(x_mobile_all[col == c, 2])

    def select(self, x):
        """Mask of the rows this rank owns among positions x, (n, 3) [d]."""
        return self.owner_of(x) == self.rank

    def scatter(self, a, L_x, L_y):
        """This rank's State from the whole particle set ``a`` held on every rank.

        ``a`` has ``id, x, v, omega, fixed`` and, for a state that carries
        contact histories, ``count, partner, ds`` (rows in the same order).
        Chooses the grid where it is "auto", and sets the bounds at the
        quantiles of the mobile heights first.
        """
        x_mob = a["x"][a["fixed"] == 0]
        z_range = float(np.ptp(x_mob[:, 2])) if len(x_mob) else 0.0
        self._place(L_x, L_y, len(x_mob), z_range)
        self.set_bounds(x_mob)
        return _local_state(a, np.flatnonzero(self.select(a["x"])), L_x, L_y)

    def distribute(self, a, L_x, L_y):
        """This rank's State from a share of the particles read by each rank.

        ``a`` holds some rows (``id, x, v, omega, f, torque, fixed, count,
        partner, ds``, as ``checkpoint.read`` gives them); together the ranks
        hold every particle once. Chooses the grid where it is "auto"; on
        several columns the rows first travel to their column; each column's
        bounds are set at the quantiles of its mobile heights, every rank
        learns them, then rows travel to the rank that owns them.
        """
        x_mob = a["x"][a["fixed"] == 0]
        n = len(x_mob)
        ext = self.max_many(np.array([-x_mob[:, 2].min() if n else -math.inf, x_mob[:, 2].max() if n else -math.inf]))
        n_mobile = int(self.sum_int(np.array([n]))[0])
        self._place(L_x, L_y, n_mobile, max(float(ext[1]) + float(ext[0]), 0.0) if n_mobile else 0.0)
        if self.n_columns > 1:
            # to the rank of the row's column with this rank's slab index: the column's ranks then hold its rows
            dest = self.column_of(a["x"]) * self.grid[2] + self.iz
            a = self._send_to(a, dest)
        self.bounds[1:-1] = self.histogram_bounds(a["x"][a["fixed"] == 0, 2])
        self._share_bounds()
        if self.parallel:
            a = self._send_to(a, self.owner_of(a["x"]))
        return _local_state(a, np.arange(len(a["id"])), L_x, L_y)

    def _send_to(self, a, dest):
        """The rows of state-array dict ``a`` sent to ranks ``dest`` (one per row), those received here
        merged in id order (pickled, once a run)."""
        parts = [_subset(a, np.flatnonzero(dest == r)) for r in range(self.size)]
        return merge_sorted(self.net.alltoall(parts))

    def _share_bounds(self):
        """Every rank learns every column's slab bounds (one max reduction of Px Py (Pz - 1) values;
        nothing on one column or with one slab a column)."""
        if self.n_columns == 1 or self.grid[2] == 1:
            return
        inner = np.full((self.n_columns, self.grid[2] - 1), -math.inf)
        inner[self.col] = self.zb[self.col, 1:-1]
        self.zb[:, 1:-1] = np.asarray(self.max_many(inner.ravel())).reshape(inner.shape)

    def free(self):
        """Release this Domain's MPI resources (the ghost plan's requests, the column's communicator):
        for a Domain of a part of a run (``build.make_bed``'s), not the run's own (collective)."""
        self._drop_plan()
        if self.col_net is not self.net:
            self.col_net.comm.Free()
            self.col_net = self.net

    def _drop_plan(self):
        """Free the ghost refresh's plan (its persistent requests), if there is one."""
        if self._plan is not None:
            self._plan.free()
            self._plan = None

    # -- particle movement --
    def rebuild(self, state, work=0.0, keeper=None):
        """Migrate, rebalance the uneven columns, then build the halo (ghost rows).

        ``work``: this rank's compute seconds since the last rebuild [s] (the measure
        with ``by_work``; counts are balanced until every rank has measured some).
        ``keeper``: where an engine keeps the contact history elsewhere (the GPU), an object
        told of every migration (``_migrate``): ``leaving(state, rows)`` before owned rows
        leave (it brings their fields and slots current in ``state``), ``moved(keep, arrived)``
        after (the rows kept, ascending, then ``arrived`` rows appended); and of the ghosts'
        sources (``_halo``): ``sending(state, rows)`` before their x, v and omega are sent.
        """
        state.n_rows = state.n_own
        self._since_rebuild = 0
        self._drop_plan()
        if not self.parallel:
            return
        self._migrate(state, keeper)
        measure = self._owned_counts(state)
        works = None
        if self.by_work:
            works = np.array(self.allgather(float(work)))
            if np.all(works > 0.0) and np.all(np.isfinite(works)):
                measure = works
                self.work_imbalance = float(works.max() / works.mean())
            else:
                works = None
                self.work_imbalance = None
        # every rank sees every column's measure, so all agree on which columns rebalance
        uneven = self._uneven(measure)
        if uneven[self.col]:
            zs = state.x[:state.n_own, 2][state.fixed[:state.n_own] == 0]
            # each particle carries its rank's seconds over its particles (``works``), or counts one
            mine = None if works is None else works[self.col * self.grid[2]:(self.col + 1) * self.grid[2]]
            target = self.histogram_bounds(zs, mine)
            self.bounds[1:-1] += self.damping * (target - self.bounds[1:-1])
            # keep the bounds ordered (damping of ordered targets keeps them so)
            self.bounds[1:-1] = np.maximum.accumulate(self.bounds[1:-1])
            self.n_rebalances += 1
        if any(uneven):
            self._share_bounds()
            self._migrate(state, keeper)
        self._halo(state, keeper)

    def _uneven(self, measure):
        """Per column, whether max/mean of ``measure`` (one value a rank, (P,)) over its ranks > 1 + tolerance."""
        per_column = np.asarray(measure, float).reshape(self.n_columns, self.grid[2])
        return [bool(m.sum() > 0 and m.max() / (m.sum() / len(m)) > 1.0 + self.tolerance) for m in per_column]

    def rebalance_due(self, work):
        """Count a step; whether a rebuild now should rebalance the slabs by work.

        Every ``balance_every`` steps since the last rebuild (a count every rank keeps alike) the ranks'
        compute seconds since it, ``work()`` here [s] (a callable: asked on those steps only), are gathered
        (one small collective on those steps only); the answer is yes, the same on every rank, when some
        column's max/mean exceeds ``1 + tolerance`` and its slowest rank has measured at least
        ``balance_seconds`` (less is the clock's noise). A settled pile rebuilds its lists rarely (once in
        hundreds of steps), so without this its slabs kept the balance of counts its start gave them
        (benches of the 20k pile on a 16-core machine: the slowest rank's work 1.05-1.55 times the mean on
        2-12 ranks). A rebuild made early changes no bit.
        """
        # one slab a column: nothing to balance (the columns keep equal widths)
        if not (self.balance_every > 0 and self.by_work and self.parallel and self.grid[2] > 1):
            return False
        self._since_rebuild += 1
        if self._since_rebuild % self.balance_every:
            return False
        works = np.array(self.allgather(float(work())))
        if not (np.all(works > 0.0) and np.all(np.isfinite(works)) and works.max() >= self.balance_seconds):
            return False
        due = any(self._uneven(works))
        self.n_balance_rebuilds += due
        return due

    def _migrate(self, state, keeper=None):
        """Send owned particles outside this domain, with their slots, to their owners.

        A particle may jump several domains when the bounds move, so every rank
        learns from every rank how much comes (one Alltoall of counts); the
        rows then travel only between ranks that exchange something.
        """
        n = state.n_own
        owner = self.owner_of(state.x[:n])
        leave = owner != self.rank
        counts = np.zeros((self.size, 2), np.int64)
        sends = {}
        if leave.any():
            rows = np.flatnonzero(leave)
            if keeper is not None:
                keeper.leaving(state, rows)
            for r in np.unique(owner[rows]):
                part = state.take(rows[owner[rows] == r])
                counts[r] = len(part["id"]), int(part["count"].sum())
                sends[int(r)] = list(_pack(part))
        got = self.net.alltoall_counts(counts)
        recvs = {s: list(_empty_packed(m, slots)) for s, (m, slots) in enumerate(got) if m}
        self.net.exchange(sends, recvs, TAG_MIGRATE)
        keep = np.flatnonzero(~leave)
        if len(keep) != n:
            state.keep(keep)
        # arrivals in ascending rank order of their senders (the order changes no result)
        parts = [_unpack(*recvs[s], *got[s]) for s in sorted(recvs)]
        arrived = state.append(parts)
        self.n_migrated += arrived
        if keeper is not None:
            keeper.moved(keep, arrived)

    def boxes(self):
        """Every rank's box: (lo, hi), each (P, 3) float64 [d], the z bounds from ``zb`` (+-inf at the
        ends), x and y from the columns' bounds (the whole period on one column along that axis)."""
        r = np.arange(self.size)
        ix, iy, iz = domains.coords(r, self.grid)
        col = ix * self.grid[1] + iy
        lo, hi = np.empty((self.size, 3)), np.empty((self.size, 3))
        for a, (b, i) in enumerate(((self.xb, ix), (self.yb, iy))):
            lo[:, a], hi[:, a] = b[i], b[i + 1]
        lo[:, 2], hi[:, 2] = self.zb[col, iz], self.zb[col, iz + 1]
        return lo, hi

    def reach(self):
        """Ranks this rank may send ghosts to, and may receive ghosts from.

        Rank s may send to rank r when domain s meets domain r widened by
        ``r_list`` (periodic in x and y); every rank evaluates the same
        expressions on the same bounds, so sender and receiver agree.

        Returns
        -------
        to, frm : (k,) int64
            Ranks, ascending; this rank is in neither.
        """
        if self.n_columns == 1:
            b = self.zb[0]
            lo, hi = b[:-1] - self.r_list, b[1:] + self.r_list
            # may[s, r]: some z in [b_s, b_s+1) lies in [lo_r, hi_r), the test _halo applies to rows
            may = (b[:-1, None] < hi[None, :]) & (lo[None, :] < b[1:, None])
            np.fill_diagonal(may, False)
            return np.flatnonzero(may[self.rank]), np.flatnonzero(may[:, self.rank])
        lo, hi = self.boxes()
        r, me = self.r_list, self.rank

        def meets(a_lo, a_hi, b_lo, b_hi):
            # boxes a meet boxes b widened by r_list: z as is, x and y modulo the period
            hit = (a_lo[..., 2] < b_hi[..., 2] + r) & (b_lo[..., 2] - r < a_hi[..., 2])
            for axis, L in ((0, self.L_x), (1, self.L_y)):
                hit &= domains.overlap_periodic(a_lo[..., axis], a_hi[..., axis], b_lo[..., axis] - r,
                                                b_hi[..., axis] + r, L)
            return hit
        to = meets(lo[me], hi[me], lo, hi)
        frm = meets(lo, hi, lo[me], hi[me])
        to[me] = frm[me] = False
        return np.flatnonzero(to), np.flatnonzero(frm)

    def _in_reach(self, x, lo, hi):
        """Mask of positions x, (n, 3) [d], within ``r_list`` of the box [lo, hi) (periodic in x and y)."""
        r = self.r_list
        z = x[:, 2]
        mask = (z >= lo[2] - r) & (z < hi[2] + r)
        if self.n_columns > 1:
            for axis, L, parts in ((0, self.L_x, self.grid[0]), (1, self.L_y, self.grid[1])):
                if parts > 1:
                    mask &= domains.in_periodic(x[:, axis], lo[axis] - r, hi[axis] + r, L)
        return mask

    def _halo(self, state, keeper=None):
        """Send the ranks in reach the owned rows within r_list of their domains; append ghosts.

        Counts go to every rank in reach, rows only where there are some. The
        ghost rows are stored in ascending rank order of their owners, and the
        refresh plan of x, v, omega is built and run once to fill them.
        """
        n = state.n_own
        to, frm = self.reach()
        if self.n_columns == 1:
            z = state.x[:n, 2]
            lo = self.zb[0, :-1] - self.r_list
            hi = self.zb[0, 1:] + self.r_list
            send = {int(r): np.flatnonzero((z >= lo[r]) & (z < hi[r])) for r in to}
        else:
            blo, bhi = self.boxes()
            send = {int(r): np.flatnonzero(self._in_reach(state.x[:n], blo[r], bhi[r])) for r in to}
        got = {int(s): np.zeros(1, np.int64) for s in frm}
        self.net.exchange({r: [np.array([len(rows)], np.int64)] for r, rows in send.items()},
                          {s: [c] for s, c in got.items()}, TAG_HALO_COUNT)
        send = {r: rows for r, rows in send.items() if len(rows)}
        recv, k = {}, n
        for s in sorted(got):
            m = int(got[s][0])
            if m:
                recv[s] = (k, m)
                k += m
        if k > state.capacity:
            state.grow(rows=int(k * 1.2) + 16)
        # ids and fixed flags straight into the ghost rows
        self.net.exchange({r: [state.id[rows], state.fixed[rows]] for r, rows in send.items()},
                          {s: [state.id[a:a + m], state.fixed[a:a + m]] for s, (a, m) in recv.items()},
                          TAG_HALO_ROWS)
        state.n_rows = k
        self._plan = self.net.ghost_plan(send, recv, alloc=self.buffer_alloc)
        if keeper is not None and send:
            keeper.sending(state, np.unique(np.concatenate(list(send.values()))))
        self._plan.run((state.x, state.v, state.omega))

    def refresh(self, state):
        """Update ghost x, v, omega from their owners through the current plan."""
        if not self.parallel:
            return
        if self._plan is None:
            raise RuntimeError("Domain.refresh before the first rebuild")
        self._plan.run((state.x, state.v, state.omega))

    def to_ghosts(self, field):
        """Copy the owned rows of ``field`` ((rows, 3) float64) into its ghost rows, through the refresh's
        plan (a collective; nothing on one rank): a per-row value the owners decide, for the ghosts."""
        if self.parallel:
            self.plan.run((field, field, field))

    @property
    def plan(self):
        """The ghost refresh's plan of the last rebuild (``parallel.GhostPlan``)."""
        if self._plan is None:
            raise RuntimeError("Domain.plan before the first rebuild")
        return self._plan

    def ghost_sources(self):
        """The owned rows the ghost refresh sends to other ranks, ascending, (m,) intp (none on one
        rank): an engine that keeps the rows elsewhere (the GPU) brings these current before
        ``refresh``."""
        if self._plan is None:
            return np.zeros(0, np.intp)
        rows = [r for r, _ in self._plan.sends]
        return np.unique(np.concatenate(rows)) if rows else np.zeros(0, np.intp)

    def _owned_counts(self, state):
        """Owned mobile particles of every rank, (P,) int64 (a collective)."""
        mob = int(np.count_nonzero(state.fixed[:state.n_own] == 0))
        return self.sum_int(np.eye(self.size, dtype=np.int64)[self.rank] * mob)

    def imbalance(self, state):
        """max / mean over ranks of what the slabs balance (1 on one rank): with ``by_work``
        the compute seconds of the last interval between rebuilds once every rank measured
        some, else the owned mobile particles (a collective)."""
        if not self.parallel:
            return 1.0
        if self.work_imbalance is not None:
            return self.work_imbalance
        counts = self._owned_counts(state)
        mean = counts.sum() / self.size
        return float(counts.max() / mean) if mean else 1.0

    def gather_arrays(self, arrays):
        """Merge per-rank id-sorted state arrays on rank 0 (None elsewhere)."""
        if not self.parallel:
            return arrays
        parts = self.net.gather(arrays, root=0)
        if self.rank != 0:
            return None
        return merge_sorted(parts)


def merge_sorted(parts):
    """Concatenate id-sorted state arrays of several ranks into one id-sorted set."""
    a = concat_rows(parts)
    return select_rows(a, np.argsort(a["id"], kind="stable"))


def _subset(a, rows):
    """Rows of a state-array dict, with their contact slots."""
    return select_rows(a, rows)


def _local_state(a, rows, L_x, L_y):
    """A State of the given rows of a state-array dict (forces and slots if present)."""
    return State.from_arrays(select_rows(a, rows), L_x, L_y, capacity=int(1.1 * len(rows)) + 64)


def _columns(part, fields, n, dtype):
    """The fields' columns side by side: (n, total width) of ``dtype``."""
    if not fields:
        return np.zeros((n, 0), dtype)
    return np.hstack([np.asarray(part[f.name]).reshape(n, f.width).astype(dtype, copy=False) for f in fields])


def _split(fields):
    """(per-particle float, per-particle other, per-contact float, per-contact other) fields."""
    def isf(f):
        return np.dtype(f.dtype).kind == "f"
    rows = [f for f in fields if f.per == PARTICLE]
    slots = [f for f in fields if f.per != PARTICLE]
    return ([f for f in rows if isf(f)], [f for f in rows if not isf(f)],
            [f for f in slots if isf(f)], [f for f in slots if not isf(f)])


def _widths():
    """float64 and int64 columns per particle row and per contact slot: (wf, wi, cf, ci)."""
    return tuple(sum(f.width for f in group) for group in _split(MOVING))


def _pack(part):
    """A ``State.take`` dict as two flat arrays.

    Returns
    -------
    floats : (m * wf + M * cf,) float64
        The float fields (``MOVING``) of the particles row by row, then those of the slots.
    ints : (m * wi + M * ci,) int64
        The other fields (as int64) likewise.
    """
    m, M = len(part["id"]), int(np.sum(part["count"]))
    rf, ri, sf, si = _split(MOVING)
    floats = np.concatenate([_columns(part, rf, m, np.float64).ravel(), _columns(part, sf, M, np.float64).ravel()])
    ints = np.concatenate([_columns(part, ri, m, np.int64).ravel(), _columns(part, si, M, np.int64).ravel()])
    return floats, ints


def _empty_packed(m, slots):
    """Receive arrays for ``m`` packed rows with ``slots`` contact slots in all."""
    wf, wi, cf, ci = _widths()
    return np.empty(m * wf + slots * cf), np.empty(m * wi + slots * ci, np.int64)


def _unpack(floats, ints, m, slots):
    """The ``State.append`` dict of ``m`` rows with ``slots`` contact slots, packed by ``_pack``."""
    m, M = int(m), int(slots)
    wf, wi, cf, ci = _widths()
    part = {}
    for (fields, flat, n, w, at) in zip(_split(MOVING), (floats, ints, floats, ints), (m, m, M, M), (wf, wi, cf, ci),
                                        (0, 0, m * wf, m * wi)):
        block = flat[at:at + n * w].reshape(n, w)
        c = 0
        for f in fields:
            part[f.name] = block[:, c:c + f.width].astype(f.array_dtype).reshape((n,) + f.shape)
            c += f.width
    return part
