"""LAMMPS files: data files (``atom_style sphere``) and text dumps in, data files out.

A LAMMPS file is recognised by its content, not its name: a text dump
starts with ``ITEM: TIMESTEP``; a data file has a title line, then header
lines such as ``369 atoms`` and ``0 10 xlo xhi``. Both may be gzip-compressed.

mpdem's model is one sphere size and mass in a box periodic in x and y, so a
file is read only if it fits: every diameter 1 (radius 0.5), every mass 1
(LAMMPS's 4/3 pi r^3 rho, to within ``MASS_RTOL`` for a density written with
fewer digits), an orthogonal box. Positions are shifted by (xlo, ylo) into
[0, L_x) x [0, L_y) (z is kept: a wall plane at z = 0 stays at z = 0) and
wrapped with the image flags; the atom types in ``fixed_types`` are the bed.

Reduced units throughout (LAMMPS ``units lj`` with d = m = g = 1).
"""
from __future__ import annotations

import math
import os
import re

import numpy as np

from ..errors import InputError
from .tables import open_text, particle_ids

# LAMMPS's density of a d = 1 sphere of mass exactly 1.0 (4.0 * pi / 3.0 * 0.5^3 * RHO == 1.0)
RHO = 1.9098593171027443
# a mass within this relative distance of 1 is 1 (a density written with 7 digits)
MASS_RTOL = 1e-6
# a diameter within this relative distance of 1 is 1
DIAMETER_RTOL = 1e-12
TYPE_MOBILE, TYPE_BED = 1, 2
# LAMMPS atom ids start at 1, mpdem's at 0: a data file written from ids that include 0 says so
# in its title, and reading it takes the 1 off again
ID_SHIFT_NOTE = "atom id = mpdem id + 1"
_HEADER_COUNT = re.compile(r"^\s*(\d+)\s+(atoms|atom types|bonds|angles|dihedrals|impropers|ellipsoids|lines|"
                           r"triangles|bodies|bond types|angle types|dihedral types|improper types|"
                           r"extra bond per atom|extra angle per atom|extra dihedral per atom|"
                           r"extra improper per atom|extra special per atom)\s*$")
_HEADER_BOX = re.compile(r"^\s*(\S+)\s+(\S+)\s+(xlo xhi|ylo yhi|zlo zhi)\s*$")
_SECTION = re.compile(r"^\s*([A-Z][A-Za-z ]*[a-z])\s*(#.*)?$")


def kind(path):
    """'dump', 'data' or None: what LAMMPS file ``path`` is, from its first lines."""
    try:
        with open_text(path) as fh:
            head = []
            for line in fh:
                head.append(line)
                if len(head) >= 40:
                    break
    except (OSError, EOFError, UnicodeDecodeError):
        return None
    if head and head[0].startswith("ITEM: TIMESTEP"):
        return "dump"
    body = [ln.split("#", 1)[0] for ln in head[1:]]
    if any(_HEADER_COUNT.match(ln) and ln.split()[1] == "atoms" for ln in body) and \
            any(_HEADER_BOX.match(ln) for ln in body):
        return "data"
    return None


def read(path, fixed_types, what="run.initial_file"):
    """The particles of a LAMMPS data file or text dump, checked, in mpdem's frame.

    Parameters
    ----------
    path : str
    fixed_types : sequence of int
        Atom types of the bed (frozen) spheres; must be types the file has.
        Empty: every sphere is mobile (a bed file names no types).
    what : str
        The config key that named the file, for messages.

    Returns
    -------
    dict with id (N,) int64, x (N, 3) [d] in [0, L_x) x [0, L_y) x R,
    v (N, 3) [sqrt(g d)], omega (N, 3) [sqrt(g/d)] (zero if the file has
    none), fixed (N,) uint8, types (N,) int64, L_x, L_y [d], kind, note.
    """
    k = kind(path)
    if k is None:
        raise InputError(f"{what} {path}: not a LAMMPS data file or text dump")
    raw = _read_dump(path) if k == "dump" else _read_data(path)
    return _to_mpdem(raw, fixed_types, path, what)


def initial_for(cfg):
    """The config of a run whose ``run.initial_file`` may be a LAMMPS file, and that file's particles.

    A LAMMPS file needs ``run.fixed_types``; ``run.fixed_types`` with any other initial file is an
    error (a table or state file says which spheres are bed). The file's box and count become the
    run's in ``initial.config_for``, as any initial file's do.

    Returns
    -------
    (Config, dict or None) : the config and ``read``'s result (with the box, ``L_x`` and ``L_y``).
    """
    from ..config import ConfigError
    path, types = cfg.run.initial_file, cfg.run.fixed_types
    if not path or kind(path) is None:
        if types:
            raise ConfigError(f"run.fixed_types = {list(types)} is for a LAMMPS initial file; "
                              + (f"run.initial_file {path} is not one (its own `fixed` column or "
                                 f"dataset says which spheres are bed)" if path else "run.initial_file is not set"))
        return cfg, None
    if not types:
        raise ConfigError(no_bed_types(path))
    return cfg, read(path, types)


