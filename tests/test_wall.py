"""The wall plane z = 0 under the bed (bed.wall): exact answers, and the runs it lets through."""
import json
import math
import os
import shutil

import h5py
import numpy as np
import pytest

from mpdem.io import lammps
from mpdem.config import gamma_n_from_epsilon, restitution

from helpers import make_engine, mpdem

K_N = 2e5


def test_a_sphere_at_rest_on_the_wall_overlaps_it_by_m_g_over_k_n():
    for mu in (0.0, 0.5):
        eng = make_engine([[2.0, 2.0, 0.5]], L=5.0, gravity=1.0, mu=mu, wall=True)
        eng.advance(30000)                      # 3 tau: the bounce is damped out (rate gamma_n / 2 = 26 per tau)
        assert abs(eng.state.v[0, 2]) < 1e-12
        assert eng.state.x[0, 2] == pytest.approx(0.5 - 1.0 / K_N, rel=0, abs=1e-12)


def test_a_head_on_impact_on_the_wall_has_the_restitution_of_m_eff_m():
    eps = 0.88
    g_n = gamma_n_from_epsilon(eps, K_N)
    e_wall = restitution(g_n, K_N, m_eff=1.0)      # the wall's m_eff is the sphere's mass, not m / 2
    t_col = math.pi / math.sqrt(K_N - g_n ** 2 / 4)
    errors = []
    for dt in (1e-4, 1e-5):
        eng = make_engine([[2.0, 2.0, 0.55]], v=[[0.0, 0.0, -1.0]], L=5.0, wall=True, dt=dt)
        while eng.state.x[0, 2] < 0.6:
            eng.step()
        errors.append(abs(eng.state.v[0, 2] / e_wall - 1))
        # first order in dt / t_col: contact starts and ends between steps
        assert errors[-1] < dt / t_col
    assert errors[1] < errors[0] / 3
    assert e_wall != pytest.approx(eps, rel=1e-2)


def test_a_sliding_sphere_ends_rolling_at_five_sevenths_of_its_speed():
    # kinetic friction takes m v0 = m v + (I / R) omega with v = R omega at the end: v = 5/7 v0
    k_t = 2 * K_N / 7
    eng = make_engine([[2.0, 2.0, 0.5 - 1.0 / K_N]], v=[[1.0, 0.0, 0.0]], L=5.0, gravity=1.0, mu=0.2,
                      wall=True, k_t=k_t, gamma_t=gamma_n_from_epsilon(0.88, K_N) / 2)
    eng.advance(40000)
    v, w = eng.state.v[0], eng.state.omega[0]
    assert v[0] == pytest.approx(5 / 7, rel=2e-3)
    assert 0.5 * w[1] == pytest.approx(v[0], rel=2e-3)     # rolling: v = R omega_y
    assert abs(v[1]) < 1e-12 and abs(w[0]) < 1e-12


def under_the_bed(tmp_path):
    """The LAMMPS test state with three mobile spheres moved under its bed, onto the wall plane,
    where the spheres in their way (bed and pile) are taken out: a sparse bed with holes."""
    src = os.path.join(os.path.dirname(__file__), "data", "lammps_sphere.data")
    t = lammps.read(src, (2,))
    spots = np.array([[1.3, 1.1, 0.5], [5.2, 7.6, 0.5], [8.8, 3.3, 0.5]])
    moved = np.flatnonzero(t["fixed"] == 0)[:3]
    t["x"][moved] = spots
    d = t["x"][:, None, :] - spots[None, :, :]
    d[..., :2] -= 10.0 * np.round(d[..., :2] / 10.0)
    keep = (np.linalg.norm(d, axis=2).min(axis=1) > 1.0)
    keep[moved] = True
    out = tmp_path / "under.data"
    out.write_text("".join(lammps.data_lines(t["id"][keep], t["x"][keep], t["v"][keep], t["omega"][keep],
                                             t["fixed"][keep], 10.0, 10.0, "three spheres under the bed")))
    return str(out), t["id"][moved]


@pytest.mark.parametrize("mu", [0.0, 0.5])
def test_a_state_with_spheres_under_the_bed_runs_with_the_wall_and_is_refused_without(tmp_path, mu):
    path, low = under_the_bed(tmp_path)
    base = ["--set", f'run.initial_file="{path}"', "--set", "run.fixed_types=[2]", "--set", f"contact.mu={mu}"]
    p = mpdem("run", "--out", "nowall", "--set", "run.max_steps=10", *base, cwd=tmp_path)
    assert p.returncode == 1 and "is not above" in p.out and "bed.wall = true" in p.out, p.out
    p = mpdem("run", "--out", "wall", "--set", "run.max_steps=3000", "--set", "bed.wall=true",
              "--set", "output.checkpoint_every=1000", *base, cwd=tmp_path)
    assert p.returncode == 3, p.out
    s = json.load(open(tmp_path / "wall" / "summary.json"))
    with h5py.File(tmp_path / "wall" / "final.h5") as f:
        z = dict(zip(f["particles/id"][:], f["particles/x"][:, 2]))
        assert "wall" in f and f["wall/wall_ds"].shape == f["particles/x"].shape
    # the three rest on the wall (in 0.3 tau they have sagged into it by about m g / k_n)
    assert all(0.49 < z[i] < 0.5 for i in low)
    # restart from the middle checkpoint gives the straight run's digest (the wall history is saved)
    shutil.copytree(tmp_path / "wall", tmp_path / "again")
    p = mpdem("restart", os.path.join("again", "checkpoints", "ckpt-00001.h5"), cwd=tmp_path)
    assert p.returncode == 3, p.out
    assert json.load(open(tmp_path / "again" / "summary.json"))["digest"] == s["digest"]
