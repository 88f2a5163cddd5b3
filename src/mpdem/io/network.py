"""The contact network of a state file for viewers: force chains in ParaView and OVITO.

Two exports of a state file's contact list (``/pairs``: a snapshot or a final state):

``contacts`` (``<name>.contacts.h5`` and its XDMF 3 sidecar ``<name>.contacts.xmf``)
    a Polyline grid of 2-node cells for ParaView or VisIt. Each contact is two cells,
    from each sphere's centre to the contact point (``x_i - b/2`` and ``x_j + b/2``,
    b = x_i - x_j by minimum image), so a contact across a periodic face is drawn as two
    half-lines, one at each face, and none crosses the box. Cell data, equal on both
    halves: ``F_n`` (signed normal force, compressive > 0) [m g], ``F_t`` (|F_t|) [m g],
    ``zeta`` (|F_t| / (mu F_n); 0 at mu = 0) and ``delta`` (overlap) [d], ``id_i``,
    ``id_j``; the XDMF says how many contacts cross a face.
``lammps-local``
    a LAMMPS ``dump local`` frame, one line per contact: ``index patom1 patom2 dist fn
    ft zeta delta fx fy fz`` (fx, fy, fz the total contact force on patom1), which
    OVITO's "Load trajectory" modifier reads as bonds (patom1, patom2 the particle
    identifiers) with these as bond properties.

Reduced units: lengths [d], forces [m g].
"""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET

import h5py
import numpy as np

from . import checkpoint, diskspace
from ..errors import WriteError
from ..kernels.pairdist import separations
from .rundir import CONTACTS_DIR, write_atomic


# the cell data of a contact (both half-lines carry it)
CELL_DATA = ("F_n", "F_t", "zeta", "delta", "id_i", "id_j")


def contact_table(path):
    """The contacts of a state file with geometry and forces.

    Returns
    -------
    dict of (P,) / (P, 3) arrays: id_i, id_j, x_i, x_j, branch (x_i - x_j, minimum image),
    dist, F_n, F_t (vector on i), ft (|F_t|), zeta, delta, force (total on i); and attrs
    """
    from ..errors import StateFileError
    a, attrs = checkpoint.read_state(path, pairs=True)
    if "id_i" not in a:
        raise StateFileError(f"{path}: no contact list (a checkpoint); a snapshot or final state has one")
    L_x, L_y = float(attrs["L_x"]), float(attrs["L_y"])
    rows_i = np.searchsorted(a["id"], a["id_i"])
    rows_j = np.searchsorted(a["id"], a["id_j"])
    b = separations(a["x"], rows_i, rows_j, L_x, L_y)
    dist = np.sqrt(np.einsum("ij,ij->i", b, b))
    nrm = b / dist[:, None]
    ft = np.sqrt(np.einsum("ij,ij->i", a["F_t"], a["F_t"]))
    mu = _mu(attrs)
    with np.errstate(invalid="ignore", divide="ignore"):
        zeta = np.where((a["F_n"] > 0) & (mu > 0), ft / (mu * a["F_n"]), 0.0)
    return {"id_i": a["id_i"], "id_j": a["id_j"], "x_i": a["x"][rows_i], "x_j": a["x"][rows_j], "branch": b,
            "dist": dist, "F_n": a["F_n"], "F_t": a["F_t"], "ft": ft, "zeta": zeta, "delta": a["delta"],
            "force": a["F_n"][:, None] * nrm + a["F_t"]}, attrs


def _mu(attrs):
    """The friction coefficient of a state file's config (0 when it says none)."""
    import tomllib
    try:
        return float(tomllib.loads(attrs.get("config", ""))["contact"]["mu"])
    except (KeyError, ValueError, tomllib.TOMLDecodeError):
        return 0.0


def crossing(t, L_x, L_y):
    """(P,) bool: contacts whose two centres are on opposite sides of a periodic face."""
    raw = t["x_i"] - t["x_j"]
    return (np.abs(raw[:, 0] - t["branch"][:, 0]) > 0.5 * L_x) | (np.abs(raw[:, 1] - t["branch"][:, 1]) > 0.5 * L_y)


