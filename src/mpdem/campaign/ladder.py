"""Stiffening ladders among the collected sets (``fits.json`` 'ladder'; docs/model.md 6.6).

A rung is a set stiffened from a settled pile (``stiffen.k_n_from`` set: ``Set.extra``), so it is
never grouped with a pile poured at the same k_n (a different protocol). The rungs of one ladder are
one family of ``runs.families`` (their rise k_n / k_n_from the same); its base is the poured set of the
same parameters at the lowest rung's k_n_from. For each ladder: the rungs (k_n, z with its error and
count, the overlaps, alpha, the 10-30 d window), and eq. 7 fitted with alpha_n free over the base and
the rungs once they give 4 distinct k_n (3 parameters and one degree of freedom), else why not.

The rungs are the base's piles again (``pile``), each keeping its offset from rung to rung, so eq. 7 is
fitted over every run with the covariance of runs of one pile (``fits.fit_eq7_piles``): the scatter of
independent piles (each pile's first run), and the noise of one pile from rung to rung (the residual of
the piles that climbed the same rungs, ``within_pile_noise``). The fit of the sets' means as if they
were independent is kept beside it (``set_means``) for comparison.
"""
from __future__ import annotations

import functools
import math
import os
import tomllib
import warnings

import numpy as np
from scipy.stats import norm, t as t_dist

from ..analysis import fits
from . import paper
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


def with_base(members, sets):
    """A family's sets with the poured set its ladder starts from first (``_base``) where every member is a
    stiffened rung; any other family as it is."""
    if not members or not all(K_FROM in s.extra for s in members):
        return list(members)
    base = _base(members, sets)
    return ([base] if base is not None else []) + list(members)


def _rung(s):
    out = {"set": s.id, "k_n": s.p("k_n"), "k_n_from": s.extra[K_FROM], "n_runs": len(s.runs), "seeds": s.seeds}
    for q in RUNG_QUANTITIES:
        m, e, n = s.stat(q)
        out[q] = m
        out[f"{q}_sem"] = e if math.isfinite(e) else None
    return out


def pile(run):
    """A pile's identity along a ladder (a rung is its pour stiffened): its seed, its bed's seed and the k_n
    it was poured at (``poured_k_n``). A pour is a pure function of its parameters and seeds, so a pile
    poured again with the same ones is the same pile, and one poured at 2e6 is not the pile of the same
    seeds poured at 2e5 and stiffened. A run directory without a readable config.toml (a summary alone)
    is named by its seeds alone (``piles`` warns where a family mixes the two)."""
    k = poured_k_n(run.path)
    key = (run.params["run.seed"], run.bed_seed)
    return key if k is None else (*key, k)


def piles(runs):
    """``pile`` of each run, warning where some are named by their seeds alone and others by their pour:
    the same pile would then count as two."""
    keys = [pile(r) for r in runs]
    if len({len(k) for k in keys}) > 1:
        n = sum(len(k) == 2 for k in keys)
        warnings.warn(f"{n} of {len(keys)} runs have no readable config.toml to follow back to their pour: "
                      f"named by their seeds alone, their piles may count twice", stacklevel=2)
    return keys


def _read_config(path):
    try:
        with open(os.path.join(path, "config.toml"), "rb") as fh:
            c = tomllib.load(fh)
        start = c["run"].get("initial_file") or ""
        return float(c["contact"]["k_n"]), float((c.get("stiffen") or {}).get("k_n_from") or 0.0), start
    except (OSError, ValueError, KeyError, TypeError):     # tomllib.TOMLDecodeError is a ValueError
        return None


def _started_from(path, start):
    """The run directory of the state a run started from (``run.initial_file``): as written (a checkpoint's
    run: the directory above checkpoints/), or, where the run was made elsewhere (a device's copy), the
    directory of that name beside ``path``, or a relative one below an ancestor of ``path`` (collect run
    from another directory than the run was); None where none holds a config.toml."""
    d = os.path.dirname(os.path.normpath(start))
    if os.path.basename(d) == "checkpoints":
        d = os.path.dirname(d)
    if not d:
        return None
    real = os.path.realpath(path)
    sibling = os.path.join(os.path.dirname(os.path.normpath(path)), os.path.basename(d))
    # a relative start was written from where the run was launched: the checkout holding it, an ancestor
    up = [os.path.join(a, d) for a in _ancestors(os.path.abspath(path))] if not os.path.isabs(d) else []
    return next((x for x in (d, sibling, *up) if os.path.realpath(x) != real
                 and os.path.isfile(os.path.join(x, "config.toml"))), None)


