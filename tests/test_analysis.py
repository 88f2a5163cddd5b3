"""The analysis stage on structures with known answers (docs/model.md 6, issue 5).

FCC and simple cubic crystals (z = 12 and 6, phi = pi/(3 sqrt 2) and pi/6),
an ideal gas (g = 1), rattler removal on hand-built clusters, the fits on
synthetic data with known parameters, and the kernels against brute force.
"""
import json
import math

import numba
import numpy as np
import pytest

from mpdem.io import checkpoint
from mpdem import config
from mpdem.io import rundir
from mpdem.analysis import bulk, fits, gofr, measures, mobilisation, report
from mpdem.kernels import pairdist
from mpdem.kernels.bundles import make_box

from helpers import SQUEEZE, fcc, mpdem, simple_cubic, write_crystal

def brute_pairs(x, L_x, L_y, r_c):
    d = x[:, None, :] - x[None, :, :]
    d[..., 0] -= L_x * np.round(d[..., 0] / L_x)
    d[..., 1] -= L_y * np.round(d[..., 1] / L_y)
    r = np.sqrt((d ** 2).sum(-1))
    i, j = np.nonzero(np.triu(r < r_c, 1))
    return set(zip(i.tolist(), j.tolist())), r


# ---- kernels -----------------------------------------------------------------

@pytest.mark.parametrize("L,n", [(10.0, 1500), (3.0, 150), (4.2, 300)])
def test_close_pairs_are_all_pairs_within_the_cutoff(L, n):
    rng = np.random.default_rng(int(L * 10))
    x = rng.random((n, 3)) * [L, L, 6.0]
    x[:, :2] += rng.integers(-2, 3, (n, 2)) * L        # unwrapped images find the same pairs
    want, _ = brute_pairs(x, L, L, 1.0)
    got = pairdist.close_pairs(x, L, L, 1.0)
    assert np.all(got[:, 0] < got[:, 1])
    assert set(map(tuple, got.tolist())) == want and len(got) == len(want)


def test_a_sphere_far_above_keeps_the_grid_small_and_the_pairs_right():
    rng = np.random.default_rng(2)
    L, n = 6.0, 800
    x = rng.random((n, 3)) * [L, L, 8.0]
    x[-1, 2] = 1e7
    order, start, dims, geo = pairdist.cell_grid(x, L, L, 1.0)
    assert len(start) <= 2 * n + 2 * dims[0] * dims[1] * 5
    want, _ = brute_pairs(x, L, L, 1.0)
    assert set(map(tuple, pairdist.close_pairs(x, L, L, 1.0).tolist())) == want


def test_pair_histograms_count_every_ordered_pair_once_for_any_thread_count():
    rng = np.random.default_rng(3)
    L, n = 7.0, 900
    x = rng.random((n, 3)) * [L, L, 10.0]
    refs = np.flatnonzero((x[:, 2] > 3) & (x[:, 2] < 7)).astype(np.int64)
    r_max, dr, per_dec, xi_min = 3.0, 0.05, 10, 1e-4
    n_log = int(round(-math.log10(xi_min) * per_dec))
    grid = pairdist.cell_grid(x, L, L, r_max)
    before = numba.get_num_threads()
    out = []
    for t in sorted({1, before}):
        numba.set_num_threads(t)
        out.append(pairdist.pair_histograms(x, refs, make_box(L, L), r_max, dr, int(r_max / dr), xi_min, per_dec,
                                            n_log, grid))
    numba.set_num_threads(before)
    lin, lg, over = out[0]
    for o in out[1:]:
        assert np.array_equal(o[0], lin) and np.array_equal(o[1], lg) and o[2] == over
    _, r = brute_pairs(x, L, L, 1.0)
    r = r[refs]
    r[np.arange(len(refs)), refs] = np.inf
    r = r[r < r_max]
    assert np.array_equal(lin, np.bincount((r / dr).astype(int), minlength=int(r_max / dr)))
    assert over == int((r < 1).sum())
    xi = r[r > 1] - 1
    q = np.floor((np.log10(xi) - math.log10(xi_min)) * per_dec).astype(int)
    assert np.array_equal(lg, np.bincount(q[(q >= 0) & (q < n_log)], minlength=n_log))


