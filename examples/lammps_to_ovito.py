"""From a LAMMPS data file to OVITO and ParaView: a pile LAMMPS wrote, run on in mpdem, exported.

What it does
    Starts a run from a LAMMPS data file (``run.initial_file``; ``atom_style sphere``, diameter 1,
    mass 1; ``run.fixed_types`` names the bed's atom types, which mpdem freezes; the box comes from
    the file), runs it on, and exports the final state for the viewers with ``mpdem export``:
    a LAMMPS dump (OVITO), extended XYZ (OVITO, ASE, VMD), the contact network as HDF5 + XDMF
    (ParaView) and as a LAMMPS ``dump local`` (OVITO's bonds), and a LAMMPS data file that LAMMPS's
    ``read_data`` (or mpdem again) reads. ``final.xmf`` beside ``final.h5`` opens in ParaView as is.

What it prints
    The particles read (mobile and bed), the run's status, one ``wrote ...`` line a file exported
    and how to open it; the dump read back: ``read back: N particles ..., same positions``; last
    ``wrote OUT/side_view.png``.

Cost
    Full size: your own file, ``--data FILE --fixed-types 2 [--steps N]``: as long as its run.
    Default: ``tests/data/lammps_sphere.data`` (369 spheres written by LAMMPS: the bottom of
    ``make run``'s pile, 106 of them bed), run until the stop rule holds: 73 000 steps, some 20 s
    (at most 2 million steps).
    ``--tiny``: the same file, 2000 steps: 10-20 s (five exports, a process each).

Run
    python examples/lammps_to_ovito.py [--tiny] [--data FILE --fixed-types 2] [--out runs/examples/lammps]
"""
import argparse
import os
import subprocess
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt           # noqa: E402
import numpy as np                        # noqa: E402

import mpdem                              # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.normpath(os.path.join(HERE, "..", "tests", "data", "lammps_sphere.data"))

# format -> what opens it (docs/running.md, "For viewing")
EXPORTS = {
    "lammps-dump": "OVITO (File > Load File), LAMMPS rerun",
    "xyz": "OVITO, ASE, VMD",
    "contacts": "ParaView, beside final.xmf (colour by F_n, Tube filter)",
    "lammps-local": "OVITO: Load trajectory modifier on the dump, contacts as bonds",
    "lammps-data": "LAMMPS read_data; mpdem run.initial_file with run.fixed_types = [2]",
}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tiny", action="store_true", help="2000 steps (seconds), as CI runs it")
    ap.add_argument("--data", default=DATA, help="a LAMMPS data file (atom_style sphere) or text dump")
    ap.add_argument("--fixed-types", default="2", help="atom types of the bed, comma-separated (default 2)")
    ap.add_argument("--steps", type=int, default=2_000_000, help="run.max_steps (default 2e6; --tiny 2000)")
    ap.add_argument("--out", default="runs/examples/lammps", help="output directory")
    args = ap.parse_args()
    types = [int(t) for t in args.fixed_types.split(",")]
    steps = 2000 if args.tiny else args.steps

    # 1. the run from the LAMMPS file: the model is mpdem's config (here the built-in example's, mu = 0.5)
    cfg = mpdem.load_config(**{"run.initial_file": os.path.abspath(args.data), "run.fixed_types": types,
                               "run.max_steps": steps})
    r = mpdem.run(cfg, os.path.join(args.out, "run"), force=True)
    s = mpdem.read_state(r.final)
    bed = int(s["fixed"].sum())
    print(f"read {args.data}: {len(s['id']) - bed} mobile and {bed} bed spheres, box {s['L_x']:g} d x {s['L_y']:g} d")
    print(f"run: {r.status} after {r.steps} steps; ParaView opens {os.path.join(r.out, 'final.xmf')} as is")

    # 2. the exports: `mpdem export FILE --format F [--out PATH]`, the command a user types
    for fmt, what in EXPORTS.items():
        p = subprocess.run([sys.executable, "-m", "mpdem", "export", r.final, "--format", fmt],
                           capture_output=True, text=True, check=True)
        wrote = p.stdout.split("\n")[0].removeprefix("wrote ").strip()
        print(f"wrote {wrote}  ({fmt}: {what})")
        if fmt == "lammps-dump":
            dump = wrote

    # 3. what OVITO will read: the dump's columns (ITEM: ATOMS id type x y z ...), against the state
    with open(dump) as fh:
        lines = fh.read().splitlines()
    head = lines.index(next(ln for ln in lines if ln.startswith("ITEM: ATOMS")))
    cols = lines[head].split()[2:]
    table = np.loadtxt(lines[head + 1:], ndmin=2)
    order = np.argsort(table[:, cols.index("id")])
    xyz = table[order][:, [cols.index(c) for c in ("x", "y", "z")]]
    same = len(xyz) == len(s["x"]) and np.allclose(xyz, s["x"], rtol=0, atol=1e-12)
    print(f"read back: {len(xyz)} particles in {os.path.basename(dump)}, {'same' if same else 'DIFFERENT'} positions")

    fig, ax = plt.subplots(figsize=(7, 3.5))
    mobile = s["fixed"] == 0
    ax.scatter(s["x"][mobile, 0], s["x"][mobile, 2], s=14, c=s["x"][mobile, 1], cmap="viridis")
    ax.scatter(s["x"][~mobile, 0], s["x"][~mobile, 2], s=14, c="0.6")
    ax.set(xlabel="x [d]", ylabel="height [d]", aspect="equal", title="side view (colour: y; grey: bed)")
    fig.tight_layout()
    png = os.path.join(args.out, "side_view.png")
    fig.savefig(png, dpi=100)
    print(f"wrote {png}")
    if not same:
        sys.exit("the exported dump did not read back to the state's particles")


if __name__ == "__main__":
    main()
