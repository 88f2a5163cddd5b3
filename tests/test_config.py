"""Configuration: defaults, derivations, validation, round trip, --set."""

import re

import pytest

from mpdem import config
from mpdem.config import ConfigError, gamma_n_from_epsilon, restitution


def cfg(**sets):
    items = [f"{k}={v}" for k, v in sets.items()]
    return config.load(None, ["run.max_steps=100"] + items)


def test_defaults_follow_physics_md():
    c = cfg()
    assert c.contact.k_t == pytest.approx(2 * 2e5 / 7)
    assert c.contact.gamma_n == pytest.approx(51.43, abs=0.01)
    assert c.contact.gamma_t == 0.0
    assert c.integration.dt == pytest.approx(1e-4)
    assert c.stop.E_stop == pytest.approx(1e-8)
    assert c.stop.rule == "window"
    assert c.box.L_x == 20.0 and c.pour.N == 20000 and c.pour.phi_i == 0.13


def test_derived_defaults_scale_with_k_n():
    c = config.load(None, ["run.max_steps=1", "contact.k_n=2e9"])
    assert c.integration.dt == pytest.approx(1e-6)
    assert c.stop.E_stop == pytest.approx(1e-11)
    assert c.contact.gamma_n == pytest.approx(5142.7, rel=1e-4)


def test_max_steps_is_required():
    with pytest.raises(ConfigError, match="run.max_steps is required"):
        config.load(None, [])


@pytest.mark.parametrize("key,value,words", [
    ("contact.k_n", "-1", "k_n > 0"),
    ("contact.k_n", "nan", "finite"),
    ("contact.mu", "-0.1", "0 <= mu"),
    ("contact.epsilon", "0", "0 < epsilon <= 1"),
    ("contact.epsilon", "1.5", "0 < epsilon <= 1"),
    ("contact.gamma_n", "1e6", "critical"),
    ("contact.gamma_t", "-1", "gamma_t >= 0"),
    ("contact.k_t", "-1", "k_t >= 0"),
    ("pour.phi_i", "0.36", "phi_i < 0.35"),
    ("pour.phi_i", "0", "0 < phi_i"),
    ("pour.N", "0", "N >= 1"),
    ("pour.K0", "-2", "K0 >= 0"),
    ("box.L_x", "2.0", "L >= 3 d"),
    ("integration.dt", "5e-4", "t_col / dt"),
    ("integration.dt", "-1e-4", "dt > 0"),
    ("stop.E_stop", "0", "E_stop > 0"),
    ("run.max_steps", "0", "max_steps > 0"),
    ("contact.model", '"lj"', "accepted values"),
    ("pour.N", "1.5", "integer"),
    ("contact.limit_damping", "1", "true or false"),
])
def test_bad_values_name_key_value_and_range(key, value, words):
    with pytest.raises(ConfigError) as e:
        cfg(**{key: value})
    msg = str(e.value)
    assert key in msg and words in msg


