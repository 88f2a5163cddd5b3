"""Flow arrest from one config (docs/model.md 5.5, ``mpdem.flowarrest``): gravity tilted by
``flow.incline`` for ``flow.time``, then by ``box.incline``, the stop rule from the switch on.

Known answer: a sphere on the frictionless plane z = 0 (``bed.wall``) slides at g sin(theta) of the
law in force, so after N steps with the switch at step E its v_x is exactly what velocity Verlet
gives, dt ((E - 1/2) sin(theta_flow) + (N - E + 1/2) sin(theta_arrest)); a switch a step early or late
is 1e-4 off. A small pile poured onto the tilted bed flows, then settles after the switch by the stop
rule; a restart inside the flow gives the straight run's digest, and so does the GPU engine.
"""
import math
import re

import numpy as np
import pytest

import mpdem
from mpdem import config
from mpdem.config import ConfigError
from mpdem.flowarrest import FlowPhase
from mpdem.kernels.law import gravity_vector
from mpdem.kernels.particle import R

from helpers import mpdem as cli

K_N = 2e5
# 150 spheres poured onto a bed tilted by 25 degrees, flowing for 0.2 tau, then level
PILE = dict(box__L_x=4.0, box__L_y=4.0, pour__N=150, pour__phi_i=0.3, contact__mu=0.5, run__seed=3,
            flow__incline=25.0, flow__time=0.2, run__max_steps=400000)


def cfg_of(**sets):
    return mpdem.load_config(**{k.replace("__", "."): v for k, v in sets.items()})


def test_the_flow_law_then_the_configs():
    from mpdem.engine.base import Physics
    cfg = cfg_of(**PILE, box__incline=5.0)
    final = Physics.from_config(cfg).law
    f = FlowPhase.from_config(cfg, final)
    assert f.end == 2000                     # 0.2 tau at dt = 1e-4
    assert (f.law(0).g_x, f.law(0).g_y, f.law(0).g_z) == gravity_vector(1.0, 25.0)
    assert f.law(1999) == f.law(0) and f.law(2000) is final and f.law(10 ** 7) is final
    assert (final.g_x, final.g_z) == gravity_vector(1.0, 5.0)[::2]
    assert f.law(0)._replace(g_x=final.g_x, g_z=final.g_z) == final     # nothing else changes
    # a GPU launch of one law: after step s, the steps s + 1 ... s + room(s) share the law of s + 1
    for s in (0, 1000, 1998, 1999, 2000, 5000):
        n = f.room(s)
        assert all(f.law(k) == f.law(s + 1) for k in range(s + 1, s + 1 + min(n, 50)))
        assert n >= 1 << 60 or f.law(s + 1 + n) != f.law(s + 1)
    assert f.active(1999) and not f.active(2000)
    assert FlowPhase.from_config(cfg_of(**{**PILE, "flow__incline": 0.0, "flow__time": 0.0}), final) is None


@pytest.mark.parametrize("sets, what", [
    (["flow.incline=20"], "flow.time = 0.0: accepted time > 0 with a flow phase"),
    (["flow.time=5"], "flow.time = 5.0: accepted time > 0 with a flow phase (flow.incline > 0), 0 without"),
    (["flow.incline=90", "flow.time=5"], "flow.incline = 90.0: accepted 0 (no flow phase) <= incline < 90"),
    (["flow.incline=20", "flow.time=5", "stiffen.k_n_from=2e4", "run.initial_file=x.h5"],
     "a run takes a flow phase or a stiffening ramp, not both"),
])
def test_bad_flow_settings_are_refused(sets, what):
    with pytest.raises(ConfigError, match=re.escape(what)):
        config.load_run_config(None, sets + ["run.max_steps=10"])


def test_a_sphere_slides_at_the_incline_in_force(tmp_path):
    """One sphere on the smooth plane: 0.3 tau at 30 degrees, then 0.2 tau at 10."""
    z = R - math.cos(math.radians(30.0)) / K_N
    table = tmp_path / "one.txt"
    table.write_text(f"id x y z\n0 5.0 5.0 {z!r}\n")
    n, e, dt = 5000, 3000, 1e-4
    r = cli("run", "--out", tmp_path / "slide", "--quiet", "--set", f"run.initial_file=\"{table}\"",
            "--set", "bed.wall=true", "--set", "contact.mu=0", "--set", "box.L_x=10", "--set", "box.L_y=10",
            "--set", "flow.incline=30", "--set", "flow.time=0.3", "--set", "box.incline=10",
            "--set", f"run.max_steps={n}", "--set", "output.progress_every=1000", check=3)
    log = (tmp_path / "slide/log.txt").read_text()
    assert "flow arrest: gravity tilted by 30 degrees for 3000 steps" in log
    # the progress line shows the flow's kinetic energy, though the stop rule's window stays empty:
    # at t = 0.1, v = g sin(30) t = 0.05 and E_k = v^2 / 2
    assert "E_k/N         -" not in log.split("flow arrest:")[1]
    assert "step      1000  t     0.100  E_k/N 1.250e-03" in log
    v = mpdem.read_state(tmp_path / "slide" / "final.h5")["v"][0]
    want = dt * ((e - 0.5) * math.sin(math.radians(30.0)) + (n - e + 0.5) * math.sin(math.radians(10.0)))
    assert v[0] == pytest.approx(want, rel=1e-9), r.stdout
    assert v[1] == 0.0
    # thermo.csv's v_x, the mean downslope velocity of the mobile spheres (here the one), at every sample
    th = np.genfromtxt(tmp_path / "slide" / "thermo.csv", delimiter=",", names=True)
    assert th["v_x"][-1] == pytest.approx(v[0], rel=1e-6)
    assert np.all(np.diff(th["v_x"]) > 0)


