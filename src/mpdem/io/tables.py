"""Text tables of particles: ``id x y z [vx vy vz] [omegax omegay omegaz] [fixed]``.

Read plain or gzip-compressed (``read_table``), written exactly (``write_table``:
the repr of every double, atomic), tiled side by side (``tile_table``, for the
bench). Initial states and ``bed.txt`` use them (docs/running.md).
"""
from __future__ import annotations

import gzip

import numpy as np

from .rundir import write_atomic
from ..errors import InputError
from ..state import INITIAL


def open_text(path):
    """A text file handle of ``path``, decompressing gzip (magic bytes 1f 8b).

    Raises
    ------
    InputError for a file named ``.gz`` that is not gzip-compressed.
    """
    with open(path, "rb") as fh:
        magic = fh.read(2)
    if magic == b"\x1f\x8b":
        return gzip.open(path, "rt")
    if str(path).endswith(".gz"):
        raise InputError(f"{path}: named .gz but not gzip-compressed (it begins {magic!r}, gzip begins "
                         f"b'\\x1f\\x8b'); compress it with gzip or drop the .gz")
    return open(path)


def read_table(path):
    """Read a text table of particles.

    Columns ``id x y z`` with optional ``vx vy vz``, ``omegax omegay omegaz``
    and ``fixed`` (1 = bed). A first line naming the columns (``#``
    optional) sets their order; without it, 4, 5, 7 or 8 columns are read
    as id x y z [vx vy vz] [fixed].

    A gzip-compressed table (any name; recognised by its magic bytes) is
    read the same way.

    Returns
    -------
    dict with id (N,) int64, x (N, 3), v (N, 3), omega (N, 3) (zero when
    not in the table), fixed (N,) uint8.
    """
    try:
        with open_text(path) as fh:
            lines = [ln for ln in fh if ln.strip()]
    except (OSError, EOFError, UnicodeDecodeError) as e:
        raise InputError(f"{path}: cannot read the particle table: {e}") from None
    if not lines:
        raise InputError(f"{path}: empty particle table")
    first = lines[0].lstrip("#").split()
    names = None
    try:
        [float(t) for t in first]
    except ValueError:
        names = [t.lower() for t in first]
        lines = lines[1:]
    lines = [ln for ln in lines if not ln.lstrip().startswith("#")]
    try:
        data = np.loadtxt(lines, ndmin=2) if lines else np.zeros((0, len(names or [0] * 4)))
    except ValueError as e:
        raise InputError(f"{path}: unreadable particle table: {e}") from None
    if names is None:
        names = {4: "id x y z", 5: "id x y z fixed", 7: "id x y z vx vy vz",
                 8: "id x y z vx vy vz fixed"}.get(data.shape[1], "").split()
        if not names:
            raise InputError(f"{path}: {data.shape[1]} columns; expected a header line or "
                             f"id x y z [vx vy vz] [fixed]")
    if len(names) != data.shape[1]:
        raise InputError(f"{path}: header names {len(names)} columns but rows have {data.shape[1]}")
    known = {"id", "x", "y", "z", "vx", "vy", "vz", "omegax", "omegay", "omegaz", "fixed"}
    unknown = set(names) - known
    if unknown or not {"id", "x", "y", "z"} <= set(names):
        raise InputError(f"{path}: columns {names}; need id x y z, optional vx vy vz omegax omegay omegaz fixed")
    col = {n: data[:, i] for i, n in enumerate(names)}
    if not np.all(np.isfinite(data)):
        raise InputError(f"{path}: non-finite values in the particle table")
    ids = particle_ids(col["id"], path)
    n = len(ids)
    v = np.zeros((n, 3))
    omega = np.zeros((n, 3))
    for a, nm in enumerate(("vx", "vy", "vz")):
        if nm in col:
            v[:, a] = col[nm]
        if "omega" + "xyz"[a] in col:
            omega[:, a] = col["omega" + "xyz"[a]]
    fixed = col.get("fixed", np.zeros(n))
    if np.any((fixed != 0) & (fixed != 1)):
        raise InputError(f"{path}: column fixed must be 0 or 1")
    return {"id": ids, "x": np.stack([col["x"], col["y"], col["z"]], axis=1), "v": v, "omega": omega,
            "fixed": fixed.astype(np.uint8)}


def particle_ids(values, path):
    """Particle ids read as floats, checked: non-negative integers, each once. (N,) int64."""
    if np.any(values != np.round(values)) or np.any(values < 0):
        raise InputError(f"{path}: ids must be non-negative integers")
    ids = values.astype(np.int64)
    if len(np.unique(ids)) != len(ids):
        raise InputError(f"{path}: duplicate particle ids")
    return ids


def write_table(path, ids, x, v=None, fixed=None, omega=None):
    """Write a particle table readable by ``read_table`` (exact: repr of doubles);
    with ``omega``, the columns omegax omegay omegaz too. Atomic: written to
    ``path.tmp``, then renamed."""
    n = len(ids)
    v = np.zeros((n, 3)) if v is None else v
    fixed = np.zeros(n, np.uint8) if fixed is None else fixed

    def lines():
        yield "# id x y z vx vy vz" + (" omegax omegay omegaz" if omega is not None else "") + " fixed\n"
        for k in range(n):
            row = [float(a) for a in (*x[k], *v[k], *(omega[k] if omega is not None else ()))]
            yield f"{int(ids[k])} " + " ".join(map(repr, row)) + f" {int(fixed[k])}\n"
    write_atomic(path, lines())


def tile_table(table, L_x, L_y, nx, ny):
    """Copies of an x-y periodic particle table side by side: nx along x, ny along y.

    Parameters
    ----------
    table : dict
        ``read_table``'s arrays: id (N,) int64, x (N, 3) [d], v (N, 3)
        [sqrt(g d)], fixed (N,) uint8, in a box periodic in [0, L_x) x [0, L_y).
    L_x, L_y : float
        The table's box [d].
    nx, ny : int
        Copies along x and y, >= 1.

    Returns
    -------
    dict like ``table`` with nx * ny * N rows in a box nx L_x by ny L_y:
    copy k = j nx + i is shifted by (i L_x, j L_y, 0) and its ids by
    k (max id + 1), so copy 0 keeps the table's ids and all ids are unique.
    """
    if nx < 1 or ny < 1:
        raise InputError(f"tiling {nx} x {ny}: accepted at least one copy along x and y")
    x0 = table["x"].copy()
    x0[:, 0] %= L_x
    x0[:, 1] %= L_y
    k = np.arange(nx * ny)
    shift = np.stack([(k % nx) * L_x, (k // nx) * L_y, np.zeros(nx * ny)], axis=1)   # (K, 3)
    span = int(table["id"].max(initial=-1)) + 1
    # every field of the table copied as it is, then ids and positions shifted
    out = {k: np.tile(table[k], (nx * ny,) + (1,) * (np.ndim(table[k]) - 1)) for k in INITIAL if k in table}
    out["id"] = (table["id"][None, :] + span * k[:, None]).reshape(-1)
    out["x"] = (x0[None, :, :] + shift[:, None, :]).reshape(-1, 3)
    return out
