"""Where the claim table's numbers come from: sources that read this collect's sets, fits and depth
windows, or another collect's tables, and turn into a ``Measure``.

A claim (``claims.Claim``) names its number by a source: a set's mean over its seeds (``S``, or ``Find``
by parameters, so that a set joining later is picked up), a fixed depth window (``Window``), a difference
of two sources (``Diff``; a one-setting contrast takes its pooled error), a fit of ``fits.json`` (``Fit``),
a rung of a paper-size stiffening ladder (``Rung``), a run-level quantity of the summaries (``PerRun``),
an eq. 6 window (``AlphaWindow``), 1 minus a source (``OneMinus``), or another collect's tables (``Ext``,
``ExtFit``, ``ExtTest``, ``Eq9Deviation``, ``Eq9PaperTest``: the development sweeps of
``analysis/results/dev``, the N = 2000 ladders). ``Context`` is what they read. Numbers are never written
by hand here: a source with nothing to read gives a ``Measure`` that says "not measured" (or "running",
"not determined") and why.
"""
from __future__ import annotations

import csv
import dataclasses
import json
import math
import os
from dataclasses import dataclass, field

from . import verdict as V
from ..analysis.fits import pooled_scatter
from .runs import NAN, fmt_kn, mean_sem, off_columns

# the paper-size stiffening ladders (docs/model.md 6.6): runs/ladder-size/<mu>_s<seed>/kn<K>/
LADDER_DIR = "ladder-size"
PAPER_N = 20000


# ---------------------------------------------------------------- a measured number

@dataclass
class Measure:
    """A number of this work: ``value`` ± ``err`` from ``n`` samples (runs; ``count`` says of what),
    ``where`` it comes from (sets, window); ``status`` 'ok', 'not measured', 'not determined' or
    'running', ``why`` the reason for a status other than 'ok'. ``k_n``: the stiffness of a rung.
    ``assumption`` and ``alts``: a number that rests on an assumed choice, with the same number made with
    each alternative the claim names (``Assumes``; the verdict weighs them: ``claimtable.judge``).
    ``pooled_sd``: a set's value of one run, the seed scatter pooled over the sets of its N and μ (nan where
    none has two seeds), the error the rule judges it with beside none (``claimtable._one_seed_alternative``)."""
    value: float = NAN
    err: float = NAN
    n: int = 0
    count: str = ""
    where: str = ""
    status: str = "ok"
    why: str = ""
    k_n: float = NAN
    assumption: str = ""                        # what the number rests on (``Assumes``)
    alts: list = field(default_factory=list)    # [(label, Measure, kind or None)]: the same made with each alternative
    borrowed: str = ""                          # where a value of one run takes its error from ("1 run with …")
    pooled_sd: float = NAN                      # one run alone: the seed scatter of the sets of its N and μ
    source: object = None                       # the source that made it (a test's rival part: ``claimtable``)

    @property
    def ok(self):
        return self.status == "ok" and isinstance(self.value, (int, float)) and math.isfinite(self.value)


def missing(where, why="", status="not measured"):
    """A ``Measure`` without a number: ``status`` and why."""
    return Measure(where=where, status=status, why=why)


def _runs(n):
    return f"{n} run{'s' if n != 1 else ''}"


def _runs_note(n):
    """The samples cell of a mean over ``n`` runs: one run has no scatter, so no error."""
    return _runs(n) + ("" if n > 1 else ", no error")


def finite(x):
    """Whether ``x`` is a finite number (not a bool, None or a string)."""
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


# ---------------------------------------------------------------- sources

