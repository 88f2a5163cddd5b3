"""``mpdem collect``: many analysed runs -> the paper's tables and figures.

::

    OUT/runs.csv      one row per usable run (parameters, z, z_nr, phi_f, alpha, ...)
    OUT/sets.csv      one row per parameter set: mean and standard error over its seeds
    OUT/fits.json     eq. 7 per family of k_n, eq. 9 per family of phi_i (or why not)
    OUT/fig*.png      Figs. 2-9 of the paper, its values drawn as open markers / dashes
    OUT/README.md     sets, seeds, numbers next to the paper's and physics.md 7's acceptance
    OUT/collect.json  the runs used and skipped, the figures made and not made, and why

A parameter set is every run parameter of ``report.PARAMS`` except the seed,
compared exactly. Error bars are the standard error of the mean over the
runs (seeds) of a set; a set with one seed has none (empty in the tables).
Empty CSV cells mean "not available".
"""
from __future__ import annotations

import csv
import io
import json
import math
import os
import time
import warnings
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from .. import rundir
from . import fits, paper
from .report import PARAMS, SUMMARY, AnalysisError

SHORT = {k: k.split(".", 1)[1] for k in PARAMS}   # contact.mu -> mu, run.seed -> seed, ...
SET_QUANTITIES = ("z", "z_no_rattlers", "phi", "alpha", "rattler_fraction", "mobilised_fraction",
                  "z_halved", "phi_halved", "overlap_median", "step")
# k_t, gamma_n, gamma_t and dt follow k_n in a stiffness sweep (physics.md 3, 4.2)
FOLLOW_K_N = ("contact.k_n", "contact.k_t", "contact.gamma_n", "contact.gamma_t", "integration.dt")
NAN = float("nan")


# ---------------------------------------------------------------- runs and sets

@dataclass
class Run:
    """One analysed run: its directory, its summary.json and the numbers read from it."""
    path: str
    s: dict
    q: dict = field(default_factory=dict)

    def __post_init__(self):
        self.q = quantities(self.s)

    @property
    def params(self):
        return self.s["params"]


@dataclass
class Set:
    """The runs of one parameter set (all of ``PARAMS`` but the seed equal)."""
    id: str
    params: dict
    runs: list

    def p(self, short):
        """A parameter by its short name (mu, epsilon, k_n, phi_i, N, L_x, ...)."""
        return self.params[next(k for k in PARAMS if SHORT[k] == short)]

    @property
    def seeds(self):
        return [r.params["run.seed"] for r in self.runs]

    def stat(self, q):
        """(mean, standard error, count) of quantity ``q`` over the runs; see ``mean_sem``."""
        return mean_sem([r.q[q] for r in self.runs])


def _num(v):
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else NAN


def quantities(s):
    """The per-run numbers of a summary.json (nan where absent or null)."""
    hm, zt = s.get("halved_margins") or {}, s.get("zeta") or {}
    q = {k: _num(s.get(k)) for k in ("z", "z_no_rattlers", "rattler_fraction", "phi", "alpha", "alpha_err",
                                     "n_bulk", "overlap_median", "overlap_max", "step")}
    q.update(mobilised_fraction=_num(zt.get("mobilised_fraction")), z_halved=_num(hm.get("z")),
             phi_halved=_num(hm.get("phi")))
    return q


def mean_sem(values):
    """Mean and standard error of the mean of the finite values.

    Returns
    -------
    (mean, sem, n): sem = std(ddof=1) / sqrt(n), nan when n < 2 (no error bar
    from a single seed); mean nan when n = 0.
    """
    v = np.asarray([x for x in values if x is not None and math.isfinite(x)], float)
    n = len(v)
    mean = float(np.mean(v)) if n else NAN
    sem = float(np.std(v, ddof=1) / np.sqrt(n)) if n >= 2 else NAN
    return mean, sem, n


def set_key(params):
    """The exact, tolerance-free key of a parameter set: every parameter but the seed."""
    return tuple((k, params.get(k)) for k in PARAMS if k != "run.seed")


def _order(v):
    return (0, v, "") if isinstance(v, (int, float)) and not isinstance(v, bool) else (1, 0, str(v))


SORT = ("contact.model", "pour.N", "box.L_x", "box.L_y", "pour.K0", "contact.gamma_t", "contact.epsilon",
        "pour.phi_i", "contact.k_n", "contact.mu")


def _set_order(params):
    rest = [k for k in PARAMS if k not in SORT]
    return tuple(_order(params.get(k)) for k in SORT + tuple(rest))


# ---------------------------------------------------------------- finding and loading runs

def _is_run(d):
    return any(os.path.exists(os.path.join(d, *p)) for p in
               (("final.h5",), ("analysis", SUMMARY), ("config.toml",)))


def find_runs(targets):
    """Run directories named on the command line or found below them.

    A run directory holds final.h5, analysis/summary.json or config.toml (an
    unfinished run: listed, then skipped). Below a directory that is not a
    run, the search is recursive (hidden directories left out) and stops at
    each run directory.

    Returns
    -------
    (paths, skipped): run directories, each once, in the order found, and
    [{"path", "reason"}] for arguments that hold no run.
    """
    found, skipped, seen = [], [], set()
    for t in targets:
        if not os.path.isdir(t):
            skipped.append({"path": t, "reason": "no such directory"})
            continue
        hits = []
        for root, dirs, _ in os.walk(t):
            if _is_run(root):
                hits.append(root)
                dirs[:] = []
            else:
                dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        if not hits:
            skipped.append({"path": t, "reason": "no run directories in it (none holds final.h5, "
                                                 "analysis/summary.json or config.toml)"})
        for h in hits:
            real = os.path.realpath(h)
            if real not in seen:
                seen.add(real)
                found.append(os.path.normpath(h))
    return found, skipped


def _analyse(path, why, log):
    """``mpdem analyze`` of a run (no plots); None, or the reason it failed."""
    from . import report
    log(f"collect: analysing {path} ({why})")
    try:
        report.analyze(path, plots=False, log=lambda m: [log(f"  {ln}") for ln in str(m).splitlines()])
    except Exception as e:  # one bad run must not stop the others: it is reported as skipped
        return f"analysis failed: {type(e).__name__}: {e}"
    return None


