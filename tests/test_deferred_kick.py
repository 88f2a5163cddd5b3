"""The deferred second half-kick (``Engine.step(defer_kick=True)``): the same bits as the
kick at the end of each step, and every reader of the state sees the completed step."""
import dataclasses
import math

import numpy as np
import pytest

from helpers import make_engine
from mpdem.build import insert_random, rng
from mpdem.io.checkpoint import digest, gather_state


def _pour(n=300, L=6.0, seed=7):
    return insert_random(rng(seed, 1), n, L, L, 0.5, 0.5 + n * (math.pi / 6) / (L * L * 0.3)), L


@pytest.mark.parametrize("mu,nchunk", [(0.0, 1), (0.5, 1), (0.5, 3)])
def test_deferred_kick_changes_no_bit_and_readers_see_the_whole_step(mu, nchunk):
    x, L = _pour()
    # a hot gas on a floor: collisions from the first steps
    g = np.random.default_rng(3)
    v, omega = 3.0 * g.standard_normal(x.shape), g.standard_normal(x.shape)
    pair = []
    for _ in range(2):
        eng = make_engine(x, v.copy(), omega.copy(), L=L, mu=mu, gravity=1.0, gamma_t=10.0 if mu else 0.0)
        eng.set_chunks(nchunk)
        eng.phys = dataclasses.replace(eng.phys, floor=True)
        pair.append(eng)
    plain, deferred = pair
    differed, touched = 0, []
    for k in range(1, 4001):
        plain.step()
        deferred.step(defer_kick=True)
        # the raw arrays lack the kick until a reader asks for the rows
        differed += not np.array_equal(plain.state.v[:plain.state.n_own], deferred.state.v[:deferred.state.n_own])
        if k % 397 == 0:
            assert deferred.kinetic() == plain.kinetic()
            assert deferred.contacts() == plain.contacts()
            touched.append(plain.n_contacts)
        if k % 1000 == 0:
            assert digest(gather_state(deferred.state)) == digest(gather_state(plain.state))
    assert differed > 3900
    assert min(touched) > 0 and sum(touched) > 100, touched
    assert plain.n_rebuilds > 5
    # advance() defers inside and completes at its end
    plain.advance(500)
    for _ in range(500):
        deferred.step()
    assert digest(gather_state(deferred.state)) == digest(gather_state(plain.state))
    assert np.array_equal(plain.state.v[:plain.state.n_own], deferred.state.v[:deferred.state.n_own])
