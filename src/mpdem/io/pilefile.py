"""What a particle file says of the pile it holds, read without its rows where it can: the box and the
number of mobile spheres (``initial.config_for`` makes them a new run's, ``stiffen`` a rung's, the bench
times a state file in its box)."""
from __future__ import annotations

import os

import numpy as np

from ..errors import InputError
from . import checkpoint, packing, tables


def file_facts(path, lammps_table=None, what="run.initial_file"):
    """What an initial file says of the run it starts: ``{'box.L_x', 'box.L_y', 'pour.N'}`` from an mpdem
    state or packing file (its attributes) or a LAMMPS file already read (``lammps.initial_for``),
    ``{'pour.N'}`` from a text table (which keeps no box), ``{}`` without a path.

    Raises
    ------
    InputError
        A path that is a directory or nothing (named as ``what``), before a run directory is made.
    """
    if not path:
        return {}
    if os.path.isdir(path):
        raise InputError(f"{what} {path}: a directory, not a file (a finished run's state is "
                         f"{os.path.join(path, 'final.h5')})")
    if not os.path.isfile(path):
        raise InputError(f"{what} {path}: no such file")
    if lammps_table is not None:
        attrs = {"L_x": lammps_table["L_x"], "L_y": lammps_table["L_y"],
                 "n_mobile": (np.asarray(lammps_table["fixed"]) == 0).sum()}
    elif checkpoint.is_state_file(path):
        attrs = checkpoint.read_attrs(path)
    elif packing.is_packing(path):
        attrs = packing.read_attrs(path)
    else:
        return {"pour.N": int((np.asarray(tables.read_table(path)["fixed"]) == 0).sum())}
    facts = {"box.L_x": attrs.get("L_x"), "box.L_y": attrs.get("L_y"), "pour.N": attrs.get("n_mobile")}
    return {k: (int(v) if k == "pour.N" else float(v)) for k, v in facts.items() if v is not None}