@dataclass
class S:
    """A set's mean ± standard error over its runs (seeds), by set id; ``label`` names it in the table."""
    set: str
    q: str = "z"
    label: str = ""

    def resolve(self, ctx):
        where = self.label or self.set
        s, gone = ctx.set_or_missing(self.set, where)
        if gone:
            return gone
        m, e, n = s.stat(self.q)
        if not n:
            return missing(where, f"no {self.q} in set {self.set}")
        # one run alone has no error of its own: the rule judges it with its sets' seed scatter as well
        sd = ctx.pooled_scatter(None, self.set, self.set, self.q) if n == 1 else NAN
        return Measure(m, e, n, _runs_note(n), f"{where}" if self.label else self.set,
                       k_n=s.p("k_n"), pooled_sd=sd)


@dataclass
class Find:
    """The poured set (no setting away from its default but those named in ``extra``) with the parameters
    ``sel`` (short names: mu, epsilon, k_n, N, phi_i, K0, ...); picks up a set that joins later."""
    q: str
    sel: dict
    extra: dict = field(default_factory=dict)
    label: str = ""

    def resolve(self, ctx):
        for s in ctx.set_list:
            if ctx.matches(s, self.sel, self.extra):
                return S(s.id, self.q, self.label and f"{self.label} ({s.id})").resolve(ctx)
        return missing(self.label or _sel_text(self.sel), "no such set collected")


def _sel_text(sel):
    return ", ".join(f"{k} = {fmt_kn(v) if k == 'k_n' else v}" for k, v in sel.items())


@dataclass
class Window:
    """A set's value on a fixed depth window below the surface (``depth.csv``), its error the seed scatter
    pooled over the sets of one N and mu (the jackknife over lateral columns where that is absent)."""
    set: str
    window: str
    q: str = "z"

    def resolve(self, ctx):
        where = f"{self.set}, {self.window} d"
        r = ctx.windows.get((self.set, self.window, self.q))
        if r is None or not finite(r["mean"]):
            return missing(where, "no depth window")
        pooled = finite(r["pooled_sem"])
        err = r["pooled_sem"] if pooled else r["jackknife"]
        n = r["n_seeds"]
        # one run has no scatter of its own: its error is the sets' pooled one (or its columns'), and says so
        why = ("the seed scatter pooled over its N and μ's sets" if pooled else "the jackknife over its columns") \
            if n == 1 else ""
        return Measure(r["mean"], err, n, _runs(n) + (f", its error {why}" if why else ""), where,
                       borrowed=f"1 run with {why}" if why else "")


@dataclass
class Diff:
    """``a`` minus ``b`` (two sources), errors in quadrature (``diff_error``: a side of one run takes the
    other's seed scatter, and the count says so); two sets of a one-setting contrast (``fits.json``
    contrasts) take its pooled seed error instead."""
    a: object
    b: object
    label: str = ""

    def resolve(self, ctx):
        ma, mb = self.a.resolve(ctx), self.b.resolve(ctx)
        where = self.label or f"{ma.where} − {mb.where}"
        if not (ma.ok and mb.ok):
            bad = ma if not ma.ok else mb
            return missing(where, bad.why, bad.status)
        err, lent = diff_error(ma, mb)
        if isinstance(self.a, S) and isinstance(self.b, S):
            c = ctx.contrast(self.a.set, self.b.set, self.a.q)
            if c is not None and finite(c["err"]):
                err = c["err"]
                # the contrast's pooled scatter, not the other side's alone
                lent = "; its 1 run with the sets' pooled seed scatter" if lent else ""
        if not finite(err) and ma.n == mb.n == 1:
            # two sides of one seed each: the seed scatter pooled over the sets of their N and μ (the rule)
            sd = _one_seed_scatter(ctx, self.a, self.b)
            if finite(sd):
                err, lent = sd * math.sqrt(2), POOLED_BOTH
        if not lent and (ma.borrowed or mb.borrowed):
            if ma.borrowed == mb.borrowed:      # both sides one run, their error from the same place
                lent = "; each side's " + ma.borrowed
            else:
                lent = "; " + "; ".join("its " + x.borrowed for x in (ma, mb) if x.borrowed)
        return Measure(ma.value - mb.value, err, ma.n + mb.n, f"{ma.n} + {mb.n} runs" + lent, where, k_n=ma.k_n)