def no_bed_types(path, what="run.initial_file"):
    """The one message refusing a LAMMPS file read without ``run.fixed_types``: every sphere would be
    mobile, a pile with no bed. It names the file's atom types and the setting that fixes it.

    Returns
    -------
    str : the message, for the caller's own error class.
    """
    present = sorted(set(read(path, (), what=what).get("types_present", [])))
    return (f"run.fixed_types is not set: {what} {path} is a LAMMPS file with atom types {present}; "
            f"name the bed's types, e.g. --set run.fixed_types=[{present[-1]}]")


def _numbers(lines, path, where, ncols):
    """(n, ncols) float array of whitespace-separated rows (comments cut), or a clear error."""
    rows = [ln.split("#", 1)[0].split() for ln in lines]
    rows = [r for r in rows if r]
    bad = [r for r in rows if len(r) not in ncols]
    if bad:
        raise InputError(f"{path}: {where}: a row of {len(bad[0])} values ({' '.join(bad[0])}); "
                         f"accepted {' or '.join(map(str, ncols))}")
    width = {len(r) for r in rows}
    if len(width) > 1:
        raise InputError(f"{path}: {where}: rows of {sorted(width)} values mixed")
    try:
        return np.array(rows, dtype=float).reshape(len(rows), -1)
    except ValueError as e:
        raise InputError(f"{path}: {where}: not a number: {e}") from None


def _read_data(path):
    """The Atoms and Velocities sections and the box of a data file (atom_style sphere)."""
    with open_text(path) as fh:
        lines = fh.read().splitlines()
    counts, box, i = {}, {}, 1
    # header: up to the first section keyword
    while i < len(lines):
        text = lines[i].split("#", 1)[0]
        if not text.strip():
            i += 1
            continue
        m = _HEADER_COUNT.match(text)
        b = _HEADER_BOX.match(text)
        if m:
            counts[m.group(2)] = int(m.group(1))
        elif b:
            box[b.group(3)[0]] = (float(b.group(1)), float(b.group(2)))
        elif text.split()[-3:] == ["xy", "xz", "yz"]:
            if any(float(t) != 0.0 for t in text.split()[:3]):
                raise InputError(f"{path}: a triclinic box ({text.strip()}); mpdem's box is orthogonal")
        elif _SECTION.match(lines[i]):
            break
        else:
            raise InputError(f"{path}: line {i + 1}: unknown header line {lines[i].strip()!r}")
        i += 1
    for axis in "xyz":
        if axis not in box:
            raise InputError(f"{path}: no '{axis}lo {axis}hi' line in the header")
    n = counts.get("atoms", 0)
    sections, style = {}, None
    while i < len(lines):
        m = _SECTION.match(lines[i])
        if not m:
            if lines[i].split("#", 1)[0].strip():
                raise InputError(f"{path}: line {i + 1}: expected a section keyword, found {lines[i].strip()!r}")
            i += 1
            continue
        name = m.group(1).strip()
        if name == "Atoms" and m.group(2):
            style = m.group(2).lstrip("#").strip() or None
        body, i = [], i + 1
        while i < len(lines) and not _SECTION.match(lines[i]):
            body.append(lines[i])
            i += 1
        sections[name] = body
    if style is not None and style != "sphere":
        raise InputError(f"{path}: atom_style {style}; mpdem reads atom_style sphere "
                         f"(id type diameter density x y z)")
    if "Atoms" not in sections:
        raise InputError(f"{path}: no Atoms section")
    atoms = _numbers(sections["Atoms"], path, "Atoms (atom_style sphere: id type diameter density x y z "
                     "[ix iy iz])", (7, 10))
    if len(atoms) != n:
        raise InputError(f"{path}: the header says {n} atoms, the Atoms section has {len(atoms)}")
    ids = atoms[:, 0] - (1 if ID_SHIFT_NOTE in lines[0] else 0)
    out = {"id": ids, "types": atoms[:, 1], "diameter": atoms[:, 2], "kind": "data",
           "mass": 4.0 * math.pi / 3.0 * (0.5 * atoms[:, 2]) ** 3 * atoms[:, 3],
           "x": atoms[:, 4:7].copy(), "box": box, "periodic": (True, True),
           "note": "LAMMPS data file, atom_style sphere"}
    if atoms.shape[1] == 10:
        out["image"] = atoms[:, 7:10]
    if "Velocities" in sections:
        vel = _numbers(sections["Velocities"], path, "Velocities (atom_style sphere: id vx vy vz "
                       "omegax omegay omegaz)", (7,))
        if len(vel) != n:
            raise InputError(f"{path}: {n} atoms but {len(vel)} rows of Velocities")
        order = {int(a): r for r, a in enumerate(atoms[:, 0])}
        try:
            rows = np.array([order[int(a)] for a in vel[:, 0]])
        except KeyError as e:
            raise InputError(f"{path}: Velocities of atom {e.args[0]}, which is not in Atoms") from None
        out["v"] = np.zeros((n, 3))
        out["omega"] = np.zeros((n, 3))
        out["v"][rows] = vel[:, 1:4]
        out["omega"][rows] = vel[:, 4:7]
    return out