def load_run(path, analyze_missing=True, log=print):
    """One run directory as a Run, analysing it first if it needs it and may.

    Returns
    -------
    (Run, None), or (None, reason) when the run cannot be used: unfinished,
    not analysed (with ``analyze_missing`` False), analysis failed, summary
    unreadable or incomplete, or not converged (physics.md 5.4: a run at the
    step cap is not used for comparisons).
    """
    summ, final = os.path.join(path, "analysis", SUMMARY), rundir.final_path(path)
    if not os.path.exists(summ):
        if not os.path.exists(final):
            return None, "unfinished: no final.h5 and no analysis/summary.json"
        if not analyze_missing:
            return None, "not analysed: no analysis/summary.json (--no-analyze; run `mpdem analyze` on it)"
        err = _analyse(path, "no analysis/summary.json", log)
        if err:
            return None, err
    elif os.path.exists(final) and os.path.getmtime(final) > os.path.getmtime(summ):
        if analyze_missing:
            err = _analyse(path, "final.h5 is newer than analysis/summary.json", log)
            if err:
                return None, err
        else:
            log(f"collect: warning: {path}: final.h5 is newer than analysis/summary.json (--no-analyze: used as is)")
    try:
        with open(summ) as fh:
            s = json.load(fh)
    except (OSError, ValueError) as e:
        return None, f"unreadable {summ}: {e}"
    if not isinstance(s, dict):
        return None, f"{summ}: not a JSON object"
    missing = [k for k in PARAMS if k not in (s.get("params") or {})]
    if missing:
        return None, f"{summ}: params lack {', '.join(missing)}"
    if not s.get("converged"):
        return None, (f"not converged (stopped at step {s.get('step', '?')} without reaching the kinetic-energy "
                      f"threshold; physics.md 5.4: not used for comparisons)")
    run = Run(os.path.normpath(path), s)
    if not (math.isfinite(run.q["z"]) and math.isfinite(run.q["phi"])):
        return None, f"{summ}: no bulk z or phi"
    return run, None


def group(runs):
    """Sets of runs with equal parameters; a repeated seed in a set is a duplicate.

    A run is a pure function of its parameters and seed (design.md 2), so two
    runs of one set with one seed are one sample: the later is skipped.

    Returns
    -------
    (sets, skipped): Sets ordered by parameters (ids S01, S02, ...), runs
    ordered by seed; [{"path", "reason"}] of the duplicates.
    """
    by_key, skipped = {}, []
    for r in runs:
        by_key.setdefault(set_key(r.params), []).append(r)
    sets = []
    for key in sorted(by_key, key=lambda k: _set_order(dict(k))):
        kept = {}
        for r in by_key[key]:
            seed = r.params["run.seed"]
            if seed in kept:
                skipped.append({"path": r.path, "reason": f"duplicate: seed {seed} of this parameter set is "
                                                          f"{kept[seed].path} (the same sample)"})
            else:
                kept[seed] = r
        sets.append(Set("", dict(key), [kept[k] for k in sorted(kept, key=_order)]))
    width = max(2, len(str(len(sets))))
    for i, s in enumerate(sets, 1):
        s.id = f"S{i:0{width}d}"
    return sets, skipped


# ---------------------------------------------------------------- families and fits

def _sig(x):
    return float(f"{x:.10g}")


def family_key(params, vary):
    """What a family of sets that differ only in ``vary`` (a PARAMS key) shares.

    For ``contact.k_n`` the parameters that follow k_n enter as the scale-free
    k_t/k_n, gamma_n/sqrt(k_n) and gamma_t/gamma_n (10 significant digits) and
    dt is left out.

    Returns
    -------
    tuple of (name, value) pairs, short names.
    """
    skip = {"run.seed", vary} | (set(FOLLOW_K_N) if vary == "contact.k_n" else set())
    key = [(SHORT[k], params[k]) for k in PARAMS if k not in skip]
    if vary == "contact.k_n":
        k, g_n, g_t = params["contact.k_n"], params["contact.gamma_n"], params["contact.gamma_t"]
        key += [("k_t/k_n", _sig(params["contact.k_t"] / k)), ("gamma_n/sqrt(k_n)", _sig(g_n / math.sqrt(k))),
                ("gamma_t/gamma_n", _sig(g_t / g_n) if g_n else g_t)]
    return tuple(key)


def families(sets, vary):
    """[(family dict, sets sorted by ``vary``)] in the order of the first set of each."""
    fam = {}
    for s in sets:
        fam.setdefault(family_key(s.params, vary), []).append(s)
    return [(dict(k), sorted(v, key=lambda s: s.params[vary])) for k, v in fam.items()]


def _fit_one(kind, fam, members):
    """The eq. 7 (kind 'eq7': z vs k_n) or eq. 9 ('eq9': phi_f vs phi_i) fit of one family."""
    xkey, q, fn = (("contact.k_n", "z", fits.fit_eq7) if kind == "eq7"
                   else ("pour.phi_i", "phi", fits.fit_eq9))
    stats = [s.stat(q) for s in members]
    x = [s.params[xkey] for s in members]
    e = {"family": fam, "sets": [s.id for s in members], SHORT[xkey]: x, q: [m for m, _, _ in stats],
         f"{q}_sem": [v if math.isfinite(v) else None for _, v, _ in stats],
         "n_seeds": [n for _, _, n in stats]}
    distinct = len(set(x))
    if distinct < 3:
        e.update(status="not fitted", reason=f"{distinct} distinct {SHORT[xkey]} (3 parameters need at least 3)")
        return e
    sem = np.array([v for _, v, _ in stats])
    weighted = bool(np.all(np.isfinite(sem) & (sem > 0)))
    if not weighted:
        e["note"] = ("unweighted, errors scaled by the residuals: sets "
                     + ", ".join(s.id for s, v in zip(members, sem) if not (math.isfinite(v) and v > 0))
                     + " have no standard error (a single seed, or identical values)")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = fn(x, e[q], sem if weighted else None)
    except (RuntimeError, ValueError, TypeError, np.linalg.LinAlgError) as err:
        e.update(status="failed", reason=f"{type(err).__name__}: {err}")
        return e
    e.update(status="fitted", **r)
    if not all(math.isfinite(r[f"{n}_err"]) for n in (("z_inf", "a", "alpha_n") if kind == "eq7" else "ABC")):
        e["note"] = (e.get("note", "") + "; " if "note" in e else "") + "parameter errors not determined"
    return e


def _alpha_check(e, members):
    """Eq. 8: alpha_n against 1 - alpha, alpha averaged over all runs of the family."""
    a, a_err, n = mean_sem([r.q["alpha"] for s in members for r in s.runs])
    chk = {"alpha": a, "alpha_err": a_err, "n_runs": n, "one_minus_alpha": 1.0 - a}
    if e.get("status") == "fitted" and math.isfinite(a):
        d = e["alpha_n"] - (1.0 - a)
        err = math.hypot(e["alpha_n_err"], a_err) if math.isfinite(a_err) else NAN
        chk.update(difference=d, difference_err=err, n_sigma=abs(d) / err if err > 0 else NAN)
    if e["family"]["mu"] == 0:
        chk["paper"] = {k: paper.EQ7_MU0[k] for k in ("z_inf", "z_inf_err", "alpha_n", "alpha_n_err", "a_tilde")}
        chk["paper"]["note"] = "eq. 8, alpha_n = 1 - alpha, holds for mu = 0 (physics.md 6.6)"
    else:
        chk["paper"] = {"alpha_n": paper.EQ7_FRICTIONAL_ALPHA_N,
                        "note": "mu > 0: z - z_inf ~ k_n^(-1/4), z_inf > 4; eq. 8 does not hold (physics.md 6.6)"}
    return chk


