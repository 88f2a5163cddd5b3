"""Stiffening ladders among the collected sets (``fits.json`` 'ladder'; physics.md 6.6).

A rung is a set stiffened from a settled pile (``stiffen.k_n_from`` set: ``Set.extra``), so it is
never grouped with a pile poured at the same k_n (a different protocol). The rungs of one ladder are
one family of ``runs.families`` (their rise k_n / k_n_from the same); its base is the poured set of the
same parameters at the lowest rung's k_n_from. For each ladder: the rungs (k_n, z with its error and
count, the overlaps, alpha, the 10-30 d window), and eq. 7 fitted with alpha_n free over the base and
the rungs once they give 4 distinct k_n (3 parameters and one degree of freedom), else why not.
"""
from __future__ import annotations

import math

from .runs import families

K_FROM = "stiffen.k_n_from"
# the stop rule's settings: a ladder's base may differ from its rungs in them (``_base``)
STOP = "stop."
MIN_K_N = 4     # distinct k_n for eq. 7 with alpha_n free: 3 parameters and a degree of freedom
RUNG_QUANTITIES = ("z", "z_no_rattlers", "phi", "alpha", "overlap_median", "overlap_max", "step", "z_10_30")


def _base(rungs, sets):
    """The poured set a ladder starts from: no setting away from its default, the rungs' parameters but
    k_n (and what follows k_n), at the lowest rung's k_n_from; where none has the rungs' own stop rule,
    the one that differs from them only in it (a ladder's rungs may stop on the translational energy, a
    spinner holding the total, while its pile was poured on the default: ``STOP_ENERGY`` of ladder.sh)."""
    from .runs import family_key
    low = min(rungs, key=lambda s: s.p("k_n"))
    k0 = low.extra[K_FROM]
    extra = {k: v for k, v in low.extra.items() if k != K_FROM}
    for strip in (False, True):
        want_extra = {k: v for k, v in extra.items() if not (strip and k.startswith(STOP))}
        want = family_key(low.params, "contact.k_n", want_extra)
        for s in sets:
            if K_FROM in s.extra or s.p("k_n") != k0:
                continue
            got = {k: v for k, v in s.extra.items() if not (strip and k.startswith(STOP))}
            if got == want_extra and family_key(s.params, "contact.k_n", got) == want:
                return s
    return None


def _rung(s):
    out = {"set": s.id, "k_n": s.p("k_n"), "k_n_from": s.extra[K_FROM], "n_runs": len(s.runs), "seeds": s.seeds}
    for q in RUNG_QUANTITIES:
        m, e, n = s.stat(q)
        out[q] = m
        out[f"{q}_sem"] = e if math.isfinite(e) else None
    return out


def ladders(sets, fit_one):
    """{'family', 'base', 'rungs', 'sets', 'status', ...} per ladder; ``fit_one(family, members)``: the eq. 7 fit
    entry of a list of sets (``collect._fit_one``), merged in when there are enough k_n."""
    out = []
    stiff = [s for s in sets if K_FROM in s.extra]
    for fam, rungs in families(stiff, "contact.k_n"):
        base = _base(rungs, sets)
        members = ([base] if base is not None else []) + sorted(rungs, key=lambda s: s.p("k_n"))
        e = {"family": fam, "base": base.id if base is not None else None,
             "rungs": [_rung(s) for s in rungs], "sets": [s.id for s in members],
             "n_runs": sum(len(s.runs) for s in members)}
        k = len({s.p("k_n") for s in members})
        if k < MIN_K_N:
            e.update(status="not fitted", reason=f"{k} distinct k_n (the base and {len(rungs)} converged rung(s)); "
                                                 f"eq. 7 with alpha_n free needs {MIN_K_N}")
        else:
            fit = fit_one(fam, members)
            e.update({kk: v for kk, v in fit.items() if kk not in ("family", "sets")})
        out.append(e)
    return out
