"""Seeds and beds (``campaign.samples``): the two-way analysis of variance against scipy's paired t and
against draws with and without a shared seed offset; a pour seed on several beds against the pour seeds."""
import numpy as np
import pytest
from scipy import stats

from mpdem import config
from mpdem.analysis.fits import two_way_anova
from mpdem.campaign import samples
from mpdem.campaign.runs import AnalysedRun, Set


def params(**kw):
    vals = config.resolve({"run.max_steps": 1, **kw}).values
    return {k: vals[k] for k in config.PARAM_KEYS}


def make_set(sid, values, extra=None, **kw):
    """A set of runs, ``values`` {seed or (seed, bed): (z, phi)}."""
    runs = []
    for key, (z, p) in values.items():
        seed, bed = key if isinstance(key, tuple) else (key, key)
        runs.append(AnalysedRun(f"/nowhere/{sid}/{seed}-{bed}",
                                {"params": params(**{"run.seed": seed, **kw}), "z": z, "phi": p, "bed_seed": bed}))
    return Set(sid, {k: v for k, v in runs[0].params.items() if k != "run.seed"}, runs, dict(extra or {}))


def test_two_seeds_give_the_paired_t_squared():
    rng = np.random.default_rng(1)
    Y = rng.normal(0, 1, (6, 2)) + np.arange(6)[:, None]
    a = two_way_anova(Y)
    t = stats.ttest_rel(Y[:, 0], Y[:, 1])
    assert a["dof"] == [1, 5]
    assert a["F"] == pytest.approx(t.statistic ** 2) and a["p"] == pytest.approx(t.pvalue)
    assert a["effects"] == pytest.approx([(Y[:, 0].mean() - Y[:, 1].mean()) / 2, (Y[:, 1].mean() - Y[:, 0].mean()) / 2])
    with pytest.raises(ValueError, match="2 x 2"):
        two_way_anova(Y[:1])


def test_no_seed_offset_is_found_at_the_stated_rate_and_a_shared_one_is():
    rng = np.random.default_rng(2)
    set_means = np.array([6.1, 5.0, 4.9, 6.0, 5.2])[:, None]     # sets far apart: blocks, not the test
    ps = [two_way_anova(set_means + rng.normal(0, 0.01, (5, 3)))["p"] for _ in range(2000)]
    assert 0.035 < np.mean(np.array(ps) < 0.05) < 0.065
    offset = np.array([0.02, 0.0, -0.02])                       # seed 1's bed makes every pile denser
    a = two_way_anova(set_means + offset + rng.normal(0, 0.005, (5, 3)))
    assert a["p"] < 1e-3 and a["effects"] == pytest.approx(offset, abs=0.006)


def test_the_seeds_most_sets_share_are_tested_and_continued_sets_left_out():
    rng = np.random.default_rng(3)

    def vals(seeds, mu):
        return {s: (6.0 - 2 * mu + rng.normal(0, 0.01), 0.64 - 0.05 * mu + rng.normal(0, 0.001)) for s in seeds}

    sets = [make_set("S1", vals([1, 2, 3, 4, 5], 0.0), **{"contact.mu": 0.0}),
            make_set("S2", vals([1, 2, 3], 0.5), **{"contact.mu": 0.5}),
            make_set("S3", vals([1, 2, 3], 0.1), **{"contact.mu": 0.1}),
            make_set("S4", vals([1, 2], 1.0), **{"contact.mu": 1.0}),
            make_set("S5", vals([1, 2, 3], 0.0), extra={"stop.E_stop": 1e-10}, **{"contact.mu": 0.0}),
            make_set("S6", vals([1, 2, 3], 0.0), **{"contact.mu": 0.0, "pour.N": 5000})]
    (e,) = samples.seed_effects(sets)
    assert e["N"] == 20000 and e["seeds"] == [1, 2, 3] and e["sets"] == ["S1", "S2", "S3"]
    assert e["left_out"] == ["S4"]
    Y = [[s.runs[i].q["z"] for i in range(3)] for s in sets[:3]]
    assert e["z"]["F"] == pytest.approx(two_way_anova(Y)["F"])


def test_a_pour_seed_on_three_beds_against_the_pour_seeds():
    # a pile fixed by its pour seed: the beds scatter little, the seeds much -> F large
    fixed = make_set("S1", {(1, 1): (6.10, 0.640), (1, 101): (6.101, 0.6401), (1, 102): (6.099, 0.6399),
                            2: (6.13, 0.642), 3: (6.07, 0.638)}, **{"contact.mu": 0.0})
    # beds scatter as widely as seeds: F small
    free = make_set("S2", {(1, 1): (6.10, 0.640), (1, 101): (6.13, 0.642), (1, 102): (6.07, 0.638),
                           2: (6.101, 0.6401), 3: (6.099, 0.6399)}, **{"contact.mu": 0.5})
    plain = make_set("S3", {1: (5.0, 0.61), 2: (5.1, 0.61)}, **{"contact.mu": 1.0})
    a, b = samples.bed_scatter([fixed, free, plain])
    assert a["set"] == "S1" and b["set"] == "S2"
    assert [r[:2] for r in a["runs"]] == [[1, 1], [1, 101], [1, 102], [2, 2], [3, 3]]
    assert a["z"]["dof"] == [2, 2] and a["z"]["p"] < 0.01
    assert a["z"]["scatter"] == pytest.approx(0.001)
    assert a["z"]["seed_scatter"] == pytest.approx(np.std([6.10, 6.13, 6.07], ddof=1))
    assert b["z"]["p"] > 0.9
    ref = stats.f_oneway([6.10, 6.101, 6.099], [6.13], [6.07])
    assert a["z"]["F"] == pytest.approx(ref.statistic) and a["z"]["p"] == pytest.approx(ref.pvalue)
    text = "\n".join(samples.section(samples.tests([fixed, free, plain])))
    assert "seed 1 bed 101: z 6.1010" in text and "No two sets of one size share two seeds." not in text