def make_fits(sets):
    """{'eq7': [...], 'eq9': [...]}: one entry per family with >= 2 values of k_n (phi_i)."""
    out = {"eq7": [], "eq9": []}
    for fam, members in families(sets, "contact.k_n"):
        if len({s.p("k_n") for s in members}) >= 2:
            e = _fit_one("eq7", fam, members)
            e["check_alpha_n"] = _alpha_check(e, members)
            out["eq7"].append(e)
    for fam, members in families(sets, "pour.phi_i"):
        if len({s.p("phi_i") for s in members}) >= 2:
            e = _fit_one("eq9", fam, members)
            e["z"] = [s.stat("z")[0] for s in members]
            e["z_sem"] = [v if math.isfinite(v) else None for _, v, _ in (s.stat("z") for s in members)]
            out["eq9"].append(e)
    return out


# ---------------------------------------------------------------- tables

def _cell(v):
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ""
    return str(v)


def write_csv(path, header, rows):
    """Rows as CSV (empty cell = not available), written atomically."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows([[_cell(v) for v in row] for row in rows])
    rundir.write_atomic(path, buf.getvalue())


RUN_COLUMNS = ("z", "z_no_rattlers", "rattler_fraction", "phi", "n_bulk", "alpha", "alpha_err",
               "mobilised_fraction", "z_halved", "phi_halved", "overlap_median", "overlap_max", "step")


def write_runs_csv(path, sets):
    """runs.csv: one row per run."""
    head = ["set", "path"] + [SHORT[k] for k in PARAMS] + ["converged", *RUN_COLUMNS, "n_warnings"]
    rows = [[s.id, r.path] + [r.params[k] for k in PARAMS] + [True] + [r.q[c] for c in RUN_COLUMNS]
            + [len(r.s.get("warnings") or [])] for s in sets for r in s.runs]
    write_csv(path, head, rows)


def write_sets_csv(path, sets):
    """sets.csv: one row per parameter set, mean and standard error over its seeds."""
    head = ["set"] + [SHORT[k] for k in PARAMS if k != "run.seed"] + ["n_seeds", "seeds"]
    for q in SET_QUANTITIES:
        head += [f"{q}_mean", f"{q}_sem"] + ([f"{q}_count"] if q in ("alpha", "mobilised_fraction") else [])
    rows = []
    for s in sets:
        row = [s.id] + [s.params[k] for k in PARAMS if k != "run.seed"] + [len(s.runs), " ".join(map(str, s.seeds))]
        for q in SET_QUANTITIES:
            m, e, n = s.stat(q)
            row += [m, e] + ([n] if q in ("alpha", "mobilised_fraction") else [])
        rows.append(row)
    write_csv(path, head, rows)


def _json_safe(o):
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, (np.floating, np.integer)):
        return _json_safe(o.item())
    if isinstance(o, dict):
        return {str(k): _json_safe(v) for k, v in o.items()}
    if isinstance(o, (list, tuple, np.ndarray)):
        return [_json_safe(v) for v in o]
    return o


def write_json(path, obj):
    rundir.write_atomic(path, json.dumps(_json_safe(obj), indent=1) + "\n")


# ---------------------------------------------------------------- comparison with the paper

def _size_note(s):
    N, L_x, L_y = s.p("N"), s.p("L_x"), s.p("L_y")
    if paper.is_paper_size(N, L_x, L_y):
        return ""
    return f"; N = {N}, {L_x:g}d x {L_y:g}d box (paper: {paper.REFERENCE['N']}, {paper.REFERENCE['L']:g}d)"


def _cond(s, alpha=False):
    base = f"mu = {s.p('mu'):g}, eps = {s.p('epsilon'):g}"
    if alpha:
        base += f", k_n = {_kn(s.p('k_n'))}, phi_i = {s.p('phi_i'):g}"
    return base + _size_note(s)


def _verdict(value, accept):
    if accept is None or not math.isfinite(value):
        return "n/a"
    return "within" if accept[0] <= value <= accept[1] else "outside"


def comparisons(sets, fit_res):
    """Rows of the README's comparison table (dicts: quantity, conditions, set, value, err, n_seeds,
    paper, paper_err, accept, verdict, source). Verdicts only for physics.md 7's acceptance list."""
    rows = []

    def add(quantity, cond, sid, value, err, n, p_value, p_err, accept, source, note=""):
        rows.append(dict(quantity=quantity, conditions=cond, set=sid, value=value, err=err, n_seeds=n,
                         paper=p_value, paper_err=p_err, accept=accept, verdict=_verdict(value, accept),
                         source=source, note=note))

    for p in paper.POINTS:
        for s in sets:
            ref = paper.is_reference(s.p("k_n"), s.p("phi_i"))
            if not (paper.applies(p, s.p("mu"), s.p("epsilon")) and (ref or p["quantity"] == "alpha")):
                continue
            m, e, n = s.stat(p["quantity"])
            if n:
                add(p["quantity"], _cond(s, p["quantity"] == "alpha"), s.id, m, e, n, p["value"], p["err"],
                    p["accept"], p["source"])
    ref = [s for s in sets if paper.is_reference(s.p("k_n"), s.p("phi_i"))]
    for fam, members in families(ref, "contact.mu"):
        if len(members) >= 3:
            for q in ("z", "phi"):
                add(f"{q}(mu) trend", f"eps = {fam['epsilon']:g}" + _fam_size(fam), " ".join(s.id for s in members),
                    _trend(members, q), None, None, "decreases monotonically, saturates for mu >= 1", None, None,
                    paper.SOURCE)
    for p in paper.SMALL_POINTS:
        for s in sets:
            if (paper.is_small_pile(s.p("N"), s.p("L_x"), s.p("L_y")) and paper.is_reference(s.p("k_n"), s.p("phi_i"))
                    and paper.applies(p, s.p("mu"), s.p("epsilon"))):
                m, e, n = s.stat(p["quantity"])
                add(p["quantity"], f"mu = {s.p('mu'):g}, eps = {s.p('epsilon'):g}; N = {s.p('N')}, "
                    f"{s.p('L_x'):g}d box vs 7.1 (N = 2000, 10d box)", s.id, m, e, n, p["value"],
                    None, None, p["source"], "one seed in 7.1; no acceptance range given")
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
    rises = [f"{a[0]:g} to {b[0]:g} by {_pm(b[1] - a[1], math.hypot(a[2], b[2]), 3)}"
             for a, b in zip(st, st[1:]) if b[1] > a[1]]
    return "decreasing at every step" if not rises else "rises from mu = " + "; ".join(rises)


def _fam_size(f):
    return "" if paper.is_paper_size(f["N"], f["L_x"], f["L_y"]) else f"; N = {f['N']}, {f['L_x']:g}d box"


# ---------------------------------------------------------------- figures

