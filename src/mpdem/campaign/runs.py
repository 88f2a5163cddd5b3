"""Runs, parameter sets and families of sets, shared by ``collect``, ``figures`` and ``comparison``.

A ``AnalysedRun`` is one analysed run directory (its summary.json and the
numbers read from it); a ``Set`` is the runs of one parameter set (every
parameter of ``config.PARAM_KEYS`` but the seed equal), with the mean and
standard error of a quantity over its seeds (``mean_sem``). ``families``
groups sets that differ in one parameter only (the curves of the figures,
the eq. 7 and eq. 9 fits). ``fmt_kn`` and ``fmt_pm`` are the number texts
of the figures and README.md.
"""
from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass, field

import numpy as np

from ..config import PARAM_KEYS
from . import depth

SHORT = {k: k.split(".", 1)[1] for k in PARAM_KEYS}   # contact.mu -> mu, run.seed -> seed, ...
# k_t, gamma_n, gamma_t and dt follow k_n in a stiffness sweep (docs/model.md 3, 4.2)
FOLLOW_K_N = ("contact.k_n", "contact.k_t", "contact.gamma_n", "contact.gamma_t", "integration.dt")
NAN = float("nan")


# ---------------------------------------------------------------- runs and sets

@dataclass
class AnalysedRun:
    """One analysed run: its directory, its summary.json and the numbers read from it."""
    path: str
    s: dict
    q: dict = field(default_factory=dict)

    def __post_init__(self):
        self.q = quantities(self.s)
        # summaries written before 2026-11-27 (late night) hold epsilon as gamma_n's round trip, off in the
        # last bit at some k_n (0.49999999999999994 for 0.5): the value given, as the config keeps it now
        p = self.s.get("params", {})
        if isinstance(p.get("contact.epsilon"), float):
            p["contact.epsilon"] = float(f"{p['contact.epsilon']:.12g}")

    @property
    def params(self):
        return self.s["params"]

    @property
    def bed_seed(self):
        """The seed of the run's bed (summaries written before ``bed.seed`` existed: the run's seed)."""
        return self.s.get("bed_seed", self.params["run.seed"])


@dataclass
class Set:
    """The runs (``AnalysedRun``) of one parameter set (all of ``PARAM_KEYS`` but the seed equal).

    ``extra`` holds the physics keys outside ``PARAM_KEYS`` that the set's runs chose
    away from their defaults (e.g. ``{"stop.energy": "translational"}``); derived keys
    (E_stop, which follows k_n) are not among them. Families keep such sets apart.
    """
    id: str
    params: dict
    runs: list
    extra: dict = field(default_factory=dict)
    signature: str = ""     # its identity across collects (``collect.signature``)

    def p(self, short):
        """A parameter by its short name (mu, epsilon, k_n, phi_i, N, L_x, ...)."""
        return self.params[next(k for k in PARAM_KEYS if SHORT[k] == short)]

    @property
    def seeds(self):
        return [r.params["run.seed"] for r in self.runs]

    def stat(self, q):
        """(mean, standard error, count) of quantity ``q`` over the runs; see ``mean_sem``."""
        return mean_sem([r.q[q] for r in self.runs])


def read_table(run_dir, name):
    """Columns of RUN/analysis/<name>.csv as float arrays (empty cells nan); None when missing or unreadable."""
    try:
        with open(os.path.join(run_dir, "analysis", f"{name}.csv"), newline="") as fh:
            rows = list(csv.reader(fh))
        return {h: np.array([float(r[i]) if r[i] else NAN for r in rows[1:]]) for i, h in enumerate(rows[0])}
    except (OSError, ValueError, IndexError):
        return None


def num(v):
    """A JSON number as float; nan for anything else (None, a bool, a string)."""
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else NAN


def quantities(s):
    """The per-run numbers of a summary.json (nan where absent or null)."""
    hm, zt = s.get("halved_margins") or {}, s.get("zeta") or {}
    q = {k: num(s.get(k)) for k in ("z", "z_no_rattlers", "rattler_fraction", "phi", "alpha", "alpha_err",
                                    "n_bulk", "overlap_median", "overlap_max", "step")}
    bb, iso, od = s.get("backbone") or {}, s.get("isostatic") or {}, s.get("order") or {}
    q.update(mobilised_fraction=num(zt.get("mobilised_fraction")), z_halved=num(hm.get("z")),
             phi_halved=num(hm.get("phi")), z_backbone=num(bb.get("z")),
             # from n_m (4 + n_m / 3, docs/model.md 6.2): summaries written before 2026-11-26 hold 4 + 2 n_m / 3
             z_iso=4.0 + num(iso["n_m"]) / 3.0 if "n_m" in iso else NAN,
             crystal_fraction=num(od.get("crystal_fraction")))
    q.update(depth.window_quantities(s, num))
    return q


