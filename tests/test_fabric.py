"""The fabric of the contact normals (``analysis.fabric``) and the free surface's roughness
(``analysis.surface``) on known answers (docs/model.md 6.10)."""
import json
import math

import numpy as np
import pytest

from helpers import SQUEEZE, fcc, write_crystal
from mpdem.analysis import fabric, report, surface


def _fcc_normals():
    """The 12 unit normals of a sphere's neighbours in a cubic-oriented FCC crystal."""
    out = []
    for a, b in ((0, 1), (0, 2), (1, 2)):
        for sa in (1, -1):
            for sb in (1, -1):
                v = np.zeros(3)
                v[a], v[b] = sa, sb
                out.append(v / math.sqrt(2.0))
    return np.array(out)


def _rotate_y(v, deg):
    """Rotate vectors about y, taking +z toward +x by ``deg`` degrees."""
    t = math.radians(deg)
    rot = np.array([[math.cos(t), 0.0, math.sin(t)], [0.0, 1.0, 0.0], [-math.sin(t), 0.0, math.cos(t)]])
    return v @ rot.T


def test_the_fcc_neighbours_are_an_isotropic_fabric_and_one_axis_the_most_anisotropic():
    n = _fcc_normals()
    R = fabric.tensor(n)
    assert np.allclose(R, np.eye(3) / 3.0, atol=1e-15)
    d = fabric.describe(R)
    assert d["anisotropy"] == pytest.approx(0.0, abs=1e-14) and d["R_zz"] == pytest.approx(1.0 / 3.0)
    axis = fabric.describe(fabric.tensor(np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])))
    assert axis["anisotropy"] == pytest.approx(1.0) and axis["R_zz"] == 1.0 and axis["angle"] == 0.0
    assert all(math.isnan(v) for v in fabric.describe(fabric.tensor(np.zeros((0, 3)))).values())


