"""``bed.seed``: the bed's random stream apart from the pour's (issue 41: beds and pours sampled
apart). -1 is the run's seed, so every run before the key had its bed from run.seed."""
import numpy as np

import mpdem
from mpdem import build

TINY = {"box.L_x": 3.0, "box.L_y": 3.0, "bed.settle_time": 1.0, "run.max_steps": 1}


def bed_of(**sets):
    cfg = mpdem.load_config(**{**TINY, **sets})
    return build.make_bed(cfg, progress=lambda msg: None).x


def test_the_bed_follows_its_own_seed_and_the_runs_by_default():
    default = bed_of(**{"run.seed": 1})
    assert np.array_equal(default, bed_of(**{"run.seed": 1, "bed.seed": 1}))
    other = bed_of(**{"run.seed": 1, "bed.seed": 2})
    assert np.array_equal(other, bed_of(**{"run.seed": 2}))
    assert len(other) != len(default) or not np.array_equal(other, default)


def test_a_bed_seed_below_minus_one_is_refused():
    import pytest
    from mpdem.config import ConfigError
    with pytest.raises(ConfigError, match=r"bed\.seed = -2: accepted -1 \(run\.seed\) or a seed >= 0"):
        mpdem.load_config(**{**TINY, "bed.seed": -2})
