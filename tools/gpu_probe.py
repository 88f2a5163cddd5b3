"""One call that measures every GPU engine variant (docs/performance.md, "GPU variants"): the probe.

    python tools/gpu_probe.py all TABLE OUT [--variants a,b] [--steps 1000] [--repeats 3] [--tiles 7x7]
                                             [--big-steps 100] [--check-steps 200] [--set KEY=VALUE ...]
    python tools/gpu_probe.py measure TABLE JSONL --variants a,b --shapes 128,256 --deadline T ...
                                             (variants one after another in one process, a record a line)

A variant is a set of ``engine.gpu_*`` switches (``VARIANTS``; a new one is a line there) run at two block
shapes (``--shapes``). The CPU's digest is taken in a process of its own; then the variants run one after
another in one process (the kernels they share compiled once: a GPU's loan is minutes), each at each
shape, each record appended to OUT/variants.jsonl as it is made. A process that dies (a fault of the GPU
loses its context) or hangs past the budget leaves its variant and shape recorded as failed, and a new
process goes on from the next (a timing shares the GPU with nothing):

- its kernels compiled and warmed on a tiny pile (``bench.warm_up_kernels``; the seconds it took: the
  first variant's include the kernels every variant shares);
- from TABLE's pile, ``--check-steps`` steps as a run takes them, then the state's digest (x, v, omega, the
  contact history): every variant and shape must give the CPU engine's digest (``cpu``, run first), and a
  difference between two shapes of one variant is a race;
- ``--steps`` steps timed ``--repeats`` times (CUDA events; the median): microseconds a step and nanoseconds
  per atom-step (all atoms, the bed's too, as the bench counts);
- five list rebuilds, each timed, marked by whether it went through the host (every ``SORT_EVERY``-th, unless
  the variant orders the rows on the GPU);
- a stop-rule sample (``kinetic`` and ``force_ratio`` after an evaluation that kept its pairs), timed;
- each launched kernel's registers, local (spill) memory, shared memory and the cooperative grid's blocks;
- at its first shape, TABLE tiled ``--tiles`` (7 x 7: 994k spheres), ``--big-steps`` steps timed ``--repeats``
  times.

Then ``tools/gpu_anatomy.py`` on the same machine (the baseline: machines of one kind differ by 15 %), and
OUT/probe.json, OUT/probe.txt (the table), the table printed last. Exit 0 when every digest is the CPU's, 1
otherwise, 2 on bad arguments. Under numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``, a small TABLE and
``--tiles 1x1``) it is a dry run of all of that: the timings mean nothing there, the digests do.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "src"))

# Every variant runs with BASE's switches, then its own over them, whatever the config's defaults are, so that
# a name means the same code in every probe: BASE is the engine before the defaults of 2026-11-28, "row" it alone.
BASE = {"engine.gpu_threads": "row", "engine.gpu_pinned": "false", "engine.gpu_drift": "apart",
        "engine.gpu_reductions": "tree", "engine.gpu_rebuild": "host", "engine.gpu_sort": "host",
        "engine.gpu_samples": "host", "engine.gpu_max_registers": "0"}
# name: the engine.gpu_* switches of the variant over BASE ("default": the config's defaults, BASE not applied;
# the defaults since 2026-11-28 are row-all-rebuild-hostsort's with the samples on the GPU)
VARIANTS = {
    "default": {},
    # the defaults' switches with the forces a thread an entry (entry-all's) and the list rebuilds inside the launches:
    # measured first (right after the defaults) on the next GPU
    "entry-all-rebuild-hostsort": {"engine.gpu_threads": "entry", "engine.gpu_pinned": "true",
                                   "engine.gpu_drift": "fused", "engine.gpu_reductions": "fused",
                                   "engine.gpu_rebuild": "launch"},
    # the defaults' switches with L lanes of a warp a row in the launches (a row's entries L at a time, summed in
    # list order through warp shuffles; built 2026-11-28, proven under the simulator, not yet timed)
    "lanes4-all-rebuild-hostsort": {"engine.gpu_threads": "lanes4", "engine.gpu_pinned": "true",
                                    "engine.gpu_drift": "fused", "engine.gpu_reductions": "fused",
                                    "engine.gpu_rebuild": "launch"},
    # the same with the steps' reductions by warp shuffles (two block barriers a phase instead of a tree's nine at 256
    # threads), and the defaults so reduced
    "lanes4-warp-rebuild-hostsort": {"engine.gpu_threads": "lanes4", "engine.gpu_pinned": "true",
                                     "engine.gpu_drift": "fused", "engine.gpu_reductions": "warp",
                                     "engine.gpu_rebuild": "launch"},
    "default-warp": {"engine.gpu_threads": "row", "engine.gpu_pinned": "true", "engine.gpu_drift": "fused",
                     "engine.gpu_reductions": "warp", "engine.gpu_rebuild": "launch", "engine.gpu_samples": "device"},
    "lanes8-all-rebuild-hostsort": {"engine.gpu_threads": "lanes8", "engine.gpu_pinned": "true",
                                    "engine.gpu_drift": "fused", "engine.gpu_reductions": "fused",
                                    "engine.gpu_rebuild": "launch"},
    "lanes2-all-rebuild-hostsort": {"engine.gpu_threads": "lanes2", "engine.gpu_pinned": "true",
                                    "engine.gpu_drift": "fused", "engine.gpu_reductions": "fused",
                                    "engine.gpu_rebuild": "launch"},
    # the same at 128 registers a thread (ptxas, sm_90: 4 blocks of 128 a multiprocessor instead of 3, 100 B of
    # spill stores and 252 of loads a thread), and the defaults so capped
    "lanes4-all-rebuild-hostsort-r128": {"engine.gpu_threads": "lanes4", "engine.gpu_pinned": "true",
                                         "engine.gpu_drift": "fused", "engine.gpu_reductions": "fused",
                                         "engine.gpu_rebuild": "launch", "engine.gpu_max_registers": "128"},
    "default-r128": {"engine.gpu_threads": "row", "engine.gpu_pinned": "true", "engine.gpu_drift": "fused",
                     "engine.gpu_reductions": "fused", "engine.gpu_rebuild": "launch", "engine.gpu_samples": "device",
                     "engine.gpu_max_registers": "128"},
    "row": {"engine.gpu_threads": "row"},
    "row-all": {"engine.gpu_threads": "row", "engine.gpu_pinned": "true", "engine.gpu_drift": "fused",
                "engine.gpu_reductions": "fused"},
    # the same with the list rebuilds as phases of the launches of many steps (no launch, copy or allocation of their
    # own; their cost is in the steps' time of run_quiet), every 20th ordering the rows by cell on the GPU
    "row-all-rebuild": {"engine.gpu_threads": "row", "engine.gpu_pinned": "true", "engine.gpu_drift": "fused",
                        "engine.gpu_reductions": "fused", "engine.gpu_rebuild": "launch", "engine.gpu_sort": "device"},
    "row-rebuild-launch": {"engine.gpu_threads": "row", "engine.gpu_rebuild": "launch", "engine.gpu_sort": "device"},
    # the ordering of the rows left out of the launch (its code costs registers: 150 against 164 pinned), the launch
    # ending at every 20th rebuild, which goes through the host
    "row-all-rebuild-hostsort": {"engine.gpu_threads": "row", "engine.gpu_pinned": "true", "engine.gpu_drift": "fused",
                                 "engine.gpu_reductions": "fused", "engine.gpu_rebuild": "launch"},
    # list rebuilds on the GPU with no host round trip, launched from the host (the table's "rebuild ms")
    "row-rebuild": {"engine.gpu_threads": "row", "engine.gpu_rebuild": "device"},
    "entry": {"engine.gpu_threads": "entry"},
    # each of the three alone
    "row-pinned": {"engine.gpu_threads": "row", "engine.gpu_pinned": "true"},
    "row-drift": {"engine.gpu_threads": "row", "engine.gpu_drift": "fused"},
    "row-fused": {"engine.gpu_threads": "row", "engine.gpu_reductions": "fused"},
    "entry-all": {"engine.gpu_threads": "entry", "engine.gpu_pinned": "true", "engine.gpu_drift": "fused",
                  "engine.gpu_reductions": "fused"},
    # the stop rule's sums on the GPU (its cost is the table's "sample ms", not the steps')
    "row-samples": {"engine.gpu_threads": "row", "engine.gpu_samples": "device"},
}


def variant_sets(variant):
    """The --set items of ``variant``: BASE's (but for "default"), then its own, which override them."""
    base = {} if variant == "default" else BASE
    return [f"{k}={v}" for k, v in base.items()] + [f"{k}={v}" for k, v in VARIANTS[variant].items()]


