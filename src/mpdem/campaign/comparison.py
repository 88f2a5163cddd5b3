"""``mpdem collect``'s comparison with the paper and its OUT/README.md.

``comparisons`` sets this work's numbers (set means with standard errors
over seeds, the eq. 7 and eq. 9 fits) next to the paper's values and, where
docs/model.md 7 gives one, its acceptance range, with a verdict (within /
outside / n/a). ``write_readme`` writes OUT/README.md: the parameter sets
and seeds, that comparison table, the fits, the figures made and not made,
and the runs skipped.
"""
from __future__ import annotations

import math

import numpy as np

from ..io import rundir
from ..analysis import fits
from . import contrasts, depth, paper, pooled, ratio, samples
from .figures import FIGURES
from .runs import NAN, families, fmt_kn, fmt_pm, md_table as _table, off_columns as _off_columns

# findings written by hand beside the results, copied into the README by every collect
NOTES = "NOTES.md"


# ---------------------------------------------------------------- comparison with the paper

def _size_note(s):
    N, L_x, L_y = s.p("N"), s.p("L_x"), s.p("L_y")
    if paper.is_paper_size(N, L_x, L_y):
        return ""
    return f"; N = {N}, {L_x:g}d x {L_y:g}d box (paper: {paper.REFERENCE['N']}, {paper.REFERENCE['L']:g}d)"


def _extras(s):
    """A set's settings away from their defaults outside the tables' columns (``Set.extra`` and the
    parameters of ``_off_columns``), as text; empty when there are none."""
    return ", ".join(f"{k} = {v}" for k, v in sorted({**_off_columns(s), **s.extra}.items()))


def flow_arrested(s):
    """Whether a set's packings were made by stopping a flow (a flow phase, ``flow.time``: docs/model.md
    5.5), the paper's second protocol: compared with its flow-arrest numbers, not the poured ones."""
    return bool(s.extra.get("flow.time"))


def _cond(s, alpha=False):
    base = f"mu = {s.p('mu'):g}, eps = {s.p('epsilon'):g}"
    if alpha:
        base += f", k_n = {fmt_kn(s.p('k_n'))}, phi_i = {s.p('phi_i'):g}"
    return base + (f", {_extras(s)}" if _extras(s) else "") + _size_note(s)


def _verdict(value, accept):
    if accept is None or not math.isfinite(value):
        return "n/a"
    return "within" if accept[0] <= value <= accept[1] else "outside"


