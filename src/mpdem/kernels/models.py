"""The contact models, one row each (docs/model.md 2.2 and 2.7).

The table is read by everything that depends on which model a run uses: the config schema (the
accepted ``contact.model`` names), the law record (``law.make_law``: the kernels' model id), the
contact list and the analysis (``overlap_scale``), and the LAMMPS input writer (the pair style and
its coefficients). A new model is a row here and its force in ``kernels/law.py``.
Plain Python: the command line reads it without loading numba.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Model:
    """One contact model.

    Attributes
    ----------
    name : str
        ``contact.model``.
    kernel : int
        ``Law.model``, the id the kernels branch on.
    sqrt_overlap : bool
        Forces scaled by sqrt(delta / d) (Hertz), else linear in the overlap (Hooke).
    lammps : str
        The LAMMPS pair style it matches (``pair_style granular`` sub-models aside).
    lammps_scale : (float, float)
        The factor on k_n, k_t, gamma_n, gamma_t that gives LAMMPS's coefficients for a pair and for
        ``fix wall/gran`` (Hertz: LAMMPS scales by sqrt(delta R_eff), R_eff = 1/4 for a pair and 1/2
        for the wall, against mpdem's sqrt(delta / d)).
    about : str
    """
    name: str
    kernel: int
    sqrt_overlap: bool
    lammps: str
    lammps_scale: tuple
    about: str


MODELS = {m.name: m for m in (
    Model("hooke", 0, False, "gran/hooke/history", (1.0, 1.0), "linear spring-dashpot (docs/model.md 2.2)"),
    Model("hertz", 1, True, "gran/hertz/history", (2.0, math.sqrt(2.0)),
          "Hertzian: the Hookean forces scaled by sqrt(delta / d) (docs/model.md 2.7)"),
)}


# the models by the kernels' id (``Law.model``)
BY_KERNEL = {m.kernel: m for m in MODELS.values()}


def overlap_scale(model, delta):
    """The factor on the forces of contacts with overlaps ``delta`` (M,) [d] under ``model`` (a name,
    or the kernels' id ``Law.model``): sqrt(delta) for a Hertzian model, 1 otherwise; (M,)."""
    delta = np.asarray(delta, dtype=float)
    m = BY_KERNEL[model] if isinstance(model, int) else MODELS[model]
    return np.sqrt(np.maximum(delta, 0.0)) if m.sqrt_overlap else np.ones_like(delta)