def _seeds(n):
    return f"{n} seed" + ("" if n == 1 else "s")


def _kn(k):
    """2e5-style text of a stiffness."""
    m, e = f"{k:.3e}".split("e")
    return f"{m.rstrip('0').rstrip('.')}e{int(e)}"


def _label(fam, varying, keys=("mu", "epsilon")):
    names = {"mu": "μ", "epsilon": "ε", "phi_i": "φ_i", "k_n": "k_n"}
    parts = [f"{names[k]} = {_kn(fam[k]) if k == 'k_n' else format(fam[k], 'g')}" for k in keys if k in fam]
    return ", ".join(parts + [f"{k} = {fam[k]}" for k in varying if k not in keys])


# follow epsilon and k_n: named in a label only when the families differ in nothing else
_QUIET = ("k_t", "gamma_n", "dt", "k_t/k_n", "gamma_n/sqrt(k_n)")


def _varying(dicts):
    """The keys whose values differ between the family dicts (what tells their curves apart)."""
    keys = [k for k in dicts[0]] if dicts else []
    vary = [k for k in keys if len({repr(d.get(k)) for d in dicts}) > 1]
    loud = [k for k in vary if k not in _QUIET]
    distinct = len({tuple(repr(d.get(k)) for k in loud) for d in dicts}) == len(dicts)
    return loud if distinct else vary