def comparisons(sets, fit_res):
    """Rows of the README's comparison table (dicts: quantity, conditions, set, value, err, n_seeds,
    paper, paper_err, accept, verdict, source). Verdicts only for docs/model.md 7's acceptance list."""
    rows = []

    def add(quantity, cond, sid, value, err, n, p_value, p_err, accept, source, note=""):
        rows.append(dict(quantity=quantity, conditions=cond, set=sid, value=value, err=err, n_seeds=n,
                         paper=p_value, paper_err=p_err, accept=accept, verdict=_verdict(value, accept),
                         source=source, note=note))

    poured = [s for s in sets if not flow_arrested(s)]
    for p in paper.POINTS:
        for s in poured:
            ref = paper.is_reference(s.p("k_n"), s.p("phi_i"))
            if not (paper.applies(p, s.p("mu"), s.p("epsilon")) and (ref or p["quantity"] == "alpha")):
                continue
            m, e, n = s.stat(p["quantity"])
            if n:
                add(p["quantity"], _cond(s, p["quantity"] == "alpha"), s.id, m, e, n, p["value"], p["err"],
                    p["accept"], p["source"])
    for p in paper.FLOW_ARREST:
        for s in sets:
            if flow_arrested(s) and paper.applies(p, s.p("mu"), s.p("epsilon")):
                m, e, n = s.stat(p["quantity"])
                if n:
                    add(p["quantity"], _cond(s), s.id, m, e, n, p["value"], p["err"], p["accept"], p["source"],
                        p["note"])
    ref = [s for s in poured if paper.is_reference(s.p("k_n"), s.p("phi_i"))]
    for fam, members in families(ref, "contact.mu"):
        if len(members) >= 3:
            for q in ("z", "phi"):
                add(f"{q}(mu) trend", f"eps = {fam['epsilon']:g}" + _fam_size(fam), " ".join(s.id for s in members),
                    _trend(members, q), None, None, "decreases monotonically, saturates for mu >= 1", None, None,
                    paper.SOURCE)
    for p in paper.SMALL_POINTS:
        for s in poured:
            if (paper.is_small_pile(s.p("N"), s.p("L_x"), s.p("L_y")) and paper.is_reference(s.p("k_n"), s.p("phi_i"))
                    and paper.applies(p, s.p("mu"), s.p("epsilon"))):
                m, e, n = s.stat(p["quantity"])
                add(p["quantity"], f"mu = {s.p('mu'):g}, eps = {s.p('epsilon'):g}; N = {s.p('N')}, "
                    f"{s.p('L_x'):g}d box vs 7.1 (N = 2000, 10d box)", s.id, m, e, n, p["value"],
                    None, p["accept"], p["source"], "7.1 is one seed; the acceptance is this project's "
                    "development-size choice")
    for e in fit_res["eq7"]:
        if e["status"] != "fitted":
            continue
        f, ids = e["family"], " ".join(e["sets"])
        cond = f"eq. 7, mu = {f['mu']:g}, eps = {f['epsilon']:g}, phi_i = {f['phi_i']:g}"
        if f["mu"] == 0:
            P = paper.EQ7_MU0
            add("z_inf", cond, ids, e["z_inf"], e["z_inf_err"], None, P["z_inf"], P["z_inf_err"],
                P["accept_z_inf"], P["source"])
            add("alpha_n", cond, ids, e["alpha_n"], e["alpha_n_err"], None, P["alpha_n"], P["alpha_n_err"], None,
                P["source"])
        else:
            add("z_inf", cond, ids, e["z_inf"], e["z_inf_err"], None, "> 4", None, None, paper.SOURCE,
                "frictional: z_inf depends on mu and eps")
            add("alpha_n", cond, ids, e["alpha_n"], e["alpha_n_err"], None, paper.EQ7_FRICTIONAL_ALPHA_N, None,
                None, paper.SOURCE, "frictional: ~ 1/4")
        c = e["check_alpha_n"]
        if math.isfinite(c.get("difference", NAN)):
            add("alpha_n - (1 - alpha)", cond, ids, c["difference"], c["difference_err"], None, 0.0, None, None,
                paper.SOURCE, "eq. 8 (mu = 0 only)")
    for e in fit_res["eq9"]:
        f = e["family"]
        if e["status"] != "fitted" or (f["mu"], f["epsilon"], f["k_n"]) != (paper.EQ9["mu"], paper.EQ9["epsilon"],
                                                                          paper.EQ9["k_n"]):
            continue
        phi_i = np.array(e["phi_i"])
        dev = fits.eq9(phi_i, e["A"], e["B"], e["C"]) - paper.eq9_paper(phi_i)
        worst = float(dev[np.argmax(np.abs(dev))])
        tol = paper.EQ9["accept_dphi"]
        add("eq. 9 fit - paper, worst phi_i", f"mu = {f['mu']:g}, eps = {f['epsilon']:g}" + _fam_size(f),
            " ".join(e["sets"]), worst, None, None, 0.0, None, (-tol, tol), paper.EQ9["source"],
            f"over phi_i = {', '.join(f'{v:g}' for v in phi_i)}")
        for k in "ABC":
            add(f"eq. 9 {k}", f"mu = {f['mu']:g}, eps = {f['epsilon']:g}", " ".join(e["sets"]), e[k], e[f"{k}_err"],
                None, paper.EQ9[k], None, None, paper.EQ9["source"])
    return rows


def _trend(members, q):
    """'decreasing at every step', or where the mean rises with mu (by how much, with its error)."""
    st = [(s.p("mu"), *s.stat(q)[:2]) for s in members]
    rises = [f"{a[0]:g} to {b[0]:g} by {fmt_pm(b[1] - a[1], math.hypot(a[2], b[2]), 3)}"
             for a, b in zip(st, st[1:]) if b[1] > a[1]]
    return "decreasing at every step" if not rises else "rises from mu = " + "; ".join(rises)


