"""The grid of domains without MPI: ranks and boxes, periodic reach, and the choice of a grid (``domains``,
``decomp.Domain``'s decisions). That grids give the one-rank bits is mpi_tests/test_grid.py's."""
import math

import numpy as np
import pytest

from mpdem import config, domains
from mpdem.decomp import Domain
from mpdem.errors import ConfigError


def _domain(grid, rank, L=(6.0, 5.0), zb=None, r_list=1.2):
    """Rank ``rank``'s view of ``grid`` on an L_x x L_y box, the columns' slab bounds ``zb``."""
    d = Domain(None, r_list=r_list)
    d.size, d.rank = math.prod(grid), rank
    d._set_grid(grid)
    d._set_box(*L)
    if zb is not None:
        d.zb[:] = zb
    return d


def test_ranks_and_coordinates_go_both_ways_with_a_column_s_slabs_consecutive():
    grid = (3, 2, 4)
    ix, iy, iz = domains.coords(np.arange(24), grid)
    assert np.array_equal((ix * 2 + iy) * 4 + iz, np.arange(24))
    assert list(iz[:4]) == [0, 1, 2, 3] and ix[-1] == 2 and iy[-1] == 1
    b = domains.axis_bounds(0.1 * 3, 3)
    assert b[0] == 0.0 and b[-1] == 0.1 * 3 and np.all(np.diff(b) > 0)


def test_periodic_membership_is_an_image_of_the_point_in_the_interval():
    rng = np.random.default_rng(2)
    L = 7.0
    for _ in range(300):
        a = rng.uniform(0, L)
        lo, hi = a - rng.uniform(0, 3), a + rng.uniform(0, 3)
        x = rng.uniform(0, L, 50)
        want = np.array([any(lo <= v + k * L < hi for k in (-1, 0, 1)) for v in x])
        assert np.array_equal(domains.in_periodic(x, lo, hi, L), want)
        b0, b1 = sorted(rng.uniform(0, L, 2))
        assert domains.overlap_periodic(b0, b1, lo, hi, L) == any(
            b0 < hi + k * L and lo + k * L < b1 for k in (-1, 0, 1))


def test_owners_follow_the_columns_and_each_column_s_own_slabs():
    zb = np.array([[-np.inf, 1.0, np.inf], [-np.inf, 2.0, np.inf], [-np.inf, 3.0, np.inf], [-np.inf, 4.0, np.inf]])
    d = _domain((2, 2, 2), 0, L=(6.0, 5.0), zb=zb)
    x = np.array([[0.1, 0.1, 0.5], [0.1, 0.1, 1.5], [0.1, 4.9, 1.5], [3.0, 0.0, 3.5], [5.99, 2.5, 4.0]])
    assert list(d.owner_of(x)) == [0, 1, 2, 5, 7]
    assert list(d.column_of(x)) == [0, 0, 1, 2, 3]


@pytest.mark.parametrize("grid", [(2, 1, 1), (1, 3, 1), (2, 2, 1), (2, 1, 3), (3, 2, 2), (4, 1, 1)])
def test_reach_holds_every_rank_a_row_within_r_list_is_sent_to(grid):
    """A brute force over random positions and slab bounds: every rank that has a row of rank s within
    r_list of its box (in x and y through the periodic faces) is in s's reach, and s in its."""
    rng = np.random.default_rng(sum(grid))
    L = (6.0, 5.0)
    P = math.prod(grid)
    for _ in range(20):
        inner = np.sort(rng.uniform(0, 6, (grid[0] * grid[1], grid[2] - 1)), axis=1)
        zb = np.column_stack([np.full(len(inner), -np.inf), inner, np.full(len(inner), np.inf)])
        views = [_domain(grid, r, L, zb) for r in range(P)]
        x = np.column_stack([rng.uniform(0, L[0], 400), rng.uniform(0, L[1], 400), rng.uniform(-2, 8, 400)])
        owner = views[0].owner_of(x)
        lo, hi = views[0].boxes()
        for s in range(P):
            to, _ = views[s].reach()
            mine = x[owner == s]
            for r in range(P):
                near = np.ones(len(mine), bool)
                for axis in range(3):
                    shifts = (-L[axis], 0.0, L[axis]) if axis < 2 else (0.0,)
                    v = mine[:, axis]
                    near &= np.any([(lo[r, axis] - 1.2 <= v + k) & (v + k < hi[r, axis] + 1.2) for k in shifts], axis=0)
                sent = views[s]._in_reach(mine, lo[r], hi[r]) if r != s else near
                assert np.array_equal(sent, near)
                if r != s and near.any():
                    assert r in to and s in views[r].reach()[1]


