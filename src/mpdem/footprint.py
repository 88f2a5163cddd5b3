"""The memory a run needs on each rank, estimated before any work, and the memory there is.

A run of more spheres than its ranks can hold must be refused in one line before it builds
anything, not end in a MemoryError after minutes of set-up. The estimate is a sum of bytes per
sphere, per list entry and per contact slot, each taken from the arrays the code allocates
(``state.FIELDS``, the arrays of ``engine.lists.NeighbourLists`` and of ``engine.pairstore``),
times counts from the pile's geometry, in three phases whose largest sets the need:

- the set-up: every rank builds the whole pile (``initial.initial_state``: its arrays, the
  insertion's cell lists, the new velocities), then keeps its own rows (``Domain.scatter``: a copy
  of them, then its State); in a tiled pour (``pour.insertion = "tiles"``) a rank fills its share
  of the tiles and holds its share of the rows, and the whole bed;
- the run: the rank's rows and ghosts with their lists, contact slots, near lists and the pair
  store of a settled pile, and the copy of its rows a state file is written from;
- the end: on rank 0 the final state's digest a chunk of ids at a time (``checkpoint.digest_parts``);
  with ``output.bulk_at_end`` on every rank the bulk measurement of its rows and ghosts
  (``analysis.bulkpar``: their contacts with normals, forces and each sphere's list of them).

List entries and contacts per sphere are those of the densest packing of equal spheres,
PHI_MAX = 0.74, within the list's reach r: 8 PHI_MAX r^3 neighbours (a settled pile of the paper
holds 9.7 within 1.2 d, where this gives 10.2, and 4.8 contact slots against 5.9). A process's
own libraries (Python, numpy, numba's compiled kernels, MPI, HDF5) are ``BASE`` bytes.

What there is: ``$MPDEM_MEMORY_LIMIT`` (bytes, or with a suffix k, M, G, T: ``4G``; ``off``: no
check) if set; else the cgroup's limit less what the cgroup uses (v2 ``memory.max`` and
``memory.current``, v1 ``memory.limit_in_bytes`` and ``memory.usage_in_bytes``) where one is set,
and never more than /proc/meminfo's MemAvailable; plus what the ranks of this node already hold
(counted in ``BASE``). The ranks of one node share it.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from . import state
from .errors import MemoryRefused

# the densest packing of equal spheres: the bound of the pile's density anywhere
PHI_MAX = 0.74
# a rank's process before any array of the pile: the interpreter, numpy, numba and its compiled
# kernels, mpi4py, h5py [bytes] (measured: 0.2-0.3 GB resident after a small run's first step with
# numba's cache warm; a process that has just compiled the kernels holds some 0.18 GB more)
BASE = 300e6
# the State's row capacity over its rows (``decomp._local_state``; ``State.append`` grows by 1.2)
CAPACITY = 1.1
# cells of the insertion's cell lists per unit volume of the insertion region (``kernels.insert``: unit
# cells, a layer below and two above)
INSERT_CELLS = 1.0
ENV = "MPDEM_MEMORY_LIMIT"
CGROUP_V2 = ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current")
CGROUP_V1 = ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes")
MEMINFO = "/proc/meminfo"

# what one element (row) of each array of the CPU engine's lists is per: a row of the State, a
# list entry, a computed entry (a slot of history), a near entry, a near computed entry
LIST_ARRAYS = {"nbr_start": "row", "comp_start": "row", "near_start": "row", "near_cstart": "row",
               "nbr_list": "entry", "link": "entry", "hist": "computed", "stamp": "computed",
               "near_link": "near", "near_plink": "near",
               "near_cj": "near_computed", "near_cslot": "near_computed", "near_cpair": "near_computed"}


def field_bytes(fields):
    """Bytes of one row of each of ``fields`` together (``state.Field``: dtype times width)."""
    return sum(np.dtype(f.dtype).itemsize * f.width for f in fields)


def element_bytes(a):
    """Bytes of one row (first index) of array ``a``."""
    return a.itemsize * int(np.prod(a.shape[1:], dtype=np.int64))


def list_bytes():
    """Bytes per row, entry, computed entry, near entry and near computed entry of the CPU engine's
    lists (``LIST_ARRAYS``, from the arrays a ``NeighbourLists`` allocates), and per near computed
    entry of a kept pair store (``PairStore``). A dict by kind."""
    from .engine.lists import NeighbourLists
    from .engine.pairstore import PairStore
    lists = NeighbourLists(state.State(np.zeros(1, np.int64), np.zeros((1, 3))), 0.2, 0.03, 1)
    per = dict.fromkeys(("row", "entry", "computed", "near", "near_computed"), 0)
    for name, kind in LIST_ARRAYS.items():
        per[kind] += element_bytes(getattr(lists, name))
    per["pair"] = element_bytes(PairStore().pair)
    # ``NeighbourLists.filter``'s g2e: one int32 a computed entry, while filtering
    per["computed"] += np.dtype(np.int32).itemsize
    return per


def neighbours(r):
    """Spheres within centre distance ``r`` [d] of a sphere at the density PHI_MAX (8 PHI_MAX r^3)."""
    return 8.0 * PHI_MAX * r ** 3


@dataclass
class Estimate:
    """Bytes a rank needs in each phase of a run (without ``BASE``).

    Attributes
    ----------
    n : int
        Spheres of the whole pile (mobile and bed).
    ranks : int
    setup, run, end : float
        Peak bytes of the set-up (every rank), the run (a rank of the settled pile) and the end
        (rank 0) [bytes].
    through_root : float
        Bytes rank 0 holds more while it writes a state file for every rank (several ranks without
        parallel HDF5: ``checkpoint._write_through_root``), in the run and at the end [bytes].
    """
    n: int
    ranks: int
    setup: float
    run: float
    end: float
    through_root: float = 0.0

    def rank0(self):
        """Bytes rank 0 needs at its peak, ``BASE`` included [bytes]."""
        return BASE + max(self.setup, self.run + self.through_root, self.end + self.through_root)

    def other(self):
        """Bytes another rank needs at its peak, ``BASE`` included [bytes]."""
        return BASE + max(self.setup, self.run)

    def peak_phase(self):
        """The phase of rank 0's peak: "the set-up", "the run" or "the end"."""
        return max((self.setup, "the set-up"), (self.run + self.through_root, "the run"),
                   (self.end + self.through_root, "the end"))[1]

    def node(self, local):
        """Bytes of ``local`` ranks of one node, rank 0 among them [bytes]."""
        return self.rank0() + (local - 1) * self.other()


