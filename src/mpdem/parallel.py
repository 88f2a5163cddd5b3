"""Every collective and exchange of the run, on numpy buffers (ARCHITECTURE.md).

``Channel`` wraps the communicator handed down by the CLI (or None for one
rank without MPI) and times every call into ``seconds``. ``decomp`` decides
what moves where and calls this module to move it:

- exact reductions (``max_many``, ``sum_int``) into buffers kept between
  calls, so the per-step allreduce allocates nothing;
- ``alltoall_counts`` and ``exchange``: counts to everyone, then contiguous
  arrays only to the ranks that have something to receive (migration and
  halo, at rebuilds);
- ``GhostPlan``: the per-step refresh of ghost x, v, omega through
  persistent requests on buffers built at the rebuild;
- pickled ``allgather``, ``alltoall``, ``gather`` and ``bcast``, for the few
  exchanges of whole state sets that run once per run or per checkpoint;
- the agreement on errors (``agree``, ``on_root``), ``barrier`` and ``abort``.

``world()`` starts MPI for the CLI. No other module but ``checkpoint`` (its
parallel HDF5 open) touches the communicator: they take a Channel.
mpi4py is imported when a Channel is made for a communicator, so one-rank
runs without MPI never import it.
"""
from __future__ import annotations

import atexit
import os
import sys
import time
import weakref

import numpy as np

from .errors import MpdemError
from .kernels.calls import Bound
from .kernels.ghosts import gather_rows, scatter_rows

# point-to-point tags; every exchange is completed before the next one starts
TAG_GHOSTS = 31


def world(exit_status=1):
    """A Channel on MPI's COMM_WORLD, after checking that the launcher and mpi4py agree.

    A process started by an mpiexec of several processes that sees a world
    of one (mpi4py built for another MPI) prints why and exits with
    ``exit_status``: each such process is a world of its own, so an abort
    would stop only itself.
    """
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    launched = os.environ.get("OMPI_COMM_WORLD_SIZE") or os.environ.get("PMI_SIZE")
    if launched and int(launched) > 1 and comm.Get_size() == 1:
        lib = MPI.Get_library_version().strip(chr(0)).splitlines()[0]
        sys.stderr.write(
            f"mpdem: started by an mpiexec of {launched} processes, but mpi4py sees a world of "
            f"size 1: mpi4py was built for a different MPI ({lib}).\n"
            f"       Use the mpiexec of the MPI that mpi4py was built with (the .venv/bin/mpiexec "
            f"wrapper), or rebuild mpi4py (tools/setup.sh).\n")
        sys.exit(exit_status)
    _abort_on_uncaught(comm)
    return Channel(comm)


def _abort_on_uncaught(comm):
    """An exception that no caller catches, on any rank of several, ends every rank (MPI_Abort)
    after printing it: library use (a script or notebook under mpiexec) must not leave the other
    ranks waiting in a collective for ever. Installed once per process."""
    if comm.Get_size() < 2 or getattr(sys.excepthook, "_mpdem", False):
        return
    previous = sys.excepthook

    def hook(kind, value, tb):
        sys.stderr.write(f"mpdem: uncaught exception on rank {comm.Get_rank()} of {comm.Get_size()}; "
                         f"aborting every rank\n")
        previous(kind, value, tb)
        sys.stderr.flush()
        comm.Abort(1)
    hook._mpdem = True
    sys.excepthook = hook


def _everywhere(e):
    """``e``, raised on every rank: an MpdemError is marked ``agreed`` (said once, no MPI_Abort)."""
    if isinstance(e, MpdemError):
        e.agreed = True
    return e


def payload(obj):
    """The bytes a pickled exchange of ``obj`` carries, near enough: arrays' bytes, 8 a number or a
    string's length, summed through dicts, lists and tuples (pickle's framing left out)."""
    if isinstance(obj, np.ndarray):
        return obj.nbytes
    if isinstance(obj, dict):
        return sum(payload(v) for v in obj.values())
    if isinstance(obj, (list, tuple)):
        return sum(payload(v) for v in obj)
    if isinstance(obj, (str, bytes)):
        return len(obj)
    return 8


def channel(net):
    """``net`` as a Channel: a Channel itself, or one made for a communicator or None."""
    return net if isinstance(net, Channel) else Channel(net)


