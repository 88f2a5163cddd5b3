"""State files (HDF5): the only place that reads or writes them.

Format ``mpdem-state`` version 1, rows sorted by particle id:

``/particles/{id, x, v, omega, f, torque, fixed}``
    per-particle datasets, shapes (n,) or (n, 3);
``/contacts/{count, partner, ds}``
    contact slots: per-particle counts (n,), then flat partner ids (M,) and
    tangential displacements (M, 3), in particle-id order;
attributes: ``format``, ``version``, ``kind``, ``step``, ``time``,
``n_mobile``, ``n_bed``, ``L_x``, ``L_y``, ``z_bed``, ``config`` (TOML text).

Files are written under a temporary name and renamed, so a crash never leaves
a half-written file under a real name. (Parallel collective writing and
restart checkpoints arrive with the checkpoint issue.)
"""
from __future__ import annotations

import hashlib
import os

import h5py
import numpy as np

FORMAT = "mpdem-state"
VERSION = 1
PARTICLE_FIELDS = ("id", "x", "v", "omega", "f", "torque", "fixed")


class StateFileError(ValueError):
    """A state file that cannot be used."""


def gather_state(state):
    """The owned particles of a State as id-sorted arrays (one rank)."""
    n = state.n_own
    counts, partner, ds, order = state.contacts_flat()
    return {
        "id": state.ids[:n][order], "x": state.x[:n][order], "v": state.v[:n][order],
        "omega": state.omega[:n][order], "f": state.f[:n][order],
        "torque": state.torque[:n][order], "fixed": state.fixed[:n][order],
        "count": counts, "partner": partner, "ds": ds,
    }


def digest(arrays):
    """SHA-256 over the state sorted by id (positions, velocities, angular
    velocities, forces, torques, contact slots), as hex."""
    h = hashlib.sha256()
    for name in PARTICLE_FIELDS + ("count", "partner", "ds"):
        a = np.ascontiguousarray(arrays[name])
        a = a.astype(a.dtype.newbyteorder("<"), copy=False)
        h.update(name.encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def write_state(path, arrays, attrs):
    """Write id-sorted arrays and attributes atomically to ``path``."""
    tmp = f"{path}.tmp"
    with h5py.File(tmp, "w") as f:
        f.attrs["format"] = FORMAT
        f.attrs["version"] = VERSION
        for k, v in attrs.items():
            f.attrs[k] = v
        g = f.create_group("particles")
        for name in PARTICLE_FIELDS:
            g.create_dataset(name, data=arrays[name])
        c = f.create_group("contacts")
        c.create_dataset("count", data=arrays["count"])
        c.create_dataset("partner", data=arrays["partner"])
        c.create_dataset("ds", data=np.asarray(arrays["ds"]).reshape(-1, 3))
        f.flush()
    os.replace(tmp, path)


def read_state(path):
    """Read a state file: (arrays, attrs). Raises StateFileError if unusable."""
    try:
        f = h5py.File(path, "r")
    except (OSError, FileNotFoundError) as e:
        raise StateFileError(f"{path}: cannot open as HDF5 ({e})") from None
    with f:
        if f.attrs.get("format") != FORMAT:
            raise StateFileError(f"{path}: not an mpdem state file (format = {f.attrs.get('format')!r})")
        if int(f.attrs.get("version", -1)) != VERSION:
            raise StateFileError(f"{path}: format version {f.attrs.get('version')} is not supported "
                                 f"(this mpdem reads version {VERSION})")
        try:
            arrays = {n: f["particles"][n][()] for n in PARTICLE_FIELDS}
            for n in ("count", "partner", "ds"):
                arrays[n] = f["contacts"][n][()]
        except KeyError as e:
            raise StateFileError(f"{path}: missing dataset {e}") from None
        attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
    n = len(arrays["id"])
    if any(len(arrays[k]) != n for k in PARTICLE_FIELDS) or arrays["count"].sum() != len(arrays["partner"]):
        raise StateFileError(f"{path}: inconsistent dataset lengths")
    return arrays, attrs


def is_state_file(path):
    """True if ``path`` looks like HDF5 (by its signature)."""
    try:
        with open(path, "rb") as fh:
            return fh.read(8) == b"\x89HDF\r\n\x1a\n"
    except OSError:
        return False
