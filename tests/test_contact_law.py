"""docs/model.md section 9, items 3 to 5, and the force kernel's invariants."""
import math

import numpy as np
import pytest

from mpdem.analysis import find_contacts
from mpdem.build import insert_random, rng
from mpdem.kernels.bundles import Near, Particles, Scratch, Slots, make_box
from mpdem.kernels.forces import contact_forces
from mpdem.kernels.particle import HALF_I

from helpers import make_engine


def total_energy(eng):
    """Kinetic plus Hookean elastic energy (1/2 k_n delta^2 per contact) [m g d]."""
    st = eng.state
    n = st.n_own
    ke = 0.5 * np.sum(st.v[:n] ** 2) + HALF_I * np.sum(st.omega[:n] ** 2)
    pairs, r = find_contacts(st.x[:n], st.L_x, st.L_y)
    return ke + 0.5 * eng.law.k_n * np.sum((1.0 - r) ** 2)


def test_elastic_energy_conservation():
    """9.3: no damping, no friction, no gravity: energy drift < 1e-4 over 1e5 steps."""
    n, L = 300, 8.0
    x = insert_random(rng(7, 99), n, L, L, 0.5, 0.5 + n * (math.pi / 6) / (L * L * 0.25))
    v = rng(7, 98).normal(0.0, 1.0, (n, 3))
    eng = make_engine(x, v, L=L, epsilon=1.0)
    assert eng.law.gamma_n == 0.0
    e0 = total_energy(eng)
    collisions = 0
    for _ in range(100):
        eng.advance(1000)
        collisions += eng.contacts()
    e1 = total_energy(eng)
    assert collisions > 100           # the particles did collide
    assert abs(e1 - e0) / e0 < 1e-4


def pair_kernel(x, v, omega, ds_old, fixed=(0, 1), mu=0.5, k_n=2e5, gamma_n=0.0, gamma_t=0.0,
                dt=1e-4, increment=True, model=0, limit_damping=False, rotate=False):
    """One call of the force kernel on two particles; returns f, torque, the
    contact flags (2,) and Delta s (2, 3) of the two views, and the kernel's result."""
    from mpdem.kernels.law import Law
    x = np.array(x, float)
    v = np.array(v, float)
    omega = np.array(omega, float)
    fx = np.array(fixed, np.uint8)
    nbr_start = np.array([0, 1, 2], np.int64)
    nbr = np.array([1, 0], np.int32)
    hist = np.zeros((2, 3))
    # evaluation 1; the stamp 0 (the previous one) marks a contact going on, any other a new one
    stamp = np.full(2, 7, np.uint32)
    if ds_old is not None:
        hist[0] = ds_old
        stamp[0] = 0
    f = np.zeros((2, 3))
    t = np.zeros((2, 3))
    law = Law(k_n, 2 * k_n / 7, gamma_n, gamma_t, mu, 0.0, 0.0, 0.0, dt, model, limit_damping, rotate)
    # one chunk per row, so each row computes its view in full: each entry its own slot
    # (link k, hist[k] is entry k's, and so is place k of the pair store), both entries computed (cj = nbr)
    slot = np.arange(2, dtype=np.int32)
    near = Near(nbr_start, slot, nbr_start.copy(), nbr.copy(), slot.copy(), slot.copy())
    scratch = Scratch(np.zeros(2), np.zeros(2, np.int64), np.zeros((2, 4, 3), np.int32), np.zeros((2, 4, 4)),
                      np.zeros((2, 4, 9)))
    res = contact_forces(2, Particles(x, v, omega, f, t, fx), near, Slots(hist, stamp, np.zeros((3, 6))), 1,
                         make_box(10.0, 10.0), law, increment, scratch)
    return f, t, (stamp == 1).astype(np.uint8), hist, res


