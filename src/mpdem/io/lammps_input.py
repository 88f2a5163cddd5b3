"""A LAMMPS input script (with its data file) that runs mpdem's model from one of its states.

``mpdem export STATE --format lammps-input [--out DIR]`` writes ``DIR/in.mpdem`` and
``DIR/data.mpdem``; ``lmp -in in.mpdem`` (run in DIR) continues the state in LAMMPS:

- ``pair_style gran/hooke/history`` (or ``gran/hertz/history``) with k_n, k_t, gamma_n,
  gamma_t, mu of the state's config as literal doubles; ``dampflag`` 1 when gamma_t > 0;
- the bed (type 2) frozen (``fix freeze``, its pairs excluded from the lists), gravity on the
  mobile spheres (type 1), ``fix wall/gran ... zplane 0.0 NULL`` where ``bed.wall`` is on;
- the time step, the skin, lists checked every step; ``reset_timestep`` to the state's step;
- every ``${every}`` steps a particle dump (``traj.dump``, the columns of ``export --format
  lammps-dump``) and a contact dump (``contacts.dump``: ``compute property/local patom1 patom2``
  and ``compute pair/local dist force p4``, i.e. the distance, the signed normal force and
  |F_t| of every contact, as in ``export --format lammps-local``), floats with 17 digits;
- ``${steps}`` steps: by default what is left of the state's ``run.max_steps``; then the last
  step's particles and contacts in ``final.dump`` and ``final-contacts.dump``.

Model equivalences (docs/model.md 2.7, docs/running.md): LAMMPS's Hertz prefactor is
sqrt(delta R_i R_j / (R_i + R_j)) = sqrt(delta) / 2 for a pair and sqrt(delta R) = sqrt(delta / 2)
for the wall, where mpdem's is sqrt(delta / d): the pair coefficients are doubled and the wall's
multiplied by sqrt(2). What LAMMPS's granular pair styles do not have is refused:
``contact.history = "rotate"`` (theirs is mpdem's ``project``) and ``contact.limit_damping``.

A LAMMPS data file carries no contact history, so LAMMPS starts every contact's Delta s at zero:
the trajectories agree to round-off from a state without histories (a new run's first state, a
frictionless state); otherwise the script's header says how many histories are dropped.
LAMMPS atom ids are mpdem's + 1 when mpdem's start at 0 (``lammps.ID_SHIFT_NOTE``).
"""
from __future__ import annotations

import math
import os
import tomllib

import numpy as np

from ..errors import MpdemError, WriteError
from ..kernels.models import MODELS

DATA_NAME = "data.mpdem"
INPUT_NAME = "in.mpdem"


class LammpsInputError(MpdemError):
    """A state whose model LAMMPS's granular styles cannot run as mpdem does."""


def coefficients(contact):
    """The pair style, its coefficients and the wall's, from a config's ``[contact]`` table.

    Parameters
    ----------
    contact : dict
        The resolved ``contact`` section (k_n, k_t, gamma_n, gamma_t, mu, model, history,
        limit_damping).

    Returns
    -------
    (style, pair, wall) : str, tuple of 6, tuple of 6
        ``gran/hooke/history`` or ``gran/hertz/history``; (k_n, k_t, gamma_n, gamma_t, mu,
        dampflag) for the pair style and for ``fix wall/gran``.
    """
    if contact["history"] != "project":
        raise LammpsInputError(f"contact.history = {contact['history']!r} has no LAMMPS counterpart; "
                               "LAMMPS's gran/*/history styles do what mpdem's 'project' does")
    if contact["limit_damping"]:
        raise LammpsInputError("contact.limit_damping = true has no counterpart in LAMMPS's gran/*/history "
                               "styles; accepted: false")
    # + 0.0: a -0.0 (gamma_n at epsilon = 1) is written as 0
    k = [float(contact[key]) + 0.0 for key in ("k_n", "k_t", "gamma_n", "gamma_t")]
    mu = float(contact["mu"])
    damp = 1 if k[3] > 0.0 else 0
    model = MODELS[contact["model"]]
    pair, wall = model.lammps_scale
    return model.lammps, (*[pair * c for c in k], mu, damp), (*[wall * c for c in k], mu, damp)


def _literal(values):
    return " ".join(f"{v:.17g}" if isinstance(v, float) else str(v) for v in values)


