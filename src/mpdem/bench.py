"""``python -m mpdem bench``: nanoseconds per particle-step on a landed pile.

The case (fixed, so figures compare across versions and with LAMMPS):
N = 20 000 mobile spheres on the rough bed of a 20 d x 20 d box, Hookean,
k_n = 2e5, epsilon = 0.88, gamma_t = 0, mu = 0.5, dt = 1e-4, skin 0.2 d.
The landed pile is made once per machine and cached (about 8 minutes on
one core): poured at phi_i = 0.3 with the benchmark's own physics and run
for 25 tau (250 000 steps), by which time it has landed (E_k/N ~ 1e-3,
about 4.5 contacts per particle). The timed part continues it for
``--steps`` steps (default 2000) after 200 untimed steps (kernels compiled,
lists built). It prints ns
per particle-step, the share in neighbour-list rebuilds, and the peak
memory per particle.
"""
from __future__ import annotations

import os
import resource
import time

import numpy as np

from . import build, checkpoint, config
from .decomp import Domain
from .engine import Engine, Physics
from .state import State

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
    eng.setup()
    t0 = time.perf_counter()
    steps = int(round(LANDING_TIME / cfg.integration.dt))
    for k in range(10):
        eng.run(steps // 10)
        et, er = eng.kinetic()
        log(f"bench:   t = {st.time:5.1f}: E_k/N = {(et + er) / N:.2e}, contacts per particle "
            f"{eng.contacts() / N:.2f}, {time.perf_counter() - t0:.0f} s")
    st.step, st.time = 0, 0.0
    a = checkpoint.gather_state(st)
    checkpoint.write(path, a, {"kind": "bench-pile", "step": 0, "time": 0.0, "n": N + nb,
                               "n_mobile": N, "n_bed": nb, "L_x": L, "L_y": L})
    return a, path


def run_bench(args, comm):
    """Time the benchmark case; print figures (rank 0)."""
    cfg = bench_config(args.N, args.mu)
    if args.set:
        cfg = config.load(None, ["run.max_steps=1"] + list(args.set),
                          base={k: v for k, v in cfg.values.items() if k not in cfg.derived})
    cache = args.cache or os.path.join(os.path.expanduser("~"), ".cache", "mpdem", "bench")
    rank = comm.Get_rank() if comm is not None else 0
    a, path = landed_pile(cfg, cache) if rank == 0 else (None, None)
    if comm is not None and comm.Get_size() > 1:
        a, path = comm.bcast((a, path), root=0)
    dom = Domain(comm, r_list=1.0 + cfg.integration.skin, tolerance=cfg.decomp.balance_tolerance,
                 damping=cfg.decomp.balance_damping)
    N = int((a["fixed"] == 0).sum())
    st = dom.scatter(a, cfg.box.L_x, cfg.box.L_y)
    eng = Engine(st, Physics.from_config(cfg), dom)
    eng.setup()
    eng.run(200)
    r0 = eng.n_rebuilds
    c0 = dom.comm_seconds
    t0 = time.perf_counter()
    for _ in range(args.steps):
        eng.step()
    wall = time.perf_counter() - t0
    comm_share = (dom.comm_seconds - c0) / wall
    et, er = eng.kinetic()
    contacts = eng.contacts()
    imbalance = dom.imbalance(st)
    # rebuild share: time as many rebuilds again, separately (the state is not used after)
    nreb = eng.n_rebuilds - r0
    tr = time.perf_counter()
    for _ in range(nreb):
        eng.rebuild()
    t_rebuild = time.perf_counter() - tr
    ns = 1e9 * wall / (args.steps * N)
    if rank != 0:
        return ns
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    arrays = eng.memory_bytes()
    print(f"bench: N = {N} mobile + {len(a['id']) - N} bed, mu = {cfg.contact.mu:g}, k_n = {cfg.contact.k_n:g}, "
          f"dt = {cfg.integration.dt:g}, skin = {cfg.integration.skin:g}, ranks = {dom.size}, landed pile {path}")
    print(f"bench: {args.steps} steps in {wall:.2f} s: {ns:.1f} ns per particle-step "
          f"({args.steps / wall:.0f} steps/s), {nreb} list rebuilds ({100 * t_rebuild / wall:.0f}% of the time), "
          f"contacts per particle {contacts / N:.2f}, E_k/N {(et + er) / N:.2e}")
    if dom.parallel:
        print(f"bench: {dom.size} ranks: communication {100 * comm_share:.0f}% of rank 0's time, "
              f"imbalance (max/mean owned) {imbalance:.2f}")
    print(f"bench: peak memory {peak / N:.0f} bytes per particle (process RSS {peak / 2**20:.0f} MiB); "
          f"particle and list arrays {arrays / N:.0f} bytes per particle")
    return ns


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
    a = {"id": ids, "x": g + 0.01 * rng.random((n, 3)), "v": rng.standard_normal((n, 3)),
         "omega": rng.standard_normal((n, 3)), "f": rng.standard_normal((n, 3)),
         "torque": rng.standard_normal((n, 3)), "fixed": np.zeros(n, np.uint8),
         "count": np.full(n, slots, np.int64)}
    a["partner"] = rng.integers(0, N, n * slots)
    a["ds"] = 1e-3 * rng.standard_normal((n * slots, 3))
    return a


def run_io_bench(args, comm):
    """Time a checkpoint write and read (with the split to slab owners) of N particles."""
    import tempfile
    rank, size = comm.Get_rank(), comm.Get_size()
    a = synthetic_share(args.N, rank, size)
    d = comm.bcast(tempfile.mkdtemp(prefix="mpdem-io-", dir=args.cache) if rank == 0 else None)
    path = os.path.join(d, "ckpt.h5")
    attrs = {"kind": "checkpoint", "step": 0, "time": 0.0, "n": args.N, "L_x": 100.0, "L_y": 100.0}
    times = {"write": [], "read": []}
    for _ in range(args.repeat):
        comm.Barrier()
        t = time.perf_counter()
        checkpoint.write(path, a, attrs, comm)
        comm.Barrier()
        times["write"].append(time.perf_counter() - t)
        t = time.perf_counter()
        local, _ = checkpoint.read(path, comm)
        Domain(comm).distribute(local, 100.0, 100.0)
        comm.Barrier()
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
    for f in ("v", "omega", "f", "torque"):
        out[f] = np.zeros((n, 3))
    out["count"] = np.zeros(n, np.int64)
    out["partner"], out["ds"] = np.zeros(0, np.int64), np.zeros((0, 3))
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


def run_analysis_bench(args, comm):
    """Write a tiled pile of N spheres with all ranks, then time ``mpdem analyze`` of it (rank 0)."""
    import shutil
    import tempfile
    from .analysis.report import analyze
    rank, size = comm.Get_rank(), comm.Get_size()
    cfg = bench_config(20000, args.mu)
    cache = args.cache or os.path.join(os.path.expanduser("~"), ".cache", "mpdem", "bench")
    a, pile = landed_pile(cfg, cache) if rank == 0 else (None, None)
    a = comm.bcast(a, root=0) if size > 1 else a
    L = cfg.box.L_x
    t0 = time.perf_counter()
    whole, nx, ny = tiled_pile(a, L, args.N, cfg.contact.mu, cfg.contact.k_n)
    n, m = len(whole["id"]), len(whole["id_i"])
    share = {k: whole[k][rank * n // size:(rank + 1) * n // size] for k in checkpoint.PARTICLE_FIELDS + ("count",)}
    share["partner"], share["ds"] = whole["partner"], whole["ds"]
    share.update({k: whole[k][rank * m // size:(rank + 1) * m // size] for k in checkpoint.PAIR_FIELDS})
    n_mob = int((whole["fixed"] == 0).sum())
    tcfg = config.load(None, ["run.max_steps=1", f"pour.N={n_mob}", f"box.L_x={nx * L}", f"box.L_y={ny * L}",
                              f"contact.mu={cfg.contact.mu}"])
    d = comm.bcast(tempfile.mkdtemp(prefix="mpdem-analysis-", dir=args.cache) if rank == 0 else None)
    path = os.path.join(d, "snap.h5")
    attrs = {"kind": "snapshot", "step": 0, "time": 0.0, "n": n, "n_mobile": n_mob, "n_bed": n - n_mob,
             "L_x": nx * L, "L_y": ny * L, "config": tcfg.to_toml()}
    t_make = time.perf_counter() - t0
    t0 = time.perf_counter()
    checkpoint.write(path, share, attrs, comm)
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
