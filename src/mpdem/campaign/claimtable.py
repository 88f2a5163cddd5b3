"""The claim table of ``mpdem collect``: each claim of ``claims.CLAIMS`` measured (``sources``) and judged
by the one rule of ``verdict``.

``row`` judges one claim: its first source with a number (``Measure``) by the claim's kind (compare, bound,
nonzero, range, sign, test; a qualitative claim by eye), the others beside it with their distance from the
paper's value; a row that differs carries the claim's curated reason (explained or open), or "open: no
cause found". ``rows`` judges them all, ``table`` and ``section`` write them as Markdown for README.md.
"""
from __future__ import annotations

import dataclasses

import math

from . import verdict as V
from .runs import md_table
from .sources import NAN, diff_error, finite, missing


# ---------------------------------------------------------------- judging a claim

def judge(claim, m, ctx=None):
    """The rule (``verdict``) for measure ``m`` of ``claim`` (a ``claims.Claim``). A number that rests on an
    assumed choice (``m.alts``: ``sources.Assumes``, an alternative of the claim's kind or a fit's p beside
    a value) or a paper error its text allows to read otherwise (``Claim.err_alternatives``) is judged with
    each alternative too (``_judge_assumed``): where every one gives the same verdict it stands, and says
    so; where one gives another, or has no number, the claim is not determined by it, and the verdict
    gives each. A claim with a ``rival`` is reproduced only where the
    rival is not (``_against_rival``; ``ctx`` resolves a rival source)."""
    return _against_rival(claim, m, _judge_assumed(claim, m), ctx)


def _against_rival(claim, m, v, ctx):
    """A reproduced verdict that the claim's rival would get as well: not determined, saying so."""
    if claim.rival is None or v.kind != "reproduced" or not m.ok:
        return v
    label, r = claim.rival
    if claim.kind == "compare":
        rv = V.compare(m.value, m.err, r, claim.paper_err)
        if rv.kind == "reproduced":
            return V.Verdict("not determined", why=f"within 2 σ of the paper's {claim.paper} ({v.n_sigma:.1f} σ) "
                                                    f"and of {label} ({rv.n_sigma:.1f} σ): it cannot tell them apart")
        v.why = "; ".join(w for w in (v.why, f"{label} {rv.n_sigma:.1f} σ away") if w)
        return v
    if claim.kind == "test":
        # a part name: the same fit of this measure's own source with the rival law (each family its own)
        with_part = getattr(m.source, "with_part", None)
        src = with_part(r) if isinstance(r, str) and with_part is not None \
            else r if hasattr(r, "resolve") else None
        rm = src.resolve(ctx) if ctx is not None and src is not None else None
        if rm is None or not rm.ok:
            return V.Verdict("not determined", why=f"{v.why}; {label}: " + (
                f"{rm.status} ({rm.why})" if rm is not None else "not resolved") + ": not told apart")
        if rm.value >= V.P_K:
            return V.Verdict("not determined", why=f"{v.why}, and {label} p = {rm.value:.2g}: the test does not "
                                                    f"tell them apart")
        v.why = f"{v.why}: not rejected; {label}: p = {rm.value:.2g}, rejected"
        return v
    raise ValueError(f"claim {claim.id}: a rival for kind {claim.kind!r}")


ONE_SEED = "1 seed with no error of its own"


def _one_seed_alternative(claim, m):
    """A value of one run alone with no error: judged as it is (on the paper's error, or by its side of a
    bound) and with the seed scatter pooled over the sets of its N and μ as its error (``m.pooled_sd``):
    neither is measured on it, so a verdict that changes with the reading is not determined (the rule)."""
    if m.alts or claim.err_alternatives or claim.kind == "test" or m.n != 1 or finite(m.err) \
            or not finite(m.pooled_sd):
        return []
    label = f"the seed scatter pooled over its N and μ's sets (±{m.pooled_sd:.2g}) as its error"
    return [(label, dataclasses.replace(m, err=m.pooled_sd, pooled_sd=NAN), None)]