# the two block shapes each variant runs at (threads per block)
SHAPES = (128, 256)
REBUILDS = 5


def parse_tiles(text):
    try:
        nx, ny = (int(t) for t in text.lower().split("x"))
        if nx < 1 or ny < 1:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"--tiles {text}: accepted AxB with whole A, B >= 1 (e.g. 7x7)") from None
    return nx, ny


def parse_variants(text):
    names = [t for t in text.split(",") if t]
    unknown = [t for t in names if t not in VARIANTS]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"--variants {text}: accepted a comma-separated choice of "
                                         f"{', '.join(VARIANTS)}")
    return names


def parse_measured(text):
    """``measure``'s --variants: ``parse_variants``'s, or "cpu" alone (the CPU engine's digest)."""
    return ["cpu"] if text == "cpu" else parse_variants(text)


def parse_shapes(text):
    try:
        shapes = [int(t) for t in text.split(",") if t]
        if not shapes or any(b < 32 or b > 1024 or b & (b - 1) for b in shapes):
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"--shapes {text}: accepted comma-separated powers of two from 32 to "
                                         f"1024 (threads per block)") from None
    return shapes


def arguments(argv):
    ap = argparse.ArgumentParser(prog="gpu_probe", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    for name in ("all", "measure"):
        p = sub.add_parser(name)
        p.add_argument("table", help="the bench's particle table (landed20k.txt.gz)")
        p.add_argument("out", help="output folder (all) or JSON file (measure)")
        p.add_argument("--steps", type=int, default=1000)
        p.add_argument("--repeats", type=int, default=3)
        p.add_argument("--tiles", type=parse_tiles, default=(7, 7))
        p.add_argument("--big-steps", type=int, default=100)
        p.add_argument("--check-steps", type=int, default=200)
        p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                       help="a config item of the table's run (bench.table_config), e.g. box.L_x=5")
        if name == "all":
            p.add_argument("--variants", type=parse_variants, default=list(VARIANTS))
            p.add_argument("--shapes", type=parse_shapes, default=list(SHAPES),
                           help="threads per block each variant runs at (default 128,256)")
            p.add_argument("--no-anatomy", action="store_true", help="leave out tools/gpu_anatomy.py")
            p.add_argument("--budget", type=float, default=420.0,
                           help="seconds of the call: a variant that would start past them (by the longest "
                                "one so far) is skipped and says so (default 420)")
        else:
            p.add_argument("--variants", type=parse_measured, required=True)
            p.add_argument("--shapes", type=parse_shapes, default=list(SHAPES))
            p.add_argument("--deadline", type=float, default=math.inf,
                           help="time.time() past which no variant starts (it is recorded as skipped)")
            p.add_argument("--longest", type=float, default=0.0,
                           help="seconds the longest variant took so far (a variant starts only if that fits)")
    a = ap.parse_args(argv)
    for key in ("steps", "repeats", "big_steps", "check_steps"):
        if getattr(a, key) < 1:
            ap.error(f"--{key.replace('_', '-')} {getattr(a, key)}: accepted a whole number >= 1")
    if not os.path.isfile(a.table):
        ap.error(f"TABLE {a.table}: no such file")
    return a


