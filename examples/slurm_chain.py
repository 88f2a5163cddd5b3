"""A long run as a chain of jobs: each stops before its time limit with a checkpoint, the next restarts.

What it does
    A cluster job has a time limit; a pile that needs longer runs as a chain of jobs
    (``jobs/slurm/chain.sbatch``, jobs/README.md): each job runs ``mpdem run --walltime T`` (the
    first) or ``mpdem restart RUN --walltime T`` (the others) with T the time the job has left less
    a margin; mpdem writes a checkpoint and exits 75 before T, and the job submits itself again.
    Exit 0 (at rest) or 3 (at ``run.max_steps``) ends the chain. A restart continues exactly, so the
    chain's final state is the straight run's, bit for bit.

    ``--tiny`` (no Slurm needed) makes the chain by hand in this process, through the functions the
    command line calls: segments of ``mpdem.run(..., walltime=1.0)`` then ``mpdem.restart(RUN,
    walltime=1.0)`` (``mpdem run``/``mpdem restart RUN --walltime 1``) until the status is not
    "interrupted" (exit 75), then the same config run straight through, and compares the digests.
    Without ``--tiny`` it submits the real chain with ``sbatch`` (where there is no ``sbatch`` it
    says ``skipped: no Slurm`` and exits 0).

What it prints
    ``--tiny``: one line a segment (``segment 2: restart, checkpoint at step 61234 (exit 75)``), the chain's and
    the straight run's digests and ``digests equal: True``; last ``wrote OUT/chain.png`` (the
    kinetic energy over the chain, segments marked). Full: the ``sbatch`` command and its job id,
    and where to follow the chain (``RUN/jobs.log``).

Cost
    Full size: a paper-size pour (20 000 spheres in 20 d x 20 d, mu = 0.5) to rest: some 2.4
    core-hours (README.md), submitted as 30-minute jobs on 8 tasks: a few jobs.
    ``--tiny``: 150 spheres, 100 000 steps in segments of 1 s, then straight: 15-25 s.

Run
    python examples/slurm_chain.py --tiny [--out runs/examples/chain]
    python examples/slurm_chain.py [--ntasks 8] [--time 00:30:00]     # on a Slurm login node
"""
import argparse
import csv
import os
import shutil
import subprocess
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt           # noqa: E402

import mpdem                              # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
CHAIN = os.path.normpath(os.path.join(HERE, "..", "jobs", "slurm", "chain.sbatch"))
FULL = ["pour.N=20000", "box.L_x=20.0", "box.L_y=20.0", "run.max_steps=20000000"]
# not at rest by 100 000 steps (E_stop at its default): the chain ends at run.max_steps, exit 3
TINY = {"pour.N": 150, "box.L_x": 4.0, "box.L_y": 4.0, "pour.phi_i": 0.3, "contact.k_n": 2e4,
        "run.max_steps": 100_000}


def by_hand(out):
    """The chain of segments as the jobs of chain.sbatch run them, each stopped by its wall time;
    returns (the last RunRecord, the step of each stop)."""
    run_dir = os.path.join(out, "chain")
    walltime, stops = 1.0, []
    # the first job: `mpdem run --walltime T`; the next ones: `mpdem restart RUN --walltime T`
    r = mpdem.run(mpdem.load_config(**TINY), run_dir, force=True, walltime=walltime)
    while True:
        what = "run" if not stops else "restart"
        if r.status != "interrupted":
            print(f"segment {len(stops) + 1}: {what}, {r.status} at step {r.steps} (exit {r.exit_status})")
            return r, stops
        print(f"segment {len(stops) + 1}: {what}, checkpoint at step {r.steps} (exit {r.exit_status})", flush=True)
        if stops and r.steps <= stops[-1]:
            walltime *= 2           # a loaded machine: nothing done in the segment; give the next more
        else:
            stops.append(r.steps)
        if len(stops) > 40:
            sys.exit("40 segments and not finished")
        r = mpdem.restart(run_dir, walltime=walltime)


def submit(args):
    """The real chain: ``sbatch jobs/slurm/chain.sbatch`` with the run's directory and keys."""
    if shutil.which("sbatch") is None:
        print("skipped: no Slurm here (sbatch is not on the PATH); `--tiny` makes the chain by hand")
        return
    env = dict(os.environ, MPDEM_RUN_DIR=os.path.join(args.out, "chain"), MPDEM_SET=" ".join(FULL))
    cmd = ["sbatch", f"--ntasks={args.ntasks}", f"--time={args.time}", "--parsable", CHAIN]
    print("$ MPDEM_RUN_DIR=... MPDEM_SET=... " + " ".join(cmd))
    p = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"sbatch refused the job (exit {p.returncode}): {p.stderr.strip()}")
    job = p.stdout.strip()
    print(f"submitted job {job}; follow the chain in {os.path.join(args.out, 'chain', 'jobs.log')}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tiny", action="store_true", help="the chain by hand, without Slurm (seconds), as CI runs it")
    ap.add_argument("--ntasks", type=int, default=8, help="MPI ranks a job (full size)")
    ap.add_argument("--time", default="00:30:00", help="a job's time limit (full size)")
    ap.add_argument("--out", default="runs/examples/chain", help="output directory")
    args = ap.parse_args()
    if not args.tiny:
        submit(args)
        return

    chain, stops = by_hand(args.out)
    straight = mpdem.run(mpdem.load_config(**TINY), os.path.join(args.out, "straight"), force=True)
    print(f"chain: {len(stops) + 1} segments, {chain.steps} steps, digest {chain.digest}")
    print(f"straight: {straight.steps} steps, digest {straight.digest}")
    equal = chain.digest == straight.digest
    print(f"digests equal: {equal}")

    with open(os.path.join(chain.out, "thermo.csv"), newline="") as fh:
        rows = list(csv.DictReader(fh))
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.semilogy([int(r["step"]) for r in rows], [float(r["ek"]) for r in rows])
    for k, s in enumerate(stops):
        ax.axvline(s, ls=":", c="k", label="checkpoint, exit 75" if k == 0 else None)
    ax.set(xlabel="step", ylabel="E_k / N [m g d]", title=f"one run in {len(stops) + 1} segments")
    if stops:
        ax.legend()
    fig.tight_layout()
    png = os.path.join(args.out, "chain.png")
    fig.savefig(png, dpi=100)
    print(f"wrote {png}")
    if not equal:
        sys.exit("the chain's final state is not the straight run's")


if __name__ == "__main__":
    main()
