"""``mpdem collect``: many analysed runs -> the paper's tables and figures.

::

    OUT/runs.csv      one row per usable run (parameters, z, z_nr, phi_f, alpha, ...)
    OUT/sets.csv      one row per parameter set: mean and standard error over its seeds
    OUT/fits.json     eq. 7 per family of k_n, eq. 9 per family of phi_i (or why not)
    OUT/fig*.png      Figs. 2-9 of the paper, its values drawn as open markers / dashes
    OUT/README.md     the paper's claims judged by one rule (``claims``, ``sources``, ``claimtable``,
                      ``verdict``), the sets and seeds, a section per figure and equation
    OUT/collect.json  the runs used and skipped, the figures made and not made, and why

This module finds and loads the runs (analysing those that need it), groups
them into parameter sets, fits eqs. 7 and 9 and writes the CSV and JSON
tables; the figures are drawn by ``figures``, the comparison with the paper
and README.md by ``comparison`` (``AnalysedRun``, ``Set`` and families: ``runs``).

A parameter set is every run parameter of ``config.PARAM_KEYS`` except the
seed, compared exactly, and every other physics key of the run's config
(``config.PHYSICS_KEYS``, the summary's ``physics``) equal as well. Error
bars are the standard error of the mean over the runs (seeds) of a set; a
set with one seed has none (empty in the tables).
Empty CSV cells mean "not available".
"""
from __future__ import annotations

import json
import math
import os
import re
import time
import warnings

import numpy as np

from ..errors import MpdemError
from ..io import checkpoint, packing, rundir
from ..config import PARAM_KEYS
from ..analysis import fits
from . import claims, claimtable, contrasts, depth, ladder, paper, pooled, ratio, samples, sources
from .comparison import comparisons, write_readme
from .figures import make_figures
from ..analysis.report import MEASURES_VERSION, PACKING, SUMMARY, AnalysisError
from .runs import NAN, SHORT, AnalysedRun, Set, families, mean_sem

SET_QUANTITIES = ("z", "z_no_rattlers", "phi", "alpha", "rattler_fraction", "mobilised_fraction",
                  "z_halved", "phi_halved", "overlap_median", "step", "z_backbone", "z_iso", "crystal_fraction")


# ---------------------------------------------------------------- parameter sets

def set_key(params):
    """The exact, tolerance-free key of a parameter set: every parameter but the seed."""
    return tuple((k, params.get(k)) for k in PARAM_KEYS if k != "run.seed")


def _order(v):
    return (0, v, "") if isinstance(v, (int, float)) and not isinstance(v, bool) else (1, 0, str(v))


SORT = ("contact.model", "pour.N", "box.L_x", "box.L_y", "pour.K0", "contact.gamma_t", "contact.epsilon",
        "pour.phi_i", "contact.k_n", "contact.mu")


def _set_order(params):
    rest = [k for k in PARAM_KEYS if k not in SORT]
    return tuple(_order(params.get(k)) for k in SORT + tuple(rest))


# ---------------------------------------------------------------- finding and loading runs

def _is_run(d):
    return any(os.path.exists(os.path.join(d, *p)) for p in
               (("final.h5",), (PACKING,), ("analysis", SUMMARY), ("config.toml",)))


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


def _analyse(path, why, log, settings=None):
    """``mpdem analyze`` of a run (no plots); None, or the reason it failed.

    ``settings``: the ``analysis.*`` values of an earlier analysis, kept.
    """
    from ..analysis import report
    log(f"collect: analysing {path} ({why})")
    sets = [f"{k}={v!r}" for k, v in (settings or {}).items()]
    try:
        report.analyze(path, sets=sets, plots=False,
                       log=lambda m: [log(f"  {ln}") for ln in str(m).splitlines()])
    except Exception as e:  # one bad run must not stop the others: it is reported as skipped
        return f"analysis failed: {type(e).__name__}: {e}"
    return None


