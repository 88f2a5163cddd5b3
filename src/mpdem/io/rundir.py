"""A run directory: its layout, file numbering and atomic text files.

::

    RUN/config.toml              resolved config (rewritten by a restart with --set)
    RUN/log.txt, RUN/thermo.csv  log and thermo table (continued by restarts)
    RUN/bed.txt                  the bed as a text table
    RUN/checkpoints/ckpt-NNNNN.h5    the newest output.checkpoint_keep checkpoints
    RUN/snapshots/snap-NNNNN.h5 (+ .xmf, series.xmf)   snapshots for analysis
    RUN/final.h5 (+ .xmf), RUN/summary.json            the end of the run

Everything here runs on one rank (rank 0 decides, or every rank reads the
same small files); collective reading is ``checkpoint``'s, and which file a
restart starts from is ``restart``'s.
"""
from __future__ import annotations

import contextlib
import csv
import glob
import io
import math
import os
import re

import numpy as np

from ..errors import WriteError
from .diskspace import remove


CKPT_DIR, SNAP_DIR = "checkpoints", "snapshots"
CONTACTS_DIR = "contacts"   # contact networks beside their state files (network.contacts_path)


@contextlib.contextmanager
def atomic(path, mode="w"):
    """A file object for ``path``, written as ``path.tmp`` and renamed when the block ends: the one way
    mpdem writes a file other than a state file (``checkpoint.write``), an appended log or a lock.

    Raises
    ------
    WriteError
        Naming ``path`` and the reason, when the file cannot be made or written (no such directory,
        no permission, a full disk): the partial ``path.tmp`` is removed and nothing is left under
        ``path``. Any other error in the block removes the partial file too.
    """
    tmp = f"{path}.tmp"
    try:
        fh = open(tmp, mode)
    except OSError as e:
        raise WriteError(f"cannot write {path}: {e.strerror or e}") from None
    try:
        with fh:
            yield fh
        os.replace(tmp, path)
    except OSError as e:
        remove(tmp)
        raise WriteError(f"cannot write {path}: {e.strerror or e}; nothing was written under that name") from None
    except BaseException:
        remove(tmp)
        raise


def write_atomic(path, chunks):
    """Write a string, or an iterable of strings, to ``path`` via ``path.tmp`` and a rename (``atomic``)."""
    with atomic(path) as fh:
        fh.writelines([chunks] if isinstance(chunks, str) else chunks)


def writable(out, probe=65536):
    """None if run directory ``out`` can be made and written (a ``probe``-byte file is
    written and removed), else why not, in a few words."""
    try:
        os.makedirs(out, exist_ok=True)
        path = os.path.join(out, f".mpdem-write-test-{os.getpid()}")
        try:
            with open(path, "wb") as fh:
                fh.write(b"\0" * probe)
                fh.flush()
                os.fsync(fh.fileno())
        finally:
            if os.path.exists(path):
                os.remove(path)
    except OSError as e:
        return f"cannot be created or written ({e.strerror or e})"
    return None


LOCK = ".lock"


class RunLock:
    """One writer per run directory: an exclusive ``flock`` on RUN/.lock, held by one process for the
    life of a run or restart and released on any exit (the kernel drops it when the process dies).

    ``acquire`` returns None, or the reason it cannot: the holder's host, pid and start time, as the
    holder wrote them into the file. A file left by a process that died (its lock gone with it) is
    taken over; ``taken_over`` then names the old holder.
    """

    def __init__(self, run):
        self.path = os.path.join(run, LOCK)
        self.fh = None
        self.taken_over = None

    def acquire(self):
        import fcntl
        import socket
        import time
        fh = open(self.path, "a+")
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.seek(0)
            holder = fh.read().strip() or "another process"
            fh.close()
            return f"in use by {holder} ({self.path}); one run or restart at a time writes a run directory"
        except OSError as e:        # a file system without flock: go on unlocked, and say so
            fh.close()
            self.taken_over = f"not locked: {self.path}: {e.strerror or e} (no flock on this file system)"
            return None
        fh.seek(0)
        old = fh.read().strip()
        if old:
            self.taken_over = f"taking over the lock of {old}, which has ended ({self.path})"
        fh.seek(0)
        fh.truncate()
        try:                        # unbuffered: nothing is left to fail again at the release
            os.write(fh.fileno(), f"pid {os.getpid()} on {socket.gethostname()} since "
                                  f"{time.strftime('%Y-%m-%d %H:%M:%S')}\n".encode())
        except OSError:             # a full disk: the lock holds without the holder's name
            pass
        self.fh = fh
        return None

    def release(self):
        """Give the lock up (the file stays empty: no holder)."""
        if self.fh is not None:
            import fcntl
            self.fh.seek(0)
            self.fh.truncate()
            self.fh.flush()
            fcntl.flock(self.fh.fileno(), fcntl.LOCK_UN)
            self.fh.close()
            self.fh = None


