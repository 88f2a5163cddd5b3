"""Exports of state files for visualisation tools (serial, no MPI).

XDMF sidecars (ParaView, VisIt) only point into the HDF5 state file, so they
are small and stay valid as long as the pair of files is kept together; the
LAMMPS dump and extended XYZ formats (OVITO, ASE, VMD) are text copies.
Particles only: the contact slots and a snapshot's pair list are not
exported (``checkpoint.read_state(path, pairs=True)`` reads them).

The export formats are one table, ``FORMATS`` (name -> ``Format``): the command line's
``--format`` choices and help come from it, so a new format is one writer and one entry here. The
files a run writes beside every snapshot and final.h5 are another, ``SIDECARS``.
The module imports h5py and the state files' reader on first use, so the command line can read
the table without loading them.

Reduced units throughout: lengths [d], times [sqrt(d/g)], forces [m g].
"""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..kernels.particle import R    # particle radius [d]
from .lammps import state_data
from . import rundir
from .rundir import write_atomic
from ..state import FIELDS, PARTICLE

# XDMF 3 (NumberType, Precision) of the dtypes in a state file. XDMF 3 reads
# "UInt" as 32-bit whatever its Precision, so one unsigned byte is "UChar".
XDMF_TYPES = {"f8": ("Float", "8"), "i8": ("Int", "8"), "i4": ("Int", "4"), "u1": ("UChar", "1")}
# node attributes of the XDMF grid: name -> dataset (the exported per-particle fields of the registry)
XDMF_ATTRIBUTES = {f.exported: f"{f.group}/{f.name}" for f in FIELDS if f.exported and f.per == PARTICLE}


# -- XDMF --
def _data_item(ds, ref):
    """A DataItem for an HDF5 dataset; ``ref`` is the HDF5 file as the XDMF file sees it."""
    kind, precision = XDMF_TYPES[ds.dtype.str[1:]]
    item = ET.Element("DataItem", Dimensions=" ".join(map(str, ds.shape)), NumberType=kind,
                      Precision=precision, Format="HDF")
    item.text = f"{ref}:{ds.name}"
    return item


def _grid(h5_path, xmf_dir):
    """The Polyvertex grid of one state file.

    Parameters
    ----------
    h5_path : str
    xmf_dir : str
        Directory of the XDMF file the grid goes in; dataset paths are
        relative to it.

    Returns
    -------
    (time, step, grid) : float, int, Element
    """
    import h5py
    from . import checkpoint
    attrs = checkpoint.read_attrs(h5_path)          # layout checks; raises StateFileError
    time, step = float(attrs["time"]), int(attrs["step"])
    ref = os.path.relpath(os.path.abspath(h5_path), xmf_dir)
    grid = ET.Element("Grid", Name=os.path.splitext(os.path.basename(h5_path))[0], GridType="Uniform")
    ET.SubElement(grid, "Time", Value=repr(time))
    with h5py.File(h5_path, "r") as f:
        x = f["particles/x"]
        ET.SubElement(grid, "Topology", TopologyType="Polyvertex", NumberOfElements=str(x.shape[0]),
                      NodesPerElement="1")
        ET.SubElement(grid, "Geometry", GeometryType="XYZ").append(_data_item(x, ref))
        for name, path in XDMF_ATTRIBUTES.items():
            ds = f[path]
            ET.SubElement(grid, "Attribute", Name=name, Center="Node",
                          AttributeType="Vector" if ds.ndim == 2 else "Scalar").append(_data_item(ds, ref))
        ET.SubElement(grid, "Attribute", Name="radius", Center="Node",
                      AttributeType="Scalar").append(_radius_item(x.shape[0]))
    return time, step, grid


