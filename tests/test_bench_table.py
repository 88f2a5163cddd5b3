"""bench --table: LAMMPS's settings, the phase report, the CLI's output, tiling and errors."""
import argparse
import re

import numpy as np
import pytest

from mpdem import bench

from helpers import mpdem, settled_table

BOX = ["--set", "box.L_x=6.0", "--set", "box.L_y=6.0"]


def test_table_config_has_lammps_settings():
    cfg = bench.table_config()
    assert cfg.contact.gamma_t == 25.713732817929117 == cfg.contact.gamma_n / 2
    assert (cfg.contact.mu, cfg.contact.k_n, cfg.integration.dt, cfg.integration.skin) == (0.5, 2e5, 1e-4, 0.2)
    assert bench.table_config(["contact.gamma_t=0"]).contact.gamma_t == 0.0
    assert bench.table_config(["box.L_x=6"]).box.L_x == 6.0


def test_phase_lines_add_up_to_the_loop():
    before = {"forces": 1.0, "lists": 0.5, "integration": 0.2, "communication": 0.0}
    after = {"forces": 7.0, "lists": 1.5, "integration": 1.2, "communication": 0.5}
    lines = bench.phase_lines(before, after, 10.0)
    share = {ln.split()[2]: float(ln.split()[-1].rstrip("%")) for ln in lines}
    assert share == {"forces": 60.0, "lists": 10.0, "integration": 10.0, "communication": 5.0, "glue": 15.0}


def test_steps_run_in_one_go_share_their_runs_time_evenly(monkeypatch):
    """An engine that runs steps in one go is timed in runs of ``bench.QUIET`` steps, each run's time
    shared evenly among its steps: every step of the steady loop (no list work) gets a run's share."""
    import time

    from mpdem.decomp import Domain

    class Engine:
        steps_in_one_call, n_rebuilds = True, 0
        timers = {"forces": 0.0, "lists": 0.0, "integration": 0.0}

        def run_quiet(self, n):
            time.sleep(2e-5 * n)

        def complete(self):
            pass

    got = {}
    monkeypatch.setattr(bench, "steadiness", lambda steps, lists, wall, switches: got.update(steps=steps) or {})
    bench.timed_loop(Engine(), Domain(None), 3 * bench.QUIET)
    steps = got["steps"]
    assert len(steps) == 3 * bench.QUIET and (steps > 0).all()
    for run in steps.reshape(3, bench.QUIET):
        assert np.allclose(run, run[0], rtol=1e-6) and 2e-5 <= run[0] < 2e-3


def test_steadiness_leaves_list_steps_out_and_counts_the_slow_ones_beyond_the_median():
    steps = np.array([1.0, 1.0, 1.05, 1.0, 3.0, 1.0, 9.0, 1.0, 1.0, 1.0])
    lists = np.zeros(10, bool)
    lists[6] = True
    st = bench.steadiness(steps, lists, 20.0, 40)
    # the 9 s step rebuilt: left out; of the others only the 3 s one is over 1.1 x the median (1 s)
    assert st["median"] == 1.0 and st["slow"] == 2.0 / 20.0 and st["switches"] == 2.0
    assert st["p90"] == np.percentile(np.delete(steps, 6), 90)
    line = bench.steadiness_line([st, dict(st, switches=3.0)])
    assert "median 1000.000 / 1000.000 ms" in line and "took 10.0 / 10.0 %" in line
    assert "switches 2 / 3 a second" in line


def test_cli_bench_table_output_and_tiling(tmp_path):
    n_mob, n_bed = settled_table(tmp_path / "t.txt")
    atoms = []
    for extra in ([], ["--tile", "2x1"]):
        p = mpdem("bench", "--table", str(tmp_path / "t.txt"), "--steps", "20", *BOX, *extra)
        assert p.returncode == 0, p.stderr
        out = p.stdout.strip().splitlines()
        assert re.fullmatch(r"ns_per_atom_step=[0-9.eE+-]+", out[-1]) and float(out[-1].split("=")[1]) > 0
        assert any(ln.startswith("bench: phase forces") for ln in out)
        assert any(ln.startswith("bench: phase communication") for ln in out)
        assert any("overlapping pairs accepted" in ln for ln in out)
        assert any(ln.startswith("bench: memory") and "bytes per atom" in ln for ln in out)
        atoms.append(int(re.search(r"(\d+) atoms = (\d+) mobile \+ (\d+) bed", p.stdout)[1]))
    assert atoms == [n_mob + n_bed, 2 * (n_mob + n_bed)]


