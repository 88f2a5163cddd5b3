"""The F_t/F_n collapse test across mu >= 1 (``campaign.ratio``; docs/model.md 6.7).

Known answers: a run's numbers equal those of the contacts it was made from (Coulomb-capped
contacts at mu = 1 included); the analysis of variance equals scipy's; over many families drawn
from one distribution the test rejects at its stated rate, and it finds a shift of the
distribution between sets and the 1/mu of zeta (the control).
"""
import json

import numpy as np
import pytest
from scipy import stats

from mpdem import config
from mpdem.analysis import fits, mobilisation, report
from mpdem.campaign import ratio, verdict
from mpdem.campaign.runs import AnalysedRun, Set, families
from mpdem.io import rundir


def params(mu, seed, bins=50):
    vals = config.resolve({"run.max_steps": 1, "contact.mu": mu, "run.seed": seed,
                           "analysis.zeta_bins": bins}).values
    return {k: vals[k] for k in config.PARAM_KEYS}


def draw(rng, n, scale=0.08, mu=10.0, sliding=0):
    """(F_n (n,), F_t (n, 3)) with F_t/F_n ~ Gamma(2, scale) capped at mu, ``sliding`` at the cap exactly."""
    F_n = rng.exponential(1.0, n) + 1e-3
    r = np.minimum(rng.gamma(2.0, scale, n), mu)
    r[:sliding] = mu
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    return F_n, (r * F_n)[:, None] * u, r


def make_run(path, mu, seed, F_n, F_t, bins=50):
    """A run directory as ``mpdem analyze`` leaves it: analysis/zeta.csv and the summary's zeta."""
    fr = mobilisation.force_ratios(F_n, F_t, mu, bins)
    (path / "analysis").mkdir(parents=True)
    head, cols = report.zeta_table(fr)
    rundir.write_csv(str(path / "analysis" / "zeta.csv"), head, zip(*cols))
    s = {"params": params(mu, seed, bins),
         "zeta": {k: fr[k] for k in ("n_contacts", "n_ratio_above_one", "zeta_mean") if k in fr}}
    (path / "analysis" / "summary.json").write_text(json.dumps(rundir.json_safe(s)))
    return AnalysedRun(str(path), s)


def family(tmp_path, rng, mus=(1, 2, 10), seeds=(1, 2, 3), n=4000, scale=None):
    """Sets of runs, one per mu; ``scale`` {mu: Gamma scale} (default 0.08 for every mu)."""
    sets = []
    for mu in mus:
        runs = []
        for sd in seeds:
            F_n, F_t, _ = draw(rng, n, (scale or {}).get(mu, 0.08), mu)
            runs.append(make_run(tmp_path / f"mu{mu}_s{sd}", mu, sd, F_n, F_t))
        sets.append(Set(f"S{mu}", {k: v for k, v in runs[0].params.items() if k != "run.seed"} |
                        {"run.seed": 0}, runs))
    return sets


def test_a_run_gives_the_numbers_of_its_contacts_with_the_coulomb_capped_ones(tmp_path):
    rng = np.random.default_rng(5)
    F_n, F_t, r = draw(rng, 3000, scale=0.3, mu=1.0, sliding=40)   # 40 contacts sliding at F_t = F_n
    run = make_run(tmp_path / "r", 1.0, 1, F_n, F_t)
    got = ratio.run_numbers(run)
    ft = np.linalg.norm(F_t, axis=1)
    assert got["n"] == 3000
    assert got["ratio_mean"] == pytest.approx(np.mean(ft / F_n), rel=1e-12)
    for x in ratio.POINTS:
        assert got[f"below_{x:g}"] == pytest.approx(np.mean(ft / F_n < x), abs=1e-12)
    # zeta at mu = 2 is half the ratio, the ratio's numbers unchanged
    run2 = make_run(tmp_path / "r2", 2.0, 1, F_n, F_t)
    got2 = ratio.run_numbers(run2)
    assert got2["zeta_mean"] == pytest.approx(got["zeta_mean"] / 2, rel=1e-12)
    assert got2["ratio_mean"] == pytest.approx(got["ratio_mean"], rel=1e-12)


