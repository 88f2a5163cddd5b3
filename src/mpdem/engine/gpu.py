"""The GPU engine: one velocity-Verlet step over a rank's particles on one NVIDIA GPU (numba-cuda).

The interface and its promises are ``engine/__init__.py``'s; the CPU engine's
bits, because the step's arithmetic is the law's own source, explicitly
rounded (``kernels/gpu``; docs/computing.md, "One law, two targets").

Where the data lives (docs/gpu.md). The rows (x, v, omega, f, torque, and
the wall's Delta s), the neighbour lists and each entry's contact history
are on the GPU; a step copies one small record back (the reductions that
steer the run), and ``run_quiet`` one for many steps. On one rank a list
rebuild runs on the GPU, but every ``SORT_EVERY``-th; that one, and every
rebuild on several ranks, brings the rows and the history to the host
``State``, where the domain migrates, balances and makes the ghosts as for
the CPU engine and the lists are built, then all of it goes back; with
``engine.gpu_exchange = "device"`` only the positions come down, the rows
that leave or are sent as ghosts are brought current as they go, and the
rows are placed, the lists built and the history carried on the GPU
(``_rebuild_across``). With several ranks the ghost refresh of a step goes
through the host (with "device", only its messages, packed on the GPU). A reader
of the state (a checkpoint, a snapshot, a sample) has ``sync_state`` copy
the rows and pack the history first, as ``State.sync``.
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..errors import DeviceError
from ..kernels import history
from ..kernels.balance import force_balance
from ..kernels.bundles import Lists, Near, Slots, make_box
from ..kernels.exactsum import NLIMBS, new_accumulator, to_float
from ..kernels.integrate import kinetic_energy
from ..kernels.neighbours import build_neighbours, cell_axis
from ..state import ROW_FIELDS
from .base import NO_FLAGS, EngineBase, StepInfo
from . import migrate
from .order import SORT_COLUMN, sort_rows

# steps of one launch of ``run_quiet`` at most (the host sees signals and the wall clock between
# launches; a 20k pile runs some thousands of steps a second)
BATCH = 1000
# engine.gpu_threads: how the forces take the GPU's threads (``Engine``)
THREADS = ("row", "entry", "lanes2", "lanes4", "lanes8", "lanes16")
# engine.gpu_reductions
REDUCTIONS = ("tree", "fused", "warp")
# engine.gpu_samples
SAMPLES = ("host", "device")
# engine.gpu_drift
DRIFTS = ("apart", "fused")
# engine.gpu_rebuild
REBUILDS = ("host", "device", "launch")
# engine.gpu_sort
SORTS = ("host", "device")
# engine.gpu_exchange: how the rows meet other ranks' (``_rebuild_across``, ``_refresh``)
EXCHANGES = ("host", "device")
# every this many list rebuilds on one rank go through the host, which orders the rows by cell
# (neighbours near in memory); the others are built on the GPU
SORT_EVERY = 20


def sort_columns(nx, ny):
    """The order of ``order.sort_rows`` as ranks of the list build's cells, for a counting sort on the GPU:
    for the column of cells (ix, iy) at ix + nx iy, (col_base, col_size, col_local), each (nx * ny,) int64:
    the cells across the columns of about ``SORT_COLUMN`` x ``SORT_COLUMN`` before its own, those across its
    own, and its place among them (y-major). The cell (ix, iy, iz) of a grid of nz layers then ranks
    col_base nz + iz col_size + col_local: the columns one after the other, z-major inside each, a
    permutation of the nx ny nz cells."""
    cx = max(int(round(nx / SORT_COLUMN)), 1)
    cy = max(int(round(ny / SORT_COLUMN)), 1)
    ix = np.arange(nx)
    iy = np.arange(ny)
    bx, by = ix * cx // nx, iy * cy // ny
    wx, wy = np.bincount(bx, minlength=cx), np.bincount(by, minlength=cy)
    x0, y0 = np.concatenate([[0], np.cumsum(wx)[:-1]]), np.concatenate([[0], np.cumsum(wy)[:-1]])
    size = np.outer(wy, wx).ravel()                    # by column (by cx + bx)
    base = np.concatenate([[0], np.cumsum(size)[:-1]])
    column = (by[:, None] * cx + bx[None, :]).ravel()  # by xy cell (iy nx + ix)
    local = ((iy - y0[by])[:, None] * wx[bx][None, :] + (ix - x0[bx])[None, :]).ravel()
    return base[column].astype(np.int64), size[column].astype(np.int64), local.astype(np.int64)


def runtime_samples():
    """``kernels.gpu.samples`` (imported where a GPU engine sums its samples on the GPU)."""
    from ..kernels.gpu import samples
    return samples


def require():
    """Raise ``errors.DeviceError`` (one line: what is missing) unless a GPU engine can run here."""
    _kernels()


def _kernels():
    """The modules of ``kernels.gpu``: ``runtime``, ``step`` and ``lists``, after checking that a GPU
    can be used."""
    try:
        from ..kernels.gpu import runtime
    except ImportError as e:
        raise DeviceError(f"engine.device = 'gpu' needs numba-cuda (pip install 'mpdem[gpu]'): {e}") from None
    why = runtime.unavailable()
    if why:
        # a run moved to a GPU at a restart keeps engine.device = "gpu" in its config.toml
        raise DeviceError(f"engine.device = 'gpu': {why}; `--device cpu` runs the same trajectory on the CPU, "
                          "a restart of a run made on a GPU too")
    from ..kernels.gpu import lists, step
    return runtime, step, lists


def _device_name(runtime):
    """The GPU's name ("NVIDIA H100 80GB HBM3"), or that of numba's simulator."""
    if runtime.SIMULATOR:
        return "numba's CUDA simulator"
    name = runtime.cuda.get_current_device().name
    return name.decode() if isinstance(name, bytes) else str(name)


class Engine(EngineBase):
    """Advance a State with a Physics over a Domain on one GPU (the interface of ``engine``).

    Parameters
    ----------
    state : State
    physics : Physics
    domain : Domain
    block : int
        Threads per block of the kernels (a power of two up to 1024; ``engine.gpu_block`` asks
        for 32 at least); no effect on results.
    blocks : int or None
        Blocks a launch at most (each thread then takes several rows); None for one row a thread.
        The tests under numba's simulator use a few threads: it runs each as a Python thread.
    threads : {"row", "entry", "lanes2", "lanes4", "lanes8", "lanes16"}
        How the contact forces take the threads (``engine.gpu_threads``): a thread a row computes and
        sums its list's contacts (``kernels.gpu.step.forces``), or a thread an entry computes one
        contact and then a thread a row sums its own in list order (``entry_forces``, ``row_sums``),
        or L lanes of a warp a row in ``run_quiet``'s launches ("lanesL", with ``pinned``:
        ``kernels.gpu.step._lane_phase``; the steps outside them a thread a row); no effect on results.
    max_registers : int
        The step's kernels compiled with at most this many registers a thread (``engine.gpu_max_registers``;
        0: the compiler's choice); no effect on results.
    reductions : {"tree", "fused", "warp"}
        The fused steps' block reductions (``engine.gpu_reductions``): a tree a value, or a phase's
        values in one tree (``kernels.gpu.reduce``), or (with ``pinned``, in the launches of many steps)
        a phase's values by warp shuffles, two block barriers a phase; no effect on results.
    samples : {"host", "device"}
        Where ``kinetic`` and ``force_ratio`` sum (``engine.gpu_samples``): on the host from the rows
        and the entries' forces copied there, or on the GPU (``kernels.gpu.samples``: the same exact
        sums, a few kB copied); no effect on results.
    drift : {"apart", "fused"}
        Where ``run_quiet``'s launches do the next step's half-kicks and drift (``engine.gpu_drift``): a
        phase of their own, or by the thread that has just summed the row's forces, the rows in two
        buffers (one grid barrier a step fewer; ``kernels.gpu.step.advance``); no effect on results.
    pinned : bool
        ``run_quiet``'s launches compiled for this engine's options and its law's model, friction,
        ``limit_damping`` and ``rescale_history`` as constants (``engine.gpu_pinned``,
        ``kernels.gpu.step.pinned_advance``); no effect on results.
    rebuilds : {"host", "device", "launch"}
        How a list rebuild on the GPU (one rank, not a ``SORT_EVERY``-th) is sized
        (``engine.gpu_rebuild``): by the host, which reads the rows' z range and the lists' length back
        and allocates the lists ("host"), or on the GPU alone, into lists of a fixed capacity whose
        overflow the host sees when it next reads the step's reductions, and then builds them again
        with room ("device", ``_rebuild_in_place``); "launch": as "device", and ``run_quiet``'s launches
        rebuild the lists themselves, as phases of the launch (``kernels.gpu.step.advance_lists``, a thread
        an entry ``advance_lists_entry``, or ``pinned_advance``'s with ``pinned``); no effect on results.
    list_capacity : int
        With ``rebuilds = "device"``, the entries the lists have room for at first (0: a quarter more
        than the first lists built on the GPU replace); grown on an overflow. No effect on results.
    sort : {"host", "device"}
        Where every ``SORT_EVERY``-th rebuild on one rank orders the rows by cell (``engine.gpu_sort``):
        through the host (rows and history down, ``order.sort_rows``, the lists built, all up), or on the
        GPU (``_rebuild_sorted``: a counting sort by the same cells, the rows permuted, the lists built
        and the history carried by partner id; the permutation copied back, which the host's State takes
        at once); with ``rebuilds = "launch"`` inside ``run_quiet``'s launches (``kernels.gpu.lists.sort_phases``;
        the State takes the order after the launch, ``_take_moved``). No effect on results.
    exchange : {"host", "device"}
        How the rows meet the other ranks' on several ranks (``engine.gpu_exchange``): through the host
        (at a rebuild rows and history down, the domain's migration and ghosts, the lists built, all up; at
        a step the ghosts' sources down into the host's rows, the ghosts up), or on the GPU (``_rebuild_across``:
        the positions down, the rows that leave or are sent as ghosts brought down as they go, the history
        of those that leave packed from their entries; the survivors placed on the GPU, the arrivals and
        ghosts up, the lists built over the ghosts, each survivor's history carried from its old entries
        and each arrival's from its slots; ``_refresh``: the refresh's messages packed and unpacked on the
        GPU, ``parallel.GhostPlan.layout``). No effect on results.

    Attributes
    ----------
    timers : dict of float
        Seconds in "forces", "lists" (rebuilds, with their copies between host and GPU) and
        "integration" (with the step's copy of its reductions); communication is
        ``domain.comm_seconds``.
    """

    def __init__(self, state, physics, domain, block=128, blocks=None, threads="row", max_registers=0,
                 reductions="tree", samples="host", drift="apart", pinned=False, rebuilds="host", list_capacity=0,
                 sort="host", exchange="host"):
        runtime, self.k, self.kl = _kernels()
        if not (max_registers == 0 or 32 <= max_registers <= 255):
            raise ValueError(f"max_registers = {max_registers}: accepted 0 (the compiler's choice) or 32 to 255")
        # the step's kernels compiled with at most this many registers a thread (0: the compiler's choice)
        self.max_registers = int(max_registers)
        self._capped = runtime.capped
        if reductions not in REDUCTIONS:
            raise ValueError(f"reductions = {reductions!r}: accepted {', '.join(map(repr, REDUCTIONS))}")
        # the fused steps' reductions: one a value ("tree", 0), one tree a phase ("fused", 1) or by warp shuffles
        # ("warp", ``kernels.gpu.step.WARP``: only in the pinned launches, their constant)
        self.fused = REDUCTIONS.index(reductions)
        if samples not in SAMPLES:
            raise ValueError(f"samples = {samples!r}: accepted {', '.join(map(repr, SAMPLES))}")
        # the stop rule's sums on the GPU (``kernels.gpu.samples``) or on the host
        self.ks = runtime_samples() if samples == "device" else None
        if drift not in DRIFTS:
            raise ValueError(f"drift = {drift!r}: accepted {', '.join(map(repr, DRIFTS))}")
        # the next step's drift by the thread that summed the row's forces, the rows in two buffers
        self.one_barrier = drift == "fused"
        # ``advance`` compiled for the run's options (``kernels.gpu.step.pinned_advance``)
        self.pinned = bool(pinned)
        if rebuilds not in REBUILDS:
            raise ValueError(f"rebuilds = {rebuilds!r}: accepted {', '.join(map(repr, REBUILDS))}")
        # list rebuilds on the GPU with no host round trip, into lists of a fixed capacity (``_rebuild_in_place``)
        self.in_place = rebuilds in ("device", "launch")
        # and inside ``run_quiet``'s launches (``advance_lists``, ``advance_lists_entry``)
        self.in_launch = rebuilds == "launch"
        # the entries those lists have room for (0: not yet sized), and their two sets of arrays, the old
        # lists and the new (``_list_set``)
        self._capacity = int(list_capacity)
        self._sets = []
        # a rebuild in place whose length and room the host has not yet read (``_settle``), and the lists it
        # replaced (start, nbr, hist, stamp, entries), which an overflow brings back
        self._pending = None
        if sort not in SORTS:
            raise ValueError(f"sort = {sort!r}: accepted {', '.join(map(repr, SORTS))}")
        # every SORT_EVERY-th rebuild's ordering of the rows on the GPU (``_rebuild_sorted``), and the spare
        # arrays of the permutation
        self.sort_on_gpu = sort == "device"
        if exchange not in EXCHANGES:
            raise ValueError(f"exchange = {exchange!r}: accepted {', '.join(map(repr, EXCHANGES))}")
        # a rebuild on several ranks with the history kept on the GPU, the rows' fields only through the host
        self.exchange_on_gpu = exchange == "device"
        # the ghost refresh's host buffers from page-locked memory kept between rebuilds (``_pinned``)
        self._pinned_bufs = {}
        if self.exchange_on_gpu:
            domain.buffer_alloc = self._pinned
        self._spare = {}
        self._columns = None
        # rebuilds without the host that ran out of room and were built again (``_settle``, ``run_quiet``)
        self.n_overflows = 0
        # rebuilds inside ``run_quiet``'s launches (``advance_lists``), and through the host (the rows ordered)
        self.n_rebuilds_in_launch = 0
        self.n_rebuilds_by_host = 0
        if threads not in THREADS:
            raise ValueError(f"threads = {threads!r}: accepted {', '.join(map(repr, THREADS))}")
        # a thread an entry keeps every entry's force and needs its row
        self.by_entry = threads == "entry"
        # the lanes of a warp a row in the launches (0: as ``by_entry`` says)
        self.lanes = int(threads[5:]) if threads.startswith("lanes") else 0
        if reductions == "warp" and not self.pinned:
            raise ValueError("reductions = 'warp' needs pinned = True (engine.gpu_pinned: the warps' reductions are "
                             "compiled only into the launches made for a run's options)")
        if self.lanes and not self.pinned:
            raise ValueError(f"threads = {threads!r} needs pinned = True (engine.gpu_pinned: the lanes are compiled "
                             "only into the launches made for a run's options)")
        self.cuda, self._run, self._simulator = runtime.cuda, runtime.launch, runtime.SIMULATOR
        if not (1 <= block <= self.k.BLOCK_MAX and block & (block - 1) == 0):
            raise ValueError(f"block = {block}: accepted a power of two up to {self.k.BLOCK_MAX}")
        if self._simulator and blocks is None:
            # numba's simulator runs every thread as a Python thread: a few threads, each many rows
            block, blocks = max(2, self.lanes), 2
        if block < self.lanes:
            raise ValueError(f"block = {block} with threads = {threads!r}: a block holds whole rows of "
                             f"{self.lanes} lanes, so {self.lanes} threads or more")
        # at most this many blocks a launch (None: one row a thread); the kernels take any grid
        self.blocks = blocks
        self.state, self.phys, self.domain = state, physics, domain
        self.device_name = _device_name(runtime)
        self.block = int(block)
        state.wall = physics.wall
        self.plane_arrays()     # the floor, the wall and any other plane (planes.py): checked here
        self.r_list = 1.0 + physics.skin
        self.nbr_start = np.zeros(1, np.int64)
        self.nbr_list = np.zeros(0, np.int32)
        self._link = np.zeros(0, np.int32)
        self._k = 0               # list entries
        self._host_lists = True   # the host's copy of the lists is current (``_lists``)
        self._buffers = {}        # the GPU list build's scratch (``_buffer``)
        self._halo = None         # the ghost refresh's layout on the GPU (``_halo_layout``)
        self.has_lists = False
        self._epoch = 0           # force evaluations so far (the contacts' stamps count them)
        self._kick_due = False
        self._pairs_kept = False
        self._dev = {}            # the GPU's arrays by name (``_upload``)
        # the step's reductions (``kernels.gpu.step``), and a pinned host copy the step reads
        self._red = self.cuda.to_device(self._neutral_red())
        # whether ``_red``'s slots of ``forces`` are neutral (only ``kick_drift`` resets them: an evaluation
        # after another with no step between, at ``start`` or a rebuild step of ``run_quiet``, resets them first)
        self._red_fresh = True
        self._red_host = self.cuda.pinned_array(self.k.RED_SLOTS)
        self._launchers = {}
        # the per-step reductions of ``run_quiet``'s launches, and their pinned host copy
        # (with rebuilds in the launches, each row's RED_ENTRIES and RED_OVERFLOW too)
        cols = self.k.RED_SLOTS if self.in_launch else len(self.k.NEUTRAL)
        self._rec = self.cuda.device_array((BATCH, cols))
        self._rec_host = self.cuda.pinned_array((BATCH, cols))
        self._coop_blocks = None
        self._zr = self.cuda.to_device(np.zeros(2))   # the z range of the GPU's list build
        # the same of the build in place (with the grid's lowest z), and its grid's z layers and cells
        self._zr_in = self.cuda.to_device(np.array([math.inf, -math.inf, 0.0]))
        self._dims = self.cuda.to_device(np.zeros(2, np.int64))
        self._sample_acc = {}     # the samples' accumulators on the GPU, by rows of limbs
        self.n_rebuilds = 0
        self.info = StepInfo()
        self.n_contacts = 0
        self.timers = {"forces": 0.0, "lists": 0.0, "integration": 0.0}
        self._work_mark = 0.0
        self.last_overlap = 0.0
        self._contacts = 0
        state.sync = self.sync_state

    def _neutral_red(self):
        """``_red``'s starting values: the step's ``NEUTRAL``, then no entries and no overflow."""
        red = np.zeros(self.k.RED_SLOTS)
        red[:len(self.k.NEUTRAL)] = self.k.NEUTRAL
        return red

    # -- between host and GPU --
    def _grid(self, rows):
        blocks = (max(rows, 1) + self.block - 1) // self.block
        return (blocks if self.blocks is None else min(blocks, self.blocks)), self.block

    def _launch(self, name, *args, grid=None):
        """Launch kernel ``name`` of ``kernels.gpu.step`` over its first argument's rows (n_own).

        The first launch specializes the kernel for its argument types (which the engine keeps
        the same: arrays are reallocated with their dtype and layout), so later launches skip
        numba's typing of some twenty arguments (``Dispatcher.specialize``)."""
        self._run(self._launcher(name, args), grid or self._grid(args[0]), args)

    def _launcher(self, name, args):
        """Kernel ``name`` (``_kernel``) under the register cap, specialized for ``args``'s types."""
        kernel = self._launchers.get(name)
        if kernel is None:
            kernel = self._kernel(name)
            if self.max_registers:
                kernel = self._capped(kernel, self.max_registers)
            specialize = getattr(kernel, "specialize", None)   # not in numba's simulator
            if specialize is not None:
                kernel = specialize(*args)
            self._launchers[name] = kernel
        return kernel

    def _kernel(self, name):
        """The kernel ``name`` of ``kernels.gpu.step``; ``("advance", key)``: ``pinned_advance(*key)``."""
        if isinstance(name, tuple):
            return self.k.pinned_advance(*name[1])
        return getattr(self.k, name)

    def _advance_name(self):
        """The launcher name of ``run_quiet``'s kernel: "advance", or with ``pinned`` the key of the one
        compiled for this engine's options and its law's (``kernels.gpu.step.pinned_advance``)."""
        if not self.pinned:
            if self.in_launch:
                return ("advance_lists" + ("_entry" if self.by_entry else "")
                        + ("_sorted" if self.sort_on_gpu else ""))
            return "advance_one" if self.one_barrier else "advance"
        law = self.law
        return ("advance", (self.by_entry, self.fused, self.one_barrier, int(law.model), law.mu > 0.0,
                            bool(law.limit_damping), bool(law.rescale_history),
                            (2 if self.sort_on_gpu else 1) if self.in_launch else 0, self.lanes))

    def _second_rows(self):
        """x, v and omega's second buffer on the GPU (``drift = "fused"``; shaped as x), else x, v, omega
        themselves (not written)."""
        d = self._dev
        if not self.one_barrier:
            return d["x"], d["v"], d["omega"]
        if d.get("xb") is None or d["xb"].shape != d["x"].shape:
            for name in ("xb", "vb", "wb"):
                d[name] = self.cuda.device_array(d["x"].shape)
        return d["xb"], d["vb"], d["wb"]

    def _rows_of(self):
        """The row fields the GPU steps (names of ``State`` attributes)."""
        return ("x", "v", "omega", "f", "torque") + (("wall_ds",) if self.phys.wall else ())

    def _upload(self):
        """Every row, the lists and the history to the GPU (after a rebuild)."""
        s, d, cuda = self.state, self._dev, self.cuda
        self._upload_rows()
        d["start"] = cuda.to_device(self.nbr_start[:s.n_own + 1])
        k = max(len(self.nbr_list), 1)
        d["nbr"] = cuda.to_device(self.nbr_list[:k] if len(self.nbr_list) else np.zeros(1, np.int32))
        d["hist"] = cuda.to_device(self._hist[:k] if len(self._hist) else np.zeros((1, 3)))
        d["stamp"] = cuda.to_device(self._stamp[:k] if len(self._stamp) else np.zeros(1, np.uint32))
        d["pair"] = cuda.device_array((1, 6))
        self._entry_rows(None)
        self._pairs_kept = False

    def _upload_rows(self):
        """Every row's fields (owned and ghost) to the GPU, x_ref = x, and the ghost refresh's sources."""
        s, d, cuda = self.state, self._dev, self.cuda
        m = s.n_rows
        for name in self._rows_of() + ("fixed", "id"):
            d[name] = cuda.to_device(np.ascontiguousarray(getattr(s, name)[:max(m, 1)]))
        d["x_ref"] = cuda.to_device(np.ascontiguousarray(s.x[:max(s.n_own, 1)]))
        self._ghost_sources()

    def _ghost_sources(self):
        """What the ghost refresh needs on the GPU after a rebuild: the plan's layout with
        ``exchange_on_gpu`` (``_halo_layout``), else the owned rows it sends and room to gather them."""
        d, cuda = self._dev, self.cuda
        if "wall_ds" not in d:
            d["wall_ds"] = cuda.device_array((1, 3))
        self._pairs_kept = False
        self._halo = self._halo_layout()
        if self._halo is not None:
            return
        self._sources = self.domain.ghost_sources()
        m = max(len(self._sources), 1)
        d["sources"] = cuda.to_device(np.ascontiguousarray(self._sources[:m] if len(self._sources) else [0], np.intp))
        d["sent"] = cuda.device_array((3, m, 3))
        self._sent_host = cuda.pinned_array((3, m, 3))

    def _device_planes(self):
        """The planes' arrays on the GPU (``plane_arrays``), copied there again when they change."""
        arrays = self.plane_arrays()
        if getattr(self, "_planes_sent", None) is not arrays:
            geo, kinds = arrays
            # a row at least: no kind, no plane read
            self._planes_dev = (self.cuda.to_device(geo if len(geo) else np.zeros((1, 4))),
                                self.cuda.to_device(kinds))
            self._planes_sent = arrays
        return self._planes_dev

    def _download_rows(self, names, rows):
        """Copy the GPU's ``names`` rows 0..rows-1 into the host State."""
        s, d = self.state, self._dev
        for name in names:
            if rows:
                d[name][:rows].copy_to_host(getattr(s, name)[:rows])

    def _download_history(self):
        """Each list entry's Delta s and stamp from the GPU (host arrays)."""
        self._settle()
        k = self._k
        hist = self._dev["hist"][:max(k, 1)].copy_to_host()[:k]
        stamp = self._dev["stamp"][:max(k, 1)].copy_to_host()[:k]
        return hist, stamp

    def _lists(self):
        """The lists as the host's history kernels read them (copied from the GPU if it built them)."""
        self._settle()
        if not self._host_lists:
            n, k = self.state.n_own, self._k
            self.nbr_start[:n + 1] = self._dev["start"][:n + 1].copy_to_host()
            self.nbr_list = self._dev["nbr"][:max(k, 1)].copy_to_host()[:k]
            self._link = np.arange(k, dtype=np.int32)
            self._host_lists = True
        # every entry is computed by its own row: entry k is slot k (``kernels.history``'s link)
        return Lists(self.nbr_start, self.nbr_list, self._link, self.nbr_start)

    def sync_state(self):
        """Bring the host State current for a reader (``State.sync``): the deferred half-kick, the
        rows, and the contact history packed into the compact slots."""
        self.complete()
        s = self.state
        if not self.has_lists or s.slots_current:
            return
        self._download_rows(self._rows_of(), s.n_own)
        if self._halo is not None and s.n_rows > s.n_own:
            # the ghost rows too: refreshed on the GPU alone (``_refresh_on_gpu``); a reader of the pairs reads them
            for name in ("x", "v", "omega"):
                self._dev[name][s.n_own:s.n_rows].copy_to_host(getattr(s, name)[s.n_own:s.n_rows])
        hist, stamp = self._download_history()
        slots = Slots(hist, stamp, np.zeros((0, 6)))
        n = s.n_own
        total = history.count_contacts(n, self._lists(), slots, self._epoch, s.count, 1)
        start = s.slot_offsets()
        s.alloc_slots(total)
        history.entries_to_slots(n, s.id, self._lists(), slots, self._epoch, start, s.partner, s.ds, 1)
        s.slots_current = True
        # the kept pair forces belong to the packed evaluation's scratch (as the CPU engine's)
        self._pairs_kept = False

    # -- neighbour lists --
    def rebuild(self):
        """New lists, the contact history carried. On one rank, where the rows keep their places,
        on the GPU (``kernels.gpu.lists``) but every ``SORT_EVERY``-th time; otherwise through the
        host: rows and history down, migration and ghosts (domain), the rows ordered by cell, the
        lists built, all up."""
        t = time.perf_counter()
        # the rebuild in place before this one, if nothing has read its length yet (no evaluation between)
        self._settle()
        on_gpu = self.has_lists and not self.domain.parallel
        if on_gpu and (self.n_rebuilds % SORT_EVERY or self.sort_on_gpu):
            if not self.n_rebuilds % SORT_EVERY:
                self._rebuild_sorted()
            elif self.in_place:
                self._rebuild_in_place()
            else:
                self._rebuild_on_gpu()
            self.n_rebuilds += 1
            self.timers["lists"] += time.perf_counter() - t
            return
        c0 = self.domain.comm_seconds
        if self.has_lists and self.domain.parallel and self.exchange_on_gpu:
            self._rebuild_across()
            self.n_rebuilds += 1
            self.timers["lists"] += time.perf_counter() - t - (self.domain.comm_seconds - c0)
            return
        s = self.state
        self.n_rebuilds_by_host += 1
        if self.has_lists:
            self.sync_state()
        sort_rows(s, self.r_list)
        spent = sum(self.timers.values())
        self.domain.rebuild(s, self.work_since_rebuild())
        self._work_mark = spent
        n = s.n_own
        if len(self.nbr_start) < n + 1:
            self.nbr_start = np.zeros(s.capacity + 1, np.int64)
        if not len(self.nbr_list):
            self.nbr_list = np.zeros(max(16 * n, 64), np.int32)
        box = make_box(s.L_x, s.L_y)
        while True:
            need = build_neighbours(s.x, s.n_rows, n, s.fixed, s.id, box, self.r_list, self.nbr_start,
                                    self.nbr_list, 1)
            if need <= len(self.nbr_list):
                break
            self.nbr_list = np.zeros(int(need * 1.1) + 64, np.int32)
        k = self._k = int(self.nbr_start[n])
        self.nbr_list = self.nbr_list[:k].copy() if k else np.zeros(0, np.int32)
        self._link = np.arange(k, dtype=np.int32)
        self._host_lists = True
        self._hist = np.empty((k, 3))
        self._stamp = np.empty(k, np.uint32)
        history.slots_to_entries(n, s.id, self._lists(), s.slot_offsets(), s.partner, s.ds,
                                 Slots(self._hist, self._stamp, np.zeros((0, 6))), self._epoch, 1)
        if self.law.mu == 0.0:
            # frictionless: Delta s is 0 (docs/model.md 2.6), whatever an initial file held
            self._hist[:] = 0.0
        s.drop_slots()
        self._upload()
        # room for the next build: the lists grow a little as a pile settles
        self.nbr_list = np.concatenate([self.nbr_list, np.zeros(k // 10 + 64, np.int32)])
        self.has_lists = True
        self.n_rebuilds += 1
        self.timers["lists"] += time.perf_counter() - t - (self.domain.comm_seconds - c0)

    def _rebuild_on_gpu(self):
        """The lists built on the GPU from the rows where they are, the history carried entry by
        entry (``kernels.gpu.lists``); x_ref = x. One rank only (no ghosts, no migration)."""
        s, d, cuda, L = self.state, self._dev, self.cuda, self.kl
        n = s.n_own
        grid = self._grid(n)
        start, nbr, k = self._build_lists(n, n)
        hist = cuda.device_array((max(k, 1), 3))
        stamp = cuda.device_array(max(k, 1), np.uint32)
        stale = np.uint32((self._epoch - 1) & 0xFFFFFFFF)
        self._run(L.carry_history, grid, (n, d["id"], d["start"], d["nbr"], d["hist"], d["stamp"], start, nbr, hist,
                                          stamp, stale))
        self._take_lists(start, nbr, hist, stamp, k)

    def _take_lists(self, start, nbr, hist, stamp, k):
        """New lists of ``k`` entries built on the GPU the current ones; x_ref = x."""
        s, d = self.state, self._dev
        d["start"], d["nbr"], d["hist"], d["stamp"] = start, nbr, hist, stamp
        self._k = k
        grid = self._grid(s.n_own)
        self._entry_rows(grid)
        self._run(self.kl.copy_rows, grid, (s.n_own, d["x"], d["x_ref"]))
        self._host_lists = False
        self._pairs_kept = False
        s.slots_current = False

    def _build_lists(self, n, m):
        """The lists of owned rows 0..n-1 over rows 0..m-1 (ghosts included) built on the GPU, sized by
        the host (the rows' z range and the lists' length read back).

        Returns
        -------
        start : device (n + 1,) int64, nbr : device (max(k, 1),) int32, k : int
        """
        s, d, cuda, L = self.state, self._dev, self.cuda, self.kl
        grid, one = self._grid(n), (1, self.block)
        z = self._zr
        z.copy_to_device(np.array([math.inf, -math.inf]))
        self._run(L.z_range, self._grid(m), (m, d["x"], z))
        zmin, zmax = (float(v) for v in z.copy_to_host()) if m else (0.0, 0.0)
        nx, ny = cell_axis(s.L_x, self.r_list), cell_axis(s.L_y, self.r_list)
        # z cells hashed above a bound of the grid, as the CPU's build (memory O(rows) whatever flies); a rank
        # with no row (an empty slab) has no z range
        nz = min(int((zmax - zmin) / self.r_list) + 1, max(3, 4 * (m // (nx * ny)) + 8))
        ncell = nx * ny * nz
        count = self._buffer("cells", ncell + 1, np.int32)
        fill = self._buffer("fill", ncell + 1, np.int32)
        cell, order = self._buffer("cell", m, np.int32), self._buffer("order", m, np.int32)
        self._run(L.zero, self._grid(ncell + 1), (ncell + 1, count))
        self._run(L.bin_rows, self._grid(m), (m, d["x"], nx, ny, nz, s.L_x / nx, s.L_y / ny, zmin, self.r_list, cell,
                                              count))
        self._run(L.scan, one, (count, ncell))
        fill[:ncell + 1].copy_to_device(count[:ncell + 1])
        self._run(L.fill_cells, self._grid(m), (m, cell, fill, order))
        box = make_box(s.L_x, s.L_y)
        r2 = self.r_list * self.r_list
        cells = (d["x"], d["id"], d["fixed"], cell, count, order, nx, ny, nz, *box, r2)
        start = cuda.device_array(n + 1, np.int64)
        self._run(L.count_partners, grid, (n, *cells, start))
        self._run(L.scan, one, (start, n))
        k = int(start[n:n + 1].copy_to_host()[0])
        nbr = cuda.device_array(max(k, 1), np.int32)
        self._run(L.write_partners, grid, (n, *cells, start, nbr))
        return start, nbr, k

    def _rebuild_across(self):
        """A rebuild on several ranks with the rows and the contact history kept on the GPU
        (``engine.gpu_exchange = "device"``): the owned rows' positions down, the rows
        ordered and the domain's migration, balance and ghosts on the host State as ever, the rows that
        leave brought current (fields and slots) from the GPU as they go and the ghosts' sources as they are
        sent (``migrate.Keeper``); then the survivors' rows moved into their new places on the GPU, the
        arrivals' and the ghosts' copied up, the lists built on the GPU over the ghosts, each survivor's
        history carried by partner id from its old entries, each arrival's from the slots it brought
        (``kernels.gpu.lists.carry_history_migrated``). The same rows, lists and history as the host's
        path; the host's copy of the survivors' other fields stays stale (``sync_state`` brings it)."""
        s, d, cuda, L = self.state, self._dev, self.cuda, self.kl
        self.complete()
        n = s.n_own
        self._download_rows(("x",), n)
        # no slots on the host: a leaving row's are packed as it leaves, an arriving row brings its own
        s.count[:n] = 0
        s.drop_slots()
        s.slots_current = True
        keeper = migrate.Keeper(n, self._pack_contacts, self._fetch_rows, [f for f in self._rows_of() if f != "x"])
        keeper.permute(sort_rows(s, self.r_list))
        spent = sum(self.timers.values())
        self.domain.rebuild(s, self.work_since_rebuild(), keeper)
        self._work_mark = spent
        origin, arr_start, arr_id, arr_ds = keeper.arrivals(s)
        if self.law.mu == 0.0:
            arr_ds[:] = 0.0
        old_ids, old = d["id"], (d["start"], d["nbr"], d["hist"], d["stamp"])
        n, m = s.n_own, s.n_rows
        if len(self.nbr_start) < n + 1:
            self.nbr_start = np.zeros(s.capacity + 1, np.int64)
        keep = self._place_rows(origin)
        start, nbr, k = self._build_lists(n, m)
        hist = cuda.device_array((max(k, 1), 3))
        stamp = cuda.device_array(max(k, 1), np.uint32)
        stale = np.uint32((self._epoch - 1) & 0xFFFFFFFF)
        now = np.uint32(self._epoch & 0xFFFFFFFF)
        up = self._up
        self._run(L.carry_history_migrated, self._grid(n),
                  (n, keep, old_ids, d["id"], *old, cuda.to_device(arr_start), up(arr_id, 1),
                   up(arr_ds, (1, 3)), start, nbr, hist, stamp, stale, now))
        self._take_lists(start, nbr, hist, stamp, k)
        s.drop_slots()

    def _place_rows(self, origin):
        """The GPU's rows in the host State's new order after a migration (``_rebuild_across``): owned row i
        from old GPU row origin[i] where that is >= 0 (``permute_kept3``), the arrivals (origin < 0) from the
        host (``scatter_rows3``), the ghosts' x, v and omega from the host; ids and flags all from the host.
        Returns ``origin`` on the GPU."""
        s, d, cuda, L = self.state, self._dev, self.cuda, self.kl
        n, m = s.n_own, s.n_rows
        arrived = np.flatnonzero(origin < 0)
        at = self._up(arrived.astype(np.intp), 1)
        keep = self._up(origin, 1)
        for name in self._rows_of():
            new = cuda.device_array((max(m, 1), 3))
            self._run(L.permute_kept3, self._grid(n), (n, keep, d[name], new))
            if len(arrived):
                self._run(L.scatter_rows3, self._grid(len(arrived)),
                          (at, cuda.to_device(np.ascontiguousarray(getattr(s, name)[arrived])), new))
            if m > n and name in ("x", "v", "omega"):
                new[n:m].copy_to_device(np.ascontiguousarray(getattr(s, name)[n:m]))
            d[name] = new
        for name in ("fixed", "id"):
            d[name] = cuda.to_device(np.ascontiguousarray(getattr(s, name)[:max(m, 1)]))
        d["x_ref"] = cuda.device_array((max(n, 1), 3))
        self._ghost_sources()
        return keep

    def _fetch_rows(self, rows, names):
        """GPU rows ``rows``' fields ``names`` (each (n, 3)) as host arrays (``migrate.Keeper``'s ``fetch``)."""
        d, cuda = self._dev, self.cuda
        m = len(rows)
        g = cuda.to_device(np.ascontiguousarray(rows, np.intp))
        out = cuda.device_array((3, m, 3))
        got = {}
        for part in (names[i:i + 3] for i in range(0, len(names), 3)):
            fields = [d[name] for name in part] + [d[part[0]]] * (3 - len(part))
            self._run(self.kl.gather_rows, self._grid(m), (g, *fields, out))
            host = out.copy_to_host()
            got.update({name: host[j] for j, name in enumerate(part)})
        return got

    def _up(self, a, empty):
        """``a`` on the GPU, or zeros of shape ``empty`` (its dtype) where it has no element."""
        return self.cuda.to_device(np.ascontiguousarray(a) if len(a) else np.zeros(empty, a.dtype))

    def _pack_contacts(self, rows):
        """GPU rows ``rows``' entries in contact as compact slots (``migrate.Keeper``'s ``pack``): counts
        (m,) int64, partner ids (M,) int64 and Delta s (M, 3) [d]."""
        d, cuda, L = self._dev, self.cuda, self.kl
        m = len(rows)
        g = cuda.to_device(np.ascontiguousarray(rows, np.intp))
        counts = cuda.device_array(m, np.int64)
        now = np.uint32(self._epoch & 0xFFFFFFFF)
        self._run(L.count_contacts_of, self._grid(m), (g, d["start"], d["stamp"], now, counts))
        c = counts.copy_to_host()
        first = np.zeros(m + 1, np.int64)
        np.cumsum(c, out=first[1:])
        total = int(first[-1])
        sid, sds = cuda.device_array(max(total, 1), np.int64), cuda.device_array((max(total, 1), 3))
        self._run(L.pack_contacts_of, self._grid(m), (g, cuda.to_device(first[:m]), d["id"], d["start"], d["nbr"],
                                                      d["hist"], d["stamp"], now, sid, sds))
        return c, sid.copy_to_host()[:total], sds.copy_to_host()[:total]

    def _rebuild_in_place(self):
        """``_rebuild_on_gpu`` with no round trip through the host and no allocation once sized
        (``engine.gpu_rebuild = "device"``): the cell grid's z layers from the z range on the GPU
        (``kernels.gpu.lists.grid_depth``, at most the layers the cells' arrays hold), the lists into
        the set of fixed-capacity arrays the current lists are not in (``_list_set``), their length and
        whether it fit into ``_red`` (``write_partners_in``). The host reads those with the next
        evaluation's reductions (``forces``, or ``_settle`` where something reads the lists first); on
        an overflow the forces' kernels have done nothing, the old lists come back and the lists are
        built as ``_rebuild_on_gpu`` builds them, the capacity grown. With a thread an entry (whose
        launches are sized by the entries) the length is read at once. x_ref = x."""
        s, d, L = self.state, self._dev, self.kl
        n = s.n_own
        grid, one = self._grid(n), (1, self.block)
        nx, ny, nz_cap, count, fill, cell, order = self._cells()
        room = nx * ny * nz_cap + 1
        zr, dims = self._zr_in, self._dims
        self._run(L.z_range, grid, (n, d["x"], zr))
        self._run(L.grid_depth, (1, 1), (zr, nx, ny, nz_cap, self.r_list, dims))
        self._run(L.zero_cells, self._grid(room), (count, dims))
        self._run(L.bin_rows_in, grid, (n, d["x"], nx, ny, s.L_x / nx, s.L_y / ny, zr, dims, self.r_list, cell,
                                        count))
        self._run(L.scan_in, one, (count, fill, dims))
        self._run(L.fill_cells, grid, (n, cell, fill, order))
        new = self._list_set()
        cells = (d["x"], d["id"], d["fixed"], cell, count, order, nx, ny, dims, *make_box(s.L_x, s.L_y),
                 self.r_list * self.r_list)
        self._run(L.count_partners_in, grid, (n, *cells, new["start"]))
        self._run(L.scan, one, (new["start"], n))
        self._run(L.write_partners_in, grid, (n, *cells, new["start"], new["nbr"], self._red))
        stale = np.uint32((self._epoch - 1) & 0xFFFFFFFF)
        self._run(L.carry_history_in, grid, (n, d["id"], d["start"], d["nbr"], d["hist"], d["stamp"], new["start"],
                                             new["nbr"], new["hist"], new["stamp"], stale))
        self._pending = (d["start"], d["nbr"], d["hist"], d["stamp"], self._k)
        d["start"], d["nbr"], d["hist"], d["stamp"] = new["start"], new["nbr"], new["hist"], new["stamp"]
        self._k = None
        self._run(L.copy_rows, grid, (n, d["x"], d["x_ref"]))
        self._host_lists = False
        self._pairs_kept = False
        s.slots_current = False
        if self.by_entry and not self._settle():
            self._run(L.entry_rows_in, grid, (n, d["start"], new["row"]))
            d["row"] = new["row"]

    def _rebuild_sorted(self):
        """A rebuild that first orders the rows by cell, on the GPU (``engine.gpu_sort = "device"``; one
        rank): the cells of ``order.sort_rows`` ranked (``sort_columns``, ``kernels.gpu.lists.sort_cells_of``),
        a counting sort by them, each cell's rows by id (the same permutation whatever the atomics' order),
        every row array permuted (``permute_rows``), then the lists built as ``_rebuild_in_place`` builds
        them, the history carried by partner id from the old lists (``carry_history_moved``). The lists'
        length is read back at once (a copy of 64 bytes every ``SORT_EVERY``-th rebuild): on an overflow
        the lists are built again with room, the rows staying in their new order. The permutation is
        copied back with it (4 bytes a row) and the host's State takes it at once: its rows in the GPU's
        order (ids and the bed's flags current, the rest as stale as before; the slots are packed anew by
        ``sync_state``). x_ref = x."""
        s, d, L = self.state, self._dev, self.kl
        n = s.n_own
        grid, one = self._grid(n), (1, self.block)
        nx, ny, nz_cap, count, fill, cell, order = self._cells()
        room = nx * ny * nz_cap + 1
        zr, dims = self._zr_in, self._dims
        if self._columns is None or self._columns[0] != (nx, ny):
            self._columns = ((nx, ny), tuple(self.cuda.to_device(a) for a in sort_columns(nx, ny)))
        perm = self._buffer("perm", n, np.int32)
        self._run(L.z_range, grid, (n, d["x"], zr))
        self._run(L.grid_depth, (1, 1), (zr, nx, ny, nz_cap, self.r_list, dims))
        self._run(L.zero_cells, self._grid(room), (count, dims))
        self._run(L.sort_cells_of, grid, (n, d["x"], nx, ny, s.L_x / nx, s.L_y / ny, zr, dims, self.r_list,
                                          *self._columns[1], cell, count))
        self._run(L.scan_in, one, (count, fill, dims))
        self._run(L.fill_cells, grid, (n, cell, fill, perm))
        self._run(L.sort_within_cells, self._grid(room), (dims, count, perm, d["id"]))
        # the rows into their spares in the new order, then the spares current (the old ids kept there)
        for name in self._rows_of() + ("fixed", "id"):
            a = d[name]
            b = self._spare.get(name)
            if b is None or b.shape != a.shape or b.dtype != a.dtype:
                b = self._spare[name] = self.cuda.device_array(a.shape, a.dtype)
            self._run(L.permute_rows3 if a.ndim == 2 else L.permute_rows, grid, (n, perm, a, b))
            d[name], self._spare[name] = b, a
        old_ids = self._spare["id"]
        # the lists of the rows in their new order (the z range is the same: ``dims`` stands)
        self._run(L.zero_cells, self._grid(room), (count, dims))
        self._run(L.bin_rows_in, grid, (n, d["x"], nx, ny, s.L_x / nx, s.L_y / ny, zr, dims, self.r_list, cell,
                                        count))
        self._run(L.scan_in, one, (count, fill, dims))
        self._run(L.fill_cells, grid, (n, cell, fill, order))
        cells = (d["x"], d["id"], d["fixed"], cell, count, order, nx, ny, dims, *make_box(s.L_x, s.L_y),
                 self.r_list * self.r_list)
        stale = np.uint32((self._epoch - 1) & 0xFFFFFFFF)
        k = self.k
        while True:
            new = self._list_set()
            self._run(L.count_partners_in, grid, (n, *cells, new["start"]))
            self._run(L.scan, one, (new["start"], n))
            self._run(L.write_partners_in, grid, (n, *cells, new["start"], new["nbr"], self._red))
            self._run(L.carry_history_moved, grid, (n, perm, old_ids, d["id"], d["start"], d["nbr"], d["hist"],
                                                    d["stamp"], new["start"], new["nbr"], new["hist"], new["stamp"],
                                                    stale))
            red = self._red.copy_to_host(self._red_host)
            entries = int(red[k.RED_ENTRIES])
            if not red[k.RED_OVERFLOW]:
                break
            # the flag is written again by the next build; the old lists are where they were
            self.n_overflows += 1
            self._capacity = int(1.25 * entries) + 64
            self._sets = []
        for name in ("start", "nbr", "hist", "stamp"):
            d[name] = new[name]
        self._k = entries
        order = perm[:n].copy_to_host()
        for name in ROW_FIELDS:
            a = getattr(s, name)
            a[:n] = a[:n][order]
        s.n_rows = n
        self._run(L.copy_rows, grid, (n, d["x"], d["x_ref"]))
        self._host_lists = False
        self._pairs_kept = False
        s.slots_current = False
        if self.by_entry:
            self._run(L.entry_rows_in, grid, (n, d["start"], new["row"]))
            d["row"] = new["row"]

    def _cells(self):
        """The cell grid of a rebuild without the host: (nx, ny, nz_cap, count, fill, cell, order), its
        columns, its most z layers (the host path's bound, z hashed above it) and its arrays, with room for
        that many cells and the rows; the lists' capacity set if not yet (a quarter more than the lists)."""
        s = self.state
        n = s.n_own
        if not self._capacity:
            self._capacity = int(1.25 * self._k) + 64
        nx, ny = cell_axis(s.L_x, self.r_list), cell_axis(s.L_y, self.r_list)
        nz_cap = max(3, 4 * (n // (nx * ny)) + 8)
        room = nx * ny * nz_cap + 1
        count, fill = self._buffer("cells", room, np.int32), self._buffer("fill", room, np.int32)
        cell, order = self._buffer("cell", n, np.int32), self._buffer("order", n, np.int32)
        return nx, ny, nz_cap, count, fill, cell, order

    def _launch_lists(self):
        """``advance_lists``'s arguments after ``advance``'s (ids .. col_local) and the list set its rebuilds
        alternate with the current lists (``_list_set``): rebuilds up to the one before the next
        ``SORT_EVERY``-th (which goes through the host), or with ``sort_on_gpu`` all of them, every
        ``SORT_EVERY``-th ordering the rows first (``advance_lists_sorted``: the rows' spares, ``moved``,
        the permutation's buffer and ``sort_columns``'s arrays; without, the same arrays, not read). With a thread
        an entry the entries' rows (``row``) get room for the capacity first: a rebuild inside the launch writes
        the new lists' rows there."""
        s, d = self.state, self._dev
        n = s.n_own
        nx, ny, nz_cap, count, fill, cell, order = self._cells()
        second = self._list_set()
        if self.by_entry and d["row"].shape[0] < self._capacity:
            # the entries' rows with room for the lists a rebuild inside the launch writes there (the host's or a
            # rebuild's by ``_rebuild_on_gpu`` have room for their own)
            row = self.cuda.device_array(max(self._capacity, self._k), np.int32)
            self._run(self.kl.entry_rows, self._grid(n), (n, d["start"], row))
            d["row"] = row
        r = self.n_rebuilds % SORT_EVERY
        # with the rows ordered on the GPU, every rebuild inside (every SORT_EVERY-th ordering them first)
        budget = BATCH if self.sort_on_gpu else (SORT_EVERY - r if r else 0)
        names = self._rows_of()[:5] + ("wall_ds", "fixed", "id", "moved")
        if "moved" not in d or d["moved"].shape[0] != d["x"].shape[0]:
            # each GPU row's row in the host's State (rows ordered inside a launch: ``_take_moved``)
            d["moved"] = self.cuda.to_device(np.arange(d["x"].shape[0], dtype=np.int32))
        spares = []
        for name in names:
            a, b = d[name], self._spare.get(name)
            if b is None or b.shape != a.shape or b.dtype != a.dtype:
                b = self._spare[name] = self.cuda.device_array(a.shape, a.dtype)
            spares.append(b)
        if self._columns is None or self._columns[0] != (nx, ny):
            self._columns = ((nx, ny), tuple(self.cuda.to_device(a) for a in sort_columns(nx, ny)))
        perm = self._buffer("perm", n, np.int32)
        return (d["id"], self._zr_in, count, fill, cell, order, second["start"], second["nbr"], second["hist"],
                second["stamp"], nx, ny, nz_cap, s.L_x / nx, s.L_y / ny, self.r_list, self.r_list * self.r_list,
                budget, self.sort_on_gpu, SORT_EVERY, r, d["moved"], *spares, perm, *self._columns[1]), second

    def _list_set(self):
        """The set of fixed-capacity list arrays (start, nbr, hist, stamp; row with a thread an entry)
        that the current lists are not in; both sets (re)allocated for a new capacity or row
        count."""
        n, c, cuda = self.state.n_own, self._capacity, self.cuda
        if not self._sets or self._sets[0]["nbr"].shape[0] != c or self._sets[0]["start"].shape[0] != n + 1:
            self._sets = [{"start": cuda.device_array(n + 1, np.int64), "nbr": cuda.device_array(c, np.int32),
                           "hist": cuda.device_array((c, 3)), "stamp": cuda.device_array(c, np.uint32)}
                          for _ in range(2)]
            # one array of the entries' rows: the old lists' are not read again
            self._sets[0]["row"] = self._sets[1]["row"] = cuda.device_array(c if self.by_entry else 1, np.int32)
        return self._sets[1] if self._dev["nbr"] is self._sets[0]["nbr"] else self._sets[0]

    def _settle(self, red=None):
        """Read a rebuild in place's length and room (``_rebuild_in_place``) if none has been yet: from
        ``red`` (``_red`` as copied to the host after the evaluation that followed it) or copied now.
        On an overflow the lists it replaced come back, the capacity grows to a quarter more than the
        lists need, and the lists are built as ``_rebuild_on_gpu`` builds them (the rows where they
        were: the forces' kernels did nothing). Returns whether it built them again."""
        if self._pending is None:
            return False
        k = self.k
        if red is None:
            red = self._red.copy_to_host(self._red_host)
        old, self._pending = self._pending, None
        entries = int(red[k.RED_ENTRIES])
        if not red[k.RED_OVERFLOW]:
            self._k = entries
            return False
        d = self._dev
        d["start"], d["nbr"], d["hist"], d["stamp"], self._k = old
        self._red[k.RED_ENTRIES:].copy_to_device(np.zeros(k.RED_SLOTS - k.RED_ENTRIES))
        self.n_overflows += 1
        self._capacity = int(1.25 * entries) + 64
        self._sets = []
        self._rebuild_on_gpu()
        return True

    def _entry_rows(self, grid):
        """Each list entry's row on the GPU (``row``) when the forces take a thread an entry: from the
        host's lists (``grid`` None, after ``_upload``) or built on the GPU from its (a launch over
        ``grid``)."""
        if not self.by_entry:
            return
        s, d, k = self.state, self._dev, max(self._k, 1)
        if grid is None:
            rows = np.repeat(np.arange(s.n_own, dtype=np.int32), np.diff(self.nbr_start[:s.n_own + 1]))
            d["row"] = self.cuda.to_device(rows if len(rows) else np.zeros(1, np.int32))
        else:
            d["row"] = self.cuda.device_array(k, np.int32)
            self._run(self.kl.entry_rows, grid, (s.n_own, d["start"], d["row"]))

    def _pairs(self, keep):
        """``pair`` with room for every entry where an evaluation writes it (kept pairs, or the forces
        a thread an entry)."""
        d = self._dev
        # the lists' capacity while their length is not yet read (``_rebuild_in_place``)
        k = max(self._capacity if self._k is None else self._k, 1)
        if self.in_launch and self.by_entry:
            # and at least the capacity where a launch may rebuild them (``advance_lists_entry``)
            k = max(k, self._capacity)
        if (keep or self.by_entry) and d["pair"].shape[0] < k:
            # with rebuilds in place, room for as many entries as their lists (no allocation at their rebuilds)
            d["pair"] = self.cuda.device_array((max(int(k * 1.1) + 64, self._capacity), 6))
        return d["pair"]

    def _buffer(self, name, size, dtype):
        """A device array of at least ``size`` elements kept between rebuilds (grown by a quarter)."""
        a = self._buffers.get(name)
        if a is None or a.shape[0] < size:
            a = self._buffers[name] = self.cuda.device_array(int(size * 1.25) + 64, dtype)
        return a

    def _refresh(self):
        """The ghost rows' x, v and omega from their owners, through the host (several ranks): the
        rows the refresh sends are gathered on the GPU and copied down, the ghosts copied up."""
        s, d = self.state, self._dev
        if not self.domain.parallel:
            return
        if self._halo is not None:
            self._refresh_on_gpu()
            return
        rows = self._sources
        m = len(rows)
        if m:
            self._run(self.kl.gather_rows, self._grid(m), (d["sources"], d["x"], d["v"], d["omega"], d["sent"]))
            sent = d["sent"][:, :m].copy_to_host(self._sent_host[:, :m])
            s.x[rows], s.v[rows], s.omega[rows] = sent[0], sent[1], sent[2]
        self.domain.refresh(s)
        for name in ("x", "v", "omega"):
            if s.n_rows > s.n_own:
                d[name][s.n_own:s.n_rows].copy_to_device(np.ascontiguousarray(getattr(s, name)[s.n_own:s.n_rows]))

    def _refresh_on_gpu(self):
        """The ghost refresh with its messages packed and unpacked on the GPU (``engine.gpu_exchange =
        "device"``): the plan's send buffer filled by ``pack_ghosts`` and copied down, the messages
        exchanged (``GhostPlan.exchange``), the receive buffer copied up and unpacked into the ghost rows.
        The host's rows are not touched."""
        d, L, plan = self._dev, self.kl, self.domain.plan
        (s_rows, s_at, s_stride, n_sent), (r_rows, r_at, r_stride, n_got), send, recv = self._halo
        if n_sent:
            self._run(L.pack_ghosts, self._grid(n_sent), (s_rows, s_at, s_stride, d["x"], d["v"], d["omega"], send))
            send[:plan.send_buf.size].copy_to_host(plan.send_buf)
        plan.exchange()
        if n_got:
            recv[:plan.recv_buf.size].copy_to_device(plan.recv_buf)
            self._run(L.unpack_ghosts, self._grid(n_got), (r_rows, r_at, r_stride, recv, d["x"], d["v"], d["omega"]))

    def _pinned(self, name, size):
        """(size,) float64 of page-locked host memory for the ghost refresh's buffer ``name`` (``Domain.buffer_alloc``,
        ``GhostPlan``'s ``alloc``): one array a name, grown by a quarter when too small, reused by every plan
        (a rebuild frees the old plan before it makes the new)."""
        a = self._pinned_bufs.get(name)
        if a is None or a.size < size:
            a = self._pinned_bufs[name] = self.cuda.pinned_array(int(size * 1.25) + 64)
        return a[:size]

    def _halo_layout(self):
        """The refresh plan's layout on the GPU (``_refresh_on_gpu``), after a rebuild; None without
        ``exchange_on_gpu`` or on one rank."""
        if not (self.exchange_on_gpu and self.domain.parallel):
            return None
        plan, up = self.domain.plan, self._up
        sr, sa, ss, rr, ra, rs = plan.layout()
        return ((up(sr, 1), up(sa, 1), up(ss, 1), len(sr)), (up(rr, 1), up(ra, 1), up(rs, 1), len(rr)),
                self.cuda.device_array(max(plan.send_buf.size, 1)), self.cuda.device_array(max(plan.recv_buf.size, 1)))

    # -- forces --
    def forces(self, increment=True, keep_pairs=False):
        """Contact forces on the owned rows, history updated in place; returns (max overlap, contacts).

        With ``keep_pairs`` every entry's force stays on the GPU for ``force_ratio``."""
        t = time.perf_counter()
        s, d, k = self.state, self._dev, self.k
        pair = self._pairs(keep_pairs)
        self._pairs_kept = keep_pairs
        self._epoch += 1
        planes_d, kinds_d = self._device_planes()
        box = make_box(s.L_x, s.L_y)
        if not self._red_fresh:
            # the step's slots only: those of a rebuild in place (RED_ENTRIES, RED_OVERFLOW) are read below
            self._red[:len(k.NEUTRAL)].copy_to_device(np.array(k.NEUTRAL))
        self._red_fresh = False
        if self.by_entry:
            self._launch("entry_forces", max(self._k, 1), d["row"], d["x"], d["v"], d["omega"], d["fixed"], d["nbr"],
                         d["hist"], d["stamp"], pair, keep_pairs, self._epoch, *box, self.law, increment, self._red)
            self._launch("row_sums", s.n_own, d["x"], d["v"], d["omega"], d["f"], d["torque"], d["fixed"], d["start"],
                         d["stamp"], pair, d["wall_ds"], planes_d, kinds_d, self._epoch, self.law, increment,
                         self._red)
        else:
            self._launch("forces", s.n_own, d["x"], d["v"], d["omega"], d["f"], d["torque"], d["fixed"], d["start"],
                         d["nbr"], d["hist"], d["stamp"], pair, keep_pairs, d["wall_ds"], planes_d, kinds_d,
                         self._epoch, *box, self.law, increment, self._red)
        red = self._red.copy_to_host(self._red_host)
        s.slots_current = False
        self.timers["forces"] += time.perf_counter() - t
        if self._pending is not None and red[k.RED_OVERFLOW]:
            # the lists built in place did not fit and the kernels did nothing: this evaluation again, once
            # the lists are built with room (with the stamps of the rebuild's evaluation)
            self._epoch -= 1
            self._settle(red)
            return self.forces(increment, keep_pairs)
        self._settle(red)
        return float(red[k.RED_OVERLAP]), int(red[k.RED_CONTACTS])

    def step(self, flags=NO_FLAGS, defer_kick=False, keep_pairs=False):
        """One velocity-Verlet step; returns a new StepInfo (reduced over ranks). As the CPU
        engine's ``step``: the same decisions from the same exact reductions."""
        s, p, d = self.state, self.phys, self._dev
        t = time.perf_counter()
        self._launch("kick_drift", s.n_own, d["x"], d["v"], d["omega"], d["f"], d["torque"], d["fixed"], d["x_ref"],
                     p.dt, *make_box(s.L_x, s.L_y), self._kick_due, self._red)
        self._red_fresh = True
        red = self._red.copy_to_host(self._red_host)
        self._kick_due = False
        s.slots_current = False
        self.timers["integration"] += time.perf_counter() - t
        return self._finish_step(red, self.last_overlap, flags, defer_kick, keep_pairs)

    def _finish_step(self, red, overlap, flags, defer_kick=True, keep_pairs=False):
        """The rest of a step whose drift is done, with ``red`` its reductions (``kernels.gpu.step``) and
        ``overlap`` the previous evaluation's: the one allreduce, a rebuild or the ghosts' refresh, the
        forces; returns its StepInfo."""
        s, p, k = self.state, self.phys, self.k
        n2 = math.nan if red[k.RED_BAD] else float(red[k.RED_D2])
        reduce = [n2, overlap, -float(red[k.RED_ZMIN]), float(red[k.RED_ZMAX])] + list(flags)
        n2, overlap, neg_z_min, z_max, *agreed = self.domain.max_many(np.array(reduce)).tolist()
        if math.isinf(n2):
            return self._not_finite(overlap, z_max, flags._make(agreed))
        if not math.sqrt(n2) < 0.5 * p.skin or self.domain.rebalance_due(self.work_since_rebuild):
            self.rebuild()
        else:
            self._refresh()
        self.last_overlap, self._contacts = self.forces(increment=True, keep_pairs=keep_pairs)
        self._kick_due = True
        if not defer_kick:
            self.complete()
        s.step += 1
        s.time = s.step * p.dt
        self.info = StepInfo(overlap, self.n_contacts, -neg_z_min, z_max, flags._make(agreed))
        return self.info

    @property
    def steps_in_one_call(self):
        """``run_quiet`` runs its steps in launches of many (one rank), not one by one."""
        return not self.domain.parallel

    def run_quiet(self, n, flags=NO_FLAGS):
        """``n`` steps that nothing reads between (no sample, no file, no progress line), each as
        ``step(flags, defer_kick=True)``; returns their StepInfos, with ``flags`` for all.

        On one rank the steps run in launches of up to ``BATCH`` steps (``kernels.gpu.step.advance``,
        a cooperative grid), so that a step costs no launch or copy of its own. A launch ends early at
        a step that needs a list rebuild (or has a position that is not finite), which the host
        finishes as ``step`` would. The same arithmetic, so the same bits. With several ranks (the
        ghosts are refreshed through the host every step) they are steps one by one."""
        if not self.steps_in_one_call or self.state.n_own == 0:
            return [self.step(flags, defer_kick=True) for _ in range(n)]
        # a rebuild in place with no evaluation since (``rebuild`` called on its own): its length read
        self._settle()
        if n > 0:
            # the launches' evaluations keep no pairs (the CPU engine's ``force_ratio`` is then nan too)
            self._pairs_kept = False
        s, p, d, k = self.state, self.phys, self._dev, self.k
        infos = []
        planes_d, kinds_d = self._device_planes()
        while len(infos) < n:
            m = min(n - len(infos), BATCH)
            t = time.perf_counter()
            if self.in_launch:
                # first: it sizes the lists' capacity, for which ``_pairs`` makes room with a thread an entry
                more, second = self._launch_lists()
            head = (s.n_own, d["x"], d["v"], d["omega"], d["f"], d["torque"], d["fixed"], d["x_ref"], d["start"],
                    d["nbr"], d["hist"], d["stamp"], self._pairs(False), d["wall_ds"], planes_d, kinds_d, self._epoch,
                    *make_box(s.L_x, s.L_y), self.law, self._kick_due, 0.5 * p.skin, m, self._rec)
            tail = (max(self._k, 1), d.get("row", d["nbr"]), bool(self.fused), *self._second_rows(),
                    self.one_barrier)
            if self.in_launch:
                args = head + tail + more
            else:
                args = head + (self.by_entry,) + tail
            name = self._advance_name()
            self._launch(name, *args, grid=self._cooperative_grid(name, args))
            rec = self._rec[:m].copy_to_host(self._rec_host[:m])
            self._kick_due = False
            s.slots_current = False
            overlap = self.last_overlap
            whole = rebuilt = 0
            for r in rec:
                if r[k.RED_BAD]:
                    break
                if not math.sqrt(r[k.RED_D2]) < 0.5 * p.skin:
                    # a step that rebuilt the lists inside the launch is whole
                    if not (self.in_launch and r[k.RED_ENTRIES] >= 0.0 and not r[k.RED_OVERFLOW]):
                        break
                    rebuilt += 1
                    self._k = int(r[k.RED_ENTRIES])
                infos.append(StepInfo(overlap, self.n_contacts, float(r[k.RED_ZMIN]), float(r[k.RED_ZMAX]), flags))
                overlap = float(r[k.RED_OVERLAP])
                whole += 1
            if rebuilt:
                before = self.n_rebuilds
                self._rebuilt_in_launch(rebuilt, second)
                if self.sort_on_gpu and any(r % SORT_EVERY == 0 for r in range(before, before + rebuilt)):
                    self._take_moved()
            if whole < m and self.in_launch and rec[whole][k.RED_OVERFLOW]:
                # the step's lists did not fit: the host's rebuild below (in place) with room for them
                need = int(rec[whole][k.RED_ENTRIES])
                self.n_overflows += 1
                if need > self._capacity:
                    self._capacity = int(1.25 * need) + 64
                    self._sets = []
            if whole:
                self._epoch += whole
                s.step += whole
                s.time = s.step * p.dt
                self.last_overlap, self._contacts = overlap, int(rec[whole - 1][k.RED_CONTACTS])
                self.info = infos[-1]
            # the last whole step's second half-kick is due, unless the launch went on to drift the next
            # step (which applied it)
            self._kick_due = whole == m
            self.timers["forces"] += time.perf_counter() - t
            if whole < m:
                # the step the launch ended at has drifted: its rebuild and forces on the host's path
                infos.append(self._finish_step(rec[whole], self.last_overlap, flags))
        return infos

    def _take_moved(self):
        """The host State's rows put in the order a launch gave the GPU's (``kernels.gpu.lists.sort_phases``):
        every per-particle field permuted by ``moved`` (each GPU row's row in the State; 4 bytes a row copied
        back), which is then the identity again. The slots are stale (the GPU holds the history)."""
        s, d = self.state, self._dev
        n = s.n_own
        order = d["moved"][:n].copy_to_host()
        for name in ROW_FIELDS:
            a = getattr(s, name)
            a[:n] = a[:n][order]
        s.n_rows = n
        s.slots_current = False
        d["moved"][:n].copy_to_device(np.arange(n, dtype=np.int32))

    def _rebuilt_in_launch(self, rebuilt, second):
        """The lists after ``rebuilt`` rebuilds inside a launch of ``advance_lists``: in ``second`` (the set
        ``_launch_lists`` gave) after an odd number, where they were after an even one (with a thread an entry,
        their rows in ``row`` either way)."""
        d = self._dev
        if rebuilt % 2:
            for name in ("start", "nbr", "hist", "stamp"):
                d[name] = second[name]
        self.n_rebuilds += rebuilt
        self.n_rebuilds_in_launch += rebuilt
        self._host_lists = False
        self._pairs_kept = False

    def _cooperative_grid(self, name, args):
        """The grid of ``advance``: one row (or entry, ``by_entry``) a thread if every block fits on the
        GPU at once (a cooperative launch needs that), else as many blocks as fit, each thread taking
        several."""
        if self._coop_blocks is None:
            if self._simulator:     # numba's simulator runs a cooperative grid of one block only
                self._coop_blocks = 1
            else:
                spec = self._launcher(name, args)
                try:
                    overload = next(iter(spec.overloads.values()))
                    self._coop_blocks = max(int(overload.max_cooperative_grid_blocks(self.block)), 1)
                except (AttributeError, StopIteration):
                    # one block a multiprocessor is resident whatever the kernel's resources
                    self._coop_blocks = int(self.cuda.get_current_device().MULTIPROCESSOR_COUNT)
        n = self.state.n_own
        blocks, block = self._grid(max(n, self._k) if self.by_entry else n * max(self.lanes, 1))
        return min(blocks, self._coop_blocks), block

    def complete(self):
        """Apply the second half-kick that ``step(defer_kick=True)`` left (nothing if none)."""
        if self._kick_due:
            t = time.perf_counter()
            s, d = self.state, self._dev
            self._launch("kick", s.n_own, d["v"], d["omega"], d["f"], d["torque"], d["fixed"], self.phys.dt)
            self._kick_due = False
            self.state.slots_current = False
            self.timers["integration"] += time.perf_counter() - t

    def kinetic(self, momentum=False):
        """Global (translational, rotational) kinetic energy sums [m g d], exact (on the host); with
        ``momentum`` also the momentum along x summed over the mobile spheres [m sqrt(g d)]."""
        self.complete()
        s = self.state
        if self.has_lists and self.ks is not None:
            acc = self._sums(self.ks.kinetic_sums, 3 if momentum else 2, self._dev["v"], self._dev["omega"],
                             self._dev["fixed"])
        else:
            if self.has_lists:
                self._download_rows(("v", "omega"), s.n_own)
            acc = new_accumulator(3 if momentum else 2)
            kinetic_energy(s.n_own, self._particles(), acc, 1)
        acc = self.domain.sum_int(acc)
        return tuple(to_float(a) for a in acc)

    def _sums(self, kernel, n, *args):
        """``kernel``'s exact sums over the owned rows (``kernels.gpu.samples``): a zeroed (n, NLIMBS) int64
        accumulator on the GPU, the launch, the limbs copied back."""
        acc = self._sample_acc.get(n)
        if acc is None:
            acc = self._sample_acc[n] = self.cuda.device_array((n, NLIMBS), np.int64)
        self._run(self.ks.zero, self._grid(n * NLIMBS), (acc,))
        self._run(kernel, self._grid(self.state.n_own), (self.state.n_own, *args, acc))
        return acc.copy_to_host()

    def force_ratio(self):
        """(ratio, in flight) of the last evaluation, exact on any number of ranks, as the CPU
        engine's (``kernels.balance``); (nan, -1) unless that evaluation kept its pairs' forces."""
        if self._epoch == 0 or not self._pairs_kept:
            return math.nan, -1
        s = self.state
        if self.ks is not None:
            d = self._dev
            acc = self._sums(self.ks.balance_sums, 4, d["f"], d["fixed"], d["start"], d["stamp"], d["pair"],
                             np.uint32(self._epoch & 0xFFFFFFFF))
            return self._ratio(self.domain.sum_int(acc))
        self._lists()
        k = self._k
        self._download_rows(("f",), s.n_own)
        pair = self._dev["pair"].copy_to_host()[:k]
        stamp = self._dev["stamp"].copy_to_host()[:k]
        near = Near(self.nbr_start, self._link, self.nbr_start, self.nbr_list, self._link, self._link)
        return self._ratio(self.domain.sum_int(force_balance(s.n_own, self._particles(), near,
                                                             Slots(np.zeros((0, 3)), stamp, pair), self._epoch, 1)))

    def memory_bytes(self):
        """Bytes of the GPU's arrays (rows, lists, history, the list build's scratch, the lists' second set, the
        permutation's spares and the ghost refresh's layout and buffers)."""
        # the list sets and the permutation's spares not in use (those in use are ``_dev``'s)
        spare = [a for st in self._sets for a in st.values()] + list(self._spare.values())
        spare = {id(a): a for a in spare if not any(a is b for b in self._dev.values())}
        halo = [] if self._halo is None else [*self._halo[0][:3], *self._halo[1][:3], *self._halo[2:]]
        return (sum(a.nbytes for a in self._dev.values()) + sum(a.nbytes for a in self._buffers.values())
                + sum(a.nbytes for a in spare.values()) + sum(a.nbytes for a in halo) + self._red.nbytes
                + self._rec.nbytes)
