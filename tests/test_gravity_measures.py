"""The measures of a pile under gravity (docs/model.md 6.2, 6.5, 6.6, 6.10) on known answers.

The backbone on hand-built contacts whose balance is known; alpha by maximum
likelihood on gaps drawn from a known power law; q6 order of an fcc crystal
and an ideal gas; the depth profile and sigma_zz of simple cubic columns
whose contacts carry exactly the weight above them; P(f) on known forces;
eq. 7 with a fixed exponent, the pooled scatter and the overlap fit on
synthetic data.
"""
import math

import numpy as np
import pytest

from mpdem.analysis import backbone, bands, bulk, contacts, fits, nearcontact, order

from helpers import SQUEEZE, draw_gaps, fcc, simple_cubic


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# ---- the backbone ---------------------------------------------------------------

def tripod(theta):
    """Three normals into a sphere from below, tilted theta from the vertical, 120 degrees apart."""
    phi = 2 * np.pi * np.arange(3) / 3
    return np.stack([-np.sin(theta) * np.cos(phi), -np.sin(theta) * np.sin(phi), np.full(3, np.cos(theta))], 1)


def test_a_frictionless_sphere_rests_on_a_tripod_but_not_on_two_of_its_legs():
    u = tripod(np.radians(35))
    assert backbone.balances_weight(u, 0.0)
    assert not backbone.balances_weight(u[:2], 0.0)
    # a contact from above adds nothing to hold the weight
    assert not backbone.balances_weight(np.vstack([u[:2], [[0, 0, -1.0]]]), 0.0)
    # a single contact straight below holds it (exactly), a tilted one only with friction
    assert backbone.balances_weight([[0, 0, 1.0]], 0.0)
    tilt = unit([[np.sin(np.radians(20)), 0, np.cos(np.radians(20))]])
    assert not backbone.balances_weight(tilt, 0.0)
    assert backbone.balances_weight(tilt, 0.5)       # atan(0.5) = 26.6 degrees > 20
    assert not backbone.balances_weight(tilt, 0.2)   # atan(0.2) = 11.3 degrees < 20
    assert not backbone.balances_weight(np.zeros((0, 3)), 0.5)


def test_the_backbone_drops_weak_contacts_then_spheres_that_lose_their_support_in_a_cascade():
    # rows 0-2: bed; 3 on a tripod of the bed; 4 on a tripod whose leg 4-2 is weak; 5 rests on 4 alone
    # (straight above it); 6 rests on 3 alone, straight above; 7 touches nothing
    legs = tripod(np.radians(35))
    pairs, nrm = [], []
    for bed, u in zip((0, 1, 2), legs):
        pairs += [(3, bed), (4, bed)]
        nrm += [u, u]
    pairs += [(5, 4), (6, 3)]
    nrm += [[0, 0, 1.0], [0, 0, 1.0]]
    pairs, nrm = np.array(pairs), np.array(nrm)
    F_n = np.full(len(pairs), 10.0)
    F_n[5] = 0.05                                     # the 4-2 leg: below 1 % of the mean 10
    removable = np.array([False] * 3 + [True] * 5)
    kept, live, counts, weak = backbone.backbone(8, pairs, nrm, F_n, np.full(len(pairs), 10.0), removable, 0.0, 0.01)
    assert weak.tolist() == [False] * 5 + [True] + [False] * 2
    # 4 has two legs left: out; then 5, which stood on 4, is out; 7 has nothing; 3 and 6 stay
    assert kept.tolist() == [True, True, True, True, False, False, True, False]
    assert counts.tolist() == [1, 1, 1, 4, 0, 0, 1, 0]
    assert live.tolist() == [True, False, True, False, True, False, False, True]
    # with friction (mu = 1, cones of 45 degrees) two legs of 35 degrees hold sphere 4, and so 5
    kept, *_ = backbone.backbone(8, pairs, nrm, F_n, np.full(len(pairs), 10.0), removable, 1.0, 0.01)
    assert kept.tolist() == [True] * 7 + [False]


