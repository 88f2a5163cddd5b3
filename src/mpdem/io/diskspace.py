"""Disk room for the files a run writes: free space, reservations, and removing partial files.

A state file's writer reserves its size on disk before the HDF5 library writes a byte
(``reserve``): a full file system or a full quota (which ``statvfs`` cannot see) is then found
while nothing has been written, and said in one line with the space needed and free. A restart
looks for room the same way before it starts (``room_in``).
"""
from __future__ import annotations

import errno
import os


def free_bytes(directory):
    """Bytes an unprivileged writer may still use in ``directory``'s file system (None if unknown)."""
    try:
        st = os.statvfs(directory)
    except OSError:
        return None
    return st.f_bavail * st.f_frsize


def words(b):
    """Bytes in words: ``57 kB``, ``3.2 MB``, ``80 GB``."""
    if b is None:
        return "?"
    for unit, size in (("GB", 1e9), ("MB", 1e6)):
        if b >= size:
            return f"{b / size:.3g} {unit}"
    return f"{b / 1e3:.3g} kB"


def _fallocate(fd, size):
    """Reserve ``size`` bytes of disk for file ``fd`` (Linux fallocate(2), which counts against quotas too).

    Raises OSError (ENOSPC, EDQUOT) when the file system or the quota has no room; returns False where
    the system or the file system cannot reserve (then only the free space was looked at).
    """
    import ctypes
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        call = libc.fallocate
    except (OSError, AttributeError):
        return False
    call.argtypes = (ctypes.c_int, ctypes.c_int, ctypes.c_int64, ctypes.c_int64)
    if call(fd, 0, 0, size) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
        raise OSError(err, os.strerror(err))
    return False


def reserve(path, need, name=None):
    """Make ``path`` and reserve ``need`` bytes of disk for it: None, or why not, in words (naming
    ``name``, default ``path``).

    The state file's writer then creates the file in its place (which frees the reservation for
    it): a full disk or quota is found here, before the HDF5 library writes anything, and a
    file system that fills up in between fails the write itself.
    """
    name = name or path
    free = free_bytes(os.path.dirname(os.path.abspath(path)) or ".")
    try:
        fd = os.open(path, os.O_CREAT | os.O_WRONLY | os.O_TRUNC, 0o644)
    except OSError as e:
        return f"cannot write {name}: {e.strerror}"
    why = None
    try:
        if not _fallocate(fd, need) and free is not None and free < need:
            why = os.strerror(errno.ENOSPC)
    except OSError as e:
        why = e.strerror
    finally:
        os.close(fd)
    if why:
        remove(path)
        return f"cannot write {name}: {why} (it needs {words(need)}; its file system has {words(free)} free)"
    return None


def room_in(directory, need, what):
    """None if ``directory`` has room for ``need`` more bytes (reserved and given back), else why not,
    naming ``what`` would not fit."""
    probe = os.path.join(directory, ".room.tmp")
    why = reserve(probe, need, name=what)
    remove(probe)
    return why


def remove(path):
    """Remove ``path`` if it is there (a partial file); never raises."""
    try:
        os.remove(path)
    except OSError:
        pass