def _fam_size(f):
    return "" if paper.is_paper_size(f["N"], f["L_x"], f["L_y"]) else f"; N = {f['N']}, {f['L_x']:g}d box"


# ---------------------------------------------------------------- README

_BASE = {"z": 3, "alpha": 3, "z_inf": 3, "alpha_n": 3}   # decimals shown at least, per quantity


def _quoted(v, err=None):
    """A paper value as quoted (no digits added)."""
    return v if isinstance(v, str) else f"{v!r}" + ("" if err is None else f" ± {err!r}")


def _collapse_text(e):
    """The collapse test of an overlap fit in words."""
    c = e.get("collapse")
    if not c or c.get("status") != "tested":
        return "collapse not tested (one k_n)" if c else "collapse not tested"
    res = ", ".join(f"{fmt_kn(k)} {fmt_pm(r, e, 3)}" for k, r, e in zip(c["levels"], c["residual"], c["residual_err"]))
    return f"collapse F = {c['F']:.2f} ({c['dof'][0]}, {c['dof'][1]} dof), p = {c['p']:.2g}; mean residuals {res}"


def _fam_text(f, drop=()):
    keys = [k for k in ("mu", "epsilon", "k_n", "phi_i", "N", "L_x", "model", "gamma_t/gamma_n", "gamma_t", "K0")
            if k in f and k not in drop]
    return ", ".join(f"{k} = {fmt_kn(f[k]) if k == 'k_n' else f[k]}" for k in keys)


def write_readme(path, info, sets, fit_res, rows, figs, skipped, windows=(), claim_rows=None):
    """OUT/README.md: the claim table first (``claimtable``, the rule stated once), then the parameter sets,
    one short section per figure and equation with its plot and numbers, the measures under gravity, the
    one-setting contrasts and the seeds, and the runs skipped. The dated log of findings is OUT/NOTES.md
    (written by hand; not copied here). ``rows``: the per-set comparisons (collect.json keeps them)."""
    from . import claimtable
    L = ["# mpdem collect: the paper's tables and figures", "",
         f"Made by `mpdem collect` on {info['date']} from {info['n_runs']} run(s) in {info['n_sets']} parameter "
         f"set(s); {len(skipped)} skipped (the last section). Inputs: "
         f"{', '.join(f'`{t}`' for t in info['inputs'])}. Paper: " + paper.SOURCE + ".", "",
         "`±` is the standard error of the mean over the seeds (runs) of a set, unless a row says otherwise; a set "
         "with one seed has no error bar and says so. The dated log of how each number came about, newest first "
         f"at its head: [`{NOTES}`]({NOTES}).", ""]
    if claim_rows is not None:
        L += claimtable.section(claim_rows)
    L += ["## Parameter sets", "",
          "Every run parameter but the seed is equal within a set (`sets.csv` has them all; runs in `runs.csv`). "
          "A stiffened rung (`stiffen.k_n_from` set) is a set of its own, apart from a pile poured at its k_n.", ""]
    head = ["set", "μ", "ε", "k_n", "φ_i", "N", "box", "seeds", "z", "z (no rattlers)", "φ_f", "α", "rattlers"]
    L += [_table(head, [[s.id, f"{s.p('mu'):g}", f"{s.p('epsilon'):g}", fmt_kn(s.p("k_n")), f"{s.p('phi_i'):g}",
                         s.p("N"), f"{s.p('L_x'):g}×{s.p('L_y'):g}", _seeds(s),
                         fmt_pm(*s.stat("z")[:2], 3, len(s.runs)), fmt_pm(*s.stat("z_no_rattlers")[:2], 3, len(s.runs)),
                         fmt_pm(*s.stat("phi")[:2], 4, len(s.runs)),
                         fmt_pm(*s.stat("alpha")[:2], 3, s.stat("alpha")[2]),
                         fmt_pm(*s.stat("rattler_fraction")[:2], 3, len(s.runs))] for s in sets]), ""]
    # settings outside the columns (e.g. the stop rule) that a set ran with away from their defaults
    other = [f"- {s.id}: run with {_extras(s)} (not the default; docs/config.md)" for s in sets if _extras(s)]
    L += other + ([""] if other else [])
    L += _figure_sections(sets, fit_res, figs, windows)
    L += _gravity_section(sets)
    L += contrasts.section(fit_res.get("contrasts", []), _fam_text)
    L += samples.section(fit_res.get("samples", {}))
    L += ["## Skipped", ""]
    L += [_table(["run", "reason"], [[f"`{s['path']}`", s["reason"]] for s in skipped])] if skipped else ["None."]
    rundir.write_atomic(path, "\n".join(L) + "\n")


