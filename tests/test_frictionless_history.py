"""The stored contact history is canonical: an exact zero is +0.0, never -0.0.

With mu = 0 Delta s is zero (docs/model.md 2.6; running 2.4 with mu = 0 leaves
-m_eff gamma_t v_t / k_t, zero when gamma_t = 0), and the mirror slot of a
pair holds the negation of its partner's (ARCHITECTURE.md, "Invariants"). -(+0.0) is -0.0,
and which partner computes the pair depends on the row order, hence on the
ranks: a non-canonical zero changes the digest with the rank count
(mpi_tests/test_decomposition.py, test_frictionless_pile_matches_one_rank).
"""
import numpy as np
import pytest

from mpdem.io import checkpoint


def gathered_slots(eng):
    """The contact slots as a checkpoint stores them: (owner, partner, ds)."""
    if hasattr(eng, "sync_slots"):      # history kept with the neighbour lists between rebuilds
        eng.sync_slots()
    a = checkpoint.gather_state(eng.state)
    return np.repeat(a["id"], a["count"]), a["partner"], a["ds"]


@pytest.mark.parametrize("gamma_t", [0.0, 25.7])
def test_frictionless_history_has_no_negative_zeros(engine_factory, gamma_t):
    """mu = 0: four layers of 25 spheres, stacked loosely over the hollows of
    a bed in a 6 d box, land in 1000 steps; then no stored Delta s component
    is -0.0 (with gamma_t = 0, docs/model.md 2.4 makes every Delta s exactly 0)."""
    n, L, layers = 5, 6.0, 4
    a = L / n
    grid = np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="ij"), -1).reshape(-1, 2) * a
    h = np.sqrt(1.0 - a * a / 2) + 0.001                  # 0.001 d above contact
    x = np.concatenate([np.column_stack([(grid + a / 2 * (k % 2 == 0)) % L, np.full(n * n, 0.5 + (k + 1) * h)])
                        for k in range(layers)] + [np.column_stack([grid, np.full(n * n, 0.5)])])
    n_mobile = layers * n * n
    x[:n_mobile, :2] = (x[:n_mobile, :2] + 0.0002 * np.random.default_rng(3).uniform(-1, 1, (n_mobile, 2))) % L
    fixed = np.r_[np.zeros(n_mobile, np.uint8), np.ones(n * n, np.uint8)]
    eng = engine_factory(x, fixed=fixed, L=L, mu=0.0, gamma_t=gamma_t, gravity=1.0)
    eng.advance(1000)
    owner, partner, ds = gathered_slots(eng)
    # the stack has landed: many mobile-mobile pairs, each in two mirror slots
    assert np.sum(partner < n_mobile) > 100
    if gamma_t == 0.0:
        assert np.all(ds == 0.0)
    zero = ds == 0.0
    neg = zero & np.signbit(ds)
    assert not neg.any(), (f"{int(neg.sum())} of {int(zero.sum())} zero Delta s components are -0.0, "
                           f"first in slot {owner[neg.any(1)][0]} -> {partner[neg.any(1)][0]}")