@pytest.mark.parametrize("gamma_t", [0.0, 25.0])
def test_coulomb_limit_stick_then_slide(gamma_t):
    """9.4: a sphere pressed on a frozen sphere and dragged tangentially sticks
    while |F_t| < mu F_n, then slides with |F_t| = mu F_n to rounding and
    Delta s in the tangent plane, |Delta s| = mu F_n / k_t for gamma_t = 0."""
    mu, k_n, dt = 0.5, 2e5, 1e-4
    k_t = 2 * k_n / 7
    delta = 1e-3
    # mobile sphere 0 above frozen sphere 1, sliding along x at speed u
    x = [[5.0, 5.0, 6.0 - delta], [5.0, 5.0, 5.0]]
    u = 0.05
    v = [[u, 0.0, 0.0], [0.0, 0.0, 0.0]]
    w = np.zeros((2, 3))
    ds = np.zeros(3)
    F_n = k_n * delta
    stuck = slid = 0
    for step in range(600):
        f, t, touch, hist, res = pair_kernel(x, v, w, ds, fixed=(0, 1), mu=mu, k_n=k_n,
                                             gamma_t=gamma_t, dt=dt)
        ds = hist[0].copy()
        assert touch[0] == 1
        assert abs(f[0, 2] - F_n) < 1e-9 * F_n          # normal force unchanged
        F_n = f[0, 2]                                    # n = z exactly: f_z is F_n
        ft = f[0] - np.array([0, 0, F_n])
        ft_mag = np.linalg.norm(ft)
        assert ft_mag <= mu * F_n * (1 + 1e-14)
        assert ds[2] == 0.0                              # tangent plane (n = z)
        trial = np.linalg.norm(k_t * (step + 1) * u * dt + gamma_t * u)
        if trial < mu * F_n:
            stuck += 1
            assert ft_mag == pytest.approx(trial, rel=1e-12)
            assert ds[0] == pytest.approx((step + 1) * u * dt, rel=1e-12)
        else:
            slid += 1
            assert ft_mag == pytest.approx(mu * F_n, rel=1e-14)
            # the history reproduces the truncated force exactly
            assert np.linalg.norm(-k_t * ds - gamma_t * np.array(v[0])) == pytest.approx(mu * F_n, rel=1e-12)
            if gamma_t == 0:
                assert np.linalg.norm(ds) == pytest.approx(mu * F_n / k_t, rel=1e-14)
        assert ft[0] < 0                                  # opposes sliding
    assert stuck > 5 and slid > 5


def test_first_evaluation_does_not_increment():
    f, t, n, ds, _ = pair_kernel([[5, 5, 5.999], [5, 5, 5]], [[1, 0, 0], [0, 0, 0]], np.zeros((2, 3)),
                                 None, increment=False)
    assert np.all(ds[0] == 0)
    f, t, n, ds, _ = pair_kernel([[5, 5, 5.999], [5, 5, 5]], [[1, 0, 0], [0, 0, 0]], np.zeros((2, 3)),
                                 None, increment=True)
    assert ds[0, 0] == pytest.approx(1e-4)


def test_a_contact_that_ended_starts_again_from_zero_history():
    """docs/model.md 2.4: the history of a contact that ended is deleted. Two spheres graze,
    part, and meet again on the same list entry (no rebuild): the step of the second touch
    has the bits of a fresh engine started just before it (no history)."""
    eng = make_engine([[2.0, 2.0, 2.0], [3.01, 2.0, 2.0]], v=[[0.2, 0.1, 0.0], [-0.2, -0.1, 0.0]],
                      mu=0.5, gamma_t=20.0)
    touched = False
    while not (touched and eng.contacts() == 0):
        eng.step()
        touched = touched or eng.contacts() > 0
    s = eng.state
    rebuilds = eng.n_rebuilds
    s.v[:2] = [[0.2, -0.1, 0.0], [-0.2, 0.1, 0.0]]
    while True:
        before = [a[:2].copy() for a in (s.x, s.v, s.omega)]
        eng.step()
        if eng.contacts() > 0:
            break
    assert eng.n_rebuilds == rebuilds                 # the same list entries as the first contact
    assert np.any(s.torque[:2] != 0)                  # a tangential force
    fresh = make_engine(*before, mu=0.5, gamma_t=20.0)
    fresh.step()
    for a, b in ((s.f, fresh.state.f), (s.torque, fresh.state.torque), (s.v, fresh.state.v)):
        assert np.array_equal(a[:2], b[:2])


