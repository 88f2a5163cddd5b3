"""stop.energy: a settled pile with a sphere that keeps spinning (docs/model.md 5.4).

Frictionless contacts exert no torque, so a sphere given a spin keeps it
exactly: the pile settles, the total kinetic energy never falls below E_stop,
and only the translational rule (``stop.energy = "translational"``) stops it.
That is the frictional campaign's spinner (a sphere turning about the line
through two contacts) in its simplest, exact form.
"""
import json

import numpy as np
import pytest

from mpdem import config
from mpdem.io import tables
from mpdem.kernels.particle import HALF_I
from mpdem.driver.schedule import StopRecord, StopRule
from mpdem.decomp import Domain
from mpdem.driver import spin
from mpdem.driver.simulation import Run
from mpdem.state import State

from helpers import mpdem, settled_table

SPIN = 2.0      # [sqrt(g/d)] about z, of the top sphere of one column: E_rot = 0.5 I w^2 = 0.2 [m g d]


def spinner_table(path):
    """The settled columns of ``helpers.settled_table`` (216 mobile on 36 bed, 6 d x 6 d), with
    the top sphere of the first column spinning about z; returns its row."""
    settled_table(path)
    t = tables.read_table(path)
    top = int(np.argmax(np.where(t["fixed"] == 0, t["x"][:, 2], -np.inf)))
    omega = np.zeros_like(t["x"])
    omega[top, 2] = SPIN
    tables.write_table(path, t["id"], t["x"], t["v"], t["fixed"], omega)
    return top


def run_pile(tmp_path, name, energy, max_steps=60000):
    table = tmp_path / "spinner.txt"
    top = spinner_table(table)
    cfg = config.load(None, [f"run.max_steps={max_steps}", "box.L_x=6.0", "box.L_y=6.0", "contact.mu=0.0",
                             "checks.overlap_warn=0.01", "stop.E_stop=1e-6", f'run.initial_file="{table}"',
                             f'stop.energy="{energy}"'])
    r = Run.new(cfg, str(tmp_path / name), quiet=True)
    status = r.run()
    r.finish()
    return r, status, top


def test_the_rule_keeps_the_energy_it_names():
    for energy, want in (("total", 3.0), ("translational", 1.0)):
        rule = StopRule(2.0, "instantaneous", 0.1, 0.1, 0.1, energy)
        rule.add(4.0, 8.0, 4)                         # per particle: 1 translational, 2 rotational
        assert rule.last == want
        assert rule.satisfied() == (want < 2.0)


def test_a_restart_that_changes_the_energy_starts_a_new_window():
    old = StopRule(1.0, "window", 0.3, 0.1, 0.1, "total")
    for _ in range(3):
        old.add(1.0, 1.0, 1)
    same, other = (StopRule(1.0, "window", 0.3, 0.1, 0.1, e) for e in ("total", "translational"))
    same.restore(old.record())
    other.restore(old.record())
    assert list(same.samples) == [2.0] * 3 and list(other.samples) == []
    # a checkpoint written before the key existed measured the total energy
    other.restore(StopRecord([2.0]))
    assert list(other.samples) == []


def test_a_spinning_sphere_holds_the_total_rule_but_not_the_translational_one(tmp_path):
    r, status, top = run_pile(tmp_path, "total", "total")
    assert status == "max_steps"
    # frictionless: no torque, so the spin is kept to the bit, and it is all the energy left
    assert r.state.omega[r.state.id == top + 1][0].tolist() == [0.0, 0.0, SPIN]
    e_rot = HALF_I * SPIN ** 2 / 216
    assert r.ek > e_rot > 100 * r.cfg.stop.E_stop
    assert r.ek - e_rot < r.cfg.stop.E_stop

    # the run says once, in its log, that rotation alone holds it, and how to stop it
    log = (tmp_path / "total" / "log.txt").read_text()
    assert log.count("rotation alone holds the run") == 1 and "stop.energy=translational" in log
    # and which sphere: the spinner, on the sphere below it alone, with all of the rotational energy
    assert f"100 % of the rotational energy is in sphere {top + 1} (1 contact, |omega| = 2 sqrt(g/d))" in log, log

    r2, status2, _ = run_pile(tmp_path, "trans", "translational")
    assert status2 == "converged" and r2.state.step < 60000
    s = json.loads((tmp_path / "trans" / "summary.json").read_text())
    assert s["converged"] and s["E_k_per_particle"] > e_rot
    assert "rotation alone" not in (tmp_path / "trans" / "log.txt").read_text()


