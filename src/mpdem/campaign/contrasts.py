"""Sets that differ from a reference set in one setting only: the paper's claims that a setting changes
nothing (docs/model.md 7): the initial kinetic energy K0, the contact law (Hooke or Hertz), the
construction (phi_i) at mu = 0, the tangential damping gamma_t.

For each family of sets equal in everything but one of ``VARY``, each set is set against the family's
set at that key's default (the reference): the difference of its z and phi (slab, mean over seeds) from
the reference's, with the error from the seed scatter pooled over the family's sets (``pooled_scatter``:
s sqrt(1/n + 1/n_ref)), t = difference / error and the two-sided p of Student's t with the pooled degrees
of freedom. p large: no difference the seeds can see; the difference and its error say how large one
could be.
"""
from __future__ import annotations

import math

from ..analysis.fits import one_way_anova, pooled_scatter
from ..config import KEYS
from .runs import NAN, SHORT, families, fmt_pm, md_table

VARY = ("pour.K0", "contact.model", "pour.phi_i", "contact.gamma_t")
QUANTITIES = ("z", "phi")
DIGITS = {"z": 3, "phi": 4}


def contrast(members, vary):
    """The sets of one family (differing in ``vary`` only) against the one at ``vary``'s default.

    Returns
    -------
    None without a set at the default, else dict: ``vary`` (short name), ``reference`` (its set id)
    and ``value``, ``rows``: per other set ``set``, ``value``, ``n_seeds``, ``n_ref`` and per quantity
    {``diff``, ``err``, ``t``, ``p``, ``dof``} (err, t and p nan without pooled degrees of freedom); with
    two other sets or more ``among``: their ``sets``, ``values`` and per quantity a one-way analysis of
    variance among them (``one_way_anova``: do the sets away from the default differ among themselves?).
    """
    from scipy import stats

    default = KEYS[vary].default
    ref = [s for s in members if s.params[vary] == default]
    if len(ref) != 1:
        return None
    ref = ref[0]
    out = {"vary": SHORT[vary], "reference": ref.id, "value": default, "rows": []}
    scatter = {q: pooled_scatter([[r.q[q] for r in m.runs] for m in members]) for q in QUANTITIES}
    for s in members:
        if s is ref:
            continue
        row = {"set": s.id, "value": s.params[vary], "n_seeds": len(s.runs), "n_ref": len(ref.runs)}
        for q in QUANTITIES:
            sd, dof = scatter[q]
            m1, _, n1 = s.stat(q)
            m0, _, n0 = ref.stat(q)
            d = m1 - m0
            err = sd * math.sqrt(1 / n1 + 1 / n0) if dof and n1 and n0 else NAN
            t = d / err if err > 0 else NAN
            p = float(2 * stats.t.sf(abs(t), dof)) if math.isfinite(t) else NAN
            row[q] = {"diff": d, "err": err, "t": t, "p": p, "dof": dof}
        out["rows"].append(row)
    others = [s for s in members if s is not ref]
    if len(others) >= 2:
        # among the sets away from the default (the paper's K0 = 20-100, say): one-way analysis of variance
        out["among"] = {"sets": [s.id for s in others], "values": [s.params[vary] for s in others],
                        **{q: one_way_anova([[r.q[q] for r in s.runs] for s in others]) for q in QUANTITIES}}
    return out


def contrasts(sets):
    """``contrast`` of every family of sets differing in one key of ``VARY`` (two sets or more)."""
    out = []
    for vary in VARY:
        for fam, members in families(sets, vary):
            if len(members) >= 2:
                c = contrast(members, vary)
                if c is not None:
                    out.append(dict(family=fam, **c))
    return out


def section(entries, fam_text):
    """README lines: one table row per set against its reference."""
    L = ["## One setting changed: does it change the packing? (the paper's \"changes nothing\" claims)", "",
         "Sets equal in all but one of " + ", ".join(SHORT[k] for k in VARY) + ", each against the set at that "
         "key's default: the difference of z and φ (slab, mean over seeds) with the error from the seed "
         "scatter pooled over the family (s √(1/n + 1/n_ref)), and the two-sided p of t. p large: no "
         "difference the seeds can see.", ""]
    rows = []
    for e in entries:
        for r in e["rows"]:
            cells = [f"{e['vary']} = {r['value']} vs {e['value']}", f"{r['set']} vs {e['reference']}",
                     fam_text(e["family"], (e["vary"],)), f"{r['n_seeds']} / {r['n_ref']}"]
            for q in QUANTITIES:
                c = r[q]
                cells += [fmt_pm(c["diff"], c["err"], DIGITS[q]),
                          f"{c['p']:.2g}" if math.isfinite(c["p"]) else "—"]
            rows.append(cells)
    if not rows:
        return L + ["No set differs from another in one of these settings alone.", ""]
    L.append(md_table(["changed", "sets", "family", "seeds", "Δz", "p (z)", "Δφ", "p (φ)"], rows))
    among = [e for e in entries if "among" in e]
    if among:
        L += ["", "Among the sets away from the default (one-way analysis of variance against their pooled seed "
              "scatter):", ""]
        for e in among:
            a = e["among"]
            ps = "; ".join(f"{q}: F = {a[q]['F']:.2f} ({a[q]['dof'][0]}, {a[q]['dof'][1]}), p = {a[q]['p']:.2g}"
                           if math.isfinite(a[q]["p"]) else f"{q}: not tested (no seed scatter)" for q in QUANTITIES)
            L.append(f"- {e['vary']} = {', '.join(map(str, a['values']))} ({', '.join(a['sets'])}): {ps}")
    return L + [""]