class Channel:
    """Timed MPI calls of one communicator.

    Parameters
    ----------
    comm : mpi4py communicator or None
        None (or a one-rank communicator) makes every call local.

    Attributes
    ----------
    seconds : float
        Wall seconds spent in communication so far [s].
    sent : dict of str -> int
        Bytes this rank has sent so far, by kind: "reductions" (its buffer of each allreduce),
        "exchanges" (the rebuild's counts and rows), "refresh" (the ghost refresh of every step), and
        "pickled" (what the pickled exchanges carry: the arrays' bytes and 8 a number, ``payload``).
    """

    def __init__(self, comm=None):
        self.comm = comm
        self.size = 1 if comm is None else comm.Get_size()
        self.rank = 0 if comm is None else comm.Get_rank()
        self.mpi = None
        if comm is not None:
            from mpi4py import MPI
            self.mpi = MPI
        self.seconds = 0.0
        self.sent = dict.fromkeys(("reductions", "exchanges", "refresh", "pickled"), 0)
        self._max = {}      # length -> (buffer, read-only view)
        self._sum = {}      # shape -> (buffer, read-only view)

    @property
    def parallel(self):
        return self.size > 1

    # -- exact reductions (order independent, so rank-count independent) --
    def max_many(self, values):
        """Element-wise global max; NaN counts as +inf.

        Parameters
        ----------
        values : (k,) float64 array or sequence of numbers

        Returns
        -------
        (k,) float64, read-only
            A buffer reused by the next call of the same length: unpack or copy it.
        """
        k = len(values)
        if k not in self._max:
            buf = np.zeros(k)
            view = buf.view()
            view.flags.writeable = False
            self._max[k] = (buf, view)
        buf, view = self._max[k]
        # NaN -> +inf, so that a NaN on any rank wins the max on every rank (fmin takes the
        # number of a NaN and a number, and leaves every number, -0.0 included, as it is)
        np.fmin(values, np.inf, out=buf)
        self._allreduce(buf, self.mpi.MAX if self.parallel else None)
        return view

    def sum_int(self, arr):
        """Exact global sum of an integer array (fixed-point accumulators, counts).

        Parameters
        ----------
        arr : array_like, any shape, cast to int64

        Returns
        -------
        int64 array of ``arr``'s shape, read-only
            A buffer reused by the next call of the same shape: use or copy it.
        """
        a = np.asarray(arr)
        if a.shape not in self._sum:
            buf = np.zeros(a.shape, np.int64)
            view = buf.view()
            view.flags.writeable = False
            self._sum[a.shape] = (buf, view)
        buf, view = self._sum[a.shape]
        np.copyto(buf, a, casting="unsafe")
        self._allreduce(buf, self.mpi.SUM if self.parallel else None)
        return view

    def _allreduce(self, buf, op):
        """``buf`` reduced in place over the ranks with ``op`` (timed); nothing on one rank."""
        if self.parallel:
            t = time.perf_counter()
            self.comm.Allreduce(self.mpi.IN_PLACE, buf, op=op)
            self.seconds += time.perf_counter() - t
            self.sent["reductions"] += buf.nbytes

    # -- contiguous exchanges (rebuilds) --
    def alltoall_counts(self, counts):
        """Every rank's counts for this rank.

        Parameters
        ----------
        counts : (P, k) int64
            Row r: what this rank sends to rank r.

        Returns
        -------
        (P, k) int64
            Row s: what rank s sends to this rank.
        """
        counts = np.ascontiguousarray(counts, np.int64)
        if not self.parallel:
            return counts.copy()
        out = np.empty_like(counts)
        t = time.perf_counter()
        self.comm.Alltoall(counts, out)
        self.seconds += time.perf_counter() - t
        self.sent["exchanges"] += counts.nbytes
        return out

    def exchange(self, sends, recvs, tag):
        """Send and receive contiguous arrays with some peers, and wait for all.

        Both sides must agree on the peers and on each array's size (exchange
        counts first); arrays of size 0 are skipped on both sides.

        Parameters
        ----------
        sends : dict of int -> list of C-contiguous arrays
            Arrays for each destination rank, in a fixed order.
        recvs : dict of int -> list of C-contiguous writable arrays
            Arrays to fill from each source rank, in the same order.
        tag : int
            Tags ``tag, tag + 1, ...`` are used for the arrays of a peer.
        """
        if not sends and not recvs:
            return
        t = time.perf_counter()
        reqs = []
        for peer, arrays in recvs.items():
            reqs += [self.comm.Irecv(a, source=peer, tag=tag + k) for k, a in enumerate(arrays) if a.size]
        for peer, arrays in sends.items():
            reqs += [self.comm.Isend(a, dest=peer, tag=tag + k) for k, a in enumerate(arrays) if a.size]
            self.sent["exchanges"] += sum(a.nbytes for a in arrays)
        self.mpi.Request.Waitall(reqs)
        self.seconds += time.perf_counter() - t

    def split(self, color, key):
        """A Channel of the ranks that give the same ``color``, ranked by ``key`` (a collective of this
        Channel; the ranks of a column of domains, ``decomp``). On one rank, this Channel."""
        if not self.parallel:
            return self
        t = time.perf_counter()
        comm = self.comm.Split(int(color), int(key))
        self.seconds += time.perf_counter() - t
        return Channel(comm)

    def ghost_plan(self, send_rows, recv_rows, n_fields=3, alloc=None):
        """A ``GhostPlan`` on this communicator (see there); freed at exit if still live."""
        plan = GhostPlan(self, send_rows, recv_rows, n_fields, alloc)
        _LIVE_PLANS.add(plan)
        return plan

    # -- pickled objects (once per run or per checkpoint) --
    def allgather(self, obj):
        """List of every rank's ``obj``, in rank order."""
        if not self.parallel:
            return [obj]
        t = time.perf_counter()
        self.sent["pickled"] += payload(obj) * (self.size - 1)
        out = self.comm.allgather(obj)
        self.seconds += time.perf_counter() - t
        return out

    def alltoall(self, objs):
        """``objs[r]`` goes to rank r; returns what each rank sent here."""
        if not self.parallel:
            return list(objs)
        t = time.perf_counter()
        self.sent["pickled"] += sum(payload(o) for r, o in enumerate(objs) if r != self.rank)
        out = self.comm.alltoall(objs)
        self.seconds += time.perf_counter() - t
        return out

    def gather(self, obj, root=0):
        """List of every rank's ``obj`` on ``root``, None elsewhere."""
        if not self.parallel:
            return [obj]
        t = time.perf_counter()
        self.sent["pickled"] += payload(obj) if self.rank != root else 0
        out = self.comm.gather(obj, root=root)
        self.seconds += time.perf_counter() - t
        return out

    def bcast(self, obj, root=0):
        """``root``'s ``obj`` on every rank."""
        if not self.parallel:
            return obj
        t = time.perf_counter()
        if self.rank == root:
            self.sent["pickled"] += payload(obj) * (self.size - 1)
        out = self.comm.bcast(obj, root=root)
        self.seconds += time.perf_counter() - t
        return out

    def sum_u64(self, values):
        """Element-wise global sum of unsigned 64-bit integers (checksums; wraps modulo 2**64).

        Parameters
        ----------
        values : sequence of int

        Returns
        -------
        (k,) uint64, a new array
        """
        a = np.array(values, np.uint64)
        if self.parallel:
            t = time.perf_counter()
            self.comm.Allreduce(self.mpi.IN_PLACE, a, op=self.mpi.SUM)
            self.seconds += time.perf_counter() - t
            self.sent["reductions"] += a.nbytes
        return a

    def barrier(self):
        """Wait until every rank is here."""
        if self.parallel:
            t = time.perf_counter()
            self.comm.Barrier()
            self.seconds += time.perf_counter() - t

    # -- errors: the same outcome on every rank --
    def agree(self, err, exc):
        """Raise ``exc(message)`` on every rank if any rank has one (collective).

        Parameters
        ----------
        err : str or None
            This rank's error message, or None.
        exc : type of Exception
            Raised with the first rank's message (an MpdemError is marked ``agreed``: the command
            line says it once).
        """
        errs = [e for e in self.allgather(err) if e]
        if errs:
            raise _everywhere(exc(errs[0]))

    def on_root(self, fn, *args, catch=()):
        """``fn(*args)`` on rank 0 and its result on every rank (collective).

        An exception of a type in ``catch`` raised on rank 0 is raised on
        every rank; others stay rank 0's (the CLI aborts on them).
        """
        res = None
        if self.rank == 0:
            try:
                res = fn(*args)
            except catch as e:
                res = e
        res = self.bcast(res)
        if catch and isinstance(res, catch):
            raise _everywhere(res)
        return res

    def abort(self, status):
        """Stop every rank with exit ``status`` (MPI_Abort); returns on one rank."""
        if self.parallel:
            self.comm.Abort(status)


