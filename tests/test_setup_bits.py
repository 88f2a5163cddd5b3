"""The set-up cut into short calls (issue 57, item 6) gives the bits it gave in one go.

The insertion draws its candidates in short batches and the bed-making settle runs in short
calls, so that a run can say its progress and honour a stop signal between them; the initial
state must be the one the single long calls made. The run's loop, too, looks at signals after
spans of at most ``QUIET_ROW_STEPS`` sphere-steps, with the digest of its longer spans.
"""
import hashlib
import math

import numpy as np

import mpdem
from mpdem import build
from mpdem.decomp import Domain
from mpdem.engine.base import Physics
from mpdem.engine.cpu import Engine
from mpdem.config import bed_seed, gamma_n_from_epsilon
from mpdem.state import State


def digest(*arrays):
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def test_the_insertion_places_the_same_centres_whatever_its_batches():
    bed = build.insert_random(build.rng(3, 9), 40, 6.0, 6.0, 0.5, 3.5)
    whole = build.insert_random(build.rng(4, 2), 600, 6.0, 6.0, 2.0, 60.0, obstacles=bed, batch=1 << 40)
    seen = []
    cut = build.insert_random(build.rng(4, 2), 600, 6.0, 6.0, 2.0, 60.0, obstacles=bed, batch=97,
                              progress=lambda done, n: seen.append(done))
    assert digest(whole) == digest(cut)
    # progress after every batch, ending at the whole count
    assert len(seen) > 5 and seen[-1] == 600 and seen == sorted(seen)
    # no sphere overlaps another or the bed (the test the initial state's check would make)
    from mpdem.analysis import find_contacts
    pairs, _ = find_contacts(np.concatenate([cut, bed]), 6.0, 6.0)
    assert not np.any(pairs < len(cut))


def bed_in_one_call_a_tenth(cfg):
    """The bed of ``make_bed`` as it was made before its settle was cut into short calls: the
    insertion in one batch, ``advance`` a tenth of the settle at a time."""
    b, L_x, L_y = cfg.bed, cfg.box.L_x, cfg.box.L_y
    n = max(1, round(b.settle_density * L_x * L_y))
    x = build.insert_random(build.rng(bed_seed(cfg), build.STREAM_BED), n, L_x, L_y, 0.5,
                            0.5 + build.insertion_height(n, L_x, L_y, 0.3), batch=1 << 40)
    k_n = b.settle_k_n
    phys = Physics.of(k_n=k_n, k_t=0.0, gamma_n=gamma_n_from_epsilon(b.settle_epsilon, k_n), gamma_t=0.0,
                      mu=0.0, dt=1e-4 * math.sqrt(2e5 / k_n), skin=0.3, gravity=1.0, floor=True)
    state = State(np.arange(n), x, L_x=L_x, L_y=L_y)
    eng = Engine(state, phys, Domain(None))
    eng.start()
    steps = int(math.ceil(b.settle_time / phys.dt))
    chunk = max(1, steps // 10)
    for done in range(0, steps, chunk):
        eng.advance(min(chunk, steps - done))
    xs = state.x[:n]
    sel = (xs[:, 2] >= b.gap) & (xs[:, 2] <= b.gap + b.thickness)
    bed = xs[sel].copy()
    bed[:, 2] -= bed[:, 2].min()
    return bed[np.lexsort((bed[:, 0], bed[:, 1], bed[:, 2]))]


def test_the_bed_settled_in_short_calls_is_the_bed_of_one_call_a_tenth(monkeypatch):
    cfg = mpdem.load_config(**{"box.L_x": 4.0, "box.L_y": 4.0, "bed.settle_time": 1.5, "run.max_steps": 1})
    n = round(cfg.bed.settle_density * 16.0)
    # 7 steps a call: the tenths (150 steps) end inside a call's span, and the insertion in batches of 50
    monkeypatch.setattr(build, "SETTLE_ROW_STEPS", 7 * n)
    monkeypatch.setattr(build, "RSA_BATCH", 50)
    lines = []
    made = build.make_bed(cfg, progress=lines.append)
    assert digest(made.x) == digest(bed_in_one_call_a_tenth(cfg))
    settle = [ln for ln in lines if "settling" in ln]
    assert len(settle) >= 1500 // 7 and settle[-1].endswith("step 1500/1500")


def test_the_loop_in_shorter_quiet_spans_gives_the_same_digest(tmp_path, monkeypatch):
    # a large pile's spans between the loop's looks at signals are cut to QUIET_ROW_STEPS sphere-steps;
    # cut a small pile's to some forty steps, which no schedule's step divides (500 between samples)
    from mpdem.driver import simulation
    sets = {"pour.N": 200, "box.L_x": 5.0, "box.L_y": 5.0, "pour.phi_i": 0.3, "pour.K0": 5.0,
            "bed.settle_time": 1.0, "stop.sample_interval": 0.05, "run.max_steps": 6000}
    cfg = mpdem.load_config(**sets)
    whole = mpdem.run(cfg, str(tmp_path / "whole"))
    spans = []
    quiet = simulation.Run._quiet_steps

    def seen(self, *a, **k):
        spans.append(quiet(self, *a, **k))
        return spans[-1]
    monkeypatch.setattr(simulation.Run, "_quiet_steps", seen)
    monkeypatch.setattr(simulation, "QUIET_ROW_STEPS", 37 * 250)
    cut = mpdem.run(cfg, str(tmp_path / "cut"))
    assert 37 <= max(spans) < 60 and whole.steps == cut.steps == 6000
    assert cut.digest == whole.digest
