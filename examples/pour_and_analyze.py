"""A pour and its analysis, from Python.

What it does
    Makes the rough bed, pours spheres onto it under gravity, steps them until the stop rule says the
    pile is at rest (``mpdem.run``), then measures the packing (``mpdem.analyze``): the bulk's
    coordination number z and packing fraction phi, the contact-number distribution P(n), z and phi
    per depth band below the free surface. Reads the final state back (``mpdem.read_state``) for a
    side view of the pile coloured by each sphere's contacts.

What it prints
    The run's status, steps and digest, then ``z = ...``, ``phi = ...``, the backbone's z and its
    rattler fraction, and P(n); last, ``wrote OUT/pour.png``.

Cost
    Full size (default): the development size of docs/model.md 7.1, 2000 spheres in a 10 d x 10 d
    box at the paper's k_n = 2e5, mu = 0.5: some 400 000 steps, 3-4 minutes on one core.
    ``--tiny``: 150 spheres in 4 d x 4 d at k_n = 2e4 with a looser stop rule (E_stop = 1e-5):
    some 60 000 steps, about 10 s with numba's cache warm (the first run of a fresh clone compiles
    the kernels first, a minute or two).

Run
    python examples/pour_and_analyze.py [--tiny] [--mu 0.5] [--out runs/examples/pour]
    mpiexec -n 2 python examples/pour_and_analyze.py     # the same pile (same digest) on two ranks;
                                                         # rank 0 alone analyses and plots it
"""
import argparse
import os

import matplotlib
matplotlib.use("Agg")                     # files only: no display needed
import matplotlib.pyplot as plt           # noqa: E402
import numpy as np                        # noqa: E402

import mpdem                              # noqa: E402

# the two sizes: keys as `--set` takes them, by name (docs/config.md); reduced units d = m = g = 1
FULL = {"pour.N": 2000, "box.L_x": 10.0, "box.L_y": 10.0, "run.max_steps": 10_000_000}
TINY = {"pour.N": 150, "box.L_x": 4.0, "box.L_y": 4.0, "pour.phi_i": 0.3, "contact.k_n": 2e4,
        "stop.E_stop": 1e-5, "run.max_steps": 400_000}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tiny", action="store_true", help="a 150-sphere pile (seconds), as CI runs it")
    ap.add_argument("--mu", type=float, default=0.5, help="friction coefficient (default 0.5)")
    ap.add_argument("--out", default="runs/examples/pour", help="output directory")
    args = ap.parse_args()

    # under mpiexec every rank runs this script: the run is collective, the analysis rank 0's
    from mpi4py import MPI
    rank = MPI.COMM_WORLD.rank

    # 1. the config: the built-in example's physics with this size's keys over it
    cfg = mpdem.load_config(**(TINY if args.tiny else FULL), **{"contact.mu": args.mu})
    if rank == 0:
        print(f"pouring {cfg.pour.N} spheres in {cfg.box.L_x:g} d x {cfg.box.L_y:g} d, mu = {cfg.contact.mu:g}, "
              f"k_n = {cfg.contact.k_n:g}")

    # 2. the run: bed, pour, settle; everything it writes goes into OUT/pile
    r = mpdem.run(cfg, out=os.path.join(args.out, "pile"), force=True)
    if rank != 0:
        return
    print(f"run: {r.status} after {r.steps} steps, digest {r.digest[:16]}")
    if r.status != "converged":
        print("  (not at rest yet: `mpdem.restart(r.out, **{'run.max_steps': ...})` goes on)")

    # 3. the measurements of `mpdem analyze`, as a dict (docs/analysis.md)
    a = mpdem.analyze(r.final)
    print(f"z = {a['z']:.3f}  ({a['n_bulk']} spheres in the bulk, heights {a['z1']:.2f} to {a['z2']:.2f} d)")
    print(f"phi = {a['phi']:.4f}")
    print(f"backbone z = {a['backbone']['z']:.3f}, rattler fraction {a['backbone']['rattler_fraction']:.3f}")
    n, P = a["arrays"]["P_z"]
    print("P(n): " + ", ".join(f"{k}: {p:.2f}" for k, p in zip(n, P) if p > 0))

    # 4. the state itself: positions [d] and the contact list, sorted by id
    s = mpdem.read_state(r.final)
    contacts = np.bincount(np.searchsorted(s["id"], np.concatenate([s["id_i"], s["id_j"]])),
                           minlength=len(s["id"]))

    fig, (ax, bx, cx) = plt.subplots(1, 3, figsize=(12, 4))
    ax.bar(n, P)
    ax.set(xlabel="contacts n", ylabel="P(n)", title=f"bulk: z = {a['z']:.2f}")
    b = a["arrays"]["bands"]
    depth = 0.5 * (np.asarray(b["depth_lo"]) + np.asarray(b["depth_hi"]))
    bx.plot(depth, b["z"], "o-", label="z")
    bx.set(xlabel="depth below the surface [d]", ylabel="z", title="depth profile")
    mobile = s["fixed"] == 0
    sc = cx.scatter(s["x"][mobile, 0], s["x"][mobile, 2], c=contacts[mobile], s=18, cmap="viridis")
    cx.scatter(s["x"][~mobile, 0], s["x"][~mobile, 2], c="0.6", s=18)
    cx.set(xlabel="x [d]", ylabel="height [d]", title="side view (grey: bed)", aspect="equal")
    fig.colorbar(sc, ax=cx, label="contacts")
    fig.tight_layout()
    png = os.path.join(args.out, "pour.png")
    fig.savefig(png, dpi=100)
    print(f"wrote {png}")


if __name__ == "__main__":
    main()