def _judge_assumed(claim, m):
    """``_judge_one`` of ``m``, then of each alternative of ``m`` (``m.alts``; a value of one run alone:
    ``_one_seed_alternative``) or of the paper's error (``claim.err_alternatives``, the same ``m`` against
    another error; a claim has one kind or the other)."""
    v = _judge_one(claim, m)
    one = _one_seed_alternative(claim, m) if m.ok else []
    if not (m.alts or one or claim.err_alternatives) or v.kind not in ("reproduced", "differs"):
        return v
    if m.alts and claim.err_alternatives:
        raise ValueError(f"claim {claim.id}: alternative measures and alternative paper errors at once")
    alts = [(label, a, _judge_one(claim, a, kind) if a.ok else None, kind or claim.kind)
            for label, a, kind in m.alts + one]
    # the paper's error read otherwise (``Claim.err_alternatives``): the same number against each
    alts += [(label, m, _judge_one(dataclasses.replace(claim, paper_err=err), m), "tolerance")
             for label, err in claim.err_alternatives]
    assumption = m.assumption if m.alts else ONE_SEED if one else claim.err_assumption

    def value(a, av, kind):
        # a test's number is its p, which its verdict names; another tolerance's, its distance
        return av.why if kind == "test" else f"{av.n_sigma:.1f} σ" if kind == "tolerance" \
            else _mtext(a, claim.digits, where=False)

    if all(av is not None and av.kind == v.kind for _, _, av, _ in alts):
        same = ", ".join(f"{label} ({value(a, av, k)})" for label, a, av, k in alts)
        v.why = "; ".join(w for w in (v.why, f"the same with {same} in place of {assumption}") if w)
        return v
    # a test's verdict names its p, another tolerance's the same number; every other verdict takes its value
    # and error first (a 'differs by X' names the distance from the paper's, not the value)
    each = "; ".join(f"with {label}: " + (
        f"{a.status} ({a.why})" if av is None
        else av.text() if k in ("test", "tolerance")
        else f"{value(a, av, k)}, {av.text()}") for label, a, av, k in alts)
    return V.Verdict("not determined", why=f"it rests on {assumption}: with it {v.text()}; {each}")


def _judge_one(claim, m, kind=None):
    """The rule for measure ``m`` by the claim's kind, or by ``kind`` (an alternative measure of another kind:
    ``sources.Assumes``)."""
    if m.status in ("not measured", "running"):
        return V.Verdict("not measured", why=("running: " if m.status == "running" else "") + m.why)
    if m.status == "not determined":
        return V.Verdict("not determined", why=m.why)
    kind = kind or claim.kind
    if kind == "compare":
        target = claim.value(m) if callable(claim.value) else claim.value
        return V.compare(m.value, m.err, target, claim.paper_err)
    if kind == "bound":
        return V.bound(m.value, m.err, claim.value, claim.above)
    if kind == "range":
        return V.in_range(m.value, m.err, *claim.value)
    if kind == "nonzero":
        return V.bound(abs(m.value), m.err, 0.0)
    if kind == "test":
        # one curve: the test of equal means not rejected at two standard errors (two-sided)
        return V.Verdict("reproduced" if m.value >= V.P_K else "differs", why=f"p = {m.value:.2g}")
    raise ValueError(f"claim {claim.id}: unknown kind {kind!r}")


def _sign_verdict(claim, ctx):
    ms = [src.resolve(ctx) for src in claim.ours]
    if not all(m.ok for m in ms):
        bad = next(m for m in ms if not m.ok)
        return ms, V.Verdict("not measured", why=f"{bad.where}: {bad.why}")
    # a step's error as a difference's (``sources.diff_error``: a side of one seed takes the other's seed
    # scatter); a step between two sides of one seed has none and is judged by its sign (``verdict.sign``)
    errs = [diff_error(b, a) for a, b in zip(ms, ms[1:])]
    v = V.sign([(b.value - a.value, e) for (a, b), (e, _) in zip(zip(ms, ms[1:]), errs)], claim.value)
    lent = [str(i + 1) for i, (_, borrowed) in enumerate(errs) if borrowed]
    if lent and v.kind in ("reproduced", "differs"):
        v.why = "; ".join(w for w in (v.why, f"step{'s' if len(lent) > 1 else ''} {', '.join(lent)}: a side "
                                              "of 1 seed with the other's seed scatter") if w)
    return ms, v


def row(claim, ctx):
    """One judged claim: dict with the claim, the paper's number, this work's (text), count, verdict
    (``Verdict`` and text), the reason (explained / open) where it differs, and the context measures."""
    if claim.kind == "qualitative":
        ms = [src.resolve(ctx) for src in claim.ours]
        v = V.Verdict(claim.seen if ms and all(m.ok for m in ms) or not claim.ours else "not measured",
                      why=claim.by_eye)
        ours = "; ".join(_mtext(m, claim.digits) for m in ms) or "figure"
        count = "; ".join(m.count for m in ms if m.ok)
    elif claim.kind == "sign":
        ms, v = _sign_verdict(claim, ctx)
        ours = ", ".join(_mtext(m, claim.digits) for m in ms)
        count = "; ".join(m.count for m in ms if m.ok)
    elif claim.kind == "none":
        v = V.Verdict("not measured", why=claim.why_none)
        ours, count = "—", "—"
    else:
        m = _first(claim.ours, ctx)
        v = judge(claim, m, ctx)
        ours = _mtext(m, claim.digits) if m.ok else "—"
        count = m.count if m.ok else "—"
    reason = ""
    if v.kind == "differs":
        reason = f"{claim.if_differs[0]}: {claim.if_differs[1]}" if claim.if_differs else "open: no cause found"
    ctxt = []
    for src in claim.also:
        m = src.resolve(ctx)
        if claim.judge_also and claim.kind in ("compare", "bound", "range", "nonzero", "test") and m.ok:
            m.source = src
            cv = judge(claim, m, ctx)
            ctxt.append(f"{m.where}: {_mtext(m, claim.digits, where=False)} ({m.count}; {_short(cv, claim.kind)})")
        else:
            ctxt.append(f"{m.where}: {_mtext(m, claim.digits, where=False)}" + (f" ({m.count})" if m.ok else ""))
    return {"id": claim.id, "claim": claim.claim, "paper": claim.paper_text(), "ours": ours, "count": count,
            "verdict": v, "verdict_text": v.text(), "reason": reason, "context": "; ".join(ctxt),
            "note": claim.note}


