"""LAMMPS files in (data files, text dumps) and out (data files), through the real CLI."""
import json
import os
import shutil

import numpy as np
import pytest

from mpdem import config
from mpdem.io import tables
from mpdem.io import checkpoint, export, lammps
from mpdem.build import InputError

from helpers import mpdem

DATA = os.path.join(os.path.dirname(__file__), "data")
LMP_DATA = os.path.join(DATA, "lammps_sphere.data")
LMP_DUMP = os.path.join(DATA, "lammps_sphere.dump.gz")


def test_files_are_recognised_by_their_content(tmp_path):
    shutil.copy(LMP_DATA, tmp_path / "state.txt")
    assert lammps.kind(str(tmp_path / "state.txt")) == "data"
    assert lammps.kind(LMP_DUMP) == "dump"
    tables.write_table(tmp_path / "t.txt", np.arange(1, 3), np.ones((2, 3)))
    assert lammps.kind(str(tmp_path / "t.txt")) is None


def test_the_data_file_and_the_dump_lammps_wrote_of_one_state_read_alike():
    a = lammps.read(LMP_DATA, (2,))
    b = lammps.read(LMP_DUMP, (2,))
    order = [np.argsort(t["id"]) for t in (a, b)]
    for key in ("id", "types", "x", "v", "omega", "fixed"):
        assert np.array_equal(a[key][order[0]], b[key][order[1]]), key
    assert len(a["id"]) == 369 and a["fixed"].sum() == 106 and set(a["types"][a["fixed"] == 1]) == {2}
    assert a["L_x"] == a["L_y"] == 10.0 and a["kind"] == "data" and b["kind"] == "dump"
    # the pile was moving: velocities and angular velocities are read, not zeros
    assert np.abs(a["v"][a["fixed"] == 0]).max() > 0 and np.abs(a["omega"][a["fixed"] == 0]).max() > 0
    assert (a["x"][:, :2] >= 0).all() and (a["x"][:, :2] < 10.0).all()


def edit_data(tmp_path, fn, name="edited.data"):
    """The LAMMPS data fixture with each Atoms row passed through fn(tokens) -> tokens."""
    out, section = [], None
    for line in open(LMP_DATA).read().splitlines():
        t = line.split()
        if t[:1] in (["Atoms"], ["Velocities"]):
            section = t[0]
        elif section == "Atoms" and len(t) == 10:
            line = " ".join(fn(t))
        out.append(line)
    path = tmp_path / name
    path.write_text("\n".join(out) + "\n")
    return str(path)


def test_sizes_masses_and_styles_outside_the_model_are_refused(tmp_path):
    def first(t, k, v):
        return t[:k] + [v] + t[k + 1:] if t[0] == "1509" else t

    with pytest.raises(InputError, match=r"atom 1509 has diameter 1\.1; mpdem's spheres all have diameter 1"):
        lammps.read(edit_data(tmp_path, lambda t: first(t, 2, "1.1")), (2,))
    with pytest.raises(InputError, match=r"atom 1509 has mass 0\.52.*mass 1"):
        lammps.read(edit_data(tmp_path, lambda t: first(t, 3, "1.0")), (2,))
    # a density written with 7 digits is LAMMPS's rounding of mass 1: accepted
    rounded = lammps.read(edit_data(tmp_path, lambda t: t[:3] + ["1.909859"] + t[4:]), (2,))
    assert len(rounded["id"]) == 369
    text = open(LMP_DATA).read()
    (tmp_path / "atomic.data").write_text(text.replace("Atoms # sphere", "Atoms # atomic"))
    with pytest.raises(InputError, match="atom_style atomic; mpdem reads atom_style sphere"):
        lammps.read(str(tmp_path / "atomic.data"), (2,))
    (tmp_path / "tri.data").write_text(text.replace("-1 20 zlo zhi", "-1 20 zlo zhi\n0.5 0 0 xy xz yz"))
    with pytest.raises(InputError, match="triclinic"):
        lammps.read(str(tmp_path / "tri.data"), (2,))
    (tmp_path / "count.data").write_text(text.replace("369 atoms", "370 atoms"))
    with pytest.raises(InputError, match="the header says 370 atoms, the Atoms section has 369"):
        lammps.read(str(tmp_path / "count.data"), (2,))
    with pytest.raises(InputError, match=r"run.fixed_types = \[3\]: .* has no atom of type 3; its types are \[1, 2\]"):
        lammps.read(LMP_DATA, (3,))