def _read_dump(path):
    """The last snapshot of a text dump (``ITEM: ATOMS id type x y z ...``)."""
    with open_text(path) as fh:
        lines = fh.read().splitlines()
    starts = [k for k, ln in enumerate(lines) if ln.startswith("ITEM: TIMESTEP")]
    s = starts[-1]
    try:
        step = int(lines[s + 1])
        if not lines[s + 2].startswith("ITEM: NUMBER OF ATOMS"):
            raise ValueError("no NUMBER OF ATOMS")
        n = int(lines[s + 3])
        bounds = lines[s + 4]
        if not bounds.startswith("ITEM: BOX BOUNDS"):
            raise ValueError("no BOX BOUNDS")
        flags = bounds.split()[3:]
        if "xy" in flags:
            raise InputError(f"{path}: a triclinic box ({bounds}); mpdem's box is orthogonal")
        box = {a: tuple(map(float, lines[s + 5 + r].split()[:2])) for r, a in enumerate("xyz")}
        head = lines[s + 8]
        if not head.startswith("ITEM: ATOMS"):
            raise ValueError("no ATOMS")
    except (IndexError, ValueError) as e:
        raise InputError(f"{path}: the snapshot at line {s + 1} is not a LAMMPS text dump ({e})") from None
    cols = head.split()[2:]
    data = _numbers(lines[s + 9:s + 9 + n], path, f"ITEM: ATOMS {' '.join(cols)}", (len(cols),))
    if len(data) != n:
        raise InputError(f"{path}: the snapshot of step {step} says {n} atoms and has {len(data)} rows")
    col = {c: data[:, k] for k, c in enumerate(cols)}
    for need in ("id", "type"):
        if need not in col:
            raise InputError(f"{path}: no {need} column in ITEM: ATOMS {' '.join(cols)}")
    x = np.zeros((n, 3))
    for a, axis in enumerate("xyz"):
        lo, hi = box[axis]
        if axis in col:
            x[:, a] = col[axis]
        elif axis + "u" in col:
            x[:, a] = col[axis + "u"]
        elif axis + "s" in col:
            x[:, a] = lo + col[axis + "s"] * (hi - lo)
        else:
            raise InputError(f"{path}: no {axis} (or {axis}u, {axis}s) column in ITEM: ATOMS {' '.join(cols)}")
    out = {"id": col["id"], "types": col["type"], "x": x, "box": box, "kind": "dump",
           "periodic": tuple(f.startswith("p") for f in flags[:2]) if len(flags) >= 2 else (True, True),
           "note": f"LAMMPS text dump, step {step}" + (f" (the last of {len(starts)} snapshots)"
                                                       if len(starts) > 1 else "")}
    if "diameter" in col:
        out["diameter"] = col["diameter"]
    elif "radius" in col:
        out["diameter"] = 2.0 * col["radius"]
    if "mass" in col:
        out["mass"] = col["mass"]
    if "ix" in col and all(axis in col for axis in "xyz"):
        out["image"] = np.stack([col["ix"], col["iy"], col["iz"]], axis=1)
    if all(c in col for c in ("vx", "vy", "vz")):
        out["v"] = np.stack([col["vx"], col["vy"], col["vz"]], axis=1)
    if all(c in col for c in ("omegax", "omegay", "omegaz")):
        out["omega"] = np.stack([col["omegax"], col["omegay"], col["omegaz"]], axis=1)
    return out


