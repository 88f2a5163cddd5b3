"""A stop signal during the set-up reaches every rank together (``mpdem.watch``), wherever it came:
at a look of every rank (``everywhere=True``), also inside the ranks' making of the bed."""
import signal

import pytest

from mpdem.errors import Interrupted
from mpdem.parallel import Channel
from mpdem.watch import Watch


def test_a_signal_on_the_last_rank_stops_every_rank_at_the_same_look(comm):
    net = Channel(comm)
    signals = [int(signal.SIGTERM)] if net.rank == net.size - 1 else []
    w = Watch(lambda line: None, net, signals, every=1e9)
    w.begin("the pour's insertion")
    with pytest.raises(Interrupted) as e:
        w(everywhere=True)
    assert e.value.status == 128 + signal.SIGTERM and e.value.agreed
    # without a signal anywhere, a look of every rank goes on
    w2 = Watch(lambda line: None, net, [], every=1e9)
    w2(everywhere=True)


def test_a_signal_on_rank_0_while_the_ranks_make_the_bed_stops_every_rank(comm, monkeypatch):
    """The bed is made by every rank together (``build.make_bed`` on the launch's ranks), each looking at
    the signals with the others between its short calls: a signal that reaches rank 0 alone ends all."""
    from mpdem import bedcache, config
    from mpdem.initial import bed
    monkeypatch.setenv(bedcache.ENV, "off")
    net = Channel(comm)
    signals = [int(signal.SIGINT)] if net.rank == 0 else []
    w = Watch(lambda line: None, net, signals, every=1e9)
    cfg = config.load(None, ["box.L_x=5", "box.L_y=5", "bed.settle_time=2", "run.max_steps=1"])
    with pytest.raises(Interrupted, match="^stopped by SIGINT during the making of the bed") as e:
        bed(cfg, net, lambda line: None, w)
    assert e.value.status == 130 and e.value.agreed


class LateSignal(Watch):
    """A Watch that receives SIGTERM at its ``at``-th look (on the rank that makes it)."""

    def __init__(self, net, at):
        super().__init__(lambda line: None, net, [], every=1e9)
        self.looks, self.at = 0, at

    def __call__(self, line=None, everywhere=False):
        self.looks += 1
        if self.looks == self.at:
            self.signals.append(int(signal.SIGTERM))
        return super().__call__(line, everywhere)


def _tiled(monkeypatch, tile=4):
    from mpdem import build, config
    # small batches, so that the ranks' runs of tiles take different numbers of rounds
    monkeypatch.setattr(build, "RSA_BATCH", 64)
    cfg = config.load(None, ["box.L_x=10", "box.L_y=10", "pour.N=400", "pour.phi_i=0.1", "pour.insertion=tiles",
                             f"pour.tile={tile}", "run.max_steps=1"])
    return cfg, build.Bed(build.insert_random(build.rng(1, 9), 30, 10.0, 10.0, 0.5, 1.0))


@pytest.mark.parametrize("tile", [4, 8])
def test_the_ranks_fill_their_tiles_in_rounds_until_the_last_is_done(comm, monkeypatch, tile):
    """A tiled pour: each rank fills its own run of tiles a batch a round, every rank looking each round,
    until the last rank is done (runs of different lengths: no rank leaves the others waiting; with
    tiles of 8 d, 2 tiles: on 3 and 4 ranks some rank fills none)."""
    from mpdem.initial import pour_tiled
    net = Channel(comm)
    cfg, b = _tiled(monkeypatch, tile)
    w = LateSignal(net, at=0)
    rows, _ = pour_tiled(cfg, b, net, lambda line: None, w)
    looks = comm.allgather(w.looks)
    assert len(set(looks)) == 1 and looks[0] > 2
    assert sum(comm.allgather(int((rows["fixed"] == 0).sum()))) == 400
    assert sum(comm.allgather(len(rows["id"]))) == 430


@pytest.mark.parametrize("late", [False, True])
def test_a_signal_on_one_rank_during_a_tiled_pour_stops_every_rank(comm, monkeypatch, late):
    """Rank 0 receives it at its second look, or (``late``) at the look before the last round, when the
    ranks' runs of tiles of fewer rounds are done: every rank stops at the same look."""
    from mpdem.initial import pour_tiled
    net = Channel(comm)
    cfg, b = _tiled(monkeypatch)
    probe = LateSignal(net, at=0)
    pour_tiled(cfg, b, net, lambda line: None, probe)
    rounds = probe.looks
    w = LateSignal(net, at=(rounds - 1 if late else 2) if net.rank == 0 else 0)
    with pytest.raises(Interrupted, match="^stopped by SIGTERM during the pour's insertion") as e:
        pour_tiled(cfg, b, net, lambda line: None, w)
    assert e.value.status == 143 and e.value.agreed
    assert comm.allgather(w.looks) == [w.looks] * net.size
