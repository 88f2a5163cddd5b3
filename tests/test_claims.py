"""The verdict rule of the claim table (``campaign.verdict``) and the table ``collect`` writes from it
(``campaign.claimtable``, ``campaign.claims``)."""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from mpdem.campaign import claims, claimtable as ct, ladder, sources as src, verdict as V
from mpdem.campaign.runs import AnalysedRun, Set

ROOT = Path(__file__).resolve().parents[1]
NAN = float("nan")


# ---------------------------------------------------------------- the rule

def test_two_combined_errors_is_reproduced_and_a_tenth_more_differs():
    """sigma = sqrt(0.375^2 + 0.5^2) = 0.625 exactly: 1.25 away is 2.0 sigma, 1.3125 is 2.1."""
    at = V.compare(1.25, 0.375, 0.0, 0.5)
    assert at.kind == "reproduced" and at.n_sigma == 2.0 and at.sigma == 0.625
    past = V.compare(1.3125, 0.375, 0.0, 0.5)
    assert past.kind == "differs" and math.isclose(past.n_sigma, 2.1)
    assert past.text() == "differs by +1.31 (2.1 σ)"   # the difference to two digits of sigma
    below = V.compare(-1.3125, 0.375, 0.0, 0.5)
    assert below.kind == "differs" and below.diff == -1.3125


def test_the_papers_error_is_combined_with_ours_not_replaced_by_an_acceptance():
    """Row 1's numbers: 6.1354 +- 0.0015 against 6.144 +- 0.002 is 3.4 combined errors: it differs (a
    +-0.02 acceptance would have called it reproduced)."""
    v = V.compare(6.1354, 0.0015, 6.144, 0.002)
    assert v.kind == "differs"
    assert math.isclose(v.n_sigma, 0.0086 / math.hypot(0.0015, 0.002), rel_tol=1e-9)
    assert 3.4 <= v.n_sigma < 3.5


def test_a_paper_value_without_an_error_takes_the_tolerance_of_its_claim():
    """4.90 quoted without an error: the claim's tolerance (half its last digit, 0.005) is the paper's
    sigma; with no tolerance at all only our error counts."""
    c = next(c for c in claims.CLAIMS if c.id == "4")
    assert c.paper_err == 0.005 and "last digit" in c.tolerance
    m = src.Measure(4.8447, 0.0040, 3, "3 runs", "S15")
    v = ct.judge(c, m)
    assert v.kind == "differs" and math.isclose(v.sigma, math.hypot(0.004, 0.005))
    wide = ct.judge(c, src.Measure(4.893, 0.0040, 3, "3 runs", "x"))
    assert wide.kind == "reproduced"
    alone = V.compare(4.893, 0.004, 4.90, None)
    assert alone.kind == "reproduced" and math.isclose(alone.sigma, 0.004)


def test_one_seed_against_a_claim_without_tolerance_is_not_determined():
    v = V.compare(0.03, NAN, 0.0, None)
    assert v.kind == "not determined" and "no error" in v.why
    # against a stated paper error the single value is judged on the paper's error alone, and says so
    w = V.compare(6.141, NAN, 6.144, 0.002)
    assert w.kind == "reproduced" and w.sigma == 0.002 and "1 seed" in w.why


def test_bounds_ranges_and_signs():
    assert V.bound(4.87, 0.02, 4.0).kind == "reproduced"
    assert V.bound(4.87, 0.02, 4.0).text() == "reproduced (beyond by 43.5 σ)"
    assert V.bound(4.03, 0.02, 4.0).kind == "differs"            # above, but not by 2 sigma
    assert V.bound(4.03, 0.02, 4.0).text() == "differs: +0.030 beyond the bound (1.5 σ, not 2)"
    assert V.bound(7.7e-6, NAN, 1e-8, above=False).kind == "differs"
    assert V.in_range(5e6, 1e5, 3e6, 8e6).kind == "reproduced"
    r = V.in_range(2.0e6, 0.4e6, 3e6, 8e6)
    assert r.kind == "differs" and r.diff == -1.0e6 and math.isclose(r.n_sigma, 2.5)
    assert V.in_range(2.4e6, 0.4e6, 3e6, 8e6).kind == "reproduced"
    both = V.sign([(-0.6, 0.01), (-0.5, 0.02)])
    assert both.kind == "reproduced" and both.why == "the nearest step to 0 (step 2) 25.0 σ"
    assert V.sign([(-0.6, 0.01), (0.5, 0.02)]).kind == "differs"
    assert V.sign([(-0.6, 0.01), (-0.01, 0.02)]).kind == "differs"   # a fall within 2 sigma is not resolved
    one = V.sign([(-0.6, NAN)])
    assert one.kind == "reproduced" and one.why == "steps 1 without an error (1 seed): judged by sign"
    mixed = V.sign([(-0.6, NAN), (-0.1, 0.02)])
    assert mixed.why == "the nearest step to 0 (step 2) 5.0 σ; steps 1 without an error (1 seed): judged by sign"


# ---------------------------------------------------------------- rows from sources

def _run(i, z, phi=0.6, **p):
    params = {"contact.mu": 0.5, "contact.epsilon": 0.88, "contact.k_n": 2e5, "pour.N": 20000, "run.seed": i,
              **p}
    return AnalysedRun(f"r{i}", {"params": params, "z": z, "phi": phi})


def _set(sid, zs, **p):
    s = Set(sid, {"contact.mu": 0.5, "contact.k_n": 2e5, **p}, [_run(i + 1, z, **p) for i, z in enumerate(zs)])
    return s


def _claim(**kw):
    base = dict(id="x", claim="z", paper="4.90", kind="compare", value=4.90, paper_err=0.005, tolerance="t")
    return claims.Claim(**{**base, **kw})


def test_a_rare_kind_of_sphere_is_counted_over_the_runs_with_its_poisson_error():
    """Row 13: 1, 1 and 2 spheres with n = 2 among 10 000 bulk spheres each: 4 of 30 000, error sqrt(4);
    a bound at 0 is then passed by exactly 2 sigma (sqrt 4), not by a standard error over three tiny counts."""
    s = _set("S15", [4.85, 4.86, 4.84])
    for r, k in zip(s.runs, (1, 1, 2)):
        r.s.update(P_z=[0.0, 0.0, k / 10000, 0.5], n_bulk=10000)
    m = src.Count("S15", 2).resolve(src.Context([s], {}, []))
    assert m.value == pytest.approx(4 / 30000) and m.err == pytest.approx(2 / 30000)
    assert m.count == "4 of 30000 bulk spheres in 3 runs, Poisson error"
    v = ct.judge(claims.Claim("13", "n = 2 appear", "P(2) > 0", "bound", 0.0), m)
    assert v.kind == "reproduced" and v.n_sigma == pytest.approx(2.0)
    s.runs[0].s["P_z"] = [0.0, 0.0]
    assert src.Count("S15", 2).resolve(src.Context([s], {}, [])).status == "not measured"


def test_a_row_whose_set_is_absent_reads_not_measured():
    ctx = src.Context([_set("S01", [4.85, 4.86])], {}, [])
    r = ct.row(_claim(ours=[src.S("S99")]), ctx)
    assert r["verdict"].kind == "not measured" and r["ours"] == "—" and r["reason"] == ""


def test_a_row_reads_the_set_mean_error_and_count():
    ctx = src.Context([_set("S01", [4.85, 4.86, 4.87])], {}, [])
    r = ct.row(_claim(ours=[src.S("S01")]), ctx)
    assert r["count"] == "3 runs" and r["ours"].startswith("4.8600 ± 0.0058")
    assert r["verdict"].kind == "differs" and r["reason"] == "open: no cause found"
    r2 = ct.row(_claim(ours=[src.S("S01")], if_differs=("explained", "the window")), ctx)
    assert r2["reason"] == "explained: the window"


def test_a_fit_that_cannot_tell_its_parameters_apart_is_not_determined():
    fit_res = {"eq7": [{"sets": ["S01", "S02"], "status": "not fitted", "reason": "2 distinct k_n"},
                       {"sets": ["S03"], "status": "fitted", "determined": False, "alpha_n": 0.3,
                        "reason": "correlation 1"},
                       {"sets": ["S04"], "status": "fitted", "determined": True, "alpha_n": 0.49,
                        "alpha_n_err": 0.01}]}
    ctx = src.Context([], fit_res, [])
    c = _claim(value=0.498, paper_err=0.002, tolerance="")
    for sid in ("S01", "S03"):
        r = ct.row(c.__class__(**{**c.__dict__, "ours": [src.Fit("eq7", "alpha_n", sid)]}), ctx)
        assert r["verdict"].kind == "not determined", r
    r = ct.row(c.__class__(**{**c.__dict__, "ours": [src.Fit("eq7", "alpha_n", "S04")]}), ctx)
    assert r["verdict"].kind == "reproduced"


