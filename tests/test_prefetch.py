"""``kernels.prefetch.prefetch_row``: one prefetch instruction in jitted code, nothing in Python."""
import numpy as np
from numba import njit

from mpdem.kernels.prefetch import prefetch_row


@njit
def _sum_ahead(a, ahead):
    s = 0.0
    n = a.shape[0]
    for i in range(n):
        prefetch_row(a, min(i + ahead, n - 1))
        s += a[i, 0]
    return s


@njit
def _first_ahead(b):
    prefetch_row(b, np.uint64(len(b) - 1))
    return b[0]


def test_prefetch_row_emits_a_prefetch_and_changes_no_value():
    a = np.arange(30.0).reshape(10, 3)
    assert _sum_ahead(a, 4) == a[:, 0].sum()
    asm = _sum_ahead.inspect_asm(_sum_ahead.signatures[0])
    # x86 or arm
    assert "prefetcht0" in asm or "prfm" in asm
    # a 1-d array and an unsigned index
    b = np.arange(5, dtype=np.int32)
    assert _first_ahead(b) == 0
    asm = _first_ahead.inspect_asm(_first_ahead.signatures[0])
    assert "prefetcht0" in asm or "prfm" in asm


def test_prefetch_row_is_a_no_op_in_python():
    a = np.zeros((3, 3))
    assert prefetch_row(a, 2) is None
    assert _sum_ahead.py_func(a + 1.0, 1) == 3.0
