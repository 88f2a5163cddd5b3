"""Particle arrays: owned rows first, then ghost rows; compact contact slots.

Rows ``0..n_own-1`` belong to this rank; rows ``n_own..n_rows-1`` are
read-only ghost copies (filled by ``decomp``). Arrays have a capacity larger
than ``n_rows`` so ghosts and arriving particles fit without reallocation;
``grow`` enlarges them.

Contact history (ARCHITECTURE.md) has two homes. Between neighbour
list rebuilds it lives in the engine, aligned with the list entries and
updated in place. At a rebuild, a migration and a checkpoint it is here, as
compact slots of the owned rows in row order: ``slot_n[i]`` partners of row
i, their ids ascending in ``slot_id`` and their tangential displacements in
``slot_ds`` (flat, CSR by ``slot_n``). ``slots_current`` says whether the
slots hold the history of the last force evaluation; when they do not, a
reader of the slots has the engine pack them first (``packer``, set to
``Engine.sync_slots``).
"""
from __future__ import annotations

import numpy as np

ROW_FIELDS = ("ids", "x", "v", "omega", "f", "torque", "fixed", "x_ref", "wall_ds")
# what travels with a particle that changes rank (x_ref is reset at the rebuild)
MOVE_FIELDS = ("ids", "x", "v", "omega", "f", "torque", "fixed", "wall_ds")