def _ancestors(path):
    while True:
        parent = os.path.dirname(path)
        if parent == path:
            return
        path = parent
        yield path


@functools.lru_cache(maxsize=None)
def poured_k_n(path):
    """The k_n a run directory's pile was poured at, followed back through the states each run started from
    (``run.initial_file``, ``_started_from``) to one that started from none. Where that chain leaves the
    runs at hand, or reaches a run whose k_n is not the one a stiffened run says it was settled at: that
    stiffened run's ``stiffen.k_n_from`` (a ladder whose earlier rungs are gone is taken as poured there);
    a run that was not stiffened, its own k_n. None where ``path`` has no readable config.toml, or the
    chain turns in a circle. ``collect`` clears the cache (``make_fits``)."""
    seen = set()
    here = _read_config(path)
    if here is None:
        return None
    while True:
        k_n, k_from, start = here
        seen.add(os.path.realpath(path))
        prev = _started_from(path, start) if start else None
        got = _read_config(prev) if prev else None
        if got is None or (k_from > 0 and not math.isclose(got[0], k_from, rel_tol=1e-9)):
            return k_from if k_from > 0 else k_n
        if os.path.realpath(prev) in seen:
            warnings.warn(f"{path}: its run.initial_file chain turns in a circle at {prev}", stacklevel=2)
            return None
        path, here = prev, got


def _points(members, q="z"):
    """(k_n, value, pile) of every run of the ladder's sets with a finite ``q``."""
    runs = [(s, r) for s in members for r in s.runs if math.isfinite(r.q[q])]
    return [(s.p("k_n"), r.q[q], p) for (s, r), p in zip(runs, piles([r for _, r in runs]))]


def total_scatter(points):
    """The seed scatter of independent piles: each pile's run at its lowest k_n, pooled over the k_n
    (``fits.pooled_scatter``); (s, dof)."""
    first = {}
    for k, v, p in sorted(points, key=lambda t: t[0]):
        first.setdefault(p, (k, v))
    groups = {}
    for k, v in first.values():
        groups.setdefault(k, []).append(v)
    return fits.pooled_scatter(list(groups.values()))


def _by_pile(points):
    """{pile: {k_n: value}} of (k_n, value, pile) points. A pile has one run at a k_n (``collect.group``
    keeps one run of a seed in a set, and a ladder has one set at each k_n): a second is an error, not a
    value to keep or average."""
    by = {}
    for k, v, p in points:
        d = by.setdefault(p, {})
        if k in d:
            raise ValueError(f"pile {p} has two runs at k_n = {k:g}: one pile at one rung counts once")
        d[k] = v
    return by


def within_pile_noise(points):
    """A pile's noise from rung to rung: the residual scatter of a two-way table (k_n by pile) of piles
    measured at the same k_n (``fits.two_way_anova``), the complete table with the most residual degrees
    of freedom (a pile that climbed fewer rungs does not cut the others' table short); (s, dof), (nan, 0)
    when no two piles share two k_n."""
    by = _by_pile(points)
    best = None
    for q in by:
        ks = sorted(by[q])
        piles = [p for p in by if set(ks) <= set(by[p])]
        dof = (len(ks) - 1) * (len(piles) - 1)
        if dof >= 1 and (best is None or dof > best[0]):
            best = (dof, ks, piles)
    if best is None:
        return math.nan, 0
    _, ks, piles = best
    a = fits.two_way_anova([[by[p][k] for p in piles] for k in ks])
    return a["scatter"], a["dof"][1]


def _triple_alpha(z):
    """eq. 7's exponent through three z a decade apart in k_n: log10((z0 - z1) / (z1 - z2)); nan unless z
    falls at both steps."""
    r1, r2 = z[0] - z[1], z[1] - z[2]
    return math.log10(r1 / r2) if r1 > 0 and r2 > 0 else math.nan


