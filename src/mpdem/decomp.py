"""Slab decomposition along z: where particles live and how ranks agree.

The only module that moves particles between ranks (design.md, invariant 3).
Rank r owns the particles with z in [b_r, b_{r+1}), b_0 = -inf, b_P = +inf.
At neighbour-list rebuilds (``rebuild``):

1. migrate: owned particles that left the slab go to their owner, with
   force, torque and contact slots;
2. rebalance: when max/mean owned mobile particles exceeds
   ``1 + tolerance``, the inner bounds move (damped) toward the quantiles of
   all mobile z, and particles migrate again;
3. halo: every rank receives, from every rank, the particles within
   ``r_list`` of its slab (so a slab thinner than the halo still gets its
   ghosts right); the plan is kept and ``refresh`` re-sends x, v, omega of
   the same rows on the other steps.

Nothing here changes arithmetic: forces depend only on ids and positions, so
the state is bit-identical for any number of ranks. Reductions are exact
(max, integer sums). Periodicity in x and y stays inside each rank.
"""
from __future__ import annotations

import math
import time

import numpy as np

from .state import select_contacts



class Domain:
    """Decomposition of the particles over the ranks of ``comm``.

    Parameters
    ----------
    comm : mpi4py communicator or None
        None runs on one rank without MPI.
    r_list : float
        Halo width: contact distance plus skin [d].
    tolerance, damping : float
        Rebalance when max/mean owned > 1 + tolerance; move bounds by this
        fraction of the way to the balanced ones.
    """

    def __init__(self, comm=None, r_list=1.2, tolerance=0.1, damping=0.5):
        self.comm = comm
        self.size = 1 if comm is None else comm.Get_size()
        self.rank = 0 if comm is None else comm.Get_rank()
        self.r_list, self.tolerance, self.damping = r_list, tolerance, damping
        self.bounds = np.array([-math.inf] + [math.inf] * self.size)
        self.comm_seconds = 0.0
        self.n_migrated = 0
        self.n_rebalances = 0
        self._plan = None

    @property
    def parallel(self):
        return self.size > 1

    # -- exact reductions (order independent, so rank-count independent) --
    def _allreduce(self, a, op):
        if not self.parallel:
            return a
        from mpi4py import MPI
        out = np.empty_like(a)
        t = time.perf_counter()
        self.comm.Allreduce(a, out, op=getattr(MPI, op))
        self.comm_seconds += time.perf_counter() - t
        return out

    def max_many(self, values):
        """Element-wise global max of a float array; NaN becomes +inf first."""
        a = np.asarray(values, float)
        return self._allreduce(np.where(np.isnan(a), np.inf, a), "MAX")

    def max(self, value):
        return float(self.max_many([value])[0])

    def sum_int(self, arr):
        """Exact global sum of an int64 array (fixed-point accumulators, counts)."""
        return self._allreduce(np.ascontiguousarray(arr, np.int64), "SUM")

    def allgather(self, obj):
        if not self.parallel:
            return [obj]
        t = time.perf_counter()
        out = self.comm.allgather(obj)
        self.comm_seconds += time.perf_counter() - t
        return out

    def _alltoall(self, objs):
        t = time.perf_counter()
        out = self.comm.alltoall(objs)
        self.comm_seconds += time.perf_counter() - t
        return out

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
            a = merge_sorted(self._alltoall(parts))
        return _local_state(a, np.arange(len(a["id"])), L_x, L_y)

    # -- particle movement --
    def rebuild(self, state):
        """Migrate, rebalance if uneven, then build the halo (ghost rows)."""
        state.n_rows = state.n_own
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
        n = state.n_own
        owner = self.owner_of(state.x[:n, 2])
        leave = owner != self.rank
        out = []
        for r in range(self.size):
            sel = np.flatnonzero(owner == r) if r != self.rank else np.zeros(0, np.int64)
            out.append(state.take(sel) if len(sel) else None)
        got = self._alltoall(out)
        keep = np.flatnonzero(~leave)
        if len(keep) != n:
            state.keep(keep)
        self.n_migrated += state.append(got)

    def _halo(self, state):
        """Send every rank the owned rows within r_list of its slab; append ghosts."""
        n = state.n_own
        z = state.x[:n, 2]
        lo = self.bounds[:-1] - self.r_list
        hi = self.bounds[1:] + self.r_list
        send = []
        for r in range(self.size):
            if r == self.rank:
                send.append(np.zeros(0, np.int64))
            else:
                send.append(np.flatnonzero((z >= lo[r]) & (z < hi[r])))
        got = self._alltoall([{"ids": state.ids[s], "fixed": state.fixed[s], "xvw": _xvw(state, s)}
                              for s in send])
        recv_counts = [len(g["ids"]) for g in got]
        total = n + sum(recv_counts)
        if total > state.capacity:
            state.grow(rows=int(total * 1.2) + 16)
        k = n
        for g in got:
            m = len(g["ids"])
            state.ids[k:k + m] = g["ids"]
            state.fixed[k:k + m] = g["fixed"]
            _set_xvw(state, slice(k, k + m), g["xvw"])
            k += m
        state.n_rows = total
        self._plan = (send, recv_counts)

    def refresh(self, state):
        """Update ghost x, v, omega from their owners through the current plan."""
        if not self.parallel:
            return
        send, recv_counts = self._plan
        t = time.perf_counter()
        reqs = []
        bufs = []
        k = state.n_own
        for r in range(self.size):
            m = recv_counts[r]
            if m:
                b = np.empty((m, 9))
                bufs.append((k, m, b))
                reqs.append(self.comm.Irecv(b, source=r, tag=7))
            k += m
        for r in range(self.size):
            if len(send[r]):
                reqs.append(self.comm.Isend(np.ascontiguousarray(_xvw(state, send[r])), dest=r, tag=7))
        from mpi4py import MPI
        MPI.Request.Waitall(reqs)
        for k, m, b in bufs:
            _set_xvw(state, slice(k, k + m), b)
        self.comm_seconds += time.perf_counter() - t

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
        t = time.perf_counter()
        parts = self.comm.gather(arrays, root=0)
        self.comm_seconds += time.perf_counter() - t
        if self.rank != 0:
            return None
        return merge_sorted(parts)


