"""Freed large arrays go back to the system at once.

The engine frees its history and scratch arrays at each list rebuild (the
history is in the compact slots meanwhile) and allocates them anew. glibc's
malloc raises its mmap threshold to the size of a freed mapping, so later
arrays of that size would come from the heap, which keeps freed memory: the
resident size would then hold the old and the new arrays side by side. A
fixed threshold keeps every array above it in its own mapping, returned when
freed. Process-wide, set once; elsewhere than glibc nothing is done.
"""
import ctypes
import ctypes.util

M_MMAP_THRESHOLD = -3        # glibc's mallopt parameter number
THRESHOLD = 1 << 20          # arrays above 1 MiB get their own mapping [bytes]
_done = False


def return_freed_memory():
    """Fix glibc's mmap threshold (once per process); False where that is not possible."""
    global _done
    if _done:
        return True
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        _done = bool(libc.mallopt(M_MMAP_THRESHOLD, THRESHOLD))
    except (OSError, AttributeError):
        _done = False
    return _done
