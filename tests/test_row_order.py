"""The rows' order in memory (``Engine._sort_rows``): columns of cells, z-major inside,
and no bit of a trajectory depends on it."""
import dataclasses
import math

import numpy as np

from helpers import make_engine
from mpdem.build import insert_random, rng
from mpdem.engine.order import SORT_COLUMN
from mpdem.io.checkpoint import digest, gather_state


def _wide_pour(n=900, L=45.0, seed=11):
    """A thin layer in a box two or three columns of cells wide."""
    return insert_random(rng(seed, 1), n, L, L, 0.5, 0.5 + n * (math.pi / 6) / (L * L * 0.3)), L


def test_rows_are_ordered_by_columns_of_cells_then_z_and_the_order_changes_no_bit():
    x, L = _wide_pour()
    g = np.random.default_rng(2)
    v = g.standard_normal(x.shape)
    runs = []
    for sort_every in (1, 10 ** 9):
        eng = make_engine(x, v.copy(), L=L, mu=0.5, gravity=1.0, gamma_t=10.0)
        eng.phys = dataclasses.replace(eng.phys, floor=True)
        eng.lists.sort_every = sort_every
        eng.advance(3000)
        assert eng.n_rebuilds > 3
        runs.append(digest(gather_state(eng.state)))
        if sort_every == 1:
            eng.rebuild()
            s = eng.state
            c = 1.0 + eng.phys.skin
            nx = int(L // c)
            assert nx > 2 * SORT_COLUMN
            ix = np.minimum(np.floor(s.x[:s.n_own, 0] * (nx / L)), nx - 1).astype(int)
            iy = np.minimum(np.floor(s.x[:s.n_own, 1] * (nx / L)), nx - 1).astype(int)
            # the rebuild sorted the rows: each column's rows in one run, in column order, z-major inside
            ncol = round(nx / SORT_COLUMN)
            column = (iy * ncol // nx) * ncol + ix * ncol // nx
            assert len(set(column.tolist())) == ncol * ncol and np.all(np.diff(column) >= 0)
            # columns about equally wide: none of fewer cells than SORT_COLUMN / 2
            assert min(np.bincount(np.arange(nx) * ncol // nx)) >= SORT_COLUMN / 2
            iz = np.floor((s.x[:s.n_own, 2] - s.x[:s.n_own, 2].min()) / c)
            for k in range(ncol * ncol):
                assert np.all(np.diff(iz[column == k]) >= 0)
    # never sorted after the first rebuild: the same bits
    assert runs[0] == runs[1]