class Clock:
    """Seconds of GPU work between ``start`` and ``stop`` (CUDA events), or of the host's clock under the
    simulator or on the CPU."""

    def __init__(self, cuda):
        self.cuda = cuda
        self.events = cuda is not None and hasattr(cuda, "event_elapsed_time")

    def start(self):
        if self.events:
            self.e0, self.e1 = self.cuda.event(), self.cuda.event()
            self.e0.record()
        self.t0 = time.perf_counter()

    def repeat(self, n, work):
        """Seconds of ``work()`` each of ``n`` times."""
        out = []
        for _ in range(n):
            self.start()
            work()
            out.append(self.stop())
        return out

    def stop(self):
        if self.events:
            self.e1.record()
            self.e1.synchronize()
            return self.cuda.event_elapsed_time(self.e0, self.e1) / 1e3
        return time.perf_counter() - self.t0


def kernel_resources(eng):
    """Each launched kernel's registers a thread, local memory a thread (spills), static shared memory a
    block, and (the fused steps) the cooperative grid's blocks; {} under the simulator."""
    out = {}
    for name, kernel in getattr(eng, "_launchers", {}).items():
        overloads = getattr(kernel, "overloads", None)
        if not overloads:
            continue
        k = next(iter(overloads.values()))

        def get(attr):
            v = getattr(k, attr, None)
            if v is None:
                v = getattr(k, "get_" + attr, None)
            try:
                return int(v() if callable(v) else v) if v is not None else None
            except Exception:     # a property this numba-cuda does not have
                return None
        # run_quiet's kernel, whichever of its forms (``Engine._advance_name``), is "advance"
        key = "advance" if isinstance(name, tuple) or name.startswith("advance") else name
        out[key] = {"registers": get("regs_per_thread"), "local_bytes": get("local_mem_per_thread"),
                    "shared_bytes": get("shared_mem_per_block")}
    if out.get("advance") is not None and getattr(eng, "_coop_blocks", None):
        out["advance"]["cooperative_blocks"] = int(eng._coop_blocks)
    return out


