"""z, phi and the contact fabric (its anisotropy and the angle of its major axis) on fixed depth windows
below the surface, per parameter set, with two independent errors (docs/model.md 6.10): the seed scatter
pooled over the sets of one N and mu (``fits.pooled_scatter``, as for eq. 7) and the jackknife over each
pile's lateral columns, combined over its seeds. The angle's mean over seeds is a plain mean (angles
away from +-90 degrees).

The windows are the default ``analysis.depth_windows``; a run analysed before they existed, or
too short for a window, has none there (nan), and ``mpdem analyze`` again gives them.
"""
from __future__ import annotations

import math

from ..analysis.fits import pooled_scatter
from ..config import SCHEMA
from ..io import rundir

_D = next(k.default for k in SCHEMA if k.section == "analysis" and k.name == "depth_windows")
WINDOWS = tuple(zip(_D[::2], _D[1::2]))       # (top, bottom) depths below the surface [d]
QUANTITIES = ("z", "phi", "fabric_a", "fabric_angle")
# where a window's quantity lives in summary.json: the depth_windows entry, or the fabric's (its contacts part)
_SOURCE = {"z": ("depth_windows", None, "z"), "phi": ("depth_windows", None, "phi"),
           "fabric_a": ("fabric", "contacts", "anisotropy"), "fabric_angle": ("fabric", "contacts", "angle")}
LABEL = {"z": "z", "phi": "φ", "fabric_a": "fabric anisotropy", "fabric_angle": "fabric angle [°]"}
DIGITS = {"z": 3, "phi": 4, "fabric_a": 3, "fabric_angle": 1}


def label(window):
    """'10-30' of the window (10, 30)."""
    return f"{window[0]:g}-{window[1]:g}"


def key(q, window, jk=False):
    """The column of quantity ``q`` on ``window`` in ``AnalysedRun.q``: z_10_30, z_10_30_jk."""
    return f"{q}_{window[0]:g}_{window[1]:g}" + ("_jk" if jk else "")


def window_quantities(summary, num):
    """The per-run numbers of the default windows from a summary.json (nan where absent)."""
    found = {part: {(w["depth_lo"], w["depth_hi"]): w for w in (summary.get(part) or {}).get("windows", [])
                    if w.get("complete")} for part in ("depth_windows", "fabric")}
    out = {}
    for win in WINDOWS:
        for q in QUANTITIES:
            part, sub, name = _SOURCE[q]
            w = found[part].get(win, {})
            w = (w.get(sub) or {}) if sub else w
            out[key(q, win)] = num(w.get(name))
            out[key(q, win, True)] = num(w.get(f"{name}_err"))
    return out


def rows(sets):
    """One row per set, window and quantity: mean over the seeds, its own standard error, the pooled
    one (over the sets of the same N and mu) and the combined jackknife error of the mean."""
    pools = {}
    for s in sets:
        pools.setdefault((s.p("N"), s.p("mu")), []).append(s)
    out = []
    for s in sets:
        peers = pools[(s.p("N"), s.p("mu"))]
        for win in WINDOWS:
            for q in QUANTITIES:
                vals = [r.q[key(q, win)] for r in s.runs]
                jks = [r.q[key(q, win, True)] for r in s.runs]
                ok = [(v, e) for v, e in zip(vals, jks) if math.isfinite(v)]
                if not ok:
                    continue
                n = len(ok)
                mean, sem, _ = s.stat(key(q, win))
                sd, dof = pooled_scatter([[r.q[key(q, win)] for r in p.runs] for p in peers])
                jk = math.sqrt(sum(e * e for _, e in ok)) / n if all(math.isfinite(e) for _, e in ok) else math.nan
                out.append({"set": s.id, "N": s.p("N"), "mu": s.p("mu"), "epsilon": s.p("epsilon"), "k_n": s.p("k_n"),
                            "window": label(win), "quantity": q, "n_seeds": n, "mean": mean, "sem": sem,
                            "pooled_sem": sd / math.sqrt(n) if dof else math.nan, "pooled_dof": dof, "jackknife": jk})
    return out


COLUMNS = ("set", "N", "mu", "epsilon", "k_n", "window", "quantity", "n_seeds", "mean", "sem", "pooled_sem",
           "pooled_dof", "jackknife")


def write_csv(path, table):
    """depth.csv: the rows of ``rows``."""
    rundir.write_csv(path, list(COLUMNS), [[r[c] for c in COLUMNS] for r in table])


def _pm(v, digits):
    return f"{v:.{digits}f}" if math.isfinite(v) else "—"


def lines(table):
    """Text lines of z per set and window: mean, pooled and jackknife errors."""
    out = []
    for r in table:
        if r["quantity"] != "z":
            continue
        out.append(f"{r['set']} (mu = {r['mu']:g}, N = {r['N']}) z at {r['window']} d: {_pm(r['mean'], 3)} "
                   f"+- {_pm(r['pooled_sem'], 3)} (seeds, pooled over {r['pooled_dof']} dof) "
                   f"+- {_pm(r['jackknife'], 3)} (jackknife; {r['n_seeds']} seed{'s' if r['n_seeds'] > 1 else ''})")
    return out
