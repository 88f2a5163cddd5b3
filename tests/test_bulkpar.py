"""analysis.bulkpar: the bulk measurement spread over ranks, here on one process (``ALONE``; the ranks:
mpi_tests/test_bulk_end.py): the rows in any order give the same bits, and ``bulk.bulk_summary``'s (its
sums exact as well), and the median found by its bits is numpy's."""
import json
import os

import numpy as np
import pytest

from mpdem import planes
from mpdem.analysis import bulk, bulkpar
from mpdem.io import packing

DEV = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "analysis", "results", "paper",
                   "runs", "dev")
PILES = {0.0: "mu0_eps0.88_kn2e5_phi0.13_s1_max_steps1e7", 0.5: "mu0.5_eps0.88_kn2e5_phi0.13_s1_max_steps1e7"}


@pytest.mark.parametrize("mu", [0.0, 0.5])
@pytest.mark.parametrize("rule", ["force", "count"])
def test_any_row_order_gives_the_same_bits_and_bulk_summary_s_numbers(mu, rule):
    a, _ = packing.read(os.path.join(DEV, PILES[mu], "packing.npz"))
    x, fixed, ids = a["x"], a["fixed"], a["id"]
    got = [bulkpar.measure(x[p], fixed[p], ids[p], len(x), 10.0, 10.0, mu, rattlers=rule)
           for p in (np.arange(len(x)), np.random.default_rng(3).permutation(len(x)))]
    assert json.dumps(got[0], sort_keys=True) == json.dumps(got[1], sort_keys=True)
    old = bulk.bulk_summary(x, fixed, 10.0, 10.0, mu, rattlers=rule)    # its sums exact too: the same bits
    assert json.dumps(old, sort_keys=True) == json.dumps(got[0], sort_keys=True)
    assert got[0]["n_bulk"] > 500 and 0.0 < got[0]["overlap_median"] < got[0]["overlap_max"]


def test_the_wall_holds_a_frictionless_pile_as_in_bulk_summary():
    # test_gravity_measures' simple cubic pile on the wall (bed.wall), no bed sphere under it: held with the
    # plane as a support, every sphere lost without it (the summary then says why)
    from helpers import simple_cubic
    x, L = simple_cubic(4, 8, 1.0 - 1e-4)
    fixed, ids = np.zeros(len(x), np.uint8), np.arange(len(x))
    held = bulkpar.measure(x, fixed, ids, len(x), L, L, 0.0, rattlers="force", planes=(planes.WALL,))
    assert held["rattler_fraction"] == 0.0 and held["z_no_rattlers"] == held["z"] and "rattler_note" not in held
    lost = bulkpar.measure(x, fixed, ids, len(x), L, L, 0.0, rattlers="force")
    assert lost["rattler_fraction"] == 1.0 and lost["rattler_note"] == bulk.NO_BACKBONE


def test_a_sphere_flown_far_above_the_pile_changes_nothing_but_the_top():
    # its profile bins travel only where filled: 2e5 empty bins between cost nothing
    a, _ = packing.read(os.path.join(DEV, PILES[0.5], "packing.npz"))
    x = np.concatenate([a["x"], [[5.0, 5.0, 1e5]]])
    fixed, ids = np.r_[a["fixed"], 0], np.r_[a["id"], a["id"].max() + 1]
    got = bulkpar.measure(x, fixed, ids, len(x), 10.0, 10.0, 0.5, rattlers="count")
    old = bulk.bulk_summary(x, fixed, 10.0, 10.0, 0.5, rattlers="count")
    assert got == old and got["h"] < 30


@pytest.mark.parametrize("n", [1, 2, 7, 1000, 1001])
def test_the_median_by_bits_is_numpy_s(n):
    v = np.random.default_rng(n).lognormal(-9.0, 2.0, n)
    v[: n // 3] = v[n // 2]                                   # ties
    v[n // 3: n // 2] *= -1.0                                 # negatives order below (overlaps have none)
    assert bulkpar._median(bulkpar.ALONE, v) == float(np.median(v))
    assert bulkpar._median(bulkpar.ALONE, np.zeros(0)) == 0.0
