"""Boundaries as planes (planes.py, ``law.plane_contact``): a sphere on a smooth plane tilted by theta
under vertical gravity slides at g sin(theta); a lid plane at z = H holds a sphere that gravity
pushes up against it, at the overlap that carries its weight; both engines give the same bits. The
floor and the wall under the bed are planes too: the digests of tools/digests.sh (a wall case
among them) are those of before."""
import math

import numpy as np
import pytest

from mpdem.config import gamma_n_from_epsilon
from mpdem.decomp import Domain
from mpdem.engine import cpu, gpu
from mpdem.engine.base import Physics
from mpdem.kernels.particle import R
from mpdem.planes import Plane, arrays, of_physics
from mpdem.state import State

K_N = 2e5


def physics(**kw):
    base = dict(k_n=K_N, k_t=2 * K_N / 7, gamma_n=gamma_n_from_epsilon(0.5, K_N), gamma_t=0.0, mu=0.0, dt=1e-4)
    base.update(kw)
    return Physics.of(**base)


def stepped(x, p, steps, engine=cpu.Engine, **kw):
    """One sphere at ``x``, at rest, stepped ``steps`` times; its State."""
    st = State(np.arange(1), np.array([x], float), L_x=10.0, L_y=10.0)
    eng = engine(st, p, Domain(None), **kw)
    eng.start()
    eng.advance(steps)
    eng.sync_state()
    return st


def tilted(theta):
    """A smooth plane through the origin tilted by ``theta`` degrees about y (it falls towards +x), and
    a sphere on it at x = 5 whose overlap carries g cos(theta): (plane, position, downhill unit vector)."""
    t = math.radians(theta)
    n = (math.sin(t), 0.0, math.cos(t))
    plane = Plane(n, 0.0, "smooth")
    foot = np.array([5.0, 5.0, -5.0 * math.tan(t)])
    x = foot + (R - math.cos(t) / K_N) * np.array(n)
    return plane, x, np.array([math.cos(t), 0.0, -math.sin(t)])


@pytest.mark.parametrize("theta", [10.0, 30.0])
def test_a_sphere_slides_down_a_smooth_tilted_plane_at_g_sin_theta(theta):
    plane, x0, down = tilted(theta)
    steps, dt = 20000, 1e-4
    st = stepped(x0, physics(gravity=1.0, planes=(plane,)), steps)
    t = steps * dt
    a = math.sin(math.radians(theta))
    v = st.v[0]
    assert v @ down == pytest.approx(a * t, rel=1e-9)
    assert abs(v @ np.array(plane.normal)) < 1e-6 and abs(v[1]) == 0.0 and not st.omega[0].any()
    assert (st.x[0] - x0) @ down == pytest.approx(0.5 * a * t * t, rel=1e-8)


def test_a_lid_holds_a_sphere_pushed_up_against_it():
    """Gravity upwards (g = -1): a sphere 1.5 d under the lid at z = H rises, bounces and comes to rest
    against it, its overlap 1 / k_n (the Hookean force that carries its weight)."""
    H = 8.0
    st = stepped([5.0, 5.0, H - 2.0], physics(gravity=-1.0, planes=(Plane.lid(H),)), 120000)
    assert st.x[0, 2] == pytest.approx(H - R + 1.0 / K_N, abs=1e-9)
    assert abs(st.v[0, 2]) < 1e-6 and st.x[0, 0] == 5.0 and st.x[0, 1] == 5.0
    # without the lid it would have flown through z = H
    free = stepped([5.0, 5.0, H - 2.0], physics(gravity=-1.0), 30000)
    assert free.x[0, 2] > H


def test_both_engines_give_the_same_bits_on_planes():
    from mpdem.kernels.gpu import runtime
    grid = dict(block=2, blocks=2) if runtime.SIMULATOR else {}
    plane, x0, _ = tilted(30.0)
    for p, x in ((physics(gravity=1.0, planes=(plane,)), x0),
                 (physics(gravity=-1.0, planes=(Plane.lid(8.0),)), [5.0, 5.0, 8.0 - R + 1e-4])):
        a = stepped(x, p, 200)
        b = stepped(x, p, 200, engine=gpu.Engine, **grid)
        for name in ("x", "v", "omega", "f", "torque"):
            assert np.array_equal(getattr(a, name)[:1], getattr(b, name)[:1]), name


def test_the_floor_and_the_wall_are_the_plane_z_0_facing_up():
    geo, kinds = arrays(of_physics(physics(floor=True, wall=True, planes=(Plane.lid(5.0),))))
    assert geo.tolist() == [[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, -1.0, -5.0]]
    from mpdem.kernels.law import PLANE_FLOOR, PLANE_ROUGH, PLANE_SMOOTH
    assert kinds.tolist() == [PLANE_FLOOR, PLANE_ROUGH, PLANE_SMOOTH]
    assert arrays(of_physics(physics()))[0].shape == (0, 4)


def test_bad_planes_are_one_clear_error():
    with pytest.raises(ValueError, match=r"normal \(0, 0, 2\): accepted a unit vector"):
        Plane((0, 0, 2))
    with pytest.raises(ValueError, match="kind 'sticky': accepted floor, smooth, rough"):
        Plane((0, 0, 1), kind="sticky")
    with pytest.raises(ValueError, match="a rough plane other than the wall under the bed"):
        of_physics(physics(planes=(Plane.lid(5.0, "rough"),)))