def test_a_difference_of_a_one_setting_contrast_takes_its_pooled_error():
    a, b = _set("S26", [4.872]), _set("S15", [4.84, 4.845, 4.85])
    fit_res = {"contrasts": [{"reference": "S15", "rows": [{"set": "S26", "z": {"diff": 0.027, "err": 0.008}}]}]}
    m = src.Diff(src.S("S26"), src.S("S15")).resolve(src.Context([a, b], fit_res, []))
    assert m.ok and m.err == 0.008 and math.isclose(m.value, 4.872 - 4.845)


def test_a_one_run_side_of_a_difference_takes_the_other_sides_seed_scatter():
    a, b = _set("S27", [6.048]), _set("S17", [6.043, 6.053])
    m = src.Diff(src.S("S27"), src.S("S17")).resolve(src.Context([a, b], {}, []))
    sd = 0.005 * math.sqrt(2)                     # S17's standard deviation: its sem times sqrt(2)
    assert math.isclose(m.err, math.hypot(sd, 0.005), rel_tol=1e-9)


def test_the_count_of_a_difference_says_when_a_one_run_side_borrowed_its_error():
    a, b = _set("S27", [6.048]), _set("S17", [6.043, 6.053])
    m = src.Diff(src.S("S27"), src.S("S17")).resolve(src.Context([a, b], {}, []))
    assert m.count == "1 + 2 runs" + src.LENT
    both = src.Diff(src.S("S17"), src.S("S17")).resolve(src.Context([b], {}, []))
    assert both.count == "2 + 2 runs"


def _sign_claim(*sids):
    return _claim(kind="sign", value=-1, paper="falls", ours=[src.S(s) for s in sids])


def test_a_step_of_a_sign_with_a_one_seed_side_takes_the_other_sides_seed_scatter():
    """4.85 +- 0.01 (sd 0.0173 over 3 seeds) to one seed at 4.84: a fall of 0.01 against an error of
    0.0173 * sqrt(1 + 1/3) = 0.02 is within 2 sigma, so the claim is not resolved (by its sign alone it
    was reproduced); a fall of 0.1 is."""
    many = _set("S01", [4.84, 4.85, 4.86])
    near, far = _set("S02", [4.84]), _set("S03", [4.75])
    r = ct.row(_sign_claim("S01", "S02"), src.Context([many, near], {}, []))
    assert r["verdict"].kind == "differs" and "within 2 σ" in r["verdict"].why
    assert "other's seed scatter" in r["verdict"].why
    r = ct.row(_sign_claim("S01", "S03"), src.Context([many, far], {}, []))
    assert r["verdict"].kind == "reproduced" and "step 1: a side of 1 seed" in r["verdict"].why
    # two sides of one seed: no error to borrow, judged by its sign and said so
    r = ct.row(_sign_claim("S02", "S03"), src.Context([near, far], {}, []))
    assert r["verdict"].kind == "reproduced" and "judged by sign" in r["verdict"].why


def test_two_one_seed_sides_take_the_seed_scatter_pooled_over_their_n_and_mu(tmp_path):
    """The rule: a difference of two sets of one seed each takes one run's seed scatter pooled over the sets
    of their N and μ, sqrt(2) times it, and says so; sets of another μ lend nothing (no error then: judged by
    its side alone, as before). The same from another collect's sets.csv (each set's sem and seeds)."""
    near, far = _set("S02", [4.84]), _set("S03", [4.75])
    many, other_mu = _set("S01", [4.84, 4.85, 4.87]), _set("S04", [6.0, 6.3], **{"contact.mu": 0.0})
    m = src.Diff(src.S("S02"), src.S("S03")).resolve(src.Context([near, far, many, other_mu], {}, []))
    assert math.isclose(m.err, float(np.std([4.84, 4.85, 4.87], ddof=1)) * math.sqrt(2), rel_tol=1e-12)
    assert m.count == "1 + 1 runs" + src.POOLED_BOTH
    alone = src.Diff(src.S("S02"), src.S("S03")).resolve(src.Context([near, far, other_mu], {}, []))
    assert math.isnan(alone.err) and alone.count == "1 + 1 runs"
    (tmp_path / "dev").mkdir()
    (tmp_path / "dev" / "sets.csv").write_text(
        "set,mu,N,n_seeds,z_mean,z_sem\nS06,0.5,2000,1,4.963,\nS07,0.5,2000,1,4.570,\nS03,0.5,2000,5,4.98,0.012\n"
        "S10,0.5,2000,2,4.86,0.0068\nS05,0.0,2000,4,6.05,0.0455\nS99,0.5,8000,3,4.9,0.1\n")
    ctx = src.Context([], {}, [], out=str(tmp_path))
    m = src.Diff(src.Ext("dev", "S07"), src.Ext("dev", "S06")).resolve(ctx)
    sd = math.sqrt((0.012 ** 2 * 5 * 4 + 0.0068 ** 2 * 2 * 1) / (4 + 1))     # S03's and S10's: μ 0.5, N 2000
    assert math.isclose(m.err, sd * math.sqrt(2), rel_tol=1e-12) and m.count.endswith(src.POOLED_BOTH)
    r = ct.row(_claim(kind="nonzero", value=None, paper="differ", ours=[src.Diff(src.Ext("dev", "S07"),
                                                                                src.Ext("dev", "S06"))]), ctx)
    assert r["verdict"].kind == "reproduced" and math.isclose(r["verdict"].sigma, sd * math.sqrt(2), rel_tol=1e-12)


def test_a_one_seed_value_beside_a_bound_is_judged_by_its_side_and_says_so():
    c = _claim(kind="bound", value=4.0, paper="> 4", ours=[src.S("S02")], also=[src.S("S02")])
    r = ct.row(c, src.Context([_set("S02", [5.47])], {}, []))
    assert r["verdict"].kind == "reproduced" and "by its side of the bound alone" in r["verdict"].why
    assert "beyond (1 seed, no error: by its side alone)" in r["context"]


def test_a_one_seed_value_alone_is_judged_with_its_sets_pooled_seed_scatter_as_well(tmp_path):
    """Row 38's case: one run alone against the paper's 4.69 +- 0.005 differs on the paper's error alone
    (3.1 sigma) and is reproduced with the seed scatter pooled over the sets of its N and mu: neither is
    measured on it, so the row is not determined and gives both. Where both readings agree the verdict
    stands and says so; with no set of two seeds at its N and mu it is judged as before."""
    c = _claim(value=4.69, paper="4.69")
    one, pair = _set("S34", [4.7054]), _set("S10", [4.57, 4.62])
    other_mu = _set("S04", [6.0, 6.3], **{"contact.mu": 0.0})
    m = src.S("S34").resolve(src.Context([one, pair, other_mu], {}, []))
    sd = float(np.std([4.57, 4.62], ddof=1))
    assert math.isclose(m.pooled_sd, sd, rel_tol=1e-12) and math.isnan(m.err)
    v = ct.judge(c, m)
    assert v.kind == "not determined"
    assert v.why.startswith("it rests on 1 seed with no error of its own: with it differs by +0.0154 (3.1 σ)")
    assert f"with the seed scatter pooled over its N and μ's sets (±{sd:.2g}) as its error: 4.705 ± 0.035, " \
           "reproduced (0.4 σ)" in v.why
    # a second set of two seeds moves nothing but the scatter: pooled over both
    tight = _set("S22", [4.6056, 4.6088])
    m2 = src.S("S34").resolve(src.Context([one, pair, tight], {}, []))
    assert math.isclose(m2.pooled_sd, math.sqrt((sd ** 2 + float(np.std([4.6056, 4.6088], ddof=1)) ** 2) / 2),
                        rel_tol=1e-12)
    # far beyond either error: the verdict stands, and says it was read both ways
    far = ct.judge(c, src.S("S34").resolve(src.Context([_set("S34", [5.2]), pair], {}, [])))
    assert far.kind == "differs" and "in place of 1 seed with no error of its own" in far.why
    # no set of its N and mu with two seeds: judged on the paper's error alone, as the rule says
    alone = ct.judge(c, src.S("S34").resolve(src.Context([one, other_mu], {}, [])))
    assert alone.kind == "differs" and alone.why == "this work: 1 seed, no error; the paper's error alone"
    # a bound: by its side alone and with the scatter, both beyond
    b = ct.judge(_claim(kind="bound", value=4.0, paper="> 4"), m)
    assert b.kind == "reproduced" and "in place of 1 seed with no error of its own" in b.why
    # another collect's set of one seed: the scatter from its sets.csv (each set's sem and seeds), its N and μ's
    (tmp_path / "dev").mkdir()
    (tmp_path / "dev" / "sets.csv").write_text(
        "set,mu,N,n_seeds,z_mean,z_sem\nS06,0.5,8000,1,4.7054,\nS10,0.5,8000,2,4.595,0.025\n"
        "S05,0.0,8000,4,6.05,0.0455\n")
    e = src.Ext("dev", "S06").resolve(src.Context([], {}, [], out=str(tmp_path)))
    assert math.isclose(e.pooled_sd, 0.025 * math.sqrt(2), rel_tol=1e-12)
    assert ct.judge(c, e).kind == "not determined"