# ---- crystals ----------------------------------------------------------------

def test_fcc_has_twelve_contacts_and_its_packing_fraction():
    a = math.sqrt(2.0) * SQUEEZE
    x, L = fcc(5, 12, a)
    fixed = (x[:, 2] < a).astype(np.uint8)          # the two lowest layers are the bed
    s = bulk.bulk_summary(x, fixed, L, L, mu=0.5)
    assert s["n_bulk"] > 200
    # surface: the top layer (phi there is half the plateau's); margins clamp(0.2 (h - z_bed), 3, 10)
    top = x[:, 2].max()
    assert s["z_bed"] == pytest.approx(0.75 * a) and abs(s["h"] - top) <= 0.5
    assert s["margin_bottom"] == pytest.approx(min(max(0.2 * (s["h"] - s["z_bed"]), 3), 10))
    assert s["z1"] == pytest.approx(s["z_bed"] + s["margin_bottom"])
    assert s["z2"] == pytest.approx(s["h"] - s["margin_top"])
    assert s["n_bulk"] == int(((x[:, 2] >= s["z1"]) & (x[:, 2] <= s["z2"]) & (fixed == 0)).sum())
    assert s["z"] == 12.0 and s["z_no_rattlers"] == 12.0 and s["rattler_fraction"] == 0.0
    assert s["P_z"][12] == 1.0
    # a slab of whole periods (a/2 per layer) holds exactly the crystal's fraction
    zm = x[fixed == 0, 2]
    phi = bulk.packing_fraction(zm, L, L, 3 * a + 0.1, 7 * a + 0.1)
    assert phi == pytest.approx(math.pi / (3 * math.sqrt(2)) / SQUEEZE ** 3, rel=1e-12)
    # the automatic slab is not a whole number of layers: within the layering ripple
    assert s["phi"] == pytest.approx(math.pi / (3 * math.sqrt(2)), abs=0.02)


def test_simple_cubic_has_six_contacts_and_pi_over_six():
    x, L = simple_cubic(6, 24, SQUEEZE)
    fixed = (x[:, 2] < 1).astype(np.uint8)
    s = bulk.bulk_summary(x, fixed, L, L, mu=0.0)
    # n_min = 4 at mu = 0: six contacts each, nobody is a rattler
    assert s["z"] == 6.0 and s["z_no_rattlers"] == 6.0 and s["rattler_fraction"] == 0.0
    assert s["P_z"][6] == 1.0
    zm = x[fixed == 0, 2]
    assert bulk.packing_fraction(zm, L, L, 5 * SQUEEZE, 15 * SQUEEZE) == pytest.approx(
        math.pi / 6 / SQUEEZE ** 3, rel=1e-12)
    # exactly touching spheres are not in contact (delta > 0 strictly)
    xt, Lt = simple_cubic(4, 4, 1.0)
    assert len(bulk.find_contacts(xt, Lt, Lt)[0]) == 0


def test_paper_sized_pile_gets_ten_d_margins_and_short_ones_the_clamp():
    for layers, want in ((60, 10.0), (20, None)):
        x, L = simple_cubic(6, layers, SQUEEZE)
        zm = x[:, 2]
        reg = bulk.bulk_region(zm, 0.0, L, L)
        if want is None:
            want = min(max(0.2 * reg["h"], 3.0), 10.0)
            assert want < 10
        assert reg["margin_bottom"] == pytest.approx(want) and reg["margin_top"] == pytest.approx(want)
        assert reg["z2"] - reg["z1"] == pytest.approx(reg["h"] - 2 * want)
        # the halved-margin slab of 6.1.4 is wider by one margin
        half = bulk.bulk_region(zm, 0.0, L, L, 0.5 * want, 0.5 * want)
        assert half["z2"] - half["z1"] == pytest.approx(reg["z2"] - reg["z1"] + want)


