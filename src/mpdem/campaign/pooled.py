"""Measures pooled over the seeds of a set, and fitted over the sets of a family (``mpdem collect``;
docs/model.md 6.5, 6.6, 6.10).

- alpha on every window of the runs' summaries: the gap statistics (n, sum
  ln xi) of the seeds add, the pooled estimate has its Fisher error, and a
  bootstrap over the seeds gives the error that includes their scatter;
- the local slope curve, pooled the same way;
- P(f), pooled counts;
- the depth profile averaged over seeds, band by band;
- z against the overlap: z - z_c = A (delta / d)^(1/2) over the depth bands
  inside the bulk of every run of a family (every k_n), z_c with a bootstrap
  error over runs (over piles for a stiffening ladder).

Runs analysed before these measures existed (no ``alpha_windows``, ``bands``
or ``P_f`` in their summary.json) are left out of them, and counted.
"""
from __future__ import annotations

import math
import warnings
from fractions import Fraction

import numpy as np

from ..analysis import bands, fits, nearcontact
from .ladder import K_FROM, piles
from .runs import fmt_pm


def _have(s, key):
    return [r for r in s.runs if r.s.get(key)]


def set_alpha(s):
    """alpha of a set on each window, pooled over its seeds.

    Returns
    -------
    None when no run has window statistics, else dict: ``windows`` (list of
    pooled window dicts with ``boot_err`` (bootstrap over seeds), ``n_runs``,
    ``soft`` (any run marked it)), ``local`` (pooled local-slope points).
    """
    runs = _have(s, "alpha_windows")
    if not runs:
        return None
    out = {"n_runs": len(runs), "windows": [], "local": []}
    for k, w in enumerate(runs[0].s["alpha_windows"]):
        st = [r.s["alpha_windows"][k] for r in runs if len(r.s["alpha_windows"]) > k
              and (r.s["alpha_windows"][k]["xi_lo"], r.s["alpha_windows"][k]["xi_hi"]) == (w["xi_lo"], w["xi_hi"])]
        p = nearcontact.pooled(st)
        p.update(boot_err=nearcontact.bootstrap(st), n_runs=len(st), soft=any(x.get("soft") for x in st),
                 alpha_runs=[x["alpha"] for x in st])
        out["windows"].append(p)
    centres = [pt["xi"] for pt in runs[0].s.get("alpha_local") or []]
    for k, c in enumerate(centres):
        st = [r.s["alpha_local"][k] for r in runs if len(r.s.get("alpha_local") or []) > k
              and r.s["alpha_local"][k]["xi"] == c]
        out["local"].append(dict(nearcontact.pooled(st), xi=c, n_runs=len(st)))
    return out


def set_force_distribution(s):
    """P(f) of a set: the runs' counts and sums added (None without P_f in any run)."""
    runs = _have(s, "P_f")
    if not runs:
        return None
    keys = ("n", "n_beyond", "n_small", "n_tail", "tail_sum")
    tot = {k: sum(r.s["P_f"][k] for r in runs) for k in keys}
    nb = min(len(r.s["P_f"]["counts"]) for r in runs)
    tot["counts"] = np.sum([r.s["P_f"]["counts"][:nb] for r in runs], axis=0).tolist()
    tot["P"] = bands.density(tot["counts"], tot["n"])
    tot.update(bands.tail_and_small(tot), n_runs=len(runs))
    return tot


def set_depth(s):
    """The depth profile of a set: per band (from the surface), the mean over the runs that reach it."""
    runs = _have(s, "bands")
    if not runs:
        return None
    nb = max(len(r.s["bands"]["z"]) for r in runs)
    out = {"n_runs": len(runs)}
    for col in ("depth_lo", "depth_hi", "z", "z_backbone", "phi", "overlap_mean", "sigma_zz", "crystal_fraction",
                "rattler_fraction"):
        vals = np.full((len(runs), nb), np.nan)
        for i, r in enumerate(runs):
            v = np.array([np.nan if x is None else x for x in r.s["bands"][col]], float)
            vals[i, :len(v)] = v
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)     # a band no run has: nan
            out[col] = np.nanmean(vals, axis=0).tolist()
    inb = np.zeros(nb, bool)
    for r in runs:
        b = r.s["bands"]["in_bulk"]
        inb[:len(b)] |= np.asarray(b, bool)
    out["in_bulk"] = inb.tolist()
    return out


# The exponent of z - z_c = A (delta/d)^x: 1/2 from theory (z - z_c ~ (phi - phi_c)^(1/2) and delta ~
# phi - phi_c for both laws), which the bands do not fix: they fit 1/3 to 2/3 alike (docs/model.md 6.6).
# A claim that rests on it is judged again with each of OVERLAP_ALTERNATIVES, a bracket of 1/6 on either
# side (``claimtable``); the fit is kept with each as ``exponent_part``.
OVERLAP_EXPONENT = 0.5
OVERLAP_ALTERNATIVES = (1 / 3, 2 / 3)