class Figures:
    """The paper's figures from the sets; each ``figN`` returns None when made, else why not."""

    def __init__(self, sets, fit_res, out):
        from . import plots
        self.plt, self.save = plots.plt, plots.save
        self.sets, self.fits, self.out = sets, fit_res, out
        self._tables, self.notes = {}, {}
        self.slice, self.slice_text = self._mu_slice()
        self.curves = families(self.slice, "contact.mu")
        self.per_mu = self._per_mu_curve()

    # ---- selection
    def _mu_slice(self):
        """Sets at the paper's k_n and phi_i when there are any, else at the most populated (k_n, phi_i)."""
        ref = [s for s in self.sets if paper.is_reference(s.p("k_n"), s.p("phi_i"))]
        if ref:
            return ref, f"k_n = {_kn(paper.REFERENCE['k_n'])}, φ_i ≈ {paper.REFERENCE['phi_i']:g}"
        if not self.sets:
            return [], ""
        c = Counter((s.p("k_n"), s.p("phi_i")) for s in self.sets)
        (k, phi), _ = max(c.items(), key=lambda kv: (kv[1], -kv[0][0]))
        return ([s for s in self.sets if (s.p("k_n"), s.p("phi_i")) == (k, phi)],
                f"k_n = {_kn(k)}, φ_i = {phi:g} (no runs at the paper's k_n = 2e5, φ_i ≈ 0.13)")

    def _per_mu_curve(self):
        """The mu-curve of Figs. 4-6 and 8: epsilon 0.88 (the paper's Fig. 4) when present, else the longest."""
        if not self.curves:
            return None
        pref = [c for c in self.curves if c[0]["epsilon"] == paper.PZ_EPSILON] or self.curves
        return max(pref, key=lambda c: len(c[1]))

    def _small(self, sets):
        return any(paper.is_small_pile(s.p("N"), s.p("L_x"), s.p("L_y")) for s in sets)

    # ---- per-run tables
    def table(self, run, name):
        """Columns of RUN/analysis/<name>.csv as float arrays, None when missing or unreadable."""
        key = (run.path, name)
        if key not in self._tables:
            path = os.path.join(run.path, "analysis", f"{name}.csv")
            try:
                with open(path, newline="") as fh:
                    rows = list(csv.reader(fh))
                self._tables[key] = {h: np.array([float(r[i]) if r[i] else NAN for r in rows[1:]])
                                     for i, h in enumerate(rows[0])}
            except (OSError, ValueError, IndexError):
                self._tables[key] = None
        return self._tables[key]

    def mean_curve(self, s, name, ycol, bins):
        """Mean and standard error over the set's runs of column ``ycol`` of ``name``.csv.

        ``bins`` = (lower, upper) bin-edge columns. Runs without the columns,
        or whose bins differ from the first run's (over their common length),
        are left out (listed in ``notes``).

        Returns
        -------
        None, or (lower edges (nb,), upper edges (nb,), mean (nb,), sem (nb,)
        (nan with one run), runs used)
        """
        lo, hi = bins
        got = [(r, t) for r, t in ((r, self.table(r, name)) for r in s.runs)
               if t is not None and {ycol, lo, hi} <= set(t)]
        if not got:
            return None
        nb = min(len(t[lo]) for _, t in got)
        x0 = got[0][1][lo][:nb]
        use = [(r, t) for r, t in got if np.array_equal(t[lo][:nb], x0)]
        left = [r.path for r in s.runs if r.path not in {u.path for u, _ in use}]
        if left:
            self.notes.setdefault(name, []).append(f"{s.id}: left out (no {ycol} in {name}.csv, or other bins): "
                                                   f"{', '.join(left)}")
        Y = np.array([t[ycol][:nb] for _, t in use])
        sem = Y.std(0, ddof=1) / np.sqrt(len(use)) if len(use) >= 2 else np.full(nb, NAN)
        return x0, use[0][1][hi][:nb], Y.mean(0), sem, len(use)

    # ---- drawing helpers
    def _points(self, ax, x, m, e, label, color=None, marker="o", ls="-"):
        """Filled markers joined by a line, error bars where there is a standard error."""
        x, m, e = (np.asarray(v, float) for v in (x, m, e))
        line, = ax.plot(x, m, marker=marker, ls=ls, color=color, ms=5, lw=1, label=label)
        ok = np.isfinite(e)
        if ok.any():
            ax.errorbar(x[ok], m[ok], yerr=e[ok], fmt="none", ecolor=line.get_color(), capsize=3, lw=1)
        return line, bool((~ok).any())

    def _paper_point(self, ax, x, y, err, label, color="k", marker="s"):
        ax.errorbar([x], [y], yerr=None if err is None else [err], fmt=marker, mfc="none", mec=color, ecolor=color,
                    ms=9, mew=1.5, capsize=3, label=label)

    def _one_seed_note(self, ax, any_single):
        if any_single:
            ax.text(0.01, 0.01, "points without error bars: a single seed", transform=ax.transAxes, fontsize=7,
                    color="grey", va="bottom")

    def _legend(self, ax):
        h, lab = ax.get_legend_handles_labels()
        seen = {}
        for hh, ll in zip(h, lab):
            seen.setdefault(ll, hh)
        ax.legend(seen.values(), seen.keys(), fontsize=7)

    def _file(self, name):
        return os.path.join(self.out, name)

    # ---- Figs. 2 and 3
    def _vs_mu(self, q, fname, ylabel, title):
        if not self.curves:
            return "no parameter sets"
        plt = self.plt
        fig, ax = plt.subplots(figsize=(6, 4.2))
        varying = _varying([f for f, _ in self.curves])
        single = False
        for fam, members in self.curves:
            st = [s.stat(q) for s in members]
            _, one = self._points(ax, [s.p("mu") for s in members], [v[0] for v in st], [v[1] for v in st],
                                  _label(fam, varying, ("epsilon",)))
            single |= one
        mus = {s.p("mu") for _, m in self.curves for s in m}
        eps = {f["epsilon"] for f, _ in self.curves}
        for p in paper.POINTS:
            if p["quantity"] == q and p["mu"] is not None and (p["epsilon"] is None or eps & set(p["epsilon"])):
                self._paper_point(ax, p["mu"], p["value"], p["err"], "paper (N = 20000, 20d box)")
        for p in paper.FLOW_ARREST:
            if p["quantity"] == q:
                self._paper_point(ax, p["mu"], p["value"], None, "paper: flow arrest (other protocol)", "grey", "D")
        if self._small(self.slice):
            for p in paper.SMALL_POINTS:
                if p["quantity"] == q:
                    self._paper_point(ax, p["mu"], p["value"], None, "7.1 reference (N = 2000, 10d box)",
                                      "tab:red", "^")
        pos = sorted(m for m in mus | {0.5} if m > 0)
        ax.set_xscale("symlog", linthresh=pos[0], linscale=0.5)
        ticks = sorted(mus | {0.0, 0.5})
        ax.set_xticks(ticks, [f"{m:g}" for m in ticks], fontsize=7)
        ax.minorticks_off()
        ax.set(xlabel="μ", ylabel=ylabel, title=f"{title}, {self.slice_text}")
        self._one_seed_note(ax, single)
        self._legend(ax)
        self.save(fig, self._file(fname))

    def fig2(self):
        """z against mu, one curve per epsilon."""
        return self._vs_mu("z", "fig2_z_vs_mu.png", "bulk z", "Fig. 2: coordination")

    def fig3(self):
        """phi_f against mu, one curve per epsilon."""
        return self._vs_mu("phi", "fig3_phi_vs_mu.png", "bulk φ_f", "Fig. 3: packing fraction")

    # ---- Figs. 4, 5, 6, 8: one curve per mu
    def _mu_sets(self):
        fam, members = self.per_mu
        return fam, members, self.plt.cm.viridis(np.linspace(0, 0.9, max(len(members), 1)))

    def fig4(self):
        """P(z) per mu at epsilon 0.88 (when present)."""
        if self.per_mu is None:
            return "no parameter sets"
        fam, members, colors = self._mu_sets()
        fig, ax = self.plt.subplots(figsize=(6, 4.2))
        single = False
        for s, c in zip(members, colors):
            P = [r.s.get("P_z") for r in s.runs]
            P = np.array([p for p in P if isinstance(p, list) and len(p) == 13 and None not in p], float)
            if not len(P):
                self.notes.setdefault("summary.json", []).append(f"{s.id}: no P_z in the summaries")
                continue
            sem = P.std(0, ddof=1) / np.sqrt(len(P)) if len(P) >= 2 else np.full(P.shape[1], NAN)
            _, one = self._points(ax, np.arange(P.shape[1]), P.mean(0), sem, f"μ = {s.p('mu'):g} ({_seeds(len(P))})", c)
            single |= one
        if not ax.lines:
            self.plt.close(fig)
            return "no P_z in the summaries"
        if self._small(members):
            for mu, (n, pk) in paper.SMALL_PZ_PEAK.items():
                if mu in {s.p("mu") for s in members}:
                    self._paper_point(ax, n, pk, None, f"7.1 reference peak, μ = {mu:g} (N = 2000, 10d box)",
                                      "tab:red", "^")
        ax.set(xlabel="contacts n (last: n ≥ 12)", ylabel="P(n)", xticks=range(0, 13),
               title=f"Fig. 4: P(z), ε = {fam['epsilon']:g}, {self.slice_text}")
        self._one_seed_note(ax, single)
        self._legend(ax)
        self.save(fig, self._file("fig4_P_z.png"))

    def fig5(self):
        """g(r) per mu, mean over seeds of g per bin, curves shifted by 1."""
        if self.per_mu is None:
            return "no parameter sets"
        fam, members, colors = self._mu_sets()
        fig, ax = self.plt.subplots(figsize=(6, 5))
        drawn, top = 0, 1.0
        for s, c in zip(members, colors):
            got = self.mean_curve(s, "gofr", "g", ("r_lo", "r_hi"))
            if got is None:
                continue
            r_lo, r_hi, g, _, n = got
            r = 0.5 * (r_lo + r_hi)
            ax.plot(r, g + drawn, color=c, lw=0.8, label=f"μ = {s.p('mu'):g} ({_seeds(n)}) + {drawn}")
            top = max(top, float(np.nanmax(g[r > 1.05], initial=1.0)) + drawn)
            drawn += 1
        if not drawn:
            self.plt.close(fig)
            return "no gofr.csv in the runs"
        ax.set(xlabel="r / d", ylabel="g(r) + shift", xlim=(0.8, None), ylim=(0, top * 1.15),
               title=f"Fig. 5: g(r), ε = {fam['epsilon']:g}, mean over seeds (first peak cut)")
        self._legend(ax)
        self.save(fig, self._file("fig5_gofr.png"))

    def fig6(self):
        """Near-contact g against xi = r/d - 1, log-log, with the paper's slope -0.52."""
        if self.per_mu is None:
            return "no parameter sets"
        fam, members, colors = self._mu_sets()
        fig, ax = self.plt.subplots(figsize=(5.5, 4.5))
        anchor, window = [], []
        for s, c in zip(members, colors):
            got = self.mean_curve(s, "gofr_near", "g", ("xi_lo", "xi_hi"))
            if got is None:
                continue
            xi_lo, xi_hi, g, _, n = got
            xi = np.sqrt(xi_lo * xi_hi)
            ok = g > 0
            a, ae, na = s.stat("alpha")
            lab = f"μ = {s.p('mu'):g}: α = " + (f"{a:.3f}" if na else "n/a") + (f" ± {ae:.3f}" if na >= 2 else "")
            ax.loglog(xi[ok], g[ok], "o-", color=c, ms=3, lw=0.7, label=lab)
            fw = [(r.s.get("alpha_fit") or {}) for r in s.runs]
            lo, hi = (np.nanmedian([_num(f.get(k)) for f in fw]) for k in ("xi_lo", "xi_hi"))
            if math.isfinite(lo) and math.isfinite(hi):
                w = ok & (xi >= lo) & (xi <= hi)
                anchor += list(np.log(g[w]) + paper.ALPHA * np.log(xi[w]))
                window += [lo, hi]
        if not ax.lines:
            self.plt.close(fig)
            return "no gofr_near.csv in the runs"
        if anchor:
            xs = np.array([min(window), max(window)])
            ax.loglog(xs, np.exp(np.mean(anchor)) * xs ** -paper.ALPHA, "k--", lw=1.5,
                      label=f"paper: slope −{paper.ALPHA} (α = {paper.ALPHA} ± {paper.ALPHA_ERR}), through the data")
        ax.set(xlabel="ξ = r/d − 1", ylabel="g", title=f"Fig. 6: near contact, ε = {fam['epsilon']:g}")
        self._legend(ax)
        self.save(fig, self._file("fig6_gofr_near.png"))

    def fig8(self):
        """P(zeta) per frictional mu (and F_t/F_n for mu >= 1 when present)."""
        if self.per_mu is None:
            return "no parameter sets"
        fam, members, colors = self._mu_sets()
        zb = ("zeta_lo", "zeta_hi")
        got = [(s, c, self.mean_curve(s, "zeta", "P", zb)) for s, c in zip(members, colors) if s.p("mu") > 0]
        got = [g for g in got if g[2] is not None]
        if not got:
            return "no zeta.csv in the runs (mu = 0 has none)"
        ratio = [(s, c, self.mean_curve(s, "zeta", "P_ratio", zb)) for s, c, _ in got if s.p("mu") >= 1]
        ratio = [g for g in ratio if g[2] is not None]
        fig, axes = self.plt.subplots(1, 2 if ratio else 1, figsize=(11 if ratio else 6, 4.2), squeeze=False)
        for s, c, (lo, hi, P, e, n) in got:
            x = 0.5 * (lo + hi)
            m = s.stat("mobilised_fraction")[0]
            mob = f", {100 * m:.1f}% fully mobilised" if math.isfinite(m) else ""
            axes[0, 0].plot(x, P, ".-", color=c, lw=1, label=f"μ = {s.p('mu'):g} ({_seeds(n)}){mob}")
            if n >= 2:
                axes[0, 0].fill_between(x, P - e, P + e, color=c, alpha=0.2, lw=0)
        axes[0, 0].set(xlabel="ζ = |F_t| / μF_n", ylabel="P / max P (mean over seeds)", ylim=(0, 1.1),
                       title=f"Fig. 8: P(ζ), ε = {fam['epsilon']:g} (paper: almost all ζ < 1)")
        self._legend(axes[0, 0])
        for s, c, (lo, hi, P, e, n) in ratio:
            axes[0, 1].plot(0.5 * (lo + hi), P, ".-", color=c, lw=1, label=f"μ = {s.p('mu'):g} ({_seeds(n)})")
        if ratio:
            axes[0, 1].set(xlabel="|F_t| / F_n", ylabel="P / max P", ylim=(0, 1.1),
                           title="μ ≥ 1 (paper: these collapse)")
            self._legend(axes[0, 1])
        self.save(fig, self._file("fig8_P_zeta.png"))

    # ---- Fig. 7
    def fig7(self):
        """z against k_n with the eq. 7 fit per family, and z - z_inf log-log."""
        ent = self.fits["eq7"]
        if not ent:
            return "no family of sets with >= 2 values of k_n"
        plt = self.plt
        fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.5))
        varying = _varying([e["family"] for e in ent])
        ks = [k for e in ent for k in e["k_n"]] + list(paper.EQ7_MU0_POINTS)
        kk = np.geomspace(min(ks), max(ks), 100)
        single = False
        for e in ent:
            zs = np.array([v if v is not None else NAN for v in e["z_sem"]])
            line, one = self._points(ax, e["k_n"], e["z"], zs, _label(e["family"], varying), ls="none")
            single |= one
            if e["status"] != "fitted":
                continue
            c = line.get_color()
            ax.plot(kk, fits.eq7(kk, e["z_inf"], e["a"], e["alpha_n"]), "-", color=c, lw=1,
                    label=f"eq. 7: z∞ = {_pm(e['z_inf'], e['z_inf_err'], 3)}, α_n = {_pm(e['alpha_n'], e['alpha_n_err'], 2)}")
            dz = np.array(e["z"]) - e["z_inf"]
            ok = dz > 0
            bx.loglog(np.array(e["k_n"])[ok], dz[ok], "o", color=c, ms=5, label=_label(e["family"], varying))
            if np.any(ok & np.isfinite(zs)):
                bx.errorbar(np.array(e["k_n"])[ok & np.isfinite(zs)], dz[ok & np.isfinite(zs)],
                            yerr=zs[ok & np.isfinite(zs)], fmt="none", ecolor=c, capsize=3)
            bx.loglog(kk, e["a"] * (kk / fits.K_REF) ** -e["alpha_n"], "-", color=c, lw=1)
            if e["family"]["mu"] > 0 and ok.any():
                k0, d0 = np.array(e["k_n"])[ok][0], dz[ok][0]
                bx.loglog(kk, d0 * (kk / k0) ** -paper.EQ7_FRICTIONAL_ALPHA_N, ":", color=c, lw=1,
                          label="paper: ∝ k_n^(−1/4) (μ > 0)")
        P = paper.EQ7_MU0
        pk = np.array(sorted(paper.EQ7_MU0_POINTS))
        pz = np.array([paper.EQ7_MU0_POINTS[k] for k in pk])
        lab = f"paper μ = 0: z∞ = {P['z_inf']} ± {P['z_inf_err']}, α_n = {P['alpha_n']}"
        ax.plot(kk, paper.eq7_mu0(kk), "k--", lw=1, label=lab)
        ax.plot(pk, pz, "ks", mfc="none", ms=8, label="paper μ = 0 (2e5 measured, others derived)")
        bx.loglog(kk, paper.eq7_mu0(kk) - P["z_inf"], "k--", lw=1, label="paper μ = 0")
        bx.loglog(pk, pz - P["z_inf"], "ks", mfc="none", ms=8)
        ax.set(xscale="log", xlabel="k_n [mg/d]", ylabel="bulk z", title="Fig. 7: z(k_n)")
        bx.set(xlabel="k_n [mg/d]", ylabel="z − z∞ (fitted z∞; paper: its own)", title="approach to z∞")
        self._one_seed_note(ax, single)
        self._legend(ax)
        self._legend(bx)
        self.save(fig, self._file("fig7_z_vs_kn.png"))

    # ---- Fig. 9
    def fig9(self):
        """phi_f and z against phi_i with the eq. 9 fit per family."""
        ent = self.fits["eq9"]
        if not ent:
            return "no family of sets with >= 2 values of phi_i"
        fig, (ax, bx) = self.plt.subplots(1, 2, figsize=(11, 4.2))
        varying = _varying([e["family"] for e in ent])
        xx = np.linspace(min(min(e["phi_i"]) for e in ent + [{"phi_i": list(paper.EQ9_POINTS)}]),
                         max(max(e["phi_i"]) for e in ent + [{"phi_i": list(paper.EQ9_POINTS)}]), 100)
        single = False
        for e in ent:
            sem = [v if v is not None else NAN for v in e["phi_sem"]]
            line, one = self._points(ax, e["phi_i"], e["phi"], sem, _label(e["family"], varying), ls="none")
            single |= one
            if e["status"] == "fitted":
                ax.plot(xx, fits.eq9(xx, e["A"], e["B"], e["C"]), "-", color=line.get_color(), lw=1,
                        label=f"eq. 9: A = {e['A']:.4f}, B = {e['B']:.4f}, C = {e['C']:.2f}")
            zs = [v if v is not None else NAN for v in e["z_sem"]]
            _, one = self._points(bx, e["phi_i"], e["z"], zs, _label(e["family"], varying), line.get_color())
            single |= one
        E = paper.EQ9
        ax.plot(xx, paper.eq9_paper(xx), "k--", lw=1,
                label=f"paper eq. 9 (μ = {E['mu']:g}, ε = {E['epsilon']:g}): {E['A']} + {E['B']} exp(−{E['C']} φ_i)")
        ax.plot(list(paper.EQ9_POINTS), list(paper.EQ9_POINTS.values()), "ks", mfc="none", ms=8, label="paper")
        ax.set(xlabel="φ_i", ylabel="bulk φ_f", title="Fig. 9: φ_f(φ_i)")
        bx.set(xlabel="φ_i", ylabel="bulk z", title="z(φ_i) (paper: decreases with φ_i)")
        self._one_seed_note(ax, single)
        self._legend(ax)
        self._legend(bx)
        self.save(fig, self._file("fig9_phi_i.png"))