def _first(sources, ctx):
    """The first source with a number; else the first 'not determined', 'running', or the first source, its
    reason followed by those of the later sources of that status (each source a way the row could be measured)."""
    ms = [src.resolve(ctx) for src in sources]
    for src, m in zip(sources, ms):
        m.source = src
    for status in ("ok", "not determined", "running"):
        for m in ms:
            if m.ok if status == "ok" else m.status == status:
                if status != "ok":
                    whys = list(dict.fromkeys(x.why for x in ms if x.status == status and x.why))
                    m = dataclasses.replace(m, why="; else: ".join(whys))
                return m
    return ms[0] if ms else missing("", "no source")


def _short(v, kind="compare"):
    """A context measure's distance from the claim in words."""
    if v.kind == "not determined" and v.why:
        return f"not determined: {v.why}"
    if kind == "test":
        said = v.why.endswith("rejected")      # a rival's verdict says it already
        return v.why if said else f"{v.why}: " + ("not rejected" if v.kind == "reproduced" else "rejected")
    if v.kind not in ("reproduced", "differs"):
        return v.kind
    if kind in ("bound", "nonzero") and not math.isfinite(v.n_sigma):
        return ("beyond" if v.kind == "reproduced" else "not beyond") + " (1 seed, no error: by its side alone)"
    n = f"{v.n_sigma:.1f} σ"
    if kind in ("bound", "nonzero"):
        return f"beyond by {n}" if v.kind == "reproduced" else f"not beyond ({n})"
    return f"within 2 σ ({n})" if v.kind == "reproduced" else f"{n} away"


def _mtext(m, digits=None, where=True):
    if not m.ok:
        return f"{m.status}" + (f" ({m.why})" if m.why else "") if not where else \
            f"{m.where}: {m.status}" + (f" ({m.why})" if m.why else "")
    if digits is None:
        txt = _pm(m.value, m.err)
    else:
        txt = f"{m.value:.{digits}f}" + (f" ± {m.err:.{digits}f}" if finite(m.err) else "")
    return f"{txt} ({m.where})" if where else txt


def _pm(v, e):
    """value ± error with two significant digits of the error; a value alone in 4 significant digits."""
    if abs(v) and (abs(v) < 1e-3 or abs(v) >= 1e5):
        return f"{v:.2e}" + (f" ± {e:.1e}" if finite(e) else "")
    if finite(e) and e > 0:
        d = min(max(0, 1 - math.floor(math.log10(e))), 8)
        return f"{v:.{d}f} ± {e:.{d}f}"
    return f"{v:.4g}" + (" ± 0" if finite(e) and e == 0 else "")


def rows(claims_, ctx):
    """Every claim judged (``row``), in order."""
    return [row(c, ctx) for c in claims_]


def counts(judged):
    """{verdict kind: number of rows}."""
    out = {}
    for r in judged:
        out[r["verdict"].kind] = out.get(r["verdict"].kind, 0) + 1
    return out


def table(judged):
    """The claim table in Markdown (one string)."""
    head = ["#", "claim", "paper", "this work", "samples", "verdict", "other sizes, windows", "note"]
    body = []
    for r in judged:
        verdict = f"**{r['verdict_text']}**" + (f"; {r['reason']}" if r["reason"] else "")
        body.append([r["id"], r["claim"], r["paper"], r["ours"], r["count"], verdict, r["context"] or "—",
                     r["note"] or ""])
    return md_table(head, body)


def section(judged):
    """README lines: the rule, the counts and the table."""
    c = counts(judged)
    order = ("reproduced", "differs", "not determined", "not measured", "seen", "not seen")
    tally = ", ".join(f"{c[k]} {k}" for k in order if c.get(k)) + "".join(
        f", {v} {k}" for k, v in c.items() if k not in order)
    diff = [r for r in judged if r["verdict"].kind == "differs"]
    expl = sum(1 for r in diff if r["reason"].startswith("explained"))
    return ["## The paper, claim by claim", "",
            "The rule, one for every row: " + V.RULE, "",
            f"Counts: {tally} ({expl} of the {len(diff)} that differ explained, {len(diff) - expl} open). "
            "Paper size: N = 20 000 in 20 d × 20 d; the slab is the bulk of docs/model.md 6.1, 10–30 d the fixed "
            "window below the surface. Made by `mpdem collect` from the claims of `src/mpdem/campaign/claims.py` "
            "and the tables of this directory (and of `analysis/results/dev` and `ladder-dev/` where a row says "
            "so).", "", table(judged), ""]