def mean_sem(values):
    """Mean and standard error of the mean of the finite values.

    Returns
    -------
    (mean, sem, n): sem = std(ddof=1) / sqrt(n), nan when n < 2 (no error bar
    from a single seed); mean nan when n = 0.
    """
    v = np.asarray([x for x in values if x is not None and math.isfinite(x)], float)
    n = len(v)
    mean = float(np.mean(v)) if n else NAN
    sem = float(np.std(v, ddof=1) / np.sqrt(n)) if n >= 2 else NAN
    return mean, sem, n


# ---------------------------------------------------------------- families

def _sig(x):
    return float(f"{x:.10g}")


def family_key(params, vary, extra=None):
    """What a family of sets that differ only in ``vary`` (a PARAM_KEYS key) shares.

    For ``contact.k_n`` the parameters that follow k_n enter as the scale-free
    k_t/k_n, gamma_n/sqrt(k_n) and gamma_t/gamma_n (10 significant digits) and
    dt is left out, and so does a stiffened pile's ``stiffen.k_n_from``, as the
    rung's rise k_n / k_n_from (the rungs of one ladder are one family, apart from
    the poured piles). ``extra`` (a Set's ``extra``) enters as it is otherwise, by
    full key name.

    Returns
    -------
    tuple of (name, value) pairs, short names.
    """
    skip = {"run.seed", vary} | (set(FOLLOW_K_N) if vary == "contact.k_n" else set())
    key = [(SHORT[k], params[k]) for k in PARAM_KEYS if k not in skip]
    extra = dict(extra or {})
    if vary == "contact.k_n":
        k, g_n, g_t = params["contact.k_n"], params["contact.gamma_n"], params["contact.gamma_t"]
        key += [("k_t/k_n", _sig(params["contact.k_t"] / k)), ("gamma_n/sqrt(k_n)", _sig(g_n / math.sqrt(k))),
                ("gamma_t/gamma_n", _sig(g_t / g_n) if g_n else g_t)]
        k_from = extra.pop("stiffen.k_n_from", 0.0)
        if k_from:
            key.append(("stiffened x", _sig(k / k_from)))
    return tuple(key + sorted(extra.items()))


def families(sets, vary):
    """[(family dict, sets sorted by ``vary``)] in the order of the first set of each."""
    fam = {}
    for s in sets:
        fam.setdefault(family_key(s.params, vary, s.extra), []).append(s)
    return [(dict(k), sorted(v, key=lambda s: s.params[vary])) for k, v in fam.items()]


# ---------------------------------------------------------------- number texts

def fmt_kn(k):
    """2e5-style text of a stiffness."""
    m, e = f"{k:.3e}".split("e")
    return f"{m.rstrip('0').rstrip('.')}e{int(e)}"


def _digits(e, base):
    if not (isinstance(e, float) and math.isfinite(e) and e > 0):
        return base
    return min(max(base, 1 - math.floor(math.log10(e))), 8)


def md_table(head, rows):
    """A Markdown table (one string) of a header and rows of cells ('|' in a cell becomes '/')."""
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    out += ["| " + " | ".join(str(c).replace("|", "/") for c in r) + " |" for r in rows]
    return "\n".join(out)


def fmt_pm(m, e=NAN, base=3, n=None):
    """'m ± e' (digits from e), 'm (1 seed)' without an error, '—' without a value."""
    if not isinstance(m, (int, float)) or not math.isfinite(m):
        return "—" if not isinstance(m, str) else m
    e = NAN if e is None else e
    d = _digits(e, base)
    if math.isfinite(e):
        return f"{m:.{d}f} ± {e:.{d}f}"
    return f"{m:.{d}f}" + (" (1 seed)" if n == 1 else "")


def off_columns(s):
    """A set's parameters that the tables' columns do not show, where away from their defaults: the
    tangential damping (as a fraction of gamma_n), the contact model, the pour's kinetic energy."""
    out = {}
    g_t, g_n = s.params.get("contact.gamma_t", 0.0), s.params.get("contact.gamma_n", 0.0)
    if g_t:
        out["gamma_t"] = f"{g_t / g_n:.4g} gamma_n" if g_n else f"{g_t:g}"
    if s.params.get("contact.model", "hooke") != "hooke":
        out["model"] = s.params["contact.model"]
    if s.params.get("pour.K0", 0.0):
        out["K0"] = f"{s.params['pour.K0']:g}"
    return out
