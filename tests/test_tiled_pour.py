"""A tiled pour (``pour.insertion = "tiles"``, docs/model.md 5.3): each rank fills its share of the tiles
and holds only its rows, and the pour is the same whatever the ranks' count.

The MPI side (the rows sent to their owners: the one-rank digest on 2-4 ranks and on columns) is
``mpi_tests/test_grid.py``'s.
"""
import math
import numpy as np
import pytest

from mpdem import build, config, footprint, initial
from mpdem.analysis import find_contacts
from mpdem.errors import ConfigError, InputError

L, N = 11.0, 900


class Share:
    """What ``pour_tiled`` reads of a Channel: rank ``rank`` of ``size``, its looks and sums its own."""

    def __init__(self, rank, size):
        self.rank, self.size, self.parallel = rank, size, False


def cfg_of(*sets):
    return config.load(None, [f"box.L_x={L}", f"box.L_y={L}", f"pour.N={N}", "pour.phi_i=0.2", "pour.K0=20.0",
                              "pour.insertion=tiles", "pour.tile=5.0", "run.max_steps=10", *sets])


def bed():
    return build.Bed(build.insert_random(build.rng(3, 9), 60, L, L, 0.5, 1.5))


def shares(cfg, b, P):
    return [initial.pour_tiled(cfg, b, Share(r, P), lambda line: None)[0] for r in range(P)]


def test_the_tiles_hold_n_spheres_that_overlap_nothing_inside_their_region():
    cfg, b = cfg_of(), bed()
    rows, H = initial.pour_tiled(cfg, b, None, lambda line: None)
    tiles = build.pour_tiles(N, L, L, b.z_top + 1.0, 0.2, 5.0)
    assert tiles.n == (2, 2, int(build.insertion_height(N, L, L, 0.2) // 5.0)) and H == tiles.H
    assert tiles.counts.sum() == N and tiles.counts.min() > 0
    assert np.array_equal(rows["id"], np.arange(N + len(b.x)))
    mob = rows["fixed"] == 0
    x = rows["x"]
    assert mob.sum() == N and np.array_equal(x[~mob], b.x)
    assert np.all((x[:, :2] >= 0) & (x[:, :2] < L))
    assert x[mob, 2].min() >= b.z_top + 1.0 and x[mob, 2].max() <= b.z_top + 1.0 + H
    # no two spheres closer than d, across the tiles' faces and the periodic ones too, nor one on the bed
    pairs, _ = find_contacts(x, L, L)
    assert len(pairs) == 0
    # every tile's centres keep d / 2 from its faces between tiles
    start = tiles.start
    for k in range(len(tiles.counts)):
        origin, lo, span, _ = tiles.region(k)
        c = x[start[k]:start[k + 1]] - np.r_[origin[:2], 0.0]
        assert np.all(c >= lo - 1e-12) and np.all(c <= lo + span + 1e-12)
        assert lo[0] == 0.5 and span[0] == L / 2 - 1.0
        # the tile's mean kinetic energy is K0
        v = rows["v"][start[k]:start[k + 1]]
        assert 0.5 * np.sum(v * v) / len(v) == pytest.approx(20.0, rel=1e-12)
    # the centres' space holds them at phi_i
    space = (L - 2.0) ** 2 * (H - (tiles.n[2] - 1))
    assert N * math.pi / 6 / space == pytest.approx(0.2, rel=1e-12)


@pytest.mark.parametrize("P", [2, 3, 7, 40])
def test_the_ranks_shares_together_are_the_one_rank_pour_bit_for_bit(P):
    cfg, b = cfg_of(), bed()
    one = shares(cfg, b, 1)[0]
    parts = shares(cfg, b, P)
    ids = np.concatenate([p["id"] for p in parts])
    order = np.argsort(ids)
    assert np.array_equal(ids[order], one["id"])
    for key in ("x", "v", "omega", "fixed"):
        assert np.concatenate([p[key] for p in parts])[order].tobytes() == one[key].tobytes(), key
    # no rank holds more than its run of tiles and of the bed (40 ranks: some hold no tile at all)
    tiles = build.pour_tiles(N, L, L, b.z_top + 1.0, 0.2, 5.0)
    most = tiles.counts.max() * math.ceil(len(tiles.counts) / P) + math.ceil(len(b.x) / P)
    assert max(len(p["id"]) for p in parts) <= most < N


def test_another_seed_another_pour_and_the_whole_insertion_is_another_one():
    b = bed()
    a = initial.pour_tiled(cfg_of(), b, None, lambda line: None)[0]
    s = initial.pour_tiled(cfg_of("run.seed=2"), b, None, lambda line: None)[0]
    assert not np.array_equal(a["x"], s["x"])
    w = initial.pour(cfg_of("pour.insertion=whole"), b, lambda line: None)[0]
    assert not np.array_equal(a["x"][:N], w["x"][:N])


def test_the_tile_edge_and_the_choice_are_checked():
    with pytest.raises(ConfigError, match=r"pour.tile = 3.0: accepted tile >= 4"):
        cfg_of("pour.tile=3.0")
    with pytest.raises(ConfigError, match=r"pour.insertion"):
        cfg_of("pour.insertion=blocks")


def test_a_tiled_pours_set_up_needs_a_share_of_the_pile_on_each_rank():
    """The estimate of a rank's set-up (``footprint``): a tiled pour's does not grow with the pile at a
    fixed share (twice the spheres on twice the ranks), the whole insertion's does."""
    def setup(insertion, n, ranks):
        cfg = config.load(None, ["box.L_x=100.0", "box.L_y=100.0", f"pour.N={n}", f"pour.insertion={insertion}",
                                 "run.max_steps=10"])
        return footprint.of_config(cfg, ranks).setup
    assert setup("tiles", 2_000_000, 8) == pytest.approx(setup("tiles", 1_000_000, 4), rel=0.02)
    assert setup("whole", 2_000_000, 8) > 1.6 * setup("whole", 1_000_000, 4)
    assert setup("tiles", 2_000_000, 8) < 0.5 * setup("whole", 2_000_000, 8)


def test_a_tile_that_cannot_be_filled_is_one_line_naming_the_pour(monkeypatch):
    """A tile whose random insertion gives up (forced here: no candidate beyond the first batch) is one
    error naming the choice and phi_i, said by every rank together (its ``agreed``)."""
    b, real = bed(), build.rsa_batches

    def giving_up(gen, out, box, lo, span, obstacles=None, max_tries=2000, batch=None):
        return real(gen, out, box, lo, span, obstacles, 0, 4)
    monkeypatch.setattr(build, "rsa_batches", giving_up)
    with pytest.raises(InputError, match=r"^pour: a tile's random insertion could not place its spheres "
                                         r"\(pour.insertion = 'tiles': 900 spheres in \d+ tiles at pour.phi_i = 0.2\); "
                                         r"lower pour.phi_i$"):
        initial.pour_tiled(cfg_of(), b, Share(0, 1), lambda line: None)
