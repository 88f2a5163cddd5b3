"""Whether the runs of a set are independent samples: a seed's offset shared across sets, and beds
against pours (docs/analysis.md).

A run's seed draws its bed (unless ``bed.seed`` is set apart) and its pour (insertion and initial
velocities), and seed k lies on the same bed in every set. Two questions follow:

- **Does a seed shift every set alike?** A bed (or an insertion) that made every pile on it denser would
  shift z in every set poured on it; the sets' seed scatter would then hold a part shared across sets
  and comparisons between sets of the same seeds would be correlated. ``seed_effects``: per pile size
  (N, L_x, L_y), the sets of the pour protocol (no ``extra`` keys: a set continued from another set's
  runs, a stricter stop or a longer flow, shares their history and is left out) on the seeds that most
  of them share, each seed on its own bed: a two-way analysis of variance of z and phi, sets by seeds
  (``fits.two_way_anova``), F of the seeds against the residual.
- **Does a pour seed fix its pile whatever the bed?** ``bed_scatter``: in a set where one pour seed lies
  on two beds or more (``bed.seed``), the runs grouped by pour seed, a one-way analysis of variance
  (``fits.one_way_anova``): the scatter over beds at one pour seed against the scatter between pour
  seeds. F near 1: a bed changes the pile as much as a new seed does.
"""
from __future__ import annotations

import math

import numpy as np

from ..analysis.fits import one_way_anova, two_way_anova
from .runs import md_table

QUANTITIES = ("z", "phi")


def _own_bed(s):
    """{seed: run} of the set's runs on their own bed, with z and phi."""
    return {r.params["run.seed"]: r for r in s.runs
            if r.bed_seed == r.params["run.seed"] and all(math.isfinite(r.q.get(q, math.nan)) for q in QUANTITIES)}


def _best_seeds(own):
    """The seeds (>= 2) shared by the most sets (>= 2), largest table first: (seeds, set indices) or None."""
    best, key = None, None
    for d in own:
        seeds = sorted(d)
        for k in range(2, len(seeds) + 1):
            T = seeds[:k]
            members = [i for i, e in enumerate(own) if all(t in e for t in T)]
            if len(members) < 2:
                continue
            score = (len(members) * k, k)
            if key is None or score > key:
                best, key = (T, members), score
    return best


def seed_effects(sets):
    """Per pile size, the two-way analysis of variance (sets by seeds) of z and phi.

    Returns
    -------
    list of dict: ``N``, ``L_x``, ``L_y``, ``sets`` (ids), ``seeds``, ``left_out`` (ids of the size's
    pour-protocol sets of two seeds or more without all of ``seeds``), per quantity the
    ``two_way_anova`` dict (``effects`` per seed, in ``seeds``' order).
    """
    groups = {}
    for s in sets:
        if not s.extra:
            groups.setdefault((s.p("N"), s.p("L_x"), s.p("L_y")), []).append(s)
    out = []
    for (N, Lx, Ly), members in groups.items():
        own = [_own_bed(s) for s in members]
        best = _best_seeds(own)
        if best is None:
            continue
        seeds, idx = best
        e = {"N": N, "L_x": Lx, "L_y": Ly, "sets": [members[i].id for i in idx], "seeds": seeds,
             "left_out": [members[i].id for i in range(len(members)) if i not in idx and len(own[i]) >= 2]}
        for q in QUANTITIES:
            e[q] = two_way_anova([[own[i][t].q[q] for t in seeds] for i in idx])
        out.append(e)
    return out


def bed_scatter(sets):
    """Per set where a pour seed lies on two beds or more: beds against pour seeds.

    Returns
    -------
    list of dict: ``set``, ``runs`` ([pour seed, bed seed, z, phi] in the set's order), per quantity the
    ``one_way_anova`` dict over the groups of one pour seed (``scatter``: the pooled scatter over beds at
    one pour seed) and ``seed_scatter``: the standard deviation over the pour seeds' own-bed runs (nan
    under two).
    """
    out = []
    for s in sets:
        by_seed = {}
        for r in s.runs:
            by_seed.setdefault(r.params["run.seed"], []).append(r)
        if not any(len({r.bed_seed for r in g}) >= 2 for g in by_seed.values()):
            continue
        e = {"set": s.id, "runs": [[r.params["run.seed"], r.bed_seed, r.q.get("z"), r.q.get("phi")] for r in s.runs]}
        own = _own_bed(s)
        for q in QUANTITIES:
            e[q] = one_way_anova([[r.q[q] for r in g if math.isfinite(r.q.get(q, math.nan))]
                                  for g in by_seed.values()])
            v = [r.q[q] for r in own.values()]
            e[q]["seed_scatter"] = float(np.std(v, ddof=1)) if len(v) >= 2 else math.nan
        out.append(e)
    return out


def tests(sets):
    """fits.json's 'samples': {'seed_effects': ..., 'beds': ...}."""
    return {"seed_effects": seed_effects(sets), "beds": bed_scatter(sets)}


def _ftext(a):
    return (f"F = {a['F']:.2f} ({a['dof'][0]}, {a['dof'][1]}), p = {a['p']:.2g}" if math.isfinite(a["p"])
            else "not tested (no residual scatter)")


def section(res):
    """README lines: the seed effect per size, the beds' scatter per set."""
    L = ["## Seeds and beds: are a set's runs independent samples?", "",
         "Seed k draws the bed and the pour of its run and lies on the same bed in every set. Sets by seeds (each "
         "seed on its own bed; sets of the pour protocol only), a two-way analysis of variance: does a seed shift "
         "z and φ in every set alike? p small: a seed's bed or pour carries an offset shared across sets.", ""]
    rows = []
    for e in res.get("seed_effects", []):
        rows.append([f"{e['N']:g} ({e['L_x']:g} d × {e['L_y']:g} d)", ", ".join(e["sets"]),
                     " ".join(map(str, e["seeds"])),
                     ", ".join(f"{x:+.4f}" for x in e["z"]["effects"]), _ftext(e["z"]),
                     ", ".join(f"{x:+.5f}" for x in e["phi"]["effects"]), _ftext(e["phi"])])
    L.append(md_table(["N", "sets", "seeds", "z offset per seed", "z: seeds", "φ offset per seed", "φ: seeds"],
                      rows) if rows else "No two sets of one size share two seeds.")
    left = [f"N {e['N']:g}: {', '.join(e['left_out'])}" for e in res.get("seed_effects", []) if e["left_out"]]
    if left:
        L += ["", "Sets of two seeds or more without all of the table's seeds, left out: " + "; ".join(left) + "."]
    L += ["", "A pour seed on several beds (`bed.seed`): the runs grouped by pour seed, a one-way analysis of "
          "variance, beds within a pour seed against the pour seeds. F near 1: a new bed changes the pile as much "
          "as a new seed.", ""]
    rows = []
    for e in res.get("beds", []):
        runs = "; ".join(f"seed {p} bed {b}: z {z:.4f}, φ {f:.4f}" for p, b, z, f in e["runs"])
        rows.append([e["set"], runs, f"{e['z']['scatter']:.4f} / {e['z']['seed_scatter']:.4f}", _ftext(e["z"]),
                     f"{e['phi']['scatter']:.5f} / {e['phi']['seed_scatter']:.5f}", _ftext(e["phi"])])
    L.append(md_table(["set", "runs", "z scatter: beds / seeds", "z", "φ scatter: beds / seeds", "φ"], rows)
             if rows else "No set has a pour seed on two beds.")
    return L + [""]