# which claims of the table each figure bears on
FIGURE_CLAIMS = {"fig2": "7, 8, 9, 10", "fig3": "7b, 10", "fig4": "11, 12, 13", "fig5": "14, 15",
                 "fig6": "16, 17", "fig7": "19-27", "fig8": "29, 30, 30b",
                 "fig9": "32 (31, the paper's eq. 9 at μ = 0.5, is fitted in analysis/results/dev)",
                 "fig10": "16-18", "fig11": "19, 27, 4 (depth)", "fig12": "33 (P(f))"}


def _figure_sections(sets, fit_res, figs, windows):
    """One short section per figure: its plot, the claims it bears on, its notes and its numbers."""
    L = ["## Figures and equations", "", f"Figs. 2-6 and 8 use the sets at {figs['_slice']}.", ""]
    numbers = {"fig6": _alpha_section, "fig7": _eq7_section, "fig8": _ratio_section, "fig9": _eq9_section,
               "fig11": _overlap_depth_section, "fig12": _pf_section}
    for name, _, shows in FIGURES:
        f = figs[name]
        L += [f"### {name.replace('fig', 'Fig. ')}: {shows}", ""]
        L += [f"Claims {FIGURE_CLAIMS[name]}.", ""] if name in FIGURE_CLAIMS else []
        L += [f"![{shows}]({f['file']})" if f["made"] else f"**Not made**: {f['reason']}.", ""]
        L += [f"- note: {n}" for n in figs["_notes"].get(name, [])]
        if figs["_notes"].get(name):
            L.append("")
        if name in numbers:
            L += numbers[name](sets, fit_res, windows)
    return L


def _ratio_section(sets, fit_res, windows):
    """The F_t/F_n collapse (``ratio.section``), its heading one level down."""
    L = ratio.section(fit_res.get("ratio", []), _fam_text)
    return [L[0].replace("## ", "#### ", 1)] + L[1:]


def _eq7_section(sets, fit_res, windows):
    L = ["Eq. 7, z(k_n) = z∞ + ã k_n^(−α_n), per family of sets differing in k_n (weights 1/σ², σ = the family's "
         "pooled seed-to-seed scatter / √(seeds of the set); the free fit, then with α_n fixed: 1/2 at μ = 0, the "
         "paper's 1/4 with friction):", ""]
    L += [_fit_lines(e, "eq7") for e in fit_res["eq7"]] or ["- no family with ≥ 2 values of k_n"]
    L += ["", "Stiffening ladders (a settled pile stiffened rung by rung, docs/model.md 6.6; eq. 7 over every run of "
          "the base set's piles and the rungs they climbed, once they give 4 k_n):", ""]
    L += [_ladder_lines(e) for e in fit_res.get("ladder", [])] or ["- none collected"]
    return L + [""]


def _widened(x):
    return f", errors × {x['scale']:.3g} (√(χ²/dof))" if x.get("scale", 1.0) > 1.0 else ""


def _pile_name(p):
    """seed S, and its bed where that is not S (a ladder's pile: seed, bed seed, poured k_n)."""
    return f"seed {p[0]}" + (f" (bed {p[1]})" if p[1] != p[0] else "")


