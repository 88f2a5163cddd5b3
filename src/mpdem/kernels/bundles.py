"""Named tuples of arrays and scalars that the kernels take as one argument each.

numba compiles a ``typing.NamedTuple`` argument to the same code as its
fields passed one by one; the bundles only keep the kernels' argument lists
short and name what is in them. They are built in Python for each call (a
few microseconds), so an array that was reallocated is never read through a
stale bundle.

One rule in a ``parallel=True`` kernel: read the fields it uses by attribute
(``lists.link``) into locals before its ``prange`` loops. numba drops, without
an error, the writes to an array reached through a named tuple inside a
``prange`` body, or unpacked from one as a tuple (``a, b = lists``); numba
issues 5872, 7135 and 10338, still so in numba 0.68. Passing a bundle whole to a
(not inlined) njit helper inside the loop is fine, and so is anything in a
kernel without ``prange``.
"""
from typing import NamedTuple

import numpy as np


class Box(NamedTuple):
    """The periodic box in x and y (z is open) [d].

    Build it with ``make_box``, which derives the half lengths.
    """
    L_x: float
    L_y: float
    half_x: float      # L_x / 2, the minimum-image threshold
    half_y: float


def make_box(L_x, L_y):
    """The ``Box`` of lengths L_x, L_y [d]."""
    L_x, L_y = float(L_x), float(L_y)
    return Box(L_x, L_y, 0.5 * L_x, 0.5 * L_y)


class Particles(NamedTuple):
    """One rank's row arrays that a step reads and writes (``State``; owned rows first, then ghosts).

    x, v, omega, f, torque : (n_rows_cap, 3) float64
        Position [d], velocity [sqrt(g d)], angular velocity [sqrt(g/d)],
        force [m g], torque [m g d].
    fixed : (n_rows_cap,) uint8
        1 for bed particles (never moved).
    """
    x: np.ndarray
    v: np.ndarray
    omega: np.ndarray
    f: np.ndarray
    torque: np.ndarray
    fixed: np.ndarray


class Lists(NamedTuple):
    """The neighbour lists of the owned rows and the entries each row computes.

    nbr_start : (n_own + 1,) int64
        CSR offsets into ``nbr_list`` (``build_neighbours``).
    nbr_list : (E,) int32
        Partner rows, each row's sorted by partner id.
    link : (E,) int32
        The slot of each entry: g, or ~g for an entry that takes its pair from
        the lower row of its chunk (``link_entries``).
    comp_start : (n_own + 1,) int64
        The slots of the entries row i computes are comp_start[i]..comp_start[i + 1] - 1,
        in the order of its list.
    """
    nbr_start: np.ndarray
    nbr_list: np.ndarray
    link: np.ndarray
    comp_start: np.ndarray


class Near(NamedTuple):
    """The entries of the lists within the near reach 1 + near_skin, the force kernel's lists.

    Between two filterings (``near.near_lists``) no particle moves near_skin/2, so a pair
    left out is out of contact and would add only zeros to its rows' sums: leaving it out
    changes no bit. The near computed entries are numbered e = 0..K_near-1 in the order of
    the slots g they come from (so a row's are still in partner-id order).

    start : (n_own + 1,) int64
        CSR offsets into ``link``.
    link : (E_near,) int32
        Each near entry's place in ``Slots.pair``: p, or ~p for an entry that takes its
        pair (as ``Lists.link``). The near lists' own (``NeighbourLists.near``) have the near
        slot e for p; the force pass's (``NeighbourLists.near_places``) the place ``cpair[e]``.
    cstart : (n_own + 1,) int64
        CSR offsets into ``cj`` and ``cslot``.
    cj : (K_near,) int32
        Partner rows of the near computed entries.
    cslot : (K_near,) int32
        The slot g (``Slots.hist``, ``Slots.stamp``) of each near computed entry.
    cpair : (K_near,) int32
        The place in ``Slots.pair`` of each near computed entry (``kernels.pairstore``;
        e itself where the store has a place per near slot).
    """
    start: np.ndarray
    link: np.ndarray
    cstart: np.ndarray
    cj: np.ndarray
    cslot: np.ndarray
    cpair: np.ndarray


class Slots(NamedTuple):
    """The contact of each slot (computed pair) of the lists, between rebuilds.

    hist : (K, 3) float64
        Delta s [d], the computing row's view; valid where ``stamp`` is the last evaluation's.
    stamp : (K,) uint32
        Number (mod 2**32) of the last force evaluation that found the pair in contact.
    pair : (places, 6) float64
        The computing row's contact force [m g] and torque [m g d] of the last
        evaluation (zeros out of contact), by place (``Near.cpair``): the pair
        store. A store of one place per near slot (``Engine.step(keep_pairs=True)``)
        keeps every pair's after the pass; a ring store (``kernels.pairstore``) only
        scratch of it. May be empty where unused (``Engine.sync_slots``).
    """
    hist: np.ndarray
    stamp: np.ndarray
    pair: np.ndarray


class Scratch(NamedTuple):
    """Per-chunk scratch of ``contact_forces``, C >= 1 chunks (any C gives the same result).

    chunk_max : (C,) float64
        Each chunk's largest overlap [d].
    chunk_count : (C,) int64
        Each chunk's contacts.
    found : (C, W, 3) int32
        Slot, partner row and row of each contact of a block of rows; W >= the
        longest list of a row (a block is as many rows as fit).
    sep : (C, W, 4) float64
        Their separations x_i - x_j [d] and its square [d^2].
    tangent : (C, W, 9) float64
        What the tangential law needs of each (with friction): the tangential
        relative velocity [sqrt(g d)] (3), the unit normal (3), f_n [m g], the
        Hertz scale sqrt(delta) [d^1/2] and m_eff [m].
    """
    chunk_max: np.ndarray
    chunk_count: np.ndarray
    found: np.ndarray
    sep: np.ndarray
    tangent: np.ndarray