def _propagated(f, z, s):
    """The standard error of ``f(z)`` for z with independent noise ``s`` each (a pile's noise from rung to
    rung), by the linear propagation of central differences; nan where f is nan or s is not finite."""
    z = list(z)
    if not (math.isfinite(s) and s > 0 and math.isfinite(f(z))):
        return math.nan
    h = 1e-3 * s
    grad = [(f(z[:i] + [z[i] + h] + z[i + 1:]) - f(z[:i] + [z[i] - h] + z[i + 1:])) / (2 * h)
            for i in range(len(z))]
    return s * math.sqrt(sum(g * g for g in grad))


def _triples(d):
    """The lowest k_n of each three rungs a decade apart in a pile's {k_n: z}."""
    return [k for k in sorted(d) if 10 * k in d and 100 * k in d]


def _triple(d, k, s_within):
    """(alpha_n, its error) through a pile's rungs k, 10 k, 100 k of {k_n: z}."""
    z = [d[k], d[10 * k], d[100 * k]]
    return _triple_alpha(z), _propagated(_triple_alpha, z, s_within)


def local_exponents(points, s_within=math.nan):
    """Each pile's eq. 7 exponent through three rungs a decade apart: z_inf drops out of
    (z(k) - z(10 k)) / (z(10 k) - z(100 k)) = 10^alpha_n. One power law gives the same alpha_n for every
    triple of a pile; list of {'pile', 'k_n' (the three), 'alpha_n' (nan where z does not fall twice),
    'alpha_n_err'} (the error from ``s_within``, a pile's noise from rung to rung; nan without it)."""
    out = []
    for p, d in _by_pile(points).items():
        for k in _triples(d):
            a, err = _triple(d, k, s_within)
            out.append({"pile": list(p), "k_n": [k, 10 * k, 100 * k], "alpha_n": a, "alpha_n_err": err})
    return out


def exponent_change(points, s_within, s_within_dof=0):
    """Does eq. 7 hold with one exponent over a ladder's rungs? Each pile's exponent through its highest
    three rungs a decade apart minus through its lowest (``local_exponents``), their shared rungs' noise
    propagated (``s_within`` for each z), pooled over the piles with inverse-variance weights. One power
    law gives 0. {'status': 'fitted', 'change', 'low', 'high' (the exponent through the lowest and the
    highest three rungs, pooled alike), each with its '_err', 'n_piles', 'n_runs', 'piles' [{'pile', 'k_n'
    (lowest rungs of the two triples), 'n_rungs', 'change', 'low', 'high', each with its '_err'}], 's_within',
    's_within_dof', 'p_normal' and 'p_student' (the change's two-sided p against 0, the noise taken as known,
    and against Student's t on s_within_dof, the noise being measured)}, or status 'not fitted' with a reason
    (no pile with two triples, no noise, z not falling)."""
    rows = []
    for p, d in _by_pile(points).items():
        ks = _triples(d)
        if len(ks) < 2:
            continue
        lo, hi = ks[0], ks[-1]
        rungs = sorted({lo, 10 * lo, 100 * lo, hi, 10 * hi, 100 * hi})
        at = {k: i for i, k in enumerate(rungs)}

        def change(z, lo=lo, hi=hi, at=at):
            return _triple_alpha([z[at[hi]], z[at[10 * hi]], z[at[100 * hi]]]) - \
                _triple_alpha([z[at[lo]], z[at[10 * lo]], z[at[100 * lo]]])

        z = [d[k] for k in rungs]
        ends = {}
        for end, k in (("low", lo), ("high", hi)):
            ends[end], ends[f"{end}_err"] = _triple(d, k, s_within)
        rows.append({"pile": list(p), "k_n": [lo, hi], "n_rungs": len(rungs), "change": change(z),
                     "change_err": _propagated(change, z, s_within), **ends})
    base = {"piles": rows, "s_within": s_within, "s_within_dof": s_within_dof}
    if not rows:
        return dict(base, status="not fitted", reason="no pile climbed four rungs a decade apart")
    if not (math.isfinite(s_within) and s_within > 0):
        return dict(base, status="not fitted", reason="no noise from rung to rung measured")
    good = [r for r in rows if math.isfinite(r["change"]) and math.isfinite(r["change_err"]) and r["change_err"] > 0]
    if not good:
        return dict(base, status="not fitted", reason="z does not fall at every step of a pile's rungs")
    out = dict(base, status="fitted", n_piles=len(good), n_runs=sum(r["n_rungs"] for r in good))
    for key in ("change", "low", "high"):
        w = [1 / r[f"{key}_err"] ** 2 for r in good]
        out.update({key: sum(wi * r[key] for wi, r in zip(w, good)) / sum(w), f"{key}_err": 1 / math.sqrt(sum(w))})
    # the error scales with s_within, itself measured on s_within_dof: Student's t beside the normal reading
    ratio = abs(out["change"]) / out["change_err"]
    out["p_normal"] = float(2 * norm.sf(ratio))
    out["p_student"] = float(2 * t_dist.sf(ratio, s_within_dof)) if s_within_dof >= 1 else math.nan
    return out