def _stale(final, summ):
    """Why the analysis ``summ`` must be made again, or None: written by earlier measures
    (``report.MEASURES_VERSION``), or not of the state ``final`` (a restart went on after it).

    Decided by what the files say, not by their times: a clone's checkout gives every
    file the time it was written out, in no particular order.
    """
    if not os.path.exists(final):
        return None
    try:
        with open(summ) as fh:
            old = json.load(fh)
        done, version = old.get("step"), int(old.get("measures_version") or 0)
    except (OSError, ValueError, TypeError, AttributeError):
        return None             # an unreadable summary is reported where it is read, not here
    if version < MEASURES_VERSION:
        return f"analysis/summary.json holds measures version {version}, this mpdem's is {MEASURES_VERSION}"
    try:
        attrs = packing.read_attrs(final) if packing.is_packing(final) else checkpoint.read_attrs(final)
    except (OSError, MpdemError):
        return None
    step = attrs.get("step")
    if step is None or done is None:
        return None
    name = os.path.basename(final)
    if int(step) != int(done):
        return f"{name} is at step {int(step)}, analysis/summary.json at step {int(done)}"
    # the same step, another state (a run made again with --force that stopped at that step)
    for key in ("time", "n"):
        if key in attrs and key in old and float(attrs[key]) != float(old[key]):
            return f"{name} has {key} = {attrs[key]}, analysis/summary.json {old[key]}"
    return None


def load_run(path, analyze_missing=True, log=print):
    """One run directory as a AnalysedRun, analysing it first if it needs it and may.

    Returns
    -------
    (AnalysedRun, None), or (None, reason) when the run cannot be used: unfinished,
    not analysed (with ``analyze_missing`` False), analysis failed, summary
    unreadable or incomplete, or not converged (docs/model.md 5.4: a run at the
    step cap is not used for comparisons).
    """
    summ, final = os.path.join(path, "analysis", SUMMARY), rundir.final_path(path)
    if not os.path.exists(final) and os.path.exists(os.path.join(path, PACKING)):
        final = os.path.join(path, PACKING)      # a campaign's kept packing, the state file gone
    if not os.path.exists(summ):
        if not os.path.exists(final):
            return None, "unfinished: no final.h5 and no analysis/summary.json"
        if not analyze_missing:
            return None, "not analysed: no analysis/summary.json (--no-analyze; run `mpdem analyze` on it)"
        err = _analyse(path, "no analysis/summary.json", log)
        if err:
            return None, err
    elif (stale := _stale(final, summ)):
        if analyze_missing:
            try:
                with open(summ) as fh:
                    settings = json.load(fh).get("settings")
            except (OSError, ValueError, AttributeError):
                settings = None
            err = _analyse(path, stale, log, settings)
            if err:
                return None, err
        else:
            log(f"collect: warning: {path}: {stale} (--no-analyze: used as is)")
    try:
        with open(summ) as fh:
            s = json.load(fh)
    except (OSError, ValueError) as e:
        return None, f"unreadable {summ}: {e}"
    if not isinstance(s, dict):
        return None, f"{summ}: not a JSON object"
    missing = [k for k in PARAM_KEYS if k not in (s.get("params") or {})]
    if missing:
        return None, f"{summ}: params lack {', '.join(missing)}"
    if not s.get("converged"):
        return None, (f"not converged (stopped at step {s.get('step', '?')} without reaching the kinetic-energy "
                      f"threshold; docs/model.md 5.4: not used for comparisons)")
    run = AnalysedRun(os.path.normpath(path), s)
    if not (math.isfinite(run.q["z"]) and math.isfinite(run.q["phi"])):
        return None, f"{summ}: no bulk z or phi"
    return run, None


def _physics_key(physics):
    """A run's physics keys as a hashable, canonical tuple. A key a summary lacks (written
    before the key existed) takes its default, so old and new runs of one physics agree."""
    from ..config import DERIVED, KEYS, REQUIRED
    full = {k: spec.default for k, spec in KEYS.items()
            if spec.physics and spec.default is not REQUIRED and spec.default is not DERIVED}
    full.update(physics)
    # keys that steer nothing under another key's choice (the tiles' edge of the whole insertion)
    for key, (other, choice) in INERT.items():
        if full.get(other) != choice:
            full.pop(key, None)
    return tuple(sorted((k, tuple(v) if isinstance(v, (list, tuple)) else v) for k, v in full.items()))