def measure(a, variant, block, big=True):
    """One variant at one block shape (or the CPU engine's digest): a dict for the JSON; ``big``: the
    tiles timed too."""
    from mpdem.bench import load_table, set_up_process, table_config, warm_up_kernels
    from mpdem.decomp import Domain
    from mpdem.engine import gpu_options, make_engine
    from mpdem.engine.gpu import SORT_EVERY
    from mpdem.engine.base import Physics
    from mpdem.io import checkpoint

    set_up_process()
    device = "cpu" if variant == "cpu" else "gpu"
    sets = [*a.set, f"engine.gpu_block={block}"]
    if device == "gpu":
        sets += variant_sets(variant)
    cfg = table_config(sets)
    phys = Physics.from_config(cfg)
    block = cfg.engine.gpu_block
    opts = gpu_options(cfg.engine)
    rec = {"variant": variant, "block": block, "device": device, "settings": sets}
    t = time.perf_counter()
    warm_up_kernels(phys, cfg.box.L_x, cfg.box.L_y, device, **opts)
    rec["compile_s"] = time.perf_counter() - t

    def engine(tile):
        whole, L_x, L_y = load_table(a.table, cfg, tile, say=lambda m: None)
        dom = Domain.from_config(None, cfg)
        st = dom.scatter(whole, L_x, L_y)
        eng = make_engine(st, phys, dom, device, **opts)
        eng.start()
        return eng, st, len(whole["id"])

    eng, st, atoms = engine((1, 1))
    rec["atoms"] = atoms
    eng.advance(a.check_steps)
    rec["digest"] = checkpoint.digest(checkpoint.gather_state(st))
    rec["check_steps"] = a.check_steps
    if device == "cpu":
        return rec
    rec["device_name"] = eng.device_name
    cuda = None if eng._simulator else eng.cuda
    clock = Clock(cuda)
    times = clock.repeat(a.repeats, lambda: (eng.run_quiet(a.steps), eng.complete()))
    rec["step_us"] = [1e6 * s / a.steps for s in times]
    rec["step_us_median"] = statistics.median(rec["step_us"])
    rec["ns_atom_step"] = 1e3 * rec["step_us_median"] / atoms
    rebuilds = []
    for _ in range(REBUILDS):
        # (every SORT_EVERY-th orders the rows by cell: through the host unless engine.gpu_sort = "device")
        host = eng.n_rebuilds % SORT_EVERY == 0 and not getattr(eng, "sort_on_gpu", False)
        clock.start()
        eng.rebuild()
        rebuilds.append({"ms": 1e3 * clock.stop(), "through_host": bool(host)})
        eng.advance(1)
    rec["rebuilds"] = rebuilds
    # a stop-rule sample: the kinetic energies and the force ratio of an evaluation that kept its pairs
    eng.step(keep_pairs=True)
    rec["sample_ms"] = 1e3 * statistics.median(clock.repeat(a.repeats, lambda: (eng.kinetic(), eng.force_ratio())))
    eng.complete()
    rec["kernels"] = kernel_resources(eng)
    eng = st = None     # the 20k pile's GPU arrays freed before the tiles
    if big and (a.tiles != (1, 1) or a.big_steps):
        big, _, n_big = engine(a.tiles)
        big.advance(min(10, a.big_steps))
        times = clock.repeat(a.repeats, lambda: (big.run_quiet(a.big_steps), big.complete()))
        rec["big"] = {"tiles": list(a.tiles), "atoms": n_big, "steps": a.big_steps,
                      "ns_atom_step": 1e9 * statistics.median(times) / (a.big_steps * n_big)}
    return rec