def fit_piles(fam, points):
    """Eq. 7 over a ladder's runs (``fits.fit_eq7_piles``), free and with the exponent fixed (1/2 at mu = 0, the
    paper's 1/4 with friction), or status "not fitted" with why."""
    s_tot, dof_tot = total_scatter(points)
    s_w, dof_w = within_pile_noise(points)
    e = {"s_total_dof": dof_tot, "s_within_dof": dof_w, "local_exponents": local_exponents(points, s_w),
         "bend": exponent_change(points, s_w, dof_w)}
    if not (math.isfinite(s_tot) and s_tot > 0):
        return dict(e, status="not fitted", reason="no two independent piles at one k_n: no seed scatter")
    if not (math.isfinite(s_w) and s_w > 0):
        return dict(e, status="not fitted", reason="fewer than two piles climbed the same two rungs: a pile's "
                                                   "own offset cannot be told from its noise")
    k, z, pl = zip(*points)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            e.update(status="fitted", **fits.fit_eq7_piles(k, z, pl, s_tot, s_w, s_within_dof=dof_w))
        except (RuntimeError, ValueError, np.linalg.LinAlgError) as err:
            return dict(e, status="failed", reason=f"{type(err).__name__}: {err}")
        fixed = 0.5 if fam["mu"] == 0 else paper.EQ7_FRICTIONAL_ALPHA_N
        try:
            e["fixed"] = fits.fit_eq7_piles(k, z, pl, s_tot, s_w, alpha_n=fixed, s_within_dof=dof_w)
        except (ValueError, np.linalg.LinAlgError) as err:
            e["fixed"] = {"status": "failed", "reason": str(err)}
    if not e["determined"]:
        e.update(status="not determined", reason=f"the points cannot tell the parameters apart (largest "
                                                 f"parameter correlation {e['correlation']:.10g})")
    return e


def ladders(sets, fit_one):
    """{'family', 'base', 'rungs', 'sets', 'status', ...} per ladder: with enough k_n, eq. 7 over its runs
    (``fit_piles``), and ``set_means``: ``fit_one(family, members)``, the eq. 7 fit of the sets' means as if
    independent (``collect._fit_one``), for comparison."""
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
            e.update(fit_piles(fam, _points(members)))
            # the sets' means fitted as if independent, beside it (and its fixed exponent: the only fit of a
            # ladder one pile climbed)
            means = fit_one(fam, members)
            e["set_means"] = {kk: means.get(kk) for kk in ("status", "reason", "z_inf", "z_inf_err", "alpha_n",
                                                           "alpha_n_err", "a_tilde", "a_tilde_err", "chi2", "dof",
                                                           "p_value", "pooled_dof") if kk in means}
            e["set_means_fixed"] = means.get("fixed") or {"status": "not fitted", "reason": means.get("reason", "")}
            if means.get("fixed") and "pooled_dof" in means:    # the noise's dof its weights rest on (its F test)
                e["set_means_fixed"] = dict(means["fixed"], pooled_dof=means["pooled_dof"])
        out.append(e)
    return out