def _ladder_lines(e):
    f = e["family"]
    rungs = "; ".join(f"{fmt_kn(r['k_n'])} ({r['set']}, {r['n_runs']} run{'s' if r['n_runs'] > 1 else ''}): z "
                      f"{fmt_pm(r['z'], r['z_sem'] if r['z_sem'] is not None else NAN, 3, r['n_runs'])}, median "
                      f"overlap {r['overlap_median']:.2g} d" for r in sorted(e["rungs"], key=lambda r: r["k_n"]))
    line = f"- μ = {f['mu']:g}, ε = {f['epsilon']:g}, N = {f['N']} [base {e['base'] or 'none'}]: {rungs}. "
    if e.get("status") in ("fitted",) and "z_inf" in e:
        noise = (f"; p = {e['p_noise']:.2g} against F({e['dof']}, {e['s_within_dof']}), the noise itself measured"
                 if math.isfinite(e.get("p_noise", NAN)) else "")
        line += (f"Eq. 7 over its {e['n_points']} runs of {e['n_piles']} piles, a pile's runs covarying "
                 f"(piles' scatter {e['s_total']:.2g} from {e['s_total_dof']} dof, a pile's noise from rung to rung "
                 f"{e['s_within']:.2g} from {e['s_within_dof']}): z∞ = {fmt_pm(e['z_inf'], e['z_inf_err'], 3)}, "
                 f"α_n = {fmt_pm(e['alpha_n'], e['alpha_n_err'], 3)}; χ² = {e['chi2']:.3g} for {e['dof']} dof "
                 f"(p = {e['p_value']:.2g} with that noise known{noise}){_widened(e)}")
        fx = e.get("fixed") or {}
        if "z_inf" in fx:
            line += (f"; α_n fixed at {fx['alpha_n']:g}: z∞ = {fmt_pm(fx['z_inf'], fx['z_inf_err'], 3)}, χ² = "
                     f"{fx['chi2']:.3g} for {fx['dof']} dof{_widened(fx)}")
    else:
        line += f"Eq. 7 over its runs: **{e.get('status')}** ({e.get('reason', '')})"
    loc = [_pile_name(x["pile"])
           + (f" {fmt_pm(x['alpha_n'], x.get('alpha_n_err', NAN))}" if math.isfinite(x["alpha_n"])
              else " none (z does not fall at both steps)")
           + f" ({fmt_kn(x['k_n'][0])}–{fmt_kn(x['k_n'][2])})" for x in e.get("local_exponents") or []]
    if loc:
        errs = any(math.isfinite(x.get("alpha_n_err", NAN)) for x in e.get("local_exponents"))
        line += (". Each pile's exponent through three rungs (one power law gives one"
                 + ("; errors from a pile's noise from rung to rung" if errs else "") + "): " + ", ".join(loc))
    bend = e.get("bend") or {}
    if bend.get("status") == "fitted":
        each = ", ".join(_pile_name(x["pile"]) + (f" {fmt_pm(x['change'], x['change_err'])}"
                                                  if math.isfinite(x["change"])
                                                  else " left out (z does not fall at every step)")
                         for x in bend["piles"])
        n, of = bend["n_piles"], len(bend["piles"])
        over = f"{n if n == of else f'{n} of {of}'} pile{'s' if of > 1 else ''}"
        line += (f". The exponent's change from a pile's lowest three rungs to its highest, pooled over "
                 f"{over}: {fmt_pm(bend['change'], bend['change_err'])} ({each}; the noise from "
                 f"{bend['s_within_dof']} dof; one power law gives 0; two-sided p = {bend['p_normal']:.2g} with that "
                 f"noise known, {bend.get('p_student', NAN):.2g} against Student's t on its dof, the noise itself "
                 f"measured); the lowest three rungs' exponent pooled "
                 f"{fmt_pm(bend['low'], bend['low_err'])}, the highest's {fmt_pm(bend['high'], bend['high_err'])}")
    sm = e.get("set_means") or {}
    if sm.get("status") == "fitted":
        line += (f". The sets' means fitted as if independent: z∞ = {fmt_pm(sm['z_inf'], sm['z_inf_err'], 3)}, "
                 f"α_n = {fmt_pm(sm['alpha_n'], sm['alpha_n_err'], 3)}; χ² = {sm['chi2']:.3g} for {sm['dof']} dof")
    return line


def _eq9_section(sets, fit_res, windows):
    L = ["Eq. 9, φ_f = A + B exp(−C φ_i), per family of sets differing in φ_i:", ""]
    L += [_fit_lines(e, "eq9") for e in fit_res["eq9"]] or ["- no family with ≥ 2 values of φ_i"]
    return L + [""]


