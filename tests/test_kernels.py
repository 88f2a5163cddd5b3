"""Neighbour lists against brute force; exact sums; integration details."""
import math
import random

import numpy as np
import pytest

from mpdem.kernels.exactsum import add_exact, new_accumulator, to_float
from mpdem.kernels.neighbours import build_neighbours


def brute_pairs(x, L_x, L_y, rc):
    d = x[:, None, :] - x[None, :, :]
    d[..., 0] -= L_x * np.round(d[..., 0] / L_x)
    d[..., 1] -= L_y * np.round(d[..., 1] / L_y)
    r2 = np.einsum("ijk,ijk->ij", d, d)
    np.fill_diagonal(r2, np.inf)
    return r2 < rc * rc


@pytest.mark.parametrize("L_x,L_y,zspan", [(10.0, 10.0, 8.0), (3.0, 2.5, 5.0), (7.3, 4.1, 2000.0)])
def test_neighbour_lists_match_brute_force(L_x, L_y, zspan):
    g = np.random.default_rng(5)
    n = 600
    x = np.column_stack([g.random(n) * L_x, g.random(n) * L_y, g.random(n) ** 4 * zspan])
    fixed = (g.random(n) < 0.2).astype(np.uint8)
    ids = g.permutation(n).astype(np.int64) * 3 + 11
    rc = 1.2
    start = np.zeros(n + 1, np.int64)
    lst = np.zeros(10, np.int32)
    need = build_neighbours(x, n, n, fixed, ids, L_x, L_y, rc, start, lst, 3)
    lst = np.zeros(need, np.int32)
    assert build_neighbours(x, n, n, fixed, ids, L_x, L_y, rc, start, lst, 5) == need
    ref = brute_pairs(x, L_x, L_y, rc)
    for i in range(n):
        got = lst[start[i]:start[i + 1]]
        if fixed[i]:
            assert len(got) == 0
            continue
        assert sorted(got.tolist()) == sorted(np.flatnonzero(ref[i]).tolist())
        assert np.all(np.diff(ids[got]) > 0)


def test_exact_sum_is_order_independent_and_correctly_rounded():
    from fractions import Fraction
    r = random.Random(1)
    vals = [r.uniform(0, 1) * 10 ** r.randint(-300, 300) for _ in range(2000)]
    vals += [5e-324, 1e-310, 1.7e308 / 4096, 0.0, -3.5, 2.5]
    exact = sum(Fraction(v) for v in vals)
    acc = new_accumulator()
    for v in vals:
        add_exact(acc, v)
    assert to_float(acc) == float(exact)
    # split over "ranks" in another order: same limbs, same bits
    r.shuffle(vals)
    parts = [new_accumulator() for _ in range(3)]
    for k, v in enumerate(vals):
        add_exact(parts[k % 3], v)
    total = parts[0] + parts[1] + parts[2]
    assert to_float(total) == float(exact)
    assert math.fsum(vals) == float(exact)


def test_select_contacts_takes_the_right_segments():
    from mpdem.state import select_contacts
    counts = np.array([2, 0, 3, 1, 0])
    partner = np.array([10, 11, 20, 21, 22, 30])
    ds = np.arange(18.0).reshape(6, 3)
    c, p, d = select_contacts(counts, partner, ds, [3, 0, 1, 2])
    assert c.tolist() == [1, 2, 0, 3]
    assert p.tolist() == [30, 10, 11, 20, 21, 22]
    assert np.array_equal(d, ds[[5, 0, 1, 2, 3, 4]])
    c, p, d = select_contacts(counts, partner, ds, [])
    assert len(c) == len(p) == len(d) == 0