LENT = "; its 1 run with the other's seed scatter"
POOLED_BOTH = "; each side's 1 run with the seed scatter pooled over its N and μ's sets"


def _one_seed_scatter(ctx, a, b):
    """One run's seed scatter for ``a`` − ``b``, two sets (``S`` of this collect, or ``Ext`` of one other) of
    one run each and of one N and μ: pooled over the sets of that N and μ (``Context.pooled_scatter``); nan
    for other sources or where no such set has two seeds."""
    if isinstance(a, S) and isinstance(b, S) and a.q == b.q:
        return ctx.pooled_scatter(None, a.set, b.set, a.q)
    if isinstance(a, Ext) and isinstance(b, Ext) and a.results == b.results and a.q == b.q:
        return ctx.pooled_scatter(a.results, a.set, b.set, a.q)
    return NAN


def diff_error(ma, mb):
    """The error of ``ma - mb`` (two ``Measure``): theirs in quadrature. A side of one run has no error of
    its own: it takes the other side's seed scatter (one run's standard deviation, the other's error times
    the square root of its runs), as the pooled contrasts do. Returns (error, ``LENT`` or "": the count's
    words when a side borrowed); nan when neither side has an error."""
    ea, eb = ma.err, mb.err
    lent = ""
    if not finite(ea) and ma.n == 1 and finite(eb) and mb.n >= 2:
        ea, lent = eb * math.sqrt(mb.n), LENT
    if not finite(eb) and mb.n == 1 and finite(ea) and ma.n >= 2:
        eb, lent = ea * math.sqrt(ma.n), LENT
    return (V.combined(ea, eb) if finite(ea) and finite(eb) else NAN), lent


@dataclass
class Fit:
    """A parameter of a ``fits.json`` fit: the first entry of ``kind`` ('eq7', 'overlap', 'eq9', 'ladder')
    whose sets include ``set`` (or, for 'ladder', of friction ``mu``); ``fixed`` reads its fixed-exponent
    fit, ``part`` another fit kept in the entry (a ladder's 'set_means'), ``label`` names it. A fit not made,
    or one that cannot tell its parameters apart, is 'not determined'."""
    kind: str
    key: str
    set: str = ""
    mu: float = None
    fixed: bool = False
    part: str = ""
    label: str = ""

    def resolve(self, ctx):
        e = ctx.fit(self.kind, self.set, self.mu)
        if e is None and self.kind == "ladder" and self.mu is not None and ctx.ladder_pending(self.mu):
            return missing(f"ladder mu = {self.mu:g}", "no rung converged yet", "running")
        m = fit_measure(e, self.key, "fixed" if self.fixed else self.part, ctx.n_runs_of, self.kind)
        if self.label:
            m.where = f"{self.label} {m.where}"
        return m

    def with_part(self, part):
        """This fit's other part ``part`` (another law kept in the same entry, such as a claim's rival)."""
        return dataclasses.replace(self, fixed=False, part=part)


@dataclass
class Assumes:
    """A source whose number rests on an assumed choice (``assumption``, e.g. the exponent of the overlap
    law for Hertzian contacts), with the same number made with each alternative choice: ``alternatives``
    [(label, source)], or [(label, source, kind)] where the alternative is another kind of measure of the
    same claim (a fit's p, kind 'test', beside a value). The claim is judged with each as well
    (``claimtable.judge``): where they disagree on the verdict, the row is not determined, and says which
    choice gives which."""
    src: object
    assumption: str
    alternatives: list = field(default_factory=list)

    def __post_init__(self):
        for alt in self.alternatives:
            if len(alt) not in (2, 3) or len(alt) == 3 and alt[2] != "test":
                raise ValueError(f"Assumes: an alternative is (label, source) or (label, source, 'test'), not "
                                 f"{alt!r}")

    def resolve(self, ctx):
        m = self.src.resolve(ctx)
        if m.ok:
            m.assumption = self.assumption
            m.alts = [(label, a.resolve(ctx), kind[0] if kind else None) for label, a, *kind in self.alternatives]
        return m