def read_records(path):
    """The records of a JSONL file (none if it does not exist; a last line cut off by a dying process is
    left out)."""
    if not os.path.exists(path):
        return []
    out = []
    with open(path) as fh:
        for line in fh:
            try:
                out.append(json.loads(line))
            except json.JSONDecodeError:
                pass
    return out


def append_record(path, rec):
    """One record as a line of ``path``, on disk before the next starts (a process may die after it)."""
    with open(path, "a") as fh:
        fh.write(json.dumps(rec) + "\n")
        fh.flush()
        os.fsync(fh.fileno())


def measure_all(a):
    """``measure``: each of ``a.variants`` at each of ``a.shapes`` not yet in the JSONL file ``a.out``, one
    after another in this process, each record appended as it is made; one that would start past
    ``a.deadline`` (by the longest so far) is recorded as skipped."""
    done = {(r["variant"], r["block"]) for r in read_records(a.out)}
    longest = a.longest
    for variant in a.variants:
        for i, block in enumerate(a.shapes):
            if (variant, block) in done:
                continue
            if time.time() + longest > a.deadline:
                append_record(a.out, {"variant": variant, "block": block,
                                      "skipped": "the budget: no time left for it in the call"})
                continue
            t = time.perf_counter()
            # the parent names the variant a dying process was at: the one after the last record
            rec = measure(a, variant, block, big=i == 0)
            rec["wall_s"] = time.perf_counter() - t
            longest = max(longest, rec["wall_s"])
            append_record(a.out, rec)
    return 0


def run_child(a, variants, shapes, path, deadline, longest, timeout):
    """``measure`` over ``variants`` x ``shapes`` in a new process; (exit status or None if it ran past
    ``timeout`` s and was killed, the tail of its output)."""
    cmd = [sys.executable, os.path.abspath(__file__), "measure", a.table, path, "--variants", ",".join(variants),
           "--shapes", ",".join(map(str, shapes)), "--deadline", repr(deadline), "--longest", repr(longest),
           "--steps", str(a.steps), "--repeats", str(a.repeats), "--tiles", "x".join(map(str, a.tiles)),
           "--big-steps", str(a.big_steps), "--check-steps", str(a.check_steps)] + [f"--set={s}" for s in a.set]
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired as e:
        out = e.stderr or e.stdout or ""
        return None, (out.decode() if isinstance(out, bytes) else out).strip()[-2000:]
    return p.returncode, (p.stderr or p.stdout).strip()[-2000:]