class GhostPlan:
    """Persistent exchange of some fields of the halo rows, run at every step.

    Built at a rebuild: per peer, the rows sent (gathered into a contiguous
    send buffer) and the ghost rows received (scattered from a contiguous
    receive buffer), with one persistent send or receive request each. A run
    then allocates no array: gather, start, wait, scatter.

    Parameters
    ----------
    channel : Channel
        Communicator, and the clock the refresh is timed into.
    send_rows : dict of int -> (m,) int
        Owned rows sent to each peer, in the order the peer stores them.
    recv_rows : dict of int -> (int, int)
        (first ghost row, number of rows) received from each peer.
    n_fields : int
        Fields per run, each a (cap, 3) float64 array (x, v, omega: 3).
    alloc : callable, optional
        ``alloc(name, size)`` -> (size,) float64 array for the buffers "send" and "recv" (default: new
        numpy arrays); the GPU engine gives them from page-locked memory it keeps between plans.
    """

    def __init__(self, channel, send_rows, recv_rows, n_fields=3, alloc=None):
        self.channel = channel
        comm = channel.comm
        n_send = sum(len(r) for r in send_rows.values())
        n_recv = sum(m for _, m in recv_rows.values())
        # one flat buffer each way; peer p's part is a contiguous (n_fields, m, 3) block
        alloc = alloc or _new_buffer
        self.send_buf = alloc("send", n_fields * 3 * n_send)
        self.recv_buf = alloc("recv", n_fields * 3 * n_recv)
        self.sends, self.recvs, self.requests = [], [], []
        self._gather, self._scatter = Bound(gather_rows), Bound(scatter_rows)
        self._startall, self._waitall = channel.mpi.Prequest.Startall, channel.mpi.Request.Waitall
        off = 0
        for peer in sorted(send_rows):
            rows = np.ascontiguousarray(send_rows[peer], np.intp)
            m = len(rows)
            if m:
                block = self.send_buf[off:off + n_fields * 3 * m].reshape(n_fields, m, 3)
                self.sends.append((rows, block))
                self.requests.append(comm.Send_init(block, dest=peer, tag=TAG_GHOSTS))
                off += block.size
        off = 0
        for peer in sorted(recv_rows):
            start, m = recv_rows[peer]
            if m:
                block = self.recv_buf[off:off + n_fields * 3 * m].reshape(n_fields, m, 3)
                self.recvs.append((start, block))
                self.requests.append(comm.Recv_init(block, source=peer, tag=TAG_GHOSTS))
                off += block.size

    @property
    def peers(self):
        """Number of messages per run (sends plus receives)."""
        return len(self.requests)

    def run(self, fields):
        """Copy the owners' rows of ``fields`` into the ghost rows on every rank.

        Parameters
        ----------
        fields : sequence of (cap, 3) float64
            E.g. (x, v, omega), the same on every rank and at every run.
        """
        t = time.perf_counter()
        fields = tuple(fields)
        # one kernel pass per peer (numpy's take and slice copies, one per field, took twice as long)
        for rows, block in self.sends:
            self._gather(fields, rows, block)
        self.channel.seconds += time.perf_counter() - t
        self.exchange()
        t = time.perf_counter()
        for start, block in self.recvs:
            self._scatter(fields, start, block)
        self.channel.seconds += time.perf_counter() - t

    def exchange(self):
        """Send ``send_buf`` and receive ``recv_buf`` as they stand: the messages of ``run`` alone, for an
        engine that packs and unpacks the rows itself (the GPU's, by ``layout``)."""
        t = time.perf_counter()
        if self.requests:
            self._startall(self.requests)
            self._waitall(self.requests)
        self.channel.seconds += time.perf_counter() - t
        self.channel.sent["refresh"] += self.send_buf.nbytes

    def layout(self):
        """Where each row's fields sit in the flat buffers: a sent row's field f at ``at + f * stride`` of
        ``send_buf`` (its peer's block is (fields, m, 3), field-major), and likewise a ghost row's in
        ``recv_buf``.

        Returns
        -------
        send_rows, send_at, send_stride : (S,) int64
            The owned rows sent, peer after peer (a row sent to two peers twice), their first element and
            the stride between their fields.
        recv_rows, recv_at, recv_stride : (R,) int64
            The ghost rows received (ascending: peer after peer), the same.
        """
        sent = _places([rows for rows, _ in self.sends], [block for _, block in self.sends])
        got = _places([start + np.arange(block.shape[1]) for start, block in self.recvs],
                      [block for _, block in self.recvs])
        return sent + got

    def free(self):
        """Release the persistent requests (the plan cannot run afterwards)."""
        for r in self.requests:
            r.Free()
        self.requests, self.sends, self.recvs = [], [], []
        _LIVE_PLANS.discard(self)


def _new_buffer(name, size):
    """``GhostPlan``'s default ``alloc``: a new (size,) float64 array."""
    return np.empty(size)


def _places(rows, blocks):
    """``GhostPlan.layout``'s (rows, at, stride) of consecutive blocks of a flat buffer, each (fields, m, 3)."""
    at, stride, off = [], [], 0
    for block in blocks:
        m = block.shape[1]
        at.append(off + 3 * np.arange(m))
        stride.append(np.full(m, 3 * m))
        off += block.size
    return tuple(np.concatenate(p).astype(np.int64) if p else np.zeros(0, np.int64) for p in (rows, at, stride))


# plans not yet freed: their persistent requests are released at exit, before mpi4py finalizes MPI
# (MPICH reports each one left: "freeing inactive persistent request")
_LIVE_PLANS = weakref.WeakSet()


@atexit.register
def _free_live_plans():
    for plan in list(_LIVE_PLANS):
        plan.free()