def _depth_section(windows):
    """z and phi on fixed depth windows below the surface (``depth.csv``, which has the fabric as well;
    docs/model.md 6.10)."""
    have = {(r["set"], r["window"], r["quantity"]): r for r in windows if math.isfinite(r["mean"])}
    keys = list(dict.fromkeys((r["set"], r["window"]) for r in windows if r["quantity"] == "z"
                              and (r["set"], r["window"], "z") in have))
    if not keys:
        return []
    L = ["z and φ at fixed depths below the surface (`depth.csv`, with the contact fabric): the slab of "
         "docs/model.md 6.1 follows each pile's height, these windows are the same depths in every pile. Errors: "
         "the seed scatter pooled over the sets of one N and μ, over √(seeds of the set); then the jackknife over "
         "each pile's 4 × 4 lateral columns, combined over its seeds (an upper bound: a pile's columns are "
         "anticorrelated; docs/model.md 6.10).", ""]

    def cell(k, q):
        r = have.get((*k, q))
        if r is None:
            return "—"
        d = depth.DIGITS[q]
        errs = " ± ".join(f"{r[e]:.{d}f}" if math.isfinite(r[e]) else "—" for e in ("pooled_sem", "jackknife"))
        return f"{r['mean']:.{d}f} ± {errs}"

    rows = []
    for k in keys:
        r = have[(*k, "z")]
        rows.append([k[0], f"{r['mu']:g}", r["N"], k[1], cell(k, "z"), cell(k, "phi"), r["n_seeds"]])
    L += [_table(["set", "μ", "N", "window [d]", "z ± pooled ± jackknife", "φ ± pooled ± jackknife", "runs"], rows),
          ""]
    return L


def _fit_lines(e, kind):
    xs = e["k_n"] if kind == "eq7" else e["phi_i"]
    pts = ", ".join((fmt_kn(x) if kind == "eq7" else f"{x:g}") + f" ({n})" for x, n in zip(xs, e["n_seeds"]))
    head = f"- {_fam_text(e['family'], ('k_n',) if kind == 'eq7' else ('phi_i',))} [sets {' '.join(e['sets'])}]; " \
           f"points (seeds): {pts}: "
    if "stiffened x" in e["family"]:
        # a ladder's rungs without the poured pile they climbed from: the ladder's line fits them with it
        head += "stiffened rungs alone, without their base (the stiffening ladders below fit them with it): "
    if e["status"] != "fitted":
        return head + f"**{e['status']}**: {e['reason']}" + _fixed_text(e)
    if kind == "eq7":
        c = e["check_alpha_n"]
        s = (f"z∞ = {fmt_pm(e['z_inf'], e['z_inf_err'], 3)}, ã = {fmt_pm(e['a_tilde'], e['a_tilde_err'], 1)}, "
             f"α_n = {fmt_pm(e['alpha_n'], e['alpha_n_err'], 3)}; α = {fmt_pm(c['alpha'], c['alpha_err'], 3)} over "
             f"{c['n_runs']} runs, so 1 − α = {fmt_pm(c['one_minus_alpha'], c['alpha_err'], 3)}")
    else:
        s = (f"A = {fmt_pm(e['A'], e['A_err'], 4)}, B = {fmt_pm(e['B'], e['B_err'], 4)}, "
             f"C = {fmt_pm(e['C'], e['C_err'], 2)}")
    s += f"; χ² = {e['chi2']:.3g} for {e['dof']} degrees of freedom" + (" (weighted)" if e["weighted"] else "")
    if e["dof"] == 0:
        # as many points as parameters: the curve passes through them, and nothing tests it
        s += f": an exact interpolation of its points, not a test of eq. {7 if kind == 'eq7' else 9}"
    if math.isfinite(e.get("p_value", math.nan)):
        s += f", p = {e['p_value']:.2g}"
    s += _fixed_text(e)
    if math.isfinite(e.get("pooled_scatter", math.nan)):
        s += f" (pooled scatter of z over seeds {e['pooled_scatter']:.4f}, {e['pooled_dof']} degrees of freedom)"
    return head + s + (f". Note: {e['note']}" if e.get("note") else "")