# physics keys that count only where another key has one value: key -> (that key, its value)
INERT = {"pour.tile": ("pour.insertion", "tiles")}


def _extra(physics_key):
    """The keys of a ``_physics_key`` outside PARAM_KEYS set away from their defaults; a derived key
    (``stop.E_stop``) where it differs from what the run's other keys derive."""
    from ..config import DERIVED, KEYS, PARAM_KEYS, REQUIRED
    out, derived = {}, _derived_values(physics_key)
    for k, v in physics_key:
        spec = KEYS.get(k)
        if spec is None or k in PARAM_KEYS or spec.default is REQUIRED:
            continue
        if spec.default is DERIVED:
            want = derived.get(k)
            if want is not None and isinstance(v, (int, float)) and not math.isclose(v, want, rel_tol=1e-12):
                out[k] = v
            continue
        default = tuple(spec.default) if isinstance(spec.default, (list, tuple)) else spec.default
        if v != default:
            out[k] = v
    return out


def _derived_values(physics_key):
    """The derived keys' values that a run's other physics keys give (empty if they do not resolve)."""
    from ..config import DERIVED, KEYS, ConfigError, resolve
    raw = {k: list(v) if isinstance(v, tuple) else v for k, v in physics_key
           if k in KEYS and KEYS[k].default is not DERIVED}
    raw.setdefault("run.max_steps", 1)
    try:
        vals = resolve(raw).values
    except (ConfigError, TypeError, ValueError):
        return {}
    return {k: vals[k] for k in KEYS if KEYS[k].default is DERIVED}


def signature(params, extra, unknown=None):
    """A set's identity as a canonical string: its parameters (all but the seed), the physics keys set away
    from their defaults (``Set.extra``) and any physics key this version does not know (``unknown``). What
    ``collect.json`` keeps to give a set the same id again."""
    sig = {"params": {k: v for k, v in params.items() if k != "run.seed"}, "extra": extra}
    if unknown:
        sig["unknown"] = unknown
    return json.dumps(sig, sort_keys=True, default=str)


_ID = re.compile(r"S([0-9]+)", re.ASCII)


def previous_ids(out):
    """{signature: id} of every set an earlier collect into ``out`` named (its collect.json: ``set_ids``, the
    sets of all collects before it, and ``sets``); empty when there is none or it is unreadable."""
    try:
        with open(os.path.join(out, "collect.json")) as fh:
            old = json.load(fh)
    except (OSError, ValueError):
        return {}
    if not isinstance(old, dict):
        return {}
    reg = {}
    ids = old.get("set_ids")
    for sig, sid in (ids.items() if isinstance(ids, dict) else ()):
        if isinstance(sig, str) and isinstance(sid, str) and _ID.fullmatch(sid):
            reg[sig] = sid
    sets = old.get("sets")
    for sid, v in (sets.items() if isinstance(sets, dict) else ()):
        if isinstance(v, dict) and isinstance(v.get("signature"), str) and _ID.fullmatch(sid):
            reg.setdefault(v["signature"], sid)
    return reg


def number(sets, known=None):
    """Give each set its id: the one ``known`` ({signature: id}, ``previous_ids``) has for its signature,
    else the next number after every number ``known`` holds (so a number once given, even to a set no
    longer collected, is not given again); without ``known`` S01, S02, ... in the order of ``sets``.

    Returns
    -------
    dict: ``known`` with the new sets' signatures added (collect.json's ``set_ids``)
    """
    reg = dict(known or {})
    nums = [int(m.group(1)) for m in map(_ID.fullmatch, reg.values()) if m]
    given, new = set(), []
    for s in sets:
        sid = reg.get(s.signature)
        if sid is None or sid in given:        # a second set of one signature takes a number of its own
            new.append(s)
        else:
            s.id = sid
            given.add(sid)
    nxt = max(nums, default=0) + 1
    width = max([2, len(str(nxt + len(new) - 1))] + [len(v) - 1 for v in reg.values() if _ID.fullmatch(v)])
    for s in new:
        s.id = f"S{nxt:0{width}d}"
        nxt += 1
        reg.setdefault(s.signature, s.id)
    return reg


