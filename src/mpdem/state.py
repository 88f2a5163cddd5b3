"""Particle arrays: owned rows first, then ghost rows; compact contact slots;
and the registry of every per-particle and per-contact field.

Rows ``0..n_own-1`` belong to this rank; rows ``n_own..n_rows-1`` are
read-only ghost copies (filled by ``decomp``). Arrays have a capacity larger
than ``n_rows`` so ghosts and arriving particles fit without reallocation;
``grow`` enlarges them.

The contact history has two homes: the engine's list slots between
rebuilds, and here the compact slots at a rebuild, a migration and a
checkpoint (see docs/computing.md, "The contact history's two homes"). The
compact slots are those of the owned rows in row order: ``count[i]``
partners of row i, their ids ascending in ``partner`` and their tangential
displacements [d] in ``ds`` (flat, CSR by ``count``). ``slots_current`` says
whether they hold the history of the last force evaluation; when they do
not, a reader of the slots has the engine pack them first (``sync``, set
to ``Engine.sync_state``, which also applies a deferred half-kick to ``v``
and ``omega``: every reader of rows through ``select`` calls it).

The field registry
------------------
``FIELDS`` lists every array of the state once: its name, dtype, width,
whether it has one row per particle, per contact slot or per pair of a
snapshot's contact list, whether it travels with a particle that changes
rank, the HDF5 group that stores it, and so on (``Field``). Everything that
handles fields as a set derives its list from here: ``State`` (allocation,
``grow``, ``permute``, ``take``, ``keep``, ``append``, ``nbytes``), ``decomp``
(migration, ``merge_sorted``, ``distribute``), ``checkpoint`` (groups,
dtypes, shapes, checksums, ``digest``), ``initial``, ``export`` and
``bench``. A new contact-history component (rolling or twisting resistance,
say) is one ``Field(..., per=CONTACT, group="contacts")`` entry plus its
physics in the kernels; the slots carry, migrate, store and verify it.

One vocabulary
--------------
A field has the same name as a ``State`` attribute, as a key of a
state-array dict (``checkpoint.read``, ``read_state``, ``gather_state``,
``Domain.scatter``, ``State.take``) and as a dataset in state files:
``id``, ``x``, ``v``, ``omega``, ``f``, ``torque``, ``fixed``, ``count``,
``partner``, ``ds``, ``wall_ds``. The names are the file's (format
``mpdem-state`` v2), not the other way round, because the files' names are
public (``/particles/...``, ``mpdem.read_state``, docs/python.md) and are
part of every digest (``checkpoint.digest`` hashes each dataset's name):
renaming the datasets would change every digest or need a second table of
old names. (Before this registry the State spelled them ``ids``, ``slot_n``,
``slot_id`` and ``slot_ds``; those aliases were retired on 2026-11-26.)

The registry's order is the v2 format's: it fixes the order of the datasets
that ``checkpoint.digest`` and the checksums hash, so it must not change
(a new field goes after those of its group, or at the end).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# what a row of a field is
PARTICLE = "particle"    # one row per particle (State arrays of the row capacity)
CONTACT = "contact"      # one row per contact slot (flat, CSR by ``count``)
PAIR = "pair"            # one row per contact of a snapshot's contact list (files only)


@dataclass(frozen=True)
class Field:
    """One array of the state.

    Attributes
    ----------
    name : str
        State attribute, state-array dict key and dataset name.
    dtype : numpy dtype (type)
        In memory and in files.
    width : int
        Columns: 1 is an (n,) array, k > 1 an (n, k) array.
    per : {PARTICLE, CONTACT, PAIR}
        What a row is.
    group : str or None
        HDF5 group of state files (``/group/name``); None for memory only.
    migrates : bool
        Travels with a particle that changes rank (``State.take``), and is
        kept by ``State.keep``.
    optional : str or None
        The name of the State flag (and run setting) without which the field
        is not stored: ``"wall"`` (``bed.wall``).
    exported : str or None
        Name of the field's node attribute in XDMF sidecars (``export``).
    initial : bool
        A field of an initial particle set (a table, a LAMMPS file, a pour):
        what ``State(...)`` and ``Domain.scatter`` take.
    history : bool
        Contact history (the slots and the wall's Delta s): a state file
        given as a new run's initial file keeps it (``initial.particles``).
    fill : int
        Value of rows not in use (-1 for ids, so an unused row names no particle).
    doc : str
        Shape, units and meaning.
    """
    name: str
    dtype: type
    width: int = 1
    per: str = PARTICLE
    group: str | None = None
    migrates: bool = False
    optional: str | None = None
    exported: str | None = None
    initial: bool = False
    history: bool = False
    fill: int = 0
    doc: str = ""

    @property
    def shape(self):
        """Shape of one row: () or (width,)."""
        return () if self.width == 1 else (self.width,)

    @property
    def array_dtype(self):
        """dtype in state-array dicts: narrow signed integers (``count``) widen to int64."""
        d = np.dtype(self.dtype)
        return np.dtype(np.int64) if d.kind == "i" and d.itemsize < 8 else d

    def empty(self, n, fill=None):
        """A new (n,) or (n, width) array of this field, every element ``fill`` (default ``self.fill``)."""
        return np.full((n,) + self.shape, self.fill if fill is None else fill, self.dtype)


FIELDS = (
    Field("id", np.int64, group="particles", migrates=True, exported="id", initial=True, fill=-1,
          doc="(n,) particle id"),
    Field("x", np.float64, 3, group="particles", migrates=True, initial=True, doc="(n, 3) position [d]"),
    Field("v", np.float64, 3, group="particles", migrates=True, exported="v", initial=True,
          doc="(n, 3) velocity [sqrt(g d)]"),
    Field("omega", np.float64, 3, group="particles", migrates=True, exported="omega", initial=True,
          doc="(n, 3) angular velocity [sqrt(g/d)]"),
    Field("f", np.float64, 3, group="particles", migrates=True, exported="f", doc="(n, 3) force [m g]"),
    Field("torque", np.float64, 3, group="particles", migrates=True, exported="torque",
          doc="(n, 3) torque [m g d]"),
    Field("fixed", np.uint8, group="particles", migrates=True, exported="fixed", initial=True,
          doc="(n,) 1 for bed particles"),
    Field("count", np.int32, group="contacts", migrates=True, exported="contacts", history=True,
          doc="(n,) contact slots of each particle"),
    Field("partner", np.int64, per=CONTACT, group="contacts", migrates=True, history=True,
          doc="(M,) partner id of each slot, ascending within a particle's slots"),
    Field("ds", np.float64, 3, per=CONTACT, group="contacts", migrates=True, history=True,
          doc="(M, 3) tangential displacement Delta s of each slot [d]"),
    Field("wall_ds", np.float64, 3, group="wall", migrates=True, optional="wall", history=True,
          doc="(n, 3) Delta s of the contact with the wall plane [d] (bed.wall)"),
    Field("x_ref", np.float64, 3, doc="(n, 3) position at the last near-list filtering [d] (reset at rebuilds)"),
    Field("id_i", np.int64, per=PAIR, group="pairs", doc="(P,) id of the first particle of each contact"),
    Field("id_j", np.int64, per=PAIR, group="pairs", doc="(P,) id of the second (id_i < id_j, or j in the bed)"),
    Field("delta", np.float64, per=PAIR, group="pairs", doc="(P,) overlap [d]"),
    Field("F_n", np.float64, per=PAIR, group="pairs", doc="(P,) normal force along (x_i - x_j)/r [m g]"),
    Field("F_t", np.float64, 3, per=PAIR, group="pairs", doc="(P, 3) tangential force on i [m g]"),
    Field("ds_i", np.float64, 3, per=PAIR, group="pairs", doc="(P, 3) Delta s of i [d]"),
)
FIELD = {f.name: f for f in FIELDS}
# the arrays a State holds: per particle (row capacity) and per contact slot
ROW = tuple(f for f in FIELDS if f.per == PARTICLE)
SLOT = tuple(f for f in FIELDS if f.per == CONTACT)
# the fields of an initial particle set (id, x, v, omega, fixed)
INITIAL = tuple(f.name for f in FIELDS if f.initial)


def names(fields):
    """The names of some fields, as a tuple."""
    return tuple(f.name for f in fields)


def stored(group=None, per=None):
    """Fields stored in state files (registry order), optionally of one group or row kind."""
    return tuple(f for f in FIELDS if f.group is not None and (group is None or f.group == group)
                 and (per is None or f.per == per))


def groups():
    """{HDF5 group: its dataset names}, groups in the order of their first field."""
    out = {}
    for f in stored():
        out.setdefault(f.group, []).append(f.name)
    return {g: tuple(v) for g, v in out.items()}


def optional_in(field, flags):
    """Whether a field belongs to a state with these flags (e.g. ``{"wall": True}``)."""
    return field.optional is None or bool(flags.get(field.optional))


# the per-particle arrays of a State, and what travels with a particle (``take``)
ROW_FIELDS = names(ROW)
MOVE_FIELDS = names(f for f in ROW + SLOT if f.migrates)


def slot_rows(counts, rows):
    """Which flat contact slots belong to some rows.

    Parameters
    ----------
    counts : (n,) int
        Slots per row.
    rows : (m,) int
        Rows wanted, in the order wanted.

    Returns
    -------
    c : (m,) int64, counts[rows]
    take : (sum c,) int64, the flat slots of the rows, row after row
    """
    counts = np.asarray(counts, np.int64)
    rows = np.asarray(rows, np.int64)
    starts = np.cumsum(counts) - counts
    c = counts[rows]
    # segment k of the output starts at sum(c[:k]) and reads from starts[rows[k]]
    take = np.arange(c.sum()) + np.repeat(starts[rows] - (np.cumsum(c) - c), c)
    return c, take


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
    c, take = slot_rows(counts, rows)
    return c, np.asarray(partner)[take], np.asarray(ds).reshape((-1,) + FIELD["ds"].shape)[take]


def select_rows(a, rows):
    """Some rows of a state-array dict, with their contact slots.

    Parameters
    ----------
    a : dict of arrays
        Per-particle fields (n rows) and, with ``count``, the per-contact
        fields (flat, in row order); other keys (pairs) are left out.
    rows : (m,) int
        Rows wanted, in the order wanted.

    Returns
    -------
    dict of the same per-particle and per-contact keys, m rows.
    """
    out = {f.name: a[f.name][rows] for f in ROW if f.name in a}
    if "count" in a:
        out["count"], take = slot_rows(a["count"], rows)
        for f in SLOT:
            if f.name in a:
                out[f.name] = np.asarray(a[f.name]).reshape((-1,) + f.shape)[take]
    return out


def concat_rows(parts):
    """State-array dicts (rows with their slots) one after the other; the keys of the first."""
    keys = [f for f in ROW + SLOT if f.name in parts[0]]
    return {f.name: np.concatenate([np.asarray(p[f.name]).reshape((-1,) + f.shape) for p in parts])
            for f in keys}


class State:
    """Particle state of one rank: one attribute per field of ``ROW`` and ``SLOT``.

    Attributes
    ----------
    id : (cap,) int64
    x, v, omega, f, torque, x_ref : (cap, 3) float64
        Position [d], velocity, angular velocity, force [m g], torque [m g d],
        position at the last neighbour-list build.
    fixed : (cap,) uint8
        1 for bed particles.
    wall_ds : (cap, 3) float64
        Delta s of the contact with the wall plane [d] (``bed.wall``).
    count : (cap,) int32
        Contacts of each owned row; like the slots, valid when ``slots_current``
        (``slots_of`` brings them up to date).
    partner : (M,) int64, ds : (M, 3) float64
        Compact contact slots of the owned rows in row order (partner ids
        ascending per row, Delta s [d]); valid when ``slots_current``.
    wall : bool
        The run has the wall (``bed.wall``): ``wall_ds`` is part of the state files.
    n_own, n_rows : int
    L_x, L_y : float
        Periodic box [d].
    step : int, time : float
    """

    def __init__(self, id, x, v=None, omega=None, fixed=None, L_x=20.0, L_y=20.0, capacity=None):
        n = len(id)
        cap = max(capacity or 0, n, 1)
        self.L_x, self.L_y = float(L_x), float(L_y)
        self.n_own = self.n_rows = n
        self.step, self.time = 0, 0.0
        for f in ROW:
            setattr(self, f.name, f.empty(cap))
        for f in SLOT:
            setattr(self, f.name, f.empty(0))
        # True when the run has the wall (bed.wall): then wall_ds is part of the state files
        self.wall = False
        for name, a in (("id", id), ("x", x), ("v", v), ("omega", omega), ("fixed", fixed)):
            if a is not None:
                getattr(self, name)[:n] = a
        self.slots_current = True
        # set by the engine that holds the history between rebuilds: brings the rows (a deferred
        # half-kick) and the slots current for a reader
        self.sync = None

    @classmethod
    def from_arrays(cls, a, L_x, L_y, capacity=None):
        """A State of the rows of a state-array dict: every per-particle field it has, and its
        contact slots when it has ``count``."""
        st = cls(a["id"], a["x"], L_x=L_x, L_y=L_y, capacity=capacity)
        n = len(a["id"])
        for f in ROW:
            if f.name in a and f.name not in ("id", "x", "count"):
                getattr(st, f.name)[:n] = a[f.name]
        if "count" in a:
            st.set_contacts(a["count"], **{f.name: a[f.name] for f in SLOT})
        return st

    @property
    def capacity(self):
        return len(self.id)

    def flags(self):
        """The State's optional-field flags (``Field.optional``), e.g. ``{"wall": True}``."""
        return {f.optional: bool(getattr(self, f.optional)) for f in ROW + SLOT if f.optional}

    def grow(self, rows):
        """Enlarge the row capacity to at least ``rows``, keeping the contents."""
        if rows <= self.capacity:
            return
        for f in ROW:
            a = getattr(self, f.name)
            b = f.empty(rows)
            b[:len(a)] = a
            setattr(self, f.name, b)

    # -- contact slots --
    def set_contacts(self, counts, *slots, **named):
        """Load the owned rows' slots in row order: counts per row, then the flat per-contact
        arrays, by position in ``SLOT`` order (``partner``, ``ds``) or by name."""
        n = self.n_own
        counts = np.asarray(counts)
        if len(counts) != n:
            raise ValueError(f"contact counts for {len(counts)} rows, state has {n}")
        named.update(zip(names(SLOT), slots))
        self.count[:n] = counts
        for f in SLOT:
            setattr(self, f.name, np.ascontiguousarray(np.asarray(named[f.name], f.dtype).reshape((-1,) + f.shape)))
        self.slots_current = True

    def alloc_slots(self, total):
        """New uninitialised per-contact arrays of ``total`` slots (the engine fills them)."""
        for f in SLOT:
            setattr(self, f.name, np.empty((total,) + f.shape, f.dtype))

    def drop_slots(self):
        """Free the compact slots (the engine holds the history between rebuilds)."""
        for f in SLOT:
            setattr(self, f.name, f.empty(0))
        self.slots_current = False

    def _check_slots(self):
        """Rows and slots current before a read: the engine's ``sync`` if one is attached."""
        if self.sync is not None:
            self.sync()
        elif not self.slots_current:
            raise RuntimeError("contact slots are stale and no engine holds the history")

    def select(self, rows, fields=None):
        """Copies of some owned rows with their slots, as a state-array dict.

        Parameters
        ----------
        rows : (m,) int
            Owned rows, in the order wanted.
        fields : iterable of Field, optional
            Which (default: every per-particle and per-contact field); ``count``
            comes with any per-contact field.
        """
        self._check_slots()
        n = self.n_own
        fields = tuple(ROW + SLOT if fields is None else fields)
        a = {f.name: getattr(self, f.name)[:n] for f in fields if f.per == PARTICLE}
        if any(f.per == CONTACT for f in fields):
            a["count"] = self.count[:n]
            a.update({f.name: getattr(self, f.name) for f in fields if f.per == CONTACT})
        return select_rows(a, rows)

    def contacts_flat(self):
        """Owned contact slots as flat arrays sorted by particle id.

        Returns
        -------
        counts : (n_own,) int64 in id order
        partner : (M,) int64
        ds : (M, 3) float64
        order : (n_own,) int64, the row order by id
        """
        order = self.id_order()
        a = self.select(order, SLOT)
        return a["count"], a["partner"], a["ds"], order

    def id_order(self):
        """(n_own,) int64: the owned rows in ascending id order."""
        return np.argsort(self.id[:self.n_own], kind="stable")

    def slot_offsets(self):
        """(n_own + 1,) int64: owned row i's slots are ``partner[o[i]:o[i + 1]]`` (from ``count``)."""
        n = self.n_own
        o = np.zeros(n + 1, np.int64)
        np.cumsum(self.count[:n], out=o[1:])
        return o

    def slots_of(self, i):
        """Partner ids (m,) int64 and Delta s (m, 3) [d] of owned row i."""
        self._check_slots()
        o = self.slot_offsets()
        return self.partner[o[i]:o[i + 1]], self.ds[o[i]:o[i + 1]]

    # -- moving rows --
    def _set_rows(self, a, fields, at=0):
        """Write the rows of state-array dict ``a`` at row ``at`` (per-particle) and replace the slots."""
        m = len(a["id"])
        for f in fields:
            if f.per == PARTICLE:
                getattr(self, f.name)[at:at + m] = a[f.name]
            else:
                setattr(self, f.name, np.ascontiguousarray(a[f.name]))
        return m

    def permute(self, order):
        """Reorder the owned rows (ghosts are dropped); arithmetic is unaffected."""
        self._set_rows(self.select(order), ROW + SLOT)
        self.n_rows = self.n_own

    def take(self, rows):
        """Copies of some owned rows with their slots: the fields that migrate (``MOVE_FIELDS``)."""
        return self.select(rows, [f for f in ROW + SLOT if f.migrates])

    def keep(self, rows):
        """Keep only these owned rows (ascending), with their slots; ghosts are dropped."""
        self.n_own = self.n_rows = self._set_rows(self.take(rows), [f for f in ROW + SLOT if f.migrates])

    def append(self, parts):
        """Append owned rows given as ``take`` dicts (ghosts are dropped)."""
        self._check_slots()
        parts = [p for p in parts if p is not None and len(p["id"])]
        if not parts:
            return 0
        n = self.n_own
        m = sum(len(p["id"]) for p in parts)
        if n + m > self.capacity:
            self.grow(int((n + m) * 1.2) + 16)
        moving = [f for f in ROW + SLOT if f.migrates]
        new = concat_rows(parts)
        for f in moving:
            if f.per == CONTACT:
                new[f.name] = np.concatenate([getattr(self, f.name), new[f.name]])
        self._set_rows(new, moving, at=n)
        self.n_own = self.n_rows = n + m
        return m

    def nbytes(self):
        """Bytes held by the particle arrays and slots."""
        return sum(getattr(self, f.name).nbytes for f in ROW + SLOT)
