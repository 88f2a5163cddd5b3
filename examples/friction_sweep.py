"""A friction sweep with ``mpdem sweep`` and ``mpdem collect``: z against mu (the paper's Fig. 2).

What it does
    Writes a sweep table (one run a line: ``mu`` and ``seed`` columns; any ``section.key`` may be a
    column), runs it with ``mpdem sweep`` (rows side by side, each in its own run directory, each
    analysed when it ends; interrupted, the same command goes on where it stopped), and pools the
    runs with ``mpdem collect``: seeds of one parameter set averaged, the paper's tables and figures
    (``fig2_z_vs_mu.png`` among them). Then draws z(mu) and phi(mu) from ``sets.csv``. The same two
    commands by hand::

        python -m mpdem sweep table.tsv --out runs/sweep --set pour.N=2000 --collect results
        python -m mpdem collect runs/sweep --out results

What it prints
    The sweep's progress, then one line a value of mu: ``mu = 0.5: z = 5.04 +- 0.03, phi = 0.603``
    (the error: the standard error over the seeds, none for one seed); last ``wrote OUT/z_of_mu.png``.

Cost
    Full size (default): mu = 0, 0.1, 0.2, 0.5, 1 with seeds 1-3 at the development size (2000
    spheres, 10 d x 10 d, k_n = 2e5): 15 rows of 3-8 minutes each on one core (the measured rows of
    analysis/results/dev), some 1.5 core-hours: 40-50 minutes on two cores.
    ``--tiny``: mu = 0, 0.3, 1, one seed, 150 spheres at k_n = 2e4 with E_stop = 1e-5: 30-60 s
    (mostly the start of six processes: each row's run and its analysis).

Run
    python examples/friction_sweep.py [--tiny] [--jobs J] [--out runs/examples/sweep]
"""
import argparse
import csv
import os
import subprocess
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt           # noqa: E402

FULL = dict(mus=[0.0, 0.1, 0.2, 0.5, 1.0], seeds=[1, 2, 3],
            sets=["pour.N=2000", "box.L_x=10.0", "box.L_y=10.0", "run.max_steps=10000000"])
TINY = dict(mus=[0.0, 0.3, 1.0], seeds=[1],
            sets=["pour.N=150", "box.L_x=4.0", "box.L_y=4.0", "pour.phi_i=0.3", "contact.k_n=2e4",
                  "stop.E_stop=1e-5", "run.max_steps=400000"])


def mpdem(*args):
    """``python -m mpdem ARGS`` with this python; stops the example if the command fails."""
    cmd = [sys.executable, "-m", "mpdem", *map(str, args)]
    print("$ mpdem " + " ".join(map(str, args)), flush=True)
    subprocess.run(cmd, check=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tiny", action="store_true", help="three 150-sphere rows (seconds each), as CI runs it")
    ap.add_argument("--jobs", type=int, default=None, help="rows at a time (default: the cores)")
    ap.add_argument("--out", default="runs/examples/sweep", help="output directory")
    args = ap.parse_args()
    size = TINY if args.tiny else FULL
    os.makedirs(args.out, exist_ok=True)

    # 1. the table: a header, then one run a line (docs/analysis.md, jobs/README.md)
    table = os.path.join(args.out, "mu.tsv")
    with open(table, "w") as fh:
        fh.write("mu\tseed\n")
        for mu in size["mus"]:
            for seed in size["seeds"]:
                fh.write(f"{mu}\t{seed}\n")

    # 2. the sweep: each row a run directory under OUT/runs (named from its row, e.g. mu0.3_s1), then
    #    collect into OUT/collect. --set applies to every row, under the row's own values.
    sets = [a for kv in size["sets"] for a in ("--set", kv)]
    jobs = ["--jobs", args.jobs] if args.jobs else []
    mpdem("sweep", table, "--out", os.path.join(args.out, "runs"), *sets, *jobs,
          "--collect", os.path.join(args.out, "collect"))

    # 3. the pooled table: one row a parameter set (here a value of mu), means over the seeds
    with open(os.path.join(args.out, "collect", "sets.csv"), newline="") as fh:
        rows = sorted(csv.DictReader(fh), key=lambda r: float(r["mu"]))
    mu = [float(r["mu"]) for r in rows]
    z = [float(r["z_mean"]) for r in rows]
    z_err = [float(r["z_sem"]) if r["z_sem"] else 0.0 for r in rows]
    phi = [float(r["phi_mean"]) for r in rows]
    for m, zz, e, p, r in zip(mu, z, z_err, phi, rows):
        err = f" +- {e:.2f}" if r["z_sem"] else ""
        print(f"mu = {m:g}: z = {zz:.3f}{err}, phi = {p:.4f}  ({r['n_seeds']} seed(s))")

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(9, 3.5))
    ax.errorbar(mu, z, yerr=z_err, fmt="o-", capsize=3)
    ax.set_xscale("symlog", linthresh=0.1)          # linear near mu = 0, logarithmic from 0.1
    ax.set(xlabel="mu", ylabel="z", title="coordination number (Fig. 2)")
    bx.plot(mu, phi, "s-")
    bx.set_xscale("symlog", linthresh=0.1)
    bx.set(xlabel="mu", ylabel="phi", title="packing fraction (Fig. 3)")
    fig.tight_layout()
    png = os.path.join(args.out, "z_of_mu.png")
    fig.savefig(png, dpi=100)
    print(f"collect's own figures: {os.path.join(args.out, 'collect', 'fig2_z_vs_mu.png')} and others")
    print(f"wrote {png}")


if __name__ == "__main__":
    main()