def json_safe(obj):
    """``obj`` with nan and inf as None (JSON has no such numbers) and numpy scalars and arrays as
    Python numbers and lists."""
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        obj = obj.item()
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [json_safe(v) for v in obj]
    return obj


def write_json(path, obj):
    """``obj`` as JSON (``json_safe``, indented) in ``path``, written atomically: the one JSON writer."""
    import json
    write_atomic(path, json.dumps(json_safe(obj), indent=1) + "\n")


def starts_with(path, magic):
    """True if the file ``path`` begins with the bytes ``magic`` (a format's signature)."""
    try:
        with open(path, "rb") as fh:
            return fh.read(len(magic)) == magic
    except OSError:
        return False


def _cell(v):
    """One CSV cell: full precision, empty for nan or None (not available)."""
    if v is None:
        return ""
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (float, np.floating)):
        return repr(float(v)) if math.isfinite(v) else ""
    if isinstance(v, np.integer):
        return str(int(v))
    return str(v)


def write_csv(path, header, rows):
    """Rows as CSV with a header line, written atomically (``write_atomic``)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows([[_cell(v) for v in row] for row in rows])
    write_atomic(path, buf.getvalue())


def checkpoint_path(run, k):
    return os.path.join(run, CKPT_DIR, f"ckpt-{k:05d}.h5")


def snapshot_path(run, k):
    return os.path.join(run, SNAP_DIR, f"snap-{k:05d}.h5")


def final_path(run):
    return os.path.join(run, "final.h5")


def _numbered(run, sub, prefix):
    out = []
    for p in glob.glob(os.path.join(run, sub, f"{prefix}-*.h5")):
        m = re.fullmatch(rf"{prefix}-(\d+)\.h5", os.path.basename(p))
        if m:
            out.append((int(m.group(1)), p))
    return sorted(out)


def checkpoints(run):
    """[(number, path)] of the run's checkpoints, oldest first (no .tmp files)."""
    return _numbered(run, CKPT_DIR, "ckpt")


def snapshots(run):
    return _numbered(run, SNAP_DIR, "snap")


def prune(run, keep):
    """Delete all but the newest ``keep`` checkpoints and any stale .tmp files."""
    for _, p in checkpoints(run)[:-keep]:
        os.remove(p)
    for p in glob.glob(os.path.join(run, CKPT_DIR, "*.tmp")):
        os.remove(p)


def clear(run):
    """Remove the outputs of an earlier run in ``run`` (a new run with --force)."""
    for p in ([p for _, p in checkpoints(run) + snapshots(run)]
              + glob.glob(os.path.join(run, CKPT_DIR, "*.tmp")) + glob.glob(os.path.join(run, SNAP_DIR, "*"))
              + glob.glob(os.path.join(run, SNAP_DIR, CONTACTS_DIR, "*"))
              + glob.glob(os.path.join(run, CONTACTS_DIR, "*"))
              + [os.path.join(run, n) for n in ("final.h5", "final.xmf", "summary.json", "thermo.csv", "packing.npz")]):
        if os.path.isfile(p):
            os.remove(p)


def truncate_thermo(path, step):
    """Drop thermo rows after ``step`` (written after the checkpoint a restart starts from)."""
    if not os.path.exists(path):
        return
    with open(path) as fh:
        lines = fh.readlines()
    width = lines[0].count(",") if lines else 0
    # whole rows only (a kill may have cut the last one), up to the checkpoint's step
    keep = lines[:1] + [ln for ln in lines[1:] if ln.endswith("\n") and ln.count(",") == width
                        and ln.split(",", 1)[0].isdigit() and int(ln.split(",", 1)[0]) <= step]
    write_atomic(path, keep)