def test_a_simple_cubic_pile_is_all_backbone_and_its_z_is_six():
    x, L = simple_cubic(6, 24, SQUEEZE)
    fixed = (x[:, 2] < 1).astype(np.uint8)
    for mu in (0.0, 0.5):
        s = bulk.bulk_summary(x, fixed, L, L, mu=mu, rattlers="force")
        assert s["rattlers"] == "force" and s["rattler_fraction"] == 0.0
        assert s["z"] == 6.0 and s["z_no_rattlers"] == 6.0
        assert s["count_rule"]["rattler_fraction"] == 0.0


def test_bed_bed_overlaps_are_not_contacts_and_do_not_weigh_on_the_backbone():
    # a bed is frozen as it settled, overlapping itself; bed-bed pairs are never computed (docs/model.md
    # 2.8), so they are no contacts. Were they, their elastic k_n delta (here 2e6 x 1e-3) would set the
    # bottom band's reference force and make every real contact on the bed "weak": nothing would stand.
    nxy, nz, a = 4, 5, 1.0 - 1e-3
    x, L = simple_cubic(nxy, nz, a)
    fixed = (x[:, 2] < a).astype(np.uint8)
    pk = bulk.Packing(x, fixed, L, L, mu=0.0)
    bed = fixed.astype(bool)
    assert not np.any(bed[pk.pairs[:, 0]] & bed[pk.pairs[:, 1]])
    # the file's forces: a vertical contact carries the spheres of its column above it, a horizontal none
    # (a state file lists the computed pairs only: none of the bed's own)
    layer = np.rint(x[:, 2] / a - 0.5).astype(int)
    every, _ = bulk.find_contacts(x, L, L)
    i, j = every[~(bed[every[:, 0]] & bed[every[:, 1]])].T
    F_n = np.where(layer[i] != layer[j], nz - 1 - np.minimum(layer[i], layer[j]), 0.0).astype(float)
    arrays = {"id": np.arange(len(x)), "id_i": i, "id_j": j, "F_n": F_n, "F_t": np.zeros((len(i), 3))}
    cf = contacts.contact_forces(pk, arrays, 2e6, 0.0)
    assert cf.from_file.all()
    bb = backbone.of_packing(pk, cf, h=float(x[:, 2].max()) + 0.5, band_width=2.5, force_fraction=0.01)
    assert bb["kept"].all() and bb["counts"][~bed].min() >= 1


def test_a_pile_resting_on_the_wall_under_a_sparse_bed_is_held_by_it():
    # a simple cubic pile, no bed sphere under it: its lowest layer rests on the wall (bed.wall, the plane
    # z = 0), which the pair list does not hold. Without the plane as a support a frictionless lowest
    # layer cannot hold its weight (its other contacts are level or from above) and the cascade takes
    # every sphere: "100 % rattlers". With friction the level contacts' cones hold it, which is why only
    # frictionless piles showed it.
    from mpdem import planes
    x, L = simple_cubic(4, 8, 1.0 - 1e-4)
    fixed = np.zeros(len(x), np.uint8)
    held = bulk.bulk_summary(x, fixed, L, L, mu=0.0, rattlers="force", planes=(planes.WALL,))
    assert held["rattler_fraction"] == 0.0 and held["z_no_rattlers"] == held["z"] and "rattler_note" not in held
    lost = bulk.bulk_summary(x, fixed, L, L, mu=0.0, rattlers="force")
    assert lost["rattler_fraction"] == 1.0 and math.isnan(lost["z_no_rattlers"])
    assert lost["rattler_note"] == bulk.NO_BACKBONE and bulk.rattlers_text(lost) == bulk.NO_BACKBONE
    assert bulk.rattlers_text(held) == f"{held['z']:.3f} (0.0% rattlers)"
    assert bulk.bulk_summary(x, fixed, L, L, mu=0.5, rattlers="force")["rattler_fraction"] == 0.0
    # the plane's contacts pass the same force cut: a plane far below supports nothing
    pk = bulk.Packing(x, fixed, L, L, 0.0, planes=(planes.Plane((0.0, 0.0, 1.0), -1.0),))
    assert len(pk.plane_contacts()[0]) == 0


