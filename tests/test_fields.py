"""The field registry (``state.FIELDS``) drives the State, the migration and the
state files; files written before it (format v2, by main's code) still load
with the same digest."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np

from mpdem.io import checkpoint
from mpdem import decomp, state
from mpdem.state import CONTACT, FIELD, MOVE_FIELDS, PARTICLE, ROW, SLOT, State

DATA = Path(__file__).resolve().parent / "data"
# written by tests/data/make_state_v2.py with main's checkpoint.write; its digest then (mpdem info --digest)
OLD_FILE = DATA / "state_v2.h5"
OLD_DIGEST = "a11aa6059cc7e9d95c2aca3f3090d2664665d9c2b7bc62566bd8cb45f5471f14"
# the datasets of format mpdem-state v2, in their digest and checksum order
V2_GROUPS = {"particles": ("id", "x", "v", "omega", "f", "torque", "fixed"), "contacts": ("count", "partner", "ds"),
             "wall": ("wall_ds",), "pairs": ("id_i", "id_j", "delta", "F_n", "F_t", "ds_i")}


def filled_state(n=7, seed=1):
    """A State whose every registered field holds distinct values (slots: 0 to 3 per row)."""
    rng = np.random.default_rng(seed)
    st = State(np.arange(50, 50 + n), rng.random((n, 3)), L_x=5.0, L_y=5.0)
    for f in ROW:
        if f.name not in ("id", "count"):
            vals = rng.integers(0, 2, (n,) + f.shape) if f.dtype == np.uint8 else rng.normal(size=(n,) + f.shape)
            getattr(st, f.name)[:n] = vals
    counts = rng.integers(0, 4, n)
    m = int(counts.sum())
    st.set_contacts(counts, **{f.name: (rng.integers(0, 99, (m,) + f.shape) if f.dtype == np.int64
                                        else rng.normal(size=(m,) + f.shape)) for f in SLOT})
    st.wall = True
    return st


def rows_of(st, fields=ROW + SLOT):
    """{field: rows of the owned particles in id order} (the slots per row as lists)."""
    order = st.id_order()
    out = {f.name: getattr(st, f.name)[:st.n_own][order].tolist() for f in fields if f.per == PARTICLE}
    o = st.slot_offsets()
    for f in fields:
        if f.per == CONTACT:
            a = getattr(st, f.name)
            out[f.name] = [a[o[i]:o[i + 1]].tolist() for i in order]
    return out


def test_every_registered_field_is_a_state_array_of_its_shape():
    st = State(np.arange(3), np.zeros((3, 3)), capacity=10)
    for f in ROW:
        a = getattr(st, f.name)
        assert a.shape == (10,) + f.shape and a.dtype == f.dtype, f.name
    for f in SLOT:
        assert getattr(st, f.name).shape == (0,) + f.shape, f.name
    assert st.id[3:].tolist() == [-1] * 7
    assert set(MOVE_FIELDS) == {f.name for f in ROW + SLOT if f.migrates}
    assert st.nbytes() == sum(getattr(st, f.name).nbytes for f in ROW + SLOT)


def by_id(st, fields=ROW + SLOT):
    """{field: {id: its rows}} of the owned particles."""
    r = rows_of(st, fields)
    return {k: dict(zip(r["id"], v)) for k, v in r.items()}


def test_grow_permute_take_keep_append_keep_every_field():
    st = filled_state()
    n, before = st.n_own, rows_of(filled_state())
    st.grow(64)
    assert st.capacity == 64 and rows_of(st) == before
    for f in ROW:
        assert np.all(getattr(st, f.name)[n:] == f.fill), f.name
    st.permute(np.array([3, 1, 6, 0, 2, 5, 4]))
    assert rows_of(st) == before and st.id[:3].tolist() == [53, 51, 56]
    # take and append: what migrates arrives whole
    moving = [f for f in ROW + SLOT if f.migrates]
    assert set(st.take(np.array([0]))) == set(MOVE_FIELDS)
    whole = by_id(st, moving)
    other = State(np.zeros(0, np.int64), np.zeros((0, 3)), L_x=5.0, L_y=5.0)
    assert other.append([st.take(np.array([5])), st.take(np.array([0, 2]))]) == 3
    assert by_id(other, moving) == {k: {i: v[i] for i in (55, 53, 56)} for k, v in whole.items()}
    # keep: the others
    st.keep(np.array([1, 3, 4, 6]))
    assert st.n_own == st.n_rows == 4 and st.id[:4].tolist() == [51, 50, 52, 54]
    assert by_id(st, moving) == {k: {i: v[i] for i in (51, 50, 52, 54)} for k, v in whole.items()}


def test_state_arrays_round_trip_through_a_state_and_a_file(tmp_path):
    st = filled_state()
    a = checkpoint.gather_state(st)
    assert set(a) == {f.name for f in state.stored() if f.per != state.PAIR}
    back = State.from_arrays(a, 5.0, 5.0)
    back.wall = True
    assert rows_of(back, [f for f in ROW + SLOT if f.group]) == rows_of(st, [f for f in ROW + SLOT if f.group])
    checkpoint.write(str(tmp_path / "s.h5"), a, {"kind": "checkpoint", "step": 0, "time": 0.0, "L_x": 5.0,
                                                 "L_y": 5.0})
    b, _ = checkpoint.read_state(str(tmp_path / "s.h5"))
    assert checkpoint.digest(b) == checkpoint.digest(a)
    # without the wall, wall_ds is neither gathered nor stored
    st.wall = False
    assert "wall_ds" not in checkpoint.gather_state(st)


def test_the_migration_packs_every_migrating_field():
    st = filled_state()
    part = st.take(np.array([4, 0, 6]))
    floats, ints = decomp._pack(part)
    m, slots = len(part["id"]), int(part["count"].sum())
    got = decomp._unpack(floats, ints, m, slots)
    assert set(got) == set(MOVE_FIELDS)
    for k in MOVE_FIELDS:
        assert got[k].dtype == part[k].dtype and got[k].tobytes() == part[k].tobytes(), k
    wf, wi, cf, ci = decomp._widths()
    assert len(floats) == m * wf + slots * cf and len(ints) == m * wi + slots * ci


def test_the_file_layout_is_format_v2():
    assert checkpoint.VERSION == 2
    assert checkpoint.GROUPS == V2_GROUPS
    assert checkpoint.ROWS_OF == {"particles": "id", "contacts": "partner", "wall": "wall_ds", "pairs": "id_i"}
    assert {k: np.dtype(v).str for k, v in checkpoint.DTYPES.items() if np.dtype(v) != np.float64} == {
        "id": "<i8", "fixed": "|u1", "count": "<i4", "partner": "<i8", "id_i": "<i8", "id_j": "<i8"}
    assert checkpoint.WIDE == {"x", "v", "omega", "f", "torque", "ds", "wall_ds", "F_t", "ds_i"}


def test_a_v2_file_written_by_main_loads_with_its_digest(tmp_path):
    a, attrs = checkpoint.read_state(str(OLD_FILE), pairs=True)
    assert attrs["version"] == 2 and checkpoint.digest(a) == OLD_DIGEST
    assert set(a) == {n for names in V2_GROUPS.values() for n in names}
    # through a State (one rank) and back: the same digest
    st = decomp.Domain(None).distribute(dict(a), float(attrs["L_x"]), float(attrs["L_y"]))
    st.wall = True
    assert checkpoint.digest(checkpoint.gather_state(st)) == OLD_DIGEST
    # its rows in file order written again by this code: the same datasets, bytes and checksums
    new = tmp_path / "again.h5"
    local, _ = checkpoint.read(str(OLD_FILE), pairs=True)
    checkpoint.write(str(new), local, {k: v for k, v in attrs.items() if not k.startswith("checksum_")})
    with h5py.File(OLD_FILE) as f, h5py.File(new) as g:
        for grp, names in V2_GROUPS.items():
            assert sorted(g[grp]) == sorted(names)
            for name in names:
                old, now = f[grp][name], g[grp][name]
                assert old.dtype == now.dtype and old.shape == now.shape and old[()].tobytes() == now[()].tobytes()
            assert f.attrs[f"checksum_{grp}"] == g.attrs[f"checksum_{grp}"]


def test_a_state_has_one_name_per_field():
    """The State's arrays are the registry's names only (the old aliases ``ids``, ``slot_n``, ... are gone)."""
    st = filled_state()
    arrays = {k for k, v in vars(st).items() if isinstance(v, np.ndarray)}
    assert arrays == {f.name for f in state.FIELDS if f.per != state.PAIR}, arrays
    for old in ("ids", "slot_n", "slot_id", "slot_ds"):
        assert not hasattr(st, old)


NEW_FIELD = '''    Field("roll", np.float64, 3, per=CONTACT, group="contacts", migrates=True, history=True,
          doc="(M, 3) a rolling-resistance history (test)"),
'''


def test_a_new_contact_history_field_is_one_registry_entry(tmp_path):
    """With one more per-contact Field, slots carry it through take/append, the
    migration's packing, a state file and its checksums, with no other change."""
    src = Path(state.__file__).resolve().parent
    copy = tmp_path / "src" / "mpdem"
    shutil.copytree(src, copy, ignore=shutil.ignore_patterns("__pycache__"))
    text = (copy / "state.py").read_text()
    anchor = '    Field("wall_ds"'
    assert anchor in text
    (copy / "state.py").write_text(text.replace(anchor, NEW_FIELD + anchor, 1))
    script = """
import numpy as np
from mpdem.io import checkpoint
from mpdem import decomp, state
from mpdem.state import State
assert state.FIELD["roll"] in state.SLOT and "roll" in checkpoint.GROUPS["contacts"]
st = State(np.arange(4), np.random.default_rng(0).random((4, 3)), L_x=5.0, L_y=5.0)
st.set_contacts([1, 0, 2, 1], [1, 0, 3, 2], np.ones((4, 3)), roll=np.arange(12.0).reshape(4, 3))
part = st.take(np.array([2, 0]))
got = decomp._unpack(*decomp._pack(part), 2, 3)
assert got["roll"].tolist() == [[3, 4, 5], [6, 7, 8], [0, 1, 2]], got["roll"]
other = State(np.zeros(0, np.int64), np.zeros((0, 3)))
other.append([got])
assert other.roll.tolist() == got["roll"].tolist()
checkpoint.write("f.h5", checkpoint.gather_state(st), {"kind": "checkpoint", "step": 0, "time": 0.0})
a, _ = checkpoint.read_state("f.h5")
assert a["roll"].tolist() == [[0, 1, 2], [3, 4, 5], [6, 7, 8], [9, 10, 11]]
print("ok")
"""
    env = dict(os.environ, PYTHONPATH=str(copy.parent))
    p = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert p.returncode == 0 and p.stdout.strip() == "ok", p.stderr


def test_field_names_are_the_registry_s():
    assert tuple(FIELD) == tuple(f.name for f in state.FIELDS) and len(FIELD) == len(state.FIELDS)
    assert state.INITIAL == ("id", "x", "v", "omega", "fixed")
    assert [f.name for f in state.FIELDS if f.history] == ["count", "partner", "ds", "wall_ds"]
