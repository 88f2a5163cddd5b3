"""docs/model.md section 9, items 1, 2 and 6: binary collisions."""
import math

import numpy as np
import pytest

from mpdem.config import collision_time, gamma_n_from_epsilon, restitution

from helpers import make_engine


def collide(k_n, eps, bed=False, speed=1.0, dt_factor=1.0, phase=0.0):
    """Head-on collision along x; returns (restitution, contact duration, engine).

    ``phase`` in [0, 1) shifts where the contact starts within a time step.
    """
    dt = 1e-4 * math.sqrt(2e5 / k_n) * dt_factor
    x1 = 5.0 + 1e3 * speed * dt + phase * speed * dt
    if bed:
        x = [[4.0, 5.0, 5.0], [x1, 5.0, 5.0]]
        v = [[0.0, 0, 0], [-speed, 0, 0]]
        fixed = [1, 0]
    else:
        x = [[4.0, 5.0, 5.0], [x1, 5.0, 5.0]]
        v = [[speed / 2, 0, 0], [-speed / 2, 0, 0]]
        fixed = None
    eng = make_engine(x, v, fixed=fixed, k_n=k_n, epsilon=eps, dt=dt)
    st, dt = eng.state, eng.phys.dt

    def gap():
        return abs(st.x[1, 0] - st.x[0, 0]) - 1.0

    # free flight to contact is exact: the start time is interpolated linearly
    t_start = t_end = None
    prev_gap, prev_t = gap(), st.time
    in_contact = False
    for _ in range(int(10 / (speed * dt)) + 2000):
        eng.step()
        g = gap()
        if not in_contact and g < 0:
            in_contact = True
            t_start = prev_t + dt * prev_gap / (prev_gap - g)
        elif in_contact and g >= 0:
            t_end = prev_t + dt * (-prev_gap) / (g - prev_gap)
            break
        prev_gap, prev_t = g, st.time
    # after separation the velocities are constant: one more step to be clear
    eng.step()
    v_rel = st.v[1, 0] - st.v[0, 0]
    return v_rel / speed, t_end - t_start, eng


PHASES = [k / 8 for k in range(8)]


@pytest.mark.parametrize("k_n", [2e5, 2e9])
@pytest.mark.parametrize("eps", [0.26, 0.5, 0.88])
def test_head_on_restitution_and_duration(k_n, eps):
    """docs/model.md 9.1, with what the scheme of 4.1 actually achieves.

    Velocity Verlet with half-step velocities in the dashpot and contacts seen
    at whole steps has an O(gamma_n dt) error in epsilon that depends on where
    the contact starts within a step. At the default dt (t_col / dt ~ 50) it
    is up to 1.2e-2 for epsilon = 0.26 (phase mean 4e-3) and the duration is
    off by up to 1.1%; docs/model.md's 1e-3 and 1% hold at every phase with
    dt / 20. The default-dt bounds are asserted too, so a regression shows.
    """
    g = gamma_n_from_epsilon(eps, k_n)
    t_col = collision_time(g, k_n)
    errs = []
    for ph in PHASES:
        e, t, _ = collide(k_n, eps, phase=ph)
        errs.append(e - eps)
        assert abs(t / t_col - 1) < 0.012
    assert max(abs(x) for x in errs) < 1.3e-2
    assert abs(sum(errs) / len(errs)) < 5e-3
    for ph in PHASES[::2]:
        e, t, _ = collide(k_n, eps, phase=ph, dt_factor=0.05)
        assert abs(e - eps) < 1e-3
        assert abs(t / t_col - 1) < 0.01


@pytest.mark.parametrize("k_n", [2e5, 2e9])
def test_elastic_collision_restitution_one(k_n):
    """Without damping the scheme is symplectic: epsilon = 1 within 1e-3 at any phase."""
    for ph in PHASES:
        e, t, _ = collide(k_n, 1.0, phase=ph)
        assert abs(e - 1.0) < 1e-3
        assert abs(t / collision_time(0.0, k_n) - 1) < 0.01


