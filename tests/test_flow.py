"""The chute diagnostics (``analysis.flow``, issue 42) against known fields: a Bagnold profile of
v_x over height, an isotropic thermal spread, and the flux as the integral of phi v_x."""
import math

import numpy as np
import pytest

from mpdem.analysis import flow


def bagnold(z, h, A=2.0):
    """The chute paper's steady profile, v_x = A (h^(3/2) - (h - z)^(3/2)) [sqrt(g d)], z above the bed."""
    return A * (h ** 1.5 - np.clip(h - z, 0, None) ** 1.5)


def test_the_profile_recovers_a_bagnold_flow_and_its_temperature():
    rng = np.random.default_rng(3)
    h, n = 20.0, 200_000
    z = rng.uniform(0, h, n)
    sigma = 0.3
    v = np.stack([bagnold(z, h), np.zeros(n), np.zeros(n)], axis=1) + sigma * rng.standard_normal((n, 3))
    edges = np.linspace(0, h, 41)
    p = flow.profile(z, v, edges)
    mid = 0.5 * (edges[:-1] + edges[1:])
    # a bin's mean of a smooth profile is its average over the bin, up to the noise and the spread of
    # the profile over the bin (its slope times the width over sqrt(12)) among the bin's spheres
    want = np.array([bagnold(np.linspace(a, b, 201), h).mean() for a, b in zip(edges[:-1], edges[1:])])
    slope = 1.5 * 2.0 * np.sqrt(np.clip(h - mid, 0, None))
    w = h / 40
    err = np.sqrt(sigma ** 2 + slope ** 2 * w ** 2 / 12) / np.sqrt(p["n"])
    assert np.all(np.abs(p["v_x"] - want) < 5 * err)
    assert np.all(np.abs(p["v_y"]) < 5 * err) and np.all(np.abs(p["v_z"]) < 5 * err)
    assert p["n"].sum() == n and np.all(p["v_x"][1:] > p["v_x"][:-1] - 5 * err[1:])
    # the temperature: sigma^2 plus a third of the profile's spread inside a bin (x alone spreads)
    assert np.allclose(p["T"], sigma ** 2 + slope ** 2 * w ** 2 / 12 / 3, rtol=0.05)


def test_the_flux_is_the_integral_of_phi_v_x():
    """A slab of spheres at packing fraction phi moving at u: flux phi u h per unit width."""
    L, h, u, phi = 10.0, 4.0, 0.7, 0.55
    n = int(round(phi * L * L * h / (math.pi / 6)))
    v = np.zeros((n, 3))
    v[:, 0] = u
    assert flow.flux(v[:, 0], L, L) == pytest.approx(phi * u * h, rel=1e-3)


def test_empty_and_single_bins_are_nan_not_errors():
    p = flow.profile([0.5, 2.5], [[1.0, 0, 0], [2.0, 0, 0]], np.array([0.0, 1.0, 2.0, 3.0]))
    assert list(p["n"]) == [1, 0, 1] and math.isnan(p["v_x"][1]) and p["v_x"][2] == 2.0
    assert np.all(np.isnan(p["T"]))


def test_a_flat_series_is_steady_and_a_drifting_one_is_not():
    """The steady-state test on series with known trends: noise about a constant (steady), the same
    with a 5 % rise over the window (not), a short series (not judged)."""
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 300.0, 0.1)
    flat = 2.0 + 0.05 * rng.standard_normal(len(t))
    s = flow.steady(t, flat, 100.0, 0.02)
    assert s["steady"] is True and abs(s["change"]) < 3 * s["sigma"] and abs(s["n"] - 1000) <= 1
    assert s["first"] == pytest.approx(2.0, abs=0.01) and s["second"] == pytest.approx(2.0, abs=0.01)
    # a rise of 0.1 over the last 100 tau: the halves' means differ by half of it, 2.5 % of the mean
    ramp = flat + 0.001 * np.clip(t - 200.0, 0, None)
    r = flow.steady(t, ramp, 100.0, 0.02)
    assert r["steady"] is False and r["change"] == pytest.approx(0.05 / 2.05, abs=0.004)
    assert flow.steady(t[:500], flat[:500], 100.0)["steady"] is None


def test_the_steadiness_of_a_flow_arrest_run_comes_from_its_flow_phase(tmp_path):
    """thermo.csv's rows up to flow.time are judged, the settling after them not."""
    import mpdem
    cfg = mpdem.load_config(**{"flow.incline": 24.0, "flow.time": 200.0, "run.max_steps": 10})
    t = np.arange(0.1, 260.0, 0.1)
    v_x = np.where(t <= 200.0, 3.0, 3.0 * np.exp(-(t - 200.0)))      # steady, then arrested
    ek = np.where(t <= 200.0, 5.0 + 0.01 * np.sin(t), 5.0 * np.exp(-(t - 200.0)))
    with open(tmp_path / "thermo.csv", "w") as fh:
        fh.write("step,time,ek,v_x\n")
        for k, (a, b, c) in enumerate(zip(t, ek, v_x)):
            fh.write(f"{k},{a:.10g},{b:.6e},{c:.6e}\n")
    s = flow.steadiness(str(tmp_path), cfg)
    assert s["steady"] is True and s["until"] == 200.0 and s["v_x"]["second"] == pytest.approx(3.0)
    assert abs(s["ek"]["n"] - 1000) <= 1
    assert flow.steadiness(str(tmp_path), mpdem.load_config(**{"run.max_steps": 10})) is None


def test_the_bagnold_fit_recovers_its_amplitude_and_exponent():
    """Bins of a Bagnold profile with noise: A and the exponent 3/2 back; a linear profile is no Bagnold
    profile (its best exponent is far from 3/2 and the 3/2 fit leaves a residual)."""
    rng = np.random.default_rng(9)
    z_bed, h = 1.0, 41.0
    z = np.arange(1.25, 41.0, 0.5)
    y, H = z - z_bed, h - z_bed
    n = np.full(len(z), 400)
    v = 0.02 * (H ** 1.5 - (H - y) ** 1.5)
    b = flow.bagnold(z, v + 0.01 * rng.standard_normal(len(z)), n, z_bed, h)
    assert b["A"] == pytest.approx(0.02, rel=1e-3) and b["rms"] < 0.01 and abs(b["exponent"] - 1.5) <= 0.02
    lin = flow.bagnold(z, 0.1 * y, n, z_bed, h)
    assert abs(lin["exponent"] - 1.5) > 0.3 and lin["rms"] > 10 * b["rms"]
    assert flow.bagnold(z[:2], v[:2], n[:2], z_bed, h) is None