def test_frictionless_has_no_tangential_force_or_torque():
    f, t, n, ds, _ = pair_kernel([[5.3, 5, 5.95], [5, 5, 5]], [[1, 0.3, 0], [0, 0, 0]],
                                 [[0, 4, 1], [0, 0, 0]], np.array([1e-3, 0, 0]), mu=0.0, gamma_t=10.0)
    assert np.all(t == 0)
    # a stale history changes nothing (the engine also zeroes it at the rebuild)
    f0 = pair_kernel([[5.3, 5, 5.95], [5, 5, 5]], [[1, 0.3, 0], [0, 0, 0]],
                     [[0, 4, 1], [0, 0, 0]], None, mu=0.0, gamma_t=10.0)[0]
    assert np.array_equal(f, f0)
    d = np.array([0.3, 0, 0.95])
    assert np.allclose(np.cross(f[0], d / np.linalg.norm(d)), 0, atol=1e-9)


def test_rolling_contact_stays_in_tangent_plane():
    """9.5: a spinning sphere rolling over a frozen sphere under gravity:
    Delta s . n = 0 to rounding after every step."""
    # start touching at the static overlap m g / k_n
    z = 5.0 + math.sqrt((1.0 - 1e-5) ** 2 - 0.02 ** 2)
    x = [[5.0, 5.0, 5.0], [5.02, 5.0, z]]
    v = [[0, 0, 0], [0.02, 0.01, 0.0]]
    w = [[0, 0, 0], [0.5, 2.0, 1.0]]
    eng = make_engine(x, v, w, fixed=[1, 0], mu=0.8, gravity=1.0)
    st = eng.state
    checked = 0
    for _ in range(3000):
        eng.step()
        partners, hist = st.slots_of(1)
        if len(partners) == 0:
            break
        d = st.x[1] - st.x[0]
        n = d / np.linalg.norm(d)
        s = hist[0]
        if np.linalg.norm(s) > 0:
            assert abs(s @ n) <= 4e-16 * np.linalg.norm(s)
            checked += 1
    assert checked > 100


def test_pile_contacts_are_mirror_exact():
    """Every contact's two slots are exact negatives; forces obey action-reaction
    bit for bit; every overlapping pair has slots on both sides."""
    n, L = 400, 6.0
    x = insert_random(rng(3, 1), n, L, L, 0.5, 0.5 + n * (math.pi / 6) / (L * L * 0.3))
    eng = make_engine(x, L=L, mu=0.5, gravity=1.0, gamma_t=10.0)
    # a floor keeps the pile together
    import dataclasses
    eng.phys = dataclasses.replace(eng.phys, floor=True)
    eng.advance(80000)
    st = eng.state
    slots = {}
    for i in range(st.n_own):
        for jid, ds in zip(*st.slots_of(i)):
            slots[(int(st.id[i]), int(jid))] = ds
    assert len(slots) > 2 * n
    nonzero = 0
    for (a, b), s in slots.items():
        assert np.array_equal(slots[(b, a)], -s)
        nonzero += bool(np.any(s))
    assert nonzero > len(slots) // 2
    pairs, r = find_contacts(st.x[:n], L, L)
    ids = st.id[:n]
    assert ({(int(min(ids[a], ids[b])), int(max(ids[a], ids[b]))) for a, b in pairs}
            == {(a, b) for (a, b) in slots if a < b})
    for i in range(st.n_own):
        assert np.all(np.diff(st.slots_of(i)[0]) > 0)