def test_paper_damping_values():
    # docs/model.md 3.2 worked values
    assert gamma_n_from_epsilon(0.88, 2e5) == pytest.approx(51.43, abs=0.01)
    assert gamma_n_from_epsilon(0.50, 2e5) == pytest.approx(272.5, abs=0.1)
    assert gamma_n_from_epsilon(0.26, 2e9) == pytest.approx(49848, rel=1e-4)
    assert collision_time(gamma_n_from_epsilon(0.88, 2e5), 2e5) == pytest.approx(4.971e-3, rel=1e-3)
    assert restitution(50.0, 2e5) == pytest.approx(0.883, abs=1e-3)


@pytest.mark.parametrize("eps", [0.88, 0.5])
def test_bed_impact_uses_full_mass(eps):
    """docs/model.md 9.2: m_eff = m against a frozen sphere (0.835 for 0.88)."""
    g = gamma_n_from_epsilon(eps, 2e5)
    expect = restitution(g, 2e5, m_eff=1.0)
    if eps == 0.88:
        assert expect == pytest.approx(0.835, abs=1e-3)
    for ph in PHASES[::2]:
        e, t, _ = collide(2e5, eps, bed=True, phase=ph, dt_factor=0.05)
        assert abs(e - expect) < 1e-3
        assert abs(t / collision_time(g, 2e5, m_eff=1.0) - 1) < 0.01
    e, t, _ = collide(2e5, eps, bed=True)
    assert abs(e - expect) < 1.5e-2
    # a free pair of the same gamma_n restitutes more than the bed collision
    assert expect < eps


def test_glancing_frictional_collision_bookkeeping():
    # two spinning spheres collide off-centre with friction
    x = [[4.0, 5.0, 5.0], [5.3, 5.45, 5.1]]
    v = [[0.7, 0.1, 0.0], [-0.6, -0.2, 0.05]]
    w = [[0.0, 3.0, -2.0], [1.0, 0.0, 4.0]]
    eng = make_engine(x, v, w, k_n=2e5, epsilon=0.5, mu=0.5, gamma_t=20.0)
    st = eng.state

    def momentum():
        return st.v[:2].sum(axis=0)

    def angmom():
        com = st.x[:2].mean(axis=0)
        r = st.x[:2] - com
        return np.cross(r, st.v[:2]).sum(axis=0) + 0.1 * st.omega[:2].sum(axis=0)

    p0, L0 = momentum(), angmom()
    residual = np.zeros(3)
    steps_in_contact = 0
    for _ in range(3000):
        eng.step()
        if len(st.slots_of(0)[0]):
            steps_in_contact += 1
            d = st.x[0] - st.x[1]
            r = np.linalg.norm(d)
            n = d / r
            # tangential force on 0 from the torque: T = -R n x F_t, F_t perpendicular to n
            t0, t1 = st.torque[0], st.torque[1]
            assert np.array_equal(t0, t1)
            assert abs(t0 @ n) <= 1e-12 * max(np.linalg.norm(t0), 1e-300)
            ft = np.cross(n, t0) / 0.5        # n x T = R F_t for F_t perpendicular to n
            residual += -(1 - r) * np.cross(n, ft) * eng.phys.dt
            # equal and opposite contact forces
            assert np.array_equal(st.f[0], -st.f[1])
            assert np.array_equal(st.slots_of(0)[1], -st.slots_of(1)[1])
    assert steps_in_contact > 20
    assert np.abs(momentum() - p0).max() < 1e-13
    dL = angmom() - L0
    # the change of angular momentum is the O(delta) residual of docs/model.md 9.6
    assert np.linalg.norm(residual) > 0
    assert np.linalg.norm(dL - residual) < 0.05 * np.linalg.norm(residual) + 1e-12
