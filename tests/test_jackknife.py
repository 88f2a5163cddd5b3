"""The jackknife over lateral columns (``analysis.jackknife``) and the fixed depth windows
(``measures.depth_windows``) on known answers (docs/model.md 6.10)."""
import json
import math

import numpy as np
import pytest

from helpers import SQUEEZE, fcc, write_crystal
from mpdem.analysis import jackknife, report


def test_columns_split_the_box_into_k_by_k_and_wrap():
    x = np.array([[0.1, 0.1, 0.0], [9.9, 0.1, 5.0], [0.1, 9.9, 0.0], [5.0, 5.0, 0.0], [10.1, -0.1, 0.0]])
    assert jackknife.columns(x, 10.0, 10.0, 2).tolist() == [0, 2, 1, 3, 1]
    with pytest.raises(ValueError, match="k >= 2"):
        jackknife.columns(x, 10.0, 10.0, 1)


def test_the_jackknife_of_a_mean_of_equal_columns_is_the_standard_error_of_their_means():
    rng = np.random.default_rng(1)
    K, m = 16, 40
    values = rng.normal(5.0, 1.0, K * m)
    groups = np.repeat(np.arange(K), m)
    est, err = jackknife.mean(values, groups, K)
    means = values.reshape(K, m).mean(axis=1)
    assert est == pytest.approx(values.mean(), rel=1e-14)
    assert err == pytest.approx(means.std(ddof=1) / math.sqrt(K), rel=1e-12)


def test_the_jackknife_error_is_the_scatter_over_draws_where_neighbours_are_correlated():
    # each column shares an offset (spheres of one column correlated): the spheres' own scatter over
    # sqrt(n) is 2.2 times too small; the jackknife over columns gives the scatter of the estimate
    rng = np.random.default_rng(2)
    K, m, draws = 16, 50, 400
    groups = np.repeat(np.arange(K), m)
    est, errs, naive = [], [], []
    for _ in range(draws):
        v = rng.normal(0.0, 1.0, K * m) + np.repeat(rng.normal(0.0, 0.3, K), m)
        e, s = jackknife.mean(v, groups, K)
        est.append(e)
        errs.append(s)
        naive.append(v.std(ddof=1) / math.sqrt(K * m))
    scatter = np.std(est, ddof=1)
    assert np.mean(errs) == pytest.approx(scatter, rel=0.1)
    assert np.mean(naive) < 0.6 * scatter


def test_a_ratio_with_the_same_density_in_every_column_has_no_error():
    den = np.array([1.0, 2.0, 3.0, 0.0, 4.0])
    est, err = jackknife.ratio(0.61 * den, den)
    assert est == pytest.approx(0.61) and err == pytest.approx(0.0, abs=1e-15)
    assert all(math.isnan(v) for v in jackknife.ratio([1.0], [2.0]))


A = math.sqrt(2.0) * SQUEEZE     # the crystal's cubic cell [d]


def test_depth_windows_of_a_crystal_are_its_z_and_phi_with_no_column_to_column_scatter(tmp_path):
    # windows of whole periods of the layers (a / 2) inside the crystal below its surface h: any
    # offset holds the crystal's fraction; the last is deeper than the slab's bottom margin, not measured
    x, L = fcc(8, 24, A)
    fixed = (x[:, 2] < A).astype(np.uint8)
    write_crystal(tmp_path / "fcc.h5", x, fixed, L, ["analysis.depth_windows=[%r, %r, %r, %r, 0, 300]"
                                                     % (A, 5 * A, 3 * A, 4 * A)])
    report.analyze(str(tmp_path / "fcc.h5"), plots=False, log=lambda m: None)
    s = json.loads((tmp_path / "fcc-analysis" / "summary.json").read_text())
    d = s["depth_windows"]
    assert d["columns"] == 16
    w1, w2, deep = d["windows"]
    for w in (w1, w2):
        assert w["complete"] and w["z1"] == pytest.approx(s["h"] - w["depth_hi"])
        assert w["z"] == 12.0 and w["z_err"] == 0.0 and w["z_no_rattlers"] == 12.0
        assert w["phi"] == pytest.approx(math.pi / (3 * math.sqrt(2)) / SQUEEZE ** 3, rel=1e-9)
        assert w["phi_err"] == pytest.approx(0.0, abs=1e-12)
        assert w["n"] == int(((x[:, 2] >= w["z1"]) & (x[:, 2] <= w["z2"]) & (fixed == 0)).sum()) >= 2 * 128
    assert deep == {"depth_lo": 0.0, "depth_hi": 300.0, "z1": pytest.approx(s["h"] - 300.0),
                    "z2": pytest.approx(s["h"]), "complete": False}


def test_depth_windows_are_checked(tmp_path):
    from mpdem import config
    for bad, why in (("[10, 30, 5]", "pairs"), ("[30, 10]", "top < bottom"), ("[-1, 10]", "0 <= top")):
        with pytest.raises(config.ConfigError, match="analysis.depth_windows"):
            config.load(None, ["run.max_steps=1", f"analysis.depth_windows={bad}"])
    with pytest.raises(config.ConfigError, match="jackknife_columns"):
        config.load(None, ["run.max_steps=1", "analysis.jackknife_columns=1"])