@pytest.mark.validation    # 4 x 40000 steps; by default mpi_tests checks ranks x threads
def test_same_bits_for_any_thread_and_chunk_count():
    """Rows split over threads and chunks change no bit of the trajectory
    (frictional, with tangential damping, so every term of the law is used)."""
    import dataclasses
    import numba
    from mpdem import threads as mt
    from mpdem.io.checkpoint import digest, gather_state
    n, L = 300, 6.0
    x = insert_random(rng(5, 1), n, L, L, 0.5, 0.5 + n * (math.pi / 6) / (L * L * 0.3))
    digests = []
    top = numba.config.NUMBA_NUM_THREADS
    for threads, nchunk in ((1, 1), (1, 7), (min(2, top), 8), (top, 3)):
        mt.configure(threads)
        try:
            eng = make_engine(x, L=L, mu=0.5, gravity=1.0, gamma_t=10.0)
            eng.set_chunks(nchunk)
            eng.phys = dataclasses.replace(eng.phys, floor=True)
            eng.advance(40000)
            assert eng.contacts() > n
            digests.append(digest(gather_state(eng.state)))
        finally:
            mt.configure(1)
    assert len(set(digests)) == 1


def test_hertz_scales_spring_and_dashpot_by_sqrt_overlap():
    """docs/model.md 2.7: F = sqrt(delta/d) [k_n delta n - m_eff gamma_n v_n]."""
    from mpdem.kernels.law import MODEL_HERTZ
    x = [[5.0, 5.0, 5.998], [5.0, 5.0, 5.0]]
    v = [[0, 0, -0.3], [0, 0, 0]]
    f_hooke = pair_kernel(x, v, np.zeros((2, 3)), None, mu=0.0, gamma_n=40.0)[0][0, 2]
    f_hertz = pair_kernel(x, v, np.zeros((2, 3)), None, mu=0.0, gamma_n=40.0, model=MODEL_HERTZ)[0][0, 2]
    d = 1.0 - (5.998 - 5.0)
    assert f_hooke == pytest.approx(2e5 * d + 1.0 * 40.0 * 0.3, rel=1e-9)    # bed partner: m_eff = m
    assert f_hertz == pytest.approx(math.sqrt(d) * f_hooke, rel=1e-12)


def test_limit_damping_clips_attraction():
    # separating fast at a tiny overlap: the dashpot outweighs the spring
    x = [[5.0, 5.0, 6.0 - 1e-6], [5.0, 5.0, 5.0]]
    v = [[0, 0, 1.0], [0, 0, 0]]
    f_free = pair_kernel(x, v, np.zeros((2, 3)), None, mu=0.0, gamma_n=50.0)[0][0, 2]
    f_clip = pair_kernel(x, v, np.zeros((2, 3)), None, mu=0.0, gamma_n=50.0, limit_damping=True)[0][0, 2]
    assert f_free < 0                       # attractive, unclipped by default
    assert f_clip == 0.0


def test_rotate_history_keeps_its_length():
    """The documented alternative: project onto the tangent plane, then rescale to the old |Delta s|."""
    s_old = np.array([1e-4, 0.0, 3e-5])     # has a normal component along z
    x = [[5.0, 5.0, 5.999], [5.0, 5.0, 5.0]]
    res = [pair_kernel(x, np.zeros((2, 3)), np.zeros((2, 3)), s_old, mu=10.0, rotate=r)[3][0]
           for r in (False, True)]
    assert res[0][2] == 0.0 and res[1][2] == 0.0
    assert np.linalg.norm(res[0]) == pytest.approx(1e-4, rel=1e-12)          # projection only
    assert np.linalg.norm(res[1]) == pytest.approx(np.linalg.norm(s_old), rel=1e-12)


def test_rotate_history_grows_with_the_sliding_like_the_projection():
    """Rescaling keeps the length of the incremented history: with the history already in the
    tangent plane both schemes add v_t dt (a rescale to the length before the increment would
    keep |Delta s| from ever growing)."""
    s_old = np.array([1e-4, 0.0, 0.0])
    x = [[5.0, 5.0, 5.999], [5.0, 5.0, 5.0]]
    v = [[0.3, 0.0, 0.0], [0.0, 0.0, 0.0]]
    res = [pair_kernel(x, v, np.zeros((2, 3)), s_old, mu=10.0, rotate=r)[3][0] for r in (False, True)]
    assert res[0][0] == pytest.approx(1e-4 + 0.3 * 1e-4, rel=1e-12)
    assert np.array_equal(res[0], res[1])