def input_lines(cfg, step, steps, every, dropped, source):
    """The lines of the LAMMPS input script.

    Parameters
    ----------
    cfg : dict
        The state's resolved config, as TOML tables.
    step : int
        The state's step (LAMMPS's timestep is reset to it).
    steps, every : int
        Default steps to run and steps between dumps (``-var steps N -var every M`` override).
    dropped : int
        Contact histories (pairs and wall) that are nonzero in the state and start at zero in LAMMPS.
    source : str
        The state file's name, for the header.
    """
    style, pair, wall = coefficients(cfg["contact"])
    gravity = float(cfg["box"]["gravity"])
    yield f"# mpdem state {source} (step {step}) in LAMMPS: lmp -in {INPUT_NAME}, run in this directory.\n"
    yield "# Written by `mpdem export --format lammps-input` (docs/lammps.md); reduced units d = m = g = 1.\n"
    if dropped:
        yield (f"# NOTE: {dropped} nonzero contact histories of the state start at zero here (a data file has\n"
               "# none), so the trajectories differ from mpdem's beyond round-off.\n")
    yield f"variable steps index {steps}\nvariable every index {every}\n\n"
    yield ("units          lj\natom_style     sphere\ndimension      3\nboundary       p p m\n"
           "newton         on\ncomm_modify    vel yes\natom_modify    map array\n\n")
    yield (f"read_data      {DATA_NAME}\nreset_timestep {step}\n"
           "group          mobile type 1\ngroup          bed type 2\n\n")
    yield f"pair_style     {style} {_literal(pair)}\npair_coeff     * *\n"
    yield (f"neighbor       {float(cfg['integration']['skin']):.17g} bin\n"
           "neigh_modify   delay 0 every 1 check yes exclude type 2 2\n"
           f"timestep       {float(cfg['integration']['dt']):.17g}\n\n")
    yield "fix            integ mobile nve/sphere\nfix            frz bed freeze\n"
    incline = float(cfg["box"].get("incline", 0.0))
    if gravity != 0.0 and incline == 0.0:
        yield f"fix            grav mobile gravity {gravity:.17g} vector 0.0 0.0 -1.0\n"
    elif gravity != 0.0:
        # tilted about y (box.incline): LAMMPS's fix gravity normalises the vector, mpdem's sin and cos
        theta = math.radians(incline)
        yield (f"fix            grav mobile gravity {gravity:.17g} vector {math.sin(theta):.17g} 0.0 "
               f"{-math.cos(theta):.17g}\n")
    if cfg["bed"]["wall"]:
        yield f"fix            zwall mobile wall/gran {style.split('/')[1]}/history {_literal(wall)} zplane 0.0 NULL\n"
    yield ("\ncompute        ket mobile ke\nthermo_style   custom step atoms c_ket\nthermo_modify  norm yes\n"
           "thermo         ${every}\n\n")
    yield ("dump           traj all custom ${every} traj.dump id type x y z vx vy vz omegax omegay omegaz "
           "fx fy fz radius\ndump_modify    traj sort id format float %.17g\n")
    yield ("compute        pa all property/local patom1 patom2\n"
           "compute        pl all pair/local dist force p4\n"
           "dump           contacts all local ${every} contacts.dump c_pa[1] c_pa[2] c_pl[1] c_pl[2] c_pl[3]\n"
           "dump_modify    contacts format float %.17g\n\n")
    yield "run            ${steps}\n\n"
    # the last step whether or not it is a multiple of ${every}
    yield ("write_dump     all custom final.dump id type x y z vx vy vz omegax omegay omegaz fx fy fz radius "
           "modify sort id format float %.17g\n")
    yield ("write_dump     all local final-contacts.dump c_pa[1] c_pa[2] c_pl[1] c_pl[2] c_pl[3] "
           "modify format float %.17g\n")


def nonzero_histories(arrays):
    """How many contact histories of a state (pair slots and wall) are nonzero."""
    n = 0
    for key in ("ds", "wall_ds"):
        if key in arrays and len(arrays[key]):
            n += int(np.any(np.asarray(arrays[key]).reshape(-1, 3) != 0.0, axis=1).sum())
    return n


def write(path, out=None, steps=None, every=None):
    """Write ``in.mpdem`` and ``data.mpdem`` for the state file ``path``.

    Parameters
    ----------
    path : str
        An mpdem state file.
    out : str, optional
        Directory for the two files; default ``<state without suffix>.lammps``.
    steps, every : int, optional
        Default steps (what is left of ``run.max_steps``, at least 1) and dump interval
        (``output.snapshot_every`` when set, else the steps).

    Returns
    -------
    (str, int) : the input script's path and the number of dropped histories.
    """
    from . import checkpoint
    from .lammps import state_data
    from .rundir import write_atomic
    arrays, attrs = checkpoint.read_state(path)
    cfg = tomllib.loads(attrs["config"])
    step = int(attrs["step"])
    if steps is None:
        steps = max(1, int(cfg["run"]["max_steps"]) - step)
    if every is None:
        every = int(cfg["output"].get("snapshot_every") or 0) or steps
    out = out or os.path.splitext(path)[0] + ".lammps"
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as e:
        raise WriteError(f"cannot make the directory {out}: {e.strerror or e}") from None
    dropped = nonzero_histories(arrays)
    script = os.path.join(out, INPUT_NAME)
    write_atomic(os.path.join(out, DATA_NAME), state_data(arrays, attrs, path))
    write_atomic(script, input_lines(cfg, step, steps, every, dropped, os.path.basename(path)))
    return script, dropped