def ext_id(results, sid):
    """A set id of another collect, named with its directory (``dev:S15``): ids repeat between collects."""
    return f"{os.path.basename(os.path.normpath(results))}:{sid}"


def fit_measure(e, key, fixed=False, n_runs_of=None, kind="fit", name=str):
    """A ``Measure`` of parameter ``key`` of fit entry ``e`` (None: not measured); ``fixed`` True (or "fixed")
    reads its fixed-exponent fit, another string the fit of that name kept in the entry; ``name`` writes a
    set's id (``ext_id`` for another collect's)."""
    if e is None:
        return missing(kind, "no such fit")
    sets = e.get("sets") or []
    where = f"{kind} [{' '.join(name(x) for x in sets)}]"
    n = e.get("n_runs") or (sum(n_runs_of(s) for s in sets) if n_runs_of else 0)
    if kind == "ladder" and e.get("status") == "running":
        return missing(where, e.get("reason", ""), "running")
    part = "fixed" if fixed is True else (fixed or "")
    f = (e.get(part) or {}) if part else e
    if part and key not in f:
        return missing(where, f.get("reason") or e.get("reason") or "not fitted", "not determined")
    n = f.get("n_runs") or n            # a part over fewer runs than its entry (a ladder's 'bend') says so
    if f.get("status", "fitted") != "fitted" or f.get("determined") is False:
        return missing(where, f.get("reason") or f.get("status", ""), "not determined")
    v, err = f.get(key), f.get(f"{key}_err")
    if not finite(v):
        return missing(where, f"no {key}", "not determined")
    # a fit over piles measured again at several k_n (a ladder's) names its piles
    piles = f" of {f['n_piles']} piles" if f.get("n_piles") else ""
    failed = _law_fails(f, f.get("pooled_dof", e.get("pooled_dof")))
    return Measure(v, err if finite(err) else NAN, n, f"{len(sets)} sets, {_runs(n)}{piles}{failed}", where)


def _law_fails(f, noise_dof):
    """The count's words for a fit whose errors are not widened by its χ² (no 'scale') and whose law fails
    the rule's test of it: χ²/dof against F(dof, ``noise_dof``), the dof of the seed scatter its weights
    rest on (the rule: F where the noise is measured). "" otherwise, and where that dof is not known."""
    chi2, dof = f.get("chi2"), f.get("dof")
    if "scale" in f or not (finite(chi2) and dof and noise_dof):
        return ""
    from scipy import stats
    p = float(stats.f.sf(chi2 / dof, dof, noise_dof))
    return f"; its law's χ² = {chi2:.3g} for {dof} dof, p = {p:.2g} against F({dof}, {noise_dof})" if p < V.P_K \
        else ""


@dataclass
class Rung:
    """A rung of the paper-size stiffening ladders of friction ``mu`` (``fits.json`` 'ladder'): the one
    at ``k_n``, or the stiffest converged ('top'). 'running' while its directory exists without a
    converged run, 'not measured' when there is none."""
    mu: float
    q: str = "z"
    k_n: object = "top"

    def resolve(self, ctx):
        e = ctx.fit("ladder", "", self.mu)
        want = "top rung" if self.k_n == "top" else f"rung {fmt_kn(self.k_n)}"
        where = f"ladder mu = {self.mu:g}, {want}"
        rungs = (e or {}).get("rungs") or []
        if self.k_n != "top":
            rungs = [r for r in rungs if r["k_n"] == self.k_n]
        if not rungs:
            if self.k_n == "top":
                pending = ctx.ladder_pending(self.mu)
            else:
                pending = ctx.ladder_pending(self.mu, self.k_n)
            have = ", ".join(ctx.ladder_dirs(self.mu)) or "none"
            at = "" if self.k_n == "top" else f" at {fmt_kn(self.k_n)}"
            return missing(where, f"no converged rung{at}; ladder directories: {have}", "running" if pending else
                            "not measured")
        r = max(rungs, key=lambda r: r["k_n"])
        v, err, n = r.get(self.q, NAN), r.get(f"{self.q}_sem", NAN), r["n_runs"]
        if not finite(v):
            return missing(where, f"no {self.q} on the rung")
        return Measure(v, err if finite(err) else NAN, n, _runs_note(n),
                       f"{where} ({fmt_kn(r['k_n'])}, {r['set']})", k_n=r["k_n"])