def test_a_frictionless_pile_loaded_from_a_lammps_dump_onto_the_wall_has_a_backbone(tmp_path):
    # as a frictionless pile settled by LAMMPS on the wall under a sparse bed, loaded from its dump
    # (run.initial_file, run.fixed_types, bed.wall), stepped once and analysed: rattlers by the force rule
    from helpers import mpdem as cli
    x, L = simple_cubic(4, 8, 1.0 - 1e-4)
    bed = np.array([[0.5, 0.5, -2.0], [2.5, 2.5, -2.0]])      # a sparse bed, out of reach below the wall
    rows = [f"{i + 1} 1 {a!r} {b!r} {c!r} 0.5" for i, (a, b, c) in enumerate(x.tolist())]
    rows += [f"{len(x) + i + 1} 2 {a!r} {b!r} {c!r} 0.5" for i, (a, b, c) in enumerate(bed.tolist())]
    dump = tmp_path / "pile.dump"
    dump.write_text(f"ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{len(rows)}\nITEM: BOX BOUNDS pp pp ff\n0 {L!r}\n"
                    f"0 {L!r}\n-3 12\nITEM: ATOMS id type x y z radius\n" + "\n".join(rows) + "\n")
    run = tmp_path / "run"
    cli("run", "--set", f'run.initial_file="{dump}"', "--set", "run.fixed_types=[2]", "--set", "bed.wall=true",
        "--set", "contact.mu=0", "--set", "run.max_steps=1", "--set", "analysis.margin_bottom=1.0",
        "--set", "analysis.margin_top=1.0", "--out", run, check=3)
    p = cli("analyze", run, "--no-plots")
    import json
    s = json.loads((run / "analysis" / "summary.json").read_text())
    assert s["rattler_fraction"] == 0.0 and s["backbone"]["z"] > 0 and "% rattlers" in p.stdout
    assert "rattler_note" not in s


# ---- contact forces --------------------------------------------------------------

def test_contact_forces_take_the_files_forces_with_the_sign_of_each_pair():
    x = np.array([[1.0, 1.0, 1.0], [1.0, 1.0, 1.0 + 0.999], [1.0, 1.0 + 0.998, 1.0]])
    pk = bulk.Packing(x, np.zeros(3), 10.0, 10.0, mu=0.5)
    assert sorted(pk.pairs.tolist()) == [[0, 1], [0, 2]]
    c01, c02 = (pk.pairs.tolist().index(p) for p in ([0, 1], [0, 2]))
    # the file lists 1-0 (reversed) with its own forces, and not 0-2
    arrays = {"id": np.array([10, 11, 12]), "id_i": np.array([11]), "id_j": np.array([10]),
              "F_n": np.array([7.0]), "F_t": np.array([[0.5, 0.0, 0.0]])}
    cf = contacts.contact_forces(pk, arrays, 2e5, 0.5)
    assert cf.from_file[c01] and not cf.from_file[c02]
    assert cf.F_n[c01] == 7.0 and cf.F_t[c01].tolist() == [-0.5, 0.0, 0.0]   # on row 0 = id 10, not id 11
    assert cf.F_n[c02] == pytest.approx(2e5 * 0.002)                        # elastic k_n delta
    assert cf.nrm[c01] == pytest.approx([0, 0, -1]) and cf.zeta[c01] == pytest.approx(0.5 / (0.5 * 7.0))
    assert cf.force[c01] == pytest.approx([-0.5, 0, -7.0])
    # Hertz: sqrt(delta) k_n delta
    assert contacts.elastic_normal(np.array([0.01]), 1e5, "hertz")[0] == pytest.approx(0.1 * 1e3)


# ---- alpha by maximum likelihood ---------------------------------------------------

