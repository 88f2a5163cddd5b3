"""The scaling table of the CPU engine on one node, in one call: strong, weak and wide, against the node's ceiling.

    python tools/scaling.py TABLE OUT [--ranks 1,2,4,8,16] [--steps 1000] [--wide 7x7]

TABLE is a landed pile (e.g. landed20k.txt.gz: 20 000 spheres on 20 d x 20 d). Every figure is a
``python -m mpdem bench --table`` run (its last line ``ns_per_atom_step``), one rank a core:

- ceiling R: R single-rank benches of one tile, all at once: what the node's cores and memory allow
  when R of them work (the mean of their ns per atom-step);
- strong R: the one tile on R ranks, the grid chosen (``decomp.grid = []``) and all slabs, and the chosen grid
  again with ``--bind none`` (the ranks as the launcher left them: MPICH's mpiexec binds nothing);
- weak R: R tiles (the most nearly square A x B = R) on R ranks, the grid chosen;
- wide: the WIDE tiles (7 x 7: 994k spheres) on the largest R, the grid chosen and all slabs.

Efficiencies: strong and weak against one rank alone (ns_1 / (R ns_R) for strong; ns_1 / ns_R per atom for weak:
a weak run of R tiles at R ranks should take the wall time of one tile at one rank), and against the ceiling of
R (the same with ns_1 replaced by the ceiling's ns), which takes out what the node itself loses when all its
cores work. Each parallel row also gives the grid, ghosts per owned row and the refresh's bytes a step.

Writes OUT/scaling.json (every row) and OUT/scaling.txt (the table, printed last). A row that fails or
passes its time limit is recorded as failed, and the table goes on.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import subprocess
import sys
import time

NS = re.compile(r"^ns_per_atom_step=([0-9.eE+-]+)$", re.M)
HALO = re.compile(r"^bench: grid ([0-9 x]+), ([0-9.]+) ghosts per owned row, the refresh sends ([0-9.]+) MB", re.M)


def tiles_of(R):
    """The most nearly square A x B = R."""
    a = max(k for k in range(1, int(math.isqrt(R)) + 1) if R % k == 0)
    return (R // a, a)


def bench_cmd(py, table, steps, tile, grid=None, extra=()):
    cmd = [py, "-m", "mpdem", "bench", "--table", table, "--steps", str(steps), "--tile", f"{tile[0]}x{tile[1]}",
           *extra]
    if grid:
        cmd += ["--set", f"decomp.grid={list(grid)}"]
    return cmd


def mpi_cmd(mpiexec, R, cmd):
    return cmd if R == 1 else [*mpiexec, "-n", str(R), *cmd]


def parse(text):
    """ns per atom-step and the halo figures of a bench's output (None where absent)."""
    ns = NS.findall(text)
    halo = HALO.search(text)
    row = {"ns": float(ns[-1]) if ns else None}
    if halo:
        row.update(grid=halo.group(1).strip(), ghosts_per_owned=float(halo.group(2)), refresh_mb=float(halo.group(3)))
    return row


def run_one(cmd, timeout, log):
    t = time.time()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        text, rc = p.stdout + p.stderr, p.returncode
    except subprocess.TimeoutExpired as e:
        text, rc = "".join(o.decode(errors="replace") if isinstance(o, bytes) else o
                           for o in (e.stdout, e.stderr) if o), "timeout"
    log.write(f"$ {' '.join(cmd)}\n{text}\n(rc {rc}, {time.time() - t:.1f} s)\n")
    log.flush()
    row = parse(text)
    row.update(rc=rc, seconds=round(time.time() - t, 1))
    return row


def run_many(cmds, timeout, log):
    """Commands started together (the ceiling); each one's row."""
    t = time.time()
    procs = [subprocess.Popen(c, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) for c in cmds]
    rows = []
    for c, p in zip(cmds, procs):
        try:
            text, _ = p.communicate(timeout=max(timeout - (time.time() - t), 1))
            rc = p.returncode
        except subprocess.TimeoutExpired:
            p.kill()
            text, rc = p.communicate()[0], "timeout"
        log.write(f"$ {' '.join(c)}\n{text}\n(rc {rc})\n")
        row = parse(text)
        row["rc"] = rc
        rows.append(row)
    log.flush()
    return rows


def efficiency(ns_ref, ns, R):
    """ns_ref / (R ns): 1 when R ranks do R times the atom-steps of ``ns_ref``'s one core in its wall time
    (strong: the same atoms in 1/R of the time; weak and wide: R times the atoms in the same time)."""
    return ns_ref / (R * ns) if ns_ref and ns else None


