"""The same run on a GPU and on the CPU: the same bits (equal digests).

What it does
    Runs one pour twice, ``engine.device = "gpu"`` (numba-cuda, one NVIDIA GPU) and ``"cpu"``
    (numba threads), and compares the SHA-256 digests of the two final states: the GPU engine's
    float arithmetic is rounded as the CPU's and its sums are exact, so the two are bit-identical
    (docs/gpu.md). A run may therefore change device at any restart
    (``mpdem restart RUN --device gpu``). Without a usable GPU (no GPU, or no numba-cuda:
    ``pip install '.[gpu]'``) it says ``skipped: no GPU`` and why, and exits 0.
    ``--simulator`` runs the GPU engine under numba's CUDA simulator instead (no GPU needed: the
    kernels' logic in Python threads, very slow, so only with ``--tiny``): that is how CI checks the
    digests on machines without a GPU.

What it prints
    The device, each run's status, steps and wall time, both digests, ``digests equal: True`` and the
    contacts of the final state (the tiny run's spheres are thrown at 5 m g d each to collide);
    last ``wrote OUT/gpu_vs_cpu.png`` (the two final piles side by side).

Cost
    Full size (default): the built-in example (1500 spheres in 10 d x 10 d, mu = 0.5) to rest, some
    435 000 steps: about 2.5 minutes on one CPU core (README.md: 73 s on two ranks); on an H100 the
    kernels' compilation (10-30 s in each process, docs/gpu.md) and some 45 us a step
    (docs/performance.md): under a minute (an estimate from those figures: the example itself has not
    been timed on a GPU yet).
    ``--tiny --simulator``: 30 spheres, 40 steps: about 15 s. ``--tiny`` on a GPU: seconds after the
    compilation.

Run
    python examples/gpu_vs_cpu.py [--tiny] [--simulator] [--out runs/examples/gpu]
"""
import argparse
import os
import sys
import time

# the simulator is chosen before numba is first imported (mpdem imports it on first use)
if "--simulator" in sys.argv:
    os.environ["NUMBA_ENABLE_CUDASIM"] = "1"

import matplotlib                         # noqa: E402
matplotlib.use("Agg")
import matplotlib.pyplot as plt           # noqa: E402

import mpdem                              # noqa: E402
from mpdem.errors import DeviceError      # noqa: E402

FULL = {"run.max_steps": 1_000_000}       # the built-in example: 1500 spheres, 10 d x 10 d, mu = 0.5
TINY = {"pour.N": 30, "box.L_x": 4.0, "box.L_y": 4.0, "pour.phi_i": 0.3, "pour.K0": 5.0, "contact.k_n": 2e3,
        "run.max_steps": 40}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tiny", action="store_true", help="30 spheres, 40 steps, as CI runs it")
    ap.add_argument("--simulator", action="store_true",
                    help="the GPU engine under numba's CUDA simulator (no GPU needed; with --tiny only)")
    ap.add_argument("--out", default="runs/examples/gpu", help="output directory")
    args = ap.parse_args()
    if args.simulator and not args.tiny:
        ap.error("--simulator runs some hundred steps a minute: use it with --tiny")
    size = TINY if args.tiny else FULL
    # under the simulator each GPU thread is a Python thread: the smallest block the engine takes
    gpu_keys = {"engine.device": "gpu", **({"engine.gpu_block": 32} if args.simulator else {})}

    # 1. the GPU run first: without a usable GPU it stops here, before any work, with one line
    t = time.monotonic()
    try:
        gpu = mpdem.run(mpdem.load_config(**size, **gpu_keys), os.path.join(args.out, "gpu"), force=True)
    except DeviceError as e:
        print(f"skipped: no GPU ({e})")
        return
    t_gpu = time.monotonic() - t
    where = "numba's CUDA simulator" if args.simulator else "the GPU"
    note = "" if args.simulator else " (the kernels' compilation included)"
    print(f"gpu ({where}): {gpu.status} after {gpu.steps} steps, {t_gpu:.1f} s{note}")

    # 2. the same config on the CPU
    t = time.monotonic()
    cpu = mpdem.run(mpdem.load_config(**size), os.path.join(args.out, "cpu"), force=True)
    print(f"cpu: {cpu.status} after {cpu.steps} steps, {time.monotonic() - t:.1f} s")

    # 3. the digests: SHA-256 of each final state sorted by id (positions, velocities, contact histories)
    print(f"gpu digest {gpu.digest}")
    print(f"cpu digest {cpu.digest}")
    equal = gpu.digest == cpu.digest
    print(f"digests equal: {equal}")
    print(f"contacts in the final state: {len(mpdem.read_state(cpu.final)['id_i'])} (their histories in the digest)")

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.5), sharey=True)
    for ax, r, name in zip(axes, (gpu, cpu), ("GPU", "CPU")):
        s = mpdem.read_state(r.final)
        ax.scatter(s["x"][:, 0], s["x"][:, 2], s=12, c=s["fixed"], cmap="coolwarm")
        ax.set(xlabel="x [d]", title=f"{name}: {r.digest[:12]}", aspect="equal")
    axes[0].set_ylabel("height [d]")
    fig.tight_layout()
    png = os.path.join(args.out, "gpu_vs_cpu.png")
    fig.savefig(png, dpi=100)
    print(f"wrote {png}")
    if not equal:
        sys.exit("the GPU and the CPU gave different states")


if __name__ == "__main__":
    main()