@dataclass
class PerRun:
    """A quantity computed from each run's summary by ``fn`` (summary -> number), mean ± standard error
    over the runs of a set."""
    set: str
    fn: object
    label: str = ""

    def resolve(self, ctx):
        s, gone = ctx.set_or_missing(self.set, self.label or self.set)
        if gone:
            return gone
        m, e, n = mean_sem([self.fn(r.s) for r in s.runs])
        if not n:
            return missing(self.label or self.set, "not in its summaries")
        return Measure(m, e, n, _runs_note(n), self.label or self.set,
                       k_n=s.p("k_n"))


@dataclass
class Count:
    """The fraction of a set's bulk spheres with ``n`` contacts, counted over all its runs (P_z[n] times
    n_bulk, summed), with the Poisson error of the count: k ± sqrt(k) spheres of the runs' bulk total. For
    events too rare for a scatter over seeds (a sphere or two a pile), where a standard error over a few
    tiny counts means nothing."""
    set: str
    n: int
    label: str = ""

    def resolve(self, ctx):
        where = self.label or self.set
        s, gone = ctx.set_or_missing(self.set, where)
        if gone:
            return gone
        k = total = 0
        for r in s.runs:
            pz, nb = r.s.get("P_z") or [], r.s.get("n_bulk")
            if len(pz) <= self.n or not nb:
                return missing(where, f"{r.path}: no P_z or n_bulk in its summary")
            k += round(float(pz[self.n]) * nb)
            total += nb
        return Measure(k / total, math.sqrt(k) / total, len(s.runs),
                       f"{k} of {total} bulk spheres in {_runs(len(s.runs))}, Poisson error", where,
                       k_n=s.p("k_n"))


@dataclass
class Ext:
    """A set of another collect's ``sets.csv`` (``results``: its directory, relative to this collect's
    output), e.g. the development sweeps at N = 2000."""
    results: str
    set: str
    q: str = "z"
    label: str = ""

    def resolve(self, ctx):
        row = ctx.ext_sets(self.results).get(self.set)
        where = f"{self.label + ' ' if self.label else ''}{ext_id(self.results, self.set)}"
        if row is None:
            return missing(where, f"{self.results}: no set {self.set}")
        m, e, n = _f(row.get(f"{self.q}_mean")), _f(row.get(f"{self.q}_sem")), _count(row.get("n_seeds"))
        if not finite(m):
            return missing(where, f"no {self.q}")
        sd = ctx.pooled_scatter(self.results, self.set, self.set, self.q) if n == 1 else NAN
        return Measure(m, e, n, _runs_note(n), where, k_n=_f(row.get("k_n")), pooled_sd=sd)


@dataclass
class ExtFit:
    """A parameter of a fit in another collect's ``fits.json`` (as ``Fit``: ``fixed`` its fixed-exponent fit,
    ``part`` another fit kept in the entry, such as an overlap fit's 'exponent 1/3')."""
    results: str
    kind: str
    key: str
    set: str
    fixed: bool = False
    label: str = ""
    part: str = ""

    def resolve(self, ctx):
        if self.fixed and self.part:
            raise ValueError(f"ExtFit {self.kind} {self.key}: fixed and part {self.part!r} both given: one fit")
        fits_ = ctx.ext_fits(self.results)
        e = next((x for x in fits_.get(self.kind, []) if self.set in (x.get("sets") or [])), None)
        sets = ctx.ext_sets(self.results)
        m = fit_measure(e, self.key, "fixed" if self.fixed else self.part,
                        lambda s: _count((sets.get(s) or {}).get("n_seeds")),
                        f"{self.label or os.path.basename(os.path.normpath(self.results))} {self.kind}",
                        lambda sid: ext_id(self.results, sid))
        return m

    def with_part(self, part):
        """This fit's other part ``part`` (another law kept in the same entry, such as a claim's rival)."""
        return dataclasses.replace(self, fixed=False, part=part)