def test_a_grid_must_have_the_ranks_domains():
    assert domains.check([2, 1, 2], 4) == (2, 1, 2)
    with pytest.raises(ConfigError, match=r"decomp.grid = \[2, 2, 2\]: 8 domains for 4 ranks"):
        domains.check([2, 2, 2], 4)
    with pytest.raises(ConfigError, match="decomp.grid"):
        config.load(None, ["run.max_steps=1", "decomp.grid=[2, 2]"])


def test_the_chosen_grid_keeps_a_tall_pile_in_slabs_and_cuts_a_wide_one_into_columns():
    # the paper's pile (20 d x 20 d, some 44 d of settled spheres): slabs at 2 and 4 ranks
    assert domains.choose(2, 20.0, 20.0, 44.0, 1.2) == (1, 1, 2)
    assert domains.choose(4, 20.0, 20.0, 44.0, 1.2) == (1, 1, 4)
    # a bed of 7 x 7 tiles (140 d x 140 d, as tall): columns, and no slabs
    assert domains.choose(16, 140.0, 140.0, 44.0, 1.2) == (4, 4, 1)
    assert domains.choose(2, 140.0, 20.0, 44.0, 1.2) == (2, 1, 1)
    # a silo 10 d wide and 400 d tall: slabs only
    assert domains.choose(16, 10.0, 10.0, 400.0, 1.2) == (1, 1, 16)
    # whatever it picks is never worse than the slabs or any other grid of the ranks
    for P in (6, 12):
        g = domains.choose(P, 60.0, 30.0, 20.0, 1.2)
        assert all(domains.ghost_volume(g, 60.0, 30.0, 20.0, 1.2) <= domains.ghost_volume(h, 60.0, 30.0, 20.0, 1.2)
                   for h in [(a, b, P // (a * b)) for a in domains.divisors(P) for b in domains.divisors(P // a)])
    # a pour's loose start is costed at its settled height
    assert domains.settled_height(20000, 20.0, 20.0, 300.0) == pytest.approx(20000 * math.pi / 6 / (400 * 0.6))
    assert domains.settled_height(20000, 20.0, 20.0, 10.0) == 10.0


def test_one_rank_chooses_one_domain_and_a_config_grid_is_taken_as_given():
    d = Domain.from_config(None, config.load(None, ["run.max_steps=1"]))
    assert d.auto and d.grid == (1, 1, 1)
    d = Domain.from_config(None, config.load(None, ["run.max_steps=1", "decomp.grid=[1, 1, 1]"]))
    assert not d.auto and d.grid == (1, 1, 1)
    with pytest.raises(ConfigError, match="2 domains for 1 ranks"):
        Domain.from_config(None, config.load(None, ["run.max_steps=1", "decomp.grid=[1, 2, 1]"]))


def test_a_grid_that_is_not_the_ranks_is_refused_before_the_run_directory_and_at_a_restart(tmp_path):
    from helpers import mpdem
    tiny = ["--set", "pour.N=20", "--set", "box.L_x=4", "--set", "box.L_y=4", "--quiet"]
    r = mpdem("run", *tiny, "--set", "run.max_steps=10", "--set", "decomp.grid=[2, 1, 1]", "--out", tmp_path / "r",
              check=1)
    assert "decomp.grid = [2, 1, 1]: 2 domains for 1 ranks" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "r").exists()
    mpdem("run", *tiny, "--set", "run.max_steps=10", "--out", tmp_path / "ok", check=3)
    log = (tmp_path / "ok" / "log.txt").read_text()
    r = mpdem("restart", tmp_path / "ok", "--set", "run.max_steps=20", "--set", "decomp.grid=[1, 1, 2]", check=1)
    assert "decomp.grid = [1, 1, 2]: 2 domains for 1 ranks" in r.stderr and "Traceback" not in r.stderr
    assert (tmp_path / "ok" / "log.txt").read_text() == log