@pytest.mark.parametrize("alpha", [0.38, 0.52, -0.2])
def test_alpha_from_gaps_drawn_from_a_known_power_law_and_its_error_is_calibrated(alpha):
    rng = np.random.default_rng(11)
    a, b = 1e-3, 5e-2
    est = []
    for _ in range(200):
        st = nearcontact.window_stats(draw_gaps(rng, 800, alpha, a, b), a, b)
        est.append((st["alpha"], st["alpha_err"]))
    est = np.array(est)
    # unbiased within the spread of the mean, and the spread is the Fisher error
    assert abs(est[:, 0].mean() - alpha) < 4 * est[:, 0].std() / math.sqrt(len(est))
    assert est[:, 0].std() == pytest.approx(est[:, 1].mean(), rel=0.15)


def test_the_power_law_goodness_of_fit_keeps_a_power_law_and_rejects_a_broken_one():
    """``window_stats``'s KS test (docs/model.md 6.5): gaps of one power law pass (the p of a fitted
    law is conservative: fewer than 5 % of draws below 0.05); gaps whose slope changes from 0.3 to 0.7
    at xi = 1e-2 (a density continuous there) fail on the whole window and pass on each half."""
    rng = np.random.default_rng(12)
    a, m, b = 1e-3, 1e-2, 5e-2
    ps = [nearcontact.window_stats(draw_gaps(rng, 800, 0.5, a, b), a, b)["ks_p"] for _ in range(200)]
    assert np.mean(np.array(ps) < 0.05) < 0.05 and np.median(ps) > 0.3
    # the two pieces' masses for a density continuous at m: c1 m^-0.3 = c2 m^-0.7
    lo_mass = (m ** 0.7 - a ** 0.7) / 0.7
    hi_mass = m ** 0.4 * (b ** 0.3 - m ** 0.3) / 0.3
    n_lo = rng.binomial(6000, lo_mass / (lo_mass + hi_mass))
    xi = np.concatenate([draw_gaps(rng, n_lo, 0.3, a, m), draw_gaps(rng, 6000 - n_lo, 0.7, m, b)])
    whole = nearcontact.window_stats(xi, a, b)
    assert whole["ks_p"] < 1e-4 and whole["ks"] > 0.02
    assert nearcontact.window_stats(xi, a, m)["ks_p"] > 1e-3 and nearcontact.window_stats(xi, m, b)["ks_p"] > 1e-3
    assert math.isnan(nearcontact.window_stats(xi[:5], a, b)["ks_p"])
    # the CDF is the likelihood's density xi^-alpha (1 + xi)^2 integrated, also where a term is a log
    from scipy.integrate import quad
    for al in (0.5, 1.0, 2.0, 3.0):
        whole = quad(lambda t: t ** -al * (1 + t) ** 2, a, b, limit=200)[0]
        part = quad(lambda t: t ** -al * (1 + t) ** 2, a, 7e-3, limit=200)[0]
        assert nearcontact.power_law_cdf(7e-3, al, a, b) == pytest.approx(part / whole, rel=1e-9)
        assert nearcontact.power_law_cdf(b, al, a, b) == pytest.approx(1.0)
        assert nearcontact.power_law_cdf(a, al, a, b) == 0


def test_pooled_seeds_are_the_estimate_of_all_their_gaps_and_bootstrap_scatters():
    rng = np.random.default_rng(4)
    a, b = 1e-2, 5e-2
    runs = [draw_gaps(rng, 300, 0.5, a, b) for _ in range(4)]
    pooled = nearcontact.pooled([nearcontact.window_stats(g, a, b) for g in runs])
    whole = nearcontact.window_stats(np.concatenate(runs), a, b)
    assert pooled["n"] == 1200 and pooled["alpha"] == pytest.approx(whole["alpha"], abs=1e-10)
    boot = nearcontact.bootstrap([nearcontact.window_stats(g, a, b) for g in runs])
    assert 0 < boot < 1
    assert math.isnan(nearcontact.bootstrap([whole]))
    # too few gaps: no estimate
    assert math.isnan(nearcontact.window_stats(runs[0][:5], a, b)["alpha"])


