"""Freed large arrays are returned to the system (mpdem.memory)."""
import numpy as np

from mpdem.bench import rss_now
from mpdem.memory import THRESHOLD, return_freed_memory


def test_a_freed_array_of_a_size_freed_before_leaves_the_resident_set():
    # below glibc's largest dynamic threshold (32 MiB): without the fixed threshold the
    # second array comes from the heap once the first is freed, and the heap keeps its pages
    assert return_freed_memory()
    size = 16 * THRESHOLD
    for _ in range(2):
        a = np.ones(size // 8)
        held = rss_now()
        del a
        assert held - rss_now() > 0.9 * size