def estimate(n_mobile, n_bed, ranks, L_x, L_y, skin=0.2, near_skin=0.03, insert_height=0.0, from_file=False,
             tiles=None, bulk_at_end=True, parallel_files=True):
    """The memory of a run of ``n_mobile`` + ``n_bed`` spheres on ``ranks`` ranks.

    Parameters
    ----------
    n_mobile, n_bed : int
        Mobile and bed spheres.
    ranks : int
    L_x, L_y : float
        The box [d] (the ghosts of a slab are a layer of its area).
    skin, near_skin : float
        The list's and the near list's reach beyond contact [d].
    insert_height : float
        Height of a pour's insertion region [d] (0: no insertion, a pile read from a file).
    from_file : bool
        The rows come from a state file with their contact slots (each rank reads a share).
    tiles : (float, float, float) or None
        A tiled pour (``pour.insertion = "tiles"``): the most mobile spheres a rank fills (its run of
        tiles), the most a tile holds, and the cells of the insertion's cell lists of a tile; each rank
        keeps its share of the rows, beside the whole bed. None: every rank inserts the whole pour.
    bulk_at_end : bool
        Each rank measures the bulk on its own rows and ghosts at the end (``output.bulk_at_end``).
    parallel_files : bool
        h5py writes state files with parallel HDF5 (``checkpoint.parallel_hdf5``); without it rank 0
        gathers every rank's rows to write each one.

    Returns
    -------
    Estimate
    """
    n = int(n_mobile) + int(n_bed)
    P = max(1, int(ranks))
    own = n / P
    row = field_bytes(state.ROW)                                     # a State's row
    initial = field_bytes([state.FIELD[k] for k in state.INITIAL])   # a row of the whole initial state
    stored = field_bytes([f for f in state.stored() if f.per == state.PARTICLE and f.optional is None])
    slot = field_bytes(state.SLOT)                                   # a contact slot
    per = list_bytes()
    f8 = np.dtype(np.float64).itemsize
    contacts = neighbours(1.0)
    # -- the set-up: the whole pile on every rank
    if from_file:
        # each rank reads its share with the slots, then the rows travel to their owners
        setup = 2 * own * (stored + contacts * slot) + CAPACITY * own * row
    elif tiles is not None:
        # the whole bed (its centres); this rank's share of new rows, a tile's cells, then the rows sent
        # to their owners (the parts, the rows received, merged and sorted by id) and its State
        filled, per_tile, tile_cells = tiles
        share = filled + n_bed / P
        filling = n_bed * 3 * f8 + share * initial + per_tile * (3 * f8 + 8) + tile_cells * 8
        setup = n_bed * 3 * f8 + max(filling, 3 * share * initial + CAPACITY * own * row)
    else:
        whole = n * initial
        # the insertion: the new centres, the cell lists (a position and a next per sphere, a head per cell)
        cells = INSERT_CELLS * L_x * L_y * (insert_height + 5.0)
        insertion = n_mobile * 3 * f8 + n * (3 * f8 + 8) + cells * 8
        # the new centres and velocities (and the square of the velocities) beside the whole state
        velocities = n_mobile * 3 * f8 * 3
        joining = whole + n_mobile * 3 * f8 * 2
        # the rank's rows: copied, then its State, beside the whole state
        scatter = whole + own * initial + CAPACITY * own * row
        setup = max(insertion, velocities, joining, scatter)
    # -- the run: a settled pile
    # a slab's ghosts: a layer 1 + skin thick on each face, at the density PHI_MAX / (pi d^3 / 6)
    ghosts = 0.0 if P == 1 else 2 * L_x * L_y * (1.0 + skin) * PHI_MAX / (math.pi / 6)
    rows = CAPACITY * own + ghosts
    entries = neighbours(1.0 + skin)
    near = neighbours(1.0 + near_skin)
    lists = (rows * per["row"] + own * CAPACITY * (entries * per["entry"] + entries / 2 * per["computed"]
                                                    + near * per["near"] + near / 2 * per["near_computed"]))
    kept_pairs = own * near / 2 * per["pair"]
    slots = own * contacts * slot
    # a state file is written from a copy of the rank's rows sorted by id, with its slots
    write = own * (stored + contacts * slot)
    run = rows * row + lists + kept_pairs + slots + write
    # -- the end: on rank 0 the final state's digest a chunk of ids at a time (``checkpoint.digest_parts``:
    # the chunk's rows with their slots, received, then put in order); with the bulk measurement
    # (``bulk_at_end``) each rank's rows and ghosts searched for contacts, each contact with its rows, branch,
    # distance, normal, force and band, and twice in the spheres' lists of their contacts (some 200 bytes),
    # each row with its flags and counts
    from .io.checkpoint import DIGEST_CHUNK
    # a field of a chunk at a time: the largest per row is a contact slot's Delta s, with the rows' ids and counts
    chunk = min(n, DIGEST_CHUNK) * 3 * (16 + contacts * 3 * f8) if P > 1 else 0.0
    # the rank's rows sorted by id for the digest, then the final state file written from a copy of them
    then = max(own * (stored + contacts * slot) + chunk, write)
    if bulk_at_end:
        then = max(then, rows * (contacts / 2 * 200 + 16 * 8))
    end = rows * row + lists + then
    # without parallel HDF5, rank 0 writes each state file for all: every rank's rows (the parts, joined)
    through = 2 * n * (stored + contacts * slot) if P > 1 and not parallel_files else 0.0
    return Estimate(n, P, float(setup), float(run), float(end), float(through))


