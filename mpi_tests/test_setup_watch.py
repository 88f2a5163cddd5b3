"""A stop signal during the set-up reaches every rank together (``mpdem.watch``), wherever it came:
at a look of every rank (``everywhere=True``), or inside rank 0's making of the bed, carried by the
bed's broadcast."""
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


def test_a_signal_in_rank_0s_bed_reaches_every_rank_with_the_broadcast(comm):
    net = Channel(comm)
    signals = [int(signal.SIGINT)] if net.rank == 0 else []
    w = Watch(lambda line: None, net, signals, every=1e9)
    w.begin("the making of the bed")

    def make_bed(progress):
        for _ in range(3):
            progress("a short call")     # rank 0's own look (``Watch.local``)
        return "a bed"
    with pytest.raises(Interrupted, match="^stopped by SIGINT during the making of the bed") as e:
        net.on_root(make_bed, w.local(), catch=(Interrupted,))
    assert e.value.status == 130 and e.value.agreed