def _radius_item(n):
    """An inline (XML) DataItem of n radii R: the state file has no radius dataset (every sphere has
    d = 1), and a viewer's Point Gaussian or Glyph scales by an array. 4 bytes per sphere of sidecar."""
    item = ET.Element("DataItem", Dimensions=str(n), NumberType="Float", Precision="8", Format="XML")
    row = " ".join([repr(R)] * 32)
    item.text = "\n".join([row] * (n // 32) + ([" ".join([repr(R)] * (n % 32))] if n % 32 else []))
    return item


def _write_xdmf_doc(path, *grids):
    """Wrap grids in an XDMF 3 document and write it atomically."""
    root = ET.Element("Xdmf", Version="3.0")
    ET.SubElement(root, "Domain").extend(grids)
    ET.indent(root)
    write_atomic(path, ['<?xml version="1.0" ?>\n', ET.tostring(root, encoding="unicode"), "\n"])


def write_xdmf(h5_path):
    """Write the XDMF 3 sidecar ``<name>.xmf`` of a state file ``<name>.h5``.

    The sidecar describes the particles as a Polyvertex grid of n points:
    geometry XYZ from ``/particles/x`` (n, 3) [d]; node attributes ``id``
    (n,) int64, ``fixed`` (n,) uint8 (1 for bed), ``v`` (n, 3) [sqrt(g d)],
    ``omega`` (n, 3) [sqrt(g/d)], ``f`` (n, 3) [m g], ``torque`` (n, 3)
    [m g d] and ``contacts`` (n,) int32 (contact slots per particle), and
    ``radius`` (n,) float64 [d], inline in the sidecar (0.5 for every sphere;
    the state file has no radius dataset); the grid's Time is the file's
    ``time``. Datasets are referenced through the HDF5 file's base name, so
    the two files can be moved together.

    In ParaView: the Point Gaussian representation with "Scale by array"
    ``radius`` (scale 1), or a Glyph filter of spheres scaled by ``radius``
    (sphere radius 1).

    Parameters
    ----------
    h5_path : str
        An mpdem state file (read only; not modified).

    Returns
    -------
    str : path of the written ``.xmf`` file, next to the ``.h5``.
    """
    xmf = os.path.splitext(h5_path)[0] + ".xmf"
    _write_xdmf_doc(xmf, _grid(h5_path, os.path.dirname(os.path.abspath(xmf)))[2])
    return xmf


def write_xdmf_series(paths, out_path):
    """Write one XDMF 3 temporal collection of several state files.

    Each snapshot's grid (as in ``write_xdmf``) is inlined, sorted by time
    (then step); where a state has its contact network beside it
    (``<name>.contacts.h5``, ``network.write_contacts_xdmf``), those grids
    form a second temporal collection, ``contacts``. Dataset paths are
    relative to ``out_path``'s directory, so
    the series file may live anywhere as long as the files keep their
    relative places. (Inlining rather than xi:include: readers resolve the
    HDF5 paths of an included file against the including file.)

    Parameters
    ----------
    paths : iterable of str
        State files (``.h5``) or their sidecars (``.xmf``, standing for the
        ``.h5`` of the same name).
    out_path : str

    Returns
    -------
    str : ``out_path``
    """
    from .network import contacts_grid, contacts_path
    xmf_dir = os.path.dirname(os.path.abspath(out_path))
    h5s = [os.path.splitext(p)[0] + ".h5" if p.endswith(".xmf") else p for p in map(str, paths)]
    grids = sorted((_grid(p, xmf_dir) for p in h5s), key=lambda g: g[:2])
    series = ET.Element("Grid", Name="series", GridType="Collection", CollectionType="Temporal")
    series.extend(g for _, _, g in grids)
    # the contact networks written beside the states (Snapshots), as a second temporal collection
    nets = sorted((contacts_grid(contacts_path(p), xmf_dir) for p in h5s if os.path.exists(contacts_path(p))),
                  key=lambda g: g[:2])
    if not nets:
        _write_xdmf_doc(out_path, series)
        return out_path
    contacts = ET.Element("Grid", Name="contacts", GridType="Collection", CollectionType="Temporal")
    contacts.extend(g for _, _, g in nets)
    _write_xdmf_doc(out_path, series, contacts)
    return out_path


# -- text formats --
def _z_bounds(x):
    """Lowest sphere bottom and highest sphere top [d] of positions (n, 3)."""
    return (x[:, 2].min() - R, x[:, 2].max() + R) if len(x) else (-R, R)


def _rows(fmt, columns):
    """Lines ``fmt % row`` over columns of equal length (exact Python scalars)."""
    return (fmt % row + "\n" for row in zip(*(np.asarray(c).tolist() for c in columns)))


def _lammps_dump(a, attrs, path=None):
    """LAMMPS text dump (one frame): box pp pp ff, atom types 1 mobile, 2 bed."""
    zlo, zhi = _z_bounds(a["x"])
    bounds = ((0.0, attrs["L_x"]), (0.0, attrs["L_y"]), (zlo, zhi))
    yield (f"ITEM: TIMESTEP\n{int(attrs['step'])}\nITEM: NUMBER OF ATOMS\n{len(a['id'])}\n"
           "ITEM: BOX BOUNDS pp pp ff\n" + "".join(f"{lo:.17g} {hi:.17g}\n" for lo, hi in bounds)
           + "ITEM: ATOMS id type x y z vx vy vz omegax omegay omegaz fx fy fz radius\n")
    yield from _rows("%d %d" + " %.17g" * 13,
                     [a["id"], 1 + (a["fixed"] != 0), *a["x"].T, *a["v"].T, *a["omega"].T, *a["f"].T,
                      np.full(len(a["id"]), R)])


def _xyz(a, attrs, path=None):
    """Extended XYZ (one frame): species M mobile, B bed; cell origin at z_lo."""
    zlo, zhi = _z_bounds(a["x"])
    yield (f"{len(a['id'])}\n"
           f'Lattice="{attrs["L_x"]:.17g} 0 0 0 {attrs["L_y"]:.17g} 0 0 0 {zhi - zlo:.17g}" '
           f'Origin="0 0 {zlo:.17g}" '
           "Properties=species:S:1:pos:R:3:velo:R:3:omega:R:3:radius:R:1:id:I:1 "
           f'pbc="T T F" Time={float(attrs["time"]):.17g} Step={int(attrs["step"])}\n')
    yield from _rows("%s" + " %.17g" * 10 + " %d",
                     [np.where(a["fixed"] != 0, "B", "M"), *a["x"].T, *a["v"].T, *a["omega"].T,
                      np.full(len(a["id"]), R), a["id"]])


# -- the formats --
@dataclass(frozen=True)
class Format:
    """One export format.

    Attributes
    ----------
    name : str
        ``--format NAME``.
    about : str
        What it is and for which tool, a few words (the command line's help).
    write : callable(path, out) -> (str, list of str)
        Writes the export of state file ``path`` to ``out`` (None: its default beside ``path``), under a
        temporary name renamed when complete; returns the path written and notes for the user.
    """
    name: str
    about: str
    write: Callable


def _text(render, suffix):
    """The writer of a text format: ``render(arrays, attrs, path)`` -> lines, default ``FILE<suffix>``."""
    def write(path, out):
        from . import checkpoint
        out = out or os.path.splitext(path)[0] + suffix
        arrays, attrs = checkpoint.read_state(path)
        write_atomic(out, render(arrays, attrs, path))
        return out, []
    return write


def _packing(path, out):
    # what the analyses need, compressed (mpdem.io.packing): RUN/final.h5 -> RUN/packing.npz
    from . import checkpoint, packing
    base = os.path.basename(path)
    out = out or (os.path.join(os.path.dirname(path), "packing.npz") if base == "final.h5"
                  else os.path.splitext(path)[0] + ".packing.npz")
    arrays, attrs = checkpoint.read_state(path, pairs=True)
    return packing.write(out, arrays, attrs), []


def _contacts(path, out):
    # the contact network for ParaView: <name>.contacts.h5 and .xmf (mpdem.io.network)
    from .network import write_contacts_xdmf
    xmf = write_contacts_xdmf(path, os.path.splitext(out)[0] if out else None)
    return xmf, [f"wrote {os.path.splitext(xmf)[0]}.h5 (the data the .xmf points to)"]


def _lammps_local(path, out):
    # the contact network for OVITO: a LAMMPS dump local of the contacts (mpdem.io.network)
    from .network import lammps_local_lines
    out = out or os.path.splitext(path)[0] + ".local"
    write_atomic(out, lammps_local_lines(path))
    return out, []


def _lammps_input(path, out):
    # a LAMMPS input script and data file that continue the run in LAMMPS (mpdem.io.lammps_input)
    from . import lammps_input
    script, dropped = lammps_input.write(path, out)
    notes = [f"run it there with `lmp -in {lammps_input.INPUT_NAME}` ({lammps_input.DATA_NAME} beside it)"]
    if dropped:
        notes.append(f"note: {dropped} nonzero contact histories of {path} start at zero in LAMMPS (a data file "
                     f"has none); the trajectories agree to round-off only from a state without them")
    return script, notes


FORMATS = {f.name: f for f in (
    Format("lammps-dump", "a LAMMPS dump frame, FILE.dump (OVITO, LAMMPS rerun)",
           _text(_lammps_dump, ".dump")),
    Format("lammps-data", "a LAMMPS data file, FILE.data (read_data; reads back as run.initial_file)",
           _text(state_data, ".data")),
    Format("xyz", "extended XYZ, FILE.xyz (ASE, OVITO, VMD)", _text(_xyz, ".xyz")),
    Format("packing", "positions and contact forces, compressed: RUN/packing.npz beside a final.h5 (analyze)",
           _packing),
    Format("contacts", "the contact network, FILE.contacts.h5 and .xmf (ParaView)", _contacts),
    Format("lammps-local", "the contact network as a LAMMPS dump local, FILE.local (OVITO)", _lammps_local),
    Format("lammps-input", "a LAMMPS input script and data file that continue the run, directory FILE.lammps",
           _lammps_input),
)}


# -- the files beside every snapshot and final.h5 --
@dataclass(frozen=True)
class Sidecar:
    """A file a run writes beside each snapshot and its final.h5 (rank 0, once the state file is whole).

    Attributes
    ----------
    name : str
    about : str
    write : callable(path, run_dir, final)
        Writes it for state file ``path`` of the run in ``run_dir``; ``final``: ``path`` is final.h5.
    """
    name: str
    about: str
    write: Callable


def _state_xdmf(path, run_dir, final):
    write_xdmf(path)


def _contacts_beside(path, run_dir, final):
    from .network import contacts_path, write_contacts_xdmf
    write_contacts_xdmf(path, contacts_path(path)[:-len(".h5")])


def _series(path, run_dir, final):
    if not final:
        write_xdmf_series([p for _, p in rundir.snapshots(run_dir)],
                          os.path.join(run_dir, rundir.SNAP_DIR, "series.xmf"))


SIDECARS = (
    Sidecar("xdmf", "the state file's XDMF 3 sidecar, FILE.xmf (ParaView, VisIt)", _state_xdmf),
    Sidecar("contacts", "its contact network, contacts/FILE.contacts.h5 and .xmf (force chains in ParaView)",
            _contacts_beside),
    Sidecar("series", "the snapshots as one time series, snapshots/series.xmf (ParaView)", _series),
)


def export(path, fmt, out=None):
    """Export state file ``path`` in format ``fmt`` (a name in ``FORMATS``) to ``out`` (default beside it).

    Returns
    -------
    (str, list of str) : the path written and notes for the user.

    Raises
    ------
    ValueError for a format not in ``FORMATS``; StateFileError for a damaged file; WriteError
    when ``out`` cannot be written (nothing is left under its name).
    """
    if fmt not in FORMATS:
        raise ValueError(f"unknown export format {fmt!r}; accepted: {', '.join(FORMATS)}")
    return FORMATS[fmt].write(path, out)


def export_file(path, fmt, out=None):
    """Export the particles of a state file as text, rows in id order.

    ``lammps-dump``: a LAMMPS dump frame (``ITEM: TIMESTEP`` ...), box
    ``0 L_x``, ``0 L_y`` and z from the lowest sphere bottom to the highest
    top (boundaries pp pp ff), columns ``id type x y z vx vy vz omegax
    omegay omegaz fx fy fz radius`` with type 1 mobile, 2 bed, radius 0.5.
    ``xyz``: extended XYZ with ``Lattice`` (L_x, L_y, z extent), ``Origin``
    (0, 0, z_lo), ``pbc="T T F"``, ``Time``, ``Step`` and properties
    species (M mobile, B bed), pos, velo, omega, radius, id.
    ``lammps-data``: a LAMMPS data file (``read_data``) with atom_style
    sphere, types 1 mobile and 2 bed, and Velocities with the angular
    velocities (``lammps.data_lines``); it reads back as ``run.initial_file``
    with ``run.fixed_types = [2]`` to the same particles.
    The others (``packing``, ``contacts``, ``lammps-local``, ``lammps-input``): ``FORMATS``.

    Floats are written with 17 significant digits, so they read back exactly.

    Parameters
    ----------
    path : str
        An mpdem state file (checksums are verified).
    fmt : str
        A name in ``FORMATS``.
    out : str, optional
        Output path; default ``path`` with the format's suffix (``FORMATS``).

    Returns
    -------
    str : the output path (written atomically).
    """
    return export(path, fmt, out)[0]