ALL_QUANTITIES = "all"     # ExtTest: every quantity of the test at once (Bonferroni)


@dataclass
class ExtTest:
    """The p value of a test in another collect's ``fits.json`` (the F_t/F_n collapse, 'ratio'): the
    entry whose sets include ``set``, quantity ``q``, or with ``q`` ``ALL_QUANTITIES`` the entry's smallest p
    over its quantities times their number (Bonferroni: 'p_bonferroni')."""
    results: str
    kind: str
    set: str
    q: str
    label: str = ""

    def resolve(self, ctx):
        e = next((x for x in ctx.ext_fits(self.results).get(self.kind, []) if self.set in (x.get("sets") or [])),
                 None)
        where = f"{self.label} [{' '.join(ext_id(self.results, x) for x in (e or {}).get('sets') or [])}]"
        t = {"p": (e or {}).get("p_bonferroni")} if self.q == ALL_QUANTITIES \
            else ((e or {}).get("quantities") or {}).get(self.q) or {}
        if not finite(t.get("p")):
            return missing(where, "no test")
        n = sum((e or {}).get("n_seeds") or [])
        return Measure(t["p"], NAN, n, _runs(n), where)


@dataclass
class OneMinus:
    """1 minus a source (eq. 8: 1 - alpha), its error kept."""
    src: object

    def resolve(self, ctx):
        m = self.src.resolve(ctx)
        if m.ok:
            m.value, m.where = 1.0 - m.value, f"(1 − {m.where})"
        return m


@dataclass
class AlphaWindow:
    """A set's eq. 6 exponent on one fixed window of xi (``fits.json`` 'alpha', seeds pooled): the one
    starting at ``lo``; its error the bootstrap over seeds where there is one, else the Fisher error."""
    set: str
    lo: float

    def resolve(self, ctx):
        e = next((x for x in ctx.fits.get("alpha", []) if x.get("set") == self.set), None)
        w = next((w for w in (e or {}).get("windows", []) if w.get("xi_lo") == self.lo), None)
        where = f"{self.set}, ξ from {self.lo:g}" + (f" to {w['xi_hi']:g}" if w else "")
        if w is None or not finite(w.get("alpha")):
            return missing(where, "no such window")
        err = w["boot_err"] if finite(w.get("boot_err")) else w.get("alpha_err", NAN)
        n = e["n_runs"]
        return Measure(w["alpha"], err, n, _runs(n), where)


@dataclass
class Eq9Deviation:
    """The largest |phi_f| difference between the eq. 9 fit of another collect (the family holding ``set``)
    and the paper's eq. 9, over the fitted phi_i (no error: a fit's curve, not a sample)."""
    results: str
    set: str

    def resolve(self, ctx):
        import numpy as np
        from ..analysis import fits as F
        from . import paper
        e = next((x for x in ctx.ext_fits(self.results).get("eq9", []) if self.set in (x.get("sets") or [])), None)
        if e is None or e.get("status") != "fitted":
            return missing("eq. 9 curve", "no fit", "not determined" if e else "not measured")
        x = np.array(e["phi_i"], float)
        d = F.eq9(x, e["A"], e["B"], e["C"]) - paper.eq9_paper(x)
        i = int(np.argmax(np.abs(d)))
        n = sum(e.get("n_seeds") or [])
        return Measure(float(d[i]), NAN, n, f"{len(x)} sets, {_runs(n)}; a fit's curve, no error",
                       f"eq. 9 fit − paper, largest at φ_i = {x[i]:g} (φ_i {x.min():g}–{x.max():g})")


