"""``python -m mpdem bench``: nanoseconds per atom-step, beside LAMMPS.

``bench --table FILE`` (the default bench) starts from a particle table
(``tables.read_table``: plain or gzip; e.g. a landed 20 000-sphere pile)
and times ``--steps`` steps (default 2000) of the contact model with the
settings of the LAMMPS comparison input: Hooke, k_n = 2e5, epsilon =
0.88, gamma_t = gamma_n / 2, mu = 0.5, dt = 1e-4, skin 0.2 d, box 20 d x 20 d
(``--set`` overrides any of them), ``--tile NXxNY`` copies of the table side
by side. Untimed first: the kernels on a tiny pile (then the memory
baseline), the set-up force evaluation and 50 steps. It prints the case,
rebuilds and contacts, each phase's share of the loop (forces, lists,
integration from the engine's ``timers``; communication from the Domain;
glue the rest; the steps an engine runs in one call, ``run_quiet``, count as
forces: on one rank and one thread the CPU's kicks and drifts are among them),
memory per atom, and last ``ns_per_atom_step=X`` with every
atom (bed included) counted, as LAMMPS counts them (a side-by-side script
reads that line).

``bench --io`` times checkpoint writes and reads; ``bench --analysis`` times
``mpdem analyze`` of copies of a landed pile (``landed_pile``, made once and
cached).
"""
from __future__ import annotations

import gc
import math
import os
import resource
import time

import numpy as np

from . import build, config, initial, memory, threads
from .errors import InputError
from .io import tables
from .io import checkpoint, lammps, pilefile
from .decomp import Domain
from .engine import gpu_options, make_engine
from .engine.base import Physics
from .engine.cpu import Engine
from .footprint import rss_now
from .parallel import channel
from .state import FIELDS, INITIAL, PAIR, PARTICLE, State

LANDING_TIME = 25.0   # [tau] from the pour at phi_i = 0.3 to the landed pile


def bench_config(N, mu):
    return config.load(None, ["run.max_steps=1", f"pour.N={N}", "pour.phi_i=0.3",
                              f"contact.mu={mu}", "box.L_x=20.0", "box.L_y=20.0"])