def _to_mpdem(raw, fixed_types, path, what):
    """Check a LAMMPS particle set against mpdem's model and put it in mpdem's frame."""
    n = len(raw["id"])
    if not np.all(np.isfinite(raw["x"])):
        raise InputError(f"{path}: non-finite positions")
    ids, types = particle_ids(raw["id"], path), raw["types"]
    if np.any(types != np.round(types)):
        raise InputError(f"{path}: atom types must be integers")
    types = types.astype(np.int64)
    for name, rtol, what in (("diameter", DIAMETER_RTOL, "the unit of length"),
                             ("mass", MASS_RTOL, f"the unit of mass; density {RHO!r} for diameter 1")):
        off = np.abs(raw[name] - 1.0) > rtol if name in raw else np.zeros(n, bool)
        if off.any():
            k = int(np.argmax(off))
            raise InputError(f"{path}: atom {ids[k]} has {name} {float(raw[name][k])!r}"
                             + (" (4/3 pi r^3 rho)" if name == "mass" else "")
                             + f"; mpdem's spheres all have {name} 1 ({what})")
    if not all(raw["periodic"]):
        raise InputError(f"{path}: the box is not periodic in x and y; mpdem's is")
    present = sorted(set(types.tolist()))
    unknown = sorted(set(fixed_types) - set(present))
    if unknown:
        raise InputError(f"run.fixed_types = {list(fixed_types)}: {path} has no atom of type "
                         f"{', '.join(map(str, unknown))}; its types are {present}")
    (xlo, xhi), (ylo, yhi) = raw["box"]["x"], raw["box"]["y"]
    L_x, L_y = xhi - xlo, yhi - ylo
    if not (L_x > 0 and L_y > 0):
        raise InputError(f"{path}: box {xlo:g} {xhi:g} x {ylo:g} {yhi:g} is empty")
    x = raw["x"].copy()
    if "image" in raw:
        x[:, 0] += raw["image"][:, 0] * L_x
        x[:, 1] += raw["image"][:, 1] * L_y
    for a, lo, length in ((0, xlo, L_x), (1, ylo, L_y)):
        if lo != 0.0:
            x[:, a] -= lo
        x[:, a] %= length
        # -tiny % L rounds to L
        x[x[:, a] >= length, a] = 0.0
    return {"id": ids, "types": types, "x": x,
            "v": raw.get("v", np.zeros((n, 3))), "omega": raw.get("omega", np.zeros((n, 3))),
            "fixed": np.isin(types, np.asarray(fixed_types, np.int64)).astype(np.uint8),
            "L_x": float(L_x), "L_y": float(L_y), "kind": raw["kind"],
            "types_present": present, "note": raw["note"]}


def data_lines(ids, x, v, omega, fixed, L_x, L_y, title):
    """A LAMMPS data file (atom_style sphere) of mpdem particles, as lines.

    Types 1 mobile and 2 bed, diameter 1, density ``RHO`` (mass exactly 1 in
    LAMMPS), image flags 0; ids as they are, or all + 1 when one is 0
    (LAMMPS's start at 1; the title says so and ``read`` takes it off); box [0, L_x) x [0, L_y) and in z from
    min(0, lowest sphere bottom) to the highest top plus one diameter;
    Velocities with the angular velocities. Floats with 17 significant
    digits, so ``read`` gives back the same doubles.

    Parameters
    ----------
    ids : (N,) int64; x, v, omega : (N, 3) float64; fixed : (N,) uint8
    L_x, L_y : float
    title : str
        The first line (one line).
    """
    n = len(ids)
    ids = np.asarray(ids)
    if n and int(ids.min()) < 1:
        ids = ids + 1
        title = f"{title} ({ID_SHIFT_NOTE})"
    zlo = min(0.0, float(x[:, 2].min()) - 0.5) if n else 0.0
    zhi = float(x[:, 2].max()) + 1.5 if n else 1.0
    yield title.replace("\n", " ") + "\n\n"
    yield f"{n} atoms\n2 atom types\n\n"
    yield f"0 {L_x:.17g} xlo xhi\n0 {L_y:.17g} ylo yhi\n{zlo:.17g} {zhi:.17g} zlo zhi\n\n"
    yield "Atoms # sphere\n\n"
    types = np.where(np.asarray(fixed) != 0, TYPE_BED, TYPE_MOBILE)
    for row in zip(ids.tolist(), types.tolist(), *np.asarray(x).T.tolist()):
        yield "%d %d 1 %r %.17g %.17g %.17g 0 0 0\n" % (row[0], row[1], RHO, *row[2:])
    yield "\nVelocities\n\n"
    for row in zip(ids.tolist(), *np.asarray(v).T.tolist(), *np.asarray(omega).T.tolist()):
        yield "%d" % row[0] + " %.17g" * 6 % row[1:] + "\n"


def state_data(a, attrs, path):
    """The lines of a LAMMPS data file (atom_style sphere, ``data_lines``) of a state file's arrays ``a``
    and attributes: what ``export --format lammps-data`` and the LAMMPS input writer write."""
    title = (f"mpdem state {os.path.basename(path)}, step {int(attrs['step'])}, time {float(attrs['time']):.17g}; "
             f"atom_style sphere, type 1 mobile, 2 bed")
    return data_lines(a["id"], a["x"], a["v"], a["omega"], a["fixed"], float(attrs["L_x"]), float(attrs["L_y"]),
                      title)
