"""Particle arrays: owned rows first, then ghost rows; contact slots per row.

Rows ``0..n_own-1`` belong to this rank; rows ``n_own..n_rows-1`` are
read-only ghost copies (filled by ``decomp``). Arrays have a capacity larger
than ``n_rows`` so ghosts and arriving particles fit without reallocation;
``grow`` enlarges them. Contact slots of a row hold its partners' ids in
ascending order and the tangential displacement Delta s of each contact
(design.md, invariant 2); ``slots`` and ``slots_new`` alternate each step.
"""
from __future__ import annotations

import numpy as np

ROW_FIELDS = ("ids", "x", "v", "omega", "f", "torque", "fixed", "x_ref")


def select_contacts(counts, partner, ds, rows):
    """The flat contact slots (per-row counts, partners, Delta s) of some rows.

    Returns counts[rows] and the matching segments of ``partner`` and ``ds``.
    """
    counts = np.asarray(counts, np.int64)
    rows = np.asarray(rows, np.int64)
    starts = np.cumsum(counts) - counts
    c = counts[rows]
    # segment k of the output starts at sum(c[:k]) and reads from starts[rows[k]]
    take = np.arange(c.sum()) + np.repeat(starts[rows] - (np.cumsum(c) - c), c)
    return c, partner[take], np.asarray(ds).reshape(-1, 3)[take]


class State:
    """Particle state of one rank.

    Attributes
    ----------
    ids : (cap,) int64
    x, v, omega, f, torque, x_ref : (cap, 3) float64
        Position [d], velocity, angular velocity, force [m g], torque [m g d],
        position at the last neighbour-list build.
    fixed : (cap,) uint8
        1 for bed particles.
    slot_n : (cap,) int64, slot_id : (cap, C) int64, slot_ds : (cap, C, 3)
        Contact slots (count, partner ids ascending, Delta s [d]).
    n_own, n_rows : int
    L_x, L_y : float
        Periodic box [d].
    step : int, time : float
    """

    def __init__(self, ids, x, v=None, omega=None, fixed=None, L_x=20.0, L_y=20.0,
                 slots=16, capacity=None):
        n = len(ids)
        cap = max(capacity or 0, n, 1)
        self.L_x, self.L_y = float(L_x), float(L_y)
        self.n_own = self.n_rows = n
        self.step, self.time = 0, 0.0
        self.ids = np.full(cap, -1, np.int64)
        self.fixed = np.zeros(cap, np.uint8)
        for name in ("x", "v", "omega", "f", "torque", "x_ref"):
            setattr(self, name, np.zeros((cap, 3)))
        self.ids[:n] = ids
        self.x[:n] = x
        if v is not None:
            self.v[:n] = v
        if omega is not None:
            self.omega[:n] = omega
        if fixed is not None:
            self.fixed[:n] = fixed
        self.slot_n = np.zeros(cap, np.int64)
        self.slot_id = np.full((cap, slots), -1, np.int64)
        self.slot_ds = np.zeros((cap, slots, 3))
        self.slot_n_new = np.zeros_like(self.slot_n)
        self.slot_id_new = np.full_like(self.slot_id, -1)
        self.slot_ds_new = np.zeros_like(self.slot_ds)

    @property
    def capacity(self):
        return len(self.ids)

    @property
    def n_slots(self):
        return self.slot_id.shape[1]

    def grow(self, rows=None, slots=None):
        """Enlarge row capacity and/or slot capacity, keeping the contents."""
        rows = max(rows or 0, self.capacity)
        slots = max(slots or 0, self.n_slots)
        if rows == self.capacity and slots == self.n_slots:
            return
        for name in ROW_FIELDS:
            a = getattr(self, name)
            b = np.full((rows,) + a.shape[1:], -1 if name == "ids" else 0, a.dtype)
            b[:len(a)] = a
            setattr(self, name, b)
        for pre in ("slot_n", "slot_n_new"):
            a = getattr(self, pre)
            b = np.zeros(rows, np.int64)
            b[:len(a)] = a
            setattr(self, pre, b)
        for pre in ("slot_id", "slot_id_new"):
            a = getattr(self, pre)
            b = np.full((rows, slots), -1, np.int64)
            b[:a.shape[0], :a.shape[1]] = a
            setattr(self, pre, b)
        for pre in ("slot_ds", "slot_ds_new"):
            a = getattr(self, pre)
            b = np.zeros((rows, slots, 3))
            b[:a.shape[0], :a.shape[1]] = a
            setattr(self, pre, b)

    def swap_slots(self):
        """Make the slots written this step the current ones."""
        self.slot_n, self.slot_n_new = self.slot_n_new, self.slot_n
        self.slot_id, self.slot_id_new = self.slot_id_new, self.slot_id
        self.slot_ds, self.slot_ds_new = self.slot_ds_new, self.slot_ds

    @property
    def mobile(self):
        """Boolean mask of owned mobile rows, shape (n_own,)."""
        return self.fixed[:self.n_own] == 0

    def owned(self, name):
        """View of an owned-rows array."""
        return getattr(self, name)[:self.n_own]

    def permute(self, order):
        """Reorder the owned rows (ghosts are dropped); arithmetic is unaffected."""
        n = self.n_own
        for name in ROW_FIELDS + ("slot_n", "slot_id", "slot_ds"):
            a = getattr(self, name)
            a[:n] = a[:n][order]
        self.n_rows = n

    def set_contacts(self, counts, partner, ds):
        """Load contact slots given in row order (counts per row, flat partners, Delta s)."""
        n = self.n_own
        counts = np.asarray(counts, np.int64)
        if len(counts) != n:
            raise ValueError(f"contact counts for {len(counts)} rows, state has {n}")
        self.grow(slots=int(counts.max(initial=0)))
        self.slot_n[:n] = counts
        # a row-major mask of the used slots takes the flat slots in order
        mask = np.arange(self.n_slots)[None, :] < counts[:, None]
        self.slot_id[:n][mask] = partner
        self.slot_ds[:n][mask] = np.asarray(ds).reshape(-1, 3)

    def contacts_flat(self):
        """Owned contact slots as flat arrays sorted by particle id.

        Returns
        -------
        counts : (n_own,) int64 in id order
        partner : (M,) int64
        ds : (M, 3) float64
        order : (n_own,) int64, the row order by id
        """
        n = self.n_own
        order = np.argsort(self.ids[:n], kind="stable")
        counts = self.slot_n[:n][order]
        mask = np.arange(self.n_slots)[None, :] < counts[:, None]
        partner = self.slot_id[:n][order][mask]
        ds = self.slot_ds[:n][order][mask]
        return counts, partner, ds, order
