"""Stiffening a pile: one packing taken to stiffer springs, and z against k_n (the paper's Fig. 7).

What it does
    Pours and settles a frictionless pile at a soft k_n, then stiffens it rung by rung, each rung a
    decade at most (``mpdem.stiffen_config`` and ``mpdem.run``; on the command line
    ``mpdem stiffen RUN --k_n K``): the new run starts from the previous rung's final state, k_n rises
    geometrically over ``stiffen.ramp_time`` with the tangential springs rescaled, then the stop rule
    settles the pile again (docs/model.md 6.6). The same spheres keep their contacts; overlaps shrink
    as 1/k_n, and z falls toward the isostatic 6 of a frictionless packing as k_n grows.

What it prints
    One line a rung: ``k_n = 200000: z = 6.121, phi = 0.6392, median overlap 2.10e-05 d, 123456 steps (converged)``;
    last ``wrote OUT/z_of_kn.png``.

Cost
    Full size (default): 2000 spheres in 10 d x 10 d poured at the paper's k_n = 2e5, then 2e6 and
    2e7 (analysis/results/paper/runs/ladder-dev measured this ladder at mu = 0: the pour 6.5 minutes,
    the 2e6 rung 6 minutes, the 2e7 rung 10 minutes on one core; z 6.10, 6.04, 6.03).
    ``--tiny``: 150 spheres in 4 d x 4 d, 2e3 then 2e4 and 2e5, ramps of 5 tau, E_stop = 1e-5:
    about 20 s.

Run
    python examples/stiffen_pile.py [--tiny] [--mu 0] [--out runs/examples/stiffen]
"""
import argparse
import os

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt           # noqa: E402

import mpdem                              # noqa: E402

FULL = dict(pour={"pour.N": 2000, "box.L_x": 10.0, "box.L_y": 10.0, "run.max_steps": 10_000_000},
            ladder=[2e6, 2e7], rung={"run.max_steps": 30_000_000})
TINY = dict(pour={"pour.N": 150, "box.L_x": 4.0, "box.L_y": 4.0, "pour.phi_i": 0.3, "contact.k_n": 2e3,
                  "stop.E_stop": 1e-5, "run.max_steps": 400_000},
            ladder=[2e4, 2e5], rung={"stiffen.ramp_time": 5.0, "stop.E_stop": 1e-5, "run.max_steps": 600_000})


def describe(r):
    """z, phi and the median overlap [d] of a run's final state, printed; returned as a dict."""
    a = mpdem.analyze(r.final)
    k_n = a["params"]["contact.k_n"]
    print(f"k_n = {k_n:g}: z = {a['z']:.3f}, phi = {a['phi']:.4f}, median overlap {a['overlap_median']:.2e} d, "
          f"{r.steps} steps ({r.status})", flush=True)
    return dict(k_n=k_n, z=a["z"], phi=a["phi"], overlap=a["overlap_median"])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tiny", action="store_true", help="a 150-sphere pile (seconds), as CI runs it")
    ap.add_argument("--mu", type=float, default=0.0, help="friction coefficient (default 0: frictionless)")
    ap.add_argument("--out", default="runs/examples/stiffen", help="output directory")
    args = ap.parse_args()
    size = TINY if args.tiny else FULL

    # 1. the soft pile
    cfg = mpdem.load_config(**size["pour"], **{"contact.mu": args.mu})
    r = mpdem.run(cfg, os.path.join(args.out, f"kn{cfg.contact.k_n:g}"), force=True)
    rows = [describe(r)]

    # 2. the ladder: each rung from the previous rung's final state; keys by name over the run's own
    for k_n in size["ladder"]:
        cfg = mpdem.stiffen_config(r.out, k_n, **size["rung"])
        r = mpdem.run(cfg, os.path.join(args.out, f"kn{k_n:g}"), force=True)
        rows.append(describe(r))

    k = [row["k_n"] for row in rows]
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(9, 3.5))
    ax.plot(k, [row["z"] for row in rows], "o-")
    ax.axhline(6.0 if args.mu == 0 else 4.0, ls=":", c="k", label="isostatic")
    ax.set(xscale="log", xlabel="k_n [m g / d]", ylabel="z", title=f"z against k_n (mu = {args.mu:g})")
    ax.legend()
    bx.loglog(k, [row["overlap"] for row in rows], "s-", label="median overlap")
    bx.loglog(k, [rows[0]["overlap"] * k[0] / kk for kk in k], ":", c="k", label="1 / k_n")
    bx.set(xlabel="k_n [m g / d]", ylabel="overlap [d]")
    bx.legend()
    fig.tight_layout()
    png = os.path.join(args.out, "z_of_kn.png")
    fig.savefig(png, dpi=100)
    print(f"wrote {png}")


if __name__ == "__main__":
    main()
