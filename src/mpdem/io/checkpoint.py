"""State files (HDF5): the only module that reads or writes them.

Format ``mpdem-state`` version 2. One file holds the whole state, written
collectively by all ranks (h5py ``mpio`` driver), rows in rank order:

``/particles/{id, x, v, omega, f, torque, fixed}``
    per-particle datasets, shapes (n,) or (n, 3); rows in any order, the
    ``id`` column says which particle a row is;
``/contacts/{count, partner, ds}``
    contact slots: per-row counts (n,), aligned with ``/particles``, then the
    flat partner ids (M,) and tangential displacements Delta s (M, 3) of the
    rows in row order;
``/wall/wall_ds`` (runs with ``bed.wall`` only)
    Delta s of each particle's contact with the wall plane (n, 3) [d],
    aligned with ``/particles``;
``/pairs/{id_i, id_j, delta, F_n, F_t, ds_i}`` (snapshots only)
    every contact once: ids, overlap [d], normal force (signed, along the
    unit vector from j to i) [m g], tangential force on i (P, 3) [m g],
    Delta s of i (P, 3) [d];
The groups, datasets, dtypes and widths are the stored fields of the
registry (``state.FIELDS``, in its order), under the names the State and the
state-array dicts use;
attributes: ``format``, ``version``, ``kind`` (checkpoint, snapshot, final),
``step``, ``time``, ``n``, ``n_mobile``, ``n_bed``, ``L_x``, ``L_y``,
``config`` (the resolved TOML), ``checksum_<group>`` and the run's own
continuation values (stop-rule samples, counters; see ``simulation``).

Checksums are order independent (a sum over rows of a 64-bit hash of the
row, mod 2^64), so any number of ranks can write a file and any number can
verify it while reading its own share of rows.

Files are written under ``<name>.tmp`` and renamed when complete, so a
crash never leaves a half-written file under a real name.
"""
from __future__ import annotations

import errno
import hashlib
import os
import re
import signal
import sys

import h5py
import numpy as np

from .. import state
from ..errors import StateFileError, WriteError
from ..parallel import channel
from . import diskspace
from .rundir import starts_with

FORMAT = "mpdem-state"
VERSION = 2
KINDS = ("checkpoint", "snapshot", "final")
# the groups and datasets of the format, from the field registry (``state.FIELDS``), in its order
GROUPS = state.groups()
PARTICLE_FIELDS = GROUPS["particles"]
CONTACT_FIELDS = GROUPS["contacts"]
PAIR_FIELDS = GROUPS["pairs"]
WALL_FIELDS = GROUPS["wall"]
DTYPES = {f.name: f.dtype for f in state.stored()}
WIDE = {f.name for f in state.stored() if f.width > 1}
# the row-length dataset of each group: its first field with rows of its own (contacts: partner)
ROWS_OF = {g: next((n for n in names if state.FIELD[n].per != state.PARTICLE), names[0])
           for g, names in GROUPS.items()}
# the salt of each group's row hashes
SALTS = {"particles": 1, "contacts": 2, "pairs": 3, "wall": 4}

# Test hook: SIGKILL this process in the middle of its k-th checkpoint write.
KILL_ENV = "MPDEM_TEST_KILL_IN_WRITE"
_writes = 0
# Test hook: "k" or "k:rank": the k-th state-file write of this process (of that MPI rank only) fails
# in its rows with ENOSPC, as on a full disk (a file system that fills up under one rank's writes)
FAIL_ENV = "MPDEM_TEST_FAIL_WRITE"
_all_writes = 0
# HDF5 handles of files the library failed to close (a disk that filled up during the write): kept
# alive, for freeing one crashes the library; the command line then ends the process without its
# clean-up (``held``)
HELD = []
# seconds a rank whose write failed waits for the others to reach the agreement before ending every rank
AGREE_SECONDS = 20.0
_said_funnel = False       # rank 0 said once that it writes for every rank (no mpio)


# -- order-independent checksums --
_C1, _C2, _C3 = np.uint64(0x9E3779B97F4A7C15), np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)


def _mix(z):
    """splitmix64 finaliser on a uint64 array (wrapping arithmetic)."""
    z = z + _C1
    z = (z ^ (z >> np.uint64(30))) * _C2
    z = (z ^ (z >> np.uint64(27))) * _C3
    return z ^ (z >> np.uint64(31))


