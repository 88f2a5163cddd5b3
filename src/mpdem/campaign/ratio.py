"""Whether F_t / F_n collapses across friction coefficients mu >= 1 (the paper's Fig. 8; docs/model.md 6.7).

The paper draws P(F_t / F_n) for mu >= 1 and says the curves collapse: once friction is large,
few contacts reach the Coulomb limit and the force ratio no longer feels mu. Drawn curves do not
test that; here each run gives a few numbers of its bulk contacts' F_t / F_n (its mean, and the
fraction of contacts below each of ``POINTS``), and a one-way analysis of variance across the
sets of a family (sets equal in all but mu, mu >= 1) asks whether the sets' means of each number
differ by more than the seeds scatter: F = (between-set mean square) / (within-set mean square),
with (S - 1, n - S) degrees of freedom for S sets of n runs. The seed scatter is pooled over the
family's sets (two or three seeds give a poor error of their own). The same numbers for zeta =
F_t / (mu F_n) are the control: if F_t / F_n collapses, zeta's mean cannot (it scales as 1 / mu),
so a test that found no difference there would have no power.
"""
from __future__ import annotations

import math

import numpy as np

from ..analysis.fits import one_way_anova
from .runs import families, fmt_pm, md_table, read_table
from .verdict import P_K

POINTS = (0.1, 0.2, 0.3, 0.5)        # F_t / F_n at which the cumulative fraction is compared
QUANTITIES = ("ratio_mean",) + tuple(f"below_{x:g}" for x in POINTS)   # tested for the collapse
CONTROL = "zeta_mean"                 # must differ across mu if the ratio collapses
LEVEL = P_K                           # the family's verdict: Bonferroni over QUANTITIES, by the claim rule


def run_numbers(run):
    """The F_t / F_n numbers of one analysed run of mu >= 1.

    Parameters
    ----------
    run : AnalysedRun with ``RUN/analysis/zeta.csv`` holding ``count_ratio`` (F_t / F_n on the
        bins of [0, 1)) and a summary whose ``zeta`` has ``n_ratio_above_one`` (the contacts at
        or beyond 1, the Coulomb limit at mu = 1) and ``zeta_mean``

    Returns
    -------
    None without the table, else dict: ``n`` (bulk contacts with F_n > 0), ``ratio_mean``
    (mu x zeta_mean: the mean of F_t / F_n over every contact), ``below_<x>`` (the fraction of
    contacts with F_t / F_n < x, for x in ``POINTS``, which must be bin edges), ``zeta_mean``.
    """
    zt = run.s.get("zeta") or {}
    t = read_table(run.path, "zeta")
    if t is None or "count_ratio" not in t or "zeta_mean" not in zt:
        return None
    count = t["count_ratio"]
    n = float(np.nansum(count)) + float(zt.get("n_ratio_above_one", 0))
    if n <= 0:
        return None
    out = {"n": n, "ratio_mean": run.params["contact.mu"] * zt["zeta_mean"], "zeta_mean": zt["zeta_mean"]}
    for x in POINTS:
        edge = np.flatnonzero(np.isclose(t["zeta_hi"], x, rtol=0, atol=1e-9))
        if len(edge) != 1:
            raise ValueError(f"{run.path}/analysis/zeta.csv: {x:g} is not an upper bin edge "
                             f"(analysis.zeta_bins must divide [0, 1] so that it is)")
        out[f"below_{x:g}"] = float(np.nansum(count[: edge[0] + 1])) / n
    return out