def test_frictional_excess_over_the_count_is_taken_run_by_run():
    """z and 4 + n_m/3 of the same runs move together: their difference's error is the runs' scatter of
    the difference, not the two scatters in quadrature, and its count is the runs once."""
    runs = [AnalysedRun(f"r{i}", {"params": {"contact.mu": 0.5, "run.seed": i}, "z": z, "isostatic": {"n_m": nm}})
            for i, (z, nm) in enumerate([(4.80, 0.9), (4.90, 1.2), (5.00, 1.5)])]
    s = Set("S15", {"contact.mu": 0.5, "contact.k_n": 2e5}, runs)
    c = next(c for c in claims.CLAIMS if c.id == "28")
    ctx = src.Context([s], {}, [])
    # z - (4 + n_m/3) = 0.5 in each run: (almost) no scatter, where z's own spread is 0.1
    m = c.ours[0].resolve(ctx)
    assert math.isclose(m.value, 0.5) and m.err < 1e-12
    assert ct.row(c, ctx)["count"] == "3 runs"
    assert claims._above_count({"z": 5.0, "isostatic": {"n_m": 3.0}}) == 0.0


def test_the_rule_covers_one_seed_values_and_tests():
    assert "one seed has no error of its own" in V.RULE and "p ≥ 0.0455" in V.RULE
    assert math.isclose(V.P_K, 1 - math.erf(V.K / math.sqrt(2)), abs_tol=1e-5)


def test_a_ladder_rung_reads_running_while_its_directory_has_no_converged_run(tmp_path):
    lad = tmp_path / "ladder-size" / "mu0_s1"
    (lad / "kn2e6").mkdir(parents=True)
    (lad / "kn2e7").mkdir()
    ctx = src.Context([], {"ladder": []}, [], str(tmp_path), [str(tmp_path / "ladder-size")])
    assert src.Rung(0.0, "z", 2e7).resolve(ctx).status == "running"
    far = src.Rung(0.0, "z", 2e9).resolve(ctx)
    assert far.status == "not measured" and "mu0_s1/kn2e7" in far.why and "no converged rung at 2e9" in far.why
    assert src.Rung(0.5, "z", 2e6).resolve(ctx).status == "not measured"
    fit_res = {"ladder": [{"family": {"mu": 0.0}, "rungs": [{"set": "S27", "k_n": 2e6, "n_runs": 1, "z": 6.048,
                                                             "z_sem": None}]}]}
    m = src.Rung(0.0, "z", "top").resolve(src.Context([], fit_res, [], str(tmp_path), []))
    assert m.ok and m.value == 6.048 and m.k_n == 2e6 and "no error" in m.count


def test_ladders_find_their_base_and_fit_eq7_only_with_four_k_n():
    from mpdem import config

    def p(k_n, seed):
        vals = config.resolve({"run.max_steps": 1, "contact.mu": 0.0, "contact.k_n": k_n, "pour.N": 20000,
                               "run.seed": seed}).values
        return {k: vals[k] for k in config.PARAM_KEYS}

    def st(sid, k_n, zs, k_from=None):
        runs = [AnalysedRun(f"{sid}{i}", {"params": p(k_n, i + 1), "z": z, "phi": 0.64}) for i, z in enumerate(zs)]
        return Set(sid, p(k_n, 1), runs, {"stiffen.k_n_from": k_from} if k_from else {})

    base, poured2e6 = st("S12", 2e5, [6.13, 6.14, 6.135]), st("S17", 2e6, [6.043, 6.053])
    r6 = st("S27", 2e6, [6.048], 2e5)
    calls = []
    got = ladder.ladders([base, poured2e6, r6], lambda fam, m: calls.append(m) or {"status": "fitted"})
    assert len(got) == 1 and got[0]["base"] == "S12" and got[0]["sets"] == ["S12", "S27"]
    assert got[0]["status"] == "not fitted" and "needs 4" in got[0]["reason"] and not calls
    rungs = [r6, st("S28", 2e7, [6.03], 2e6), st("S29", 2e8, [6.02], 2e7)]
    got = ladder.ladders([base, poured2e6, *rungs], lambda fam, m: calls.append(m) or {"status": "fitted"})
    # four k_n, but one pile climbed: its offset cannot be told from its noise; the sets' means fitted beside
    assert got[0]["status"] == "not fitted" and "two piles" in got[0]["reason"]
    assert [s.id for s in calls[0]] == ["S12", "S27", "S28", "S29"] and got[0]["set_means"]["status"] == "fitted"
    # two piles climb (seed 2 sits 0.004 below seed 1 at every rung): eq. 7 over the runs
    z = lambda k, off: 6.0 + 0.13 * (k / 2e5) ** -0.5 + off     # noqa: E731
    two = [st("S12", 2e5, [z(2e5, 0.002), z(2e5, -0.002) + 1e-4, z(2e5, 0.0)]),
           st("S27", 2e6, [z(2e6, 0.002), z(2e6, -0.002) - 1e-4], 2e5),
           st("S28", 2e7, [z(2e7, 0.002) - 1e-4, z(2e7, -0.002)], 2e6), st("S29", 2e8, [z(2e8, 0.002)], 2e7)]
    got = ladder.ladders([*two, poured2e6], lambda fam, m: {"status": "fitted"})
    assert got[0]["status"] == "fitted" and got[0]["n_piles"] == 3 and got[0]["n_points"] == 8
    assert abs(got[0]["alpha_n"] - 0.5) < 0.01 and abs(got[0]["z_inf"] - 6.0) < 0.002
    # rungs stopped on the translational energy (a spinner) find the pile they were stiffened from, poured on the
    # default rule, when no poured set shares their rule; one that does is taken first
    tr = {"stop.energy": "translational"}
    spun = [Set(r.id, r.params, r.runs, {**r.extra, **tr}) for r in rungs]
    got = ladder.ladders([base, poured2e6, *spun], lambda fam, m: {"status": "fitted"})
    assert got[0]["base"] == "S12" and got[0]["sets"] == ["S12", "S27", "S28", "S29"]
    same_rule = Set("S40", base.params, base.runs, dict(tr))
    got = ladder.ladders([base, same_rule, poured2e6, *spun], lambda fam, m: {"status": "fitted"})
    assert got[0]["base"] == "S40"


def test_a_ladders_overlap_fit_spans_its_base_and_draws_its_piles():
    """The overlap fit of a stiffened family takes its base set first (``ladder.with_base``) and bootstraps
    piles (a run's seed and bed seed), each with its runs at every rung; it gives an error only where two piles
    climbed; a poured family's runs are samples of their own."""
    from mpdem import config
    from mpdem.campaign import pooled

    def p(k_n, seed):
        vals = config.resolve({"run.max_steps": 1, "contact.mu": 0.0, "contact.k_n": k_n, "pour.N": 20000,
                               "run.seed": seed}).values
        return {k: vals[k] for k in config.PARAM_KEYS}

    def st(sid, k_n, piles, k_from=None):
        runs = []
        for i, bed in piles:
            d = np.logspace(-5, -4, 5) * 2e5 / k_n
            bands = {"in_bulk": [True] * 5, "overlap_mean": d.tolist(),
                     "z": (6.0 + 12.0 * np.sqrt(d) + 0.002 * i + 0.001 * (bed != i)).tolist()}
            runs.append(AnalysedRun(f"{sid}-{i}-{bed}", {"params": p(k_n, i), "bed_seed": bed, "z": 6.1,
                                                         "phi": 0.64, "bands": bands}))
        return Set(sid, p(k_n, piles[0][0]), runs, {"stiffen.k_n_from": k_from} if k_from else {})

    # seed 1 on bed 101 is a pile apart from seed 1 on its own bed
    base, poured = st("S12", 2e5, [(1, 1), (2, 2), (3, 3), (1, 101)]), st("S17", 2e6, [(1, 1), (2, 2)])
    rungs = [st("S27", 2e6, [(1, 1), (2, 2)], 2e5), st("S28", 2e7, [(1, 1), (2, 2)], 2e6)]
    members = ladder.with_base(rungs, [base, poured, *rungs])
    assert [s.id for s in members] == ["S12", "S27", "S28"]
    assert ladder.with_base([base, poured], [base, poured, *rungs]) == [base, poured]
    assert ladder.with_base(rungs, rungs) == rungs                  # no base collected: the rungs alone
    e = pooled.overlap_fit(members)
    assert e["status"] == "fitted" and e["n_runs"] == 8 and e["n_samples"] == e["n_piles"] == 4
    assert e["n_piles_climbed"] == 2 and e["determined"] and e["sets"] == ["S12", "S27", "S28"]
    assert e["z_c"] == pytest.approx(6.004, abs=0.003)
    # one pile climbed: the bootstrap over piles cannot give an error, and a row citing it is not determined
    one = [st("S27", 2e6, [(1, 1)], 2e5), st("S28", 2e7, [(1, 1)], 2e6)]
    e1 = pooled.overlap_fit(ladder.with_base(one, [base, *one]))
    assert e1["n_piles_climbed"] == 1 and e1["determined"] is False and "needs two" in e1["reason"]
    m = src.Fit("overlap", "z_c", "S27").resolve(src.Context([], {"overlap": [e1]}, []))
    assert m.status == "not determined" and "needs two" in m.why
    e = pooled.overlap_fit([base, poured])
    assert e["n_runs"] == 6 and e["n_samples"] == 6 and "n_piles" not in e and "determined" not in e