def drive(keys, path, child, deadline, grace):
    """Every (variant, block) of ``keys`` recorded in the JSONL file ``path``: ``child(variants, shapes,
    deadline, longest, timeout)`` (``run_child``'s) is run until each has a record; the key a child died or
    hung at (the first without one) is recorded as failed with the child's last output, and a new child
    goes on from the next. Returns the records in ``keys``'s order."""
    while True:
        recs = {(r["variant"], r["block"]): r for r in read_records(path)}
        left = [k for k in keys if k not in recs]
        if not left:
            return [recs[k] for k in keys]
        variants = list(dict.fromkeys(v for v, _ in left))
        shapes = sorted({b for _, b in left}, key=[b for _, b in keys].index)
        longest = max([r.get("wall_s", 0.0) for r in recs.values()], default=0.0)
        rc, tail = child(variants, shapes, deadline, longest, max(deadline - time.time(), 0.0) + grace)
        recs = {(r["variant"], r["block"]) for r in read_records(path)}
        stuck = next((k for k in keys if k not in recs), None)
        if stuck is not None and rc != 0:
            why = "ran past the budget and was stopped" if rc is None else f"its process ended with status {rc}"
            append_record(path, {"variant": stuck[0], "block": stuck[1], "failed": f"{why}\n{tail}"})
        elif stuck is not None:
            # a child that ended well leaves nothing undone: guard against a loop all the same
            append_record(path, {"variant": stuck[0], "block": stuck[1], "failed": f"not measured\n{tail}"})


def anatomy(a):
    """tools/gpu_anatomy.py's lines on the table (today's engine, block 128, a thread a row)."""
    p = subprocess.run([sys.executable, os.path.join(HERE, "gpu_anatomy.py"), a.table, str(a.steps), "128", "row"],
                       capture_output=True, text=True)
    return {"rc": p.returncode, "lines": [ln for ln in (p.stdout + p.stderr).splitlines() if ln.strip()][-20:]}


def verdicts(result):
    """Each GPU record's ``same``: its digest is the CPU's; and the races: variants whose shapes differ."""
    ref = result["cpu"].get("digest")
    races = []
    ran = [r for r in result["variants"] if "skipped" not in r]
    for rec in ran:
        rec["same"] = "digest" in rec and rec["digest"] == ref
    by_variant = {}
    for rec in ran:
        by_variant.setdefault(rec["variant"], set()).add(rec.get("digest"))
    races = sorted(v for v, d in by_variant.items() if len(d) > 1)
    result["races"] = races
    result["all_same"] = ref is not None and all(r["same"] for r in ran)
    return result