def group(runs, known=None):
    """Sets of runs with equal parameters; a repeated seed in a set is a duplicate.

    A run is a pure function of its parameters and seed (ARCHITECTURE.md, "Invariants"), so two
    runs of one set with one seed are one sample: the later is skipped.

    Parameters
    ----------
    runs : AnalysedRun list
    known : {signature: id} of the sets of earlier collects (``previous_ids``) or None: a set found
        there keeps its id, a new one takes a number never given before (``number``); without it the
        sets are numbered S01, S02, ... in parameter order. So notes that cite a set by its id stay
        right when new sets join.

    Returns
    -------
    (sets, skipped, ids): Sets ordered by parameters, runs ordered by seed; [{"path", "reason"}] of the
    duplicates; {signature: id} of ``known`` and the new sets.
    """
    from ..config import KEYS
    by_key, skipped = {}, []
    for r in runs:
        # PARAM_KEYS name the set; every other physics key of the config must agree as well
        other = _physics_key(r.s.get("physics") or {})
        by_key.setdefault((set_key(r.params), other), []).append(r)
    sets = []
    for key in sorted(by_key, key=lambda k: (_set_order(dict(k[0])), repr(k[1]))):
        kept = {}
        for r in by_key[key]:
            # the sample: the pour's seed and the bed's
            seed = (r.params["run.seed"], r.bed_seed)
            if seed in kept:
                skipped.append({"path": r.path, "reason": f"duplicate: seed {seed[0]} (bed seed {seed[1]}) of this "
                                                          f"parameter set is {kept[seed].path} (the same sample)"})
            else:
                kept[seed] = r
        samples = sorted(kept, key=lambda k: (_order(k[0]), _order(k[1])))
        extra = _extra(key[1])
        unknown = {k: v for k, v in key[1] if k not in KEYS}
        sets.append(Set("", dict(key[0]), [kept[k] for k in samples], extra,
                        signature(dict(key[0]), extra, unknown)))
    ids = number(sets, known)
    return sets, skipped, ids


# ---------------------------------------------------------------- fits

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
    if kind == "eq7":
        # docs/model.md 6.6: weights from the family's pooled seed scatter (two seeds give a poor error of their own)
        sigma, scatter, dof = pooled.eq7_sigma(members, q)
        e.update(pooled_scatter=scatter, pooled_dof=dof)
        if sigma is not None:
            sem = sigma
        e[f"{q}_sigma"] = [float(v) if math.isfinite(v) else None for v in sem]
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
    if kind == "eq7" and weighted:
        # the exponent fixed: 1/2 at mu = 0 (z - z_c ~ delta^(1/2)), the paper's 1/4 with friction
        fixed = 0.5 if e["family"]["mu"] == 0 else paper.EQ7_FRICTIONAL_ALPHA_N
        # with friction, the frictionless exponent beside it: the rival a claim of 1/4 must tell apart
        for part, a_n in (("fixed", fixed), *((("fixed 1/2", 0.5),) if e["family"]["mu"] != 0 else ())):
            try:
                e[part] = fits.fit_eq7_fixed(x, e[q], sem, a_n)
            except (ValueError, np.linalg.LinAlgError) as err:
                e[part] = {"status": "failed", "reason": str(err)}
    if not r["determined"]:
        # e.g. alpha_n -> 0, where z_inf and a trade off exactly: printing them would print noise
        e.update(status="not determined",
                 reason=f"the points cannot tell the parameters apart (largest parameter correlation "
                        f"{r['correlation']:.10g}); no values are reported")
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
        chk["paper"]["note"] = "eq. 8, alpha_n = 1 - alpha, holds for mu = 0 (docs/model.md 6.6)"
    else:
        chk["paper"] = {"alpha_n": paper.EQ7_FRICTIONAL_ALPHA_N,
                        "note": "mu > 0: z - z_inf ~ k_n^(-1/4), z_inf > 4; eq. 8 does not hold (docs/model.md 6.6)"}
    return chk


