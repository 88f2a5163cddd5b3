"""A run's initial file sets its box and sphere count (``initial.config_for``), and so does the table
bench's state file (``bench.table_box``): a pile is never stepped in another box than its own."""
import numpy as np
import pytest

from mpdem import bench, config, initial
from mpdem.errors import ConfigError, InputError
from mpdem.io import checkpoint, packing, tables

from helpers import SQUEEZE, simple_cubic, write_crystal


@pytest.fixture
def crystal(tmp_path):
    """A 4 d x 4 d simple cubic pile (its lowest layer bed) as a state file and as a packing file."""
    x, L = simple_cubic(4, 5, SQUEEZE)
    fixed = (x[:, 2] < 1).astype(np.uint8)
    h5 = tmp_path / "final.h5"
    write_crystal(h5, x, fixed, L)
    npz = tmp_path / "packing.npz"
    packing.write(str(npz), *checkpoint.read_state(str(h5), pairs=True))
    return {"h5": str(h5), "npz": str(npz), "L": L, "n_mobile": int((fixed == 0).sum()), "x": x, "fixed": fixed}


@pytest.mark.parametrize("kind", ["h5", "npz"])
def test_a_state_or_packing_file_gives_the_run_its_box_and_count(crystal, kind):
    # the built-in example's 10 x 10 box and 1500 spheres are defaults, not given: the file's replace them
    cfg = config.load_run_config(None, [f"run.initial_file={crystal[kind]}", "contact.mu=0"])
    assert (cfg.box.L_x, cfg.box.L_y, cfg.pour.N) == (10.0, 10.0, 1500)
    got, table = initial.config_for(cfg)
    assert table is None
    assert (got.box.L_x, got.box.L_y) == (crystal["L"], crystal["L"])
    assert got.pour.N == crystal["n_mobile"]
    # what the run records is the file's pile
    assert f"L_x = {crystal['L']!r}" in got.to_toml()


@pytest.mark.parametrize("key,value", [("box.L_x", 12.0), ("box.L_y", 3.0), ("pour.N", 7)])
def test_a_given_box_or_count_that_disagrees_with_the_file_is_refused(crystal, key, value):
    cfg = config.load_run_config(None, [f"run.initial_file={crystal['h5']}", f"{key}={value}"])
    with pytest.raises(ConfigError) as e:
        initial.config_for(cfg)
    msg = str(e.value)
    assert key in msg and repr(value) in msg.split(",")[0] and crystal["h5"] in msg
    assert "leave" in msg and "unset" in msg


def test_given_values_that_agree_are_kept_and_a_text_table_keeps_the_configs_box(crystal, tmp_path):
    L = crystal["L"]
    cfg = config.load_run_config(None, [f"run.initial_file={crystal['h5']}", f"box.L_x={L}", f"box.L_y={L}",
                                        f"pour.N={crystal['n_mobile']}"])
    assert initial.config_for(cfg)[0].values == cfg.values
    table = tmp_path / "pile.txt"
    tables.write_table(str(table), np.arange(1, len(crystal["x"]) + 1), crystal["x"], fixed=crystal["fixed"])
    cfg = config.load_run_config(None, [f"run.initial_file={table}"])
    got, _ = initial.config_for(cfg)
    # a table keeps no box, but its count is the run's
    assert (got.box.L_x, got.box.L_y, got.pour.N) == (10.0, 10.0, crystal["n_mobile"])


def test_every_rank_gets_rank_0s_reading_and_odd_files_are_named(crystal, tmp_path):
    from mpdem.parallel import channel
    cfg = config.load_run_config(None, [f"run.initial_file={crystal['h5']}"])
    assert initial.config_for(cfg, channel(None))[0].values == initial.config_for(cfg)[0].values
    # a pile without a mobile sphere: said of the file, not as pour.N = 0
    x, L = simple_cubic(4, 2, SQUEEZE)
    write_crystal(tmp_path / "bed.h5", x, np.ones(len(x), np.uint8), L, sets=["pour.N=1"])
    with pytest.raises(InputError, match=r"bed\.h5: no mobile sphere: every sphere is a bed sphere"):
        initial.config_for(config.load_run_config(None, [f"run.initial_file={tmp_path / 'bed.h5'}"]))
    # a box the config refuses (below 3 d) names the file it came from
    x, L = simple_cubic(2, 3, SQUEEZE)
    write_crystal(tmp_path / "narrow.h5", x, (x[:, 2] < 1).astype(np.uint8), L, sets=["box.L_x=3", "box.L_y=3"])
    with pytest.raises(ConfigError, match=r"box\.L_x = 1\.99.*\(from run\.initial_file .*narrow\.h5\)"):
        initial.config_for(config.load_run_config(None, [f"run.initial_file={tmp_path / 'narrow.h5'}"]))


def test_stiffening_a_run_started_from_a_file_takes_the_piles_box_and_count(crystal, tmp_path):
    """A run started from a file may have recorded the config's box and count (a text table keeps no box,
    and runs before the file's were taken): its rung is the pile's."""
    from mpdem import stiffen
    run = tmp_path / "run"
    run.mkdir()
    (run / "final.h5").write_bytes(open(crystal["h5"], "rb").read())
    cfg = config.load_run_config(None, ["contact.mu=0", "run.max_steps=10"])    # 10 x 10, 1500 spheres
    (run / "config.toml").write_text(cfg.to_toml())
    rung = stiffen.rung_config(str(run), 2e6, [])
    assert (rung.box.L_x, rung.pour.N) == (crystal["L"], crystal["n_mobile"])
    assert initial.config_for(rung)[0].values == rung.values