def table(rows):
    lines = [f"{'row':<8} {'R':>3} {'case':<10} {'grid':<11} {'ns/atom-step':>12} {'eff vs 1':>8} {'eff vs ceil':>11} "
             f"{'ghosts/own':>10} {'refresh MB':>10}"]
    for r in rows:
        def f(k, fmt):
            return format(r[k], fmt) if r.get(k) is not None else "-"
        grid = r.get("grid") or "1 x 1 x 1"
        lines.append(f"{r['kind']:<8} {r['R']:>3} {r.get('label', ''):<10} {grid:<11} {f('ns', '12.4g')} "
                     f"{f('eff_one', '8.2f')} {f('eff_ceiling', '11.2f')} {f('ghosts_per_owned', '10.3f')} "
                     f"{f('refresh_mb', '10.3f')}" + ("" if r.get("rc") == 0 else f"  failed ({r.get('rc')})"))
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("table")
    ap.add_argument("out")
    ap.add_argument("--ranks", default="1,2,4,8,16", help="rank counts, comma-separated (default 1,2,4,8,16)")
    ap.add_argument("--steps", type=int, default=1000, help="timed steps of each bench (default 1000)")
    ap.add_argument("--wide", default="7x7", help="the wide case's tiles (default 7x7; 'none' to leave it out)")
    ap.add_argument("--wide-steps", type=int, default=100, help="timed steps of the wide case (default 100)")
    ap.add_argument("--timeout", type=float, default=240, help="seconds a row may take (default 240)")
    ap.add_argument("--mpiexec", default=None, help="the launcher (default: mpiexec beside the Python, or on PATH)")
    a = ap.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    py = sys.executable
    beside = os.path.join(os.path.dirname(py), "mpiexec")
    mpiexec = [a.mpiexec or (beside if os.path.exists(beside) else shutil.which("mpiexec"))]
    # Open MPI: more ranks than cores allowed (a row that oversubscribes says so by its ceiling), and as root
    os.environ.setdefault("OMPI_MCA_rmaps_base_oversubscribe", "1")
    os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
    os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    ranks = [int(r) for r in a.ranks.split(",")]
    rows, log = [], open(os.path.join(a.out, "scaling.log"), "w")

    def keep(row):
        rows.append(row)
        with open(os.path.join(a.out, "scaling.json"), "w") as fh:
            json.dump(rows, fh, indent=1)
        print(table([row]).splitlines()[1], flush=True)

    print(table([]), flush=True)
    # the kernels compiled once into numba's cache before any timing
    run_one(bench_cmd(py, a.table, 10, (1, 1)), a.timeout, log)
    one = None
    for R in ranks:
        ceil = run_many([bench_cmd(py, a.table, a.steps, (1, 1))] * R, a.timeout, log)
        ns = [c["ns"] for c in ceil if c["ns"]]
        c_ns = sum(ns) / len(ns) if len(ns) == R else None
        one = one or (c_ns if R == 1 else None)
        keep(dict(kind="ceiling", R=R, label=f"{R} x 1 rank", ns=c_ns, rc=0 if c_ns else "failed"))
        # the ranks as the launcher left them (--bind none) beside mpdem's own binding, on the chosen grid
        for label, grid, extra in (("chosen", None, ()), ("chosen unbound", None, ("--bind", "none")),
                                   ("slabs", (1, 1, R), ())):
            if R == 1 and (grid or extra):
                continue
            row = run_one(mpi_cmd(mpiexec, R, bench_cmd(py, a.table, a.steps, (1, 1), grid, extra)), a.timeout, log)
            row.update(kind="strong", R=R, label=label, eff_one=efficiency(one, row["ns"], R),
                       eff_ceiling=efficiency(c_ns, row["ns"], R))
            keep(row)
        if R > 1:
            row = run_one(mpi_cmd(mpiexec, R, bench_cmd(py, a.table, a.steps, tiles_of(R))), a.timeout, log)
            row.update(kind="weak", R=R, label=f"{tiles_of(R)[0]}x{tiles_of(R)[1]} tiles",
                       eff_one=efficiency(one, row["ns"], R), eff_ceiling=efficiency(c_ns, row["ns"], R))
            keep(row)
    if a.wide != "none":
        R = ranks[-1]
        tx, ty = (int(t) for t in a.wide.split("x"))
        c_ns = next((r["ns"] for r in rows if r["kind"] == "ceiling" and r["R"] == R), None)
        for label, grid in (("chosen", None), ("slabs", (1, 1, R))):
            row = run_one(mpi_cmd(mpiexec, R, bench_cmd(py, a.table, a.wide_steps, (tx, ty), grid)), a.timeout, log)
            row.update(kind="wide", R=R, label=label, eff_one=efficiency(one, row["ns"], R),
                       eff_ceiling=efficiency(c_ns, row["ns"], R))
            keep(row)
    text = table(rows)
    with open(os.path.join(a.out, "scaling.txt"), "w") as fh:
        fh.write(text + "\n")
    print(text)
    return 0 if all(r.get("rc") == 0 for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