def test_random_normals_are_isotropic_within_their_sampling_error():
    rng = np.random.default_rng(3)
    v = rng.normal(size=(200_000, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    R = fabric.tensor(v)
    assert np.allclose(R, np.eye(3) / 3.0, atol=5e-3)
    assert fabric.describe(R)["anisotropy"] < 0.01


@pytest.mark.parametrize("tilt", [-30.0, 0.0, 12.5, 40.0])
def test_the_principal_angle_follows_a_tilted_fabric(tilt):
    # more contacts along z than along x and y, then the whole set turned about y by ``tilt``
    base = np.concatenate([np.tile([[0.0, 0.0, 1.0]], (3, 1)), [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]]])
    d0 = fabric.describe(fabric.tensor(base))
    d = fabric.describe(fabric.tensor(_rotate_y(base, tilt)))
    assert d["angle"] == pytest.approx(tilt, abs=1e-12)
    assert d["anisotropy"] == pytest.approx(d0["anisotropy"], rel=1e-12)   # a rotation keeps the invariant
    # sheared toward +x the x-z part of R has R_xz of the angle's sign
    assert np.sign(d["R_xz"]) == np.sign(round(tilt, 9))


def test_force_weights_count_each_contact_by_its_force():
    n = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    R = fabric.tensor(n, np.array([2.0, 1.0, 1.0]))
    assert np.allclose(np.diag(R), [0.25, 0.25, 0.5]) and np.trace(R) == pytest.approx(1.0)
    assert fabric.tensor(n, np.zeros(3))[0, 0] != fabric.tensor(n, np.zeros(3))[0, 0]   # nan


def test_the_jackknife_of_equal_columns_is_zero_and_of_random_ones_the_scatter_over_draws():
    # every column the same set of normals: no column-to-column scatter
    n = np.tile(_rotate_y(np.concatenate([np.tile([[0.0, 0, 1]], (3, 1)), np.eye(3)[:2]]), 20.0), (16, 1))
    f = fabric.of_contacts(n, np.repeat(np.arange(16), 5), 16)
    for q in fabric.QUANTITIES:
        assert f[f"{q}_err"] == pytest.approx(0.0, abs=1e-12)
    assert f["n"] == 80 and f["angle"] == pytest.approx(20.0) and f["eigenvalues"][0] >= f["eigenvalues"][2]
    # normals drawn from an anisotropic law (z stretched), columns independent: the jackknife error
    # matches the scatter of the estimate over independent draws
    rng = np.random.default_rng(7)
    K, m = 16, 60
    est, errs = {q: [] for q in fabric.QUANTITIES}, {q: [] for q in fabric.QUANTITIES}
    for _ in range(300):
        v = rng.normal(size=(K * m, 3)) * [1.0, 1.0, 1.6]
        v = _rotate_y(v / np.linalg.norm(v, axis=1)[:, None], 15.0)
        f = fabric.of_contacts(v, rng.integers(0, K, K * m), K)
        for q in fabric.QUANTITIES:
            est[q].append(f[q])
            errs[q].append(f[f"{q}_err"])
    for q in fabric.QUANTITIES:
        assert np.mean(errs[q]) == pytest.approx(np.std(est[q], ddof=1), rel=0.15), q
    assert np.mean(est["angle"]) == pytest.approx(15.0, abs=1.0)


def test_the_angle_error_of_an_axis_near_the_horizontal_does_not_wrap():
    # major axis at -89.9 degrees: leave-one-out angles on both sides of +-90 are one axis, not 180 apart
    rng = np.random.default_rng(2)
    K, m = 16, 50
    v = rng.normal(size=(K * m, 3)) * [1.0, 1.0, 2.0]
    v = _rotate_y(v / np.linalg.norm(v, axis=1)[:, None], -89.9)
    f = fabric.of_contacts(v, np.repeat(np.arange(K), m), K)
    assert abs(abs(f["angle"]) - 89.9) < 3.0 and f["angle_err"] < 3.0


def test_a_contact_across_the_periodic_seam_sits_in_its_midpoint_s_column(tmp_path):
    """Two spheres touching across x = 0 (at x = 0.3 and L - 0.6): the contact's midpoint is at
    x = -0.15, i.e. L - 0.15, in the last column along x, not the middle of the box."""
    from mpdem import config
    from mpdem.analysis import measures
    L = 8.0
    x = np.array([[0.3, 4.1, 5.0], [L - 0.6 + 1e-3, 4.1, 5.0], [4.0, 0.5, 2.0], [4.0, 1.5 - 1e-3, 2.0]])
    fixed = np.zeros(4, np.uint8)
    arrays = {"id": np.arange(4), "x": x, "fixed": fixed}
    cfg = config.load(None, ["run.max_steps=1", f"box.L_x={L}", f"box.L_y={L}", "pour.N=4",
                             "analysis.jackknife_columns=4", "analysis.margin_bottom=0",
                             "analysis.margin_top=0"])
    m = measures.sample(arrays, {"L_x": L, "L_y": L}, cfg)
    assert len(m.pk.pairs) == 2
    mid = measures.midpoints(m)
    seam = int(np.argmax(np.abs(m.cf.nrm[:, 0])))
    assert np.mod(mid[seam, 0], L) == pytest.approx(L - 0.15 + 5e-4)
    from mpdem.analysis import jackknife
    assert jackknife.columns(mid, L, L, 4)[seam] == 3 * 4 + 2      # last column in x, y = 4.1 in the third


def test_a_flat_surface_is_smooth_and_a_sine_has_its_rms_height_and_slope():
    L_x, L_y, cell = 20.0, 10.0, 2.0
    gx, gy = np.meshgrid(np.arange(10) * 2.0 + 1.0, np.arange(5) * 2.0 + 1.0, indexing="ij")
    flat = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, 7.5)])
    below = flat - [0.0, 0.0, 3.0]
    h = surface.heights(np.concatenate([flat, below]), L_x, L_y, cell)
    assert h.shape == (10, 5) and np.all(h == 8.0)
    r = surface.roughness(h, L_x, L_y)
    assert r["h_mean"] == 8.0 and r["h_rms"] == 0.0 and r["slope_x_rms"] == 0.0 and r["slope_y_rms"] == 0.0
    A, k = 0.8, 2 * math.pi / L_x
    wavy = flat.copy()
    wavy[:, 2] += A * np.sin(k * wavy[:, 0])
    r = surface.roughness(surface.heights(wavy, L_x, L_y, cell), L_x, L_y)
    # differences of neighbouring cells: 2 A cos(k (x + c / 2)) sin(k c / 2), rms sqrt(2) A sin(k c / 2)
    assert r["h_rms"] == pytest.approx(A / math.sqrt(2.0), rel=1e-12)
    want = math.degrees(math.atan(math.sqrt(2.0) * A * math.sin(k * cell / 2) / cell))
    assert r["slope_x_rms"] == pytest.approx(want, rel=1e-12)
    assert r["slope_y_rms"] == 0.0 and r["empty"] == 0 and r["cells"] == 50
    # an empty cell is left out, not taken as height 0
    h = surface.heights(wavy[1:], L_x, L_y, cell)
    assert np.isnan(h[0, 0]) and surface.roughness(h, L_x, L_y)["empty"] == 1


