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
