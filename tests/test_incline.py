"""Gravity tilted by ``box.incline`` (docs/model.md 1): a sphere on the plane z = 0 (``bed.wall``)
of a pile tilted by theta slides at g sin(theta) without friction and rolls at 5/7 g sin(theta)
with it; untilted, nothing moves along the plane. Both engines give the same bits."""
import math

import numpy as np
import pytest

from helpers import mpdem
from mpdem.config import gamma_n_from_epsilon
from mpdem.decomp import Domain
from mpdem.engine import cpu, gpu
from mpdem.engine.base import Physics
from mpdem.kernels.law import gravity_vector
from mpdem.kernels.particle import R
from mpdem.state import State

K_N = 2e5


def on_the_plane(theta, mu, engine=cpu.Engine, steps=20000, **kw):
    """One sphere resting on the wall plane (its overlap the one that carries g cos(theta)), stepped
    ``steps`` times (dt 1e-4); returns its state."""
    p = Physics.of(k_n=K_N, k_t=2 * K_N / 7, gamma_n=gamma_n_from_epsilon(0.5, K_N), gamma_t=0.0, mu=mu, dt=1e-4,
                   gravity=1.0, incline=theta, wall=True)
    z = R - math.cos(math.radians(theta)) / K_N
    st = State(np.arange(1), np.array([[5.0, 5.0, z]]), L_x=10.0, L_y=10.0)
    eng = engine(st, p, Domain(None), **kw)
    eng.start()
    eng.advance(steps)
    eng.sync_state()
    return st, steps * p.dt


def test_untilted_gravity_is_exactly_minus_z():
    g = gravity_vector(1.0, 0.0)
    assert g == (0.0, 0.0, -1.0) and math.copysign(1.0, g[0]) == 1.0
    st, _ = on_the_plane(0.0, 0.5, steps=2000)
    assert st.v[0, 0] == 0.0 and st.v[0, 1] == 0.0 and st.x[0, 0] == 5.0


@pytest.mark.parametrize("theta", [10.0, 30.0])
def test_a_sphere_slides_down_a_frictionless_incline_at_g_sin_theta(theta):
    st, t = on_the_plane(theta, 0.0)
    a = math.sin(math.radians(theta))
    # 40 000 half-kicks, each rounded
    assert st.v[0, 0] == pytest.approx(a * t, rel=1e-10)
    # x was wrapped into the box: the distance is 1/2 a t^2 modulo L_x
    assert (st.x[0, 0] - 5.0) % 10.0 == pytest.approx((0.5 * a * t * t) % 10.0, rel=1e-9)
    assert st.v[0, 1] == 0.0 and abs(st.v[0, 2]) < 1e-6 and not st.omega[0].any()


def test_a_sphere_rolls_down_a_rough_incline_at_five_sevenths_g_sin_theta():
    """Rolling without slipping (tan 30 deg < 7 mu / 2): a = 5/7 g sin(theta), v = R omega_y; the
    tangential spring rings about that, so to 1 %."""
    st, t = on_the_plane(30.0, 0.5)
    a = 5.0 / 7.0 * math.sin(math.radians(30.0))
    assert st.v[0, 0] == pytest.approx(a * t, rel=1e-2)
    assert R * st.omega[0, 1] == pytest.approx(st.v[0, 0], rel=1e-2)


def test_both_engines_roll_the_same_bits():
    """100 steps, one launch on the GPU: the tilted gravity, the wall's normal and tangential force and
    its history enter every step, so a difference in any shows in the first; each simulated step is slow."""
    from mpdem.kernels.gpu import runtime
    grid = dict(block=2, blocks=2) if runtime.SIMULATOR else {}
    a, _ = on_the_plane(30.0, 0.5, steps=100)
    b, _ = on_the_plane(30.0, 0.5, engine=gpu.Engine, steps=100, **grid)
    for name in ("x", "v", "omega", "f", "torque", "wall_ds"):
        assert np.array_equal(getattr(a, name)[:1], getattr(b, name)[:1]), name


def test_incline_is_checked_before_any_work(tmp_path):
    r = mpdem("run", "--set", "box.incline=90", "--set", "run.max_steps=10", "--out", tmp_path / "r", check=1)
    assert "box.incline = 90.0: accepted 0 <= incline < 90 degrees" in r.stderr and "Traceback" not in r.stderr
