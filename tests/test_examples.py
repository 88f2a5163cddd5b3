"""The studies of examples/ at their tiny size, and the tutorial whole (examples/README.md): each runs
as a user runs it (``python examples/X.py --tiny``, a process of its own) and its printed numbers and
files are checked: physical ranges, the physics each shows (z falls with friction, overlaps shrink
as 1/k_n), digests equal where it compares two runs.

The sweep and the tutorial take half a minute or more and are marked ``validation`` (``make test``
runs them; ``make test-fast`` leaves them out)."""
import re
import subprocess
import sys
from pathlib import Path

import pytest

from helpers import ROOT, child_env

EXAMPLES = ROOT / "examples"
NUMBER = r"([-+0-9.eE]+)"


def example(name, *args, env=None, tmp_path=None):
    """``python examples/NAME --tiny ARGS --out TMP``: its stdout (exit 0 asserted)."""
    cmd = [sys.executable, str(EXAMPLES / name), *map(str, args)]
    if tmp_path is not None:
        cmd += ["--out", str(tmp_path)]
    p = subprocess.run(cmd, capture_output=True, text=True, env=child_env(env, clean=True), timeout=900,
                       cwd=tmp_path or ROOT)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    return p.stdout


def values(pattern, text):
    """Every match of ``pattern`` in ``text`` (its groups as floats where they parse)."""
    def num(g):
        try:
            return float(g)
        except ValueError:
            return g
    return [tuple(num(g) for g in m.groups()) if len(m.groups()) > 1 else num(m.group(1))
            for m in re.finditer(pattern, text)]


def test_every_example_says_what_it_does_prints_and_costs():
    scripts = sorted(EXAMPLES.glob("*.py"))
    assert len([p for p in scripts if p.name != "tutorial.py"]) >= 6
    readme = (EXAMPLES / "README.md").read_text()
    for p in scripts:
        text = p.read_text()
        assert p.name in readme, f"{p.name} is not in examples/README.md"
        if p.name != "tutorial.py":
            for part in ("What it does", "What it prints", "Cost", "Full size", "--tiny"):
                assert part in text, f"{p.name}: no {part!r} in its header"


def test_pour_and_analyze(tmp_path):
    out = example("pour_and_analyze.py", "--tiny", tmp_path=tmp_path)
    assert "run: converged" in out
    z, = values(rf"\nz = {NUMBER}", out)
    phi, = values(rf"\nphi = {NUMBER}", out)
    assert 4.0 < z < 7.0 and 0.55 < phi < 0.66                  # a mu = 0.5 pile's bulk
    P = [float(p) for p in re.findall(r"\d+: ([0-9.]+)", out.split("P(n): ")[1].split("\n")[0])]
    assert sum(P) == pytest.approx(1.0, abs=0.03)               # printed to 2 digits
    assert (tmp_path / "pour.png").stat().st_size > 10_000 and (tmp_path / "pile" / "final.h5").exists()


@pytest.mark.validation
def test_friction_sweep(tmp_path):
    out = example("friction_sweep.py", "--tiny", "--jobs", 1, tmp_path=tmp_path)
    rows = values(rf"mu = {NUMBER}: z = {NUMBER}, phi = {NUMBER}", out)
    assert [r[0] for r in rows] == [0.0, 0.3, 1.0]
    z = {r[0]: r[1] for r in rows}
    assert 5.7 < z[0.0] < 6.8 and 4.2 < z[1.0] < 5.7 and z[0.0] > z[1.0] + 0.4   # friction: fewer contacts
    assert all(0.55 < r[2] < 0.67 for r in rows)
    assert (tmp_path / "collect" / "fig2_z_vs_mu.png").exists() and (tmp_path / "z_of_mu.png").exists()
    assert len((tmp_path / "collect" / "sets.csv").read_text().splitlines()) == 4


def test_stiffen_pile(tmp_path):
    out = example("stiffen_pile.py", "--tiny", tmp_path=tmp_path)
    rows = values(rf"k_n = {NUMBER}: z = {NUMBER}, phi = {NUMBER}, median overlap {NUMBER} d, \d+ steps \((\w+)\)",
                  out)
    assert [r[0] for r in rows] == [2e3, 2e4, 2e5] and all(r[4] == "converged" for r in rows)
    for soft, stiff in zip(rows, rows[1:]):
        assert 5 < soft[3] / stiff[3] < 20                        # overlaps as 1/k_n: tenfold a rung
        assert stiff[1] <= soft[1] + 0.05                         # z does not grow with k_n
    assert all(5.5 < r[1] < 7.2 and 0.6 < r[2] < 0.67 for r in rows)   # frictionless: z near 6
    assert (tmp_path / "z_of_kn.png").exists()