def _words(a, n):
    """Columns of 64-bit words of an array with n rows."""
    a = np.ascontiguousarray(a)
    if n == 0:
        return []
    if a.dtype.itemsize != 8:
        a = a.astype(np.int64)
    return a.reshape(n, -1).view(np.uint64).T


def _row_hashes(cols, n, salt):
    with np.errstate(over="ignore"):
        h = np.full(n, np.uint64(salt), np.uint64)
        for c in cols:
            for w in _words(c, n):
                h = _mix(h ^ w)
        return h


def _hashed(local, g):
    """The columns of group ``g`` that its checksum hashes per row, and the row count.

    Particles: every per-particle field of the particle rows (``/particles`` and
    ``/contacts/count``); contact slots: the owner's id, then the per-contact
    fields; an optional per-particle group (``/wall``): the id, then its
    fields; pairs: their fields.
    """
    kinds = {state.FIELD[n].per for n in GROUPS[g]}
    if "id" in GROUPS[g]:
        return [local[f.name] for f in state.stored(per=state.PARTICLE) if f.optional is None], len(local["id"])
    if state.CONTACT in kinds:
        owner = np.repeat(np.asarray(local["id"], np.int64), np.asarray(local["count"], np.int64))
        return [owner] + [local[f.name] for f in state.stored(g, state.CONTACT)], len(owner)
    if kinds == {state.PARTICLE}:
        return [local["id"]] + [local[n] for n in GROUPS[g]], len(local["id"])
    return [local[n] for n in GROUPS[g]], len(local[ROWS_OF[g]])


def present(local):
    """The groups whose data ``local`` holds (its row-length dataset), in file order."""
    return [g for g in GROUPS if ROWS_OF[g] in local]


def checksums(local):
    """Partial checksums of this rank's rows, one uint64 per group present.

    Particles hash (id, fields, count) per row; contact slots hash
    (owner id, partner, Delta s) per slot; the wall (id, wall_ds) per row;
    pairs hash all their columns.
    """
    out = {g: _row_hashes(*_hashed(local, g), SALTS[g]) for g in present(local)}
    return {g: np.sum(h, dtype=np.uint64) for g, h in out.items()}