def test_gaps_count_each_pair_once_and_say_its_ordered_count():
    # three spheres on a line at gaps 0.01 and 0.03; a fourth far away
    x = np.array([[1.0, 1, 1], [2.01, 1, 1], [3.04, 1, 1], [1.0, 5, 5]])
    refs = np.array([True, True, False, True])
    xi, w = nearcontact.gaps(x, refs, 10.0, 10.0, 0.05)
    order = np.argsort(xi)
    # 0-1 has two references: one gap for the likelihood, two ordered pairs for g(r); 1-2 one
    assert xi[order] == pytest.approx([0.01, 0.03]) and w[order].tolist() == [2, 1]
    st = nearcontact.window_stats(xi, 1e-3, 5e-2, w)
    assert (st["n"], st["n_ordered"]) == (2, 3)
    assert nearcontact.windows_of([1e-3, 1e-2, 5e-2]) == [(1e-3, 1e-2), (1e-2, 5e-2), (1e-3, 5e-2)]


# ---- crystal order ---------------------------------------------------------------

def test_fcc_is_crystal_like_and_an_ideal_gas_is_not():
    x, L = fcc(4, 4, math.sqrt(2.0) * SQUEEZE)
    # the crystal is periodic in x and y; its inner layers have full shells
    Q6, crystal, nsb = order.crystal_order(x, L, L, cutoff=1.2)
    inner = (x[:, 2] > 1.5) & (x[:, 2] < x[:, 2].max() - 1.5)
    assert inner.sum() > 50
    assert Q6[inner] == pytest.approx(0.57452, abs=1e-4) and crystal[inner].all() and (nsb[inner] == 12).all()
    rng = np.random.default_rng(8)
    gas = rng.random((3000, 3)) * [8.0, 8.0, 10.0]
    Q6, crystal, _ = order.crystal_order(gas, 8.0, 8.0)
    assert crystal.mean() < 0.01 and np.nanmean(Q6) < 0.4


# ---- depth profile and P(f) ------------------------------------------------------

def loaded_columns(n_cols=4, height=30, k_n=2e5):
    """Simple cubic columns whose contact k from the top carries the weight of the k spheres above it.

    Returns (x, fixed, L, F_n on the vertical contacts in order from the top): the bottom sphere of
    each column is the bed.
    """
    load = np.arange(height - 1, 0, -1, dtype=float)         # contact below sphere k (bottom first)
    gaps = 1.0 - load / k_n
    z = np.concatenate([[0.5], 0.5 + np.cumsum(gaps)])
    L = n_cols * (1.0 + 1e-6)
    xy = (np.arange(n_cols) + 0.5) * (1.0 + 1e-6)
    x = np.array([[a, b, c] for a in xy for b in xy for c in z])
    fixed = (x[:, 2] == 0.5).astype(np.uint8)
    return x, fixed, L, load


def test_depth_profile_of_loaded_columns_gives_the_weight_above_as_sigma_zz():
    x, fixed, L, load = loaded_columns()
    pk = bulk.Packing(x, fixed, L, L, mu=0.0)
    cf = contacts.contact_forces(pk, {}, 2e5, 0.0)
    assert np.sort(cf.F_n) == pytest.approx(np.sort(np.tile(load, 16)))
    h = x[:, 2].max()
    kept = np.ones(len(x), bool)
    prof = bands.depth_profile(pk, cf, kept, pk.counts, None, h + 0.5, 1.0, 3.0, h - 3.0)
    n_band = len(prof["z"])
    assert n_band == int(math.ceil(h + 0.5 - pk.z_bed))
    # band k (depth k to k + 1 below h + 0.5) holds sphere k from the top and the contact below it,
    # which carries the weight of k + 1 spheres over one d^2 per column
    for k in range(1, 20):
        assert prof["n_particles"][k] == 16 and prof["z"][k] == 2.0
        assert prof["sigma_zz"][k] == pytest.approx((k + 1) * (1 - (k + 1) / 2e5) / (1 + 1e-6) ** 2, rel=1e-9)
        assert prof["overlap_mean"][k] == pytest.approx((k + 1) / 2e5, rel=1e-6)
        assert prof["F_n_mean"][k] == pytest.approx(k + 1, rel=1e-9)
        assert prof["phi"][k] == pytest.approx(math.pi / 6, rel=1e-4)
    assert prof["in_bulk"][2] is False and prof["in_bulk"][5] is True
    # each column sits on its bed sphere: all backbone, at mu = 0 too (the contact below is vertical)
    s = bulk.bulk_summary(x, fixed, L, L, mu=0.0, rattlers="force")
    assert s["rattler_fraction"] == 0.0


