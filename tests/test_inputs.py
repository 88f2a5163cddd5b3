"""Initial files, initial-state checks and the run directory."""
import json

import numpy as np
import pytest

from mpdem import build, config
from mpdem.io import tables
from mpdem.io import checkpoint
from mpdem.driver.simulation import Run

from helpers import mpdem

SMALL = ["run.max_steps=300", "box.L_x=5.0", "box.L_y=5.0", "pour.N=60", "pour.phi_i=0.2",
         "bed.settle_time=2.0", "output.progress_every=100", "stop.sample_interval=0.005"]


def small_cfg(*extra):
    return config.load(None, SMALL + list(extra))


def test_table_round_trip(tmp_path):
    g = np.random.default_rng(1)
    ids = np.array([5, 2, 9])
    x = g.random((3, 3)) * 10
    v = g.normal(size=(3, 3))
    fixed = np.array([0, 1, 0], np.uint8)
    p = tmp_path / "t.txt"
    tables.write_table(p, ids, x, v, fixed)
    t = tables.read_table(p)
    assert np.array_equal(t["id"], ids) and np.array_equal(t["x"], x)
    assert np.array_equal(t["v"], v) and np.array_equal(t["fixed"], fixed)


def test_table_without_header_and_bad_tables(tmp_path):
    p = tmp_path / "t.txt"
    p.write_text("1 0.5 0.5 3.0\n2 2.5 0.5 3.0\n")
    t = tables.read_table(p)
    assert t["id"].tolist() == [1, 2] and np.all(t["v"] == 0) and np.all(t["fixed"] == 0)
    p.write_text("id x y z fixed\n1 0.5 0.5 3.0 2\n")
    with pytest.raises(build.InputError, match="fixed must be 0 or 1"):
        tables.read_table(p)
    p.write_text("id x y z\n1 0.5 0.5 3.0\n1 2.5 0.5 3.0\n")
    with pytest.raises(build.InputError, match="duplicate"):
        tables.read_table(p)
    p.write_text("a b c\n1 2 3\n")
    with pytest.raises(build.InputError, match="need id x y z"):
        tables.read_table(p)


def test_initial_overlap_is_named():
    ids = np.array([3, 8, 1])
    x = np.array([[1.0, 1.0, 3.0], [1.0, 1.0, 3.9], [4.0, 4.0, 0.0]])
    with pytest.raises(build.InputError, match=r"particles 3 and 8 overlap by 0\.1"):
        build.check_initial(ids, x, np.array([0, 0, 1], np.uint8), 5.0, 5.0, 0.0)
    x[1, 2] = 5.0
    x[0, 0] = 5.5
    with pytest.raises(build.InputError, match="particle 3 .* outside"):
        build.check_initial(ids, x, np.array([0, 0, 1], np.uint8), 5.0, 5.0, 0.0)


def test_insertion_is_deterministic_and_non_overlapping():
    a = build.insert_random(build.rng(4, 2), 500, 6.0, 6.0, 1.0, 40.0)
    b = build.insert_random(build.rng(4, 2), 500, 6.0, 6.0, 1.0, 40.0)
    assert np.array_equal(a, b)
    from mpdem.analysis import find_contacts
    assert len(find_contacts(a, 6.0, 6.0)[0]) == 0
    assert a[:, 2].min() >= 1.0 and a[:, 2].max() <= 40.0


def test_initial_velocities_have_exact_mean_energy():
    v = build.initial_velocities(build.rng(1, 3), 1000, 50.0)
    assert 0.5 * np.sum(v * v) / 1000 == pytest.approx(50.0, rel=1e-12)


def run_small(tmp_path, name, *extra):
    out = tmp_path / name
    r = Run.new(small_cfg(*extra), str(out), quiet=True)
    r.run()
    s = r.finish()
    return out, r, s


def test_run_from_text_table_continues_exactly(tmp_path):
    """A pile built by mpdem, written as a table, then run from the table
    with the same number of steps gives the same state bit for bit."""
    out, r, s = run_small(tmp_path, "a")
    # the initial state of run a, rebuilt, as a table
    cfg = small_cfg()
    r0 = Run.new(cfg, str(tmp_path / "a0"), quiet=True)
    st = r0.state
    n = st.n_own
    tables.write_table(tmp_path / "init.txt", st.id[:n], st.x[:n], st.v[:n], st.fixed[:n])
    out_b, rb, sb = run_small(tmp_path, "b", f'run.initial_file="{tmp_path / "init.txt"}"')
    assert sb["digest"] == s["digest"]
    # and from the final state file: the run continues from where it stopped
    arrays, attrs = checkpoint.read_state(out / "final.h5")
    assert attrs["step"] == 300 and len(arrays["id"]) == n


def test_run_directory_contents(tmp_path):
    out, r, s = run_small(tmp_path, "c")
    for name in ("config.toml", "log.txt", "thermo.csv", "final.h5", "summary.json", "bed.txt"):
        assert (out / name).exists(), name
    back = config.load(out / "config.toml")
    assert back.pour.N == 60 and back.contact.gamma_n == r.cfg.contact.gamma_n
    rows = (out / "thermo.csv").read_text().splitlines()
    assert rows[0].startswith("step,time,ek")
    assert len(rows) > 1
    summary = json.loads((out / "summary.json").read_text())
    assert summary["steps"] == 300 and summary["converged"] is False
    # the exit status that follows is explained in one line
    log = (out / "log.txt").read_text()
    assert "exit status 3: the run reached run.max_steps = 300 before the stop rule held; not an error" in log