def initial_count(cfg, lammps_table=None):
    """Spheres of a new run's ``run.initial_file`` when they are known before reading it (a state
    file's attribute, a LAMMPS file already read); None for a pour, -1 when not known (a text table)."""
    path = cfg.run.initial_file
    if not path:
        return None
    if lammps_table is not None:
        return len(lammps_table["id"])
    from .io import checkpoint
    try:
        if checkpoint.is_state_file(path):
            return int(checkpoint.read_attrs(path)["n"])
    except Exception:     # a file that cannot be read is refused, with its reason, where it is read
        pass
    return -1


def of_config(cfg, ranks, n_file=None):
    """The Estimate of a new run of Config ``cfg`` on ``ranks`` ranks: a pour (``pour.N`` spheres on a bed
    of about ``bed.density_max`` per d^2), or ``n_file`` spheres of an initial file (None: a pour)."""
    L_x, L_y = cfg.box.L_x, cfg.box.L_y
    skin, near_skin = cfg.integration.skin, cfg.integration.near_skin
    from .io.checkpoint import parallel_hdf5
    opts = dict(bulk_at_end=cfg.output.bulk_at_end, parallel_files=parallel_hdf5())
    if n_file is not None:
        return estimate(n_file, 0, ranks, L_x, L_y, skin, near_skin, from_file=True, **opts)
    from .build import insertion_height, pour_tiles
    n_bed = int(math.ceil(cfg.bed.density_max * L_x * L_y))
    if cfg.pour.insertion == "tiles":
        t = pour_tiles(cfg.pour.N, L_x, L_y, 0.0, cfg.pour.phi_i, cfg.pour.tile)
        wx, wy, wz = t.w
        most = int(t.counts.max())
        # a rank's run of tiles: ceil(T / P) of them at most (initial.pour_tiled)
        filled = min(cfg.pour.N, -(-len(t.counts) // max(1, int(ranks))) * most)
        cells = INSERT_CELLS * (wx + 1.0) * (wy + 1.0) * (wz + 5.0)
        return estimate(cfg.pour.N, n_bed, ranks, L_x, L_y, skin, near_skin, insert_height=t.H,
                        tiles=(filled, most, cells), **opts)
    H = insertion_height(cfg.pour.N, L_x, L_y, cfg.pour.phi_i)
    return estimate(cfg.pour.N, n_bed, ranks, L_x, L_y, skin, near_skin, insert_height=H, **opts)


def parse_bytes(text):
    """Bytes of ``4000000000``, ``4G``, ``512M``, ``1.5T`` (powers of 1024 for the suffixes); None for
    ``off``; ValueError otherwise."""
    t = str(text).strip().lower()
    if t in ("off", "none", "no"):
        return None
    scale = 1
    if t and t[-1] in "kmgt":
        scale = 1024 ** ("kmgt".index(t[-1]) + 1)
        t = t[:-1].rstrip("i")
    v = float(t) * scale
    if not v >= 0 or math.isinf(v):
        raise ValueError(text)
    return int(v)


def _read_int(path):
    """The integer in file ``path``, or None (missing, unreadable, or ``max``)."""
    try:
        with open(path) as fh:
            t = fh.read().strip()
        return int(t)
    except (OSError, ValueError):
        return None


def mem_available(path=MEMINFO):
    """/proc/meminfo's MemAvailable [bytes], or None."""
    try:
        with open(path) as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def cgroup_room(v2=CGROUP_V2, v1=CGROUP_V1):
    """(the cgroup's limit less its use, its limit, the file) [bytes], or None without a limit."""
    for limit_path, use_path in (v2, v1):
        limit = _read_int(limit_path)
        # v1 says "no limit" with a number near 2^63
        if limit is None or limit >= 1 << 60:
            continue
        used = _read_int(use_path) or 0
        return max(limit - used, 0), limit, limit_path
    return None


def rss_now():
    """Resident set size of this process now [bytes] (/proc/self/status VmRSS; 0 if unknown)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


def available(local=1, env=None):
    """(bytes the ``local`` ranks of this node may use in all, in words where from), or (None, why) when
    the check is off or nothing is known.

    ``env``: the environment to read ``MPDEM_MEMORY_LIMIT`` from (default ``os.environ``)."""
    env = os.environ if env is None else env
    if env.get(ENV):
        try:
            v = parse_bytes(env[ENV])
        except ValueError:
            raise MemoryRefused(f"{ENV}={env[ENV]!r}: accepted bytes, with an optional suffix k, M, G or T "
                                f"(4G), or off") from None
        return (None, f"{ENV}=off") if v is None else (v, f"{ENV}={env[ENV]}")
    held = local * rss_now()
    avail, where = mem_available(), "MemAvailable"
    room = cgroup_room()
    if room is not None and (avail is None or room[0] < avail):
        avail, where = room[0], f"cgroup {os.path.basename(room[2])} {words(room[1])}"
    if avail is None:
        return None, "not known"
    return avail + held, where


def words(b):
    """Bytes in words: ``830 MB``, ``41.2 GB``."""
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if b >= size:
            return f"{b / size:.3g} {unit}"
    return f"{b / 1e3:.3g} kB"


def what(cfg, n_file, label=None):
    """The spheres of a run, in words (``pour.N = 1000000 spheres``), or ``label``."""
    if label:
        return label
    return f"{n_file} spheres of run.initial_file" if n_file is not None else f"pour.N = {cfg.pour.N} spheres"


def verdict(cfg, ranks, local, n_file=None, env=None, label=None):
    """(the log's line on the memory, the refusal's line or None) for a run of ``cfg`` on ``ranks``
    ranks, ``local`` of them on this node; ``label`` names its spheres in the lines."""
    est = of_config(cfg, ranks, n_file)
    avail, where = available(local, env)
    need = est.node(local)
    share = f"{local} ranks of this node {words(need)}, " if local > 1 else ""
    other = f", {words(est.other())} on another" if ranks > 1 else ""
    line = (f"memory: {what(cfg, n_file, label)} (+ bed) on {ranks} rank(s) need about {words(est.rank0())} on rank 0 "
            f"(its peak at {est.peak_phase()}){other}; {share}available "
            f"{words(avail) if avail is not None else '?'} ({where})")
    if avail is None or need <= avail:
        return line, None
    refuse = (f"{what(cfg, n_file, label)} on {ranks} rank(s) need about {words(est.rank0())} on rank 0 (its peak at "
              f"{est.peak_phase()}){f' and {words(need)} for the {local} ranks of this node' if local > 1 else ''}"
              f", more than the {words(avail)} available ({where}): run fewer spheres, more nodes, or give the "
              f"job more memory ({ENV} sets what is available; off: no check)")
    return line, refuse


def check(cfg, net, n_file=None, env=None, label=None):
    """Refuse a run that cannot fit, on every rank, before any work (collective); the log's line.

    ``n_file``: the spheres of a pile read from a file (``initial_count``; a restart's state file),
    None for a pour; ``label`` names them in the lines.

    Raises
    ------
    MemoryRefused
        On every rank (agreed), with the first refusing rank's line: the spheres, the estimate and
        what is available.
    """
    from .threads import ranks_on_node
    if n_file is not None and n_file < 0:
        return "memory: not estimated (the initial file's spheres are counted as it is read)"
    try:
        line, refuse = verdict(cfg, net.size, min(ranks_on_node(), net.size), n_file, env, label)
    except MemoryRefused as e:
        line, refuse = "", str(e)
    net.agree(refuse, MemoryRefused)
    return line