def test_a_pile_is_followed_back_to_its_pour_and_one_poured_stiffer_is_another_pile(tmp_path):
    """``ladder.pile``: (seed, bed seed, k_n poured at), the pour found through each rung's run.initial_file:
    as written, or the rung of that name in its own ladder (a copy run elsewhere); where the state's run is
    gone, its stiffen.k_n_from. A pile of the same seeds poured at 2e6 is another pile."""

    def run(rel, k_n, k_from=0.0, start=""):
        d = tmp_path / rel
        d.mkdir(parents=True)
        (d / "config.toml").write_text(f'[run]\nseed = 1\ninitial_file = "{start}"\n[contact]\nk_n = {k_n}\n'
                                       f'[stiffen]\nk_n_from = {k_from}\n')
        return AnalysedRun(str(d), {"params": {"run.seed": 1, "contact.k_n": k_n}, "bed_seed": 1})

    pour = run("size/s1", 2e5)
    r6 = run("lad/s1/kn2e6", 2e6, 2e5, f"{tmp_path}/size/s1/packing.npz")
    r7 = run("lad/s1/kn2e7", 2e7, 2e6, ".device/lad/s1/kn2e6/final.h5")     # ran elsewhere: its sibling
    again = run("lad/s1/kn2e5", 2e5)                                          # the same pour again
    stiff = run("size/s1_kn2e6", 2e6)                                         # poured at 2e6
    gone = run("lad2/s1/kn2e6", 2e6, 2e5, "removed/kn2e5/final.h5")           # its start is not at hand
    ckpt = run("lad/s1/kn2e8", 2e8, 2e7, f"{tmp_path}/lad/s1/kn2e7/checkpoints/ckpt-00003.h5")   # a checkpoint
    settle = run("lad/s1/kn2e8_strict", 2e8, 0.0, f"{tmp_path}/lad/s1/kn2e8/final.h5")          # settled on
    keys = [ladder.pile(r) for r in (pour, r6, r7, again, stiff, gone, ckpt, settle)]
    assert keys[0] == (1, 1, 2e5) and keys[:4] == [keys[0]] * 4 and keys[5:] == [keys[0]] * 3
    assert keys[4] == (1, 1, 2e6)
    # a relative start, written from the checkout the ladder ran in, is found below an ancestor of the rung
    run("ck/runs/size/s9", 2e4)
    run("ck/runs/mid/s9", 2e5, 2e4, f"{tmp_path}/ck/runs/size/s9/packing.npz")
    rel = run("ck/runs/lad/s9/kn2e6", 2e6, 2e5, "runs/mid/s9/final.h5")
    assert ladder.pile(rel) == (1, 1, 2e4)
    # a start whose k_n is not the one the rung was stiffened from is not its start: its k_n_from stands
    odd = run("lad3/s1/kn2e7", 2e7, 2e6, f"{tmp_path}/size/s1/final.h5")
    assert ladder.pile(odd) == (1, 1, 2e6)
    # a chain that turns in a circle names no pour
    run("loop/a", 2e5, 0.0, f"{tmp_path}/loop/b/final.h5")
    loop_b = run("loop/b", 2e5, 0.0, f"{tmp_path}/loop/a/final.h5")
    with pytest.warns(UserWarning, match="circle"):
        assert ladder.poured_k_n(loop_b.path) is None
    # a summary without its config.toml is named by its seeds, and a family mixing both is warned of
    bare = AnalysedRun(str(tmp_path / "none"), {"params": {"run.seed": 3}, "bed_seed": 7})
    assert ladder.pile(bare) == (3, 7)
    with pytest.warns(UserWarning, match="may count twice"):
        ladder.piles([pour, bare])


def test_an_overlap_fit_keeps_its_alternative_exponents_beside_with_their_own_piles_and_reasons():
    """The bands lie on z = 6 + 12 (delta/d)^(1/2): fitted with 1/3 too, the part 'exponent 1/3' has its own
    z_c (off 6, worse residual) and the same piles; a ladder one pile climbed is not determined in every part."""
    from mpdem.campaign import pooled

    assert pooled.exponent_part(1 / 3) == "exponent 1/3" and pooled.exponent_part(2 / 3) == "exponent 2/3"
    sets_ = []
    for k_n, k_from in ((2e5, None), (2e6, 2e5)):
        rr = []
        for seed in (1, 2, 3):
            d = np.logspace(-5, -4, 5) * 2e5 / k_n
            bands = {"in_bulk": [True] * 5, "overlap_mean": d.tolist(),
                     "z": (6.0 + 12.0 * np.sqrt(d) + 0.001 * seed).tolist()}
            rr.append(AnalysedRun(f"{k_n}-{seed}", {"params": {"run.seed": seed, "contact.k_n": k_n},
                                                     "z": 6.1, "phi": 0.64, "bands": bands}))
        sets_.append(Set(f"S{len(sets_)}", {"contact.k_n": k_n}, rr, {"stiffen.k_n_from": k_from} if k_from else {}))
    e = pooled.overlap_fit(sets_, alternatives=(1 / 3,))
    third = e["exponent 1/3"]
    assert e["exponent"] == 0.5 and third["exponent"] == 1 / 3 and "exponent 2/3" not in e
    assert e["z_c"] == pytest.approx(6.002, abs=1e-3) and abs(third["z_c"] - 6.0) > 0.01
    assert third["rms"] > e["rms"] and third["n_piles"] == e["n_piles"] == 3 and third["determined"]
    m = src.Fit("overlap", "z_c", "S1", part="exponent 1/3").resolve(src.Context([], {"overlap": [e]}, []))
    assert m.ok and m.value == third["z_c"]
    one = [Set("S0", sets_[0].params, sets_[0].runs), Set("S1", sets_[1].params, sets_[1].runs[:1],
                                                          sets_[1].extra)]
    e1 = pooled.overlap_fit(one, alternatives=(1 / 3,))
    assert e1["determined"] is False and e1["exponent 1/3"]["determined"] is False
    m1 = src.fit_measure(e1, "z_c", "exponent 1/3", kind="overlap")
    assert m1.status == "not determined" and "needs two" in m1.why


def test_a_value_that_rests_on_an_assumed_choice_is_not_determined_where_an_alternative_changes_its_verdict():
    """``sources.Assumes``: the claim is judged with every alternative; agreeing verdicts stand, a disagreeing
    one makes the row 'not determined' with each choice's verdict; an alternative with no number is left out."""
    c = claims.Claim("x", "the same", "the same", "compare", 0.0, None)

    @dataclasses.dataclass
    class Fixed:
        m: src.Measure

        def resolve(self, ctx):
            return dataclasses.replace(self.m)

    def ms(v, e=0.01):
        return Fixed(src.Measure(v, e, 4, "4 runs", "w"))

    agree = src.Assumes(ms(0.001), "x = 1/2", [("1/3", ms(0.005)), ("2/3", ms(-0.01))]).resolve(None)
    assert agree.assumption == "x = 1/2" and len(agree.alts) == 2
    assert ct.judge(c, agree).kind == "reproduced"
    split = src.Assumes(ms(0.001), "x = 1/2", [("1/3", ms(0.1)), ("2/3", ms(0.005))]).resolve(None)
    v = ct.judge(c, split)
    assert v.kind == "not determined"
    assert v.why == ("it rests on x = 1/2: with it reproduced (0.1 σ); with 1/3: 0.100 ± 0.010, differs by +0.100 "
                     "(10.0 σ); with 2/3: 0.005 ± 0.010, reproduced (0.5 σ)")
    # alternatives that agree leave the verdict, and it says they were tried
    both_differ = src.Assumes(ms(0.1), "x = 1/2", [("1/3", ms(0.2)), ("2/3", ms(-0.3))]).resolve(None)
    w = ct.judge(c, both_differ)
    assert w.kind == "differs" and "the same with 1/3 (0.200 ± 0.010), 2/3 (-0.300 ± 0.010) in place of x = 1/2" \
        in w.why
    # an alternative without a number cannot confirm the verdict: not determined, with its reason
    gone = src.Assumes(ms(0.001), "x = 1/2", [("1/3", ms(0.005)), ("2/3", Fixed(src.missing("w", "no part")))])
    u = ct.judge(c, gone.resolve(None))
    assert u.kind == "not determined" and "with 2/3: not measured (no part)" in u.why
    # a primary without a number keeps its own status
    assert src.Assumes(Fixed(src.missing("w", "no set")), "x", [("1/3", ms(0.1))]).resolve(None).alts == []
    # an alternative of another kind (a fit's p beside a value): judged by its own kind, its p named once
    mixed = src.Assumes(ms(0.1), "the change", [("the fit", Fixed(src.Measure(0.33, math.nan, 4, "4 runs", "f")),
                                                  "test")]).resolve(None)
    x = ct.judge(c, mixed)
    assert x.kind == "not determined"
    assert x.why == "it rests on the change: with it differs by +0.100 (10.0 σ); with the fit: reproduced; p = 0.33"
    rejected = src.Assumes(ms(0.1), "the change", [("the fit", Fixed(src.Measure(0.01, math.nan, 4, "4 runs", "f")),
                                                    "test")]).resolve(None)
    y = ct.judge(c, rejected)
    assert y.kind == "differs" and y.why == "the same with the fit (p = 0.01) in place of the change"


