"""The CPU engine's steps in one call (``Engine.run_quiet``, ``kernels.quiet``): the bits, the
step records and the list work of the same steps taken one by one (``step(defer_kick=True)``)."""
import dataclasses
import math

import numpy as np
import pytest

from helpers import make_engine
from mpdem.build import insert_random, rng
from mpdem.engine import cpu
from mpdem.io.checkpoint import digest, gather_state


def _gas(mu, wall):
    """A hot gas of 300 spheres over a floor (or the rough wall plane): collisions, rebuilds and
    filterings of the near lists from the first steps."""
    n, L = 300, 6.0
    x = insert_random(rng(7, 1), n, L, L, 0.5, 0.5 + n * (math.pi / 6) / (L * L * 0.3))
    g = np.random.default_rng(3)
    v, omega = 3.0 * g.standard_normal(x.shape), g.standard_normal(x.shape)
    eng = make_engine(x, v, omega, L=L, mu=mu, gravity=1.0, gamma_t=10.0 if mu else 0.0)
    eng.phys = dataclasses.replace(eng.phys, floor=not wall, wall=wall)
    return eng


def _counting(eng):
    """Count the kernel calls of ``run_quiet`` and the steps finished on ``step``'s path."""
    calls = {"kernel": 0, "host": 0}
    kernel, host = eng._kernels.quiet_steps, eng._after_drift

    class Counted:
        reset = kernel.reset

        def __call__(self, *a):
            calls["kernel"] += 1
            return kernel(*a)

    def counted_host(*a):
        calls["host"] += 1
        return host(*a)

    eng._kernels = eng._kernels._replace(quiet_steps=Counted())
    eng._after_drift = counted_host
    return calls


@pytest.mark.parametrize("mu,wall", [(0.0, False), (0.5, False), (0.5, True)])
def test_steps_in_one_call_are_the_steps_one_by_one(mu, wall):
    one, many = _gas(mu, wall), _gas(mu, wall)
    assert many.steps_in_one_call
    calls = _counting(many)
    r0, f0 = many.n_rebuilds, many.lists.n_filters
    assert r0 == 1
    filters, touched = [], []
    # runs of every length: one step, a few, many, and more than one kernel call's room
    for n in (1, 2, 7, 250, 1, cpu.QUIET_CALL + 313, 40, 1500):
        flags = one.info.flags
        want = [one.step(flags, defer_kick=True) for _ in range(n)]
        got = many.run_quiet(n, flags)
        assert got == want
        assert many.state.step == one.state.step and many.state.time == one.state.time
        assert digest(gather_state(many.state)) == digest(gather_state(one.state))
        assert many.kinetic() == one.kinetic() and many.contacts() == one.contacts()
        filters.append(many.lists.n_filters)
        touched.append(one.n_contacts)
    assert many.n_rebuilds == one.n_rebuilds > 5
    assert many.lists.n_filters == one.lists.n_filters and filters[-1] > filters[0]
    assert min(touched) > 0 and sum(touched) > 100, touched
    # the steps that needed no list work ran in the kernel; those that did, on the host's path
    steps = sum((1, 2, 7, 250, 1, cpu.QUIET_CALL + 313, 40, 1500))
    # (a rebuild filters its new lists too)
    assert calls["host"] == many.lists.n_filters - f0 > many.n_rebuilds - r0
    assert calls["kernel"] >= calls["host"] and calls["host"] < steps // 5


def test_a_position_that_is_not_finite_is_reported_at_its_step_without_list_work():
    one, many = _gas(0.5, False), _gas(0.5, False)
    one.advance(20)
    many.advance(20)
    builds = one.n_rebuilds
    for e in (one, many):
        e.state.v[5, 0] = math.nan
    want = [one.step(defer_kick=True) for _ in range(3)]
    got = many.run_quiet(3)
    # every step from the bad one on says so (z_min NaN: ``Checks.fatal`` stops a run), with no
    # rebuild of lists over a NaN position
    assert all(math.isnan(i.z_min) for i in got + want)
    assert [(i.z_max, i.max_overlap) for i in got] == [(i.z_max, i.max_overlap) for i in want]
    assert one.n_rebuilds == many.n_rebuilds == builds
    assert one.state.step == many.state.step == 23


def test_several_threads_take_the_steps_one_by_one():
    eng = _gas(0.5, False)
    eng.set_chunks(3)
    assert not eng.steps_in_one_call
    calls = _counting(eng)
    ref = _gas(0.5, False)
    got = eng.run_quiet(300)
    assert got == [ref.step(defer_kick=True) for _ in range(300)]
    assert calls["kernel"] == 0 and calls["host"] == 300
    assert digest(gather_state(eng.state)) == digest(gather_state(ref.state))


def test_the_drivers_quiet_span_ends_before_the_first_step_a_schedule_reads():
    """``schedule.quiet_span`` (the steps the driver hands to ``run_quiet``) against a walk over the
    steps with each schedule's ``due``: the stop samples, progress lines, snapshots and checkpoints."""
    from types import SimpleNamespace

    from mpdem.decomp import Domain
    from mpdem.driver.schedule import Checkpoints, Progress, Snapshots, StopRule, quiet_span

    g = np.random.default_rng(5)
    for _ in range(200):
        every = [int(g.integers(1, 400)), int(g.integers(1, 400)), int(g.integers(0, 3)) * int(g.integers(1, 400)),
                 int(g.integers(0, 3)) * int(g.integers(1, 400))]
        stop = StopRule(1e-9, "energy", 1.0, every[0] * 1e-4, 1e-4)
        progress = Progress(every[1], print, Domain(None), 1e-4, 10**6, 1, 0, 0.0)
        snaps = Snapshots("-", every[2], None, 0)
        ckpts = Checkpoints("-", SimpleNamespace(checkpoint_every=every[3], checkpoint_seconds=0.0), None,
                            Domain(None), print)
        step, max_steps, most = int(g.integers(0, 2000)), int(g.integers(0, 2500)), int(g.integers(0, 600))
        walk, s = 0, step + 1
        while walk < most and s < max_steps and not (stop.due(s) or progress.due(s) or snaps.due(s)
                                                     or ckpts.due(s, False)):
            walk += 1
            s += 1
        assert quiet_span(step, max_steps, (stop, progress, snaps, ckpts), most) == walk, (every, step, max_steps)


def test_each_call_takes_the_scratch_a_rebuild_made():
    """A rebuild on the host's path may make a wider force scratch (``Engine._scratch``, for a longer
    list); the next kernel call of the same ``run_quiet`` must take that one, not the one before."""
    eng = _gas(0.5, False)
    kernel, rebuild = eng._kernels.quiet_steps, eng.rebuild
    seen = []

    def wider():
        rebuild()
        eng._scratch(eng._work.found.shape[1] + 1)    # as a longer list would

    class Checked:
        reset = kernel.reset

        def __call__(self, *a):
            seen.append(a[11] is eng._work)
            return kernel(*a)

    eng.rebuild = wider
    eng._kernels = eng._kernels._replace(quiet_steps=Checked())
    builds = eng.n_rebuilds
    eng.run_quiet(600)
    assert eng.n_rebuilds > builds + 2 and len(seen) > 3 and all(seen)