def family_test(members):
    """The collapse test of one family (sets equal in all but mu; those of mu >= 1 are used).

    Returns
    -------
    dict: ``sets``, ``mu``, ``n_seeds``, ``n_contacts`` (per set, summed over its runs), ``left_out``
    (why runs whose tables do not serve were left out);
    ``quantities`` {name: {``mean`` [per set], ``err`` [pooled scatter / sqrt(seeds)], ``F``,
    ``dof``, ``p``}} for QUANTITIES and CONTROL; ``status`` ("tested", or "not tested" with
    ``reason``); when tested ``p_min`` (the smallest p of QUANTITIES), ``p_bonferroni``
    (p_min x their number, at most 1) and ``collapses`` (p_bonferroni >= LEVEL, the claim rule's test).
    """
    left_out, use = [], []
    for s in members:
        if s.p("mu") < 1:
            continue
        xs = []
        for r in s.runs:
            try:
                x = run_numbers(r)
            except ValueError as err:       # bins whose edges miss the points: that run is left out, said why
                left_out.append(str(err))
                continue
            if x is not None:
                xs.append(x)
        if xs:
            use.append((s, xs))
    e = {"sets": [s.id for s, _ in use], "mu": [s.p("mu") for s, _ in use],
         "n_seeds": [len(xs) for _, xs in use], "n_contacts": [int(sum(x["n"] for x in xs)) for _, xs in use],
         "quantities": {}, "left_out": left_out}
    if len(use) < 2:
        return dict(e, status="not tested", reason=f"{len(use)} set(s) of mu >= 1 with F_t/F_n tables (2 needed)")
    if sum(e["n_seeds"]) - len(use) < 1:
        return dict(e, status="not tested", reason="one seed in every set: no seed scatter to test against")
    for q in QUANTITIES + (CONTROL,):
        groups = [[x[q] for x in xs] for _, xs in use]
        a = one_way_anova(groups)
        a["mean"] = [float(np.mean(v)) for v in groups]
        a["err"] = [a["scatter"] / math.sqrt(len(v)) for v in groups]
        e["quantities"][q] = a
    ps = [e["quantities"][q]["p"] for q in QUANTITIES]
    if not all(math.isfinite(p) for p in ps):
        return dict(e, status="not tested", reason="no seed scatter (identical runs)")
    p_min = min(ps)
    pb = min(1.0, p_min * len(QUANTITIES))
    return dict(e, status="tested", p_min=p_min, p_bonferroni=pb, collapses=pb >= LEVEL)


def tests(sets):
    """``family_test`` of every family of sets differing in mu with two or more sets of mu >= 1."""
    out = []
    for fam, members in families(sets, "contact.mu"):
        if sum(s.p("mu") >= 1 for s in members) >= 2:
            out.append(dict(family=fam, **family_test(members)))
    return out


LABEL = {"ratio_mean": "mean F_t/F_n", **{f"below_{x:g}": f"F_t/F_n < {x:g}" for x in POINTS},
         CONTROL: "mean ζ (control)"}


def section(entries, fam_text):
    """README lines: the collapse test per family (``fam_text(family, drop)`` names a family)."""
    L = ["## F_t/F_n for μ ≥ 1: does it collapse? (Fig. 8; docs/model.md 6.7)", "",
         "Per run, the bulk contacts' mean F_t/F_n and the fractions below " + ", ".join(f"{x:g}" for x in POINTS)
         + "; per family of sets differing in μ (μ ≥ 1), a one-way analysis of variance of each across the sets "
         "against the seed scatter pooled over them (± below: that scatter / √seeds). The paper says the curves "
         f"collapse: p large. Verdict: the smallest p of the {len(QUANTITIES)} times {len(QUANTITIES)} "
         f"(Bonferroni) against {LEVEL:g} (the claim table's rule: two-sided 2 σ). Mean ζ = F_t/(μF_n) is the "
         "control: it must differ.", ""]
    if not entries:
        return L + ["No family has two sets of μ ≥ 1.", ""]
    for e in entries:
        L.append(f"- {fam_text(e['family'], ('mu',))}: " + (
            f"sets {', '.join(e['sets'])} (μ = {', '.join(f'{m:g}' for m in e['mu'])}; seeds "
            f"{', '.join(map(str, e['n_seeds']))}): "
            + (f"smallest p {e['p_min']:.2g}, Bonferroni {e['p_bonferroni']:.2g}: "
               + ("**collapses**" if e["collapses"] else "**does not collapse**")
               if e["status"] == "tested" else f"not tested ({e['reason']})")))
        L += [f"  - left out: {why}" for why in e.get("left_out", [])]
        if e["status"] != "tested":
            continue
        head = ["quantity"] + [f"μ = {m:g}" for m in e["mu"]] + ["F (dof)", "p"]
        rows = []
        for q, a in e["quantities"].items():
            rows.append([LABEL[q]] + [fmt_pm(m, s, 4) for m, s in zip(a["mean"], a["err"])]
                        + [f"{a['F']:.2f} ({a['dof'][0]}, {a['dof'][1]})", f"{a['p']:.2g}"])
        L += ["", md_table(head, rows), ""]
    return L + [""]
