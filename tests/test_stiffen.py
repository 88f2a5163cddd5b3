"""Stiffening a settled pile (docs/model.md 6.6, ``mpdem.stiffen``): the ramp's laws, the tangential
force kept through a rescaled history, the refusals, and a pile stiffened tenfold that keeps its
contacts, carries its weight on overlaps ten times smaller and ends static, restart-exact.

The soft pile: 120 spheres poured at k_n = 2e4 (mu = 0.5) in a 5 d x 5 d box, settled by the stop
rule; the rung takes it to k_n = 2e5 over a ramp of 2 tau.
"""
import math

import numpy as np
import pytest

import mpdem
from mpdem import stiffen
from mpdem.config import ConfigError, gamma_n_from_epsilon, restitution
from mpdem.errors import InputError
from mpdem.io import checkpoint
from mpdem.kernels.law import make_law, tangential

from helpers import mpdem as cli

SOFT = dict(box__L_x=5.0, box__L_y=5.0, pour__N=120, pour__phi_i=0.3, contact__k_n=2e4, contact__mu=0.5,
            run__seed=2, run__max_steps=400000)
RAMP = ["stiffen.ramp_time=2.0", "run.max_steps=300000"]


def cfg_of(**sets):
    return mpdem.load_config(**{k.replace("__", "."): v for k, v in sets.items()})


@pytest.fixture(scope="module")
def soft(tmp_path_factory):
    """The soft pile, settled: its run directory."""
    out = tmp_path_factory.mktemp("soft") / "run"
    r = mpdem.run(cfg_of(**SOFT), out)
    assert r.status == "converged"
    return out


@pytest.fixture(scope="module")
def stiffened(soft, tmp_path_factory):
    """The soft pile stiffened tenfold through the ramp: its run directory."""
    out = tmp_path_factory.mktemp("stiff") / "run"
    r = mpdem.run(stiffen.rung_config(str(soft), 2e5, RAMP), out)
    assert r.status == "converged", "a stiffened pile must settle by the stop rule"
    return out


def pairs_and_overlaps(path):
    """The contacts of a state file as a set of (id, id) and their mean overlap [d]."""
    t, _ = checkpoint.read_state(path)
    x, ids, count, partner = t["x"], t["id"], t["count"], t["partner"]
    row = {int(i): k for k, i in enumerate(ids)}
    first = np.concatenate([[0], np.cumsum(count)])
    found, deltas = set(), []
    for a in range(len(ids)):
        for slot in range(first[a], first[a + 1]):
            b = row[int(partner[slot])]
            d = x[a] - x[b]
            d[:2] -= 5.0 * np.round(d[:2] / 5.0)
            delta = 1.0 - math.sqrt(d @ d)
            pair = (min(int(ids[a]), int(ids[b])), max(int(ids[a]), int(ids[b])))
            if delta > 0 and pair not in found:
                found.add(pair)
                deltas.append(delta)
    return found, float(np.mean(deltas))


