"""Exports of state files: XDMF sidecars and series, LAMMPS dump, extended XYZ."""
import os
import shlex
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest

from mpdem.io import checkpoint, export

L_X, L_Y = 6.0, 7.5
# dtype -> (NumberType, Precision) as XDMF 3 readers understand them
XDMF_NUMBER = {np.dtype("f8"): ("Float", "8"), np.dtype("i8"): ("Int", "8"),
               np.dtype("i4"): ("Int", "4"), np.dtype("u1"): ("UChar", "1")}


def write_state(path, time=0.123456789, step=1234, n=50, seed=0):
    """A random snapshot (rows shuffled, contact slots, pairs); returns id-sorted arrays and attrs."""
    rng = np.random.default_rng(seed)
    ids = rng.permutation(n).astype(np.int64) + 100
    x = rng.random((n, 3)) * [L_X, L_Y, 10.0] + [0, 0, 1.0]
    count = rng.integers(0, 4, n)
    m, p = int(count.sum()), 7
    local = dict(id=ids, x=x, v=rng.normal(size=(n, 3)), omega=rng.normal(size=(n, 3)),
                 f=rng.normal(size=(n, 3)), torque=rng.normal(size=(n, 3)),
                 fixed=(ids < 112).astype(np.uint8), count=count,
                 partner=rng.choice(ids, m), ds=rng.normal(size=(m, 3)) * 1e-3)
    for name in checkpoint.PAIR_FIELDS:
        shape = (p, 3) if name in checkpoint.WIDE else (p,)
        local[name] = rng.integers(100, 100 + n, shape) if name in ("id_i", "id_j") else rng.normal(size=shape)
    attrs = dict(kind="snapshot", step=step, time=time, n=n, n_mobile=int((ids >= 112).sum()),
                 n_bed=int((ids < 112).sum()), L_x=L_X, L_y=L_Y, config="")
    checkpoint.write(str(path), local, attrs)
    order = np.argsort(ids)
    return {k: local[k][order] for k in checkpoint.PARTICLE_FIELDS}, attrs


def data_items(xmf):
    """(HDF5 file, dataset, DataItem) for every DataItem of an XDMF file that points into HDF5 (all but
    the inline radius)."""
    for item in ET.parse(xmf).getroot().iter("DataItem"):
        if item.get("Format") == "XML":
            continue
        assert item.get("Format") == "HDF"
        fname, dset = item.text.strip().split(":")
        yield fname, dset, item


def test_xdmf_sidecar_matches_the_datasets(tmp_path):
    h5 = tmp_path / "snap.h5"
    a, attrs = write_state(h5)
    xmf = export.write_xdmf(str(h5))
    assert xmf == str(tmp_path / "snap.xmf") and not os.path.exists(xmf + ".tmp")
    root = ET.parse(xmf).getroot()
    assert root.tag == "Xdmf" and root.get("Version") == "3.0"
    grid = root.find("Domain/Grid")
    assert float(grid.find("Time").get("Value")) == attrs["time"]
    topo = grid.find("Topology")
    assert topo.get("TopologyType") == "Polyvertex" and topo.get("NumberOfElements") == "50"
    geo = grid.find("Geometry")
    assert geo.get("GeometryType") == "XYZ" and geo.find("DataItem").text.strip() == "snap.h5:/particles/x"
    kinds = {att.get("Name"): (att.get("AttributeType"), att.find("DataItem").text.strip().split(":")[1])
             for att in grid.findall("Attribute") if att.find("DataItem").get("Format") == "HDF"}
    # the radius a viewer scales by: inline, one 0.5 per sphere
    radius = [att.find("DataItem") for att in grid.findall("Attribute") if att.get("Name") == "radius"]
    assert len(radius) == 1 and radius[0].get("Format") == "XML" and radius[0].get("Dimensions") == "50"
    assert np.array_equal(np.array(radius[0].text.split(), float), np.full(50, 0.5))
    for name, kind in (("id", "Scalar"), ("fixed", "Scalar"), ("v", "Vector"), ("omega", "Vector"), ("f", "Vector")):
        assert kinds[name] == (kind, f"/particles/{name}")
    seen = set()
    with h5py.File(h5, "r") as f:
        for fname, dset, item in data_items(xmf):
            assert fname == "snap.h5"          # base name: the pair of files can move together
            ds = f[dset]
            assert item.get("Dimensions").split() == [str(s) for s in ds.shape]
            assert ds.shape[0] == 50
            assert (item.get("NumberType"), item.get("Precision")) == XDMF_NUMBER[ds.dtype]
            seen.add(dset)
    assert {"/particles/x", "/particles/id", "/particles/fixed"} <= seen