def test_stiffening_a_run_started_from_a_lammps_file_starts_from_its_final_state(tmp_path):
    """A run from a LAMMPS file names its bed's types (run.fixed_types); its rung starts from the run's
    final.h5, whose own flags say which spheres are bed, so the types are not the rung's."""
    from pathlib import Path
    from mpdem import stiffen
    from mpdem.io import lammps
    dump = str(Path(__file__).parent / "data" / "lammps_sphere.dump.gz")
    cfg, table = initial.config_for(config.load_run_config(None, [f"run.initial_file={dump}", "run.fixed_types=[2]",
                                                                  "bed.wall=true", "contact.mu=0"]))
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.toml").write_text(cfg.to_toml())
    t = lammps.read(dump, (2,))
    write_crystal(run / "final.h5", t["x"], t["fixed"], t["L_x"], sets=["bed.wall=true"])
    rung = stiffen.rung_config(str(run), 2e6, [])
    assert rung.run.fixed_types == () and rung.run.initial_file == str(run / "final.h5")
    got, _ = initial.config_for(rung)
    assert (got.box.L_x, got.pour.N) == (10.0, int((t["fixed"] == 0).sum()))


def test_the_table_bench_times_a_state_file_in_its_own_box(crystal, tmp_path):
    cfg = bench.table_config()
    assert cfg.box.L_x == 20.0
    got = bench.table_box(cfg, crystal["h5"])
    assert (got.box.L_x, got.box.L_y) == (crystal["L"], crystal["L"])
    whole, L_x, L_y = bench.load_table(crystal["h5"], got)
    assert (L_x, L_y) == (crystal["L"], crystal["L"]) and len(whole["id"]) == len(crystal["x"])
    # a --set box that disagrees with the file: one error naming both
    sets = ["box.L_x=10"]
    with pytest.raises(InputError, match=r"box\.L_x=10\.0.*--table .*final\.h5 is 3\.99+6 long in x"):
        bench.table_box(bench.table_config(sets), crystal["h5"], sets)
    # a text table keeps no box: the bench's stays
    table = tmp_path / "pile.txt"
    tables.write_table(str(table), np.arange(1, len(crystal["x"]) + 1), crystal["x"], fixed=crystal["fixed"])
    assert bench.table_box(cfg, str(table)).box.L_x == 20.0


@pytest.mark.parametrize("name", ["lammps_sphere.data", "lammps_sphere.dump.gz"])
def test_the_table_bench_times_a_lammps_file_in_its_own_box(name):
    """A LAMMPS data file or dump (10 d x 10 d, its bed type 2, a wall under it) is timed in its header's
    box, its bed the spheres of run.fixed_types, as a run from it would step it."""
    from pathlib import Path
    path = str(Path(__file__).parent / "data" / name)
    sets = ["run.fixed_types=[2]", "bed.wall=true"]
    got = bench.table_box(bench.table_config(sets), path, sets)
    assert (got.box.L_x, got.box.L_y) == (10.0, 10.0)
    whole, L_x, L_y = bench.load_table(path, got)
    assert (L_x, L_y) == (10.0, 10.0) and len(whole["id"]) == 369 and 0 < whole["fixed"].sum() < 369
    run_cfg, _ = initial.config_for(config.load_run_config(None, [f"run.initial_file={path}", *sets]))
    assert (run_cfg.box.L_x, run_cfg.box.L_y) == (got.box.L_x, got.box.L_y)
    sets = ["box.L_x=20", "run.fixed_types=[2]"]
    with pytest.raises(InputError, match=r"box\.L_x=20\.0.*--table .* is 10\.0 long in x"):
        bench.table_box(bench.table_config(sets), path, sets)
    # without the bed's types every sphere would be mobile: refused, as a run refuses it
    with pytest.raises(InputError, match=r"run\.fixed_types is not set: --table .* is a LAMMPS file with atom types "
                                         r"\[1, 2\]; .* --set run\.fixed_types=\[2\]"):
        bench.table_box(bench.table_config(), path)


def test_an_initial_file_that_is_a_directory_or_nothing_is_refused_before_the_run_directory(tmp_path):
    from helpers import mpdem
    for path, said in ((tmp_path, "a directory, not a file (a finished run's state is"),
                       (tmp_path / "nope.h5", "no such file")):
        with pytest.raises(InputError, match=r"run\.initial_file .*: " + said.replace("(", r"\(")):
            initial.config_for(config.load_run_config(None, [f"run.initial_file={path}"]))
    p = mpdem("run", "--set", f"run.initial_file={tmp_path / 'nope.h5'}", "--set", "run.max_steps=10",
              "--out", str(tmp_path / "out"), check=1)
    assert "run.initial_file" in p.stderr and "no such file" in p.stderr and not (tmp_path / "out").exists()
    with pytest.raises(InputError, match=r"--table .*nope\.h5: no such file"):
        bench.table_box(bench.table_config(), str(tmp_path / "nope.h5"))