def landed_pile(cfg, cache, log=print):
    """The landed pile of the benchmark, from the cache or made now."""
    N, mu = cfg.pour.N, cfg.contact.mu
    path = os.path.join(cache, f"pile-N{N}-mu{mu:g}-v3.h5")
    if os.path.exists(path):
        a, _ = checkpoint.read_state(path)
        return a, path
    os.makedirs(cache, exist_ok=True)
    log(f"bench: making the landed pile once ({N} spheres; cached in {path})")
    bed = build.make_bed(cfg)
    L = cfg.box.L_x
    H = build.insertion_height(N, L, L, cfg.pour.phi_i)
    xm = build.insert_random(build.rng(cfg.run.seed, build.STREAM_POUR), N, L, L,
                             bed.z_top + 1, bed.z_top + 1 + H, obstacles=bed.x)
    nb = len(bed.x)
    st = State(np.arange(N + nb), np.concatenate([xm, bed.x]),
               fixed=np.concatenate([np.zeros(N, np.uint8), np.ones(nb, np.uint8)]), L_x=L, L_y=L)
    eng = Engine(st, Physics.from_config(cfg), Domain(None))
    eng.start()
    t0 = time.perf_counter()
    steps = int(round(LANDING_TIME / cfg.integration.dt))
    for k in range(10):
        eng.advance(steps // 10)
        et, er = eng.kinetic()
        log(f"bench:   t = {st.time:5.1f}: E_k/N = {(et + er) / N:.2e}, contacts per particle "
            f"{eng.contacts() / N:.2f}, {time.perf_counter() - t0:.0f} s")
    st.step, st.time = 0, 0.0
    a = checkpoint.gather_state(st)
    checkpoint.write(path, a, {"kind": "bench-pile", "step": 0, "time": 0.0, "n": N + nb,
                               "n_mobile": N, "n_bed": nb, "L_x": L, "L_y": L})
    return a, path


# the settings of the LAMMPS comparison input (gamma_t = gamma_n / 2 is set after resolving)
TABLE_SETTINGS = ("contact.model=hooke", "contact.k_n=2e5", "contact.epsilon=0.88", "contact.mu=0.5",
                  "integration.dt=1e-4", "integration.skin=0.2", "box.L_x=20.0", "box.L_y=20.0")
WARMUP_STEPS = 50
PHASES = ("forces", "lists", "integration")


def table_config(sets=()):
    """The table bench's Config: LAMMPS's settings, then ``--set`` items.

    gamma_t is gamma_n / 2 (25.713732817929117 at epsilon 0.88, k_n 2e5, as
    LAMMPS's input) unless ``contact.gamma_t`` is among ``sets``.
    """
    cfg = config.load(None, ["run.max_steps=1", *TABLE_SETTINGS, *sets])
    if any(config.parse_set(item)[0] == "contact.gamma_t" for item in sets):
        return cfg
    return cfg.replace(**{"contact.gamma_t": cfg.contact.gamma_n / 2})


def table_box(cfg, path, sets=()):
    """The table bench's config in the box of an mpdem state or packing file or a LAMMPS file
    (``io.pilefile.file_facts``): the pile is timed as it lies. A text table keeps no box: the bench's
    20 x 20 d (or ``--set box.*``) stays.

    Raises
    ------
    InputError
        A ``--set box.*`` that disagrees with the file's box, naming both; a LAMMPS file without
        ``run.fixed_types``.
    """
    # a LAMMPS file's box is in its header; read as load_table reads it (run.fixed_types: the bed's types)
    lammps_table = None
    if os.path.isfile(path) and lammps.kind(path):
        if not cfg.run.fixed_types:   # every sphere mobile: a pile with no bed (a run refuses it too)
            raise InputError(lammps.no_bed_types(path, what="--table"))
        lammps_table = lammps.read(path, cfg.run.fixed_types, what="--table")
    box = {k: v for k, v in pilefile.file_facts(path, lammps_table, what="--table").items() if k.startswith("box.")}
    user = {config.parse_set(item)[0] for item in sets}
    for key, length in box.items():
        if key in user and cfg.values[key] != length:
            raise InputError(f"--set {key}={cfg.values[key]!r}, but the box of --table {path} is {length!r} long "
                             f"in {key[-1]}; leave {key} unset to take the file's box")
    return cfg.replace(**box) if box else cfg


def rss_peak():
    """Peak resident set size of this process so far [bytes] (ru_maxrss, KiB on Linux)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def warm_up_kernels(phys, L_x, L_y, device="cpu", **gpu):
    """Compile (or load) the step's kernels on a tiny pile, so no timing or baseline includes it.

    A 3 x 3 bed with five mobile spheres resting on it, touching each other
    and the bed (overlaps 0.005 d), stepped ``WARMUP_STEPS`` times with the
    bench's physics on this rank alone, then rebuilt and stepped once more,
    by the engine the timed loop uses (``gpu``: ``make_engine``'s ``gpu_*``
    keywords, ``engine.gpu_options``: the GPU engine's kernels differ by them).
    """
    g = np.arange(3.0)
    bed = np.array([[1.0 + i, 1.0 + j, 0.0] for j in g for i in g])
    mob = np.array([[1.5, 1.5, 0.7], [2.5, 1.5, 0.7], [1.5, 2.495, 0.7], [2.5, 2.5, 0.7], [2.0, 2.0, 1.4]])
    x = np.concatenate([mob, bed])
    fixed = np.concatenate([np.zeros(len(mob), np.uint8), np.ones(len(bed), np.uint8)])
    eng = make_engine(State(np.arange(len(x)), x, fixed=fixed, L_x=L_x, L_y=L_y), phys, Domain(None), device,
                      **gpu)
    eng.start()
    # (in ``run_quiet``'s way: the kernels of steps in one call compiled too)
    eng.advance(WARMUP_STEPS)
    # a rebuild with contacts in the lists compiles the history's list-to-slot kernels too
    eng.rebuild()
    if getattr(eng, "sort_on_gpu", False):
        # and a GPU engine that orders the rows on the GPU every SORT_EVERY-th rebuild (engine.gpu_sort), that
        # rebuild's kernels: as many rebuilds as it takes to reach one
        from .engine.gpu import SORT_EVERY
        while eng.n_rebuilds % SORT_EVERY:
            eng.rebuild()
        eng.rebuild()
    eng.advance(1)
    eng.kinetic()
    eng.contacts()


def load_table(path, cfg, tile=(1, 1), say=print):
    """The bench's whole particle set from a table, checked, then tiled.

    Parameters
    ----------
    path : str
        A text table (``tables.read_table``, plain or gzip), a state or packing file or a LAMMPS data
        file or dump (its bed by ``run.fixed_types``), read as ``run.initial_file`` is (``initial.particles``).
    cfg : Config
        Box (``box.L_x``, ``box.L_y``: a state file's, ``table_box``) and ``checks.overlap_warn``.
    tile : (int, int)
        Copies along x and y (``tables.tile_table``).
    say : callable
        Takes the overlap warning line.

    Returns
    -------
    whole : dict of ``Domain.scatter``'s arrays id (N,), x (N, 3) [d],
        v (N, 3), omega (N, 3) (zero unless the table has it), fixed (N,) uint8
    L_x, L_y : the (tiled) box [d]
    """
    if not os.path.isfile(path):
        raise InputError(f"--table {path}: no such file")
    # the reader of run.initial_file: a text table (or a state or LAMMPS file)
    t = initial.particles(path, cfg, log=say)
    L_x, L_y = cfg.box.L_x, cfg.box.L_y
    fixed = t["fixed"]
    z_floor = float(t["x"][fixed == 1, 2].mean()) if fixed.any() else -np.inf
    build.check_initial(t["id"], t["x"], fixed, L_x, L_y, z_floor,
                        overlap_warn=cfg.checks.overlap_warn, warn=say)
    nx, ny = tile
    if (nx, ny) != (1, 1):
        t = tables.tile_table(t, L_x, L_y, nx, ny)
    whole = {k: t[k] for k in INITIAL}
    return whole, nx * L_x, ny * L_y


def phase_clock(eng, dom):
    """Accumulated seconds per phase now: the engine's ``timers`` and communication."""
    out = {k: float(eng.timers[k]) for k in PHASES}
    out["communication"] = dom.comm_seconds
    return out


def phase_lines(before, after, wall):
    """``bench:`` lines of each phase's seconds and share of the loop's wall time [s];
    glue is the rest of the loop."""
    spent = {k: after[k] - before[k] for k in PHASES + ("communication",)}
    spent["glue"] = wall - sum(spent.values())
    return [f"bench: phase {k:<13s} {t:8.3f} s {100 * t / wall:5.1f}%" for k, t in spent.items()]


# steps of one ``run_quiet`` call in the timed loop (its launches are of up to ``engine.gpu.BATCH`` steps)
QUIET = 1000


def timed_loop(eng, dom, steps):
    """Run ``steps`` steps; wall seconds, rebuilds, phase clocks before and after, and the
    steadiness of the steps (``steadiness``)."""
    r0, before = eng.n_rebuilds, phase_clock(eng, dom)
    timers = eng.timers
    lists0 = timers["lists"]
    # each step's end and the lists clock after it (a step that rebuilt or filtered moved it):
    # two appends a step, some 0.1 us
    ends, lists = [], []
    switches = resource.getrusage(resource.RUSAGE_SELF).ru_nivcsw
    # an engine that runs steps in one go (``steps_in_one_call``: the CPU's on one rank and one thread,
    # the GPU's on one rank) is timed in runs of QUIET steps, each run's time shared evenly among its steps
    quiet = eng.run_quiet if eng.steps_in_one_call else None
    t0 = time.perf_counter()
    done = 0
    while done < steps:
        n = min(QUIET, steps - done) if quiet else 1
        if quiet:
            quiet(n)
        else:
            eng.step(defer_kick=True)
        t = time.perf_counter()
        # (the run's start read before the list grows)
        start = ends[-1] if ends else t0
        ends.extend([start + (t - start) * (k + 1) / n for k in range(n)])
        lists.extend([timers["lists"]] * n)
        done += n
    eng.complete()
    wall = time.perf_counter() - t0
    switches = resource.getrusage(resource.RUSAGE_SELF).ru_nivcsw - switches
    steady = steadiness(np.diff(np.array([t0] + ends)), np.diff(np.array([lists0] + lists)) > 0.0, wall, switches)
    return wall, eng.n_rebuilds - r0, before, phase_clock(eng, dom), steady


def steadiness(step_s, list_work, wall, switches):
    """How steady a timed loop's steps were on this rank: what a busy machine costs a run.

    On several ranks every step waits for the slowest rank, so a step that one rank loses to
    the machine's own work (another process, the kernel's threads, interrupts) is lost on all.

    Parameters
    ----------
    step_s : (S,) float
        Wall seconds of each step.
    list_work : (S,) bool
        Steps that rebuilt or filtered the lists (left out: they are slower by design).
    wall : float
        The loop's wall seconds.
    switches : int
        Involuntary context switches of this process during the loop.

    Returns
    -------
    dict: ``median`` and ``p90`` step [s] of the other steps; ``slow`` the share of the loop
    that their steps above 1.1 x the median took beyond the median; ``switches`` a second.
    """
    plain = step_s[~list_work]
    if len(plain) == 0:
        return dict(median=math.nan, p90=math.nan, slow=math.nan, switches=switches / wall)
    med = float(np.median(plain))
    slow = plain[plain > 1.1 * med]
    return dict(median=med, p90=float(np.percentile(plain, 90)), slow=float((slow - med).sum()) / wall,
                switches=switches / wall)


def steadiness_line(per_rank):
    """The ``bench: steps`` line from each rank's ``steadiness``, ranks joined by " / "."""
    def each(key, scale, fmt):
        return " / ".join(fmt.format(scale * r[key]) for r in per_rank)
    return ("bench: steps (rebuilds and filterings aside): median " + each("median", 1e3, "{:.3f}")
            + " ms, 90th percentile " + each("p90", 1e3, "{:.3f}") + " ms; those over 1.1 x the median took "
            + each("slow", 100, "{:.1f}") + " % of the loop beyond it; involuntary context switches "
            + each("switches", 1, "{:.0f}") + " a second")


def set_up_process():
    """The process's threads (``--threads``) and allocator, as a run sets them (``simulation``)."""
    threads.apply()
    memory.return_freed_memory()


def run_table_bench(args, net):
    """Time ``args.steps`` steps from a particle table; print figures on rank 0.

    The last line rank 0 prints is ``ns_per_atom_step=X``: loop wall seconds
    (the slowest rank's) x 1e9 / (steps x all atoms, bed included), as LAMMPS
    counts them. Returns X.
    """
    set_up_process()
    cfg = table_box(table_config(args.set), args.table, args.set)
    net = channel(net)
    rank = net.rank
    say = print if rank == 0 else (lambda msg: None)
    phys = Physics.from_config(cfg)
    device = getattr(args, "device", "cpu")
    warm_up_kernels(phys, cfg.box.L_x, cfg.box.L_y, device, **gpu_options(cfg.engine))
    gc.collect()
    baseline = rss_now()
    # every rank reads the same table, so a bad table stops every rank alike
    whole, L_x, L_y = load_table(args.table, cfg, args.tile, say=lambda msg: say(f"bench: warning: {msg}"))
    n_atoms, n_mobile = len(whole["id"]), int((whole["fixed"] == 0).sum())
    dom = Domain.from_config(net, cfg)
    st = dom.scatter(whole, L_x, L_y)
    del whole
    eng = make_engine(st, phys, dom, device, **gpu_options(cfg.engine))
    eng.start()
    if dom.parallel and device == "gpu":
        # a rebuild on every rank before the timing (the GPU engine completes its deferred half-kick first): what
        # a rebuild on several ranks compiles (engine.gpu_exchange = "device") compiles here, not in the timed steps
        eng.rebuild()
    eng.advance(WARMUP_STEPS)
    wall, rebuilds, before, after, steady = timed_loop(eng, dom, args.steps)
    fig = dict(table=args.table, tile=tuple(args.tile), n_atoms=n_atoms, n_mobile=n_mobile, L_x=L_x, L_y=L_y,
               cfg=cfg, ranks=dom.size, steps=args.steps, wall=wall, wall_max=dom.max(wall), rebuilds=rebuilds,
               phases=(before, after), steadiness=dom.allgather(steady), device=getattr(eng, "device_name", "CPU"),
               **after_loop(eng, dom, st, baseline, (before, after)))
    for line in report_lines(fig):
        say(line)
    return fig["ns"]


def after_loop(eng, dom, st, baseline, phases):
    """Figures taken after the timed loop (collectives: every rank calls this).

    Returns contacts (global, both partners counted), E_k [m g d], imbalance (``Domain.imbalance``)
    and what it is of (balanced: "work" or "owned"), per_rank (each rank's seconds per phase, from
    ``phases`` = (before, after) clocks),
    grown (peak RSS - baseline summed over ranks [bytes]), peak (largest
    process peak RSS [bytes]), engine_bytes (``eng.memory_bytes()`` summed), threads.
    """
    from .threads import BOUND, count
    et, er = eng.kinetic()
    before, after = phases
    spent = {k: after[k] - before[k] for k in before}
    return dict(contacts=eng.contacts(), ek=et + er, imbalance=dom.imbalance(st),
                balanced="work" if dom.work_imbalance is not None else "owned", per_rank=dom.allgather(spent),
                grown=int(dom.sum_int(np.array([rss_peak() - baseline]))[0]), peak=dom.max(rss_peak()),
                engine_bytes=int(dom.sum_int(np.array([eng.memory_bytes()]))[0]),
                threads=count(), bound=dom.max(0.0 if BOUND is None else 1.0) > 0, grid=dom.grid,
                **halo_figures(dom, st))


def halo_figures(dom, st):
    """ghosts_per_owned (ghost rows over owned rows, summed over ranks) and refresh_bytes (the bytes every
    step's ghost refresh sends, summed over ranks) of the halo now (collectives)."""
    plan = dom._plan
    sent = 0 if plan is None else int(plan.send_buf.nbytes)
    ghosts, owned, sent = dom.sum_int(np.array([st.n_rows - st.n_own, st.n_own, sent]))
    return dict(ghosts_per_owned=int(ghosts) / max(int(owned), 1), refresh_bytes=int(sent))


def report_lines(fig):
    """The table bench's lines, ``ns_per_atom_step=X`` last; sets ``fig['ns']``."""
    cfg, n, n_mob, par = fig["cfg"], fig["n_atoms"], max(fig["n_mobile"], 1), fig["ranks"] > 1
    c = cfg.contact
    fig["ns"] = 1e9 * fig["wall_max"] / (fig["steps"] * n)
    tiled = "" if fig["tile"] == (1, 1) else " tiled {}x{}".format(*fig["tile"])
    lines = [
        f"bench: case {os.path.basename(fig['table'])}{tiled}: {n} atoms = {fig['n_mobile']} mobile + "
        f"{n - fig['n_mobile']} bed, box {fig['L_x']:g} x {fig['L_y']:g}; {c.model} k_n = {c.k_n:g}, "
        f"gamma_t = {c.gamma_t:.6g}, mu = {c.mu:g}, dt = {cfg.integration.dt:g}, skin = {cfg.integration.skin:g}",
        f"bench: {fig['ranks']} rank(s) x {fig['threads']} thread(s){' (bound)' if fig.get('bound') else ''} on "
        f"{fig['device']}, {fig['steps']} steps in "
        f"{fig['wall_max']:.2f} s (after {WARMUP_STEPS} untimed), {fig['rebuilds']} list rebuilds, contacts per "
        f"mobile particle {fig['contacts'] / n_mob:.2f}, E_k/N {fig['ek'] / n_mob:.2e}"
        + (f", imbalance (max/mean {fig['balanced']}) {fig['imbalance']:.2f}" if par else ""),
        *([f"bench: grid {' x '.join(map(str, fig['grid']))}, {fig['ghosts_per_owned']:.3f} ghosts per owned row, "
           f"the refresh sends {fig['refresh_bytes'] / 1e6:.3f} MB a step (all ranks)"] if par else []),
        "bench: the loop by phase" + (" (rank 0's loop)" if par else "") + ":",
        *phase_lines(*fig["phases"], fig["wall"]),
        *(["bench: seconds per rank: " + "; ".join(
            f"{k} " + " / ".join(f"{p[k]:.3f}" for p in fig["per_rank"]) for k in fig["per_rank"][0])]
          if par else []),
        steadiness_line(fig["steadiness"]),
        f"bench: memory {fig['grown'] / n:.0f} bytes per atom (peak RSS minus the import baseline"
        + (", summed over ranks" if par else "") + ")"
        + f", engine arrays {fig['engine_bytes'] / n:.0f} bytes per atom"
        + f"; process peak RSS {fig['peak'] / 1e6:.0f} MB" + (" (largest rank)" if par else ""),
        f"ns_per_atom_step={fig['ns']:.6g}",
    ]
    return lines


def synthetic_share(N, rank, size, slots=6, seed=0):
    """This rank's share of a synthetic N-particle state for timing file IO.

    Particles sit on a jittered cubic lattice (spacing 1.1 d) in a 100 x 100
    box, ids split into contiguous blocks by rank; each has ``slots``
    contact slots with random partners. Shapes as ``checkpoint.read`` gives.
    """
    lo, hi = rank * N // size, (rank + 1) * N // size
    rng = np.random.default_rng([seed, rank])
    ids = np.arange(lo, hi, dtype=np.int64)
    side = 90
    g = np.column_stack([ids % side, (ids // side) % side, ids // side ** 2]) * 1.1
    n = hi - lo
    given = {"id": lambda: ids, "x": lambda: g + 0.01 * rng.random((n, 3)), "fixed": lambda: np.zeros(n, np.uint8),
             "count": lambda: np.full(n, slots, np.int64), "partner": lambda: rng.integers(0, N, n * slots)}
    a = {}
    # every stored field of the particles and their slots (registry order: the draws' order); the rest random
    for f in FIELDS:
        if f.group and f.per != PAIR and not f.optional:
            rows = n if f.per == PARTICLE else n * slots
            a[f.name] = given[f.name]() if f.name in given else rng.standard_normal((rows,) + f.shape)
    a["ds"] *= 1e-3
    return a


def run_io_bench(args, net):
    """Time a checkpoint write and read (with the split to slab owners) of N particles."""
    import tempfile
    net = channel(net)
    rank, size = net.rank, net.size
    a = synthetic_share(args.N, rank, size)
    d = net.bcast(tempfile.mkdtemp(prefix="mpdem-io-", dir=args.cache) if rank == 0 else None)
    path = os.path.join(d, "ckpt.h5")
    attrs = {"kind": "checkpoint", "step": 0, "time": 0.0, "n": args.N, "L_x": 100.0, "L_y": 100.0}
    times = {"write": [], "read": []}
    for _ in range(args.repeat):
        net.barrier()
        t = time.perf_counter()
        checkpoint.write(path, a, attrs, net)
        net.barrier()
        times["write"].append(time.perf_counter() - t)
        t = time.perf_counter()
        local, _ = checkpoint.read(path, net)
        Domain(net).distribute(local, 100.0, 100.0)
        net.barrier()
        times["read"].append(time.perf_counter() - t)
    if rank == 0:
        mb = os.path.getsize(path) / 2**20
        for k, v in times.items():
            print(f"bench-io: {k} {args.N} particles ({mb:.0f} MiB) on {size} ranks: best {min(v):.2f} s, "
                  f"median {sorted(v)[len(v) // 2]:.2f} s ({mb / min(v):.0f} MiB/s) over {len(v)}")
        import shutil
        shutil.rmtree(d)
    return times


def tiled_pile(a, L, N, mu, k_n, seed=0):
    """Copies of the landed (x-y periodic) pile side by side: at least N mobile spheres.

    Parameters
    ----------
    a : state arrays of the landed pile (``landed_pile``), box L x L [d]
    N : mobile spheres wanted; mu, k_n : for the contact list's forces

    Returns
    -------
    arrays : whole state, ids 0..n-1, with a contact list ``id_i, id_j,
        delta, F_n, F_t, ds_i`` of the geometric contacts. Its forces are
        synthetic (F_n = k_n delta, |F_t| uniform in [0, mu F_n) in a random
        tangent direction): the benchmark times the analysis, not physics.
    nx, ny : tiles along x and y
    """
    from .analysis.bulk import find_contacts
    from .kernels.pairdist import separations
    n_mob = int((a["fixed"] == 0).sum())
    tiles = -(-N // n_mob)
    # the most nearly square nx x ny = tiles
    nx = max(k for k in range(1, int(np.sqrt(tiles)) + 1) if tiles % k == 0)
    ny = tiles // nx
    x0 = a["x"].copy()
    x0[:, 0] %= L
    x0[:, 1] %= L
    shifts = np.array([[i * L, j * L, 0.0] for j in range(ny) for i in range(nx)])
    x = (x0[None, :, :] + shifts[:, None, :]).reshape(-1, 3)
    n = len(x)
    out = {"id": np.arange(n, dtype=np.int64), "x": x, "fixed": np.tile(a["fixed"], nx * ny)}
    # the other stored fields of the particles and the slots: zeros, no slots
    for f in FIELDS:
        if f.group and f.per != PAIR and not f.optional and f.name not in out:
            out[f.name] = np.zeros(((n if f.per == PARTICLE else 0),) + f.shape, f.array_dtype)
    pairs, r = find_contacts(x, nx * L, ny * L)
    rng = np.random.default_rng(seed)
    delta = 1.0 - r
    d = separations(x, pairs[:, 0], pairs[:, 1], nx * L, ny * L)
    nrm = d / r[:, None]
    t = np.cross(nrm, rng.standard_normal((len(r), 3)))
    t /= np.linalg.norm(t, axis=1)[:, None]
    F_n = k_n * delta
    out.update(id_i=pairs[:, 0], id_j=pairs[:, 1], delta=delta, F_n=F_n,
               F_t=t * (mu * F_n * rng.random(len(r)))[:, None], ds_i=np.zeros((len(r), 3)))
    return out, nx, ny


def run_analysis_bench(args, net):
    """Write a tiled pile of N spheres with all ranks, then time ``mpdem analyze`` of it (rank 0)."""
    set_up_process()
    import shutil
    import tempfile
    from .analysis.report import analyze
    net = channel(net)
    rank, size = net.rank, net.size
    cfg = bench_config(20000, args.mu)
    cache = args.cache or os.path.join(os.path.expanduser("~"), ".cache", "mpdem", "bench")
    a, pile = landed_pile(cfg, cache) if rank == 0 else (None, None)
    a = net.bcast(a)
    L = cfg.box.L_x
    t0 = time.perf_counter()
    whole, nx, ny = tiled_pile(a, L, args.N, cfg.contact.mu, cfg.contact.k_n)
    n, m = len(whole["id"]), len(whole["id_i"])
    # each rank writes a share of the particle rows and of the pairs (there are no slots)
    rows, pairs = slice(rank * n // size, (rank + 1) * n // size), slice(rank * m // size, (rank + 1) * m // size)
    share = {f.name: whole[f.name][pairs if f.per == PAIR else rows if f.per == PARTICLE else slice(None)]
             for f in FIELDS if f.name in whole}
    n_mob = int((whole["fixed"] == 0).sum())
    tcfg = config.load(None, ["run.max_steps=1", f"pour.N={n_mob}", f"box.L_x={nx * L}", f"box.L_y={ny * L}",
                              f"contact.mu={cfg.contact.mu}"])
    d = net.bcast(tempfile.mkdtemp(prefix="mpdem-analysis-", dir=args.cache) if rank == 0 else None)
    path = os.path.join(d, "snap.h5")
    attrs = {"kind": "snapshot", "step": 0, "time": 0.0, "n": n, "n_mobile": n_mob, "n_bed": n - n_mob,
             "L_x": nx * L, "L_y": ny * L, "config": tcfg.to_toml()}
    t_make = time.perf_counter() - t0
    t0 = time.perf_counter()
    checkpoint.write(path, share, attrs, net)
    t_write = time.perf_counter() - t0
    del whole, share
    if rank != 0:
        return None
    import numba
    print(f"bench-analysis: {n_mob} mobile + {n - n_mob} bed spheres ({nx} x {ny} tiles of {pile}), "
          f"{m} contacts, {os.path.getsize(path) / 2**20:.0f} MiB written by {size} rank(s) in {t_write:.1f} s "
          f"(made in {t_make:.1f} s); analysing with {numba.get_num_threads()} numba threads")
    times = []
    for k in range(args.repeat):
        t0 = time.perf_counter()
        s, _ = analyze(path, os.path.join(d, "analysis"), plots=True, log=lambda msg: None)
        times.append(time.perf_counter() - t0)
        print(f"bench-analysis: run {k + 1}: {times[-1]:.1f} s (read {s['seconds']['read']:.1f} s); "
              f"z = {s['z']:.3f}, phi = {s['phi']:.4f}, {s['n_bulk']} bulk spheres, "
              f"g(r) from {s['gofr']['n_ref']} reference spheres to {s['gofr']['r_max']:g} d")
    print(f"bench-analysis: best {min(times):.1f} s, median {sorted(times)[len(times) // 2]:.1f} s over {len(times)} "
          f"(the first includes loading the compiled kernels)")
    shutil.rmtree(d)
    return times