FIGURES = (  # name, file, what it shows
    ("fig2", "fig2_z_vs_mu.png", "bulk z against mu, one curve per epsilon, paper values as open markers"),
    ("fig3", "fig3_phi_vs_mu.png", "bulk phi_f against mu, one curve per epsilon, paper values as open markers"),
    ("fig4", "fig4_P_z.png", "P(z) (mean over seeds) per mu at epsilon 0.88 when present"),
    ("fig5", "fig5_gofr.png", "g(r) (mean over seeds per bin) per mu, curves shifted by 1"),
    ("fig6", "fig6_gofr_near.png", "near-contact g against xi = r/d - 1, log-log, per mu, paper slope -0.52"),
    ("fig7", "fig7_z_vs_kn.png", "z against k_n with the eq. 7 fit per (mu, epsilon) family; z - z_inf log-log"),
    ("fig8", "fig8_P_zeta.png", "P(zeta) (mean over seeds) per frictional mu; F_t/F_n for mu >= 1"),
    ("fig9", "fig9_phi_i.png", "phi_f and z against phi_i with the eq. 9 fit, paper eq. 9 dashed"),
)


def make_figures(sets, fit_res, out, log=print):
    """Every figure the sets have data for: {name: {file, shows, made, reason, notes}}."""
    figs = Figures(sets, fit_res, out)
    res = {}
    for name, fname, shows in FIGURES:
        why = getattr(figs, name)()
        res[name] = {"file": fname, "shows": shows, "made": why is None, "reason": why}
        log(f"collect: {name}: " + (f"wrote {fname}" if why is None else f"not made ({why})"))
    for name, notes in figs.notes.items():
        for n in notes:
            log(f"collect: note: {name}: {n}")
    res["_notes"] = figs.notes
    res["_slice"] = figs.slice_text
    return res