def test_force_distribution_on_known_forces():
    f = np.array([0.05, 0.5, 0.95, 1.5, 2.5, 9.0])
    d = bands.force_distribution(f)
    assert d["n"] == 6 and d["n_beyond"] == 1 and sum(d["counts"]) == 5
    assert d["counts"][0] == 1 and d["counts"][5] == 1 and d["counts"][9] == 1 and d["counts"][15] == 1
    assert d["small_f_fraction"] == pytest.approx(1 / 6)
    # tail beyond f = 1: 0.5, 1.5, 8.0 -> beta = 3 / 10
    assert d["tail_rate"] == pytest.approx(0.3) and d["tail_rate_err"] == pytest.approx(0.3 / math.sqrt(3))
    rng = np.random.default_rng(2)
    d = bands.force_distribution(1.0 + rng.exponential(1 / 1.7, 20000))
    assert d["tail_rate"] == pytest.approx(1.7, abs=4 * d["tail_rate_err"])
    assert sum(bands.density(d["counts"], d["n"])) * bands.F_BIN == pytest.approx(1 - d["n_beyond"] / d["n"])


# ---- eq. 7 soundly, and z against the overlap ---------------------------------------

def test_pooled_scatter_is_the_within_set_standard_deviation():
    s, dof = fits.pooled_scatter([[1.0, 3.0], [5.0], [2.0, 4.0, 6.0]])
    assert dof == 3 and s == pytest.approx(math.sqrt((2 + 8) / 3))
    assert math.isnan(fits.pooled_scatter([[1.0], [2.0]])[0])


def test_eq7_with_the_exponent_fixed_recovers_z_inf_and_reports_chi2_and_p():
    rng = np.random.default_rng(3)
    k = np.array([2e5, 2e6, 2e7, 2e8])
    sig = np.full(4, 0.004)
    p_values = []
    for _ in range(300):
        z = fits.eq7(k, 6.0, 0.14, 0.5) + sig * rng.standard_normal(4)
        f = fits.fit_eq7_fixed(k, z, sig, 0.5)
        p_values.append(f["p_value"])
    assert f["dof"] == 2 and f["alpha_n_fixed"] and f["alpha_n"] == 0.5
    assert abs(f["z_inf"] - 6.0) < 4 * f["z_inf_err"] and abs(f["a"] - 0.14) < 4 * f["a_err"]
    # p is uniform under the right model
    assert 0.4 < np.mean(p_values) < 0.6
    assert fits.p_value(2.0, 2) == pytest.approx(math.exp(-1.0))
    # a wrong exponent on precise data is rejected
    z = fits.eq7(k, 6.0, 0.14, 0.25)
    assert fits.fit_eq7_fixed(k, z, np.full(4, 1e-4), 0.5)["p_value"] < 1e-6


def test_overlap_fit_recovers_z_c_with_a_bootstrap_error_over_runs():
    rng = np.random.default_rng(6)
    delta, z, run = [], [], []
    for r in range(6):
        d = np.logspace(-5, -4, 8)
        delta.append(d)
        z.append(6.0 + 12.0 * np.sqrt(d) + 0.01 * rng.standard_normal(8))
        run.append(np.full(8, r))
    f = fits.fit_overlap(np.concatenate(delta), np.concatenate(z), np.concatenate(run))
    assert f["n_bands"] == 48 and f["n_runs"] == 6
    assert 0 < f["z_c_err"] < 0.05 and abs(f["z_c"] - 6.0) < 4 * f["z_c_err"]
    assert abs(f["A"] - 12.0) < 4 * f["A_err"]
    with pytest.raises(ValueError, match="at least 3"):
        fits.fit_overlap([1e-5, 2e-5], [6.1, 6.2], [0, 0])


