"""A flow-arrest packing: spheres flow down an incline, the incline drops, the pile settles.

What it does
    The paper's second protocol (docs/model.md 5.5): one config with ``flow.incline`` (the tilt of
    gravity, x downslope, from the first step) and ``flow.time`` (how long the flow runs [tau]); then
    gravity takes ``box.incline`` (0: level) and the stop rule settles the pile. The same pile is also
    poured and settled without the flow, and the two packings are compared. ``thermo.csv`` follows
    the flow: its ``v_x`` column is the mean downslope velocity of the mobile spheres [sqrt(g d)].

What it prints
    The flow's peak and final mean v_x, then ``arrested: z = ..., phi = ...`` and
    ``poured: z = ..., phi = ...``; last ``wrote OUT/flow_arrest.png``. The paper has z = 4.69,
    phi = 0.594 arrested against 4.90, 0.61 poured (mu = 0.5, k_n = 2e5).

Cost
    Full size (default): 8000 spheres in 20 d x 10 d (a layer some 35 d thick), 24 degrees for
    400 tau, mu = 0.5, k_n = 2e5: the campaign's row analysis/results/paper/runs/flow, 6.2 million
    steps, 4.4 hours on one core (z 4.62, phi 0.592); and the pour to compare, an hour or two more
    (analysis/results/paper/runs/height poured 5000 spheres in 10 d x 10 d in 44 to 115 minutes).
    ``--tiny``: 150 spheres in 4 d x 4 d at k_n = 2e4, 26 degrees for 20 tau (a thin layer needs a
    steeper slope to flow), E_stop = 1e-5: about 20 s.

Run
    python examples/flow_arrest.py [--tiny] [--out runs/examples/flow]
    python -m mpdem run --set flow.incline=24 --set flow.time=400 --set contact.mu=0.5 ...   (the same)
"""
import argparse
import csv
import os

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt           # noqa: E402

import mpdem                              # noqa: E402

FULL = dict(pile={"pour.N": 8000, "box.L_x": 20.0, "box.L_y": 10.0, "contact.mu": 0.5,
                  "run.max_steps": 20_000_000},
            flow={"flow.incline": 24.0, "flow.time": 400.0})
TINY = dict(pile={"pour.N": 150, "box.L_x": 4.0, "box.L_y": 4.0, "pour.phi_i": 0.3, "contact.k_n": 2e4,
                  "contact.mu": 0.5, "stop.E_stop": 1e-5, "run.max_steps": 600_000},
            flow={"flow.incline": 26.0, "flow.time": 20.0})


def thermo(run_dir):
    """The columns of RUN/thermo.csv (one row per kinetic-energy sample) as lists of floats."""
    with open(os.path.join(run_dir, "thermo.csv"), newline="") as fh:
        rows = list(csv.DictReader(fh))
    return {k: [float(r[k]) for r in rows] for k in ("time", "ek", "v_x")}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tiny", action="store_true", help="a 150-sphere layer (seconds), as CI runs it")
    ap.add_argument("--out", default="runs/examples/flow", help="output directory")
    args = ap.parse_args()
    size = TINY if args.tiny else FULL

    # 1. the flow-arrest run: one config, the flow phase first
    cfg = mpdem.load_config(**size["pile"], **size["flow"])
    arrested = mpdem.run(cfg, os.path.join(args.out, "arrested"), force=True)
    t = thermo(arrested.out)
    t_end = cfg.flow.time
    during = [v for tt, v in zip(t["time"], t["v_x"]) if tt <= t_end]
    print(f"flow at {cfg.flow.incline:g} degrees for {t_end:g} tau: mean v_x peaked at {max(during):.3f}, "
          f"{during[-1]:.3f} when the incline dropped [sqrt(g d)]")
    print(f"arrested run: {arrested.status} after {arrested.steps} steps")

    # 2. the same pile poured and settled without the flow
    poured = mpdem.run(mpdem.load_config(**size["pile"]), os.path.join(args.out, "poured"), force=True)
    print(f"poured run: {poured.status} after {poured.steps} steps")

    for name, r in (("arrested", arrested), ("poured", poured)):
        a = mpdem.analyze(r.final)
        print(f"{name}: z = {a['z']:.3f}, phi = {a['phi']:.4f}, backbone z = {a['backbone']['z']:.3f}")

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 3.5))
    ax.plot(t["time"], t["v_x"])
    ax.axvline(t_end, ls=":", c="k", label="incline drops")
    ax.set(xlabel="t [tau]", ylabel="mean v_x [sqrt(g d)]", title="the flow and its arrest")
    ax.legend()
    bx.semilogy(t["time"], t["ek"])
    bx.axvline(t_end, ls=":", c="k")
    bx.set(xlabel="t [tau]", ylabel="E_k / N [m g d]", title="kinetic energy")
    fig.tight_layout()
    png = os.path.join(args.out, "flow_arrest.png")
    fig.savefig(png, dpi=100)
    print(f"wrote {png}")


if __name__ == "__main__":
    main()