def test_bins_whose_edges_miss_the_points_are_refused_by_name(tmp_path):
    rng = np.random.default_rng(1)
    F_n, F_t, _ = draw(rng, 200)
    run = make_run(tmp_path / "r", 2.0, 1, F_n, F_t, bins=7)
    with pytest.raises(ValueError, match="0.1 is not an upper bin edge"):
        ratio.run_numbers(run)
    # in a family the run is left out, with the reason, and the test goes on without it
    good = [make_run(tmp_path / f"g{mu}_{sd}", mu, sd, *draw(rng, 500)[:2]) for mu in (2.0, 10.0) for sd in (1, 2)]
    sets = [Set(f"S{mu:g}", {k: v for k, v in g[0].params.items() if k != "run.seed"} | {"run.seed": 0}, g)
            for mu, g in ((2.0, good[:2] + [run]), (10.0, good[2:]))]
    e = ratio.family_test(sets)
    assert e["status"] == "tested" and e["n_seeds"] == [2, 2] and "not an upper bin edge" in e["left_out"][0]


def test_a_run_without_the_ratio_table_gives_nothing(tmp_path):
    rng = np.random.default_rng(1)
    F_n, F_t, _ = draw(rng, 200, mu=0.5)
    assert ratio.run_numbers(make_run(tmp_path / "r", 0.5, 1, F_n, F_t)) is None   # mu < 1: no F_t/F_n columns


def test_anova_equals_scipys():
    rng = np.random.default_rng(2)
    groups = [rng.normal(0, 1, 3), rng.normal(0.5, 1, 2), rng.normal(0, 1, 4)]
    a = fits.one_way_anova(groups)
    ref = stats.f_oneway(*groups)
    assert a["F"] == pytest.approx(ref.statistic, rel=1e-12)
    assert a["p"] == pytest.approx(ref.pvalue, rel=1e-9)
    assert a["dof"] == [2, 6]
    pooled = np.sqrt(sum(((g - g.mean()) ** 2).sum() for g in groups) / 6)
    assert a["scatter"] == pytest.approx(pooled, rel=1e-12)


def test_anova_rejects_at_its_stated_rate_and_finds_a_shift():
    rng = np.random.default_rng(3)
    p_same = [fits.one_way_anova([rng.normal(0, 1, 3) for _ in range(3)])["p"] for _ in range(2000)]
    # under one distribution p is uniform: 5 % below 0.05 (binomial sd 0.5 %)
    assert 0.035 < np.mean(np.array(p_same) < 0.05) < 0.065
    p_shift = [fits.one_way_anova([rng.normal(m, 1, 3) for m in (0, 0, 6)])["p"] for _ in range(200)]
    assert np.median(p_shift) < 1e-3


def test_one_distribution_for_every_mu_collapses_and_zeta_does_not(tmp_path):
    rng = np.random.default_rng(11)
    sets = family(tmp_path, rng)
    (fam, members), = families(sets, "contact.mu")
    e = ratio.family_test(members)
    assert e["status"] == "tested" and e["mu"] == [1, 2, 10] and e["n_seeds"] == [3, 3, 3]
    assert e["collapses"] and e["p_bonferroni"] > ratio.LEVEL
    assert ratio.LEVEL == verdict.P_K           # the family's word and the claim table's rows 30, 30b agree
    assert e["quantities"][ratio.CONTROL]["p"] < 1e-6
    z = e["quantities"][ratio.CONTROL]["mean"]
    assert z[0] / z[1] == pytest.approx(2.0, rel=0.05) and z[0] / z[2] == pytest.approx(10.0, rel=0.05)


def test_a_wider_distribution_at_one_mu_does_not_collapse(tmp_path):
    rng = np.random.default_rng(12)
    sets = family(tmp_path, rng, scale={10: 0.1})
    e = ratio.tests(sets)[0]
    assert e["status"] == "tested" and not e["collapses"] and e["p_bonferroni"] < 1e-3
    m = e["quantities"]["ratio_mean"]["mean"]
    assert m[2] == pytest.approx(0.2, rel=0.03) and m[0] == pytest.approx(0.16, rel=0.03)


def test_too_few_sets_or_seeds_are_not_tested(tmp_path):
    rng = np.random.default_rng(13)
    one_mu = family(tmp_path / "a", rng, mus=(0.5, 1))
    assert ratio.tests(one_mu) == []                          # one set of mu >= 1: no family to test
    one_seed = family(tmp_path / "b", rng, seeds=(1,))
    e = ratio.tests(one_seed)[0]
    assert e["status"] == "not tested" and "one seed" in e["reason"]
    lines = "\n".join(ratio.section(ratio.tests(family(tmp_path / "c", rng)), lambda f, drop: "fam")).split("\n")
    assert any("**collapses**" in ln for ln in lines) and any(ln.startswith("| mean ζ (control)") for ln in lines)
