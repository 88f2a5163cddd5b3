"""Slab decomposition along z: where particles live and how ranks agree.

The only module that moves particles between ranks (ARCHITECTURE.md).
Rank r owns the particles with z in [b_r, b_{r+1}), b_0 = -inf, b_P = +inf.
At neighbour-list rebuilds (``rebuild``):

1. migrate: owned particles that left the slab go to their owner, with
   force, torque and contact slots;
2. rebalance: when max/mean owned mobile particles exceeds
   ``1 + tolerance``, the inner bounds move (damped) toward the quantiles of
   all mobile z, and particles migrate again;
3. halo: every rank receives the particles within ``r_list`` of its slab
   from the ranks whose slabs reach that far (not only the next ones, so a
   slab thinner than the halo still gets its ghosts right); the plan is kept
   and ``refresh`` re-sends x, v, omega of the same rows on the other steps.

Rows travel as contiguous numpy arrays through ``parallel.Channel``: counts
first, then data only between ranks that have something to send.

Nothing here changes arithmetic: forces depend only on ids and positions, so
the state is bit-identical for any number of ranks. Reductions are exact
(max, integer sums). Periodicity in x and y stays inside each rank.
"""
from __future__ import annotations

import math

import numpy as np

from .parallel import channel
from .checkpoint import PARTICLE_FIELDS, WALL_FIELDS
from .state import MOVE_FIELDS, select_contacts