@dataclass
class Eq9PaperTest:
    """The paper's eq. 9 curve against another collect's sets' means of phi_f (the family of its eq. 9 fit
    holding ``set``): chi^2 over the sets with no parameter fitted, each set's error the seed scatter
    pooled over the family (from its sets' standard errors and seeds) over sqrt(its seeds). That scatter is
    itself estimated (on the seeds' degrees of freedom), so chi^2 / K over K sets is F(K, dof) distributed
    where the curve holds: its p is the value."""
    results: str
    set: str

    def resolve(self, ctx):
        import numpy as np
        from scipy.stats import f as f_dist
        from . import paper
        e = next((x for x in ctx.ext_fits(self.results).get("eq9", []) if self.set in (x.get("sets") or [])), None)
        where = "the paper's eq. 9 against the sets' means"
        if e is None:
            return missing(where, "no eq. 9 family")
        x, y = np.array(e["phi_i"], float), np.array(e["phi"], float)
        sem = np.array([_f(v) for v in e["phi_sem"]], float)
        n = np.array(e["n_seeds"], float)
        have = np.isfinite(sem) & (n >= 2)
        dof = float(np.sum(n[have] - 1))
        if dof < 1:
            return missing(where, "no set with two seeds: no seed scatter", "not determined")
        scatter = math.sqrt(float(np.sum((n[have] - 1) * sem[have] ** 2 * n[have])) / dof)
        r = (y - paper.eq9_paper(x)) / (scatter / np.sqrt(n))
        chi2 = float(np.sum(r ** 2))
        i = int(np.argmax(np.abs(r)))
        k = len(x)
        return Measure(float(f_dist.sf(chi2 / k, k, dof)), NAN, int(n.sum()), f"{k} sets, {_runs(int(n.sum()))}",
                       f"{where}: χ² = {chi2:.1f} for {k} dof, F = {chi2 / k:.2f} on ({k}, {dof:g}) dof (the seed "
                       f"scatter {scatter:.2g} pooled on {dof:g} dof), largest residual {r[i]:+.1f} σ at "
                       f"φ_i = {x[i]:g}")


def _n_mu(s):
    """A set's (N, μ): the sets whose seed scatter a one-seed value borrows."""
    return s.params.get("pour.N"), s.params.get("contact.mu")


def _count(v):
    """A count read from a table cell: 0 where it holds none."""
    x = _f(v)
    return int(x) if math.isfinite(x) else 0


def _f(v):
    try:
        return float(v)
    except (TypeError, ValueError):
        return NAN


# ---------------------------------------------------------------- what the sources read