def test_the_spinners_are_the_spheres_of_the_largest_rotational_energy():
    x = np.zeros((5, 3))
    omega = np.array([[0, 0, 1.0], [3.0, 0, 0], [0, 2.0, 0], [0, 0, 9.0], [0, 0, 0]])
    st = State(np.arange(10, 15), x, omega=omega, fixed=np.array([0, 0, 0, 1, 0], np.uint8))
    st.set_contacts(np.array([1, 2, 0, 0, 3]), np.arange(6), np.zeros((6, 3)))
    spheres, total = spin.spinners(st, Domain(None), top=2)
    # the bed's sphere (id 13) spins fastest but is not mobile
    assert spheres == [(HALF_I * 9.0, 11, 2, 3.0), (HALF_I * 4.0, 12, 0, 2.0)]
    assert total == pytest.approx(HALF_I * 14.0, rel=1e-15)
    text = spin.describe(spheres, total)
    assert text.startswith("64.3 % of the rotational energy is in sphere 11 (2 contacts, |omega| = 3 sqrt(g/d))")
    assert text.endswith("92.86 % in the 2 largest (ids 11, 12)")
    assert spin.describe([], 0.0) == "no mobile sphere is spinning"


def test_the_spinner_hint_needs_a_full_window_held_by_rotation_alone():
    def rule(energy="total", kind="window"):
        return StopRule(1.0, kind, 0.3, 0.1, 0.1, energy)     # a window of 3 samples, E_stop = 1
    r = rule()
    r.add(0.5, 20.0, 1)
    r.add(0.5, 20.0, 1)
    assert r.spin_hint() is None                      # the window is not full
    r.add(0.5, 20.0, 1)
    msg = r.spin_hint()
    assert "is 20.5 over the stop window" in msg and "translational part is 0.5" in msg
    assert "stop.energy=translational" in msg
    assert r.spin_hint() is None                      # once
    moving = rule()
    for _ in range(3):
        moving.add(2.0, 40.0, 1)                      # the translation itself above E_stop: no hint
    assert moving.spin_hint() is None
    both = rule()
    for _ in range(3):
        both.add(0.5, 1.0, 1)                         # rotation not 10 times the translation
    assert both.spin_hint() is None
    for energy, kind in (("translational", "window"), ("total", "instantaneous")):
        other = rule(energy, kind)
        for _ in range(3):
            other.add(0.5, 20.0, 1)
        assert other.spin_hint() is None              # that rule is not held by the spin
    cleared = rule()
    for _ in range(3):
        cleared.add(0.5, 20.0, 1)
    cleared.clear()
    cleared.add(0.5, 20.0, 1)
    assert cleared.spin_hint() is None and len(cleared.trans) == 1


def test_restart_with_the_translational_rule_ends_a_run_held_by_a_spinner(tmp_path):
    run_pile(tmp_path, "held", "total", max_steps=30000)
    p = mpdem("restart", tmp_path / "held", "--set", 'stop.energy="translational"', "--set", "run.max_steps=60000",
              check=0)
    s = json.loads((tmp_path / "held" / "summary.json").read_text())
    assert s["status"] == "converged" and 30000 < s["steps"] < 60000, p.stdout
    cfg = (tmp_path / "held" / "config.toml").read_text()
    assert 'energy = "translational"' in cfg