def exponent_part(x):
    """The name of an overlap fit entry's part fitted with exponent ``x``: 'exponent 1/3' (a fraction of
    denominator 12 at most: an exponent that is none has no part name)."""
    f = Fraction(x).limit_denominator(12)
    if not math.isclose(float(f), x, rel_tol=1e-12):
        raise ValueError(f"overlap exponent {x!r}: a part is named by a fraction of denominator 12 at most")
    return f"exponent {f.numerator}/{f.denominator}"


def overlap_fit(members, exponent=OVERLAP_EXPONENT, alternatives=()):
    """z - z_c = A (delta / d)^exponent over the bulk depth bands of every run of a family's sets, and
    whether the bands of its k_n collapse on that one curve (``fits.collapse``).

    A stiffening ladder's sets (any member stiffened, its base set with them: ``ladder.with_base``) are its
    piles again at each rung: the error's bootstrap then resamples piles (``ladder.pile``), each
    with its runs at every rung; elsewhere each run is a sample of its own. A ladder's fit is ``determined``
    only where two piles or more have bands at two k_n or more: with one, the bootstrap only says whether
    that pile was drawn (the others' bands lie at one k_n, over a narrow range of the overlap).

    Parameters
    ----------
    members : sets (``runs.Set``) of one family
    exponent : float, the exponent x of the overlap
    alternatives : exponents to fit the same bands with as well, each kept as the part
        ``exponent_part(x)`` (its z_c, error, rms, collapse, piles), for a claim judged with each

    Returns
    -------
    dict with the fit (``fits.fit_overlap``) and the sets and runs used, or
    status "not fitted" with the reason.
    """
    stiffened = any(K_FROM in s.extra for s in members)
    have = [(s, r) for s in members for r in _have(s, "bands")]
    units = piles([r for _, r in have]) if stiffened else [r.path for _, r in have]
    delta, z, grp, smp, k_n, used, samples, levels = [], [], [], [], [], [], {}, {}
    for (s, r), key in zip(have, units):
        b = r.s["bands"]
        unit = samples.setdefault(key, len(samples))
        for k, inb in enumerate(b["in_bulk"]):
            if inb and b["overlap_mean"][k] is not None and b["z"][k] is not None:
                delta.append(b["overlap_mean"][k])
                z.append(b["z"][k])
                grp.append(len(used))
                smp.append(unit)
                k_n.append(s.params["contact.k_n"])
                levels.setdefault(unit, set()).add(s.params["contact.k_n"])
        used.append(r.path)
    e = {"sets": [s.id for s in members], "runs": used}
    if len(used) < 2 or len(z) < 3:
        e.update(status="not fitted", reason=f"{len(used)} runs with depth profiles and {len(z)} bulk bands "
                                             f"(the fit needs 2 runs and 3 bands)")
        return e
    climbed = sum(len(v) >= 2 for v in levels.values())
    for x in (exponent, *(a for a in alternatives if not math.isclose(a, exponent))):
        f = {"status": "fitted", **fits.fit_overlap(delta, z, grp, level=k_n, sample=smp, exponent=x)}
        if stiffened:
            f.update(n_piles=f["n_samples"], n_piles_climbed=climbed, determined=climbed >= 2)
            if climbed < 2:
                f["reason"] = (f"{climbed} of its {f['n_samples']} piles with bands at two k_n or more: the "
                               f"bootstrap over piles needs two")
        if x == exponent:
            e.update(f)
        else:
            e[exponent_part(x)] = f
    return e


def z_c_text(e, why=True):
    """An overlap fit's z_c with its error; where it has none (a ladder one pile climbed: ``determined``
    False), without, saying why (``why``) or, shorter, how many piles climbed."""
    if e.get("determined") is False:
        tail = e.get("reason", "") if why else f"{e.get('n_piles_climbed', 0)} pile climbed"
        return f"{e['z_c']:.3f} (no error: {tail})"
    return fmt_pm(e["z_c"], e["z_c_err"], 3)


def eq7_sigma(members, q="z"):
    """The weights of eq. 7: the family's pooled seed scatter over sqrt(n) per set.

    Returns
    -------
    (sigma (n_sets,) or None, scatter, dof): None when no set has two seeds.
    """
    scatter, dof = fits.pooled_scatter([[r.q[q] for r in s.runs] for s in members])
    if not math.isfinite(scatter) or scatter <= 0:
        return None, scatter, dof
    return np.array([scatter / math.sqrt(len(s.runs)) for s in members]), scatter, dof