# the per-particle arrays of a state-array dict (``checkpoint.read``); wall_ds only with the wall
ROW_KEYS = PARTICLE_FIELDS + WALL_FIELDS

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
        Rebalance when max/mean owned > 1 + tolerance; move bounds by this
        fraction of the way to the balanced ones.
    """

    def __init__(self, net=None, r_list=1.2, tolerance=0.1, damping=0.5):
        self.net = channel(net)
        self.size, self.rank = self.net.size, self.net.rank
        self.r_list, self.tolerance, self.damping = r_list, tolerance, damping
        self.bounds = np.array([-math.inf] + [math.inf] * self.size)
        self.n_migrated = 0
        self.n_rebalances = 0
        self._plan = None

    @property
    def parallel(self):
        return self.size > 1

    @property
    def comm_seconds(self):
        """Wall seconds spent communicating so far [s] (refresh and reductions included)."""
        return self.net.seconds

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
    def owner_of(self, z):
        """Rank owning each height z (array of int)."""
        return np.searchsorted(self.bounds[1:-1], z, side="right")

    def balanced_bounds(self, z_mobile_all):
        """Inner bounds splitting the sorted mobile heights into equal counts."""
        z = np.sort(z_mobile_all)
        n, P = len(z), self.size
        inner = []
        for r in range(1, P):
            k = (r * n) // P
            if n == 0:
                inner.append(0.0)
            elif k <= 0:
                inner.append(z[0])
            elif k >= n:
                inner.append(z[-1] + 1e-9)
            else:
                inner.append(0.5 * (z[k - 1] + z[k]))
        return np.array(inner)

    def set_bounds(self, z_mobile_all):
        """Initial bounds at the quantiles of all mobile heights."""
        self.bounds[1:-1] = self.balanced_bounds(z_mobile_all)

    def select(self, z):
        """Mask of the rows this rank owns among heights z."""
        return self.owner_of(z) == self.rank

    def scatter(self, a, L_x, L_y):
        """This rank's State from the whole particle set ``a`` held on every rank.

        ``a`` has ``id, x, v, omega, fixed`` and, for a state that carries
        contact histories, ``count, partner, ds`` (rows in the same order).
        Sets the bounds at the quantiles of the mobile heights first.
        """
        self.set_bounds(a["x"][a["fixed"] == 0, 2])
        return _local_state(a, np.flatnonzero(self.select(a["x"][:, 2])), L_x, L_y)

    def distribute(self, a, L_x, L_y):
        """This rank's State from a share of the particles read by each rank.

        ``a`` holds some rows (``id, x, v, omega, f, torque, fixed, count,
        partner, ds``, as ``checkpoint.read`` gives them); together the ranks
        hold every particle once. Bounds are set at the quantiles of all
        mobile heights, then rows travel to the rank that owns them.
        """
        zm = a["x"][a["fixed"] == 0, 2]
        self.set_bounds(np.concatenate(self.allgather(zm)))
        if self.parallel:
            owner = self.owner_of(a["x"][:, 2])
            parts = [_subset(a, np.flatnonzero(owner == r)) for r in range(self.size)]
            a = merge_sorted(self.net.alltoall(parts))
        return _local_state(a, np.arange(len(a["id"])), L_x, L_y)

    # -- particle movement --
    def rebuild(self, state):
        """Migrate, rebalance if uneven, then build the halo (ghost rows)."""
        state.n_rows = state.n_own
        if self._plan is not None:
            self._plan.free()
            self._plan = None
        if not self.parallel:
            return
        self._migrate(state)
        counts = self._owned_counts(state)
        mean = counts.sum() / self.size
        if mean > 0 and counts.max() / mean > 1.0 + self.tolerance:
            zs = state.x[:state.n_own, 2][state.fixed[:state.n_own] == 0]
            z_all = np.concatenate(self.allgather(zs))
            target = self.balanced_bounds(z_all)
            self.bounds[1:-1] += self.damping * (target - self.bounds[1:-1])
            # keep the bounds ordered (damping of ordered targets keeps them so)
            self.bounds[1:-1] = np.maximum.accumulate(self.bounds[1:-1])
            self.n_rebalances += 1
            self._migrate(state)
        self._halo(state)

    def _migrate(self, state):
        """Send owned particles outside this slab, with their slots, to their owners.

        A particle may jump several slabs when the bounds move, so every rank
        learns from every rank how much comes (one Alltoall of counts); the
        rows then travel only between ranks that exchange something.
        """
        n = state.n_own
        owner = self.owner_of(state.x[:n, 2])
        leave = owner != self.rank
        layout = _row_layout(state)
        counts = np.zeros((self.size, 2), np.int64)
        sends = {}
        if leave.any():
            rows = np.flatnonzero(leave)
            for r in np.unique(owner[rows]):
                part = state.take(rows[owner[rows] == r])
                counts[r] = len(part["ids"]), len(part["slot_id"])
                sends[int(r)] = list(_pack(part, layout))
        got = self.net.alltoall_counts(counts)
        recvs = {s: list(_empty_packed(m, slots, layout)) for s, (m, slots) in enumerate(got) if m}
        self.net.exchange(sends, recvs, TAG_MIGRATE)
        keep = np.flatnonzero(~leave)
        if len(keep) != n:
            state.keep(keep)
        # arrivals in ascending rank order of their senders (the order changes no result)
        parts = [_unpack(*recvs[s], got[s, 0], layout) for s in sorted(recvs)]
        self.n_migrated += state.append(parts)

    def reach(self):
        """Ranks this rank may send ghosts to, and may receive ghosts from.

        Rank s may send to rank r when slab s meets slab r widened by
        ``r_list``; every rank evaluates the same expressions on the same
        bounds, so sender and receiver agree.

        Returns
        -------
        to, frm : (k,) int64
            Ranks, ascending; this rank is in neither.
        """
        b = self.bounds
        lo, hi = b[:-1] - self.r_list, b[1:] + self.r_list
        # may[s, r]: some z in [b_s, b_s+1) lies in [lo_r, hi_r), the test _halo applies to rows
        may = (b[:-1, None] < hi[None, :]) & (lo[None, :] < b[1:, None])
        np.fill_diagonal(may, False)
        return np.flatnonzero(may[self.rank]), np.flatnonzero(may[:, self.rank])

    def _halo(self, state):
        """Send the ranks in reach the owned rows within r_list of their slabs; append ghosts.

        Counts go to every rank in reach, rows only where there are some. The
        ghost rows are stored in ascending rank order of their owners, and the
        refresh plan of x, v, omega is built and run once to fill them.
        """
        n = state.n_own
        z = state.x[:n, 2]
        lo = self.bounds[:-1] - self.r_list
        hi = self.bounds[1:] + self.r_list
        to, frm = self.reach()
        send = {int(r): np.flatnonzero((z >= lo[r]) & (z < hi[r])) for r in to}
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
        self.net.exchange({r: [state.ids[rows], state.fixed[rows]] for r, rows in send.items()},
                          {s: [state.ids[a:a + m], state.fixed[a:a + m]] for s, (a, m) in recv.items()},
                          TAG_HALO_ROWS)
        state.n_rows = k
        self._plan = self.net.ghost_plan(send, recv)
        self._plan.run((state.x, state.v, state.omega))

    def refresh(self, state):
        """Update ghost x, v, omega from their owners through the current plan."""
        if not self.parallel:
            return
        if self._plan is None:
            raise RuntimeError("Domain.refresh before the first rebuild")
        self._plan.run((state.x, state.v, state.omega))

    def _owned_counts(self, state):
        """Owned mobile particles of every rank, (P,) int64 (a collective)."""
        mob = int(np.count_nonzero(state.fixed[:state.n_own] == 0))
        return self.sum_int(np.eye(self.size, dtype=np.int64)[self.rank] * mob)

    def imbalance(self, state):
        """max / mean owned mobile particles over ranks (1 on one rank)."""
        if not self.parallel:
            return 1.0
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
    ids = np.concatenate([p["id"] for p in parts])
    order = np.argsort(ids, kind="stable")
    out = {k: np.concatenate([p[k] for p in parts])[order] for k in ROW_KEYS if k in parts[0]}
    counts = np.concatenate([p["count"] for p in parts])
    partner = np.concatenate([p["partner"] for p in parts])
    ds = np.concatenate([np.asarray(p["ds"]).reshape(-1, 3) for p in parts])
    out["count"], out["partner"], out["ds"] = select_contacts(counts, partner, ds, order)
    return out


def _subset(a, rows):
    """Rows of a state-array dict, with their contact slots."""
    out = {k: a[k][rows] for k in ROW_KEYS if k in a}
    out["count"], out["partner"], out["ds"] = select_contacts(a["count"], a["partner"], a["ds"], rows)
    return out


def _local_state(a, rows, L_x, L_y):
    """A State of the given rows of a state-array dict (forces and slots if present)."""
    from .state import State
    st = State(a["id"][rows], a["x"][rows], a["v"][rows], a["omega"][rows], a["fixed"][rows],
               L_x, L_y, capacity=int(1.1 * len(rows)) + 64)
    for k in ("f", "torque", "wall_ds"):
        if k in a:
            getattr(st, k)[:len(rows)] = a[k][rows]
    if "count" in a:
        st.set_contacts(*select_contacts(a["count"], a["partner"], a["ds"], rows))
    return st


def _row_layout(state):
    """How ``MOVE_FIELDS`` travel: [(name, float?, columns, row shape, dtype)].

    Float fields go as float64 columns, the others as int64 columns; the
    receiver reads the same layout from its own state.
    """
    out = []
    for f in MOVE_FIELDS:
        a = getattr(state, f)
        out.append((f, a.dtype.kind == "f", int(np.prod(a.shape[1:], dtype=np.int64)), a.shape[1:], a.dtype))
    return out


def _widths(layout):
    """float64 and int64 columns per row (the int columns end with the slot count)."""
    wf = sum(w for _, isf, w, _, _ in layout if isf)
    return wf, sum(w for _, isf, w, _, _ in layout if not isf) + 1


def _pack(part, layout):
    """A ``State.take`` dict as two flat arrays.

    Returns
    -------
    floats : (m * wf + 3 M,) float64
        The float fields row by row, then ``slot_ds``.
    ints : (m * wi + M,) int64
        The other fields and ``slot_n`` row by row, then ``slot_id``.
    """
    m = len(part["ids"])
    fcols = [part[f].reshape(m, w) for f, isf, w, _, _ in layout if isf]
    icols = [part[f].reshape(m, w) for f, isf, w, _, _ in layout if not isf] + [part["slot_n"].reshape(m, 1)]
    floats = np.concatenate([np.hstack(fcols).ravel(), np.asarray(part["slot_ds"], np.float64).ravel()])
    ints = np.concatenate([np.hstack(icols).astype(np.int64).ravel(), np.asarray(part["slot_id"], np.int64)])
    return floats, ints


def _empty_packed(m, slots, layout):
    """Receive arrays for ``m`` packed rows with ``slots`` contact slots in all."""
    wf, wi = _widths(layout)
    return np.empty(m * wf + 3 * slots), np.empty(m * wi + slots, np.int64)


def _unpack(floats, ints, m, layout):
    """The ``State.append`` dict of ``m`` rows packed by ``_pack``."""
    m = int(m)
    wf, wi = _widths(layout)
    fb, ib = floats[:m * wf].reshape(m, wf), ints[:m * wi].reshape(m, wi)
    part, cf, ci = {}, 0, 0
    for f, isf, w, shape, dtype in layout:
        if isf:
            part[f] = fb[:, cf:cf + w].astype(dtype).reshape((m,) + shape)
            cf += w
        else:
            part[f] = ib[:, ci:ci + w].astype(dtype).reshape((m,) + shape)
            ci += w
    part["slot_n"] = ib[:, ci].copy()
    part["slot_id"] = ints[m * wi:]
    part["slot_ds"] = floats[m * wf:].reshape(-1, 3)
    return part