def merge_sorted(parts):
    """Concatenate id-sorted state arrays of several ranks into one id-sorted set."""
    ids = np.concatenate([p["id"] for p in parts])
    order = np.argsort(ids, kind="stable")
    out = {k: np.concatenate([p[k] for p in parts])[order]
           for k in ("id", "x", "v", "omega", "f", "torque", "fixed")}
    counts = np.concatenate([p["count"] for p in parts])
    partner = np.concatenate([p["partner"] for p in parts])
    ds = np.concatenate([np.asarray(p["ds"]).reshape(-1, 3) for p in parts])
    out["count"], out["partner"], out["ds"] = select_contacts(counts, partner, ds, order)
    return out


def _subset(a, rows):
    """Rows of a state-array dict, with their contact slots."""
    out = {k: a[k][rows] for k in ("id", "x", "v", "omega", "f", "torque", "fixed")}
    out["count"], out["partner"], out["ds"] = select_contacts(a["count"], a["partner"], a["ds"], rows)
    return out


def _local_state(a, rows, L_x, L_y):
    """A State of the given rows of a state-array dict (forces and slots if present)."""
    from .state import State
    st = State(a["id"][rows], a["x"][rows], a["v"][rows], a["omega"][rows], a["fixed"][rows],
               L_x, L_y, capacity=int(1.1 * len(rows)) + 64)
    for k in ("f", "torque"):
        if k in a:
            getattr(st, k)[:len(rows)] = a[k][rows]
    if "count" in a:
        st.set_contacts(*select_contacts(a["count"], a["partner"], a["ds"], rows))
    return st


def _xvw(state, rows):
    return np.concatenate([state.x[rows], state.v[rows], state.omega[rows]], axis=1)


def _set_xvw(state, rows, a):
    state.x[rows] = a[:, 0:3]
    state.v[rows] = a[:, 3:6]
    state.omega[rows] = a[:, 6:9]