def test_the_ramp_rises_geometrically_and_ends_on_the_configs_law():
    cfg = cfg_of(run__initial_file="x.h5", contact__k_n=2e6, stiffen__k_n_from=2e5, stiffen__ramp_time=1.0,
                 stiffen__update_interval=0.01, contact__gamma_t=5.0, run__max_steps=10)
    law = make_law(2e6, cfg.contact.k_t, cfg.contact.gamma_n, 5.0, 0.5, cfg.integration.dt)
    r = stiffen.Ramp(cfg, law)
    assert r.tread == round(0.01 / cfg.integration.dt) and r.treads * r.tread * cfg.integration.dt >= 1.0 - 1e-12
    assert r.law(0).k_n == 2e5 and r.law(0).ds_scale == 1.0
    ks = [r.law(m * r.tread).k_n for m in range(r.treads + 1)]
    steps = np.array(ks[1:]) / np.array(ks[:-1])
    assert np.allclose(steps, 10 ** (1 / r.treads), rtol=1e-12, atol=0)
    for m in (0, 1, r.treads // 2, r.treads - 1):
        lm = r.law(m * r.tread + 1)
        assert lm.ds_scale == 1.0 and lm.k_n == ks[m]
        assert lm.k_t == pytest.approx(2 * lm.k_n / 7, rel=1e-14)
        assert restitution(lm.gamma_n, lm.k_n) == pytest.approx(cfg.contact.epsilon, rel=1e-12)
        assert lm.gamma_t / lm.gamma_n == pytest.approx(5.0 / cfg.contact.gamma_n, rel=1e-12)
        assert lm.dt == cfg.integration.dt
    # from ``end`` on, the config's law itself
    assert r.law(r.end)._replace(ds_scale=1.0) == law and r.law(r.end + 1) == law
    assert not r.active(r.end) and r.active(r.end - 1)
    # the rescalings of the history over the ramp take k_t from the soft spring's to the stiff one's
    product = math.prod(r.law(m * r.tread).ds_scale for m in range(1, r.treads + 1))
    assert product * law.k_t == pytest.approx(2 * 2e5 / 7, rel=1e-12)
    # steps that share one law: none at a tread's first step, the rest of the tread otherwise
    assert r.room(r.tread - 1) == 0 and r.room(0) == r.tread - 1 and r.room(r.end) > 10 ** 15
    # the ramp's last step (the end's rescaling) is a step of its own, from wherever a launch starts
    assert r.room(r.end - 1) == 0 and r.law(r.end).ds_scale != 1.0 and r.room(r.end - 2) == 1
    assert {r.law(s) for s in range(1, r.tread)} == {r.law(1)}


def test_the_rescaled_history_keeps_the_tangential_force():
    """F_t = -k_t Delta s: the stored Delta s times k_t(old) / k_t(new), met by k_t(new), gives the
    force k_t(old) gave it (no slip this evaluation, no damping)."""
    rng = np.random.default_rng(4)
    old = make_law(2e5, 2 * 2e5 / 7, gamma_n_from_epsilon(0.88, 2e5), 0.0, 0.5, 1e-4)
    k_new = 2e5 * 10 ** 0.01
    new = make_law(k_new, 2 * k_new / 7, gamma_n_from_epsilon(0.88, k_new), 0.0, 0.5, 1e-4,
                   ds_scale=old.k_t / (2 * k_new / 7))
    for _ in range(20):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        ds = rng.normal(size=3) * 1e-4
        ds -= (ds @ n) * n
        fn = 10.0    # far from the Coulomb bound: sticking
        *_, fx, fy, fz = tangential(tuple(ds), (0.0, 0.0, 0.0), tuple(n), 1.0, 0.5, fn, old, False)
        sx, sy, sz, gx, gy, gz = tangential(tuple(ds), (0.0, 0.0, 0.0), tuple(n), 1.0, 0.5, fn, new, False)
        assert np.allclose([gx, gy, gz], [fx, fy, fz], rtol=1e-13, atol=1e-20)
        assert np.linalg.norm([sx, sy, sz]) < np.linalg.norm(ds)


@pytest.mark.parametrize("sets,what", [
    (dict(stiffen__k_n_from=1e4), "by at most a decade"),
    (dict(stiffen__k_n_from=3e5), "by at most a decade"),
    (dict(stiffen__k_n_from=2e4, run__initial_file=""), "needs run.initial_file"),
    (dict(stiffen__k_n_from=2e4, stiffen__ramp_time=0.0), "stiffen.ramp_time"),
    (dict(stiffen__k_n_from=2e4, stiffen__update_interval=20.0), "stiffen.update_interval"),
])
def test_a_rung_past_a_decade_or_without_its_pile_is_refused(sets, what):
    base = dict(run__initial_file="pile.h5", contact__k_n=2e5, run__max_steps=10)
    base.update(sets)
    with pytest.raises(ConfigError, match=what.replace(".", r"\.")):
        cfg_of(**base)


def test_a_settled_pile_met_by_a_stiffer_spring_without_the_ramp_is_refused(soft, tmp_path):
    final = str(soft / "final.h5")
    with pytest.raises(InputError, match=r"settled at contact\.k_n = 20000.*stiffen\.k_n_from = 20000"):
        mpdem.run(cfg_of(**{**SOFT, "run__initial_file": final, "contact__k_n": 2e5}), tmp_path / "jump")
    with pytest.raises(InputError, match=r"stiffen\.k_n_from = 30000.*accepted: stiffen\.k_n_from = 20000"):
        mpdem.run(cfg_of(**{**SOFT, "run__initial_file": final, "contact__k_n": 2e5, "stiffen__k_n_from": 3e4}),
                  tmp_path / "wrong")
    # the command line says the same in one line, before any work
    p = cli("run", "--set", f'run.initial_file="{final}"', "--set", "contact.k_n=2e5", "--set", "run.max_steps=10",
            "--out", tmp_path / "cli", check=1)
    assert "stiffen.k_n_from = 20000" in p.stderr and not (tmp_path / "cli" / "thermo.csv").exists()


def test_a_stiffened_pile_keeps_its_contacts_carries_its_weight_on_smaller_overlaps_and_ends_static(soft, stiffened,
                                                                                                    tmp_path):
    before, delta_soft = pairs_and_overlaps(soft / "final.h5")
    after, delta_stiff = pairs_and_overlaps(stiffened / "final.h5")
    kept = len(before & after) / len(before)
    assert kept > 0.85, f"only {kept:.2f} of the soft pile's contacts survive the stiffening"
    # the same weights on ten times the spring: overlaps ten times smaller (Hooke), give or take the
    # contacts that opened or closed and the damping's share
    assert 0.07 < delta_stiff / delta_soft < 0.14
    log = (stiffened / "log.txt").read_text()
    assert "stiffen: k_n from 20000 to 200000" in log and "converged" in log
    rows = np.loadtxt(stiffened / "thermo.csv", delimiter=",", skiprows=1)
    end = int(log.split("over ")[1].split(" steps")[0])
    assert rows[-1, 0] > end, "the stop rule only holds after the ramp"
    # what the ramp is for: a jump (a ramp of one step) shakes the pile far more
    mpdem.run(stiffen.rung_config(str(soft), 2e5, ["stiffen.ramp_time=1e-4", "stiffen.update_interval=1e-4",
                                              "run.max_steps=3000"]), tmp_path / "jump")
    jump = np.loadtxt(tmp_path / "jump" / "thermo.csv", delimiter=",", skiprows=1)
    assert jump[:, 2].max() > 20 * rows[:, 2].max()


def test_a_restart_inside_the_ramp_goes_on_bit_for_bit(soft, tmp_path):
    short = RAMP + ["run.max_steps=12345", "output.checkpoint_every=6789"]
    straight = mpdem.run(stiffen.rung_config(str(soft), 2e5, short), tmp_path / "straight")
    first = mpdem.run(stiffen.rung_config(str(soft), 2e5, short[:-2] + ["run.max_steps=6789",
                                                                     "output.checkpoint_every=6789"]),
                      tmp_path / "split")
    assert first.status == "max_steps"
    again = mpdem.restart(tmp_path / "split", set_items=["run.max_steps=12345"])
    assert again.digest == straight.digest


def test_the_command_line_names_a_rise_past_a_decade(soft, tmp_path):
    p = cli("stiffen", soft, "--k_n", "5e5", "--out", tmp_path / "x", check=1)
    assert "--k_n 500000" in p.stderr and "up to 200000" in p.stderr and not (tmp_path / "x").exists()
    p = cli("stiffen", tmp_path / "nothing", "--k_n", "2e5", check=1)
    assert "nothing: no such run directory" in p.stderr
    (tmp_path / "empty").mkdir()
    p = cli("stiffen", tmp_path / "empty", "--k_n", "2e5", check=1)
    assert "neither final.h5 nor packing.npz" in p.stderr


def test_the_ladder_script_refuses_a_start_that_is_not_its_pile(soft, tmp_path):
    """analysis/sweeps/paper/ladder.sh FROM=RUN: a pile of another mu or seed, or a run without its final
    state, is refused before any rung (exit 2) and nothing is written."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "analysis" / "sweeps" / "paper" / "ladder.sh"

    def ladder(start, mu, seed):
        env = {**os.environ, "PY": sys.executable, "FROM": str(start)}
        return subprocess.run(["bash", str(script), mu, seed, str(tmp_path / "out")], env=env,
                              capture_output=True, text=True, timeout=120)

    p = ladder(soft, "0", "2")
    assert p.returncode == 2 and "mu = 0.5, seed = 2, not MU = 0" in p.stdout + p.stderr
    p = ladder(soft, "0.5", "3")
    assert p.returncode == 2 and "not MU = 0.5, SEED = 3" in p.stdout + p.stderr
    p = ladder(tmp_path / "nothing", "0.5", "2")
    assert p.returncode == 2 and "not a converged run with its final.h5" in p.stdout
    assert not any((tmp_path / "out").glob("kn*"))


def test_a_frictionless_pile_kept_as_its_packing_stiffens_from_rest_and_a_frictional_one_is_refused(soft, tmp_path):
    """A committed run keeps its packing.npz, not its final.h5 (``initial.from_packing``): without friction
    a rung starts from the packing's positions at rest, the settled pile (no tangential force needs a history);
    with friction the packing is refused in one line before any work (its tangential springs are lost)."""
    import shutil

    from mpdem import initial
    from mpdem.io import export

    frictionless = mpdem.run(cfg_of(**{**SOFT, "contact__mu": 0.0}), tmp_path / "mu0")
    assert frictionless.status == "converged"
    kept = tmp_path / "kept"
    kept.mkdir()
    export.export(str(tmp_path / "mu0" / "final.h5"), "packing")
    for name in ("config.toml", "summary.json", "packing.npz"):
        shutil.copy(tmp_path / "mu0" / name, kept / name)
    cfg = stiffen.rung_config(str(kept), 2e5, RAMP + ["run.max_steps=400"])
    assert cfg.run.initial_file == str(kept / "packing.npz") and cfg.stiffen.k_n_from == 2e4
    got = initial.particles(cfg.run.initial_file, cfg)
    want, _ = checkpoint.read_state(str(tmp_path / "mu0" / "final.h5"))
    order = np.argsort(want["id"])
    assert np.array_equal(got["id"], want["id"][order]) and np.array_equal(got["x"], want["x"][order])
    assert np.array_equal(got["fixed"], want["fixed"][order]) and not got["v"].any() and not got["omega"].any()
    assert np.abs(want["v"][want["fixed"] == 0]).max() > 0, "the state file's own velocities are left behind"
    r = mpdem.run(cfg, tmp_path / "rung")
    after, _ = checkpoint.read_state(str(tmp_path / "rung" / "final.h5"))
    moved = np.abs(after["x"][np.argsort(after["id"])] - got["x"]).max()
    assert r.steps == 400 and 0 < moved < 1e-3, f"the settled pile moved {moved} d in its first 400 steps"
    # a frictional pile's packing: one line, nothing written
    shutil.copy(soft / "config.toml", kept / "config.toml")
    p = cli("stiffen", kept, "--k_n", "2e5", "--out", tmp_path / "frictional", check=1)
    assert "keeps no contact histories" in p.stderr and "contact.mu = 0.5" in p.stderr
    assert not (tmp_path / "frictional").exists()


def test_a_ramp_read_back_from_its_config_toml_has_the_same_laws(tmp_path):
    """A rung's config.toml holds epsilon and gamma_n; a restart reads it back, and its ramp makes every
    tread's gamma_n from that epsilon: the same laws as the straight run's, also for an epsilon whose
    round trip through gamma_n is not exact (0.1)."""
    cfg = cfg_of(run__initial_file="x.h5", contact__k_n=2e6, contact__epsilon=0.1, stiffen__k_n_from=2e5,
                 stiffen__ramp_time=1.0, stiffen__update_interval=0.01, run__max_steps=10)
    (tmp_path / "config.toml").write_text(cfg.to_toml())
    again = mpdem.load_config(tmp_path / "config.toml")
    assert again.contact.epsilon == cfg.contact.epsilon == 0.1
    law = make_law(2e6, cfg.contact.k_t, cfg.contact.gamma_n, 0.0, 0.5, cfg.integration.dt)
    a, b = stiffen.Ramp(cfg, law), stiffen.Ramp(again, law)
    assert all(a.law(s) == b.law(s) for s in range(0, a.end + 2, 7))


def test_the_api_stiffen_config_is_the_command_lines_rung(soft):
    """``mpdem.stiffen_config`` (keys by name) is ``mpdem stiffen``'s config (``--set`` texts)."""
    cfg = mpdem.stiffen_config(soft, 2e5, **{"stiffen.ramp_time": 2.0, "run.max_steps": 300000})
    assert cfg == stiffen.rung_config(str(soft), 2e5, RAMP)
    assert cfg.contact.k_n == 2e5 and cfg.stiffen.k_n_from == 2e4 and cfg.stiffen.ramp_time == 2.0
    assert cfg.run.initial_file == str(soft / "final.h5") and cfg.contact.mu == 0.5 and cfg.pour.N == 120
    with pytest.raises(InputError, match="--k_n 500000.*up to 200000"):
        mpdem.stiffen_config(soft, 5e5)


def test_the_ladder_script_keeps_the_pours_stop_rule_and_sets_stop_energy_on_the_rungs_only(tmp_path):
    """STOP_ENERGY=translational: the stiffened rungs start and restart on the translational energy, the pour
    (the poured set's pile, its bits) keeps the config's rule, whether it starts or restarts. THREADS=2 reaches
    every run, rung and restart. A stand-in for python records each mpdem command and ends each run converged."""
    import os
    import stat
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "analysis" / "sweeps" / "paper" / "ladder.sh"
    journal = tmp_path / "journal"
    stub = tmp_path / "py"
    stub.write_text(f"""#!/usr/bin/env bash
[ "$1" = -c ] && exec {sys.executable} "$@"
echo "$*" >> {journal}
out=""; prev=""
for a in "$@"; do [ "$prev" = --out ] && out=$a; prev=$a; done
[ "$3" = restart ] && out=$4
[ -n "$out" ] && mkdir -p "$out/analysis" && echo '{{"status": "converged"}}' > "$out/summary.json" \\
    && echo '{{}}' > "$out/analysis/summary.json"
exit 0
""")
    stub.chmod(stub.stat().st_mode | stat.S_IEXEC)
    out = tmp_path / "lad"

    def ladder():
        env = {**os.environ, "PY": str(stub), "STOP_ENERGY": "translational", "THREADS": "2"}
        return subprocess.run(["bash", str(script), "0.5", "2", str(out), "2e7"], env=env, capture_output=True,
                              text=True, timeout=60)

    p = ladder()
    assert p.returncode == 0, p.stdout + p.stderr
    lines = journal.read_text().splitlines()
    pour, *rungs = [ln for ln in lines if " run " in ln or " stiffen " in ln]
    assert "-m mpdem run" in pour and "stop.energy" not in pour
    assert len(rungs) == 2 and all("--set stop.energy=translational" in r for r in rungs)
    assert all("--threads 2" in r for r in (pour, *rungs))
    # a pour restarted from its checkpoint keeps its rule too; a rung restarted takes the translational one
    for d in ("kn2e5", "kn2e6"):
        (out / d / "summary.json").unlink()
        (out / d / "checkpoints").mkdir(parents=True, exist_ok=True)
        (out / d / "checkpoints" / "ckpt-00001.h5").write_text("x")
    journal.unlink()
    assert ladder().returncode == 0
    restarts = [ln for ln in journal.read_text().splitlines() if " restart " in ln]
    assert len(restarts) == 2
    assert "kn2e5" in restarts[0] and "stop.energy" not in restarts[0]
    assert "kn2e6" in restarts[1] and "--set stop.energy=translational" in restarts[1]
    assert all("--threads 2" in r for r in restarts)