def _fixed_text(e):
    """The eq. 7 fit with its exponent fixed, in words ('' without one)."""
    fx = e.get("fixed") or {}
    if "z_inf" not in fx:
        return ""
    return (f". α_n fixed at {fx['alpha_n']:g}: z∞ = {fmt_pm(fx['z_inf'], fx['z_inf_err'], 3)}, "
            f"ã = {fmt_pm(fx['a_tilde'], fx['a_tilde_err'], 1)}; χ² = {fx['chi2']:.3g} for {fx['dof']} degrees "
            f"of freedom, p = {fx['p_value']:.2g}")


def _by_id(entries):
    return {e["set"]: e for e in entries}


def _gravity_section(sets):
    """The README section of the counts of a pile under gravity (docs/model.md 6.2)."""
    L = ["## Counting under gravity", "",
         "z over all bulk spheres (the paper's z); z of the force-bearing backbone (contacts below 1 % of their "
         "depth band's mean normal force dropped, then spheres that cannot balance their weight with the rest; "
         "docs/model.md 6.2) and its rattler fraction; the count rule's rattler fraction (fewer than 4 contacts at "
         "μ = 0, 2 with friction: the rule of packings without gravity); for μ > 0 the generalized isostatic "
         "count 4 + n_m / 3 (n_m = 2 N_m / N, the fully mobilised contacts counted once for each of their two "
         "spheres; docs/model.md 6.2); the "
         "crystal-like fraction (q6 bond order).", ""]
    rows = []
    for s in sets:
        if not any(r.s.get("backbone") for r in s.runs):
            continue
        cr = [((r.s.get("count_rule") or {}).get("rattler_fraction")) for r in s.runs]
        cr = [c for c in cr if c is not None]
        n = len(s.runs)
        rows.append([s.id, f"{s.p('mu'):g}", f"{s.p('epsilon'):g}", fmt_kn(s.p("k_n")), s.p("N"),
                     fmt_pm(*s.stat("z")[:2], 3, n), fmt_pm(*s.stat("z_backbone")[:2], 3, n),
                     fmt_pm(*s.stat("rattler_fraction")[:2], 3, n),
                     f"{np.mean(cr):.3f}" if cr else "—",
                     fmt_pm(*s.stat("z_iso")[:2], 3, n) if s.p("mu") > 0 else "6",
                     fmt_pm(*s.stat("crystal_fraction")[:2], 4, n)])
    L += [_table(["set", "μ", "ε", "k_n", "N", "z (all)", "z (backbone)", "rattlers (force)", "rattlers (count rule)",
                  "isostatic count", "crystal-like"], rows), ""] if rows else \
        ["No run has the backbone measures (analysed before they existed: `mpdem analyze` again).", ""]
    return L


def _alpha_section(sets, fit_res, windows=()):
    """The eq. 6 exponent on fixed windows of xi (docs/model.md 6.5)."""
    al = _by_id(fit_res.get("alpha", []))
    L = ["Near-contact exponent α (eq. 6) on fixed windows:", "",
          "Maximum likelihood on the gaps ξ = r/d − 1 of every bulk pair in the window (docs/model.md 6.5), the "
          "seeds pooled: first error the statistical (Fisher) one, second a bootstrap over seeds. `soft`: the "
          "window's lower end is below 20 × the median bulk overlap. Paper: 0.52 ± 0.03 on an unnamed window; "
          "later work on jammed frictionless spheres: about 0.4 (Donev et al. 2005; Lerner et al. 2013 about 0.38).",
          ""]
    rows = []
    for s in sets:
        e = al.get(s.id)
        if not e:
            continue
        cells = [s.id, f"{s.p('mu'):g}", f"{s.p('epsilon'):g}", fmt_kn(s.p("k_n")), s.p("N"), e["n_runs"]]
        for w in e["windows"]:
            boot = f" ± {w['boot_err']:.3f}" if math.isfinite(w["boot_err"]) else ""
            txt = f"{w['alpha']:.3f} ± {w['alpha_err']:.3f}{boot}" if math.isfinite(w["alpha"]) else "—"
            cells.append(txt + (" soft" if w["soft"] else ""))
        rows.append(cells)
    if rows:
        wins = next(e for e in fit_res["alpha"])["windows"]
        head = ["set", "μ", "ε", "k_n", "N", "seeds"] + [f"[{w['xi_lo']:g}, {w['xi_hi']:g}]" for w in wins]
        L += [_table(head, rows), ""]
    else:
        L += ["No run has window statistics.", ""]
    return L