def test_a_paper_error_read_two_ways_judges_each_number_against_both():
    """``Claim.err_alternatives``: every measure of the row (the judged one and those beside) is judged against
    the paper's error and each other reading its text allows; a verdict that changes is not determined."""
    c = _claim(value=6.024, paper_err=0.02, err_alternatives=(("±0.002", 0.002),), err_assumption="±0.02")
    near, far = (src.Measure(v, 0.0024, 2, "2 runs", "w") for v in (6.023, 6.0173))
    assert ct.judge(c, near).kind == "reproduced" and "the same with ±0.002 (0.3 σ) in place of ±0.02" in \
        ct.judge(c, near).why
    v = ct.judge(c, far)
    assert v.kind == "not determined"
    assert v.why == "it rests on ±0.02: with it reproduced (0.3 σ); with ±0.002: differs by -0.0067 (2.1 σ)"
    # a claim without other readings is judged once, as before
    assert ct.judge(_claim(value=6.024, paper_err=0.02), far).kind == "reproduced"


def test_alpha_on_the_default_window_is_judged_on_both_decades_with_the_same_window_on_both_sides():
    a = claims._alpha("S17", diff_with="S12")
    assert a.assumption == claims.ALPHA_DEFAULT
    assert a.src == src.Diff(src.S("S17", "alpha"), src.S("S12", "alpha"))
    assert [(label, alt) for label, alt in a.alternatives] == [
        (label, src.Diff(src.AlphaWindow("S17", lo), src.AlphaWindow("S12", lo))) for label, lo in claims.ALPHA_DECADES]
    one = claims._alpha("S12", one_minus=True)
    assert one.src == src.OneMinus(src.S("S12", "alpha"))
    assert [alt for _, alt in one.alternatives] == [src.OneMinus(src.AlphaWindow("S12", lo))
                                                    for _, lo in claims.ALPHA_DECADES]


def test_eq7_over_the_runs_of_piles_follows_each_piles_change_not_its_offset():
    """Two piles climb four rungs of an exact eq. 7 (alpha_n = 0.5), each with an offset of its own; a third
    is poured at 2e5 only. Raising one pile's every run by 0.005 moves the fit of the runs hardly at all
    (a pile's own offset), where the fit of the sets' means, which sees that pile at some k_n only, moves."""
    from mpdem.analysis import fits
    ks = [2e5, 2e6, 2e7, 2e8]
    rng = np.random.default_rng(3)

    def runs(lift):
        k, z, pl = [], [], []
        for pile, off in (("a", 0.003 + lift), ("b", -0.003)):
            for kk in ks[: 4 if pile == "a" else 3]:
                k.append(kk)
                z.append(6.0 + 0.13 * (kk / 2e5) ** -0.5 + off + rng.normal(0, 1e-4))
                pl.append(pile)
        return k + [2e5], z + [6.0 + 0.13], pl + ["c"]

    k, z, pl = runs(0.0)
    f0 = fits.fit_eq7_piles(k, z, pl, 0.003, 1e-4)
    assert abs(f0["alpha_n"] - 0.5) < 0.01 and f0["n_piles"] == 3 and f0["dof"] == 5
    assert f0["alpha_n_err"] < 0.01 and f0["p_value"] > 0.001
    k1, z1, _ = runs(0.005)
    f1 = fits.fit_eq7_piles(k1, z1, pl, 0.003, 1e-4)
    means = lambda kk, zz: [np.mean([v for q, v in zip(kk, zz) if q == x]) for x in ks]  # noqa: E731
    m0, m1 = (fits.fit_eq7(ks, means(a, b), [0.003] * 4) for a, b in ((k, z), (k1, z1)))
    assert abs(f1["alpha_n"] - f0["alpha_n"]) < 0.2 * abs(m1["alpha_n"] - m0["alpha_n"])
    # the same pile's runs covary by its offset; a run has its noise of its own
    C = fits.pile_covariance(["a", "a", "b"], 0.003, 1e-4)
    assert np.isclose(C[0, 1], 0.003 ** 2 - 1e-8) and C[0, 2] == 0.0 and np.isclose(C[0, 0], 0.003 ** 2)


def test_eq7_over_piles_widens_its_errors_when_the_noise_is_larger_than_said():
    from mpdem.analysis import fits
    k = [2e5, 2e6, 2e7, 2e8, 2e5, 2e6, 2e7]
    pl = ["a"] * 4 + ["b"] * 3
    noise = [3e-4, -3e-4, 3e-4, -3e-4, -3e-4, 3e-4, -3e-4]
    z = [6.0 + 0.13 * (kk / 2e5) ** -0.5 + n + (0.003 if p == "a" else 0.0) for kk, n, p in zip(k, noise, pl)]
    said = fits.fit_eq7_piles(k, z, pl, 0.003, 1e-4)
    assert said["chi2"] > said["dof"] and math.isclose(said["scale"], math.sqrt(said["chi2"] / said["dof"]))
    honest = fits.fit_eq7_piles(k, z, pl, 0.003, 3e-4)
    assert honest["scale"] <= said["scale"] and said["alpha_n_err"] > 0
    fixed = fits.fit_eq7_piles(k, z, pl, 0.003, 3e-4, alpha_n=0.5)
    assert fixed["alpha_n_fixed"] and fixed["dof"] == 5 and abs(fixed["z_inf"] - 6.0015) < 0.002


def test_eq7_over_piles_multiplies_every_error_by_its_scale_and_tests_chi2_against_the_measured_noise():
    from mpdem.analysis import fits
    from scipy.stats import f as f_dist
    k = np.array([2e5, 2e6, 2e7, 2e8, 2e5, 2e6, 2e7])
    pl = ["a"] * 4 + ["b"] * 3
    z = 6.0 + 0.13 * (k / 2e5) ** -0.5 + np.array([3, -3, 3, -3, -3, 3, -3]) * 1e-4
    fx = fits.fit_eq7_piles(k, z, pl, 0.003, 1e-4, alpha_n=0.5, s_within_dof=2)
    C = fits.pile_covariance(pl, 0.003, 1e-4)
    X = np.stack([np.ones_like(k), (k / 2e5) ** -0.5], axis=1)
    cov = np.linalg.inv(X.T @ np.linalg.solve(C, X))          # the linear GLS covariance, unscaled
    assert fx["scale"] > 1
    assert math.isclose(fx["z_inf_err"], math.sqrt(cov[0, 0]) * fx["scale"], rel_tol=1e-9)
    assert math.isclose(fx["a_tilde_err"], math.sqrt(cov[1, 1]) * fx["scale"] * 2e5 ** 0.5, rel_tol=1e-9)
    assert math.isclose(fx["p_noise"], f_dist.sf(fx["chi2"] / fx["dof"], fx["dof"], 2), rel_tol=1e-12)
    assert fx["p_noise"] > fx["p_value"]                       # a measured noise makes the test milder
    # a pile's noise measured above the piles' scatter: no shared part, each run its own noise, and said so
    C2 = fits.pile_covariance(pl, 1e-4, 3e-4)
    assert np.count_nonzero(C2 - np.diag(np.diag(C2))) == 0 and np.allclose(np.diag(C2), 9e-8)
    assert fits.fit_eq7_piles(k, z, pl, 1e-4, 3e-4)["s_b_clamped"]


