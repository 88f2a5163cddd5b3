"""``mpdem collect``: many analysed runs -> tables, fits and figures.

Synthetic run directories only (analysis/summary.json and the CSV files of
``mpdem analyze`` written directly, no simulation): a mu = 0 stiffness sweep
whose z follows eq. 7, a phi_i sweep whose phi_f follows eq. 9, a few mu
values with P(z), g(r) and P(zeta), and runs that must be skipped.
"""
import csv
import fcntl
import json
import math
import os
import pickle
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from mpdem import config
from mpdem.io import rundir
from mpdem.campaign import collect as co, pooled
from mpdem.analysis import bands, fits, nearcontact, report
from mpdem.analysis.report import AnalysisError

from helpers import draw_gaps, fake_segment_mpdem, mpdem

ROOT = Path(__file__).resolve().parents[1]
PNG = b"\x89PNG\r\n\x1a\n"
KN = [2e5, 2e6, 2e7, 2e8, 2e9]
EQ7_TRUE = dict(z_inf=6.02, a=0.12, alpha_n=0.45)    # synthetic truth, not the paper's
EQ9_TRUE = dict(A=0.58, B=0.05, C=5.0)
PHI_I = [0.02, 0.05, 0.08, 0.13, 0.20, 0.30]
NOISE_Z, NOISE_PHI = 2e-3, 5e-4                      # seed-to-seed scatter of the synthetic runs
OVERLAP_TRUE = dict(z_c=6.0, A=12.0)                 # z of a depth band = z_c + A (delta/d)^(1/2), synthetic


def params(**kw):
    """summary.json params of a run with these contact.*/pour.*/run.* values (short names)."""
    full = {"mu": "contact.mu", "epsilon": "contact.epsilon", "k_n": "contact.k_n", "phi_i": "pour.phi_i",
            "seed": "run.seed", "N": "pour.N"}
    raw = {"run.max_steps": 1, **{full[k]: v for k, v in kw.items()}}
    vals = config.resolve(raw).values
    return {k: vals[k] for k in config.PARAM_KEYS}


def comparison_rows(out):
    """The per-set comparisons with the paper's numbers (collect.json; the README carries the claim table)."""
    return json.loads((Path(out) / "collect.json").read_text())["comparisons"]


def write_csv(path, head, cols):
    """Columns as ``mpdem analyze`` writes its tables."""
    rundir.write_csv(path, head, zip(*cols))


def make_run(run, p, z, phi, alpha, rng, converged=True):
    """A run directory with analysis/summary.json and the CSV tables of ``mpdem analyze``."""
    an = Path(run) / "analysis"
    an.mkdir(parents=True)
    n = np.arange(13)
    P = np.exp(-0.5 * ((n - z) / 1.2) ** 2)
    P /= P.sum()
    xi_edges = np.logspace(-6, 0, 61)
    xi = np.sqrt(xi_edges[:-1] * xi_edges[1:])
    g_near = 0.3 * xi ** -alpha * rng.uniform(0.9, 1.1, len(xi))
    zeta = None
    if p["contact.mu"] > 0:
        edges = np.linspace(0, 1, 51)
        Pz = np.exp(-((edges[:-1] - 0.2) / 0.2) ** 2) + 0.05 * rng.random(50)
        cols, head = [edges[:-1], edges[1:], np.round(100 * Pz), Pz / Pz.max()], ["zeta_lo", "zeta_hi", "count", "P"]
        if p["contact.mu"] >= 1:
            cols += [np.round(100 * Pz), Pz / Pz.max()]
            head += ["count_ratio", "P_ratio"]
        write_csv(an / "zeta.csv", head, cols)
        zeta = {"n_contacts": 1000, "n_tensile": 0, "n_above_one": 0, "mobilised_fraction": 0.01 * rng.random(),
                "zeta_mean": 0.3, "zeta_max": 1.0}
    r_lo = np.arange(300) * 0.01
    g = 1 + np.exp(-(r_lo - 1) / 0.5) * np.cos(2 * np.pi * (r_lo - 1)) * (r_lo >= 1)
    write_csv(an / "gofr.csv", ["r_lo", "r_hi", "count", "g"], [r_lo, r_lo + 0.01, np.round(100 * g), g])
    write_csv(an / "gofr_near.csv", ["xi_lo", "xi_hi", "xi", "count", "g"],
              [xi_edges[:-1], xi_edges[1:], xi, np.round(10 * g_near), g_near])
    write_csv(an / "coordination.csv", ["n", "P", "P_no_rattlers"], [n, P, P])
    s = {"source": str(Path(run) / "final.h5"), "kind": "final", "step": 123456, "converged": converged,
         "n": 20400, "params": p, "z1": 10.0, "z2": 35.0, "h": 45.0, "z": z, "z_no_rattlers": z + 0.05,
         "rattler_fraction": 0.02 + 0.001 * rng.random(), "phi": phi, "n_bulk": 10000, "P_z": list(P),
         "P_z_no_rattlers": list(P), "overlap_median": 1e-4, "overlap_max": 1e-3,
         "halved_margins": {"z": z + 0.001, "z_no_rattlers": z, "rattler_fraction": 0.02, "phi": phi, "n_bulk": 12000},
         "alpha": alpha, "alpha_err": 0.01,
         "alpha_fit": {"alpha": alpha, "alpha_err": 0.01, "c": -1.0, "n_bins": 17, "xi_lo": 1e-3, "xi_hi": 5e-2},
         "gofr": {}, "zeta": zeta, "warnings": []}
    # the measures under gravity: gaps drawn from the run's alpha, depth bands on the overlap law, P(f)
    wins = [(1e-3, 1e-2), (1e-2, 5e-2), (1e-3, 5e-2)]
    gaps = draw_gaps(rng, 1500, alpha, 1e-3, 5e-2)
    s["alpha_windows"] = [nearcontact.window_stats(gaps, a, b) for a, b in wins]
    s["alpha_local"] = nearcontact.local_slope(gaps, [3e-3, 1e-2])
    depth = np.arange(8) * 2.5
    delta = (depth + 1.25) * 1e-5 * 2e5 / p["contact.k_n"]
    s["bands"] = {"depth_lo": depth.tolist(), "depth_hi": (depth + 2.5).tolist(),
                  "in_bulk": [False] + [True] * 6 + [False],
                  "z": (OVERLAP_TRUE["z_c"] + OVERLAP_TRUE["A"] * np.sqrt(delta) + rng.normal(0, 0.01, 8)).tolist(),
                  "overlap_mean": delta.tolist()}
    for col in ("z_backbone", "phi", "sigma_zz", "crystal_fraction", "rattler_fraction"):
        s["bands"][col] = [0.5] * 8
    s["P_f"] = bands.force_distribution(rng.exponential(1.0, 3000))
    s["backbone"] = {"z": z - 0.01}
    (an / "summary.json").write_text(json.dumps(rundir.json_safe(s)))
    return s