def select_contacts(counts, partner, ds, rows):
    """The flat contact slots (per-row counts, partners, Delta s) of some rows.

    Parameters
    ----------
    counts : (n,) int
        Slots per row.
    partner : (M,) int64, ds : (M, 3) float64
        Flat slots of all rows, in row order.
    rows : (m,) int
        Rows wanted, in the order wanted.

    Returns
    -------
    counts[rows] (m,) int64, and the matching segments of ``partner`` and ``ds``.
    """
    counts = np.asarray(counts, np.int64)
    rows = np.asarray(rows, np.int64)
    starts = np.cumsum(counts) - counts
    c = counts[rows]
    # segment k of the output starts at sum(c[:k]) and reads from starts[rows[k]]
    take = np.arange(c.sum()) + np.repeat(starts[rows] - (np.cumsum(c) - c), c)
    return c, np.asarray(partner)[take], np.asarray(ds).reshape(-1, 3)[take]


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
    slot_n : (cap,) int32
        Contacts of each owned row; like the slots, valid when ``slots_current``
        (``slots_of`` brings them up to date).
    slot_id : (M,) int64, slot_ds : (M, 3) float64
        Compact contact slots of the owned rows in row order (partner ids
        ascending per row, Delta s [d]); valid when ``slots_current``.
    n_own, n_rows : int
    L_x, L_y : float
        Periodic box [d].
    step : int, time : float
    """

    def __init__(self, ids, x, v=None, omega=None, fixed=None, L_x=20.0, L_y=20.0, capacity=None):
        n = len(ids)
        cap = max(capacity or 0, n, 1)
        self.L_x, self.L_y = float(L_x), float(L_y)
        self.n_own = self.n_rows = n
        self.step, self.time = 0, 0.0
        self.ids = np.full(cap, -1, np.int64)
        self.fixed = np.zeros(cap, np.uint8)
        for name in ("x", "v", "omega", "f", "torque", "x_ref", "wall_ds"):
            setattr(self, name, np.zeros((cap, 3)))
        # True when the run has the wall (bed.wall): then wall_ds is part of the state files
        self.wall = False
        self.ids[:n] = ids
        self.x[:n] = x
        if v is not None:
            self.v[:n] = v
        if omega is not None:
            self.omega[:n] = omega
        if fixed is not None:
            self.fixed[:n] = fixed
        self.slot_n = np.zeros(cap, np.int32)
        self.slot_id = np.zeros(0, np.int64)
        self.slot_ds = np.zeros((0, 3))
        self.slots_current = True
        # set by the engine that holds the history between rebuilds: packs it into the slots
        self.packer = None

    @property
    def capacity(self):
        return len(self.ids)

    def grow(self, rows):
        """Enlarge the row capacity to at least ``rows``, keeping the contents."""
        if rows <= self.capacity:
            return
        for name in ROW_FIELDS + ("slot_n",):
            a = getattr(self, name)
            b = np.full((rows,) + a.shape[1:], -1 if name == "ids" else 0, a.dtype)
            b[:len(a)] = a
            setattr(self, name, b)

    # -- contact slots --
    def set_contacts(self, counts, partner, ds):
        """Load the owned rows' slots (counts per row, flat partners, Delta s) in row order."""
        n = self.n_own
        counts = np.asarray(counts)
        if len(counts) != n:
            raise ValueError(f"contact counts for {len(counts)} rows, state has {n}")
        self.slot_n[:n] = counts
        self.slot_id = np.ascontiguousarray(partner, np.int64)
        self.slot_ds = np.ascontiguousarray(np.asarray(ds, np.float64).reshape(-1, 3))
        self.slots_current = True

    def drop_slots(self):
        """Free the compact slots (the engine holds the history between rebuilds)."""
        self.slot_id = np.zeros(0, np.int64)
        self.slot_ds = np.zeros((0, 3))
        self.slots_current = False

    def _check_slots(self):
        if not self.slots_current:
            if self.packer is None:
                raise RuntimeError("contact slots are stale and no engine holds the history")
            self.packer()

    def contacts_flat(self):
        """Owned contact slots as flat arrays sorted by particle id.

        Returns
        -------
        counts : (n_own,) int64 in id order
        partner : (M,) int64
        ds : (M, 3) float64
        order : (n_own,) int64, the row order by id
        """
        self._check_slots()
        n = self.n_own
        order = np.argsort(self.ids[:n], kind="stable")
        counts, partner, ds = select_contacts(self.slot_n[:n], self.slot_id, self.slot_ds, order)
        return counts, partner, ds, order

    def slot_offsets(self):
        """(n_own + 1,) int64: owned row i's slots are ``slot_id[o[i]:o[i + 1]]`` (from ``slot_n``)."""
        n = self.n_own
        o = np.zeros(n + 1, np.int64)
        np.cumsum(self.slot_n[:n], out=o[1:])
        return o

    def slots_of(self, i):
        """Partner ids (m,) int64 and Delta s (m, 3) [d] of owned row i."""
        self._check_slots()
        o = self.slot_offsets()
        return self.slot_id[o[i]:o[i + 1]], self.slot_ds[o[i]:o[i + 1]]

    # -- moving rows --
    def permute(self, order):
        """Reorder the owned rows (ghosts are dropped); arithmetic is unaffected."""
        self._check_slots()
        n = self.n_own
        c, self.slot_id, self.slot_ds = select_contacts(self.slot_n[:n], self.slot_id, self.slot_ds, order)
        for name in ROW_FIELDS:
            a = getattr(self, name)
            a[:n] = a[:n][order]
        self.slot_n[:n] = c
        self.n_rows = n

    def take(self, rows):
        """Copies of some owned rows with their slots: MOVE_FIELDS and ``slot_n, slot_id, slot_ds``."""
        self._check_slots()
        part = {f: getattr(self, f)[rows] for f in MOVE_FIELDS}
        part["slot_n"], part["slot_id"], part["slot_ds"] = select_contacts(
            self.slot_n[:self.n_own], self.slot_id, self.slot_ds, rows)
        return part

    def keep(self, rows):
        """Keep only these owned rows (ascending), with their slots; ghosts are dropped."""
        self._check_slots()
        k = len(rows)
        c, self.slot_id, self.slot_ds = select_contacts(self.slot_n[:self.n_own], self.slot_id,
                                                        self.slot_ds, rows)
        for f in MOVE_FIELDS:
            a = getattr(self, f)
            a[:k] = a[rows]
        self.slot_n[:k] = c
        self.n_own = self.n_rows = k

    def append(self, parts):
        """Append owned rows given as ``take`` dicts (ghosts are dropped)."""
        self._check_slots()
        parts = [p for p in parts if p is not None and len(p["ids"])]
        if not parts:
            return 0
        n = self.n_own
        m = sum(len(p["ids"]) for p in parts)
        if n + m > self.capacity:
            self.grow(int((n + m) * 1.2) + 16)
        k = n
        for p in parts:
            q = len(p["ids"])
            for f in MOVE_FIELDS:
                getattr(self, f)[k:k + q] = p[f]
            self.slot_n[k:k + q] = p["slot_n"]
            k += q
        self.slot_id = np.concatenate([self.slot_id] + [p["slot_id"] for p in parts])
        self.slot_ds = np.concatenate([self.slot_ds] + [np.asarray(p["slot_ds"]).reshape(-1, 3) for p in parts])
        self.n_own = self.n_rows = n + m
        return m

    def nbytes(self):
        """Bytes held by the particle arrays and slots."""
        return sum(getattr(self, f).nbytes for f in ROW_FIELDS + ("slot_n", "slot_id", "slot_ds"))