def table(result):
    """The summary table (text lines)."""
    head = (f"{'variant':<12} {'block':>5} {'us/step':>9} {'ns/atom-step':>12} {'big ns':>8} {'rebuild ms':>10} "
            f"{'sample ms':>9} {'regs':>5} {'local B':>7} {'coop':>5} {'compile s':>9}  digest")
    lines = [head, "-" * len(head)]
    for r in result["variants"]:
        if "skipped" in r:
            lines.append(f"{r['variant']:<12} {r['block']:>5}  skipped: {r['skipped']}")
            continue
        if "failed" in r:
            lines.append(f"{r['variant']:<12} {r['block']:>5}  failed: {r['failed'].splitlines()[-1][:80]}")
            continue
        gpu_rebuilds = [b["ms"] for b in r["rebuilds"] if not b["through_host"]] or [b["ms"] for b in r["rebuilds"]]
        adv = r["kernels"].get("advance", {})
        big = r.get("big", {}).get("ns_atom_step")

        def num(v, fmt):
            return format(v, fmt) if v is not None else "-"
        lines.append(f"{r['variant']:<12} {r['block']:>5} {r['step_us_median']:>9.2f} {r['ns_atom_step']:>12.3f} "
                     f"{num(big, '8.3f'):>8} {statistics.median(gpu_rebuilds):>10.2f} {r['sample_ms']:>9.2f} "
                     f"{num(adv.get('registers'), 'd'):>5} {num(adv.get('local_bytes'), 'd'):>7} "
                     f"{num(adv.get('cooperative_blocks'), 'd'):>5} {r['compile_s']:>9.1f}  "
                     f"{'= CPU' if r['same'] else 'DIFFERS from the CPU ' + str(r.get('digest'))[:16]}")
    cpu = result["cpu"]
    lines.append(f"CPU digest after {cpu.get('check_steps')} steps of {cpu.get('atoms')} atoms: "
                 f"{str(cpu.get('digest', cpu.get('failed')))[:16]}")
    if result["races"]:
        lines.append(f"RACE: the block shapes of {', '.join(result['races'])} give different digests")
    name = next((r.get("device_name") for r in result["variants"] if r.get("device_name")), "?")
    lines.append(f"{name}, {result['commit']}; us/step the median of {result['repeats']} x {result['steps']} steps "
                 f"(CUDA events), big = {result['tiles']} tiles, {result['big_steps']} steps")
    return lines


def commit():
    p = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=HERE)
    return p.stdout.strip() or "?"


def run_all(a):
    os.makedirs(a.out, exist_ok=True)
    t = time.perf_counter()
    deadline = time.time() + a.budget
    result = {"commit": commit(), "steps": a.steps, "repeats": a.repeats, "tiles": "x".join(map(str, a.tiles)),
              "big_steps": a.big_steps, "check_steps": a.check_steps, "sets": a.set}
    print(f"gpu_probe: the CPU engine's digest ({a.check_steps} steps)", flush=True)
    cpu_path = os.path.join(a.out, "cpu.jsonl")
    for stale in (cpu_path, os.path.join(a.out, "variants.jsonl")):
        if os.path.exists(stale):
            os.remove(stale)
    result["cpu"] = drive([("cpu", SHAPES[0])], cpu_path, lambda v, s, d, lo, to: run_child(
        a, v, s, cpu_path, math.inf, 0.0, None), math.inf, 0.0)[0]
    print(f"gpu_probe: {len(a.variants)} variants at blocks {', '.join(map(str, a.shapes))}", flush=True)
    path = os.path.join(a.out, "variants.jsonl")
    # a child past the deadline is stopped after this much more (the variant it is at, and its tiles)
    grace = 120.0
    result["variants"] = drive([(v, b) for v in a.variants for b in a.shapes], path, lambda v, s, d, lo, to: run_child(
        a, v, s, path, d, lo, to), deadline, grace)
    if not a.no_anatomy:
        print("gpu_probe: tools/gpu_anatomy.py (the baseline)", flush=True)
        result["anatomy"] = anatomy(a)
    verdicts(result)
    result["wall_s"] = time.perf_counter() - t
    lines = table(result)
    with open(os.path.join(a.out, "probe.json"), "w") as fh:
        json.dump(result, fh, indent=1)
    with open(os.path.join(a.out, "probe.txt"), "w") as fh:
        fh.write("\n".join(lines + [""] + result.get("anatomy", {}).get("lines", [])) + "\n")
    for ln in result.get("anatomy", {}).get("lines", []):
        print(ln)
    print("\n".join(lines))
    return 0 if result["all_same"] and not result["races"] else 1


def main(argv=None):
    a = arguments(argv)
    if a.cmd == "measure":
        return measure_all(a)
    return run_all(a)


if __name__ == "__main__":
    sys.exit(main())