def test_a_claim_set_against_a_rival_is_reproduced_only_where_the_rival_is_not():
    """Row 23's reading: 0.06 +- 0.30 lies within 2 sigma of 1/4 and of the frictionless 1/2 (not determined);
    0.25 +- 0.05 reproduces 1/4 and lies 5 sigma from 1/2. A test's rival is its own source: both passed is
    not determined, the rival rejected reproduces, a rival without a number cannot reject anything."""
    c = claims.Claim("x", "follows 1/4", "1/4", "compare", 0.25, 0.005, rival=("1/2", 0.5))
    wide = ct.judge(c, src.Measure(0.06, 0.30, 11, "11 runs", "w"))
    assert wide.kind == "not determined" and "cannot tell them apart" in wide.why and "(1.5 σ)" in wide.why
    sharp = ct.judge(c, src.Measure(0.25, 0.05, 11, "11 runs", "w"))
    assert sharp.kind == "reproduced" and "1/2 5.0 σ away" in sharp.why
    assert ct.judge(c, src.Measure(0.6, 0.05, 11, "11 runs", "w")).kind == "differs"    # a rival cannot rescue

    @dataclasses.dataclass
    class P:
        p: float

        def resolve(self, ctx):
            return src.missing("rival", "gone") if self.p is None else src.Measure(self.p, NAN, 6, "6 runs", "r")

    def judged(rival_p):
        t = claims.Claim("t", "follows 1/4", "figure", "test", rival=("1/2", P(rival_p)))
        return ct.judge(t, src.Measure(0.69, NAN, 6, "6 runs", "w"), ctx=object())

    both = judged(0.47)
    assert both.kind == "not determined" and "does not tell them apart" in both.why
    told = judged(0.01)
    assert told.kind == "reproduced" and told.why == "p = 0.69: not rejected; 1/2: p = 0.01, rejected"
    assert judged(None).kind == "not determined"
    # a rival named by a fit part: each measure, first or beside, is set against its own family's rival fit
    fits_ = {"eq7": [{"sets": ["A"], "status": "fitted", "fixed": {"p_value": 0.6}, "fixed 1/2": {"p_value": 0.5}},
                     {"sets": ["B"], "status": "fitted", "fixed": {"p_value": 0.5}, "fixed 1/2": {"p_value": 0.001}}]}

    class Ctx(src.Context):
        def ext_fits(self, results):
            return fits_

        def ext_sets(self, results):
            return {}

    t = claims.Claim("t", "follows 1/4", "figure", "test", rival=("1/2", "fixed 1/2"),
                     ours=[src.ExtFit("d", "eq7", "p_value", "A", True)],
                     also=[src.ExtFit("d", "eq7", "p_value", "B", True)])
    r = ct.row(t, Ctx([], {}, []))
    assert r["verdict"].kind == "not determined" and "p = 0.5: the test does not tell them apart" in r["verdict"].why
    assert "p = 0.5: not rejected; 1/2: p = 0.001, rejected)" in r["context"]
    both_pass = dict(fits_["eq7"][1], **{"fixed 1/2": {"p_value": 0.3}})
    fits_["eq7"][1] = both_pass
    assert "not determined: p = 0.5, and 1/2 p = 0.3" in ct.row(t, Ctx([], {}, []))["context"]
    with pytest.raises(ValueError, match="a rival for kind"):
        claims.Claim("b", "x", "x", "bound", 4.0, rival=("y", 5.0))


def test_the_papers_eq9_is_tested_against_the_sets_means_with_the_pooled_seed_scatter():
    """Two sets of two seeds with standard errors 0.003 and 0.004 (variances 2 * 0.003^2 and 2 * 0.004^2, one
    dof each) pool to a scatter of 0.005 on 2 dof. Points on the paper's curve give F = 0 (p = 1); moved by
    0.005 / sqrt 2 at one set, chi^2 = 1 and chi^2 / 2 is F(2, 2) distributed, the scatter being estimated."""
    from mpdem.campaign import paper
    from scipy.stats import chi2, f

    x = np.array([0.02, 0.3])
    n = np.array([2, 2])
    sem = np.array([0.003, 0.004])

    class Ctx:
        def __init__(self, y):
            self.y = y

        def ext_fits(self, results):
            return {"eq9": [{"sets": ["S1", "S2"], "phi_i": x.tolist(), "phi": self.y.tolist(),
                             "phi_sem": sem.tolist(), "n_seeds": n.tolist()}]}

    on = src.Eq9PaperTest("d", "S2").resolve(Ctx(paper.eq9_paper(x)))
    assert on.ok and on.value == pytest.approx(1.0) and on.n == 4 and "F = 0.00 on (2, 2) dof" in on.where
    assert "seed scatter 0.005 pooled on 2 dof" in on.where
    y = paper.eq9_paper(x)
    y[1] += 0.005 / math.sqrt(2)
    off = src.Eq9PaperTest("d", "S2").resolve(Ctx(y))
    assert off.value == pytest.approx(f.sf(0.5, 2, 2), rel=1e-9) and "+1.0 σ at φ_i = 0.3" in off.where
    assert off.value > chi2.sf(1.0, 2)             # an estimated scatter makes the test milder than chi^2
    assert src.Eq9PaperTest("d", "S9").resolve(Ctx(y)).status == "not measured"


def test_row_34_reads_its_alternative_exponents_from_the_committed_ladder_fits():
    """Row 34's overlap difference rests on the exponent 1/2: both alternatives resolve against the committed
    ladder-dev fits, each a number apart from the assumed one (were they lost, the row would be judged on 1/2
    alone, and this fails)."""
    c = next(c for c in claims.CLAIMS if c.id == "34")
    a = next(x for x in c.ours if isinstance(x, src.Assumes))
    m = a.resolve(src.Context([], {}, [], str(ROOT / "analysis/results/paper")))
    assert m.ok and len(m.alts) == 2 and all(am.ok and am.value != m.value for _, am, _ in m.alts)
    assert [label for label, *_ in m.alts] == ["1/3 for both", "2/3 for both"]
    for x in ("19", "27"):              # the Hookean overlap fit that stands in for eq. 7 rests on it too
        row = next(c for c in claims.CLAIMS if c.id == x)
        assert isinstance(row.ours[1], src.Assumes) and len(row.ours[1].alternatives) == 2


def test_the_rows_judged_on_alternatives_read_every_alternative_from_the_committed_tables():
    """Rows 16-18 and 21 (α's window), 20b (one law by its fit's p) and 22-22c (the paper's curve error):
    every alternative resolves against the committed fits (were one lost, the row would read not determined
    for want of a number, not for a verdict that changes)."""
    import json
    out = ROOT / "analysis/results/paper"
    fit_res = json.loads((out / "fits.json").read_text())
    ctx = src.Context([], fit_res, [], str(out))
    by_id = {c.id: c for c in claims.CLAIMS}
    for cid in ("16", "17", "18", "21", "20b"):
        a = by_id[cid].ours[0]
        assert isinstance(a, src.Assumes)
        alts = [(label, alt.resolve(ctx)) for label, alt, *_ in a.alternatives]
        assert alts and all(m.ok for _, m in alts), (cid, [(lb, m.status, m.why) for lb, m in alts])
    kinds = [k for _, _, *k in by_id["20b"].ours[0].alternatives]
    assert kinds == [["test"]]
    for cid in ("22", "22b", "22c"):
        c = by_id[cid]
        assert c.err_alternatives == (("±0.002, the paper's error of one measured z", 0.002),) and c.paper_err == 0.02
    with pytest.raises(ValueError, match="err_alternatives need kind 'compare'"):
        claims.Claim("x", "c", "p", "bound", 4.0, err_alternatives=(("±1", 1.0),), err_assumption="±2")
    with pytest.raises(ValueError, match="an err_assumption"):
        claims.Claim("x", "c", "p", "compare", 4.0, 0.1, err_alternatives=(("±1", 1.0),))
    with pytest.raises(ValueError, match="'test'"):
        src.Assumes(src.S("S1"), "x", [("y", src.S("S2"), "bound")])


def test_a_fit_part_that_is_not_fitted_gives_its_own_reason_and_ids_of_other_collects_name_them():
    e = {"sets": ["S12", "S27"], "status": "fitted", "z_inf": 6.0, "z_inf_err": 0.004,
         "set_means": {"status": "not determined", "reason": "correlation 1", "z_inf": 6.1}}
    m = src.fit_measure(e, "z_inf", "set_means", kind="ladder")
    assert m.status == "not determined" and m.why == "correlation 1"
    # a part fitted but not determined (a ladder one pile climbed) reads not determined, with its reason
    e["exponent 1/3"] = {"status": "fitted", "z_c": 5.9, "z_c_err": 0.1, "determined": False, "reason": "1 pile"}
    m3 = src.fit_measure(e, "z_c", "exponent 1/3", kind="overlap")
    assert m3.status == "not determined" and m3.why == "1 pile"
    with pytest.raises(ValueError, match="one fit"):
        src.ExtFit("x", "overlap", "z_c", "S1", fixed=True, part="exponent 1/3").resolve(None)
    assert src.fit_measure(e, "z_inf", kind="ladder").value == 6.0
    assert src.ext_id("../dev", "S15") == "dev:S15" and src.ext_id("ladder-dev", "S07") == "ladder-dev:S07"


