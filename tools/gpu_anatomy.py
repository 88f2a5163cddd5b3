"""Where a fused GPU step's time goes (docs/performance.md, "GPU"): the bench's pile stepped in launches of
``kernels.gpu.step.advance`` (the one kernel for every option, its list rebuilds by the host: the engine's
switches before 2026-11-28's defaults, set here explicitly), timed three ways on the same grid.

    python tools/gpu_anatomy.py TABLE [STEPS] [BLOCK] [THREADS]    (e.g. .devdata/landed20k.txt.gz 1000 128 row)

THREADS is ``engine.gpu_threads``: ``row`` (a thread a row) or ``entry`` (a thread an entry, then a row's sum).

1. the steps as a run takes them (``Engine.run_quiet``: launches ended by list rebuilds, which the host does);
2. one launch of STEPS steps that never stops for a rebuild (half the skin infinite: the lists go stale, the
   rows drift on; timing only), so the fused steps alone;
3. one launch of STEPS steps over no rows on the same grid: the grid barriers, the block reductions, the
   per-step record and the launch, with no row's work.

Prints microseconds a step of each; (2) - (3) is the rows' work. Nothing here is a test of results.
"""
import sys
import time

import numpy as np

from mpdem.bench import load_table, set_up_process, table_config, warm_up_kernels
from mpdem.decomp import Domain
from mpdem.engine import make_engine
from mpdem.engine.base import Physics
from mpdem.kernels.bundles import make_box


def main(path, steps=1000, block=128, threads="row"):
    set_up_process()
    cfg = table_config([f"engine.gpu_block={block}", f"engine.gpu_threads={threads}"])
    phys = Physics.from_config(cfg)
    # the one `advance` kernel with its rebuilds by the host, whatever the defaults: the launches below are its
    old = dict(gpu_reductions="tree", gpu_samples="host", gpu_drift="apart", gpu_pinned=False, gpu_rebuild="host")
    warm_up_kernels(phys, cfg.box.L_x, cfg.box.L_y, "gpu", gpu_block=block, gpu_threads=threads, **old)
    whole, L_x, L_y = load_table(path, cfg)
    dom = Domain.from_config(None, cfg)
    st = dom.scatter(whole, L_x, L_y)
    eng = make_engine(st, phys, dom, "gpu", block, threads, **old)
    eng.start()
    eng.advance(50)
    cuda = eng.cuda
    print(f"gpu_anatomy: {st.n_own} rows, {eng._k} entries, block {block}, a thread a {threads}, on {eng.device_name}")

    cuda.synchronize()
    t = time.perf_counter()
    r0 = eng.n_rebuilds
    eng.run_quiet(steps)
    eng.complete()
    cuda.synchronize()
    wall = time.perf_counter() - t
    print(f"gpu_anatomy: run_quiet({steps}): {1e6 * wall / steps:.2f} us a step ({eng.n_rebuilds - r0} rebuilds)")

    d, k = eng._dev, eng.k
    planes_d, kinds_d = eng._device_planes()

    def launch(rows, half_skin):
        args = (rows, d["x"], d["v"], d["omega"], d["f"], d["torque"], d["fixed"], d["x_ref"], d["start"], d["nbr"],
                d["hist"], d["stamp"], d["pair"], d["wall_ds"], planes_d, kinds_d, eng._epoch,
                *make_box(st.L_x, st.L_y), eng.law, True, half_skin, steps, eng._rec, eng.by_entry,
                eng._k if rows else 0, d.get("row", d["nbr"]), eng.fused, *eng._second_rows(),
                eng.one_barrier)
        name = eng._advance_name()
        grid = eng._cooperative_grid(name, (st.n_own,) + args[1:])
        kernel = eng._launcher(name, args)
        kernel[grid](*args)         # warm (and the grid's first use)
        cuda.synchronize()
        t0 = time.perf_counter()
        kernel[grid](*args)
        cuda.synchronize()
        return time.perf_counter() - t0, grid

    if len(eng._rec) < steps:
        eng._rec = cuda.device_array((steps, len(k.NEUTRAL)))
    full, grid = launch(st.n_own, np.inf)
    empty, _ = launch(0, np.inf)
    print(f"gpu_anatomy: grid {grid[0]} x {grid[1]}; one launch of {steps} steps: "
          f"{1e6 * full / steps:.2f} us a step with the rows, {1e6 * empty / steps:.2f} us with none "
          f"(barriers, reductions, record); the rows' work {1e6 * (full - empty) / steps:.2f} us")


if __name__ == "__main__":
    a = sys.argv[1:]
    main(a[0], *(int(v) for v in a[1:3]), *a[3:4])