class Context:
    """What the sources read: this collect's sets (by id and in order), its fits and depth windows, the
    output directory (another collect's tables lie relative to it) and the ladder directories."""

    def __init__(self, sets, fit_res, windows=(), out=".", inputs=()):
        self.set_list = list(sets)
        self.sets = {s.id: s for s in sets}
        self.fits = fit_res or {}
        self.windows = {(r["set"], r["window"], r["quantity"]): r for r in windows}
        self.out = out
        self.inputs = list(inputs)
        self._ext = {}

    def set_or_missing(self, sid, where):
        """``(set, None)`` for a collected set id, else ``(None, a Measure saying it was not collected)``."""
        s = self.sets.get(sid)
        return (s, None) if s is not None else (None, missing(where, f"set {sid} not collected"))

    def n_runs_of(self, sid):
        s = self.sets.get(sid)
        return len(s.runs) if s else 0

    def matches(self, s, sel, extra):
        if s.extra != dict(extra):
            return False
        off = off_columns(s)
        for k, v in sel.items():
            if k in ("K0", "gamma_t", "model"):
                continue
            if s.p(k) != v:
                return False
        want_off = {k: v for k, v in sel.items() if k in ("K0", "model")}
        if {k: off.get(k) for k in ("K0", "model")} != {k: (f"{want_off[k]:g}" if k == "K0" else want_off[k])
                                                         if k in want_off else None for k in ("K0", "model")}:
            return False
        return ("gamma_t" in off) == bool(sel.get("gamma_t"))

    def fit(self, kind, sid="", mu=None):
        for e in self.fits.get(kind, []) or []:
            if sid and sid in (e.get("sets") or []):
                return e
            if mu is not None and (e.get("family") or {}).get("mu") == mu:
                return e
        return None

    def contrast(self, sid, ref, q):
        for c in self.fits.get("contrasts", []) or []:
            if c.get("reference") != ref:
                continue
            for r in c.get("rows", []):
                if r.get("set") == sid and q in r:
                    return r[q]
        return None

    def ladder_dirs(self, mu):
        """The rung directories (``<ladder>/kn<K>``) of the paper-size ladders of friction ``mu``."""
        out = []
        for base in self.inputs:
            d = base if os.path.basename(os.path.normpath(base)) == LADDER_DIR else os.path.join(base, LADDER_DIR)
            if not os.path.isdir(d):
                continue
            for lad in sorted(x for x in os.listdir(d) if x.startswith(f"mu{mu:g}_s")):
                out += [f"{lad}/{r}" for r in sorted(os.listdir(os.path.join(d, lad))) if r.startswith("kn")]
        return out

    def ladder_pending(self, mu, k_n=None):
        """Whether a paper-size ladder of friction ``mu`` has a rung directory (at ``k_n``, or any) under an
        input's ladder-size/ (converged or not: a converged one is a collected set)."""
        want = None if k_n is None else f"kn{fmt_kn(k_n)}"
        return any(want is None or d.endswith("/" + want) for d in self.ladder_dirs(mu))

    def pooled_scatter(self, results, sid, other, q):
        """The seed-to-seed standard deviation of ``q`` pooled over the sets of ``sid``'s N and μ, in this
        collect (``results`` None) or another's ``sets.csv`` (from each set's standard error and seeds); nan
        where ``other`` is of another N or μ, or no such set has two seeds."""
        if results is None:
            a, b = self.sets.get(sid), self.sets.get(other)
            if a is None or b is None or _n_mu(a) != _n_mu(b):
                return NAN
            return pooled_scatter([[r.q.get(q) for r in s.runs] for s in self.set_list
                                   if _n_mu(s) == _n_mu(a)])[0]
        rows = self.ext_sets(results)
        a, b = rows.get(sid), rows.get(other)
        if a is None or b is None or (_f(a.get("N")), _f(a.get("mu"))) != (_f(b.get("N")), _f(b.get("mu"))):
            return NAN
        ss = dof = 0
        for r in rows.values():
            n, sem = _count(r.get("n_seeds")), _f(r.get(f"{q}_sem"))
            if (_f(r.get("N")), _f(r.get("mu"))) == (_f(a.get("N")), _f(a.get("mu"))) and n >= 2 and finite(sem):
                ss += sem ** 2 * n * (n - 1)        # the set's sum of squares about its mean
                dof += n - 1
        return math.sqrt(ss / dof) if dof else NAN

    def ext_sets(self, results):
        key = ("sets", results)
        if key not in self._ext:
            path = os.path.join(self.out, results, "sets.csv")
            try:
                with open(path, newline="") as fh:
                    self._ext[key] = {r["set"]: r for r in csv.DictReader(fh)}
            except OSError:
                self._ext[key] = {}
        return self._ext[key]

    def ext_fits(self, results):
        key = ("fits", results)
        if key not in self._ext:
            try:
                with open(os.path.join(self.out, results, "fits.json")) as fh:
                    self._ext[key] = json.load(fh)
            except (OSError, ValueError):
                self._ext[key] = {}
        return self._ext[key]