def test_flow_arrest(tmp_path):
    out = example("flow_arrest.py", "--tiny", tmp_path=tmp_path)
    peak, last = values(rf"peaked at {NUMBER}, {NUMBER} when", out)[0]
    assert peak > 0.3 and last > 0.1                              # it flowed downslope
    assert "arrested run: converged" in out and "poured run: converged" in out
    for name in ("arrested", "poured"):
        (z, phi), = values(rf"{name}: z = {NUMBER}, phi = {NUMBER}", out)
        assert 4.0 < z < 6.5 and 0.55 < phi < 0.66
    assert (tmp_path / "flow_arrest.png").exists()


def test_lammps_to_ovito(tmp_path):
    out = example("lammps_to_ovito.py", "--tiny", tmp_path=tmp_path)
    assert "263 mobile and 106 bed spheres, box 10 d x 10 d" in out     # tests/data/README.md's file
    assert "run: max_steps after 2000 steps" in out
    wrote = [Path(p) for p in re.findall(r"^wrote (\S+)", out, re.M)]
    assert {p.suffix for p in wrote} == {".dump", ".xyz", ".xmf", ".local", ".data", ".png"}
    assert all(p.stat().st_size > 0 for p in wrote)
    assert "read back: 369 particles in final.dump, same positions" in out


def test_gpu_vs_cpu_under_the_simulator(tmp_path):
    out = example("gpu_vs_cpu.py", "--tiny", "--simulator", tmp_path=tmp_path)
    gpu, = values(r"gpu digest ([0-9a-f]{64})", out)
    cpu, = values(r"cpu digest ([0-9a-f]{64})", out)
    assert gpu == cpu and "digests equal: True" in out
    contacts, = values(r"contacts in the final state: (\d+)", out)
    assert contacts > 0                                           # the histories were compared too
    assert "numba's CUDA simulator" in out and (tmp_path / "gpu_vs_cpu.png").exists()


def test_gpu_vs_cpu_without_a_gpu_says_skipped(tmp_path):
    """No GPU visible and no simulator: one line, exit 0, nothing written."""
    p = subprocess.run([sys.executable, str(EXAMPLES / "gpu_vs_cpu.py"), "--tiny", "--out", str(tmp_path / "none")],
                       capture_output=True, text=True, timeout=600, cwd=tmp_path,
                       env=child_env({"NUMBA_ENABLE_CUDASIM": "0", "CUDA_VISIBLE_DEVICES": ""}, clean=True))
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    assert p.stdout.startswith("skipped: no GPU (engine.device = 'gpu'") and "Traceback" not in p.stderr
    assert not (tmp_path / "none").exists()                       # refused before any work


def test_slurm_chain_by_hand(tmp_path):
    out = example("slurm_chain.py", "--tiny", tmp_path=tmp_path)
    stops = values(r"checkpoint at step (\d+) \(exit 75\)", out)
    assert len(stops) >= 2 and stops == sorted(stops)            # a chain of at least three segments
    assert "max_steps at step 100000 (exit 3)" in out
    chain, = values(r"chain: \d+ segments, 100000 steps, digest ([0-9a-f]{64})", out)
    straight, = values(r"straight: 100000 steps, digest ([0-9a-f]{64})", out)
    assert chain == straight and "digests equal: True" in out
    assert (tmp_path / "chain.png").exists()


@pytest.mark.validation
def test_the_tutorial_runs_whole(tmp_path):
    out = example("tutorial.py", env={"MPDEM_TUTORIAL_OUT": str(tmp_path)}, tmp_path=None)
    assert "converged after" in out
    rows = values(rf"\nmu = {NUMBER}: z = {NUMBER}, phi = {NUMBER}", out)
    assert [r[0] for r in rows] == [0.0, 0.1, 0.5, 1.0, 10.0]
    z = {r[0]: r[1] for r in rows}
    assert 5.7 < z[0.0] < 6.8 and z[0.0] > z[10.0] + 0.5 and 4.0 < z[10.0] < 5.7
    for name in ("settling.png", "pile.png", "P_n.png", "fig2.png"):
        assert (tmp_path / name).stat().st_size > 5_000, name


def test_the_readme_stays_short_and_links_the_examples():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 150
    assert "examples/README.md" in text


def test_the_examples_pass_lint():
    """``make lint`` covers src, tests, mpi_tests and tools; the examples and the docs' conf.py here."""
    ruff = Path(sys.executable).parent / "ruff"
    p = subprocess.run([str(ruff), "check", "examples", "docs/conf.py"], cwd=ROOT, capture_output=True, text=True)
    assert p.returncode == 0, p.stdout + p.stderr