def test_slab_volume_is_the_exact_cap_volume():
    from mpdem.kernels.particle import R
    for hcap in (0.1, 0.5, 0.8):
        # cut at height hcap below the top: the cap above the plane
        v = bulk.slab_volume(np.array([0.0]), R - hcap, 10.0)[0]
        assert v == pytest.approx(math.pi * hcap ** 2 * (3 * R - hcap) / 3, rel=1e-13)
    assert bulk.slab_volume(np.array([0.0]), -1, 1)[0] == pytest.approx(math.pi / 6, rel=1e-14)


# ---- ideal gas -----------------------------------------------------------------

def test_ideal_gas_has_g_of_one_in_the_slab():
    # independent ideal gases in the slab; g(r) per bin against 1 within the scatter over samples
    rng = np.random.default_rng(11)
    L, H, n = 12.0, 30.0, 4000
    lin, log = [], []
    for _ in range(16):
        x = rng.random((n, 3)) * [L, L, H]
        g = gofr.radial_distribution(x, L, L, 0.0, H, r_max=4.0, dr=0.05, xi_min=1e-3, per_decade=5)
        assert g["rho"] == pytest.approx(n / (L * L * H))
        assert g["n_ref"] == int(((x[:, 2] >= 4) & (x[:, 2] <= H - 4)).sum())
        lin.append(g["g"][g["r_lo"] >= 0.5])
        log.append(g["g_xi"][g["xi_lo"] >= 1e-2])
    for gs in (np.array(lin), np.array(log)):
        mean, sem = gs.mean(axis=0), gs.std(axis=0, ddof=1) / math.sqrt(len(gs))
        assert np.all(np.abs(mean - 1) < 4.5 * sem), (mean, sem)
        assert abs(gs.mean() - 1) < 3 * gs.mean(axis=1).std(ddof=1) / math.sqrt(len(gs))
    # a wrong normalisation (say, the shell of r_hi only) would be off by several per cent
    assert np.abs(np.array(lin).mean(axis=0) - 1).max() < 0.03


def test_g_of_r_range_must_be_below_half_the_box():
    x = np.random.default_rng(0).random((100, 3)) * 10
    with pytest.raises(ValueError, match="half the box"):
        gofr.radial_distribution(x, 10.0, 10.0, 0.0, 10.0, r_max=5.0)


# ---- rattlers ------------------------------------------------------------------

def test_rattler_removal_cascades_on_a_hand_built_cluster():
    # 0 is a bed sphere; 1-2-3 a triangle resting on it; 4-5 a chain hanging from 1; 6 alone
    pairs = np.array([[0, 1], [1, 2], [2, 3], [1, 3], [1, 5], [4, 5]])
    removable = np.array([False, True, True, True, True, True, True])
    kept, counts = bulk.remove_rattlers(7, pairs, removable, n_min=2)
    # 4 has one contact -> out; then 5 has one -> out; 6 has none -> out
    assert kept.tolist() == [True, True, True, True, False, False, False]
    assert counts.tolist() == [1, 3, 2, 2, 0, 0, 0]
    # with n_min = 4 (frictionless) the whole cluster goes, the bed stays
    kept, counts = bulk.remove_rattlers(7, pairs, removable, n_min=4)
    assert kept.tolist() == [True] + [False] * 6 and counts.sum() == 0
    # the bulk numbers of the n_min = 2 case: spheres 1..6 are the bulk
    k2, c2 = bulk.remove_rattlers(7, pairs, removable, 2)
    c = bulk.coordination(np.bincount(pairs.ravel(), minlength=7), k2, c2, removable)
    assert c["z"] == pytest.approx((4 + 2 + 2 + 1 + 2 + 0) / 6) and c["z_no_rattlers"] == pytest.approx(7 / 3)
    assert c["rattler_fraction"] == pytest.approx(0.5) and c["n_bulk"] == 6
    # P(n) over the six: n = 4, 2, 2, 1, 2, 0; without rattlers 3, 2, 2
    assert c["P_z"][:5] == pytest.approx([1 / 6, 1 / 6, 3 / 6, 0, 1 / 6]) and sum(c["P_z"]) == pytest.approx(1)
    assert c["P_z_no_rattlers"][:4] == pytest.approx([0, 0, 2 / 3, 1 / 3])


