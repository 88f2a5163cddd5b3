"""`export --format lammps-input` run in a real LAMMPS against mpdem's own trajectory, and mpdem's
`lammps-local` contact dump against what LAMMPS's `compute pair/local` writes for the same state.

The start is a new run's state after one step (no contact yet, so no contact history that a
LAMMPS data file could not carry), dense and stirred (phi_i = 0.3, K0 = 1) so that spheres collide
within the steps compared. mpdem restarts from it and LAMMPS runs the exported script from it; both
reach the same step. Agreement is to round-off grown over 3000 steps of collisions: observed
(2026-11-24) positions within 2e-12, velocities within 6e-10 and angular velocities within 1.4e-9
(the elastic case; the damped ones within 5e-11), asserted below 1e-9 and 1e-7, far below what any
difference of model would give. The wall case writes and runs the wall fix; its spheres do not
reach the wall (under the bed) in these steps; the wall's law is checked on exact answers in
tests/test_wall.py.
LAMMPS comes from Debian (tools/setup.sh installs it as root).
"""
import os
import shutil
import subprocess

import numpy as np
import pytest

from mpdem.io import checkpoint, lammps, lammps_input
from mpdem.io.lammps_input import LammpsInputError

from helpers import mpdem

LMP = shutil.which("lmp")
needs_lammps = pytest.mark.skipif(LMP is None, reason="no LAMMPS (`lmp`) on PATH; tools/setup.sh installs "
                                                       "Debian's lammps as root")
STEPS = 3000
START = ("--set", "pour.N=600", "--set", "box.L_x=6", "--set", "box.L_y=6", "--set", "pour.phi_i=0.3",
         "--set", "pour.K0=1", "--set", "run.seed=5", "--set", "run.max_steps=1", "--quiet")


def start_state(tmp_path, *sets):
    """A run of one step with the given --set items; its final.h5 (no contact history in it)."""
    run = tmp_path / "mpdem"
    mpdem("run", "--out", run, *START, *(a for s in sets for a in ("--set", s)), check=3)
    arrays, _ = checkpoint.read_state(str(run / "final.h5"))
    assert lammps_input.nonzero_histories(arrays) == 0
    return run


def both_run(tmp_path, run):
    """Export, LAMMPS to step 1 + STEPS - 1 = STEPS, mpdem restarted to the same step; the LAMMPS directory."""
    out = tmp_path / "lammps"
    ran = mpdem("export", run / "final.h5", "--format", "lammps-input", "--out", out, check=0)
    assert "note:" not in ran.out
    lmp = subprocess.run([LMP, "-in", lammps_input.INPUT_NAME, "-var", "steps", str(STEPS - 1), "-var", "every",
                          "1000", "-log", "none"], cwd=out, capture_output=True, text=True, timeout=300)
    assert lmp.returncode == 0 and "ERROR" not in lmp.stdout, lmp.stdout[-3000:] + lmp.stderr[-2000:]
    mpdem("restart", run, "--set", f"run.max_steps={STEPS}", "--quiet", check=3)
    return out


def assert_same_trajectory(run, out):
    theirs = lammps.read(str(out / "final.dump"), (2,))
    ours, attrs = checkpoint.read_state(str(run / "final.h5"))
    assert int(attrs["step"]) == STEPS
    assert open(out / "final.dump").read().split("\n", 2)[1] == str(STEPS)     # ITEM: TIMESTEP, then the step
    order = np.argsort(theirs["id"])
    # LAMMPS's atom ids are mpdem's + 1 when mpdem's start at 0 (lammps.ID_SHIFT_NOTE)
    assert np.array_equal(theirs["id"][order] - (1 if ours["id"].min() == 0 else 0), ours["id"])
    assert np.array_equal(theirs["fixed"][order], ours["fixed"])
    for key, tol in (("x", 1e-9), ("v", 1e-7), ("omega", 1e-7)):
        err = np.abs(theirs[key][order] - ours[key]).max()
        assert err < tol, (key, err)
    # the comparison is not empty: the spheres moved and collided
    assert np.abs(ours["v"][ours["fixed"] == 0]).max() > 0.1
    return ours