def make_fits(sets):
    """{'eq7', 'eq9', 'overlap', 'alpha', 'P_f', 'depth', 'ratio', 'contrasts', 'ladder'}: lists, 'samples': a dict;
    eq. 7 per family with >= 2 values of k_n, eq. 9 per family with >= 2 values of phi_i (with a note where the
    family is not the paper's eq. 9 conditions), the stiffening ladders (``ladder.ladders``), the overlap fit per family
    of k_n (any number of k_n), alpha, P(f) and the depth windows pooled over the seeds of each set, the
    F_t/F_n collapse per family of mu (``ratio.tests``), the sets that differ in one setting from the
    one at its default (``contrasts.contrasts``), whether the runs are independent samples (``samples.tests``)."""
    ladder.poured_k_n.cache_clear()     # the piles are read from the run directories as they are now
    out = {"eq7": [], "eq9": [], "overlap": [], "alpha": [], "P_f": [], "depth": [], "ratio": ratio.tests(sets),
           "contrasts": contrasts.contrasts(sets), "samples": samples.tests(sets)}
    for fam, members in families(sets, "contact.k_n"):
        # a ladder's fit spans its base set too: the piles at every k_n they climbed; with the alternative
        # exponents kept beside, for a claim that rests on the exponent (``sources.Assumes``)
        out["overlap"].append(dict(family=fam, **pooled.overlap_fit(ladder.with_base(members, sets),
                                                                    alternatives=pooled.OVERLAP_ALTERNATIVES)))
    for s in sets:
        for key, fn in (("alpha", pooled.set_alpha), ("P_f", pooled.set_force_distribution),
                        ("depth", pooled.set_depth)):
            got = fn(s)
            if got is not None:
                out[key].append(dict(set=s.id, **got))
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
            if (f := e["family"]).get("mu") != paper.EQ9["mu"] or f.get("epsilon") != paper.EQ9["epsilon"]:
                e["note"] = (f"not the paper's eq. 9 (mu = {paper.EQ9['mu']:g}, eps = {paper.EQ9['epsilon']:g}): "
                             f"phi_f against phi_i at mu = {f.get('mu'):g}, eps = {f.get('epsilon'):g}")
            out["eq9"].append(e)
    out["ladder"] = ladder.ladders(sets, lambda fam, members: _fit_one("eq7", fam, members))
    return out


# ---------------------------------------------------------------- tables

RUN_COLUMNS = ("z", "z_no_rattlers", "rattler_fraction", "phi", "n_bulk", "alpha", "alpha_err",
               "mobilised_fraction", "z_halved", "phi_halved", "overlap_median", "overlap_max", "step",
               "z_backbone", "z_iso", "crystal_fraction")


def write_runs_csv(path, sets):
    """runs.csv: one row per run."""
    head = ["set", "path"] + [SHORT[k] for k in PARAM_KEYS] + ["converged", *RUN_COLUMNS, "n_warnings"]
    rows = [[s.id, r.path] + [r.params[k] for k in PARAM_KEYS] + [True] + [r.q[c] for c in RUN_COLUMNS]
            + [len(r.s.get("warnings") or [])] for s in sets for r in s.runs]
    rundir.write_csv(path, head, rows)


def write_sets_csv(path, sets):
    """sets.csv: one row per parameter set, mean and standard error over its seeds."""
    head = ["set"] + [SHORT[k] for k in PARAM_KEYS if k != "run.seed"] + ["n_seeds", "seeds"]
    for q in SET_QUANTITIES:
        head += [f"{q}_mean", f"{q}_sem"] + ([f"{q}_count"] if q in ("alpha", "mobilised_fraction") else [])
    rows = []
    for s in sets:
        row = [s.id] + [s.params[k] for k in PARAM_KEYS if k != "run.seed"] + [len(s.runs), " ".join(map(str, s.seeds))]
        for q in SET_QUANTITIES:
            m, e, n = s.stat(q)
            row += [m, e] + ([n] if q in ("alpha", "mobilised_fraction") else [])
        rows.append(row)
    rundir.write_csv(path, head, rows)


def write_json(path, obj):
    rundir.write_json(path, obj)


# ---------------------------------------------------------------- the command