def test_xdmf_series_is_in_time_order(tmp_path):
    times = {"a": 2.0, "b": 0.5, "c": 1.25}
    for k, (name, t) in enumerate(times.items()):
        write_state(tmp_path / f"{name}.h5", time=t, step=100 * k, n=10 + k, seed=k)
    inputs = [export.write_xdmf(str(tmp_path / "a.h5")), str(tmp_path / "b.h5"), str(tmp_path / "c.h5")]
    out = tmp_path / "view" / "all.xmf"
    out.parent.mkdir()
    assert export.write_xdmf_series(inputs, str(out)) == str(out)
    series = ET.parse(out).getroot().find("Domain/Grid")
    assert (series.get("GridType"), series.get("CollectionType")) == ("Collection", "Temporal")
    grids = series.findall("Grid")
    assert [float(g.find("Time").get("Value")) for g in grids] == [0.5, 1.25, 2.0]
    for g, name, n in zip(grids, "bca", (11, 12, 10)):
        assert g.find("Topology").get("NumberOfElements") == str(n)
        for item in g.iter("DataItem"):
            if item.get("Format") == "XML":      # the inline radius: one per sphere of this file
                assert item.get("Dimensions") == str(n) and len(item.text.split()) == n
                continue
            fname, dset = item.text.strip().split(":")
            target = os.path.normpath(out.parent / fname)
            assert target == str(tmp_path / f"{name}.h5")
            with h5py.File(target, "r") as f:
                assert item.get("Dimensions").split() == [str(s) for s in f[dset].shape]


def parse_dump(path):
    lines = open(path).read().splitlines()
    assert lines[0] == "ITEM: TIMESTEP" and lines[2] == "ITEM: NUMBER OF ATOMS"
    assert lines[4] == "ITEM: BOX BOUNDS pp pp ff" and lines[8].startswith("ITEM: ATOMS ")
    n = int(lines[3])
    box = np.array([[float(v) for v in line.split()] for line in lines[5:8]])
    names = lines[8].split()[2:]
    rows = [line.split() for line in lines[9:]]
    assert len(rows) == n and all(len(r) == len(names) for r in rows)
    return int(lines[1]), box, {c: [r[i] for r in rows] for i, c in enumerate(names)}


def floats(table, *names):
    return np.array([[float(v) for v in table[c]] for c in names]).T


def test_lammps_dump_round_trip(tmp_path):
    h5 = tmp_path / "snap.h5"
    a, attrs = write_state(h5)
    out = export.export_file(str(h5), "lammps-dump")
    assert out == str(tmp_path / "snap.dump")
    step, box, t = parse_dump(out)
    assert step == 1234
    z = a["x"][:, 2]
    assert np.array_equal(box, [[0, L_X], [0, L_Y], [z.min() - 0.5, z.max() + 0.5]])
    assert np.array_equal([int(v) for v in t["id"]], a["id"])
    assert np.array_equal([int(v) for v in t["type"]], np.where(a["fixed"] == 1, 2, 1))
    assert set(np.where(a["fixed"] == 1, 2, 1)) == {1, 2}
    for key, cols in (("x", "x y z"), ("v", "vx vy vz"), ("omega", "omegax omegay omegaz"), ("f", "fx fy fz")):
        assert np.array_equal(floats(t, *cols.split()), a[key]), key
    assert np.all(floats(t, "radius") == 0.5)
    other = export.export_file(str(h5), "lammps-dump", out=str(tmp_path / "other.txt"))
    assert open(other).read() == open(out).read()


def test_extended_xyz_round_trip(tmp_path):
    h5 = tmp_path / "snap.h5"
    a, attrs = write_state(h5)
    out = export.export_file(str(h5), "xyz")
    assert out == str(tmp_path / "snap.xyz")
    lines = open(out).read().splitlines()
    assert int(lines[0]) == 50 and len(lines) == 52
    info = dict(kv.split("=", 1) for kv in shlex.split(lines[1]))
    z = a["x"][:, 2]
    zlo, zhi = z.min() - 0.5, z.max() + 0.5
    assert np.array_equal([float(v) for v in info["Lattice"].split()], [L_X, 0, 0, 0, L_Y, 0, 0, 0, zhi - zlo])
    assert np.array_equal([float(v) for v in info["Origin"].split()], [0, 0, zlo])
    assert info["Properties"] == "species:S:1:pos:R:3:velo:R:3:omega:R:3:radius:R:1:id:I:1"
    assert info["pbc"] == "T T F" and float(info["Time"]) == attrs["time"] and int(info["Step"]) == 1234
    rows = [line.split() for line in lines[2:]]
    assert all(len(r) == 12 for r in rows)
    assert [r[0] for r in rows] == ["B" if f else "M" for f in a["fixed"]]
    num = np.array([[float(v) for v in r[1:11]] for r in rows])
    assert np.array_equal(num[:, 0:3], a["x"]) and np.array_equal(num[:, 3:6], a["v"])
    assert np.array_equal(num[:, 6:9], a["omega"]) and np.all(num[:, 9] == 0.5)
    assert np.array_equal([int(r[11]) for r in rows], a["id"])


def test_unknown_format_is_named(tmp_path):
    h5 = tmp_path / "snap.h5"
    write_state(h5)
    with pytest.raises(ValueError, match=r"'vtk'.*lammps-dump.*xyz"):
        export.export_file(str(h5), "vtk")
    assert sorted(os.listdir(tmp_path)) == ["snap.h5"]