def test_rattlers_found_from_positions():
    # a square of four touching spheres in a plane, one sphere resting on one of them only
    s = SQUEEZE
    x = np.array([[2, 2, 5], [2 + s, 2, 5], [2, 2 + s, 5], [2 + s, 2 + s, 5], [2, 2, 5 + s]])
    pk = bulk.Packing(x, np.zeros(5), 10.0, 10.0, mu=0.5)
    assert pk.counts.tolist() == [3, 2, 2, 2, 1]
    assert pk.kept.tolist() == [True, True, True, True, False]


# ---- mobilisation --------------------------------------------------------------

def test_force_ratios_histogram_and_mobilised_fraction():
    mu = 0.5
    F_n = np.array([1.0, 2.0, 1.0, 4.0, -1.0])
    zeta = np.array([0.1, 0.55, 1.0, 0.995, 0.3])
    F_t = np.zeros((5, 3))
    F_t[:, 1] = zeta * mu * np.abs(F_n)
    fr = mobilisation.force_ratios(F_n, F_t, mu, bins=10, mobilised=0.99)
    assert fr["n_contacts"] == 4 and fr["n_tensile"] == 1 and fr["n_above_one"] == 0
    assert fr["count"].tolist() == [0, 1, 0, 0, 0, 1, 0, 0, 0, 2]
    assert fr["P_zeta"].max() == 1.0 and fr["mobilised_fraction"] == pytest.approx(0.5)
    big = mobilisation.force_ratios(F_n, F_t * 10, 5.0, bins=10)      # mu >= 1: F_t / F_n as well
    # F_t/F_n = 10 zeta mu = 0.5, 2.75, 5, 4.975: one on [0, 1), three beyond it (counted)
    assert big["count_ratio"].tolist() == [0, 0, 0, 0, 0, 1, 0, 0, 0, 0] and big["n_ratio_above_one"] == 3