@pytest.mark.parametrize("cmd", [["bench", "--table", "t.txt"], ["run"], ["restart", "somewhere"]])
@pytest.mark.parametrize("bad", ["0", "two"])
def test_cli_bad_threads_is_a_usage_error(cmd, bad):
    p = mpdem(*cmd, "--threads", bad)
    assert p.returncode == 2 and "--threads" in p.stderr and "integer >= 1" in p.stderr


def test_cli_bench_needs_a_mode():
    p = mpdem("bench")
    assert p.returncode == 2 and "--table FILE" in p.stderr
    p = mpdem("bench", "--table", "t.txt", "--analysis")
    assert p.returncode == 2 and "one of --table, --analysis" in p.stderr
    p = mpdem("bench", "--table", "t.txt", "--tile", "2")
    assert p.returncode == 2 and "--tile '2'" in p.stderr


def test_bench_reports_every_phase_of_the_loop(tmp_path, capsys):
    """The engine's timers give forces, lists and integration; communication and glue complete the loop."""
    settled_table(tmp_path / "t.txt")
    args = argparse.Namespace(table=str(tmp_path / "t.txt"), steps=10, tile=(1, 1),
                              set=["box.L_x=6.0", "box.L_y=6.0"])
    ns = bench.run_table_bench(args, None)
    out = capsys.readouterr().out.strip().splitlines()
    assert out[-1] == f"ns_per_atom_step={ns:.6g}"
    phases = [ln.split()[2] for ln in out if ln.startswith("bench: phase")]
    assert phases == ["forces", "lists", "integration", "communication", "glue"]
    shares = [float(ln.split()[-1].rstrip("%")) for ln in out if ln.startswith("bench: phase")]
    # the phases are disjoint parts of the loop: they and the glue add up to it
    assert abs(sum(shares) - 100) < 0.5 and shares[-1] >= 0 and shares[0] > 0
    assert "engine arrays" in next(ln for ln in out if ln.startswith("bench: memory"))
    steps = next(ln for ln in out if ln.startswith("bench: steps"))
    median, p90 = (float(re.search(rf"{k} ([0-9.]+) ms", steps)[1]) for k in ("median", "percentile"))
    assert 0 < median <= p90 and 0 <= float(re.search(r"took ([0-9.]+) %", steps)[1]) <= 100


def test_warm_up_compiles_the_engine_the_loop_times(tmp_path, monkeypatch, capsys):
    """The untimed warm-up builds its engine as the timed loop does (device and every ``engine.gpu_*``
    key): the GPU engine's kernels differ by them, and a variant first compiled inside the timed loop
    would be timed with its compilation."""
    made = []
    real = bench.make_engine

    def spy(state, phys, dom, device="cpu", **gpu):
        made.append((device, gpu))
        return real(state, phys, dom, "cpu")

    monkeypatch.setattr(bench, "make_engine", spy)
    settled_table(tmp_path / "t.txt")
    sets = ["engine.gpu_block=64", "engine.gpu_threads=entry", "engine.gpu_max_registers=80",
            "engine.gpu_reductions=fused", "engine.gpu_samples=device", "engine.gpu_drift=fused",
            "engine.gpu_pinned=true", "engine.gpu_rebuild=device", "engine.gpu_sort=device",
            "engine.gpu_exchange=device"]
    args = argparse.Namespace(table=str(tmp_path / "t.txt"), steps=5, tile=(1, 1),
                              set=["box.L_x=6.0", "box.L_y=6.0", *sets])
    bench.run_table_bench(args, None)
    capsys.readouterr()
    want = {"gpu_block": 64, "gpu_threads": "entry", "gpu_max_registers": 80, "gpu_reductions": "fused",
            "gpu_samples": "device", "gpu_drift": "fused", "gpu_pinned": True,
            "gpu_rebuild": "device", "gpu_sort": "device", "gpu_exchange": "device"}
    assert len(made) == 2 and made[0] == made[1] == ("cpu", want)
