"""Sets that differ from a reference in one setting (``campaign.contrasts``): the difference of z and phi,
its error from the pooled seed scatter and Student's p, against values drawn with a known difference."""
import math

import numpy as np
import pytest
from scipy import stats

from mpdem import config
from mpdem.campaign import contrasts
from mpdem.campaign.runs import AnalysedRun, Set


def params(**kw):
    vals = config.resolve({"run.max_steps": 1, **kw}).values
    return {k: vals[k] for k in config.PARAM_KEYS}


def make_set(sid, zs, phis, **kw):
    runs = [AnalysedRun(f"/nowhere/{sid}/{i}", {"params": params(**{"run.seed": i + 1, **kw}), "z": z, "phi": p})
            for i, (z, p) in enumerate(zip(zs, phis))]
    return Set(sid, {k: v for k, v in runs[0].params.items() if k != "run.seed"}, runs)


def test_the_difference_its_error_and_p_are_students_with_the_pooled_scatter():
    ref = make_set("S1", [5.0, 5.1, 4.9], [0.61, 0.612, 0.608])
    hot = make_set("S2", [5.3, 5.2], [0.615, 0.617], **{"pour.K0": 50.0})
    (e,) = contrasts.contrasts([ref, hot])
    assert e["vary"] == "K0" and e["reference"] == "S1" and e["value"] == 0.0
    (r,) = e["rows"]
    assert r["set"] == "S2" and r["value"] == 50.0 and (r["n_seeds"], r["n_ref"]) == (2, 3)
    z = r["z"]
    assert z["diff"] == pytest.approx(0.25)
    ss = 0.02 + 0.005                                  # sum of squares about each set's mean
    s = math.sqrt(ss / 3)
    assert z["dof"] == 3 and z["err"] == pytest.approx(s * math.sqrt(1 / 2 + 1 / 3))
    # Student's two-sample t with the pooled variance is the same test
    ref_t = stats.ttest_ind([5.3, 5.2], [5.0, 5.1, 4.9], equal_var=True)
    assert z["t"] == pytest.approx(ref_t.statistic) and z["p"] == pytest.approx(ref_t.pvalue)


def test_no_difference_is_found_at_the_stated_rate_and_a_real_one_is():
    rng = np.random.default_rng(4)
    ps = []
    for _ in range(1000):
        a = make_set("S1", rng.normal(5.0, 0.02, 3), rng.normal(0.61, 0.001, 3))
        b = make_set("S2", rng.normal(5.0, 0.02, 3), rng.normal(0.61, 0.001, 3), **{"contact.model": "hertz"})
        ps.append(contrasts.contrasts([a, b])[0]["rows"][0]["z"]["p"])
    assert 0.03 < np.mean(np.array(ps) < 0.05) < 0.07
    a = make_set("S1", rng.normal(5.0, 0.02, 3), rng.normal(0.61, 0.001, 3))
    b = make_set("S2", rng.normal(5.2, 0.02, 3), rng.normal(0.61, 0.001, 3), **{"contact.model": "hertz"})
    e = contrasts.contrasts([a, b])[0]
    assert e["vary"] == "model" and e["rows"][0]["z"]["p"] < 1e-3
    assert e["rows"][0]["z"]["diff"] == pytest.approx(0.2, abs=0.05)


def test_a_family_without_a_set_at_the_default_or_of_one_set_is_left_out():
    a = make_set("S1", [5.0, 5.1], [0.61, 0.61], **{"pour.K0": 20.0})
    b = make_set("S2", [5.0, 5.1], [0.61, 0.61], **{"pour.K0": 50.0})
    assert contrasts.contrasts([a, b]) == []
    assert contrasts.contrasts([make_set("S3", [5.0], [0.61])]) == []
    other_mu = make_set("S4", [4.0, 4.1], [0.6, 0.6], **{"pour.K0": 50.0, "contact.mu": 1.0})
    assert contrasts.contrasts([make_set("S5", [5.0, 5.1], [0.61, 0.61]), other_mu]) == []   # two things differ


def test_one_seed_a_set_gives_the_difference_without_an_error():
    e = contrasts.contrasts([make_set("S1", [5.0], [0.61]), make_set("S2", [5.2], [0.62], **{"pour.phi_i": 0.3})])
    z = e[0]["rows"][0]["z"]
    assert z["diff"] == pytest.approx(0.2) and math.isnan(z["err"]) and math.isnan(z["p"])
    lines = "\n".join(contrasts.section(e, lambda f, drop: "fam")).split("\n")
    assert any("phi_i = 0.3 vs 0.13" in ln and "0.200" in ln and "—" in ln for ln in lines)


def test_the_sets_away_from_the_default_are_compared_among_themselves():
    ref = make_set("S1", [4.9, 5.0, 5.1], [0.61, 0.611, 0.612])
    k20 = make_set("S2", [5.2, 5.25, 5.3], [0.62, 0.621, 0.622], **{"pour.K0": 20.0})
    k50 = make_set("S3", [5.2, 5.3, 5.25], [0.62, 0.622, 0.621], **{"pour.K0": 50.0})
    (e,) = contrasts.contrasts([ref, k20, k50])
    a = e["among"]
    assert a["sets"] == ["S2", "S3"] and a["values"] == [20.0, 50.0]
    assert a["z"]["F"] == pytest.approx(0.0, abs=1e-9) and a["z"]["p"] == pytest.approx(1.0)   # equal means
    assert a["z"]["dof"] == [1, 4]
    assert [r["z"]["p"] < 0.05 for r in e["rows"]] == [True, True]                              # both off the default
    assert any(ln.startswith("- K0 = 20.0, 50.0 (S2, S3): z: F = 0.00 (1, 4), p = 1")
               for ln in contrasts.section([e], lambda f, drop: "fam"))
    assert "among" not in contrasts.contrasts([ref, k20])[0]