def test_the_generalized_isostatic_count_removes_one_degree_of_freedom_per_mobilised_contact():
    """docs/model.md 6.2: with N_m fully mobilised contacts among N spheres, 3 N z / 2 - N_m = 6 N, so
    z_iso = 4 + 2 N_m / (3 N) = 4 + n_m / 3 with n_m = 2 N_m / N counted per sphere as z is."""
    from types import SimpleNamespace
    x, L = simple_cubic(4, 4, SQUEEZE)
    pk = bulk.Packing(x, np.zeros(len(x)), L, L, mu=0.5)
    n, P = len(x), len(pk.pairs)
    zeta = np.zeros(P)
    zeta[: P // 5] = 1.0                                   # N_m mobilised contacts
    cf = SimpleNamespace(zeta=zeta, from_file=np.ones(P, bool))
    every = np.ones(n, bool)
    iso = measures.isostatic(pk, cf, np.ones(P, bool), every, every, 0.5, 0.99)
    N_m = P // 5
    assert iso["n_m"] == pytest.approx(2 * N_m / n)
    assert iso["z_iso"] == pytest.approx(4 + 2 * N_m / (3 * n))
    # the counting with every contact mobilised: 3 N z / 2 - N z / 2 = 6 N needs z = 6
    cf.zeta[:] = 1.0
    z = 2 * P / n
    assert measures.isostatic(pk, cf, np.ones(P, bool), every, every, 0.5, 0.99)["z_iso"] == pytest.approx(4 + z / 3)


def test_bulk_contacts_select_by_midpoint():
    ids = np.array([3, 7, 9])
    z = np.array([1.0, 2.0, 4.0])
    sel = mobilisation.bulk_contacts({"id_i": np.array([3, 7, 3]), "id_j": np.array([7, 9, 9])}, ids, z, 1.4, 2.6)
    assert sel.tolist() == [True, False, True]


# ---- fits ----------------------------------------------------------------------

def test_the_default_alpha_window_is_the_same_for_every_stiffness():
    assert fits.fit_window() == (1e-3, 5e-2)
    assert fits.fit_window(5e-2, -1.0) == (1e-3, 5e-2)      # older configs' "automatic"
    assert fits.fit_window(1e-2, 3e-3) == (3e-3, 1e-2)


def test_eq7_fit_recovers_the_paper_like_parameters():
    rng = np.random.default_rng(7)
    k = np.repeat([2e5, 2e6, 2e7, 2e8, 2e9], 3)
    z_true = fits.eq7(k, 6.01, 0.134, 0.498)
    sigma = np.full(k.size, 2e-3)
    z = z_true + sigma * rng.standard_normal(k.size)
    f = fits.fit_eq7(k, z, sigma)
    for name, want in (("z_inf", 6.01), ("a", 0.134), ("alpha_n", 0.498)):
        assert abs(f[name] - want) < 4 * f[f"{name}_err"], (name, f)
    assert f["a_tilde"] == pytest.approx(0.134 * 2e5 ** 0.498, rel=0.3)
    assert f["weighted"] and f["dof"] == k.size - 3


def test_an_eq7_fit_whose_parameters_the_points_cannot_tell_apart_is_not_determined():
    """z that does not fall with k_n: alpha_n -> 0, where z_inf and a trade off exactly; the fit says
    so (``determined`` false, its parameters correlated to 1) instead of giving numbers like
    -321 +- 6e12. A paper-like ladder is determined."""
    k = np.array([2e5, 2e6, 2e7])
    flat = fits.fit_eq7(k, np.array([4.85, 4.85 + 1e-6, 4.85 - 1e-6]), np.full(3, 0.02))
    assert not flat["determined"] and flat["correlation"] > 1 - 1e-9
    good = fits.fit_eq7(np.repeat([2e5, 2e6, 2e7, 2e8], 2), fits.eq7(np.repeat([2e5, 2e6, 2e7, 2e8], 2), 6.01, 0.134,
                                                                       0.498), np.full(8, 2e-3))
    assert good["determined"] and good["correlation"] < 0.999


def test_eq7_fit_weights_by_the_standard_errors():
    # the stiffest point is far off but has a large error: a weighted fit discounts it
    k = np.array([2e5, 6e5, 2e6, 6e6, 2e7, 6e7, 2e8, 2e9])
    sigma = np.full(k.size, 1e-4)
    sigma[-1] = 0.2
    z = fits.eq7(k, 6.01, 0.134, 0.498)
    z[-1] += 0.3
    w = fits.fit_eq7(k, z, sigma)
    u = fits.fit_eq7(k, z)
    assert w["z_inf"] == pytest.approx(6.01, abs=1e-3) and w["alpha_n"] == pytest.approx(0.498, abs=2e-3)
    assert abs(u["z_inf"] - 6.01) > 0.02 and not u["weighted"]


def test_eq9_fit_recovers_the_paper_parameters():
    rng = np.random.default_rng(9)
    phi_i = np.repeat([0.02, 0.05, 0.08, 0.13, 0.20, 0.30], 4)
    sigma = np.full(phi_i.size, 5e-4)
    phi_f = fits.eq9(phi_i, 0.5778, 0.0567, 4.3) + sigma * rng.standard_normal(phi_i.size)
    f = fits.fit_eq9(phi_i, phi_f, sigma)
    for name, want in (("A", 0.5778), ("B", 0.0567), ("C", 4.3)):
        assert abs(f[name] - want) < 4 * f[f"{name}_err"], (name, f)
    with pytest.raises(ValueError, match="cannot fix 3 parameters"):
        fits.fit_eq9(phi_i[:2], phi_f[:2])


# ---- mpdem analyze end to end --------------------------------------------------

def test_analyze_a_crystal_file_writes_summary_tables_and_plots(tmp_path):
    a = math.sqrt(2.0) * SQUEEZE
    x, L = fcc(8, 12, a)
    fixed = (x[:, 2] < a).astype(np.uint8)
    path = tmp_path / "fcc.h5"
    write_crystal(path, x, fixed, L)
    s, out = report.analyze(str(path), plots=True, log=lambda m: None)
    assert out == str(tmp_path / "fcc-analysis")
    saved = json.loads((tmp_path / "fcc-analysis" / "summary.json").read_text())
    for k in ("z", "z_no_rattlers", "rattler_fraction", "phi", "n_bulk", "z1", "z2", "alpha", "alpha_err"):
        assert k in saved
    assert saved["z"] == 12.0 and saved["step"] == 7 and saved["params"]["contact.mu"] == 0.5
    # every contact of the crystal is at zeta = 0.5
    assert saved["zeta"]["n_contacts"] > 0 and saved["zeta"]["mobilised_fraction"] == 0.0
    zeta = np.genfromtxt(tmp_path / "fcc-analysis" / "zeta.csv", delimiter=",", names=True)
    assert zeta["count"].sum() == saved["zeta"]["n_contacts"] and zeta["P"][25] == 1.0
    # the crystal's g(r): twelve neighbours at d (the contacts), six at sqrt(2) d
    g = np.genfromtxt(tmp_path / "fcc-analysis" / "gofr.csv", delimiter=",", names=True)
    n_ref = saved["gofr"]["n_ref"]
    assert g["count"][99] == 12 * n_ref and g["count"][141] == 6 * n_ref
    assert saved["gofr"]["near_contacts_per_ref"] == 12.0
    for name in ("packing", "profile", "coordination", "gofr", "gofr_near", "zeta"):
        assert (tmp_path / "fcc-analysis" / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        if name not in ("gofr_near", "packing"):
            assert (tmp_path / "fcc-analysis" / f"{name}.csv").exists()
    assert not list((tmp_path / "fcc-analysis").glob("*.tmp"))
    # the picture shows spheres: the crystal's 12 contacts in the slab's colour, the bed's greys
    import matplotlib.image
    img = matplotlib.image.imread(tmp_path / "fcc-analysis" / "packing.png")[..., :3]
    colours = {tuple(c) for c in (img * 255).astype(int).reshape(-1, 3)[::7]}
    assert len(colours) > 50
    from matplotlib import colormaps
    twelve = (np.array(colormaps["viridis"].resampled(13)(12)[:3]) * 255).astype(int)
    assert (np.abs((img * 255).astype(int) - twelve).max(axis=-1) <= 2).sum() > 1000


def test_a_new_measurement_is_one_row_in_the_table(tmp_path, monkeypatch):
    """A measurement added to ``measures.MEASURES`` alone runs after the others (it reads what they
    left) and lands in summary.json."""
    def spheres_above_bulk(m):
        m.summary["above_bulk"] = int((m.pk.x[m.pk.mobile, 2] > m.z2).sum())
    row = measures.Measure("above_bulk", spheres_above_bulk, "mobile spheres above the slab")
    monkeypatch.setattr(measures, "MEASURES", measures.MEASURES + (row,))
    a = math.sqrt(2.0) * SQUEEZE
    x, L = fcc(4, 12, a)
    fixed = (x[:, 2] < a).astype(np.uint8)
    write_crystal(tmp_path / "fcc.h5", x, fixed, L)
    report.analyze(str(tmp_path / "fcc.h5"), plots=False, log=lambda m: None)
    saved = json.loads((tmp_path / "fcc-analysis" / "summary.json").read_text())
    assert saved["above_bulk"] == int(((x[:, 2] > saved["z2"]) & (fixed == 0)).sum()) > 0


def test_analyze_settings_and_errors(tmp_path):
    x, L = simple_cubic(6, 24, SQUEEZE)
    fixed = (x[:, 2] < 1).astype(np.uint8)
    path = tmp_path / "sc.h5"
    write_crystal(path, x, fixed, L, ["contact.mu=0"])
    s, _ = report.analyze(str(path), out=str(tmp_path / "o"), sets=["analysis.margin_bottom=4"],
                          plots=False, log=lambda m: None)
    assert s["margin_bottom"] == 4.0 and s["z"] == 6.0 and s["zeta"] is None
    assert not (tmp_path / "o" / "profile.png").exists()
    with pytest.raises(config.ConfigError, match="only analysis"):
        report.analyze(str(path), sets=["contact.mu=0.3"], plots=False, log=lambda m: None)
    with pytest.raises(config.ConfigError, match="analysis.g_r_max"):
        report.analyze(str(path), sets=["analysis.g_r_max=0.5"], plots=False, log=lambda m: None)
    with pytest.raises(report.AnalysisError, match="no final.h5"):
        report.analyze(str(tmp_path), plots=False, log=lambda m: None)
    with pytest.raises(report.AnalysisError, match="no such file"):
        report.locate(str(tmp_path / "missing.h5"))


def test_analyze_without_contact_forces_or_room_for_g_of_r(tmp_path):
    x, L = simple_cubic(6, 12, SQUEEZE)
    fixed = (x[:, 2] < 1).astype(np.uint8)
    path = tmp_path / "thin.h5"
    write_crystal(path, x, fixed, L)
    # a checkpoint-like file: the contact list removed
    arrays, attrs = checkpoint.read_state(str(path), pairs=True)
    for k in checkpoint.PAIR_FIELDS:
        arrays.pop(k)
    attrs["kind"] = "checkpoint"
    checkpoint.write(str(tmp_path / "ckpt.h5"), arrays, attrs)
    s, out = report.analyze(str(tmp_path / "ckpt.h5"), sets=["analysis.margin_bottom=3.5"], log=lambda m: None)
    assert s["zeta"] is None and "no contact forces in a checkpoint" in s["zeta_note"]
    # a 12 d pile with 3.5 d margins leaves a ~4 d slab: g(r) cut to a third of it
    third = (s["z2"] - s["z1"]) / 3
    assert 1 < third < 1.5 and s["gofr"]["r_max"] == pytest.approx(math.floor(third / 0.01) * 0.01)
    assert s["gofr"]["near_r_max"] == s["gofr"]["r_max"] and s["z"] == 6.0
    s, out = report.analyze(str(path), out=str(tmp_path / "thin"), sets=["analysis.margin_bottom=4.5"],
                            log=lambda m: None)
    # a 2 d slab: z and phi, but no g(r), said so
    assert s["z"] == 6.0 and s["gofr"] is None and math.isnan(s["alpha"])
    assert any("too thin for g(r)" in w for w in s["warnings"])
    saved = json.loads((tmp_path / "thin" / "summary.json").read_text())
    assert saved["alpha"] is None and saved["z"] == 6.0
    assert (tmp_path / "thin" / "profile.png").exists() and not (tmp_path / "thin" / "gofr.csv").exists()


def test_analyze_cli_on_a_run_directory(tmp_path):
    run = tmp_path / "run"
    (run / "snapshots").mkdir(parents=True)
    a = math.sqrt(2.0) * SQUEEZE
    x, L = fcc(8, 12, a)
    fixed = (x[:, 2] < a).astype(np.uint8)
    write_crystal(run / "final.h5", x, fixed, L)
    write_crystal(run / "snapshots" / "snap-00002.h5", x, fixed, L)
    p = mpdem("analyze", run, "--no-plots")
    assert p.returncode == 0, p.stderr
    assert "z = 12.000" in p.stdout
    assert json.loads((run / "analysis" / "summary.json").read_text())["z"] == 12.0
    p = mpdem("analyze", run / "snapshots" / "snap-00002.h5", "--no-plots", "--quiet")
    assert p.returncode == 0 and p.stdout == ""
    assert (run / "analysis" / "snap-00002" / "summary.json").exists()
    p = mpdem("analyze", tmp_path)
    assert p.returncode == 1 and "no final.h5" in p.stderr


def test_a_packing_file_keeps_what_analyze_needs_and_analyses_alike(tmp_path):
    from mpdem.io import export, packing
    run = tmp_path / "run"
    run.mkdir()
    a = math.sqrt(2.0) * SQUEEZE
    x, L = fcc(8, 12, a)
    fixed = (x[:, 2] < a).astype(np.uint8)
    write_crystal(run / "final.h5", x, fixed, L, converged=True)
    out = export.export_file(str(run / "final.h5"), "packing")
    assert out == str(run / "packing.npz") and packing.is_packing(out) and not (run / "packing.npz.tmp").exists()
    arrays, attrs = packing.read(out)
    full, fattrs = checkpoint.read_state(str(run / "final.h5"), pairs=True)
    for k in packing.FIELDS:
        assert np.array_equal(arrays[k], full[k]), k
    assert attrs["config"] == fattrs["config"] and attrs["converged"] is True and attrs["L_x"] == L
    s_full, _ = report.analyze(str(run), out=str(tmp_path / "a1"), plots=False, log=lambda m: None)
    (run / "final.h5").unlink()
    s_pack, out_dir = report.analyze(str(run), plots=False, log=lambda m: None)
    assert out_dir == str(run / "analysis") and s_pack["source"].endswith("packing.npz")
    for k in ("z", "z_no_rattlers", "phi", "alpha", "backbone", "bands", "P_f", "zeta", "order"):
        assert rundir.json_safe(s_pack[k]) == rundir.json_safe(s_full[k]), k
    # analysed again where its final.h5 was analysed, the packing keeps what it cannot measure (the flow
    # of the velocities it lacks), from the summary of the same step, and says so
    assert s_pack["flow"] is None and "carried" not in s_pack
    s_first, _ = report.analyze(str(run / "packing.npz"), out=str(tmp_path / "a1"), plots=False, log=lambda m: None)
    assert s_first["flow"] == rundir.json_safe(s_full["flow"]) and s_first["flow"]["v_x_mean"] == 0.0
    assert s_first["carried"]["keys"] == ["flow"] and s_first["carried"]["from"].endswith("final.h5")
    assert "flow_note" not in s_first and s_first["z"] == s_full["z"]
    # analysed a third time, the origin stays the final.h5
    s_third, _ = report.analyze(str(run / "packing.npz"), out=str(tmp_path / "a1"), plots=False, log=lambda m: None)
    assert s_third["carried"]["from"] == s_first["carried"]["from"] and s_third["flow"] == s_first["flow"]
    # not from a summary of another state: another step, or another run's parameters at the same step
    old = json.loads((tmp_path / "a1" / "summary.json").read_text())
    for other in (dict(old, step=old["step"] + 1), dict(old, params=dict(old["params"], **{"contact.mu": 0.25}))):
        (tmp_path / "a1" / "summary.json").write_text(json.dumps(other))
        s_other, _ = report.analyze(str(run / "packing.npz"), out=str(tmp_path / "a1"), plots=False,
                                    log=lambda m: None)
        assert s_other["flow"] is None and "carried" not in s_other
    # a damaged or foreign file is refused with its name
    bad = tmp_path / "bad.npz"
    bad.write_bytes(open(out, "rb").read()[:2000])
    with pytest.raises(packing.PackingFileError, match="bad.npz"):
        packing.read(str(bad))
    np.savez_compressed(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(packing.PackingFileError, match="not an mpdem packing file"):
        packing.read(str(tmp_path / "other.npz"))
    # a state without a contact list (a checkpoint) has no packing
    with pytest.raises(packing.PackingFileError, match="no contact list"):
        no_pairs = {k: v for k, v in full.items() if k not in checkpoint.PAIR_FIELDS}
        packing.write(str(tmp_path / "c.npz"), no_pairs, fattrs)


def test_the_one_json_writer_writes_nan_as_null(tmp_path):
    import json as js
    rundir.write_json(str(tmp_path / "s.json"), {"z": float("nan"), "a": [np.float64(1.5), np.inf], "n": np.int64(3)})
    assert js.loads((tmp_path / "s.json").read_text()) == {"z": None, "a": [1.5, None], "n": 3}
    assert "NaN" not in (tmp_path / "s.json").read_text() and not (tmp_path / "s.json.tmp").exists()


def test_analyze_plots_in_the_figure_formats_asked(tmp_path):
    x, L = simple_cubic(6, 24, SQUEEZE)
    fixed = (x[:, 2] < 1).astype(np.uint8)
    write_crystal(tmp_path / "sc.h5", x, fixed, L, ["contact.mu=0"])
    report.analyze(str(tmp_path / "sc.h5"), out=str(tmp_path / "o"), sets=["analysis.figure_format=svg,pdf"],
                   log=lambda m: None)
    assert (tmp_path / "o" / "profile.svg").exists() and (tmp_path / "o" / "profile.pdf").exists()
    assert not list((tmp_path / "o").glob("*.png"))
    with pytest.raises(config.ConfigError, match="analysis.figure_format"):
        report.analyze(str(tmp_path / "sc.h5"), sets=["analysis.figure_format=gif"], log=lambda m: None)