def _piles_text(e):
    """' of N piles' for a ladder's overlap fit, whose bootstrap draws piles (``pooled.overlap_fit``)."""
    return f" of {e['n_piles']} piles" if e.get("n_piles") else ""


def _alternatives_text(e):
    """'; with 1/3: z_c 5.887, rms 0.049; ...' of an overlap fit's alternative exponents
    (``pooled.OVERLAP_ALTERNATIVES``)."""
    alts = [(k.split()[1], f) for k, f in e.items() if k.startswith("exponent ") and isinstance(f, dict)
            and f.get("status") == "fitted"]
    return "".join(f"; with {x}: z_c {pooled.z_c_text(f, why=False)}, rms {f['rms']:.3f}" for x, f in alts)


def _overlap_depth_section(sets, fit_res, windows):
    """z against the overlap (docs/model.md 6.6), then z on the fixed depth windows."""
    L = ["z against the overlap (docs/model.md 6.6):", "",
          "z − z_c = A (δ/d)^(1/2) fitted over the depth bands inside the bulk of every run of a family (all k_n), "
          "and with the exponents of the bracket the bands do not rule out (their z_c and rms after each line), "
          "δ the band's mean contact overlap; the error of z_c is a bootstrap over runs, and over piles for a "
          "stiffening ladder (its base set with its rungs: a pile's runs at every rung drawn together). At μ = 0 "
          "isostaticity "
          "says z_c = 6. The collapse: the F test of the one curve against one of the same slope offset for each "
          "k_n (p small: the k_n do not collapse; bands taken as independent), and each k_n's mean residual from "
          "the one curve.", ""]
    ov = [e for e in fit_res.get("overlap", []) if e["status"] == "fitted"]
    L += [f"- {_fam_text(e['family'], ('k_n',))}: z_c = {pooled.z_c_text(e)}, "
          f"A = {fmt_pm(e['A'], e['A_err'], 1)}; {e['n_bands']} bands of {e['n_runs']} runs{_piles_text(e)}, δ/d from "
          f"{e['delta_min']:.2g} to {e['delta_max']:.2g}, rms residual {e['rms']:.3f}; {_collapse_text(e)}"
          f"{_alternatives_text(e)}" for e in ov] or ["- no family with depth profiles of 2 runs or more"]
    return L + [""] + _depth_section(windows)


def _pf_section(sets, fit_res, windows=()):
    """Normal forces P(f) (docs/model.md 6.10)."""
    pf = _by_id(fit_res.get("P_f", []))
    L = ["Normal forces P(f) (docs/model.md 6.10):", "",
          "f = F_n / the mean F_n of its depth band, bulk contacts, seeds pooled: the fraction with f < 0.1 and the "
          "decay rate β of P(f) ~ exp(−β f) beyond f = 1 (maximum likelihood).", ""]
    rows = [[s.id, f"{s.p('mu'):g}", f"{s.p('epsilon'):g}", fmt_kn(s.p("k_n")), s.p("N"), pf[s.id]["n"],
             f"{pf[s.id]['small_f_fraction']:.4f}", fmt_pm(pf[s.id]["tail_rate"], pf[s.id]["tail_rate_err"], 2)]
            for s in sets if s.id in pf]
    L += [_table(["set", "μ", "ε", "k_n", "N", "contacts", "f < 0.1", "β"], rows), ""] if rows else ["None.", ""]
    return L


def _seeds(s):
    """A set's seeds as the table shows them: a run whose bed has a seed of its own says so ("1 (bed 101)")."""
    return " ".join(f"{r.params['run.seed']}" + (f" (bed {r.bed_seed})" if r.bed_seed != r.params["run.seed"] else "")
                    for r in s.runs)