def test_a_shifted_box_and_image_flags_come_into_mpdem_s_frame(tmp_path):
    a = lammps.read(LMP_DATA, (2,))
    text = open(LMP_DATA).read().replace("0 10 xlo xhi", "-5 5 xlo xhi")
    # atom 1509 at x = 5.0596 in [0, 10) is at x = 0.0596 - 10 + 10 in [-5, 5), one box to the left
    lines = []
    for line in text.splitlines():
        t = line.split()
        if len(t) == 10 and t[0] == "1509":
            t[4] = repr(float(t[4]) - 5.0 - 10.0)
            t[7] = "1"
        elif len(t) == 10:
            x = float(t[4]) - 5.0
            t[4] = repr(x)
        lines.append(" ".join(t))
    (tmp_path / "shifted.data").write_text("\n".join(lines) + "\n")
    b = lammps.read(str(tmp_path / "shifted.data"), (2,))
    assert b["L_x"] == 10.0
    assert np.allclose(a["x"], b["x"], rtol=0, atol=1e-12)


def test_export_to_a_lammps_data_file_reads_back_to_the_same_particles(tmp_path):
    # a state file with ids from 0 (as mpdem numbers a pour), moving and spinning spheres
    rng = np.random.default_rng(3)
    n = 40
    ids = rng.permutation(n).astype(np.int64)
    local = dict(id=ids, x=rng.random((n, 3)) * [6.0, 7.5, 9.0], v=rng.normal(size=(n, 3)),
                 omega=rng.normal(size=(n, 3)), f=np.zeros((n, 3)), torque=np.zeros((n, 3)),
                 fixed=(ids < 8).astype(np.uint8), count=np.zeros(n, np.int64),
                 partner=np.zeros(0, np.int64), ds=np.zeros((0, 3)))
    attrs = dict(kind="snapshot", step=12, time=0.0012, n=n, n_mobile=n - 8, n_bed=8, L_x=6.0, L_y=7.5, config="")
    h5 = tmp_path / "state.h5"
    checkpoint.write(str(h5), local, attrs)
    out = export.export_file(str(h5), "lammps-data")
    assert out == str(tmp_path / "state.data") and lammps.kind(out) == "data"
    back = lammps.read(out, (2,))
    order = np.argsort(ids)
    assert np.array_equal(back["id"], ids[order])
    for key in ("x", "v", "omega", "fixed"):
        assert np.array_equal(back[key], local[key][order]), key
    assert (back["L_x"], back["L_y"]) == (6.0, 7.5)


@pytest.mark.parametrize("mu", [0.0, 0.5])
def test_a_run_from_the_lammps_data_file_has_the_digest_of_the_same_state_as_a_table(tmp_path, mu):
    t = lammps.read(LMP_DATA, (2,))
    tables.write_table(tmp_path / "same.txt", t["id"], t["x"], t["v"], t["fixed"], omega=t["omega"])
    common = ["--set", "run.max_steps=400", "--set", f"contact.mu={mu}", "--set", "output.progress_every=100"]
    p = mpdem("run", "--out", "from_data", "--set", f'run.initial_file="{LMP_DATA}"',
              "--set", "run.fixed_types=[2]", *common, cwd=tmp_path)
    assert p.returncode == 3, p.out
    assert "LAMMPS data file" in p.out and "263 mobile + 106 bed spheres, box 10 x 10" in p.out
    p = mpdem("run", "--out", "from_table", "--set", f'run.initial_file="{tmp_path / "same.txt"}"',
              "--set", "box.L_x=10.0", "--set", "box.L_y=10.0", *common, cwd=tmp_path)
    assert p.returncode == 3, p.out
    digests = [json.load(open(tmp_path / d / "summary.json"))["digest"] for d in ("from_data", "from_table")]
    assert digests[0] == digests[1]
    # the box the file gave is in the run's config, so a restart needs no file
    cfg = config.load(str(tmp_path / "from_data" / "config.toml"))
    assert (cfg.box.L_x, cfg.box.L_y, cfg.run.fixed_types) == (10.0, 10.0, (2,))


def test_lammps_inputs_that_do_not_fit_stop_before_any_work(tmp_path):
    tables.write_table(tmp_path / "t.txt", np.arange(1, 3), np.ones((2, 3)))
    cases = [
        (["--set", f'run.initial_file="{LMP_DUMP}"'],
         r"run.fixed_types is not set: .* is a LAMMPS file with atom types \[1, 2\]; name the bed's types"),
        (["--set", f'run.initial_file="{LMP_DATA}"', "--set", "run.fixed_types=[2]", "--set", "box.L_x=20.0"],
         r"box.L_x = 20.0, but the box of .* is 10.0 long in x; leave box.L_x unset"),
        (["--set", f'run.initial_file="{tmp_path / "t.txt"}"', "--set", "run.fixed_types=[2]"],
         r"run.fixed_types = \[2\] is for a LAMMPS initial file; run.initial_file .*t.txt is not one"),
        (["--set", "run.fixed_types=2"], r"run.fixed_types = 2: expected a list of integers >= 1"),
    ]
    for args, message in cases:
        p = mpdem("run", "--out", "r", "--force", "--set", "run.max_steps=10", *args, cwd=tmp_path)
        assert p.returncode == 1 and p.out.count("mpdem: error:") == 1, p.out
        assert __import__("re").search(message, p.out), p.out
        assert not (tmp_path / "r" / "log.txt").exists()