def test_a_fit_whose_law_fails_its_test_says_so_unless_its_errors_are_widened():
    """An error of a fit whose law fails the rule's test of it (χ²/dof against F on the dof of the seed
    scatter its weights rest on, p below 0.0455) is the points' alone: the row says the law's χ² and p beside
    the number. A fit whose errors are widened by its χ² ('scale'), one whose law holds, and one whose noise's
    dof is not known say nothing more. The ladder's sets'-means fits and an eq. 7 entry's fixed part read the
    dof from the fit or its entry."""
    from scipy import stats
    part = {"status": "fitted", "z_inf": 4.26, "z_inf_err": 0.0066, "chi2": 122.4, "dof": 2, "pooled_dof": 3}
    e = {"sets": ["S15", "S30"], "status": "fitted", "n_runs": 7, "set_means_fixed": part}
    p = stats.f.sf(122.4 / 2, 2, 3)
    said = src.fit_measure(e, "z_inf", "set_means_fixed", kind="ladder").count
    assert said == f"2 sets, 7 runs; its law's χ² = 122 for 2 dof, p = {p:.2g} against F(2, 3)" and p < 0.0455
    for quiet in (dict(part, scale=7.8), dict(part, chi2=5.0), {k: v for k, v in part.items() if k != "pooled_dof"}):
        assert "χ²" not in src.fit_measure(dict(e, set_means_fixed=quiet), "z_inf", "set_means_fixed").count
    # χ² = 9.4 for 3 dof fails against χ² itself (p = 0.025) but not against F(3, 10) (p = 0.074): quiet
    assert "χ²" not in src.fit_measure(dict(e, set_means_fixed=dict(part, chi2=9.39, dof=3, pooled_dof=10)), "z_inf",
                                       "set_means_fixed").count
    eq7 = {"sets": ["S1", "S2", "S3", "S4"], "status": "fitted", "pooled_dof": 4, "z_inf": 6.0, "z_inf_err": 0.01,
           "chi2": 1.0, "dof": 1, "fixed": {"z_inf": 6.1, "z_inf_err": 0.01, "chi2": 80.0, "dof": 2}}
    assert "against F(2, 4)" in src.fit_measure(eq7, "z_inf", True, kind="eq7").count


def test_a_contrasts_pooled_error_replaces_a_borrowed_one_and_the_count_says_which():
    a, b = _set("S26", [4.872]), _set("S15", [4.84, 4.845, 4.85])
    fit_res = {"contrasts": [{"reference": "S15", "rows": [{"set": "S26", "z": {"diff": 0.027, "err": 0.008}}]}]}
    m = src.Diff(src.S("S26"), src.S("S15")).resolve(src.Context([a, b], fit_res, []))
    assert m.err == 0.008 and "pooled seed scatter" in m.count and src.LENT not in m.count


def test_within_pile_noise_is_the_residual_of_the_piles_on_their_common_rungs():
    pts = [(2e5, 6.13, (1, 1)), (2e6, 6.05, (1, 1)), (2e7, 6.02, (1, 1)), (2e8, 6.01, (1, 1)),
           (2e5, 6.126, (2, 2)), (2e6, 6.046, (2, 2)), (2e7, 6.017, (2, 2)), (2e5, 6.14, (3, 3))]
    s, dof = ladder.within_pile_noise(pts)
    # piles 1 and 2 share 2e5, 2e6, 2e7: differences 0.004, 0.004, 0.003 -> a 3 x 2 table, 2 dof, whose
    # residual scatter is that of the differences over sqrt(2)
    assert dof == 2 and math.isclose(s, float(np.std([0.004, 0.004, 0.003], ddof=1)) / math.sqrt(2), rel_tol=1e-6)
    # a pile that climbed one rung only does not cut the others' table short
    short = pts + [(2e5, 6.135, (4, 4)), (2e6, 6.052, (4, 4))]
    assert ladder.within_pile_noise(short)[1] == 2
    one, none = ladder.within_pile_noise(pts[:4] + pts[7:])      # one pile climbed: no noise to be had
    assert math.isnan(one) and none == 0
    tot, tdof = ladder.total_scatter(pts)
    assert tdof == 2 and math.isclose(tot, float(np.std([6.13, 6.126, 6.14], ddof=1)))
    # one pile measured twice at one rung would count twice in the noise and the exponents: refused
    with pytest.raises(ValueError, match=r"pile \(1, 1\) has two runs at k_n = 2e\+06"):
        ladder.within_pile_noise(pts + [(2e6, 6.051, (1, 1))])


# ---------------------------------------------------------------- the claims themselves

def test_the_claims_are_well_formed_and_cite_sets_the_campaign_has():
    ids = [c.id for c in claims.CLAIMS]
    assert len(ids) == len(set(ids))
    kinds = {"compare", "bound", "nonzero", "range", "sign", "test", "qualitative", "none"}
    cited, ext = set(), {}

    def walk(x):
        if isinstance(x, (src.S, src.Window, src.PerRun)):
            cited.add(x.set)
        if isinstance(x, (src.Ext, src.ExtFit, src.ExtTest, src.Eq9Deviation, src.Eq9PaperTest)):
            ext.setdefault(x.results, set()).add(x.set)
        for v in vars(x).values():
            if hasattr(v, "resolve"):
                walk(v)
            if isinstance(v, list):     # an assumption's alternatives: [(label, source)] or [(label, source, kind)]
                for item in v:
                    walk(item[1])
    for c in claims.CLAIMS:
        assert c.kind in kinds, c.id
        if c.kind == "compare":
            assert c.value is not None, c.id
            # a tolerance in place of a paper error is always given with its reason, from the paper's text
            assert c.paper_err is None or c.tolerance or c.paper in ("6.144 ± 0.002", "0.52 ± 0.03") \
                or "±" in c.paper, c.id
        for x in c.ours + c.also + ([c.rival[1]] if c.rival and hasattr(c.rival[1], "resolve") else []):
            walk(x)
    paper = ROOT / "analysis/results/paper"
    have = set(json.loads((paper / "collect.json").read_text())["sets"])
    assert cited and cited <= have, cited - have
    # the other collects' tables the claims read (the development sweeps, the N = 2000 ladders)
    assert set(ext) == {claims.DEV, claims.LADDER_DEV}
    for results, ids in ext.items():
        other = set(json.loads((paper / results / "collect.json").read_text())["sets"])
        assert ids <= other, (results, ids - other)


def test_claims_are_written_for_the_paper_campaign_alone(tmp_path):
    assert claims.for_out(str(ROOT / "analysis/results/paper")) is claims.CLAIMS
    assert claims.for_out(str(tmp_path / "out")) == []
    assert claims.for_out(str(ROOT / "analysis/results/dev")) == []


def test_the_table_states_the_rule_once_and_counts_what_it_judged():
    ctx = src.Context([_set("S01", [4.85, 4.86, 4.87])], {}, [])
    judged = ct.rows([_claim(id="1", ours=[src.S("S01")]), _claim(id="2", ours=[src.S("S02")]),
                      _claim(id="3", ours=[src.S("S01")], value=4.86)], ctx)
    text = "\n".join(ct.section(judged))
    assert text.count("within two combined standard errors") == 1
    assert "1 reproduced, 1 differs" in text and "1 not measured" in text
    assert ct.counts(judged) == {"differs": 1, "not measured": 1, "reproduced": 1}


def test_every_verdict_of_the_committed_readme_agrees_with_its_number_of_errors():
    """The table collect wrote: no row is 'reproduced' beyond 2 combined errors, none 'differs' within them,
    and every row that differs says whether it is explained or open."""
    import re
    text = (ROOT / "analysis/results/paper/README.md").read_text()
    assert len(text.splitlines()) <= 500          # a README read in ten minutes; the dated log is NOTES.md
    rows = [ln for ln in text.split("## The paper, claim by claim")[1].split("\n## ")[0].splitlines()
            if re.match(r"\| [0-9]+[a-z]? \|", ln)]
    assert len(rows) == len(claims.CLAIMS)
    for ln in rows:
        verdict = ln.split(" | ")[5]
        m = re.search(r"\*\*reproduced \(([0-9.]+) σ\)", verdict)
        if m:
            assert float(m.group(1)) <= 2.0, ln
        m = re.search(r"\*\*differs by [-+0-9.e]+ \(([0-9.]+) σ\)[^*]*\*\*; (explained|open)", verdict)
        if "**differs by" in verdict:
            assert m and float(m.group(1)) > 2.0, ln
        elif "**differs" in verdict:        # a test or a bound: its reason all the same
            assert re.search(r"\*\*; (explained|open)", verdict), ln