# ---------------------------------------------------------------- README

def _digits(e, base):
    if not (isinstance(e, float) and math.isfinite(e) and e > 0):
        return base
    return min(max(base, 1 - math.floor(math.log10(e))), 8)


def _pm(m, e=NAN, base=3, n=None):
    """'m ± e' (digits from e), 'm (1 seed)' without an error, '—' without a value."""
    if not isinstance(m, (int, float)) or not math.isfinite(m):
        return "—" if not isinstance(m, str) else m
    e = NAN if e is None else e
    d = _digits(e, base)
    if math.isfinite(e):
        return f"{m:.{d}f} ± {e:.{d}f}"
    return f"{m:.{d}f}" + (" (1 seed)" if n == 1 else "")


_BASE = {"z": 3, "alpha": 3, "z_inf": 3, "alpha_n": 3}   # decimals shown at least, per quantity


def _quoted(v, err=None):
    """A paper value as quoted (no digits added)."""
    return v if isinstance(v, str) else f"{v!r}" + ("" if err is None else f" ± {err!r}")


def _table(head, rows):
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    out += ["| " + " | ".join(str(c).replace("|", "/") for c in r) + " |" for r in rows]
    return "\n".join(out)


def _fam_text(f, drop=()):
    keys = [k for k in ("mu", "epsilon", "k_n", "phi_i", "N", "L_x", "model", "gamma_t/gamma_n", "gamma_t", "K0")
            if k in f and k not in drop]
    return ", ".join(f"{k} = {_kn(f[k]) if k == 'k_n' else f[k]}" for k in keys)


def write_readme(path, info, sets, fit_res, rows, figs, skipped):
    """OUT/README.md: sets, seeds, numbers with errors next to the paper's, fits, figures, skipped runs."""
    L = ["# mpdem collect: the paper's tables and figures", "",
         f"Made by `mpdem collect` on {info['date']} from {info['n_runs']} run(s) in {info['n_sets']} parameter "
         f"set(s); {len(skipped)} skipped (below). Inputs: {', '.join(f'`{t}`' for t in info['inputs'])}.", "",
         "`±` is the standard error of the mean over the seeds (runs) of a set; a set with one seed has no error "
         "bar and is marked `(1 seed)`. Paper: " + paper.SOURCE + ". Acceptance ranges: physics.md 7, "
         "\"Suggested acceptance\" (a choice of this project, not the paper's).", "",
         "## Parameter sets", "",
         "Every run parameter but the seed is equal within a set (`sets.csv` has them all; runs in `runs.csv`).", ""]
    head = ["set", "μ", "ε", "k_n", "φ_i", "N", "box", "seeds", "z", "z (no rattlers)", "φ_f", "α", "rattlers"]
    L += [_table(head, [[s.id, f"{s.p('mu'):g}", f"{s.p('epsilon'):g}", _kn(s.p("k_n")), f"{s.p('phi_i'):g}",
                         s.p("N"), f"{s.p('L_x'):g}×{s.p('L_y'):g}", " ".join(map(str, s.seeds)),
                         _pm(*s.stat("z")[:2], 3, len(s.runs)), _pm(*s.stat("z_no_rattlers")[:2], 3, len(s.runs)),
                         _pm(*s.stat("phi")[:2], 4, len(s.runs)), _pm(*s.stat("alpha")[:2], 3, s.stat("alpha")[2]),
                         _pm(*s.stat("rattler_fraction")[:2], 3, len(s.runs))] for s in sets]), ""]
    L += ["## Comparison with the paper", ""]
    if rows:
        L += [_table(["quantity", "conditions", "set(s)", "this work", "paper", "acceptance", "verdict"],
                     [[r["quantity"], r["conditions"], r["set"],
                       _pm(r["value"], r["err"], _BASE.get(r["quantity"], 4), r["n_seeds"]),
                       _quoted(r["paper"], r["paper_err"]),
                       "—" if r["accept"] is None else f"{r['accept'][0]!r} … {r['accept'][1]!r}",
                       r["verdict"] + (f" ({r['note']})" if r["note"] else "")] for r in rows]), "",
              "Paper values without an error were quoted without one. 7.1 rows: the reference implementation at "
              "development size (physics.md 7.1), not the paper.", ""]
    else:
        L += ["No set matches the paper's conditions (k_n = 2e5, φ_i ≈ 0.13, the μ and ε of physics.md 7).", ""]
    L += ["## Fits (`fits.json`)", "", "Eq. 7, z(k_n) = z∞ + ã k_n^(−α_n), per family of sets differing in k_n "
          "(fit weights 1/σ², σ the standard error over seeds):", ""]
    L += [_fit_lines(e, "eq7") for e in fit_res["eq7"]] or ["- no family with ≥ 2 values of k_n"]
    L += ["", "Eq. 9, φ_f = A + B exp(−C φ_i), per family of sets differing in φ_i:", ""]
    L += [_fit_lines(e, "eq9") for e in fit_res["eq9"]] or ["- no family with ≥ 2 values of φ_i"]
    L += ["", "## Figures", "", f"Figs. 2-6 and 8 use the sets at {figs['_slice']}.", ""]
    for name, fname, shows in FIGURES:
        f = figs[name]
        L.append(f"- `{fname}`: {shows}. " + ("Made." if f["made"] else f"**Not made**: {f['reason']}."))
    for name, notes in figs["_notes"].items():
        L += [f"  - note ({name}): {n}" for n in notes]
    L += ["", "## Skipped", ""]
    L += [_table(["run", "reason"], [[f"`{s['path']}`", s["reason"]] for s in skipped])] if skipped else ["None."]
    rundir.write_atomic(path, "\n".join(L) + "\n")