def test_a_thermo_table_begun_without_v_x_keeps_its_columns(tmp_path):
    """A restart of a run begun before the v_x column appends rows of the table's own width."""
    from types import SimpleNamespace as NS
    from mpdem.driver.schedule import Thermo
    (tmp_path / "thermo.csv").write_text(Thermo.HEADER.replace(",v_x", ""))
    row = (NS(step=10, time=0.001), 2.0, 1.0, 4, NS(mean=0.5, ratio=0.1), NS(max_overlap=1e-3, n_contacts=8, z_max=3.0),
           2, 1.5, 0.4)
    Thermo(tmp_path, 0).write(*row)
    lines = (tmp_path / "thermo.csv").read_text().splitlines()
    assert len(lines[1].split(",")) == 12
    (tmp_path / "new").mkdir()
    t = Thermo(tmp_path / "new", 0)
    t.write(*row)
    t.close()
    head, first = (tmp_path / "new" / "thermo.csv").read_text().splitlines()
    assert head.endswith(",force_ratio,v_x") and float(first.split(",")[12]) == 0.1


@pytest.fixture(scope="module")
def arrested(tmp_path_factory):
    """The pile poured onto the tilted bed, flowing, then levelled and settled: (result, run dir)."""
    out = tmp_path_factory.mktemp("arrest") / "run"
    return mpdem.run(cfg_of(**PILE), out), out


def test_a_pile_flows_then_settles_after_the_switch(arrested):
    r, out = arrested
    assert r.status == "converged"
    th = np.genfromtxt(out / "thermo.csv", delimiter=",", names=True)
    flowing = th["step"] < 2000
    assert r.steps > 2000 + 10000                 # the stop rule's window (1 tau) starts at the switch
    assert th["ek"][flowing].max() > 1e3 * th["ek"][-1]
    s = mpdem.read_state(out / "final.h5")
    assert np.abs(s["v"][s["fixed"] == 0]).max() < 1e-2


def test_a_restart_inside_the_flow_goes_on_bit_for_bit(tmp_path):
    short = dict(PILE, run__max_steps=3000)
    straight = mpdem.run(cfg_of(**short), tmp_path / "straight")
    first = mpdem.run(cfg_of(**dict(short, run__max_steps=1234, output__checkpoint_every=1234)), tmp_path / "split")
    assert first.status == "max_steps"
    again = mpdem.restart(tmp_path / "split", set_items=["run.max_steps=3000"])
    assert again.digest == straight.digest


def test_a_flow_lengthened_at_a_restart_is_the_straight_run_of_its_new_time(tmp_path):
    """``restart --set flow.time`` inside the flow (docs/model.md 5.5): the run of flow.time = 0.25 tau
    (switch at step 2500) restarted at step 1234 of a run of 0.2 tau (switch at 2000) gives the straight
    0.25 tau run's digest; outside the flow it is refused before any work, naming the steps."""
    short = dict(PILE, run__max_steps=3000)
    straight = mpdem.run(cfg_of(**dict(short, flow__time=0.25)), tmp_path / "straight")
    first = mpdem.run(cfg_of(**dict(short, run__max_steps=1234, output__checkpoint_every=1234)), tmp_path / "split")
    assert first.status == "max_steps"
    with pytest.raises(ConfigError, match=r"flow would end at step 1000, before .* step 1234; accepted: a "
                                          r"flow.time above 0.1234 tau"):
        mpdem.restart(tmp_path / "split", set_items=["flow.time=0.1"])
    again = mpdem.restart(tmp_path / "split", set_items=["run.max_steps=3000", "flow.time=0.25"])
    assert again.digest == straight.digest
    assert mpdem.load_config(str(tmp_path / "split" / "config.toml")).flow.time == 0.25
    with pytest.raises(ConfigError, match=r"past its flow's end at step 2500 \(flow.time = 0.25\)"):
        mpdem.restart(tmp_path / "split", set_items=["run.max_steps=4000", "flow.time=0.5"])
    plain = mpdem.run(cfg_of(**dict(short, flow__incline=0.0, flow__time=0.0, run__max_steps=100)), tmp_path / "plain")
    assert plain.status == "max_steps"
    with pytest.raises(ConfigError, match=r"flow.time = 1.0: accepted time > 0 with a flow phase"):
        mpdem.restart(tmp_path / "plain", set_items=["flow.time=1", "run.max_steps=200"])


def test_the_gpu_engine_takes_the_same_switch(tmp_path):
    """Under the simulator (or on a GPU): a short flow across its switch, the CPU's digest; the
    progress line at step 80 ends a launch, and the next must stop before the switch at step 100."""
    small = dict(PILE, pour__N=40, flow__time=0.01, run__max_steps=200, output__progress_every=80)
    cpu = mpdem.run(cfg_of(**small), tmp_path / "cpu")
    gpu = mpdem.run(cfg_of(**small, engine__device="gpu"), tmp_path / "gpu")
    assert gpu.digest == cpu.digest