def write_contacts_xdmf(path, out=None):
    """``<name>.contacts.h5`` and ``<name>.contacts.xmf`` of state file ``path`` (see the module).

    Returns
    -------
    str : the path of the .xmf file
    """
    t, attrs = contact_table(path)
    stem = out or os.path.splitext(path)[0] + ".contacts"
    if os.path.dirname(stem):
        os.makedirs(os.path.dirname(stem), exist_ok=True)
    h5, xmf = stem + ".h5", stem + ".xmf"
    P = len(t["dist"])
    half = 0.5 * t["branch"]
    # per contact: x_i, its contact point, x_j, its contact point (4 nodes, 2 cells)
    pts = np.empty((4 * P, 3))
    pts[0::4], pts[1::4], pts[2::4], pts[3::4] = t["x_i"], t["x_i"] - half, t["x_j"], t["x_j"] + half
    conn = np.arange(4 * P, dtype=np.int64).reshape(2 * P, 2)
    cells = dict(zip(CELL_DATA, (t["F_n"], t["ft"], t["zeta"], t["delta"], t["id_i"], t["id_j"])))
    n_cross = int(crossing(t, float(attrs["L_x"]), float(attrs["L_y"])).sum())
    tmp = h5 + ".tmp"
    # the room first: the HDF5 library cannot close a file it failed to flush (checkpoint.HELD)
    why = diskspace.reserve(tmp, pts.nbytes + conn.nbytes + sum(2 * np.asarray(v).nbytes for v in cells.values())
                            + 65536, name=h5)
    if why:
        raise WriteError(why)
    try:
        with h5py.File(tmp, "w") as f:
            f["points"], f["connectivity"] = pts, conn
            for k, v in cells.items():
                f[f"cells/{k}"] = np.repeat(np.asarray(v), 2)
            f.attrs.update(source=os.path.basename(path), step=int(attrs["step"]), time=float(attrs["time"]),
                           n_contacts=P, n_crossing=n_cross)
        os.replace(tmp, h5)
    except (OSError, RuntimeError) as e:
        diskspace.remove(tmp)
        raise WriteError(f"cannot write {h5}: {e}") from None
    root = ET.Element("Xdmf", Version="3.0")
    dom = ET.SubElement(root, "Domain")
    ET.SubElement(dom, "Information", Name="contacts",
                  Value=f"{P} contacts of {os.path.basename(path)} as {2 * P} half-lines (centre to contact "
                        f"point); {n_cross} cross a periodic face and show as a half-line at each")
    dom.append(contacts_grid(h5, os.path.dirname(os.path.abspath(xmf)))[2])
    ET.indent(root)
    write_atomic(xmf, ['<?xml version="1.0" ?>\n', ET.tostring(root, encoding="unicode"), "\n"])
    return xmf


def contacts_path(path):
    """The contact network file that a run writes for state file ``DIR/<name>.h5``:
    ``DIR/contacts/<name>.contacts.h5``. A directory of its own, so that ``snapshots/*.h5`` and
    ``RUN/*.h5`` still list state files only."""
    d, base = os.path.split(path)
    return os.path.join(d, CONTACTS_DIR, os.path.splitext(base)[0] + ".contacts.h5")


def contacts_grid(h5, xmf_dir):
    """The Polyline grid of a contact network file (``write_contacts_xdmf``'s .h5).

    Parameters
    ----------
    h5 : str
    xmf_dir : str
        Directory of the XDMF file the grid goes in; dataset paths are relative to it.

    Returns
    -------
    (time, step, grid) : float, int, Element
    """
    ref = os.path.relpath(os.path.abspath(h5), xmf_dir)
    with h5py.File(h5, "r") as f:
        time, step, P = float(f.attrs["time"]), int(f.attrs["step"]), int(f.attrs["n_contacts"])
        kinds = {k: ("Int", "8") if f[f"cells/{k}"].dtype.kind in "iu" else ("Float", "8") for k in f["cells"]}
    grid = ET.Element("Grid", Name=os.path.splitext(os.path.basename(h5))[0], GridType="Uniform")
    ET.SubElement(grid, "Time", Value=repr(time))
    topo = ET.SubElement(grid, "Topology", TopologyType="Polyline", NumberOfElements=str(2 * P),
                         NodesPerElement="2")
    topo.append(_item(f"{ref}:/connectivity", (2 * P, 2), "Int", "8"))
    geo = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
    geo.append(_item(f"{ref}:/points", (4 * P, 3), "Float", "8"))
    for k in CELL_DATA:
        att = ET.SubElement(grid, "Attribute", Name=k, Center="Cell", AttributeType="Scalar")
        att.append(_item(f"{ref}:/cells/{k}", (2 * P,), *kinds[k]))
    return time, step, grid


def _item(text, dims, kind, precision):
    it = ET.Element("DataItem", Dimensions=" ".join(map(str, dims)), NumberType=kind, Precision=precision,
                    Format="HDF")
    it.text = text
    return it


def lammps_local_lines(path):
    """The lines of a LAMMPS ``dump local`` frame of the contacts of state file ``path``."""
    t, attrs = contact_table(path)
    x = np.concatenate([t["x_i"], t["x_j"]]) if len(t["dist"]) else np.zeros((1, 3))
    zlo, zhi = x[:, 2].min() - 0.5, x[:, 2].max() + 0.5
    yield (f"ITEM: TIMESTEP\n{int(attrs['step'])}\nITEM: NUMBER OF ENTRIES\n{len(t['dist'])}\n"
           f"ITEM: BOX BOUNDS pp pp ff\n0 {float(attrs['L_x']):.17g}\n0 {float(attrs['L_y']):.17g}\n"
           f"{zlo:.17g} {zhi:.17g}\n"
           "ITEM: ENTRIES index patom1 patom2 dist fn ft zeta delta fx fy fz\n")
    cols = [np.arange(1, len(t["dist"]) + 1), t["id_i"], t["id_j"], t["dist"], t["F_n"], t["ft"], t["zeta"],
            t["delta"], *t["force"].T]
    fmt = "%d %d %d" + " %.17g" * 8 + "\n"
    for row in zip(*(np.asarray(c).tolist() for c in cols)):
        yield fmt % row