def _run(seed, mu, z, z_err, N=20000, k_n=2e5):
    from mpdem.campaign.runs import AnalysedRun
    from mpdem.config import PARAM_KEYS
    params = {k: 0.0 for k in PARAM_KEYS}
    params.update({"run.seed": seed, "contact.mu": mu, "pour.N": N, "contact.k_n": k_n, "contact.epsilon": 0.88})
    wins = [{"depth_lo": 10.0, "depth_hi": 30.0, "complete": True, "z": z, "z_err": z_err, "phi": 0.6,
             "phi_err": 0.001},
            {"depth_lo": 5.0, "depth_hi": 15.0, "complete": False}]
    return AnalysedRun(f"run{seed}", {"params": params, "depth_windows": {"columns": 16, "windows": wins}})


def test_collect_pools_the_seed_scatter_over_sets_of_one_N_and_mu_and_combines_the_jackknife():
    from mpdem.campaign import depth
    from mpdem.campaign.runs import Set
    a = Set("S01", _run(1, 0.0, 0, 0).params, [_run(1, 0.0, 6.10, 0.02), _run(2, 0.0, 6.14, 0.02)])
    b = Set("S02", dict(_run(1, 0.0, 0, 0).params, **{"contact.k_n": 2e6}),
            [_run(1, 0.0, 6.00, 0.01, k_n=2e6), _run(2, 0.0, 6.02, 0.01, k_n=2e6), _run(3, 0.0, 6.04, 0.01, k_n=2e6)])
    c = Set("S03", dict(_run(1, 0.5, 0, 0).params), [_run(1, 0.5, 4.8, 0.03)])
    rows = {(r["set"], r["quantity"], r["window"]): r for r in depth.rows([a, b, c])}
    # the 5-15 window is incomplete in every run: no row
    assert {k[2] for k in rows} == {"10-30"}
    ra = rows[("S01", "z", "10-30")]
    # pooled over S01 and S02 (mu = 0, one N): (0.02^2 + 0.02^2 + 2 x 0.02^2) / (1 + 2) dof
    sd = math.sqrt((2 * 0.02 ** 2 + 2 * 0.02 ** 2) / 3)
    assert ra["mean"] == pytest.approx(6.12) and ra["pooled_dof"] == 3
    assert ra["pooled_sem"] == pytest.approx(sd / math.sqrt(2))
    assert ra["jackknife"] == pytest.approx(math.sqrt(2 * 0.02 ** 2) / 2)
    rb = rows[("S02", "z", "10-30")]
    assert rb["pooled_sem"] == pytest.approx(sd / math.sqrt(3)) and rb["sem"] == pytest.approx(0.02 / math.sqrt(3))
    # one pile of its own N and mu: no seed scatter, but a jackknife error
    rc = rows[("S03", "z", "10-30")]
    assert math.isnan(rc["pooled_sem"]) and rc["jackknife"] == pytest.approx(0.03)
    assert "S01 (mu = 0, N = 20000) z at 10-30 d: 6.120 +- 0.016" in depth.lines(list(rows.values()))[0]


def test_the_backbone_is_reported_at_each_cut_and_the_default_cut_is_the_backbone(tmp_path):
    """``backbone_cuts`` (docs/model.md 6.10) on a committed pile: at each cut the backbone of
    ``backbone.of_packing``; the 1 % cut is the summary's backbone; a higher cut keeps no more."""
    from pathlib import Path
    from mpdem.analysis import backbone, bulk, contacts
    from mpdem.io import packing
    src = Path(__file__).parents[1] / "analysis/results/paper/runs/dev/mu0.5_eps0.88_kn2e5_phi0.13_s1_max_steps1e7"
    s, _ = report.analyze(str(src / "packing.npz"), out=str(tmp_path / "a"), plots=False, log=lambda m: None)
    cuts = s["backbone_cuts"]
    assert [c["force_fraction"] for c in cuts] == [0.001, 0.01, 0.05]
    assert cuts[1]["z"] == s["backbone"]["z"]
    assert cuts[0]["z"] >= cuts[1]["z"] >= cuts[2]["z"] and cuts[0]["rattler_fraction"] <= cuts[2]["rattler_fraction"]
    arrays, attrs = packing.read(str(src / "packing.npz"))
    pk = bulk.Packing(arrays["x"], arrays["fixed"], attrs["L_x"], attrs["L_y"], 0.5)
    cf = contacts.contact_forces(pk, arrays, 2e5, 0.5, "hooke")
    bb = backbone.of_packing(pk, cf, s["h"], 2.5, 0.05)
    rows = pk.in_slab(s["z1"], s["z2"]) & bb["kept"]
    assert cuts[2]["z"] == float(bb["counts"][rows].mean())
