"""The one verdict rule of the claim table (``claims``, ``claimtable``), applied to every numeric row.

A claim of the paper is **reproduced** when this work's value lies within two combined standard errors
of the paper's: ``|ours - paper| <= 2 sigma``, ``sigma = sqrt(sigma_ours^2 + sigma_paper^2)``, where
``sigma_ours`` is this work's standard error (over seeds, pooled over sets, or a fit's) and
``sigma_paper`` the paper's stated error; where the paper states none, ``sigma_paper`` is a tolerance
taken from the paper's own text (the precision it quotes the number to, or a scatter it states), given
with its justification in the claim's row, never from this work's scatter. Otherwise the row **differs
by X (Y sigma)**, and is marked explained (the cause is found) or open. A bound ("z_inf > 4") is
reproduced when this work's value is beyond it by two errors, a range ("3-8e6 steps") when the value
lies inside it or within two errors of it. A value of one seed (no error of its own) takes the other
side's seed scatter in a difference (``sources.diff_error``), and alone is judged on the paper's error
(or by its side of a bound) and, where sets of its N and mu have two seeds, with their pooled seed
scatter as well (``claimtable._one_seed_alternative``: not determined where the two disagree), by its
side of a sign. A test's p value (one law, one curve) is reproduced at p >= 0.0455, the two-sided 2
sigma level. A value that rests on an assumed choice the measurements here do not fix (an exponent taken
from theory, where the data fit others as well; a window the paper does not name; a second reading of
the paper's error its text allows; a claim of one law tested both as a value and by its fit's p) is
judged with each alternative its row names as well (``claimtable.judge``); an alternative without a
number leaves the row not determined too. A claim set against a rival answer (``claims.Claim.rival``) is
reproduced only where the rival is not: a value within two errors of both, or a test that both pass, is
not determined. A row with nothing measured reads "not measured"; a fit that cannot tell its parameters
apart, or a value whose verdict changes with the assumed choice, "not determined".

Everything here is arithmetic on numbers already measured: nothing is tuned to a target.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

NAN = float("nan")
K = 2.0        # the rule's number of combined standard errors
P_K = 0.0455   # a test's p at K standard errors, two-sided: 1 - erf(K / sqrt(2))

RULE = (
    "**Reproduced**: this work's value lies within two combined standard errors of the paper's, "
    "|ours − paper| ≤ 2σ with σ = √(σ_ours² + σ_paper²); σ_ours is this work's standard error (over seeds, "
    "pooled over sets, or a fit's), σ_paper the paper's stated error, or, where the paper states none, the "
    "tolerance the row gives from the paper's own text (by default half a unit of the last digit the paper "
    "quotes; never this work's scatter). Otherwise **differs by X (Y σ)**, then **explained** (the cause is "
    "found and stated) or **open**. A bound (\"> 4\") is reproduced when the value lies beyond it by 2σ; "
    "a range (\"3–8e6\") when the value lies in it or within 2σ of it; a sign (\"falls\") when every step "
    "has the sign and lies 2σ from zero. A value of one seed has no error of its own: in a difference or a "
    "step with a side of two or more seeds it takes that side's seed scatter (one run's standard deviation), "
    "with two sides of one seed each the seed scatter pooled over the sets of its size and friction; "
    "alone it is judged on the paper's error or tolerance alone (against a bound by its side alone) and, where "
    "sets of its size and friction have two seeds or more, with their pooled seed scatter as its error, "
    "neither measured on it, so that a verdict that changes between the two is not determined (a depth "
    "window's single run takes that pooled scatter as its error throughout); against a sign by its side "
    "alone; each time the row says so. A claim that a family follows one law, or that sets collapse onto "
    "one curve, tested by a fit's χ² or an analysis of variance, is reproduced when the test's p ≥ 0.0455 "
    "(two-sided 2σ) and differs otherwise. A value's error is read as normal, as the paper's ± are (a row "
    "may give a Student reading beside where its scatter rests on few seeds); a test's p is its own "
    "statistic's (F where the noise is measured). A value that rests on an assumed choice the measurements "
    "here do not fix (an exponent taken from theory, where the data fit others as well; a window the paper "
    "does not name; a reading of the paper's error its text allows; a claim of one law tested both as a "
    "value and by its fit's χ² against F) is "
    "judged with each alternative the row names, with its reason, as well; none is dropped for its verdict. "
    "A claim the row sets against a rival answer (k_n^(−1/4) with friction against the frictionless k_n^(−1/2)) is "
    "reproduced only where the rival would not be. **not measured**: nothing of this work measures it (or "
    "the runs are still running); **not determined**: a fit that cannot tell its parameters apart, a value "
    "with no error against a claim with no tolerance, a value whose verdict changes with the assumed choice "
    "(the row gives each), or one that reproduces the rival as well. A claim of a figure's shape, with no "
    "number, is judged by eye and says so (**seen** / **not seen**). No method, window or default is chosen "
    "to land on the paper's number.")


@dataclass
class Verdict:
    """The outcome of the rule for one value: ``kind`` is 'reproduced', 'differs', 'not determined'
    or 'not measured'; ``diff`` ours minus the paper's (or the distance outside a bound or range),
    ``sigma`` the combined error and ``n_sigma`` |diff| / sigma (nan where there is no sigma)."""
    kind: str
    diff: float = NAN
    sigma: float = NAN
    n_sigma: float = NAN
    why: str = ""
    bound: bool = False     # a one-sided claim: n_sigma is the distance beyond the bound

    def text(self, digits=None):
        """The verdict in words: 'reproduced (0.8 σ)', 'differs by -0.0086 (3.4 σ)', for a bound
        'reproduced (beyond by 9.0 σ)', 'differs: +0.03 beyond the bound (1.5 σ, not 2)', ..."""
        if self.bound and self.kind in ("reproduced", "differs") and math.isfinite(self.n_sigma):
            w = f"; {self.why}" if self.why else ""
            if self.kind == "reproduced":
                return f"reproduced (beyond by {self.n_sigma:.1f} σ){w}"
            d = _num(self.diff, digits if digits is not None else _digits(self.sigma))
            return f"differs: {d} beyond the bound ({self.n_sigma:.1f} σ, not 2){w}"
        if self.kind == "reproduced":
            return "reproduced" + (f" ({self.n_sigma:.1f} σ)" if math.isfinite(self.n_sigma) else "") \
                + (f"; {self.why}" if self.why else "")
        if self.kind == "differs" and not (math.isfinite(self.n_sigma) and math.isfinite(self.diff)):
            return "differs" + (f"; {self.why}" if self.why else "")
        if self.kind == "differs":
            d = _num(self.diff, digits if digits is not None else _digits(self.sigma))
            return f"differs by {d} ({self.n_sigma:.1f} σ)" + (f"; {self.why}" if self.why else "")
        return self.kind + (f" ({self.why})" if self.why else "")


def _finite(x):
    return x is not None and isinstance(x, (int, float)) and math.isfinite(x)


def _digits(sigma):
    if not (_finite(sigma) and sigma > 0):
        return 3
    return min(max(1, 1 - math.floor(math.log10(sigma))), 8)


def _num(x, digits):
    return f"{x:+.{digits}f}"


def combined(err, paper_err):
    """sqrt(err^2 + paper_err^2) of the finite, positive ones; nan when neither is."""
    parts = [e for e in (err, paper_err) if _finite(e) and e > 0]
    return math.sqrt(sum(e * e for e in parts)) if parts else NAN


def _judge(diff, sigma, why=""):
    if not _finite(diff):
        return Verdict("not measured", why=why)
    if not (_finite(sigma) and sigma > 0):
        return Verdict("not determined", diff=diff,
                       why=why or "no error on either side: a single seed against a claim with no tolerance")
    n = abs(diff) / sigma
    # exactly 2 sigma is reproduced: a relative 1e-12 absorbs the rounding of the division
    return Verdict("reproduced" if n <= K * (1 + 1e-12) else "differs", diff, sigma, n, why)


def compare(value, err, paper, paper_err=None):
    """The rule for a value against the paper's: ``paper_err`` its stated error or the tolerance its text
    gives (None: none). A single value of this work without an error is judged on the paper's error alone,
    and the verdict says so."""
    if not _finite(value):
        return Verdict("not measured")
    why = "" if _finite(err) else "this work: 1 seed, no error; the paper's error alone"
    if not _finite(err) and not (_finite(paper_err) and paper_err > 0):
        why = ""
    return _judge(value - paper, combined(err, paper_err), why)


def bound(value, err, limit, above=True):
    """A one-sided claim: value > limit (``above``) or value < limit. Reproduced when the value is beyond
    the limit by 2 sigma; ``diff`` is the signed distance to the limit (positive on the claimed side)."""
    if not _finite(value):
        return Verdict("not measured")
    d = (value - limit) if above else (limit - value)
    if not (_finite(err) and err > 0):
        kind = "reproduced" if d > 0 else "differs"
        return Verdict(kind, d, why="1 seed, no error: judged by its side of the bound alone", bound=True)
    n = d / err
    return Verdict("reproduced" if n >= K * (1 - 1e-12) else "differs", d, err, abs(n), bound=True)


def in_range(value, err, lo, hi):
    """A range claim: reproduced when the value lies in [lo, hi] or within 2 sigma of it; ``diff`` the
    distance outside the range (0 inside)."""
    if not _finite(value):
        return Verdict("not measured")
    d = value - hi if value > hi else (value - lo if value < lo else 0.0)
    if d == 0.0:
        return Verdict("reproduced", 0.0, err if _finite(err) else NAN, 0.0)
    return _judge(d, err if _finite(err) else NAN)


def sign(steps, want=-1):
    """A sign claim over steps [(diff, err)]: reproduced when every step has the sign ``want`` and lies
    2 sigma from zero; a step without an error counts by its sign alone (and the verdict says so)."""
    if not steps or any(not _finite(d) for d, _ in steps):
        return Verdict("not measured")
    wrong = [i for i, (d, _) in enumerate(steps) if d * want <= 0]
    no_err = [i for i, (_, e) in enumerate(steps) if not (_finite(e) and e > 0)]
    weak = [i for i, (d, e) in enumerate(steps) if i not in no_err and abs(d) / e < K]
    if wrong:
        i = wrong[0]
        d, e = steps[i]
        return Verdict("differs", d, e if _finite(e) else NAN, abs(d) / e if _finite(e) and e > 0 else NAN,
                       f"step {i + 1} has the other sign")
    if weak:
        i = weak[0]
        d, e = steps[i]
        return Verdict("differs", d, e, abs(d) / e, f"step {i + 1} within 2 σ of zero")
    judged = [(i, abs(d) / e) for i, (d, e) in enumerate(steps) if i not in no_err]
    # the step nearest to zero, in errors: how far the weakest step stands
    least = min(judged, key=lambda t: t[1]) if judged else None
    whys = ([f"the nearest step to 0 (step {least[0] + 1}) {least[1]:.1f} σ"] if least else []) + \
        (["steps " + ", ".join(str(i + 1) for i in no_err) + " without an error (1 seed): judged by sign"]
         if no_err else [])
    return Verdict("reproduced", why="; ".join(whys))