def test_a_new_format_is_one_entry_in_the_table(tmp_path, monkeypatch, capsys):
    """A format added to ``export.FORMATS`` alone is a --format choice, in the help, and written by
    ``mpdem export`` (the command line reads the table)."""
    from mpdem.__main__ import cmd_export, parser
    from mpdem.parallel import Channel

    def write(path, out):
        out = out or path + ".ids"
        arrays, _ = checkpoint.read_state(path)
        export.write_atomic(out, [f"{i}\n" for i in arrays["id"]])
        return out, ["one id a line"]
    monkeypatch.setitem(export.FORMATS, "ids", export.Format("ids", "the particle ids, one a line", write))
    h5 = tmp_path / "snap.h5"
    write_state(h5)
    args = parser().parse_args(["export", str(h5), "--format", "ids"])
    assert cmd_export(args, Channel(None)) == 0
    assert capsys.readouterr().out == f"wrote {h5}.ids\none id a line\n"
    assert (tmp_path / "snap.h5.ids").read_text().split() == [str(i) for i in checkpoint.read_state(str(h5))[0]["id"]]
    with pytest.raises(SystemExit):
        parser().parse_args(["export", str(h5), "--format", "nope"])
    assert "ids: the particle ids, one a line" in " ".join(parser()._subparsers._group_actions[0].choices["export"]
                                                            .format_help().split())


def test_contact_network_for_paraview_and_ovito_reads_back(tmp_path):
    """export --format contacts (XDMF Polyline grid) and lammps-local (dump local): one line (or two
    half-lines) per contact with the file's forces; contacts across a periodic face are split."""
    from mpdem.io import network
    from mpdem.io.export import export_file
    from helpers import SQUEEZE, fcc, write_crystal
    a = 2.0 ** 0.5 * SQUEEZE
    x, L = fcc(4, 4, a)
    fixed = (x[:, 2] < a).astype(np.uint8)
    write_crystal(tmp_path / "f.h5", x, fixed, L)
    arr, attrs = checkpoint.read_state(str(tmp_path / "f.h5"), pairs=True)
    P = len(arr["id_i"])
    xmf = export_file(str(tmp_path / "f.h5"), "contacts")
    assert xmf == str(tmp_path / "f.contacts.xmf")
    # the command line names both files it wrote
    from mpdem.io.export import export
    assert export(str(tmp_path / "f.h5"), "contacts")[1] == [f"wrote {tmp_path / 'f.contacts.h5'} (the data the "
                                                              f".xmf points to)"]
    root = ET.parse(xmf).getroot()
    grid = root.find("Domain/Grid")
    topo = grid.find("Topology")
    assert topo.get("TopologyType") == "Polyline" and topo.get("NumberOfElements") == str(2 * P)
    with h5py.File(tmp_path / "f.contacts.h5") as f:
        pts, conn = f["points"][:], f["connectivity"][:]
        assert conn.shape == (2 * P, 2) and pts.shape == (4 * P, 3) and conn.max() == 4 * P - 1
        assert np.array_equal(f["cells/F_n"][::2], arr["F_n"]) and np.array_equal(f["cells/F_n"][1::2], arr["F_n"])
        # every half-line runs from a sphere centre to a point half a contact away (no line crosses the box)
        seg = pts[conn[:, 1]] - pts[conn[:, 0]]
        assert np.allclose(np.linalg.norm(seg, axis=1), 0.5 * SQUEEZE, rtol=1e-6)
        # the crystal is periodic in x and y: some contacts cross a face, and the file says how many
        n_cross = int(f.attrs["n_crossing"])
        names = {a_.get("Name") for a_ in grid.findall("Attribute")}
        assert {"F_n", "F_t", "zeta", "delta", "id_i", "id_j"} <= names
        assert np.allclose(f["cells/zeta"][:], 0.5)          # write_crystal puts F_t at half the limit
    assert n_cross > 0 and f"{n_cross} cross a periodic face" in root.find("Domain/Information").get("Value")
    local = export_file(str(tmp_path / "f.h5"), "lammps-local")
    lines = open(local).read().splitlines()
    assert lines[0] == "ITEM: TIMESTEP" and lines[3] == str(P)
    assert lines[8] == "ITEM: ENTRIES index patom1 patom2 dist fn ft zeta delta fx fy fz"
    rows = np.loadtxt(lines[9:], ndmin=2)
    assert rows.shape == (P, 11) and np.array_equal(rows[:, 1], arr["id_i"]) and np.array_equal(rows[:, 4], arr["F_n"])
    assert np.allclose(rows[:, 3], SQUEEZE) and np.allclose(rows[:, 7], 1 - SQUEEZE, atol=1e-12)
    t, _ = network.contact_table(str(tmp_path / "f.h5"))
    # the total force on patom1: F_n along the unit vector from patom2 to patom1, plus F_t
    want = arr["F_n"][:, None] * t["branch"] / np.linalg.norm(t["branch"], axis=1)[:, None] + arr["F_t"]
    assert np.allclose(rows[:, 8:11], want, rtol=1e-12, atol=1e-15)
    assert np.all(np.abs(t["branch"]) < 1.0)                     # the minimum image, not the raw difference