def test_overlap_fit_bootstraps_samples_not_runs():
    """A pile measured twice (a ladder's pile at two rungs, here the same bands again) is one sample: with
    ``sample`` naming it, the fit and its bootstrap error are those of each pile once; counted as two runs
    the error shrinks by about sqrt(2), the optimism the samples remove."""
    rng = np.random.default_rng(11)
    d = np.tile(np.logspace(-5, -4, 6), 4)
    run = np.repeat(np.arange(4), 6)
    z = 6.0 + 12.0 * np.sqrt(d) + 0.01 * rng.standard_normal(24) + 0.01 * rng.standard_normal(4)[run]
    once = fits.fit_overlap(d, z, run)
    twice = fits.fit_overlap(np.tile(d, 2), np.tile(z, 2), np.concatenate([run, run + 4]), sample=np.tile(run, 2))
    assert twice["n_runs"] == 8 and twice["n_samples"] == 4 and once["n_samples"] == 4
    assert twice["z_c"] == pytest.approx(once["z_c"], abs=1e-12)
    assert twice["z_c_err"] == pytest.approx(once["z_c_err"], rel=1e-9)
    naive = fits.fit_overlap(np.tile(d, 2), np.tile(z, 2), np.concatenate([run, run + 4]))
    assert naive["n_samples"] == 8 and naive["z_c_err"] < 0.85 * once["z_c_err"]
    with pytest.raises(ValueError, match="one sample per band"):
        fits.fit_overlap(d, z, run, sample=run[:-1])


def test_the_collapse_of_z_against_the_overlap_across_k_n_is_tested():
    """Bands of three k_n on one curve z = 6 + 12 sqrt(delta): the F test keeps the one curve
    (its p is uniform: a fifth of the draws below 0.2); an offset of 0.02 at one k_n, some six
    times the error of a difference of two k_n's means (0.01 sqrt(2 / 16)), is found, and that
    k_n's bands sit above the one curve."""
    rng = np.random.default_rng(8)
    ps = []
    for draw in range(200):
        delta, z, run, k_n = [], [], [], []
        for r, k in enumerate((2e5, 2e5, 2e6, 2e6, 2e7, 2e7)):
            d = np.logspace(-5, -4, 8) * 2e5 / k
            delta.append(d)
            z.append(6.0 + 12.0 * np.sqrt(d) + 0.01 * rng.standard_normal(8))
            run.append(np.full(8, r))
            k_n.append(np.full(8, k))
        f = fits.fit_overlap(*(np.concatenate(a) for a in (delta, z, run)), n_boot=2, level=np.concatenate(k_n))
        ps.append(f["collapse"]["p"])
    assert 0.1 < np.mean(np.array(ps) < 0.2) < 0.3
    c = f["collapse"]
    assert c["status"] == "tested" and c["levels"] == [2e5, 2e6, 2e7] and c["dof"] == [2, 44]
    z = np.concatenate(z) + 0.02 * (np.concatenate(k_n) == 2e7)
    shifted = fits.fit_overlap(np.concatenate(delta), z, np.concatenate(run), n_boot=2, level=np.concatenate(k_n))
    assert shifted["collapse"]["p"] < 1e-3
    r, e = shifted["collapse"]["residual"], shifted["collapse"]["residual_err"]
    assert r[2] - r[0] > 0.01 and r[2] > 3 * e[2] and abs(sum(r)) < 0.005   # the shifted k_n sits above the curve
    one = fits.fit_overlap(np.concatenate(delta), z, np.concatenate(run), n_boot=2, level=np.full(len(z), 2e5))
    assert one["collapse"]["status"] == "not tested"