A = math.sqrt(2.0) * SQUEEZE     # the crystal's cubic cell [d]


def test_a_crystal_pile_has_the_fcc_fabric_and_a_flat_surface(tmp_path):
    x, L = fcc(8, 24, A)
    # contact midpoints lie on a grid of A / 4: shifted off the column borders (multiples of 2 A) every
    # column holds the same contacts, so the jackknife has nothing to scatter
    x[:, :2] += 0.1 * A
    fixed = (x[:, 2] < A).astype(np.uint8)
    write_crystal(tmp_path / "fcc.h5", x, fixed, L, ["analysis.depth_windows=[%r, %r, 0, 300]" % (A, 5 * A),
                                                     "analysis.surface_cell=2.0"])
    report.analyze(str(tmp_path / "fcc.h5"), plots=False, log=lambda m: None)
    s = json.loads((tmp_path / "fcc-analysis" / "summary.json").read_text())
    f = s["fabric"]
    assert f["columns"] == 16
    win, deep = f["windows"]
    assert not deep["complete"] and "contacts" not in deep
    for part in (f["slab"], win):
        for kind in ("contacts", "forces"):
            d = part[kind]
            assert np.allclose(d["R"], np.eye(3) / 3.0, atol=1e-12)
            assert d["anisotropy"] == pytest.approx(0.0, abs=1e-9)
            assert d["anisotropy_err"] == pytest.approx(0.0, abs=1e-9)
    assert win["contacts"]["n"] > 6 * 2 * 128
    sf = s["surface"]
    assert sf["h_rms"] == pytest.approx(0.0, abs=1e-12) and sf["slope_x_rms"] == pytest.approx(0.0, abs=1e-12)
    assert sf["empty"] == 0 and sf["incline"] == 0.0 and sf["cell"] == 2.0
    assert sf["h_mean"] == pytest.approx(x[:, 2].max() + 0.5)


def test_a_pile_poured_along_gravity_has_no_downslope_direction_and_the_windows_reach_collect(tmp_path, monkeypatch):
    """A pile poured under gravity along -z has no preferred direction in x: R_xz and the major axis's
    angle are zero within their jackknife errors (a committed development pile); collect reads the
    windows' fabric into the per-run numbers."""
    from pathlib import Path
    from mpdem.campaign import depth
    src = Path(__file__).parents[1] / "analysis/results/paper/runs/dev/mu0.5_eps0.88_kn2e5_phi0.13_s1_max_steps1e7"
    # a development pile (some 17 d): a window of 2-10 d fits it, 5-15 d does not
    s, _ = report.analyze(str(src / "packing.npz"), out=str(tmp_path / "a"), plots=False, log=lambda m: None,
                          sets=["analysis.depth_windows=[2, 10, 5, 15]"])
    monkeypatch.setattr(depth, "WINDOWS", ((2.0, 10.0), (5.0, 15.0)))
    for kind in ("contacts", "forces"):
        d = s["fabric"]["slab"][kind]
        assert abs(d["R_xz"]) < 3 * d["R_xz_err"] and abs(d["angle"]) < 3 * d["angle_err"]
        assert d["angle_err"] < 10.0 and d["R_xz_err"] < 0.01       # errors that can tell a tilt
        assert sum(d["eigenvalues"]) == pytest.approx(1.0) and 0 < d["anisotropy_err"] < d["anisotropy"]
    got = [w for w in s["fabric"]["windows"] if w["complete"]]
    from mpdem.campaign.runs import num
    q = depth.window_quantities(s, num)
    for w in got:
        win = (w["depth_lo"], w["depth_hi"])
        assert q[depth.key("fabric_a", win)] == w["contacts"]["anisotropy"]
        assert q[depth.key("fabric_angle", win, True)] == w["contacts"]["angle_err"]
    assert got and all(q[depth.key("fabric_a", win)] != q[depth.key("fabric_a", win)]     # nan: not measured
                       for win in depth.WINDOWS if win not in {(w["depth_lo"], w["depth_hi"]) for w in got})