def collect(runs, out, analyze_missing=True, log=print, figure_format="png", claim_list=None):
    """``mpdem collect RUN_DIR ... --out OUT``: the paper's tables and figures from many runs.

    Parameters
    ----------
    runs : run directories, or directories holding them (searched recursively)
    out : output directory (created); None gives ./paper
    analyze_missing : run ``mpdem analyze`` (no plots) on runs without an
        up-to-date analysis/summary.json; False skips them with a warning
    log : one-line messages
    figure_format : formats of the figures (``analysis.figure_format``: png, pdf, svg, joined by commas)
    claim_list : the paper's claims to judge (``claims.Claim`` list) for README.md's claim table; None
        takes ``claims.for_out(out)`` (the claims of ``claims.CLAIMS`` for the paper campaign's directory,
        whose set ids they cite; none elsewhere); an empty list writes no table

    Returns
    -------
    dict (also OUT/collect.json): inputs, runs used, sets, skipped runs with
    reasons, figures made and not made, file names.

    Raises
    ------
    AnalysisError when no usable run remains.
    """
    out = out or "paper"
    from ..analysis.plots import formats_of
    fmts = formats_of(figure_format)
    if [f for f in fmts if f not in ("png", "pdf", "svg")] or not fmts:   # refused before any run is read
        raise AnalysisError(f"collect: --figure-format {figure_format!r}: accepted png, pdf or svg, several "
                            f"joined by commas")
    paths, skipped = find_runs(runs)
    log(f"collect: {len(paths)} run director{'y' if len(paths) == 1 else 'ies'} found")
    loaded = []
    for p in paths:
        run, why = load_run(p, analyze_missing, log)
        if run is None:
            skipped.append({"path": p, "reason": why})
        else:
            loaded.append(run)
    sets, dup, set_ids = group(loaded, previous_ids(out))
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
    windows = depth.rows(sets)
    depth.write_csv(os.path.join(out, "depth.csv"), windows)
    for line in depth.lines(windows):
        log(f"collect: {line}")
    fit_res = make_fits(sets)
    write_json(os.path.join(out, "fits.json"), {"source": paper.SOURCE, **fit_res})
    for kind in ("eq7", "eq9", "overlap"):
        for e in fit_res[kind]:
            why = f" ({e['reason']})" if "reason" in e else ""
            log(f"collect: {kind} [{' '.join(e['sets'])}]: {e['status']}{why}")
    figs = make_figures(sets, fit_res, out, log, fmts)
    rows = comparisons(sets, fit_res)
    info = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "inputs": [str(r) for r in runs], "out": out,
            "n_runs": n_runs, "n_sets": len(sets)}
    claim_list = claims.for_out(out) if claim_list is None else claim_list
    judged = claimtable.rows(claim_list, sources.Context(sets, fit_res, windows, out, runs)) if claim_list else None
    write_readme(os.path.join(out, "README.md"), info, sets, fit_res, rows, figs, skipped, windows, judged)
    res = {**info, "sets": {s.id: {"params": {SHORT[k]: v for k, v in s.params.items()}, "seeds": s.seeds,
                                   "runs": [r.path for r in s.runs], "signature": s.signature} for s in sets},
           "set_ids": set_ids,
           "skipped": skipped, "comparisons": rows,
           "claims": [{"id": r["id"], "claim": r["claim"], "paper": r["paper"], "this_work": r["ours"],
                       "samples": r["count"], "verdict": r["verdict_text"], "kind": r["verdict"].kind,
                       "reason": r["reason"]} for r in judged or []],
           "figures": {k: v for k, v in figs.items() if not k.startswith("_")}, "figure_notes": figs["_notes"],
           "files": ["runs.csv", "sets.csv", "depth.csv", "fits.json", "README.md", "collect.json"]
           + [p for k, f in figs.items() if not k.startswith("_") and f["made"] for p in f["files"]]}
    write_json(os.path.join(out, "collect.json"), res)
    made = [k for k, f in res["figures"].items() if f["made"]]
    log(f"collect: wrote {out}/ (runs.csv, sets.csv, depth.csv, fits.json, README.md, collect.json; "
        f"figures {', '.join(made) or 'none'})")
    return res