def read_local(path, shift):
    """{(id_a, id_b) sorted: (dist, F_n, |F_t|)} of a dump local frame (the last one in the file)."""
    lines = open(path).read().splitlines()
    head = max(k for k, ln in enumerate(lines) if ln.startswith("ITEM: ENTRIES"))
    n = int(lines[head - 5])
    cols = lines[head].split()[2:]
    rows = np.array([ln.split() for ln in lines[head + 1:head + 1 + n]], float).reshape(n, len(cols))
    if cols[0] == "index":               # mpdem's: index patom1 patom2 dist fn ft ...
        ids, vals = rows[:, 1:3], rows[:, 3:6]
    else:                                # LAMMPS's: patom1 patom2 dist force p4
        ids, vals = rows[:, 0:2] - shift, rows[:, 2:5]
    ids = np.sort(ids.astype(np.int64), axis=1)
    return {tuple(i): v for i, v in zip(ids.tolist(), vals)}


@needs_lammps
def test_frictional_elastic_pile_in_lammps_is_mpdems_and_so_are_its_contacts(tmp_path):
    # epsilon = 1: gamma_n = 0, so a contact force is k_n delta and the tangential spring, whatever the
    # velocities (LAMMPS's pair/local evaluates with full-step, mpdem's list with half-step velocities)
    run = start_state(tmp_path, "contact.mu=0.5", "contact.epsilon=1")
    out = both_run(tmp_path, run)
    ours = assert_same_trajectory(run, out)
    local = tmp_path / "final.local"
    mpdem("export", run / "final.h5", "--format", "lammps-local", "--out", local, check=0)
    shift = 1 if ours["id"].min() == 0 else 0
    a, b = read_local(local, 0), read_local(out / "final-contacts.dump", shift)
    assert len(a) >= 3 and set(a) == set(b)
    k_n = 2e5
    for pair, (dist, fn, ft) in a.items():
        d2, fn2, ft2 = b[pair]
        assert abs(dist - d2) < 1e-11, pair
        assert abs(fn - fn2) < 1e-9 * k_n, pair
        assert abs(ft - ft2) < 1e-9 * k_n, pair
    # friction acted: some contact carries a tangential force
    assert max(v[2] for v in a.values()) > 0


@needs_lammps
def test_frictionless_damped_pile_in_lammps_is_mpdems(tmp_path):
    run = start_state(tmp_path, "contact.mu=0")
    assert_same_trajectory(run, both_run(tmp_path, run))


@needs_lammps
def test_hertz_with_tangential_damping_and_a_wall_in_lammps_is_mpdems(tmp_path):
    run = start_state(tmp_path, "contact.model=hertz", "contact.mu=0.5", "contact.gamma_t=20", "bed.wall=true")
    out = both_run(tmp_path, run)
    script = (out / lammps_input.INPUT_NAME).read_text()
    assert "gran/hertz/history" in script and "wall/gran hertz/history" in script and " 1 zplane" in script
    assert_same_trajectory(run, out)


def test_models_lammps_lacks_are_refused_by_name():
    contact = {"k_n": 2e5, "k_t": 5e4, "gamma_n": 50.0, "gamma_t": 0.0, "mu": 0.5, "model": "hooke",
               "history": "rotate", "limit_damping": False}
    with pytest.raises(LammpsInputError, match=r"contact.history = 'rotate' has no LAMMPS counterpart"):
        lammps_input.coefficients(contact)
    contact.update(history="project", limit_damping=True)
    with pytest.raises(LammpsInputError, match=r"contact.limit_damping = true"):
        lammps_input.coefficients(contact)
    contact.update(limit_damping=False, model="hertz", gamma_t=1.0)
    style, pair, wall = lammps_input.coefficients(contact)
    assert style == "gran/hertz/history" and pair == (4e5, 1e5, 100.0, 2.0, 0.5, 1)
    assert wall[:4] == tuple(np.sqrt(2.0) * np.array([2e5, 5e4, 50.0, 1.0])) and wall[4:] == (0.5, 1)


def test_a_state_with_histories_is_exported_with_a_note(tmp_path):
    run = tmp_path / "r"
    mpdem("run", "--out", run, *START[:-3], "--set", "run.max_steps=3000", "--set", "contact.mu=0.5", "--quiet",
          check=3)
    ran = mpdem("export", run / "final.h5", "--format", "lammps-input", check=0)
    assert "nonzero contact histories" in ran.out
    script = open(os.path.join(run, "final.lammps", lammps_input.INPUT_NAME)).read()
    assert "# NOTE:" in script and "variable steps index 1\n" in script