def test_unknown_keys_are_rejected(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text("[run]\nmax_steps = 5\n[contact]\nfriction = 0.3\n")
    with pytest.raises(ConfigError, match="unknown key contact.friction"):
        config.load(p)
    with pytest.raises(ConfigError, match="unknown key"):
        config.load(None, ["run.max_steps=1", "contact.nope=1"])
    p.write_text("[walls]\nx = 1\n")
    with pytest.raises(ConfigError, match="unknown section"):
        config.load(p)


def test_warnings_for_unusual_but_valid_values():
    c = cfg(**{"contact.mu": "20", "contact.k_t": "1000.0", "pour.phi_i": "0.32"})
    text = " ".join(c.warnings)
    assert "contact.mu" in text and "contact.k_t" in text and "pour.phi_i" in text


def test_gamma_n_and_epsilon_must_agree():
    c = cfg(**{"contact.gamma_n": "50.0"})
    assert c.contact.epsilon == pytest.approx(0.883, abs=1e-3)
    with pytest.raises(ConfigError, match="disagree"):
        cfg(**{"contact.gamma_n": "50.0", "contact.epsilon": "0.5"})


def test_epsilon_given_beside_its_gamma_n_stays_as_given():
    """A run's config.toml holds epsilon and the gamma_n made from it; read back, epsilon is the one given,
    not gamma_n's round trip (which differs in the last bit for 0.1 at every k_n, 0.5 at most)."""
    for eps, k_n in ((0.1, 2e5), (0.5, 2e7), (0.26, 2e8)):
        g = gamma_n_from_epsilon(eps, k_n)
        assert restitution(g, k_n) != eps                    # the round trip this guards against
        c = cfg(**{"contact.k_n": repr(k_n), "contact.epsilon": repr(eps), "contact.gamma_n": repr(g)})
        assert c.contact.epsilon == eps and c.contact.gamma_n == g
        assert "contact.epsilon" not in c.derived


def test_resolved_config_round_trips(tmp_path):
    c = cfg(**{"contact.mu": "0.3", "contact.k_n": "2e6", "box.L_x": "12.5", "run.initial_file": '"a b.txt"'})
    p = tmp_path / "resolved.toml"
    p.write_text(c.to_toml())
    back = config.load(p)
    assert dict(back.values) == dict(c.values)
    assert "derived default" in c.to_toml()


def test_set_parses_toml_values_and_bare_strings():
    assert config.parse_set("contact.mu=0.25") == ("contact.mu", 0.25)
    assert config.parse_set("contact.model=hertz") == ("contact.model", "hertz")
    assert config.parse_set("contact.limit_damping=true") == ("contact.limit_damping", True)
    with pytest.raises(ConfigError, match="section.key=value"):
        config.parse_set("contact.mu")


def test_docs_config_reference_is_current():
    from pathlib import Path
    doc = (Path(__file__).parents[1] / "docs" / "config.md").read_text()
    assert config.reference_markdown() in doc


def test_docs_config_lists_the_parameter_keys():
    from pathlib import Path
    doc = (Path(__file__).parents[1] / "docs" / "config.md").read_text()
    assert ", ".join(f"`{k}`" for k in config.PARAM_KEYS) in doc


def _section(*names):
    return {k for k in config.KEYS if k.split(".")[0] in names}


def test_schema_flags_say_what_a_restart_may_change_and_what_is_physics():
    # a restart may change the step cap, the stop rule, the checks, the decomposition, the engine, the
    # output and the analysis settings: none of them alters a step's arithmetic
    assert set(config.RESTART_KEYS) == {"run.max_steps"} | _section("stop", "checks", "decomp", "engine", "output",
                                                                    "analysis")
    # physics: the box, the pour, the contact law, the bed, the stiffening ramp, the flow phase, dt and the stop
    # rule; not the seeds (run.seed, bed.seed), the step cap, the input files, the skin and slots (they leave a
    # run's result alone), nor the settings
    assert set(config.PHYSICS_KEYS) == (_section("box", "pour", "contact", "bed", "stiffen", "flow", "stop")
                                        | {"integration.dt"}) - {"bed.seed"}
    # the parameter set's columns: numbered 1..n, each once, the seed among them though it is not physics
    cols = sorted(k.param for k in config.SCHEMA if k.param)
    assert cols == list(range(1, len(config.PARAM_KEYS) + 1))
    assert "run.seed" in config.PARAM_KEYS and set(config.PARAM_KEYS) - {"run.seed"} <= set(config.PHYSICS_KEYS)
    assert (config.key_summary(config.RESTART_KEYS)
            == "run.max_steps, stop.*, checks.*, engine.*, decomp.*, output.*, analysis.*")


@pytest.mark.parametrize("item,allowed", [
    ("run.max_steps=200", True), ("stop.window=2.0", True), ("stop.rule=instantaneous", True),
    ("checks.escape_margin=50.0", True), ("decomp.balance_damping=0.3", True),
    ("output.checkpoint_keep=5", True), ("analysis.g_dr=0.02", True),
    ("contact.mu=0.2", False), ("contact.k_n=3e5", False), ("box.gravity=0.5", False), ("pour.N=100", False),
    ("bed.thickness=1.2", False), ("integration.dt=5e-5", False), ("integration.skin=0.3", False),
    ("run.seed=2", False), ("run.initial_file=x.h5", False),
])
def test_a_restart_set_may_change_only_restart_keys(tmp_path, item, allowed):
    from mpdem.driver import resume as restart
    attrs = {"config": cfg().to_toml()}
    if allowed:
        key, value = config.parse_set(item)
        assert restart.restart_config(attrs, "ck.h5", str(tmp_path), [item]).values[key] == value
    else:
        with pytest.raises(ConfigError, match=re.escape("a restart can change only run.max_steps, stop.*, checks.*")):
            restart.restart_config(attrs, "ck.h5", str(tmp_path), [item])


def test_sections_are_built_once_and_read_only():
    c = cfg()
    assert c.contact is c.contact and c.contact.k_n == 2e5
    with pytest.raises(AttributeError, match="read-only"):
        c.contact.k_n = 1.0
    with pytest.raises(AttributeError):
        c.no_such_section
    assert c.replace(**{"contact.k_n": 3e5}).contact.k_n == 3e5 and c.contact.k_n == 2e5
    assert c == cfg()


def test_every_error_said_as_one_line_is_an_mpdem_error():
    from mpdem import errors
    kinds = [v for v in vars(errors).values() if isinstance(v, type) and issubclass(v, Exception)]
    assert len(kinds) >= 12
    for err in kinds:
        assert issubclass(err, errors.MpdemError), err
    # the modules that raise them use the same classes
    from mpdem import build, threads
    from mpdem.io import checkpoint
    from mpdem.driver import schedule
    from mpdem.campaign import sweep
    from mpdem.analysis import report
    assert (build.InputError, checkpoint.StateFileError, schedule.RunError, report.AnalysisError,
            threads.ThreadsError, sweep.SweepError) == (errors.InputError, errors.StateFileError, errors.RunError,
                                                        errors.AnalysisError, errors.ThreadsError, errors.SweepError)


def test_a_retired_key_in_an_older_config_loads_and_a_set_of_it_is_refused(tmp_path):
    """integration.contact_slots is gone (issue 24): configs and state files that carry it still load."""
    old = tmp_path / "old.toml"
    old.write_text("[run]\nmax_steps = 10\n[integration]\ncontact_slots = 16\nskin = 0.3\n")
    cfg = config.load(str(old))
    assert cfg.integration.skin == 0.3 and "contact_slots" not in cfg.to_toml()
    assert "integration.contact_slots" not in cfg.values
    with pytest.raises(config.ConfigError, match="contact_slots: the key is retired"):
        config.load(str(old), ["integration.contact_slots=8"])


@pytest.mark.parametrize("value", ["chunk16", "chunk8"])
def test_a_gpu_thread_layout_no_longer_offered_is_one_clear_error(tmp_path, value):
    """engine.gpu_threads = "chunkR" is gone: a config file, a --set or a checkpoint's config that names it is
    refused with the key, the value and the layouts accepted."""
    from mpdem.driver import resume as restart
    from mpdem.errors import StateFileError
    said = (f"engine.gpu_threads = {value!r}: accepted values are 'row', 'entry', 'lanes2', 'lanes4', 'lanes8', "
            "'lanes16'")
    p = tmp_path / "c.toml"
    p.write_text(f'[run]\nmax_steps = 5\n[engine]\ngpu_threads = "{value}"\n')
    with pytest.raises(ConfigError, match=re.escape(said)):
        config.load(str(p))
    with pytest.raises(ConfigError, match=re.escape(said)):
        cfg(**{"engine.gpu_threads": value})
    attrs = {"config": cfg().to_toml()}
    with pytest.raises(ConfigError, match=re.escape(said)):
        restart.restart_config(attrs, "ck.h5", str(tmp_path), [f"engine.gpu_threads={value}"])
    old = {"config": cfg().to_toml().replace('gpu_threads = "row"', f'gpu_threads = "{value}"')}
    assert old["config"] != attrs["config"]
    with pytest.raises(StateFileError, match=re.escape(f"ck.h5: its config is unusable ({said})")):
        restart.restart_config(old, "ck.h5", str(tmp_path), [])


def test_lanes_a_row_need_the_pinned_launches():
    """engine.gpu_threads = "lanesL" with engine.gpu_pinned = false is one clear error naming both."""
    assert cfg(**{"engine.gpu_threads": "lanes4"}).engine.gpu_threads == "lanes4"
    with pytest.raises(ConfigError, match=re.escape("engine.gpu_threads = 'lanes4': accepted 'row' or 'entry' with "
                                                    "engine.gpu_pinned = false")):
        cfg(**{"engine.gpu_threads": "lanes4", "engine.gpu_pinned": "false"})


def test_warp_reductions_need_the_pinned_launches():
    """engine.gpu_reductions = "warp" with engine.gpu_pinned = false is one clear error naming both."""
    assert cfg(**{"engine.gpu_reductions": "warp"}).engine.gpu_reductions == "warp"
    with pytest.raises(ConfigError, match=re.escape("engine.gpu_reductions = 'warp': accepted 'tree' or 'fused' with "
                                                    "engine.gpu_pinned = false")):
        cfg(**{"engine.gpu_reductions": "warp", "engine.gpu_pinned": "false"})
