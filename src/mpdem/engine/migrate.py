"""A list rebuild on several ranks that keeps the contact history on the GPU (engine.gpu_exchange = "device").

The domain migrates, rebalances and makes the ghosts on the host ``State`` (``decomp.Domain.rebuild``) as
ever; the GPU engine copies down the rows' positions alone, which is all the domain's choices read. A
``Keeper`` follows each owned host row back to the GPU row it was (``origin``) through the domain's
migrations: the rows that leave get their other fields and their compact slots from the GPU just before
they go (``leaving``), the ghosts' sources their velocities before they are sent (``sending``), and the
rows that arrive bring everything. The GPU then moves its survivors' rows into their new places, takes
the arrivals' and the ghosts' from the host, builds the lists and carries each survivor's history from its
old entries and each arrival's from its slots (``kernels.gpu.lists.carry_history_migrated``): rows and
history cross to the host only where they leave the rank or are sent as ghosts.
"""
import numpy as np


def insert_slots(state, rows, counts, partner, ds):
    """Give owned rows that hold no compact slots (``count`` 0) these, the others' kept in place.

    Parameters
    ----------
    state : State
        Its slots current (``slots_current``), possibly some rows' only.
    rows : (m,) int
        Owned rows, ascending, each with no slot yet.
    counts : (m,) int
        Their contacts.
    partner : (sum counts,) int64, ds : (sum counts, 3) float64 [d]
        Their slots, row after row (partner ids ascending within a row).
    """
    n = state.n_own
    rows = np.asarray(rows, np.int64)
    counts = np.asarray(counts, np.int64)
    had = state.count[:n].astype(np.int64)
    if np.any(had[rows]):
        raise RuntimeError("insert_slots: a row that already holds slots")
    now = had.copy()
    now[rows] = counts
    start = np.zeros(n + 1, np.int64)
    np.cumsum(now, out=start[1:])
    total = int(start[-1])
    new_partner = np.empty(total, np.int64)
    new_ds = np.empty((total, 3))
    # each old slot to its row's new start plus its place in the row
    old_start = np.zeros(n + 1, np.int64)
    np.cumsum(had, out=old_start[1:])
    of = np.repeat(np.arange(n), had)
    at = start[of] + np.arange(len(of)) - old_start[of]
    new_partner[at] = state.partner[:len(of)]
    new_ds[at] = state.ds[:len(of)]
    first = np.zeros(len(rows) + 1, np.int64)
    np.cumsum(counts, out=first[1:])
    of = np.repeat(np.arange(len(rows)), counts)
    at = start[rows[of]] + np.arange(len(of)) - first[of]
    new_partner[at] = partner
    new_ds[at] = ds
    state.set_contacts(now, new_partner, new_ds)


class Keeper:
    """Each owned host row's GPU row before a rebuild, through ``Domain.rebuild``'s migrations (its
    ``keeper``).

    Parameters
    ----------
    n : int
        The owned rows at the start, host row i being GPU row i.
    pack : callable
        ``pack(gpu_rows)`` -> (counts, partner, ds): those GPU rows' entries in contact as compact slots
        (``kernels.gpu.lists.pack_contacts_of``).
    fetch : callable
        ``fetch(gpu_rows, names)`` -> {name: (m, 3) array}: those GPU rows' fields ``names``.
    fields : tuple of str
        The fields besides x a leaving row takes from the GPU (v, omega, f, torque and, with a wall, wall_ds).
    """

    def __init__(self, n, pack, fetch, fields):
        # origin[i]: the GPU row host row i was (>= 0), or -1 for a row that arrived (on the host, with its slots)
        self.origin = np.arange(n, dtype=np.int64)
        self._pack, self._fetch, self._fields = pack, fetch, tuple(fields)

    def permute(self, order):
        """The host's rows reordered (new row i was row order[i]; None: not reordered)."""
        if order is not None:
            self.origin = self.origin[order]

    def leaving(self, state, rows):
        """Owned rows about to leave: those that were GPU rows get their fields and slots from the GPU."""
        self._bring(state, rows, self._fields)
        g = self.origin[rows]
        mine = g >= 0
        if mine.any():
            counts, partner, ds = self._pack(g[mine])
            insert_slots(state, rows[mine], counts, partner, ds)

    def sending(self, state, rows):
        """Owned rows whose x, v and omega are about to be sent as ghosts: v and omega from the GPU."""
        self._bring(state, rows, ("v", "omega"))

    def _bring(self, state, rows, names):
        g = self.origin[rows]
        mine = g >= 0
        if mine.any():
            got = self._fetch(g[mine], names)
            for name in names:
                getattr(state, name)[rows[mine]] = got[name]

    def moved(self, keep, arrived):
        """The domain kept rows ``keep`` (ascending) and appended ``arrived`` rows."""
        self.origin = np.concatenate([self.origin[keep], np.full(arrived, -1, np.int64)])

    def arrivals(self, state):
        """What the GPU's carry reads after the domain's rebuild.

        Returns
        -------
        origin : (n_own,) int32
            The old GPU row of each owned row, or -1 - a for the a-th arrival (in row order).
        start : (arrivals + 1,) int64
            Offsets of each arrival's slots in ``partner`` and ``ds``.
        partner : (M,) int64, ds : (M, 3) float64 [d]
            The arrivals' compact slots (only arrivals hold slots now), zeros as +0.0.
        """
        n = state.n_own
        new = np.flatnonzero(self.origin < 0)
        origin = self.origin.copy()
        origin[new] = -1 - np.arange(len(new))
        counts = state.count[:n][new].astype(np.int64)
        start = np.zeros(len(new) + 1, np.int64)
        np.cumsum(counts, out=start[1:])
        total = int(start[-1])
        if total != int(state.count[:n].sum()):
            raise RuntimeError("Keeper.arrivals: slots on a row that did not arrive")
        return origin.astype(np.int32), start, state.partner[:total].copy(), state.ds[:total] + 0.0