@pytest.fixture(scope="module")
def tree(tmp_path_factory):
    """Synthetic runs under one root, collected once; what was made and what was collected.

    Under pytest-xdist the workers share one tree (collecting it takes most of a minute): the first
    worker to need it makes it in the pytest run's common temporary directory, under a lock, and a
    worker handed some of this file's tests later reads it back. The tests only read the tree.
    """
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return make_tree(tmp_path_factory.mktemp("runs"))
    common = tmp_path_factory.getbasetemp().parent
    with open(common / "collect-tree.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        saved = common / "collect-tree.pickle"
        if saved.exists():
            return pickle.loads(saved.read_bytes())
        root = common / "collect-tree" / "runs"
        root.mkdir(parents=True)
        got = make_tree(root)
        saved.write_bytes(pickle.dumps(got))
        return got


def make_tree(root):
    """The synthetic runs of ``tree`` written under ``root`` (an empty directory) and collected into
    a directory beside it: dict(root, out, res, logs, made, bad)."""
    rng = np.random.default_rng(20020304)
    made = {}   # run dir -> (set tuple (mu, eps, k_n, phi_i), summary)

    def add(rel, z, phi, alpha=0.52, converged=True, **kw):
        p = params(**kw)
        made[str(root / rel)] = ((p["contact.mu"], p["contact.epsilon"], p["contact.k_n"], p["pour.phi_i"]),
                                 make_run(root / rel, p, z, phi, alpha, rng, converged))

    for k in KN:                      # eq. 7 at mu = 0: 5 k_n x 3 seeds
        for seed in (1, 2, 3):
            add(f"kn/mu0_kn{k:.0e}_s{seed}", fits.eq7(k, **EQ7_TRUE) + rng.normal(0, NOISE_Z),
                0.64 + rng.normal(0, NOISE_PHI), 0.52 + rng.normal(0, 0.01), mu=0.0, k_n=k, seed=seed)
    for phi_i in PHI_I:               # eq. 9 at mu = 0.5: 6 phi_i x 2 seeds
        for seed in (1, 2):
            add(f"phi/phi{phi_i}_s{seed}", 4.9 - 0.5 * phi_i + rng.normal(0, NOISE_Z),
                float(fits.eq9(phi_i, **EQ9_TRUE)) + rng.normal(0, NOISE_PHI), 0.5 + rng.normal(0, 0.01),
                mu=0.5, phi_i=phi_i, seed=seed)
    for mu in (0.1, 1.0):
        for seed in (1, 2):
            add(f"mu/mu{mu}_s{seed}", 5.5 - mu / 10 + rng.normal(0, NOISE_Z), 0.62 - mu / 100, mu=mu, seed=seed)
    for seed in (1, 2):               # deep below the root: found recursively
        add(f"mu/deep/a/b/mu10_s{seed}", 4.6 + rng.normal(0, NOISE_Z), 0.60, mu=10.0, seed=seed)
    add("mu/mu0.5_eps0.26_s1", 4.7, 0.60, mu=0.5, epsilon=0.26, seed=1)      # a set with one seed
    # not usable
    bad = {}
    p = params(mu=0.3, seed=1)
    make_run(root / "bad/notconv", p, 5.0, 0.61, 0.5, rng, converged=False)
    bad["notconv"] = "not converged"
    (root / "bad/unfinished").mkdir(parents=True)
    (root / "bad/unfinished/config.toml").write_text("")
    bad["unfinished"] = "unfinished"
    (root / "bad/corrupt/analysis").mkdir(parents=True)
    (root / "bad/corrupt/analysis/summary.json").write_text("{not json")
    bad["corrupt"] = "unreadable"
    shutil.copytree(root / "mu/mu0.1_s1", root / "bad/copy")                # the same sample twice
    logs = []
    out = root.parent / (root.name + "-out")
    res = co.collect([str(root)], str(out), analyze_missing=False, log=logs.append)
    return dict(root=root, out=out, res=res, logs=logs, made=made, bad=bad)


def _fit(tree, kind, **family):
    fj = json.loads((tree["out"] / "fits.json").read_text())
    hits = [e for e in fj[kind] if all(e["family"][k] == v for k, v in family.items())]
    assert len(hits) == 1, fj[kind]
    return hits[0]


def test_eq7_parameters_recovered_within_errors(tree):
    e = _fit(tree, "eq7", mu=0.0)
    assert e["status"] == "fitted" and e["weighted"] and e["n_seeds"] == [3] * 5
    assert sorted(e["k_n"]) == KN
    for k, v in EQ7_TRUE.items():
        assert 0 < e[f"{k}_err"] < 0.2 * abs(v), (k, e[f"{k}_err"])
        assert abs(e[k] - v) <= 3 * e[f"{k}_err"], (k, e[k], v, e[f"{k}_err"])
    assert e["a_tilde"] == pytest.approx(e["a"] * fits.K_REF ** e["alpha_n"])
    chk = e["check_alpha_n"]
    assert chk["n_runs"] == 15 and chk["one_minus_alpha"] == pytest.approx(1 - chk["alpha"])
    assert chk["difference"] == pytest.approx(e["alpha_n"] - (1 - chk["alpha"]))


def test_eq9_parameters_recovered_within_errors(tree):
    e = _fit(tree, "eq9", mu=0.5, epsilon=0.88)
    assert e["status"] == "fitted" and e["weighted"] and sorted(e["phi_i"]) == PHI_I
    for k, v in EQ9_TRUE.items():
        assert math.isfinite(e[f"{k}_err"]) and abs(e[k] - v) <= 3 * e[f"{k}_err"], (k, e[k], v, e[f"{k}_err"])
    assert len(e["z"]) == len(PHI_I)


def test_set_mean_and_standard_error_match_numpy(tree):
    by_set = {}
    for key, s in tree["made"].values():
        by_set.setdefault(key, []).append(s)
    with open(tree["out"] / "sets.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(by_set)
    for row in rows:
        runs = by_set[tuple(float(row[k]) for k in ("mu", "epsilon", "k_n", "phi_i"))]
        assert int(row["n_seeds"]) == len(runs)
        assert sorted(map(int, row["seeds"].split())) == sorted(r["params"]["run.seed"] for r in runs)
        for q in ("z", "z_no_rattlers", "phi", "alpha", "rattler_fraction"):
            v = np.array([r[q] for r in runs])
            assert float(row[f"{q}_mean"]) == pytest.approx(np.mean(v), rel=1e-13, abs=0)
            if len(v) == 1:
                assert row[f"{q}_sem"] == ""          # no error bar from one seed
            else:
                assert float(row[f"{q}_sem"]) == pytest.approx(np.std(v, ddof=1) / np.sqrt(len(v)), rel=1e-12)
    assert any(r["n_seeds"] == "1" for r in rows)


def test_table_columns_are_those_of_the_committed_results(tree):
    """runs.csv and sets.csv keep their columns (the parameters in config.PARAM_KEYS's order)."""
    for name in ("runs.csv", "sets.csv"):
        with open(tree["out"] / name) as fh:
            head = fh.readline()
        with open(ROOT / "analysis" / "results" / "dev" / name) as fh:
            assert head == fh.readline(), name
    assert config.PARAM_KEYS == ("contact.mu", "contact.epsilon", "contact.k_n", "contact.k_t", "contact.gamma_n",
                                 "contact.gamma_t", "contact.model", "pour.phi_i", "pour.N", "pour.K0", "run.seed",
                                 "box.L_x", "box.L_y", "integration.dt")


def test_tables_and_figures_written(tree):
    out, res = tree["out"], tree["res"]
    for f in ("runs.csv", "sets.csv", "fits.json", "README.md", "collect.json"):
        assert (out / f).is_file(), f
    assert not list(out.glob("*.tmp"))
    figs = res["figures"]
    assert set(figs) == {f"fig{i}" for i in range(2, 13)}
    for name, f in figs.items():
        assert f["made"], (name, f["reason"])
        assert (out / f["file"]).read_bytes()[:8] == PNG, name
    with open(out / "runs.csv") as fh:
        runs = list(csv.DictReader(fh))
    assert len(runs) == len(tree["made"])
    used = {os.path.normpath(r["path"]) for r in runs}
    copy, orig = str(tree["root"] / "bad/copy"), str(tree["root"] / "mu/mu0.1_s1")
    assert used - {copy, orig} == set(tree["made"]) - {orig} and len(used & {copy, orig}) == 1
    assert json.loads((out / "collect.json").read_text())["n_runs"] == len(tree["made"])
    rows = comparison_rows(out)
    assert any(r["paper"] == 6.144 and r["verdict"] == "within" for r in rows)
    assert "S01" in (out / "README.md").read_text()


def test_eq7_is_weighted_by_the_pooled_scatter_and_fitted_with_the_exponent_fixed_too(tree):
    e = _fit(tree, "eq7", mu=0.0)
    # 5 sets of 3 seeds: 10 degrees of freedom of scatter around NOISE_Z; each set's sigma is scatter / sqrt(3)
    assert e["pooled_dof"] == 10 and 0.5 * NOISE_Z < e["pooled_scatter"] < 1.6 * NOISE_Z
    assert e["z_sigma"] == pytest.approx([e["pooled_scatter"] / math.sqrt(3)] * 5)
    assert 0 <= e["p_value"] <= 1
    fx = e["fixed"]
    assert fx["alpha_n"] == 0.5 and fx["dof"] == 3 and 0 <= fx["p_value"] <= 1
    # the truth has alpha_n = 0.45: the fixed 1/2 fits worse than the free fit
    assert fx["chi2"] >= e["chi2"]


def test_alpha_pooled_over_seeds_on_every_window_with_a_bootstrap_error(tree):
    fj = json.loads((tree["out"] / "fits.json").read_text())
    sets = {s["set"]: s for s in fj["alpha"]}
    res = json.loads((tree["out"] / "collect.json").read_text())["sets"]
    sid = next(k for k, v in res.items() if v["params"]["mu"] == 0 and v["params"]["k_n"] == 2e5)
    e = sets[sid]
    assert e["n_runs"] == 3
    assert [(w["xi_lo"], w["xi_hi"]) for w in e["windows"]] == [(1e-3, 1e-2), (1e-2, 5e-2), (1e-3, 5e-2)]
    whole = e["windows"][2]
    # three seeds of 1500 gaps each drawn at alpha = 0.52 +- 0.01
    assert whole["n"] == 4500 and abs(whole["alpha"] - 0.52) < 4 * math.hypot(whole["alpha_err"], 0.01)
    assert math.isfinite(whole["boot_err"]) and whole["boot_err"] > 0
    assert len(e["local"]) == 2 and all(p["n"] > 0 for p in e["local"])
    readme = (tree["out"] / "README.md").read_text()
    assert "Near-contact exponent α (eq. 6) on fixed windows" in readme and "[0.001, 0.05]" in readme


def test_overlap_fit_over_the_bulk_bands_of_a_family(tree):
    fj = json.loads((tree["out"] / "fits.json").read_text())
    hits = [e for e in fj["overlap"] if e["family"]["mu"] == 0 and e["status"] == "fitted"]
    assert len(hits) == 1
    e = hits[0]
    assert e["n_runs"] == 15 and e["n_bands"] == 15 * 6          # the bulk bands only
    assert abs(e["z_c"] - OVERLAP_TRUE["z_c"]) < 4 * e["z_c_err"] and e["z_c_err"] < 0.02
    assert abs(e["A"] - OVERLAP_TRUE["A"]) < 4 * e["A_err"]
    pf = {s["set"]: s for s in fj["P_f"]}
    assert all(abs(p["tail_rate"] - 1.0) < 5 * p["tail_rate_err"] for p in pf.values())
    readme = (tree["out"] / "README.md").read_text()
    assert "z against the overlap" in readme
    # the bands are drawn on the square-root law: the alternative exponents fit them worse, and say so
    third, two_thirds = e["exponent 1/3"], e["exponent 2/3"]
    assert third["rms"] > e["rms"] and two_thirds["rms"] > e["rms"]
    assert f"with 1/3: z_c {pooled.z_c_text(third, why=False)}, rms {third['rms']:.3f}" in readme


def test_unusable_runs_listed_with_reasons(tree):
    skipped = {Path(s["path"]).name: s["reason"] for s in tree["res"]["skipped"]}
    for name, words in tree["bad"].items():
        assert words in skipped[name], (name, skipped.get(name))
    dup = [r for n, r in skipped.items() if n in ("copy", "mu0.1_s1")]
    assert len(dup) == 1 and "duplicate: seed 1" in dup[0]        # one sample, counted once
    text = "\n".join(tree["logs"])
    assert all(f"skipped {tree['root'] / 'bad' / n}" in text for n in tree["bad"])
    assert "## Skipped" in (tree["out"] / "README.md").read_text()


def test_directory_of_runs_found_recursively(tree):
    root = tree["root"]
    deep = {str(root / "mu/deep/a/b/mu10_s1"), str(root / "mu/deep/a/b/mu10_s2")}
    used = {p for s in tree["res"]["sets"].values() for p in s["runs"]}
    assert deep <= used
    found, _ = co.find_runs([str(root)])
    again, _ = co.find_runs([str(root), str(root / "mu"), str(root / "mu/mu0.1_s1")])
    assert sorted(again) == sorted(found)                     # each run once
    assert not any("/analysis" in p for p in found)          # the search stops at a run directory


def test_no_usable_runs_is_a_clear_error(tmp_path):
    rng = np.random.default_rng(1)
    make_run(tmp_path / "r/a", params(seed=1), 5.0, 0.61, 0.5, rng, converged=False)
    with pytest.raises(AnalysisError, match="no usable runs.*not converged"):
        co.collect([str(tmp_path / "r")], str(tmp_path / "out"), log=lambda m: None)
    with pytest.raises(AnalysisError, match="no usable runs.*no such directory"):
        co.collect([str(tmp_path / "nothing")], str(tmp_path / "out"), log=lambda m: None)


def test_missing_analysis_runs_analyze_or_is_skipped(tmp_path, monkeypatch):
    rng = np.random.default_rng(2)
    run = tmp_path / "r/run1"
    run.mkdir(parents=True)
    (run / "final.h5").write_text("not a state file")
    calls = []

    def fake_analyze(target, out=None, sets=(), plots=True, log=print):
        calls.append((target, plots))
        make_run(target, params(seed=1), 5.0, 0.61, 0.5, rng)

    with pytest.raises(AnalysisError, match="not analysed"):
        co.collect([str(tmp_path / "r")], str(tmp_path / "o1"), analyze_missing=False, log=lambda m: None)
    with pytest.raises(AnalysisError, match="analysis failed"):       # the real analyze: not HDF5
        co.collect([str(tmp_path / "r")], str(tmp_path / "o2"), log=lambda m: None)
    monkeypatch.setattr(report, "analyze", fake_analyze)
    res = co.collect([str(tmp_path / "r")], str(tmp_path / "o3"), log=lambda m: None)
    assert calls == [(str(run), False)] and res["n_runs"] == 1


def test_cli(tree, tmp_path):
    out = tmp_path / "cli"
    p = mpdem("collect", tree["root"] / "kn", "--out", out, "--no-analyze", timeout=300)
    assert p.returncode == 0, p.stderr
    assert "wrote" in p.stdout and (out / "fig7_z_vs_kn.png").read_bytes()[:8] == PNG
    assert "fig9: not made" in p.stdout
    p = mpdem("collect", tree["root"] / "bad" / "notconv", "--out", tmp_path / "none", "--quiet", timeout=300)
    assert p.returncode == 1 and "no usable runs" in p.stderr and p.stdout == ""


def test_sweep_tables_pass_the_sweep_helper(tmp_path):
    """Every row of analysis/sweeps/*.tsv through jobs/mpdem-segment.sh --sweep (a stand-in mpdem)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("MPDEM_", "SLURM_", "PBS_"))}
    env.update(MPDEM_CMD=fake_segment_mpdem(tmp_path / "fake-mpdem.sh", tmp_path / "calls"))
    tables = sorted((ROOT / "analysis/sweeps").glob("*.tsv"))
    assert {t.name for t in tables} >= {"fig2-4.tsv", "fig7.tsv", "fig9.tsv"}
    names, cfgs = [], {}
    for t in tables:
        rows = [ln for ln in t.read_text().splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
        (tmp_path / "calls").write_text("")
        for i in range(1, len(rows)):
            p = subprocess.run(["bash", str(ROOT / "jobs/mpdem-segment.sh"), "--sweep", str(t), str(i),
                                str(tmp_path / "sweep"), ""], env=env, capture_output=True, text=True, cwd=tmp_path)
            assert p.returncode == 0, (t.name, i, p.stderr)
        calls = [c.split() for c in (tmp_path / "calls").read_text().splitlines()]
        assert len(calls) == len(rows) - 1
        for c in calls:
            assert c[:2] == ["run", "--out"]
            names.append(c[2])
            cfg = config.load(None, [c[k + 1] for k in range(len(c)) if c[k] == "--set"])   # valid inputs
            cfgs.setdefault(t.name, []).append(cfg.values)
    assert len(names) == len(set(names))          # no two rows share a run directory
    mus = {(v["contact.mu"], v["contact.epsilon"]) for v in cfgs["fig2-4.tsv"]}
    assert {m for m, _ in mus} >= {0, 0.05, 0.1, 0.2, 0.3, 0.5, 0.7, 1, 2, 10} and {e for _, e in mus} == {0.88, 0.26}
    fam = {}
    for v in cfgs["fig7.tsv"]:
        by_kn = fam.setdefault((v["contact.mu"], v["contact.epsilon"]), {})
        by_kn.setdefault(v["contact.k_n"], set()).add(v["run.seed"])
    assert set(fam) == {(0.0, 0.88), (0.5, 0.88), (0.5, 0.5), (0.5, 0.26), (10.0, 0.26)}
    assert all(sorted(k) == KN and all(len(s) >= 2 for s in k.values()) for k in fam.values())
    assert all(v["run.max_steps"] >= 3e6 for v in cfgs["fig7.tsv"])
    assert {v["pour.phi_i"] for v in cfgs["fig9.tsv"]} == set(PHI_I)


def test_a_run_analysed_again_keeps_its_analysis_settings(tmp_path):
    from helpers import SQUEEZE, simple_cubic, write_crystal
    run = tmp_path / "runs" / "sc"
    run.mkdir(parents=True)
    x, L = simple_cubic(6, 24, SQUEEZE)
    fixed = (x[:, 2] < 1).astype(np.uint8)
    write_crystal(run / "final.h5", x, fixed, L, ["contact.mu=0"], converged=True)
    report.analyze(str(run), sets=["analysis.margin_bottom=4"], plots=False, log=lambda m: None)
    summ = run / "analysis" / "summary.json"
    t = os.path.getmtime(summ)
    os.utime(run / "final.h5", (t + 10, t + 10))          # a fresh clone's order of files: not a newer state
    lines = []
    co.collect([str(tmp_path / "runs")], str(tmp_path / "out"), log=lines.append)
    assert not any("analysing" in ln for ln in lines) and os.path.getmtime(summ) == t
    write_crystal(run / "final.h5", x, fixed, L, ["contact.mu=0"], converged=True, step=9)  # a restart went on
    lines = []
    co.collect([str(tmp_path / "runs")], str(tmp_path / "out"), log=lines.append)
    assert any("step 9" in ln and "step 7" in ln for ln in lines)
    again = json.loads(summ.read_text())
    assert again["step"] == 9 and again["margin_bottom"] == 4.0
    assert again["settings"]["analysis.margin_bottom"] == 4.0
    assert again["measures_version"] == report.MEASURES_VERSION
    del again["measures_version"]                                 # written before the measures had a version
    summ.write_text(json.dumps(again))
    lines = []
    co.collect([str(tmp_path / "runs")], str(tmp_path / "out"), log=lines.append)
    assert any("measures version 0" in ln for ln in lines)
    assert json.loads(summ.read_text())["measures_version"] == report.MEASURES_VERSION


def test_development_size_verdicts_figures_inline_and_notes(tmp_path):
    """Dev-size piles (N = 2000, 10d box) are judged against docs/model.md 7.1 with the project's
    acceptance (z +-0.05 at mu = 0, +-0.10 at mu = 0.5, phi +-0.01: collect.json's comparisons); the
    README shows the figures it made inline and links OUT/NOTES.md (the dated log) without copying it."""
    rng = np.random.default_rng(7)
    root = tmp_path / "runs"
    for mu, z, phi in ((0.0, 6.12, 0.640), (0.5, 4.70, 0.612)):
        for seed in (1, 2):
            p = params(mu=mu, epsilon=0.88, k_n=2e5, phi_i=0.13, seed=seed, N=2000)
            p["box.L_x"] = p["box.L_y"] = 10.0
            make_run(root / f"mu{mu}_s{seed}", p, z + 0.001 * seed, phi, 0.5, rng)
    out = tmp_path / "out"
    out.mkdir()
    (out / "NOTES.md").write_text("### What we found\n\nz at mu = 0.5 is low: a finite-size effect.\n")
    co.collect([str(root)], str(out), analyze_missing=False, log=lambda m: None)
    readme = (out / "README.md").read_text()
    rows = [r for r in comparison_rows(out) if "vs 7.1" in r["conditions"]]
    z0 = [r for r in rows if r["quantity"] == "z" and "mu = 0," in r["conditions"]]
    z5 = [r for r in rows if r["quantity"] == "z" and "mu = 0.5," in r["conditions"]]
    phi5 = [r for r in rows if r["quantity"] == "phi" and "mu = 0.5," in r["conditions"]]
    assert z0 and z0[0]["accept"] == [6.09, 6.19] and z0[0]["verdict"] == "within"
    assert z5 and z5[0]["accept"] == [4.817, 5.017] and z5[0]["verdict"] == "outside"
    assert phi5 and phi5[0]["verdict"] == "within"
    assert "![" in readme and "(fig2_z_vs_mu.png)" in readme and (out / "fig2_z_vs_mu.png").exists()
    made = [ln for ln in readme.splitlines() if ln.startswith("![")]
    assert all((out / ln.split("(")[-1].rstrip(")")).exists() for ln in made)
    assert "(NOTES.md)" in readme and "a finite-size effect" not in readme


def test_a_summary_from_before_a_key_existed_joins_the_set_of_its_default():
    from mpdem.campaign.collect import _physics_key
    old = {"contact.mu": 0.5, "contact.k_n": 2e5}
    new = dict(old, **{"bed.wall": False})
    assert _physics_key(old) == _physics_key(new)
    assert _physics_key(old) != _physics_key(dict(old, **{"bed.wall": True}))


def test_the_tiles_edge_parts_sets_of_tiled_pours_only():
    from mpdem.campaign.collect import _physics_key
    whole = {"contact.mu": 0.5, "pour.insertion": "whole"}
    tiled = dict(whole, **{"pour.insertion": "tiles"})
    assert _physics_key(dict(whole, **{"pour.tile": 30.0})) == _physics_key(whole)
    assert _physics_key(dict(tiled, **{"pour.tile": 30.0})) != _physics_key(tiled)
    assert _physics_key(tiled) != _physics_key(whole)


def test_sets_that_differ_outside_the_params_are_separate_families(tmp_path):
    """A set run under another stop rule (stop.energy, not a PARAM_KEYS column) at the same mu
    is its own family: the z(mu) trend of the others does not step from mu = 0.5 to 0.5."""
    from mpdem.campaign.runs import AnalysedRun, families
    rng = np.random.default_rng(11)
    root = tmp_path / "runs"
    for mu, z in ((0.0, 6.10), (0.5, 4.90), (1.0, 4.80)):
        for seed in (1, 2):
            make_run(root / f"mu{mu}_s{seed}", params(mu=mu, seed=seed), z + 0.001 * seed, 0.62, 0.5, rng)
    s = make_run(root / "mu0.5_s1_translational", params(mu=0.5, seed=1), 5.0, 0.62, 0.5, rng)
    s["physics"] = {"stop.energy": "translational", "stop.E_stop": 1e-9}   # E_stop: derived, not a family key
    (root / "mu0.5_s1_translational/analysis/summary.json").write_text(json.dumps(s))
    runs = [AnalysedRun(str(d), json.loads((d / "analysis/summary.json").read_text())) for d in sorted(root.iterdir())]
    sets, _, _ = co.group(runs)
    assert len(sets) == 4 and sorted(x.extra.get("stop.energy", "total") for x in sets).count("translational") == 1
    fams = families(sets, "contact.mu")
    assert sorted(len(m) for _, m in fams) == [1, 3]
    assert [f for f, m in fams if len(m) == 1][0]["stop.energy"] == "translational"
    out = tmp_path / "out"
    co.collect([str(root)], str(out), analyze_missing=False, log=lambda m: None)
    text = (out / "README.md").read_text().splitlines()
    trend = [r for r in comparison_rows(out) if r["quantity"] == "z(mu) trend"]
    assert len(trend) == 1 and trend[0]["value"] == "decreasing at every step", trend
    # the README says which set ran under the other rule, below the sets table
    marked = [ln for ln in text if ln.startswith("- S") and "stop.energy = translational" in ln]
    assert len(marked) == 1, marked


def test_figures_in_several_formats(tree, tmp_path):
    res = co.collect([str(tree["root"] / "kn")], str(tmp_path / "out"), analyze_missing=False,
                     log=lambda m: None, figure_format="pdf,svg")
    f7 = res["figures"]["fig7"]
    assert f7["made"] and f7["file"] == "fig7_z_vs_kn.pdf" and f7["files"] == ["fig7_z_vs_kn.pdf", "fig7_z_vs_kn.svg"]
    assert (tmp_path / "out" / "fig7_z_vs_kn.pdf").read_bytes()[:5] == b"%PDF-"
    assert b"<svg" in (tmp_path / "out" / "fig7_z_vs_kn.svg").read_bytes()[:2000]
    assert not list((tmp_path / "out").glob("*.png")) and not list((tmp_path / "out").glob("*.tmp"))
    assert "(fig7_z_vs_kn.pdf)" in (tmp_path / "out" / "README.md").read_text()
    said = []
    with pytest.raises(AnalysisError, match="^collect: --figure-format 'jpg': accepted png, pdf or svg"):
        co.collect([str(tree["root"] / "kn")], str(tmp_path / "bad"), analyze_missing=False, log=said.append,
                   figure_format="jpg")
    assert said == [] and not (tmp_path / "bad").exists()     # refused before any run is read


def test_the_isostatic_count_comes_from_n_m_in_old_and_new_summaries():
    """Summaries written before 2026-11-26 hold z_iso = 4 + 2 n_m / 3 (each mobilised contact counted
    twice); the tables take 4 + n_m / 3 from the stored n_m (docs/model.md 6.2), whichever was written."""
    from mpdem.campaign.runs import quantities
    old = {"isostatic": {"n_m": 0.3, "z_iso": 4.2}}
    new = {"isostatic": {"n_m": 0.3, "z_iso": 4.1}}
    assert quantities(old)["z_iso"] == quantities(new)["z_iso"] == pytest.approx(4.1)
    assert math.isnan(quantities({"isostatic": {"z_iso": 6.0}})["z_iso"])


def test_the_rungs_of_a_stiffening_ladder_are_one_family_apart_from_the_poured_piles(tmp_path):
    """A stiffened rung (``stiffen.k_n_from``, a physics key outside the params) is its own set, and
    across k_n the rungs of a ladder (each a decade above the last) are one family: the rise
    k_n / k_n_from enters the family as the other quantities that follow k_n do."""
    from mpdem.campaign.runs import AnalysedRun, families
    rng = np.random.default_rng(12)
    root = tmp_path / "runs"
    for k_n, z in ((2e5, 6.10), (2e6, 6.05), (2e7, 6.03)):
        for seed in (1, 2):
            make_run(root / f"poured_kn{k_n:g}_s{seed}", params(mu=0, k_n=k_n, seed=seed), z + 0.001 * seed, 0.63,
                     0.5, rng)
    for k_n in (2e6, 2e7):
        d = root / f"stiffened_kn{k_n:g}_s1"
        s = make_run(d, params(mu=0, k_n=k_n, seed=1), 6.07, 0.63, 0.5, rng)
        s["physics"] = {"stiffen.k_n_from": k_n / 10}
        (d / "analysis/summary.json").write_text(json.dumps(s))
    runs = [AnalysedRun(str(d), json.loads((d / "analysis/summary.json").read_text())) for d in sorted(root.iterdir())]
    sets, _, _ = co.group(runs)
    assert len(sets) == 5
    fams = families(sets, "contact.k_n")
    assert sorted(len(m) for _, m in fams) == [2, 3]
    ladder = [(f, m) for f, m in fams if len(m) == 2][0]
    assert ladder[0]["stiffened x"] == 10.0 and [s.params["contact.k_n"] for s in ladder[1]] == [2e6, 2e7]


def test_a_family_across_k_n_keeps_an_epsilon_that_differs_in_its_last_bit(tmp_path):
    """Summaries written before 2026-11-27 (late night) hold epsilon as gamma_n's round trip, which
    differs in the last bit at some k_n (0.5 -> 0.49999999999999994 at 2e5 and 2e7, not at 2e6): read,
    it is the value given, and the three sets are one family across k_n."""
    from mpdem.campaign.runs import AnalysedRun, families
    rng = np.random.default_rng(14)
    root = tmp_path / "runs"
    for k_n, z, eps in ((2e5, 4.82, 0.49999999999999994), (2e6, 4.73, 0.5), (2e7, 4.69, 0.49999999999999994)):
        for seed in (2, 3):
            p = params(mu=0.5, epsilon=0.5, k_n=k_n, seed=seed)
            p["contact.epsilon"] = eps
            make_run(root / f"kn{k_n:g}_s{seed}", p, z + 0.001 * seed, 0.60, 0.5, rng)
    runs = [AnalysedRun(str(d), json.loads((d / "analysis/summary.json").read_text())) for d in sorted(root.iterdir())]
    assert {r.params["contact.epsilon"] for r in runs} == {0.5}
    sets, _, _ = co.group(runs)
    assert len(sets) == 3
    (fam, members), = families(sets, "contact.k_n")
    assert fam["epsilon"] == 0.5 and [s.params["contact.k_n"] for s in members] == [2e5, 2e6, 2e7]


def test_a_run_on_another_bed_is_another_sample(tmp_path):
    """``bed.seed`` apart from run.seed: one pour seed on two beds is two samples of the set; the
    same pair of seeds again is the same sample (a duplicate). Summaries written before bed.seed
    (no ``bed_seed``) are on the bed of their run.seed."""
    rng = np.random.default_rng(13)
    root = tmp_path / "runs"
    for name, bed in (("s1", None), ("s1_bed7", 7), ("s1_bed7_again", 7), ("s1_bed1", 1), ("s10", None)):
        seed = 10 if name == "s10" else 1
        s = make_run(root / name, params(mu=0, seed=seed), 6.1, 0.64, 0.5, rng)
        if bed is not None:
            s["bed_seed"] = bed
        else:
            s.pop("bed_seed", None)
        (root / name / "analysis/summary.json").write_text(json.dumps(s))
    from mpdem.campaign.runs import AnalysedRun
    runs = [AnalysedRun(str(d), json.loads((d / "analysis/summary.json").read_text())) for d in sorted(root.iterdir())]
    sets, skipped, _ = co.group(runs)
    assert len(sets) == 1 and len(sets[0].runs) == 3
    assert [os.path.basename(r.path) for r in sets[0].runs] == ["s1", "s1_bed7", "s10"]
    reasons = sorted(os.path.basename(s["path"]) + ": " + s["reason"] for s in skipped)
    assert len(reasons) == 2 and "duplicate: seed 1 (bed seed 1)" in reasons[0] and "bed seed 7" in reasons[1]


def test_a_set_apart_by_a_parameter_outside_the_columns_says_so(tmp_path):
    """Two sets equal in every column of the tables but gamma_t (gamma_n / 2 against 0): the comparison
    rows and the note under the sets table name the one with tangential damping, not the other."""
    rng = np.random.default_rng(5)
    root = tmp_path / "runs"
    for g_t, tag in ((0.0, ""), (25.7, "_gt")):
        for seed in (1, 2):
            p = params(mu=0.5, seed=seed)
            p["contact.gamma_t"] = g_t
            make_run(root / f"mu0.5_s{seed}{tag}", p, 4.85 - g_t / 1000, 0.61, 0.6, rng)
    out = tmp_path / "out"
    co.collect([str(root)], str(out), analyze_missing=False, log=lambda m: None)
    text = (out / "README.md").read_text().splitlines()
    ratio = f"gamma_t = {25.7 / params(mu=0.5)['contact.gamma_n']:.4g} gamma_n"
    z_rows = [r["conditions"] for r in comparison_rows(out) if r["quantity"] == "z"
              and r["conditions"].startswith("mu = 0.5")]
    assert len(z_rows) == 2 and sum(ratio in ln for ln in z_rows) == 1, z_rows
    assert len([ln for ln in text if ln.startswith("- S") and ratio in ln]) == 1


def test_flow_arrested_sets_are_compared_with_the_papers_flow_arrest_numbers_alone(tmp_path):
    """A poured set and a flow-arrest set (a flow phase: docs/model.md 5.5) of one mu, eps, k_n and
    phi_i: collect compares the first with the poured z = 4.90 and the second with 4.69 and
    phi = 0.594, never the other way round."""
    rng = np.random.default_rng(6)
    root = tmp_path / "runs"
    for flow, z, phi in ((False, 4.85, 0.612), (True, 4.71, 0.596)):
        for seed in (1, 2):
            run = root / f"mu0.5_s{seed}{'_flow' if flow else ''}"
            s = make_run(run, params(mu=0.5, seed=seed), z + 0.01 * seed, phi, 0.6, rng)
            if flow:
                s["physics"] = {"flow.incline": 24.0, "flow.time": 400.0}
                (run / "analysis" / "summary.json").write_text(json.dumps(rundir.json_safe(s)))
    out = tmp_path / "out"
    co.collect([str(root)], str(out), analyze_missing=False, log=lambda m: None)
    rows = [r for r in comparison_rows(out) if r["quantity"] in ("z", "phi")
            and r["conditions"].startswith("mu = 0.5")]
    flow_rows = [r for r in rows if "flow.time" in r["conditions"]]
    poured = [r for r in rows if "flow.time" not in r["conditions"]]
    assert len(flow_rows) == 2 and sorted(r["paper"] for r in flow_rows) == [0.594, 4.69], flow_rows
    assert sorted(round(r["value"], 4) for r in flow_rows) == [0.596, 4.725], flow_rows
    assert not any(r["paper"] in (4.69, 0.594) for r in poured), poured
    assert any(r["paper"] == 4.9 and round(r["value"], 4) == 4.865 for r in poured), poured


def test_a_derived_key_set_away_from_its_derivation_is_named(tmp_path):
    """stop.E_stop is derived from k_n (docs/config.md): a set run with a stricter stop is a set apart
    and says so under the sets table, one with the derived value (written out) says nothing."""
    rng = np.random.default_rng(7)
    root = tmp_path / "runs"
    for E_stop, tag in ((None, ""), (1e-10, "_strict")):
        s = make_run(root / f"mu0_s1{tag}", params(mu=0.0, seed=1), 6.14, 0.64, 0.4, rng)
        s["physics"] = {"stop.E_stop": E_stop if E_stop else 1e-8, "contact.k_n": 2e5}
        (root / f"mu0_s1{tag}" / "analysis" / "summary.json").write_text(json.dumps(rundir.json_safe(s)))
    out = tmp_path / "out"
    co.collect([str(root)], str(out), analyze_missing=False, log=lambda m: None)
    text = (out / "README.md").read_text().splitlines()
    notes = [ln for ln in text if ln.startswith("- S")]
    assert len([ln for ln in text if ln.startswith("| S0")]) >= 2
    assert len(notes) == 1 and "stop.E_stop = 1e-10" in notes[0], notes


def test_a_set_keeps_its_id_when_new_sets_join_in_front_of_it(tmp_path):
    """collect.json keeps each set's signature; a later collect into the same directory gives the same
    set the same id, and a new set (here one that sorts first, mu = 0) the next free number."""
    from mpdem.campaign.runs import AnalysedRun
    rng = np.random.default_rng(5)
    root, out = tmp_path / "runs", tmp_path / "out"
    for mu, z in ((0.5, 4.90), (1.0, 4.80)):
        for seed in (1, 2):
            make_run(root / f"mu{mu}_s{seed}", params(mu=mu, seed=seed), z + 0.001 * seed, 0.62, 0.5, rng)
    first = co.collect([str(root)], str(out), analyze_missing=False, log=lambda m: None)
    ids = {tuple(v["runs"]): k for k, v in first["sets"].items()}
    assert sorted(ids.values()) == ["S01", "S02"] and sorted(first["set_ids"].values()) == ["S01", "S02"]
    for seed in (1, 2):
        make_run(root / f"mu0.0_s{seed}", params(mu=0.0, seed=seed), 6.1, 0.64, 0.4, rng)
    # a set of the same parameters as an old one but another physics key is new as well
    s = make_run(root / "mu0.5_s1_translational", params(mu=0.5, seed=1), 5.0, 0.62, 0.5, rng)
    s["physics"] = {"stop.energy": "translational"}
    (root / "mu0.5_s1_translational/analysis/summary.json").write_text(json.dumps(s))

    def runs_in(root):
        return [AnalysedRun(str(d), json.loads((d / "analysis/summary.json").read_text()))
                for d in sorted(root.iterdir())]

    # what collect does with the earlier collect.json of its output directory
    sets, _, reg = co.group(runs_in(root), co.previous_ids(str(out)))
    again = {tuple(r.path for r in x.runs): x.id for x in sets}
    for paths, sid in ids.items():
        assert again[paths] == sid
    assert sorted(k for r, k in again.items() if r not in ids) == ["S03", "S04"]
    assert sorted(reg.values()) == ["S01", "S02", "S03", "S04"]
    # listed in parameter order: mu = 0 first, its id notwithstanding
    assert sets[0].p("mu") == 0.0 and sets[0].id in ("S03", "S04")
    # without an earlier collect.json the sets are numbered in parameter order
    fresh, _, _ = co.group(runs_in(root), co.previous_ids(str(tmp_path / "nowhere")))
    assert [x.id for x in fresh] == ["S01", "S02", "S03", "S04"] and fresh[0].p("mu") == 0.0


def test_a_number_once_given_is_not_given_again_and_ids_stay_distinct():
    """A set no longer collected keeps its number in the registry; a new set does not take it. Two sets of
    one signature get distinct ids; widths follow the largest number; odd ids in an old file are ignored."""
    from mpdem.campaign.runs import Set
    known = {"a": "S01", "b": "S02", "gone": "S03"}
    sets = [Set("", {}, [], signature=sig) for sig in ("b", "new", "a", "a")]
    reg = co.number(sets, known)
    assert [x.id for x in sets] == ["S02", "S04", "S01", "S05"]
    assert reg["gone"] == "S03" and reg["new"] == "S04" and reg["a"] == "S01"
    many = [Set("", {}, [], signature=str(k)) for k in range(120)]
    co.number(many)
    assert many[0].id == "S001" and many[-1].id == "S120"
    late = [Set("", {}, [], signature="x")]
    co.number(late, {f"s{k}": f"S{k:02d}" for k in range(1, 100)})
    assert late[0].id == "S100"


def test_previous_ids_reads_the_registry_and_skips_what_it_cannot_use(tmp_path):
    (tmp_path / "collect.json").write_text(json.dumps({
        "set_ids": {"a": "S01", "b": "S\u00b2", "c": 3, "d": "S07"},
        "sets": {"S02": {"signature": "e"}, "S\u00b3": {"signature": "f"}, "S09": {"signature": ["g"]}}}))
    assert co.previous_ids(str(tmp_path)) == {"a": "S01", "d": "S07", "e": "S02"}
    (tmp_path / "collect.json").write_text("[1, 2]")
    assert co.previous_ids(str(tmp_path)) == {}