def _fit_lines(e, kind):
    xs = e["k_n"] if kind == "eq7" else e["phi_i"]
    pts = ", ".join((_kn(x) if kind == "eq7" else f"{x:g}") + f" ({n})" for x, n in zip(xs, e["n_seeds"]))
    head = f"- {_fam_text(e['family'], ('k_n',) if kind == 'eq7' else ('phi_i',))} [sets {' '.join(e['sets'])}]; " \
           f"points (seeds): {pts}: "
    if e["status"] != "fitted":
        return head + f"**{e['status']}**: {e['reason']}"
    if kind == "eq7":
        c = e["check_alpha_n"]
        s = (f"z∞ = {_pm(e['z_inf'], e['z_inf_err'], 3)}, ã = {_pm(e['a_tilde'], e['a_tilde_err'], 1)}, "
             f"α_n = {_pm(e['alpha_n'], e['alpha_n_err'], 3)}; α = {_pm(c['alpha'], c['alpha_err'], 3)} over "
             f"{c['n_runs']} runs, so 1 − α = {_pm(c['one_minus_alpha'], c['alpha_err'], 3)}")
    else:
        s = f"A = {_pm(e['A'], e['A_err'], 4)}, B = {_pm(e['B'], e['B_err'], 4)}, C = {_pm(e['C'], e['C_err'], 2)}"
    s += f"; χ² = {e['chi2']:.3g} for {e['dof']} degrees of freedom" + (" (weighted)" if e["weighted"] else "")
    return head + s + (f". Note: {e['note']}" if e.get("note") else "")


# ---------------------------------------------------------------- the command

def collect(runs, out, analyze_missing=True, log=print):
    """``mpdem collect RUN_DIR ... --out OUT``: the paper's tables and figures from many runs.

    Parameters
    ----------
    runs : run directories, or directories holding them (searched recursively)
    out : output directory (created); None gives ./paper
    analyze_missing : run ``mpdem analyze`` (no plots) on runs without an
        up-to-date analysis/summary.json; False skips them with a warning
    log : one-line messages

    Returns
    -------
    dict (also OUT/collect.json): inputs, runs used, sets, skipped runs with
    reasons, figures made and not made, file names.

    Raises
    ------
    AnalysisError when no usable run remains.
    """
    out = out or "paper"
    paths, skipped = find_runs(runs)
    log(f"collect: {len(paths)} run director{'y' if len(paths) == 1 else 'ies'} found")
    loaded = []
    for p in paths:
        run, why = load_run(p, analyze_missing, log)
        if run is None:
            skipped.append({"path": p, "reason": why})
        else:
            loaded.append(run)
    sets, dup = group(loaded)
    skipped += dup
    for s in skipped:
        log(f"collect: skipped {s['path']}: {s['reason']}")
    if not sets:
        why = "; ".join(f"{s['path']}: {s['reason']}" for s in skipped[:5]) + (" ..." if len(skipped) > 5 else "")
        raise AnalysisError(f"collect: no usable runs in {' '.join(map(str, runs))}"
                            + (f" ({why})" if why else ""))
    n_runs = sum(len(s.runs) for s in sets)
    log(f"collect: {n_runs} usable run(s) in {len(sets)} parameter set(s), {len(skipped)} skipped")
    os.makedirs(out, exist_ok=True)
    write_runs_csv(os.path.join(out, "runs.csv"), sets)
    write_sets_csv(os.path.join(out, "sets.csv"), sets)
    fit_res = make_fits(sets)
    write_json(os.path.join(out, "fits.json"), {"source": paper.SOURCE, **fit_res})
    for kind in ("eq7", "eq9"):
        for e in fit_res[kind]:
            log(f"collect: {kind} [{' '.join(e['sets'])}]: {e['status']}" + (f" ({e['reason']})" if "reason" in e else ""))
    figs = make_figures(sets, fit_res, out, log)
    rows = comparisons(sets, fit_res)
    info = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "inputs": [str(r) for r in runs], "out": out,
            "n_runs": n_runs, "n_sets": len(sets)}
    write_readme(os.path.join(out, "README.md"), info, sets, fit_res, rows, figs, skipped)
    res = {**info, "sets": {s.id: {"params": {SHORT[k]: v for k, v in s.params.items()}, "seeds": s.seeds,
                                   "runs": [r.path for r in s.runs]} for s in sets},
           "skipped": skipped, "comparisons": rows,
           "figures": {k: v for k, v in figs.items() if not k.startswith("_")}, "figure_notes": figs["_notes"],
           "files": ["runs.csv", "sets.csv", "fits.json", "README.md", "collect.json"]
           + [f["file"] for k, f in figs.items() if not k.startswith("_") and f["made"]]}
    write_json(os.path.join(out, "collect.json"), res)
    made = [k for k, f in res["figures"].items() if f["made"]]
    log(f"collect: wrote {out}/ (runs.csv, sets.csv, fits.json, README.md, collect.json; "
        f"figures {', '.join(made) or 'none'})")
    return res