def test_progress_before_the_first_energy_sample_shows_a_dash(tmp_path):
    out, r, s = run_small(tmp_path, "dash", "output.progress_every=10", "stop.sample_interval=0.01")
    lines = [ln for ln in (out / "log.txt").read_text().splitlines() if ln.startswith("step ")]
    assert "E_k/N         -  " in lines[0] and not any("inf" in ln for ln in lines)
    assert "E_k/N 0." in lines[-1] or "e-" in lines[-1].split("E_k/N")[1].split()[0]


def test_cli_reports_bad_values_before_work(tmp_path):
    p = mpdem("run", "--set", "contact.mu=-1", "--out", str(tmp_path / "x"))
    assert p.returncode == 1
    assert "contact.mu = -1" in p.stderr and "0 <= mu" in p.stderr
    assert not (tmp_path / "x").exists()
    p = mpdem("run", str(tmp_path / "missing.toml"))
    assert p.returncode == 1 and "missing.toml" in p.stderr


def test_cli_info_and_digest(tmp_path):
    out, r, s = run_small(tmp_path, "d")
    p = mpdem("info", str(out / "final.h5"), "--digest")
    assert p.returncode == 0 and p.stdout.strip() == s["digest"]
    p = mpdem("info", str(out / "final.h5"))
    assert "step 300" in p.stdout and "mobile" in p.stdout


def test_runtime_checks_stop_the_run(tmp_path):
    from mpdem.errors import RunError
    # a head-on collision far too fast for k_n: overlap above checks.overlap_error
    p = tmp_path / "fast.txt"
    tables.write_table(p, np.array([0, 1]), np.array([[2.0, 2.5, 10.0], [3.2, 2.5, 10.0]]),
                      np.array([[300.0, 0, 0], [-300.0, 0, 0]]))
    r = Run.new(small_cfg(f'run.initial_file="{p}"', "box.gravity=0.0"), str(tmp_path / "f"), quiet=True)
    with pytest.raises(RunError, match="overlap .* exceeds checks.overlap_error"):
        r.run()
    # it failed before its first stop-rule sample: no thermo table, not even a header
    assert not (tmp_path / "f" / "thermo.csv").exists()
    # a sphere dropping past the single bed sphere, beside it
    p = tmp_path / "fall.txt"
    tables.write_table(p, np.array([0, 1]), np.array([[1.0, 1.0, 3.0], [3.5, 3.5, 1.0]]),
                      fixed=np.array([0, 1], np.uint8))
    r = Run.new(small_cfg(f'run.initial_file="{p}"', "run.max_steps=20000"), str(tmp_path / "g"), quiet=True)
    with pytest.raises(RunError, match="fell through the bed"):
        r.run()


def test_version_and_nearest_key(tmp_path):
    from mpdem import __version__
    p = mpdem("--version")
    assert p.returncode == 0 and p.stdout.strip() == f"mpdem {__version__}"
    for given, near in (("contact.kn", "contact.k_n"), ("k_n", "contact.k_n"), ("pour.phi", "pour.phi_i"),
                        ("stop.Estop", "stop.E_stop")):
        p = mpdem("run", "--set", f"{given}=1", "--out", str(tmp_path / "x"))
        assert p.returncode == 1 and f"--set {given}: unknown key (did you mean {near}?)" in p.stderr, p.stderr
    toml = tmp_path / "c.toml"
    toml.write_text("[contakt]\nk_n = 1\n")
    p = mpdem("run", str(toml))
    assert p.returncode == 1 and "unknown section [contakt] (did you mean contact?)" in p.stderr
    toml.write_text("[contact]\nepsilom = 0.5\n")
    p = mpdem("run", str(toml))
    assert p.returncode == 1 and "unknown key contact.epsilom (did you mean contact.epsilon?)" in p.stderr
    # the right key in the wrong section is named; an unknown key lists its section's keys, not all
    toml.write_text("[run]\nmax_steps = 10\n[contact]\nmax_steps = 10\n")
    p = mpdem("run", str(toml))
    assert p.returncode == 1 and "unknown key contact.max_steps (did you mean run.max_steps?)" in p.stderr
    p = mpdem("run", "--set", "contact.muu=0.3", "--out", str(tmp_path / "x"))
    assert p.returncode == 1 and "keys of [contact]: model, k_n" in p.stderr and "max_steps" not in p.stderr
    # a space for '=': the item is named, not taken for the config file
    p = mpdem("run", "--set", "contact.mu", "-0.3", "--out", str(tmp_path / "x"))
    assert p.returncode == 1 and "--set 'contact.mu': expected section.key=value" in p.stderr, p.stderr
    assert "config file" not in p.stderr
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("ranks", [1, 2])
def test_an_out_directory_that_cannot_be_made_is_one_line(tmp_path, ranks):
    """A path under /proc, or under a regular file: one line naming it and why, before any work."""
    (tmp_path / "file").write_text("")
    for out in ("/proc/mpdem-cannot/run", str(tmp_path / "file" / "run")):
        p = mpdem("run", "--out", out, "--set", "pour.N=10", n=ranks, timeout=300)
        assert p.returncode != 0
        lines = [ln for ln in p.stderr.splitlines() if ln.startswith("mpdem: error: --out")]
        assert len(lines) == 1, p.stderr          # every rank stops; rank 0 says why, once
        assert f"--out {out}: cannot be created or written (" in lines[0]
        assert "Traceback" not in p.stderr and "bed:" not in p.stdout   # no work started