def test_a_fit_with_as_many_points_as_parameters_says_it_tests_nothing():
    from mpdem.campaign import comparison
    fam = {"mu": 0.0, "epsilon": 0.88, "N": 20000}
    e = {"family": fam, "sets": ["S27", "S28", "S29"], "k_n": [2e6, 2e7, 2e8], "n_seeds": [2, 2, 1],
         "status": "fitted", "z_inf": 6.011, "z_inf_err": 0.005, "a_tilde": 1762.0, "a_tilde_err": 9128.0,
         "alpha_n": 0.747, "alpha_n_err": 0.366, "chi2": 0.0, "dof": 0, "weighted": True,
         "check_alpha_n": {"alpha": 0.42, "alpha_err": 0.005, "n_runs": 5, "one_minus_alpha": 0.58}}
    assert "an exact interpolation of its points, not a test of eq. 7" in comparison._fit_lines(e, "eq7")
    assert "interpolation" not in comparison._fit_lines(dict(e, chi2=0.65, dof=1), "eq7")


def test_a_piles_local_exponent_is_read_from_three_rungs_a_decade_apart():
    z = lambda k, a: 6.0 + 0.13 * (k / 2e5) ** -a   # noqa: E731
    pts = [(k, z(k, 0.5), (1, 1)) for k in (2e5, 2e6, 2e7)] + [(2e8, z(2e8, 0.5) + 0.001, (1, 1))] + \
          [(k, z(k, 0.5) - 0.004, (2, 2)) for k in (2e5, 2e6)]
    loc = ladder.local_exponents(pts)
    assert [x["k_n"][0] for x in loc] == [2e5, 2e6]          # pile 2 has no three rungs
    assert math.isclose(loc[0]["alpha_n"], 0.5, rel_tol=1e-9)
    assert loc[1]["alpha_n"] > 0.5                            # a 2e8 rung left high steepens the upper triple


def test_a_piles_exponent_change_is_zero_for_one_law_and_its_error_is_the_propagated_noise():
    law = lambda k, a=0.5: 6.0 + 0.13 * (k / 2e5) ** -a   # noqa: E731
    ks = (2e5, 2e6, 2e7, 2e8)
    one = [(k, law(k), (1, 1)) for k in ks] + [(k, law(k) + 0.003, (2, 2)) for k in ks]
    b = ladder.exponent_change(one, 1e-4, 6)
    assert b["status"] == "fitted" and b["n_piles"] == 2 and b["n_runs"] == 8
    assert abs(b["change"]) < 1e-9 and math.isclose(b["low"], 0.5) and math.isclose(b["high"], 0.5)
    # a triple's error: var(ln r1 - ln r2) = 2 s^2 / r1^2 + 2 s^2 / r2^2 + 2 s^2 / (r1 r2), z_b shared
    s, z = 1e-4, [law(k) for k in ks[:3]]
    r1, r2 = z[0] - z[1], z[1] - z[2]
    want = s / math.log(10) * math.sqrt(2 / r1 ** 2 + 2 / r2 ** 2 + 2 / (r1 * r2))
    loc = ladder.local_exponents(one, s)
    assert math.isclose(loc[0]["alpha_n_err"], want, rel_tol=1e-5)
    assert all(math.isnan(x["alpha_n_err"]) for x in ladder.local_exponents(one))    # no noise, no error
    # a 2e8 rung left high steepens the upper triple of that pile alone; the pooled change is their
    # inverse-variance mean, and a pile of three rungs has no change
    bent = [(k, law(k) + (0.002 if k == 2e8 else 0.0), (1, 1)) for k in ks] + one[4:] + \
        [(k, law(k), (3, 3)) for k in ks[:3]]
    b = ladder.exponent_change(bent, 1e-4, 6)
    (p1, p2) = b["piles"]
    assert p1["change"] > 0.05 and abs(p2["change"]) < 1e-9 and b["n_piles"] == 2
    w1, w2 = p1["change_err"] ** -2, p2["change_err"] ** -2
    assert math.isclose(b["change"], (w1 * p1["change"] + w2 * p2["change"]) / (w1 + w2))
    assert math.isclose(b["change_err"], (w1 + w2) ** -0.5)
    assert b["change_err"] < min(p1["change_err"], p2["change_err"])
    # the noise measured on 6 dof: Student's t gives a larger p than the normal reading of the same ratio
    r = b["change"] / b["change_err"]
    assert math.isclose(b["p_normal"], math.erfc(r / math.sqrt(2)), rel_tol=1e-9)
    assert b["p_student"] > b["p_normal"]
    assert math.isnan(ladder.exponent_change(bent, 1e-4, 0)["p_student"])
    # a pile whose z rises at a step has no exponent there: it is left out of the pooling, and the ladder
    # line says so beside the pile that counts
    risen = [(k, law(k) + (0.02 if k == 2e8 else 0.0), (3, 3)) for k in ks] + one[4:]
    b = ladder.exponent_change(risen, 1e-4, 6)
    assert b["n_piles"] == 1 and b["n_runs"] == 4 and abs(b["change"]) < 1e-9
    assert math.isnan(b["piles"][0]["change"])
    from mpdem.campaign import comparison
    e = {"family": {"mu": 0.0, "epsilon": 0.88, "N": 20000}, "base": "S12", "rungs": [], "status": "not fitted",
         "reason": "r", "bend": b}
    line = comparison._ladder_lines(e)
    assert "seed 3 left out (z does not fall at every step)" in line and "pooled over 1 of 2 piles" in line
    # what cannot be read says why
    assert ladder.exponent_change(one[:3], 1e-4)["status"] == "not fitted"
    assert "noise" in ladder.exponent_change(one, math.nan)["reason"]


def test_a_fit_part_over_fewer_runs_than_its_entry_counts_its_own():
    e = {"family": {"mu": 0.0}, "sets": ["S12", "S27"], "n_runs": 10, "status": "fitted", "alpha_n": 0.5,
         "alpha_n_err": 0.01, "bend": {"status": "fitted", "change": 0.12, "change_err": 0.05, "n_piles": 2,
                                       "n_runs": 8}}
    ctx = src.Context([], {"ladder": [e]})
    m = src.Fit("ladder", "change", mu=0.0, part="bend").resolve(ctx)
    assert (m.value, m.err, m.n) == (0.12, 0.05, 8) and "8 runs of 2 piles" in m.count
    assert src.Fit("ladder", "alpha_n", mu=0.0).resolve(ctx).n == 10


def test_a_difference_of_two_one_run_windows_says_once_where_both_errors_come_from():
    nan = float("nan")
    win = [{"set": s, "window": "10-30", "quantity": "z", "mean": v, "pooled_sem": 0.007, "jackknife": nan,
            "n_seeds": 1} for s, v in (("S30", 4.541), ("S35", 4.763))]
    win.append({"set": "S15", "window": "10-30", "quantity": "z", "mean": 4.842, "pooled_sem": 0.004,
                "jackknife": 0.006, "n_seeds": 3})
    ctx = src.Context([], {}, win)
    m = src.Diff(src.Window("S30", "10-30"), src.Window("S35", "10-30")).resolve(ctx)
    assert math.isclose(m.value, 4.541 - 4.763) and math.isclose(m.err, 0.007 * math.sqrt(2))
    assert m.count == "1 + 1 runs; each side's 1 run with the seed scatter pooled over its N and μ's sets"
    one = src.Diff(src.Window("S30", "10-30"), src.Window("S15", "10-30")).resolve(ctx)
    assert one.count == "1 + 3 runs; its 1 run with the seed scatter pooled over its N and μ's sets"


def test_a_collapse_test_reads_one_quantity_or_all_of_them_at_once(tmp_path):
    """``sources.ExtTest``: a quantity's p, or with ``ALL_QUANTITIES`` the family's Bonferroni p."""
    other = tmp_path / "dev"
    other.mkdir()
    e = {"sets": ["S23", "S24"], "n_seeds": [3, 3], "p_min": 0.017, "p_bonferroni": 0.084,
         "quantities": {"ratio_mean": {"p": 0.073}}}
    (other / "fits.json").write_text(json.dumps({"ratio": [e]}))
    ctx = src.Context([], {}, out=str(tmp_path))
    one = src.ExtTest("dev", "ratio", "S24", "ratio_mean").resolve(ctx)
    every = src.ExtTest("dev", "ratio", "S24", src.ALL_QUANTITIES).resolve(ctx)
    assert (one.value, every.value, every.n) == (0.073, 0.084, 6)
    assert src.ExtTest("dev", "ratio", "S99", src.ALL_QUANTITIES).resolve(ctx).status == "not measured"


def test_an_eq7_family_of_stiffened_rungs_alone_points_to_the_ladder_that_fits_them_with_their_base():
    from mpdem.campaign import comparison
    e = {"family": {"mu": 0.0, "epsilon": 0.88, "N": 20000}, "sets": ["S27", "S28"], "k_n": [2e6, 2e7],
         "n_seeds": [2, 2], "status": "not fitted", "reason": "r"}
    poured = comparison._fit_lines(e, "eq7")
    stiff = comparison._fit_lines(dict(e, family={**e["family"], "stiffened x": 10.0}), "eq7")
    assert "stiffened rungs alone" not in poured and "stiffened rungs alone" in stiff