def digest(arrays):
    """SHA-256 over the state sorted by id (positions, velocities, angular
    velocities, forces, torques, contact slots, and the wall histories of a
    run with the wall), as hex.

    Hashes, for every stored per-particle and per-contact field in registry
    order (optional ones when present): its name, its shape and its bytes
    (little endian; narrow integers as int64).
    """
    h = hashlib.sha256()
    for f in _digest_fields(arrays):
        a = _digest_bytes(f, arrays[f.name])
        h.update(f.name.encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _digest_fields(arrays):
    """The fields ``digest`` hashes, in its order: the stored per-particle and per-contact ones (optional
    ones when ``arrays`` has them)."""
    return [f for f in state.stored() if f.per != state.PAIR and not (f.optional and f.name not in arrays)]


def _digest_bytes(f, a):
    """Field ``f``'s array ``a`` as ``digest`` hashes it: its stored dtype (narrow integers as int64),
    little endian, contiguous."""
    a = np.ascontiguousarray(a)
    if f.array_dtype != np.dtype(f.dtype):
        a = a.astype(f.array_dtype)
    return a.astype(a.dtype.newbyteorder("<"), copy=False)


# rows of the whole state that ``digest_parts`` brings to rank 0 at a time (about this many)
DIGEST_CHUNK = 1 << 18
# ranges of the ids' first histogram that cuts the ids into chunks (``digest_parts``), and of each
# later cut of a range that holds more than a chunk
DIGEST_BINS, DIGEST_REFINE = 1 << 15, 64


def digest_parts(part, net, chunk=DIGEST_CHUNK):
    """``digest`` of the whole state held by the ranks of ``net`` in parts, without holding it anywhere
    (collective): the hex digest on rank 0, None elsewhere.

    ``part`` is this rank's rows sorted by id (``gather_state``); together the parts hold each row once.
    The ids are cut into chunks of at most ``chunk`` rows (histograms of ranges of ids, summed exactly:
    ``_id_chunks``); for each field in ``digest``'s order, each chunk's rows come to rank 0 with
    their ids (and slot counts), where they are put in id order and hashed, so rank 0 holds a chunk at a
    time and every other rank sends each of its rows once a field. Every rank must hold the same fields.
    """
    if not net.parallel:
        return digest(part)
    ids = np.asarray(part["id"], np.int64)
    n = len(ids)
    counts = np.asarray(part["count"], np.int64) if "count" in part else np.zeros(n, np.int64)
    N, M = (int(v) for v in net.sum_int(np.array([n, int(counts.sum())], np.int64)))
    cuts = _id_chunks(ids, net, N, chunk)
    # each cut's first row here (the last cut is past every id)
    rows = np.append(np.searchsorted(ids, np.array(cuts[:-1], np.int64)), n).astype(np.int64)
    slot0 = np.concatenate([[0], np.cumsum(counts)])
    h = hashlib.sha256() if net.rank == 0 else None
    for f in _digest_fields(part):
        a = _digest_bytes(f, part[f.name])
        per_row = f.per == state.PARTICLE
        if h is not None:
            h.update(f.name.encode())
            h.update(str(((N if per_row else M),) + a.shape[1:]).encode())
        for k in range(len(cuts) - 1):
            r0, r1 = int(rows[k]), int(rows[k + 1])
            piece = a[r0:r1] if per_row else a[slot0[r0]:slot0[r1]]
            got = net.gather((ids[r0:r1], counts[r0:r1], piece), root=0)
            if h is not None:
                h.update(np.ascontiguousarray(_in_id_order(got, per_row)).tobytes())
    return h.hexdigest() if h is not None else None


def _id_chunks(ids, net, N, chunk):
    """Increasing id bounds c_0 < c_1 < ... (one more than the chunks): chunk k holds the ids in
    [c_k, c_k+1), at most ``chunk`` rows of the ``N`` the ranks hold (``ids``: this rank's, sorted).
    Collective; the same bounds on every rank.

    The ids' range (exact integers, gathered) is cut into ``DIGEST_BINS`` equal ranges whose counts are
    summed exactly; a range of more than ``chunk`` rows (ids clustered, an outlier far away) is cut again
    into ``DIGEST_REFINE`` ranges, until none is; chunks are runs of whole ranges."""
    if N == 0:
        return [0]
    ends = [e for e in net.allgather((int(ids[0]), int(ids[-1])) if len(ids) else None) if e is not None]
    lo, hi = min(e[0] for e in ends), max(e[1] for e in ends)
    edges, counts, parts = [lo, hi + 1], [N], DIGEST_BINS
    while True:
        dense = [k for k, c in enumerate(counts) if c > chunk and edges[k + 1] - edges[k] > 1]
        if not dense:
            break
        cut, local = {}, []
        for k in dense:
            a, b = edges[k], edges[k + 1]
            w = -(-(b - a) // parts)                # ids a range, rounded up (integers: no overflow)
            sub = list(range(a, b, w)) + [b]
            cut[k] = sub
            inside = ids[np.searchsorted(ids, a):np.searchsorted(ids, b - 1, side="right")]
            local.append(np.bincount((inside - a) // w, minlength=len(sub) - 1).astype(np.int64))
        total = np.asarray(net.sum_int(np.concatenate(local)))
        new_edges, new_counts, at = [], [], 0
        for k in range(len(counts)):
            if k in cut:
                m = len(cut[k]) - 1
                new_edges += cut[k][:-1]
                new_counts += [int(c) for c in total[at:at + m]]
                at += m
            else:
                new_edges.append(edges[k])
                new_counts.append(counts[k])
        edges, counts, parts = new_edges + [hi + 1], new_counts, DIGEST_REFINE
    bounds, run = [lo], 0
    for k, c in enumerate(counts):
        if run and run + c > chunk:
            bounds.append(edges[k])
            run = 0
        run += c
    bounds.append(hi + 1)
    return bounds


def _in_id_order(got, per_row):
    """The pieces of one chunk (each rank's ids, slot counts and field piece) as one array, its rows (or
    its rows' slots, in row order) in id order."""
    ids = np.concatenate([g[0] for g in got])
    pieces = np.concatenate([g[2] for g in got])
    order = np.argsort(ids, kind="stable")
    if per_row:
        return pieces[order]
    counts = np.concatenate([g[1] for g in got])
    start = np.concatenate([[0], np.cumsum(counts)])[:-1]
    c = counts[order]
    # each row's slots, rows in id order: start of its slots, repeated, plus the slot's place in its row
    first = np.repeat(start[order], c)
    within = np.arange(int(c.sum())) - np.repeat(np.cumsum(c) - c, c)
    return pieces[first + within]


def gather_state(st):
    """The owned particles of a State as id-sorted arrays (this rank's rows): every
    stored field (optional ones when the State has them)."""
    flags = st.flags()
    fields = [f for f in state.stored() if f.per != state.PAIR and state.optional_in(f, flags)]
    return st.select(st.id_order(), fields)


def parallel_hdf5():
    """Whether h5py has the ``mpio`` driver (built on parallel HDF5); without it, several ranks write
    their state files through rank 0 (``write``) and read them each on its own."""
    return bool(h5py.get_config().mpi)


def _not_a_file(path):
    """Why ``path`` cannot be a state file, said before HDF5 tries it (its own words for these are long),
    or None."""
    if os.path.isdir(path):
        return f"{path}: a directory, not a state file (a finished run's is {os.path.join(path, 'final.h5')})"
    if not os.path.exists(path):
        return f"{path}: no such file"
    return None


def _open(path, mode, net):
    """The file, opened by every rank of ``net`` with parallel HDF5 (one rank, or no ``mpio``: plainly)."""
    if net.parallel and parallel_hdf5():
        return h5py.File(path, mode, driver="mpio", comm=net.comm)
    return h5py.File(path, mode)


# -- writing --
def write(path, local, attrs, net=None):
    """Write a state file collectively: each rank gives its own rows.

    Parameters
    ----------
    path : str
        Final name (the same on every rank); written as ``path + '.tmp'``
        and renamed by rank 0 when every rank has finished.
    local : dict of arrays
        This rank's rows: PARTICLE_FIELDS, ``count`` (rows,), ``partner``
        (M,), ``ds`` (M, 3); optionally ``wall_ds`` (rows, 3) and the PAIR_FIELDS
        of a snapshot.
    attrs : dict
        Attributes, identical on every rank.
    net : parallel.Channel, mpi4py communicator or None

    Raises
    ------
    WriteError
        On every rank together (``agreed``), whatever rank failed: the file named, why (no space, a
        quota, an I/O error), the space it needed and the space there was; nothing is left under
        ``path``, and the partial ``path + '.tmp'`` is removed. A rank whose write failed while
        another is still inside the parallel HDF5 library gives it ``AGREE_SECONDS``, then ends every
        rank with that line (MPI_Abort): a failed write never hangs the job.
    """
    net = channel(net)
    if net.parallel and not parallel_hdf5():
        return _write_through_root(path, local, attrs, net)
    _write(path, local, attrs, net, net.size)


def _write_through_root(path, local, attrs, net):
    """``write`` without parallel HDF5: every rank's rows go to rank 0, which writes the file alone.

    The rows are concatenated in rank order, as the ranks' slices of a collective write, and the
    file says the same number of ranks: the same file, bit for bit. Rank 0 says so once per process.
    """
    global _said_funnel
    parts = net.gather({k: np.asarray(v) for k, v in local.items()})
    err = None
    if net.rank == 0:
        if not _said_funnel:
            print("mpdem: h5py has no MPI driver (serial HDF5): state files are written through rank 0",
                  file=sys.stderr, flush=True)
            _said_funnel = True
        width = {k: state.FIELD[k].width if k in state.FIELD else 1 for k in parts[0]}
        whole = {k: np.concatenate([p[k].reshape((-1, width[k]) if width[k] > 1 else (-1,)) for p in parts])
                 for k in parts[0]}
        try:
            _write(path, whole, attrs, channel(None), net.size)
        except WriteError as e:
            err = str(e)
    net.agree(err, _agreed)


def _agreed(message):
    return WriteError(message, agreed=True)


def bytes_needed(groups, total, attrs):
    """An upper bound of a state file's size [bytes]: its data, its attributes and HDF5's own.

    ``groups`` are the groups written, ``total`` their row counts (in the order of ``groups``).
    """
    data = 0
    for g, rows in zip(groups, total):
        for name in GROUPS[g]:
            fd = state.FIELD[name]
            n = total[0] if fd.per == state.PARTICLE else rows
            data += int(n) * fd.width * np.dtype(fd.dtype).itemsize
    text = sum(len(str(v)) + len(k) + 64 for k, v in attrs.items())
    # HDF5's superblock, object headers and B-trees: under 1 kB a dataset, 2 kB a group (measured)
    return data + text + 8192 + 2048 * len(groups) + 1024 * sum(len(GROUPS[g]) for g in groups)


def held():
    """Whether this process holds an HDF5 handle that its clean-up at exit would crash on (``HELD``)."""
    return bool(HELD)


class _Watchdog:
    """Ends every rank with ``line`` if this rank, whose write failed, waits more than ``seconds`` for the
    others: they may be inside a collective of the parallel HDF5 library that it can no longer join."""

    def __init__(self, net, tmp, seconds):
        import threading
        self.net, self.tmp, self.line = net, tmp, None
        self.timer = threading.Timer(seconds, self._fire)
        self.timer.daemon = True

    def arm(self, line):
        if self.line is None:
            self.line = line
            if self.net.parallel:
                self.timer.start()

    def disarm(self):
        self.timer.cancel()

    def _fire(self):
        diskspace.remove(self.tmp)
        sys.stderr.write(f"mpdem: error: {self.line} (rank {self.net.rank}; the other ranks did not answer "
                         f"within {AGREE_SECONDS:g} s: ending every rank)\n")
        sys.stderr.flush()
        self.net.abort(1)
        os._exit(1)


def _why(e):
    """An exception of a failed write, in a few words: the system's reason where HDF5's long message has one."""
    if isinstance(e, OSError) and e.strerror:
        return e.strerror
    text = str(e).strip()
    m = re.search(r"error message = '([^']+)'", text)
    if m:
        return m.group(1)
    return (text.splitlines() or [type(e).__name__])[0][:200]


def _fail_hook():
    """The test hook's verdict: raise ENOSPC in this rank's raw data writes of this state file."""
    global _all_writes
    _all_writes += 1
    want = os.environ.get(FAIL_ENV)
    if not want:
        return False
    k, _, rank = want.partition(":")
    me = os.environ.get("OMPI_COMM_WORLD_RANK") or os.environ.get("PMI_RANK") or "0"
    return int(k) == _all_writes and (not rank or rank == me)


def _write(path, local, attrs, net, ranks):
    """The collective write of ``write`` by the ranks of ``net``; the file says ``ranks`` wrote it.

    In three phases, so that a failure on some ranks cannot leave the others waiting in a collective
    they alone reached: the layout (the file, its attributes, groups and datasets: collective, all
    in the metadata cache), the rows (independent writes, each rank its own), and the close
    (collective: every rank calls it, whatever failed). Then every rank learns every rank's outcome.
    """
    global _writes
    groups = present(local)
    lengths = np.array([len(local[ROWS_OF[g]]) for g in groups], np.int64)
    all_len = np.array(net.allgather(lengths)).reshape(-1, len(groups))
    rank = net.rank
    start, total = all_len[:rank].sum(axis=0), all_len.sum(axis=0)
    sums = net.sum_u64([checksums(local)[g] for g in groups])
    tmp = f"{path}.tmp"
    _writes += attrs.get("kind") == "checkpoint"
    fail = _fail_hook()
    need = bytes_needed(groups, total, attrs)
    # the disk space first, before the HDF5 library writes a byte (its handle of a file it could not
    # flush is unusable: see HELD)
    where = os.path.dirname(os.path.abspath(path))
    free = diskspace.free_bytes(where)
    net.agree(diskspace.reserve(tmp, need, name=path) if rank == 0 else None, _agreed)
    dog = _Watchdog(net, tmp, AGREE_SECONDS)

    def said(why):
        now = diskspace.free_bytes(where)
        full = "; the file system is full" if now is not None and now < need else ""
        return (f"cannot write {path}: {why}{full} (it needs {diskspace.words(need)}; "
                f"{diskspace.words(free)} were free)")

    def failed(e):
        dog.arm(said(_why(e)))

    f = None
    try:
        f = _open(tmp, "w", net)
        sets = _layout(f, attrs, groups, total, sums, ranks)
    except (OSError, RuntimeError, ValueError) as e:
        failed(e)
    if f is not None and dog.line is None:
        try:
            for gi, g in enumerate(groups):
                for name in GROUPS[g]:
                    fd = state.FIELD[name]
                    # per-particle fields follow the particle rows (group 0), slots and pairs their own
                    k = 0 if fd.per == state.PARTICLE else gi
                    a, b = int(start[k]), int(start[k] + lengths[k])
                    if b > a:
                        if fail:
                            raise OSError(errno.ENOSPC, f"test hook {FAIL_ENV}: {os.strerror(errno.ENOSPC)}")
                        ds = sets[g, name]
                        ds[a:b] = np.asarray(local[name]).reshape((b - a,) + ds.shape[1:])
        except (OSError, RuntimeError, ValueError) as e:
            failed(e)
        if os.environ.get(KILL_ENV) == str(_writes) and attrs.get("kind") == "checkpoint":
            f.flush()
            os.kill(os.getpid(), signal.SIGKILL)
    if f is not None:
        try:
            f.close()
        except (OSError, RuntimeError, ValueError) as e:
            failed(e)
            # the library could not flush the file: closing or freeing its handle again crashes it
            HELD.append(f)
    # every rank's outcome, in plain MPI (no HDF5 collective is open any more on a rank that got here)
    errs = [e for e in net.allgather(dog.line) if e]
    dog.disarm()
    if not errs and rank == 0:
        try:
            fd = os.open(tmp, os.O_RDONLY)
            os.fsync(fd)
            os.close(fd)
            os.replace(tmp, path)
        except OSError as e:
            errs = [said(e.strerror)]
    errs = [e for e in net.allgather(errs[0] if errs else None) if e]
    if errs:
        if rank == 0:
            diskspace.remove(tmp)
        raise WriteError(errs[0] + "; nothing was written under that name", agreed=True)


def _layout(f, attrs, groups, total, sums, ranks):
    """The attributes, groups and datasets of a state file (collective); {(group, name): dataset}."""
    f.attrs["format"] = FORMAT
    f.attrs["version"] = VERSION
    for k, v in attrs.items():
        f.attrs[k] = v
    # how many ranks wrote the file is a fact of this write, not of the caller
    f.attrs["ranks"] = ranks
    out = {}
    for gi, g in enumerate(groups):
        grp = f.create_group(g)
        f.attrs[f"checksum_{g}"] = sums[gi]
        for name in GROUPS[g]:
            fd = state.FIELD[name]
            k = 0 if fd.per == state.PARTICLE else gi
            out[g, name] = grp.create_dataset(name, shape=(int(total[k]),) + fd.shape, dtype=fd.dtype)
    return out


# -- reading --
def _attrs(f):
    return {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}


def _check_layout(f, path):
    """Format, version and dataset shapes; returns the groups present."""
    if f.attrs.get("format") != FORMAT:
        return None, f"{path}: not an mpdem state file (format = {f.attrs.get('format')!r})"
    ver = f.attrs.get("version")
    if ver != VERSION:
        return None, (f"{path}: format version {ver} is not supported "
                      f"(this mpdem reads version {VERSION})")
    groups = [g for g in GROUPS if g in f] if "particles" in f else []
    for g in ("particles", "contacts"):
        if g not in f:
            return None, f"{path}: missing group /{g}"
    for g in groups:
        n = None
        for name in GROUPS[g]:
            if name not in f[g]:
                return None, f"{path}: missing dataset /{g}/{name}"
            m = f[g][name].shape[0]
            if g != "particles" and state.FIELD[name].per == state.PARTICLE:
                # aligned with the particle rows
                if m != f["particles"]["id"].shape[0]:
                    return None, f"{path}: /{g}/{name} has {m} rows, /particles {f['particles']['id'].shape[0]}"
                continue
            if n is not None and m != n:
                return None, f"{path}: datasets of /{g} have different lengths"
            n = m
        if f"checksum_{g}" not in f.attrs:
            return None, f"{path}: no checksum for /{g}"
    return groups, None


def read(path, net=None, pairs=False):
    """Read this rank's share of a state file (any rank count) and verify it.

    Rank r of P reads particle rows [r n / P, (r+1) n / P) and their contact
    slots (and, with ``pairs``, the same share of the pair list). Every
    rank raises the same StateFileError if the file is unusable: not HDF5,
    another format or version, missing datasets, or a checksum mismatch.

    Parameters
    ----------
    path : str
    net : parallel.Channel, mpi4py communicator or None
    pairs : bool
        Read the pair list of a snapshot too.

    Returns
    -------
    local : dict of arrays (this rank's rows, file order)
    attrs : dict
    """
    net = channel(net)
    # agreed before the open, which is collective under parallel HDF5: no rank waits in it alone
    net.agree(_not_a_file(path), StateFileError)
    err, f = None, None
    try:
        f = _open(path, "r", net)
    except (OSError, ValueError) as e:
        err = f"{path}: cannot open as HDF5 ({e})"
    net.agree(err, StateFileError)
    with f:
        groups, err = _check_layout(f, path)
        net.agree(err, StateFileError)
        attrs = _attrs(f)
        P, r = net.size, net.rank
        local, err = {}, None
        try:
            n = f["particles"]["id"].shape[0]
            lo, hi = r * n // P, (r + 1) * n // P
            for fd in state.stored(per=state.PARTICLE):
                if fd.group in groups:
                    local[fd.name] = f[fd.group][fd.name][lo:hi].astype(fd.array_dtype, copy=False)
        except (OSError, KeyError, ValueError) as e:
            err = f"{path}: unreadable ({e}); the file is truncated or damaged"
        net.agree(err, StateFileError)
        # every rank takes part in this gather: no rank may have left early
        before = np.array(net.allgather(int(local["count"].sum())), np.int64)
        try:
            a = int(before[:r].sum())
            b = a + int(before[r])
            if b > f["contacts"][ROWS_OF["contacts"]].shape[0]:
                raise OSError("contact counts exceed the slot datasets")
            for fd in state.stored(per=state.CONTACT):
                local[fd.name] = f[fd.group][fd.name][a:b]
            if pairs and "pairs" in groups:
                m = f["pairs"][ROWS_OF["pairs"]].shape[0]
                for name in PAIR_FIELDS:
                    local[name] = f["pairs"][name][r * m // P:(r + 1) * m // P]
        except (OSError, KeyError, ValueError) as e:
            err = f"{path}: unreadable ({e}); the file is truncated or damaged"
        net.agree(err, StateFileError)
    have = present(local)
    sums = net.sum_u64([checksums(local)[g] for g in have])
    bad = [g for g, s in zip(have, sums) if int(s) != int(attrs[f"checksum_{g}"])]
    if bad:
        raise StateFileError(f"{path}: checksum mismatch in /{', /'.join(bad)}; the file is damaged")
    return local, attrs


def sort_by_id(local):
    """Rows (with their contact slots and pairs) in ascending id order."""
    out = state.select_rows(local, np.argsort(local["id"], kind="stable"))
    if "id_i" in local:
        po = np.lexsort((local["id_j"], local["id_i"]))
        out.update({k: local[k][po] for k in PAIR_FIELDS})
    return out


def read_state(path, pairs=False):
    """Read a whole state file on one process, rows sorted by id: (arrays, attrs)."""
    local, attrs = read(path, None, pairs=pairs)
    return sort_by_id(local), attrs


def read_attrs(path):
    """The attributes of a state file, after the layout checks (no data read)."""
    err = _not_a_file(path)
    if err:
        raise StateFileError(err)
    try:
        f = h5py.File(path, "r")
    except (OSError, ValueError) as e:
        raise StateFileError(f"{path}: cannot open as HDF5 ({e})") from None
    with f:
        _, err = _check_layout(f, path)
        if err:
            raise StateFileError(err)
        return _attrs(f)


def is_state_file(path):
    """True if ``path`` looks like HDF5 (by its signature)."""
    return starts_with(path, b"\x89HDF\r\n\x1a\n")
