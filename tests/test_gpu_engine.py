"""The GPU engine gives the CPU engine's bits (design.md, "Two engines, one result").

Without a GPU these run under numba's CUDA simulator (conftest.py sets
``NUMBA_ENABLE_CUDASIM=1`` unless ``MPDEM_REAL_GPU=1``): the kernels' logic,
their grids, block reductions and atomics, the history between the GPU's
entries and the host's slots, on small piles. On a GPU (``tools/gpu_check.sh``
runs this file with ``MPDEM_REAL_GPU=1``) the same tests check the compiled
kernels, whose float arithmetic is explicitly rounded.
"""
import ast
import dataclasses

import numpy as np
import pytest

from helpers import mpdem, tight_lattice
from mpdem.config import gamma_n_from_epsilon
from mpdem.decomp import Domain
from mpdem.engine import cpu, gpu, migrate
from mpdem.engine.base import Physics
from mpdem.errors import DeviceError
from mpdem.io import checkpoint
from mpdem.planes import Plane
from mpdem.kernels.gpu import rounded, runtime
from mpdem.state import State

# launches of a few threads under the simulator (it runs each as a Python thread); the GPU's own
# grid on a GPU. The kernels take any grid: every row (or entry) is one thread's, whichever. The
# first is today's default path; the second and the third take a thread an entry for the forces
# (``engine.gpu_threads``), the third with its kernels compiled under a register cap (``engine.gpu_max_registers``);
# the last three reduce a fused step's values in one tree a phase (``engine.gpu_reductions``); the second and
# the fourth sum the stop rule's samples on the GPU (``engine.gpu_samples``); the second and the third launch
# steps compiled for the run's options (``engine.gpu_pinned``), the third and the fourth drift the next step
# in the forces' phase, the rows in two buffers (``engine.gpu_drift``); the second and the third rebuild the
# lists on the GPU with no host round trip (``engine.gpu_rebuild``; inside the launches: REBUILD_GRIDS).
GRIDS = ([dict(block=2, blocks=2),
          dict(block=4, blocks=3, threads="entry", reductions="fused", samples="device", pinned=True,
               rebuilds="device"),
          dict(block=4, blocks=2, threads="entry", max_registers=64, reductions="fused", drift="fused", pinned=True,
               rebuilds="device"),
          dict(block=2, blocks=3, reductions="fused", samples="device", drift="fused")] if runtime.SIMULATOR
         else [dict(block=128),
               dict(block=32, threads="entry", reductions="fused", samples="device", pinned=True, rebuilds="device"),
               dict(block=64, threads="entry", max_registers=64, reductions="fused", drift="fused", pinned=True,
                    rebuilds="device"),
               dict(block=256, reductions="fused", samples="device", drift="fused")])


def physics(mu=0.5, model="hooke", **kw):
    k_n = 2e5
    base = dict(k_n=k_n, k_t=2 * k_n / 7, gamma_n=gamma_n_from_epsilon(0.88, k_n), gamma_t=0.0, mu=mu, dt=1e-4,
                gravity=1.0, model=model, skin=0.006)
    base.update(kw)
    return Physics.of(**base)


def stepped(engine, phys, steps, grid=None):
    """A tight lattice (125 spheres, its lowest layer frozen) with fast random motion, stepped by
    ``engine`` (the step before the last keeping its pairs); returns the engine and its state."""
    x, v, omega, fixed, L = tight_lattice(m=5)
    st = State(np.arange(len(x)), x, 40 * v, 40 * omega, fixed, L, L)
    eng = engine(st, phys, Domain(None), **(grid or {}))
    eng.start()
    eng.advance(steps - 1)
    eng.step(keep_pairs=True)
    return eng, st


CASES = {
    "mu0": physics(mu=0.0),
    "mu0.5-gamma_t": physics(mu=0.5, gamma_t=20.0),
    # a lid just above the lattice's top layer (its centres near 4.99 d), which some spheres touch
    "hertz-wall-lid": physics(mu=0.5, model="hertz", gamma_t=10.0, wall=True, planes=(Plane.lid(5.49),)),
    "rotate-limit": physics(mu=1.0, rescale_history=True, limit_damping=True),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_gpu_engine_steps_the_cpu_engines_bits(case):
    """Every stored field (rows, contact slots, the wall's history) after 30 steps with list rebuilds
    (the history carried through them), the exact sums and the force ratio are the CPU's."""
    phys = CASES[case]
    grid = GRIDS[sorted(CASES).index(case) % len(GRIDS)]
    want, st_c = stepped(cpu.Engine, phys, 30)
    got, st_g = stepped(gpu.Engine, phys, 30, grid)
    assert got.n_rebuilds >= 3 and want.n_rebuilds >= 3, "the history must pass through rebuilds"
    a, b = checkpoint.gather_state(st_c), checkpoint.gather_state(st_g)
    assert int(b["count"].sum()) > 100, "a pile in contact"
    for name in a:
        assert np.array_equal(a[name], b[name]), name
    assert checkpoint.digest(a) == checkpoint.digest(b)
    assert got.kinetic() == want.kinetic() and got.kinetic(momentum=True) == want.kinetic(momentum=True)
    assert got.contacts() == want.contacts()
    assert got.force_ratio() == want.force_ratio()
    assert got.last_overlap == want.last_overlap > 0
    if phys.planes:
        # the lid acted: without it the CPU's pile ends elsewhere
        free = stepped(cpu.Engine, dataclasses.replace(phys, planes=()), 30)[1]
        assert checkpoint.digest(checkpoint.gather_state(free)) != checkpoint.digest(a)


ONE_LAUNCH = ["mu0", "mu0.5-gamma_t", "hertz-wall-lid"]


@pytest.mark.parametrize("case", ONE_LAUNCH)
def test_steps_in_one_launch_give_the_steps_bits(case):
    """``run_quiet`` (the steps in cooperative launches, each ending at a step that needs a rebuild,
    which the host finishes) gives the bits and the step records of the CPU engine's steps, a
    thread a row (frictionless), a thread an entry (friction) and a thread an entry with the next step's drift in
    the forces' phase (Hertz, the wall)."""
    phys = CASES[case]
    want, st_c = stepped(cpu.Engine, phys, 30)
    x, v, omega, fixed, L = tight_lattice(m=5)
    st = State(np.arange(len(x)), x, 40 * v, 40 * omega, fixed, L, L)
    eng = gpu.Engine(st, phys, Domain(None), **GRIDS[ONE_LAUNCH.index(case)])
    eng.start()
    infos = eng.run_quiet(29)
    assert len(infos) == 29 and st.step == 29 and eng.n_rebuilds >= 3
    # as the CPU engine's steps report them
    ref = stepped(cpu.Engine, phys, 1)[0]
    assert infos[0].max_overlap == ref.info.max_overlap and infos[0].z_min == ref.info.z_min
    eng.step(keep_pairs=True)
    assert checkpoint.digest(checkpoint.gather_state(st)) == checkpoint.digest(checkpoint.gather_state(st_c))
    assert eng.kinetic() == want.kinetic() and eng.force_ratio() == want.force_ratio()
    assert eng.last_overlap == want.last_overlap and eng.contacts() == want.contacts()


def test_steps_in_one_launch_keep_no_pairs_as_on_the_cpu():
    """``force_ratio`` after ``run_quiet`` (whose evaluations keep no pair forces) is (nan, -1) on both
    engines, as after any step that did not keep them; the GPU's gave the pairs of its last launch."""
    phys = physics(mu=0.5)
    for engine, grid in ((cpu.Engine, {}), (gpu.Engine, GRIDS[0]), (gpu.Engine, GRIDS[1])):
        x, v, omega, fixed, L = tight_lattice(m=5)
        eng = engine(State(np.arange(len(x)), x, 40 * v, 40 * omega, fixed, L, L), phys, Domain(None), **grid)
        eng.start()
        eng.advance(3)
        eng.step(keep_pairs=True)
        assert np.isfinite(eng.force_ratio()[0])
        eng.run_quiet(3)
        ratio, loose = eng.force_ratio()
        assert np.isnan(ratio) and loose == -1, (engine.__module__, grid)


def test_rebuilds_asked_for_by_the_balance_change_no_bit(monkeypatch):
    """A rebuild that ``Domain.rebalance_due`` asks for between the motion's (``decomp.balance_every``:
    here every third step, as a rank of several would be told) in each engine's step path: the bits of
    the plain CPU steps."""
    phys = CASES["mu0.5-gamma_t"]
    want, st_c = stepped(cpu.Engine, phys, 20)
    asked = []
    monkeypatch.setattr(Domain, "rebalance_due", lambda self, work: asked.append(work()) or len(asked) % 3 == 0)
    for engine, kw in ((cpu.Engine, {}), (gpu.Engine, GRIDS[0])):
        x, v, omega, fixed, L = tight_lattice(m=5)
        st = State(np.arange(len(x)), x, 40 * v, 40 * omega, fixed, L, L)
        eng = engine(st, phys, Domain(None), **kw)
        eng.start()
        for _ in range(20):
            eng.step(keep_pairs=True)
        assert eng.n_rebuilds > want.n_rebuilds, engine.__module__    # the asked rebuilds came
        assert checkpoint.digest(checkpoint.gather_state(st)) == checkpoint.digest(checkpoint.gather_state(st_c))
        assert eng.last_overlap == want.last_overlap and eng.contacts() == want.contacts()


@pytest.mark.parametrize("grid", [0, 2])
def test_every_step_record_of_one_launch_is_the_cpu_engines(grid):
    """Each StepInfo of ``run_quiet`` (its overlap, contact count and height range), and the overlap
    and contacts after it, equal the CPU engine's, step by step across list rebuilds: the host path's
    evaluation at a rebuild step starts from neutral reductions, not the sum (and larger overlap) of
    the evaluation before it."""
    phys = CASES["mu0.5-gamma_t"]
    x, v, omega, fixed, L = tight_lattice(m=5)
    records = []
    for engine, kw in ((cpu.Engine, {}), (gpu.Engine, GRIDS[grid])):
        st = State(np.arange(len(x)), x.copy(), 40 * v, 40 * omega, fixed.copy(), L, L)
        eng = engine(st, phys, Domain(None), **kw)
        eng.start()
        infos = []
        for _ in range(4):      # a rebuild inside each stretch, and a contact count read between
            infos += eng.run_quiet(6)
            infos.append(eng.info._replace(n_contacts=eng.contacts()))
        records.append((eng.n_rebuilds, infos, eng.last_overlap, eng.contacts()))
    (r_c, want, o_c, n_c), (r_g, got, o_g, n_g) = records
    assert r_g >= 3 and r_c >= 3, "the steps must pass through rebuilds"
    assert len(got) == len(want) == 28
    for s, (a, b) in enumerate(zip(want, got)):
        assert a == b, f"record {s}: CPU {a}, GPU {b}"
    assert (o_g, n_g) == (o_c, n_c) and n_c > 0


def test_a_law_that_changes_between_steps_gives_the_cpu_bits():
    """The stiffening ramp's laws (``stiffen``): a stiffer law every few steps, its first step
    rescaling each stored Delta s (``Law.ds_scale``), the steps between in one launch (``run_quiet``)
    on the GPU and one by one on the CPU: the same bits."""
    phys = CASES["mu0.5-gamma_t"]
    x, v, omega, fixed, L = tight_lattice(m=5)
    engines = []
    for engine, grid in ((cpu.Engine, {}), (gpu.Engine, GRIDS[0])):
        st = State(np.arange(len(x)), x.copy(), 40 * v, 40 * omega, fixed.copy(), L, L)
        eng = engine(st, phys, Domain(None), **grid)
        eng.start()
        law = phys.law
        for tread in range(4):
            k = law.k_n * 1.5
            new = law._replace(k_n=k, k_t=2 * k / 7, gamma_n=gamma_n_from_epsilon(0.88, k))
            eng.phys = phys.with_law(new._replace(ds_scale=law.k_t / new.k_t))
            eng.step(defer_kick=True)
            eng.phys = phys.with_law(new)
            if engine is gpu.Engine:
                eng.run_quiet(5)
            else:
                for _ in range(5):
                    eng.step(defer_kick=True)
            law = new
        eng.step(keep_pairs=True)
        engines.append((eng, st))
    (want, st_c), (got, st_g) = engines
    a, b = checkpoint.gather_state(st_c), checkpoint.gather_state(st_g)
    assert int(a["count"].sum()) > 100 and np.any(a["ds"] != 0.0), "a frictional pile in contact"
    assert checkpoint.digest(a) == checkpoint.digest(b)
    assert got.force_ratio() == want.force_ratio() and got.kinetic() == want.kinetic()


def test_lists_built_on_the_gpu_are_the_cpu_build():
    """A rebuild on the GPU (``kernels.gpu.lists``) gives every row the partners of the host's
    ``build_neighbours``, sorted by id, and carries each entry's history and stamp."""
    from mpdem.kernels.bundles import make_box
    from mpdem.kernels.neighbours import build_neighbours
    eng, st = stepped(gpu.Engine, CASES["mu0.5-gamma_t"], 8, GRIDS[1])
    assert 0 < eng.n_rebuilds % gpu.SORT_EVERY, "the last rebuild was one on the GPU"
    eng.sync_state()    # the host's rows current
    hist, stamp = eng._download_history()
    old = eng._lists()
    before = {(i, int(old.nbr_list[e])): e
              for i in range(st.n_own) for e in range(old.nbr_start[i], old.nbr_start[i + 1])}
    eng.rebuild()       # on the GPU again, from the positions the host's lists are built from
    assert not eng._host_lists
    lists = eng._lists()
    n = st.n_own
    start, nbr = np.zeros(n + 1, np.int64), np.zeros(40 * n, np.int32)
    k = build_neighbours(st.x, st.n_rows, n, st.fixed, st.id, make_box(st.L_x, st.L_y), eng.r_list, start, nbr, 1)
    assert k == eng._k > 0
    assert np.array_equal(lists.nbr_start[:n + 1], start) and np.array_equal(lists.nbr_list[:k], nbr[:k])
    hist2, stamp2 = eng._download_history()
    stale = np.uint32(eng._epoch - 1)
    kept = 0
    for i in range(n):
        for e in range(start[i], start[i + 1]):
            was = before.get((i, int(nbr[e])))
            if was is None:
                assert stamp2[e] == stale and not hist2[e].any()
            else:
                assert stamp2[e] == stamp[was] and np.array_equal(hist2[e], hist[was])
                kept += stamp[was] == np.uint32(eng._epoch)
    assert kept > 50, "contacts among the carried entries"


# rebuilds without the host at two launch shapes: in place (the lists' length read with the forces' reductions),
# then inside the launches of many steps (``engine.gpu_rebuild = "launch"``; the fourth pinned), a thread a row, then
# inside the launches a thread an entry (the fifth and the sixth, pinned: the entries' rows and forces follow the
# lists the launch builds); the second, the fourth and the sixth order the rows on the GPU every SORT_EVERY-th rebuild
# (``engine.gpu_sort``: by launches, then inside the launch) and start with room for 8 entries, so that their first
# rebuild without the host overflows
REBUILD_GRIDS = ([dict(block=2, blocks=2, rebuilds="device"),
                  dict(block=2, blocks=3, reductions="fused", drift="fused", rebuilds="device", list_capacity=8,
                       sort="device"),
                  dict(block=2, blocks=2, rebuilds="launch"),
                  dict(block=2, blocks=3, reductions="fused", drift="fused", rebuilds="launch", list_capacity=8,
                       sort="device", pinned=True),
                  dict(block=2, blocks=2, threads="entry", rebuilds="launch"),
                  dict(block=2, blocks=3, threads="entry", reductions="fused", drift="fused", rebuilds="launch",
                       list_capacity=8, sort="device", pinned=True)]
                 if runtime.SIMULATOR else
                 [dict(block=128, rebuilds="device"),
                  dict(block=256, reductions="fused", drift="fused", rebuilds="device", list_capacity=8, sort="device"),
                  dict(block=128, rebuilds="launch"),
                  dict(block=256, reductions="fused", drift="fused", rebuilds="launch", list_capacity=8,
                       sort="device", pinned=True),
                  dict(block=128, threads="entry", rebuilds="launch"),
                  dict(block=256, threads="entry", reductions="fused", drift="fused", rebuilds="launch",
                       list_capacity=8, sort="device", pinned=True)])


@pytest.mark.parametrize("mu, grid", [(0.0, 0), (0.5, 1), (0.5, 2), (0.0, 3), (0.0, 4), (0.5, 5)])
def test_rebuilds_in_place_give_every_step_record_and_the_bits_of_the_cpu(mu, grid):
    """``engine.gpu_rebuild = "device"`` and ``"launch"``: a list rebuild every step or two (a skin of
    0.002 d; 27 spheres, every 20th rebuild through the host), frictionless and frictional, each
    ``StepInfo``, the contact counts read between, the digest, the kinetic sums and the force ratio are
    the CPU engine's. No
    rebuild a thread a row reads anything back before the forces that follow it. The second shape's first
    rebuild in place overflows its room (8 entries), and so does one after a third of the steps (its room set back to 8,
    the contacts' history not zero): the host sees it with the forces' reductions (in place) or the
    launch's record (inside a launch, which ends there) and builds again. Inside the launches, most
    rebuilds are phases of the launch, a thread a row or a thread an entry."""
    kw_gpu = REBUILD_GRIDS[grid]
    in_launch, sorted_in_launch = kw_gpu["rebuilds"] == "launch", kw_gpu.get("sort") == "device"
    phys = physics(mu=mu, gamma_t=20.0, skin=0.002)
    x, v, omega, fixed, L = tight_lattice(m=3)
    runs = []
    for engine, kw in ((cpu.Engine, {}), (gpu.Engine, kw_gpu)):
        st = State(np.arange(len(x)), x.copy(), 40 * v, 40 * omega, fixed.copy(), L, L)
        eng = engine(st, phys, Domain(None), **kw)
        eng.start()
        eager = []
        if engine is gpu.Engine:
            settle = eng._settle
            eng._settle = lambda red=None: (eager.append(red is None and eng._pending is not None), settle(red))[1]
        infos = []
        shift = 0
        for stretch in range(3):
            if stretch == 1 and engine is gpu.Engine and grid % 2:
                # room for 8 entries again, once the contacts carry a history: the next rebuild overflows
                eng._capacity, eng._sets = 8, []
                if in_launch and sorted_in_launch:
                    # and is one that orders the rows first (inside the launch, which puts them back)
                    shift = -eng.n_rebuilds % gpu.SORT_EVERY
                    eng.n_rebuilds += shift
            infos += eng.run_quiet(14)
            infos.append(eng.info._replace(n_contacts=eng.contacts()))
        infos.append(eng.step(keep_pairs=True))
        eng.n_rebuilds -= shift
        runs.append((eng, st, infos, eager))
    (want, st_c, a, _), (got, st_g, b, eager) = runs
    assert got.n_rebuilds == want.n_rebuilds >= 21, "rebuilds in place and through the host"
    # the first and every SORT_EVERY-th through the host, or (``sort="device"``) the first only
    assert got.n_rebuilds_by_host == (1 if got.sort_on_gpu else 1 + (got.n_rebuilds - 1) // gpu.SORT_EVERY)
    # (a thread an entry reads the length of a rebuild in place at once: its launches are sized by it)
    assert got.n_overflows == (2 if grid % 2 else 0) and (got.by_entry or not any(eager))
    assert got.n_rebuilds_in_launch > (10 if in_launch else -1) and (in_launch or got.n_rebuilds_in_launch == 0)
    assert got.by_entry == (kw_gpu.get("threads") == "entry")
    assert len(a) == len(b) == 46
    for s, (p, q) in enumerate(zip(a, b)):
        assert p == q, f"record {s}: CPU {p}, GPU {q}"
    g = checkpoint.gather_state(st_g)
    assert int(g["count"].sum()) > 50 and (mu == 0.0 or np.any(g["ds"] != 0.0)), "a pile in contact"
    assert checkpoint.digest(checkpoint.gather_state(st_c)) == checkpoint.digest(g)
    assert got.kinetic() == want.kinetic() and got.force_ratio() == want.force_ratio()


@pytest.mark.parametrize("nx, ny", [(3, 3), (20, 17), (47, 33)])
def test_the_gpus_order_of_cells_is_the_hosts(nx, ny):
    """``gpu.sort_columns`` ranks the cells as ``order.sort_rows`` orders them (columns of about SORT_COLUMN x
    SORT_COLUMN cells one after the other, z-major inside each), densely: a permutation of the cells."""
    from mpdem.engine.order import SORT_COLUMN
    nz = 5
    base, size, local = gpu.sort_columns(nx, ny)
    iz, iy, ix = (a.ravel() for a in np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij"))
    xy = iy * nx + ix
    rank = base[xy] * nz + iz * size[xy] + local[xy]
    assert np.array_equal(np.sort(rank), np.arange(nx * ny * nz))
    cx, cy = max(int(round(nx / SORT_COLUMN)), 1), max(int(round(ny / SORT_COLUMN)), 1)
    column = (iy * cy // ny) * cx + ix * cx // nx
    key = ((column * nz + iz) * ny + iy) * nx + ix
    assert np.array_equal(np.argsort(rank), np.argsort(key))


def test_any_grid_gives_the_same_bits():
    """The launch's shape (threads per block, blocks, rows a thread, a thread a row or an entry)
    changes no bit."""
    phys = CASES["mu0.5-gamma_t"]
    digests = {checkpoint.digest(checkpoint.gather_state(stepped(gpu.Engine, phys, 12, g)[1])) for g in GRIDS}
    assert len(digests) == 1


def test_a_restart_into_the_gpu_engine_goes_on_bit_for_bit():
    """Rows, forces and slots taken from the CPU engine mid-run (as a state file holds them) and
    stepped on by the GPU engine give the straight CPU run's bits, and the other way round."""
    phys = CASES["mu0.5-gamma_t"]
    straight = checkpoint.gather_state(stepped(cpu.Engine, phys, 24)[1])
    for first, second in ((cpu.Engine, gpu.Engine), (gpu.Engine, cpu.Engine)):
        eng, st = stepped(first, phys, 12, GRIDS[0] if first is gpu.Engine else None)
        eng.complete()
        half = State.from_arrays(checkpoint.gather_state(st), st.L_x, st.L_y)
        half.step = st.step
        kw = GRIDS[0] if second is gpu.Engine else {}
        nxt = second(half, phys, Domain(None), **kw)
        nxt.start_from_file()
        nxt.advance(11)
        nxt.step(keep_pairs=True)
        assert checkpoint.digest(checkpoint.gather_state(half)) == checkpoint.digest(straight)


def test_every_operation_of_a_twin_is_explicitly_rounded():
    """The GPU twins of the law hold no bare + - * / (each would let the compilers fuse a multiply
    and an add) and no math call but the rounded square root."""
    for name in rounded.LAW_FUNCTIONS:
        tree = ast.parse(rounded.rounded_source(getattr(rounded.law, name)))
        ops = [n for n in ast.walk(tree) if isinstance(n, (ast.BinOp, ast.AugAssign))]
        assert not ops, f"{name}: {ast.unparse(ops[0])}"
        calls = {n.func.id for n in ast.walk(tree) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)}
        assert calls <= set(rounded.OPS) | set(rounded.LAW_FUNCTIONS) | {"abs"}, (name, calls)
    with pytest.raises(ValueError, match="no rounded twin"):
        rounded._Rounded().visit(ast.parse("def f(a, b):\n    return a ** b"))


def test_no_gpu_is_one_clear_error(monkeypatch):
    monkeypatch.setattr(runtime, "SIMULATOR", False)
    monkeypatch.setattr(runtime.cuda, "is_available", lambda: False)
    with pytest.raises(DeviceError, match="engine.device = 'gpu': no CUDA GPU.*`--device cpu` runs the same"):
        gpu.Engine(State(np.arange(1), np.zeros((1, 3))), physics(), Domain(None))


def test_each_rank_on_a_node_takes_its_own_gpu():
    """Ranks on a node with 4 GPUs take GPUs 0-3 by their local rank, whichever launcher says it; with one
    GPU visible (CUDA_VISIBLE_DEVICES per rank) each takes it; without a local rank, GPU 0."""
    for var in runtime.LOCAL_RANK_VARS:
        assert [runtime.gpu_of_rank(4, {var: str(r)}) for r in range(6)] == [0, 1, 2, 3, 0, 1]
        assert runtime.gpu_of_rank(1, {var: "3"}) == 0
    assert runtime.gpu_of_rank(4, {}) == 0


def test_gpu_block_is_checked_before_any_work(tmp_path):
    r = mpdem("run", "--set", "engine.gpu_block=48", "--set", "run.max_steps=10", "--out", tmp_path / "r", check=1)
    assert "engine.gpu_block = 48: accepted a power of two from 32 to 1024" in r.stderr
    r = mpdem("run", "--set", "engine.gpu_max_registers=16", "--set", "run.max_steps=10", "--out", tmp_path / "s",
              check=1)
    assert "engine.gpu_max_registers = 16: accepted 0 (the compiler's choice) or 32 to 255" in r.stderr
    assert "Traceback" not in r.stderr


# a soft, fast pour: some 0.6 contacts a sphere after 200 steps, 20 list rebuilds, friction mobilised
POUR = ["box.L_x=4", "box.L_y=4", "pour.N=30", "pour.phi_i=0.3", "pour.K0=5", "contact.k_n=2e3", "run.seed=5",
        "output.progress_every=100", "integration.skin=0.1"]


def pour(out, *extra, n=1, check=3, env=None):
    args = [a for kv in POUR + list(extra) for a in ("--set", kv)]
    return mpdem("run", *args, "--out", out, "--quiet", n=n, check=check, env=env)


def summary_digest(run):
    import json
    return json.loads((run / "summary.json").read_text())["digest"]


@pytest.fixture(scope="module")
def cpu_pour(tmp_path_factory):
    run = tmp_path_factory.mktemp("pour") / "cpu"
    pour(run, "run.max_steps=200", "contact.mu=0.5")
    return summary_digest(run)


def test_a_pour_on_the_gpu_is_the_cpu_pour(cpu_pour, tmp_path):
    """``mpdem run --device gpu``, a pour with a checkpoint restarted on the CPU, and the same pour
    on two ranks (two columns) each with the GPU engine: every one the one-rank CPU run's digest."""
    pour(tmp_path / "gpu", "run.max_steps=200", "contact.mu=0.5", "engine.device=gpu")
    assert summary_digest(tmp_path / "gpu") == cpu_pour
    # the first half on the GPU (its checkpoint written from the GPU's rows and history), the rest on the CPU
    half = tmp_path / "half"
    pour(half, "run.max_steps=100", "contact.mu=0.5", "engine.device=gpu", "output.checkpoint_every=100")
    mpdem("restart", half, "--set", "run.max_steps=200", "--device", "cpu", "--quiet", check=3)
    assert summary_digest(half) == cpu_pour
    # two ranks each on its GPU, as two columns (ghosts through the side and periodic faces; the engine
    # sees only ghost rows, as on slabs)
    pour(tmp_path / "two", "run.max_steps=200", "contact.mu=0.5", "engine.device=gpu", "decomp.grid=[2, 1, 1]", n=2)
    assert "(grid 2 x 1 x 1)" in (tmp_path / "two" / "log.txt").read_text()
    assert summary_digest(tmp_path / "two") == cpu_pour
    # two slabs whose rebuilds keep the rows and the history on the GPU (engine.gpu_exchange), rebalanced by counts
    # at every rebuild so that rows with contacts leave and arrive: 26 migrations, 12 rebalances; its snapshots'
    # contact lists (whose pairs with a ghost read the ghost rows the GPU alone refreshes) are the CPU's
    pour(tmp_path / "across", "run.max_steps=200", "contact.mu=0.5", "engine.device=gpu", "decomp.grid=[1, 1, 2]",
         "engine.gpu_exchange=device", "decomp.balance_by=count", "decomp.balance_tolerance=0.01",
         "decomp.balance_damping=1.0", "output.snapshot_every=20", n=2)
    end = [ln for ln in (tmp_path / "across" / "log.txt").read_text().splitlines() if ln.startswith("end:")][0]
    assert int(end.split(" migrations")[0].split()[-1]) > 10, end
    assert summary_digest(tmp_path / "across") == cpu_pour
    pour(tmp_path / "cpu-snaps", "run.max_steps=200", "contact.mu=0.5", "output.snapshot_every=20")
    snaps = sorted(p.name for p in (tmp_path / "cpu-snaps" / "snapshots").glob("snap-*.h5"))
    assert len(snaps) == 10
    for name in snaps:
        want, got = (contact_list(tmp_path / run / "snapshots" / name) for run in ("cpu-snaps", "across"))
        assert want.keys() == got.keys() and all(np.array_equal(want[k], got[k]) for k in want), name


def contact_list(path):
    """A state file's contact list (``pairs``), its pairs in (id_i, id_j) order."""
    import h5py
    with h5py.File(path, "r") as f:
        g = f["pairs"]
        order = np.lexsort((g["id_j"][:], g["id_i"][:]))
        return {k: g[k][:][order] for k in g}


def test_lists_of_a_rank_without_rows_are_empty():
    """An empty slab's rebuild on the GPU (``engine.gpu_exchange = "device"``) builds lists of no row (no z
    range to read)."""
    eng, st = stepped(gpu.Engine, physics(), 2, GRIDS[0])
    start, nbr, k = eng._build_lists(0, 0)
    assert k == 0 and start.copy_to_host().tolist() == [0]


def _slot_state(counts, ids=None):
    """A State of len(counts) rows whose row i holds counts[i] slots: partners 100 i + 1.., Delta s (i, k, 0)."""
    n = len(counts)
    st = State(np.arange(n) if ids is None else np.asarray(ids), np.zeros((n, 3)))
    partner = np.concatenate([100 * i + 1 + np.arange(c) for i, c in enumerate(counts)]).astype(np.int64)
    ds = np.array([[i, k, 0.0] for i, c in enumerate(counts) for k in range(c)]).reshape(-1, 3)
    st.set_contacts(np.asarray(counts), partner, ds)
    return st


def test_slots_inserted_for_some_rows_keep_the_others_in_row_order():
    st = _slot_state([0, 2, 0, 1, 0])
    migrate.insert_slots(st, np.array([0, 2, 4]), [1, 0, 3], np.array([7, 9, 10, 11]),
                         np.array([[-1.0, 0, 0], [4, 0, 0], [4, 1, 0], [4, 2, 0]]))
    assert list(st.count[:5]) == [1, 2, 0, 1, 3]
    assert list(st.slots_of(0)[0]) == [7] and st.slots_of(0)[1][0, 0] == -1.0
    assert list(st.slots_of(1)[0]) == [101, 102] and list(st.slots_of(1)[1][:, 1]) == [0, 1]
    assert list(st.slots_of(3)[0]) == [301]
    assert list(st.slots_of(4)[0]) == [9, 10, 11]
    with pytest.raises(RuntimeError, match="already holds slots"):
        migrate.insert_slots(st, np.array([1]), [1], np.array([5]), np.zeros((1, 3)))


def test_a_keeper_follows_each_row_to_its_gpu_row_through_migrations():
    """Rows reordered, some leaving (their fields and slots brought from their GPU rows as they go), others
    arriving with theirs, ghosts' sources sent: ``origin`` names each final row's GPU row or its arrival,
    only arrivals hold slots, and only rows that leave or are sent were asked of the GPU."""
    st = _slot_state([0, 0, 0, 0, 0], ids=[10, 11, 12, 13, 14])
    packed, fetched = [], []

    def pack(rows):
        packed.append(list(rows))
        c = np.array([r % 2 + 1 for r in rows])
        return c, np.concatenate([np.arange(k) + 50 for k in c]), np.ones((int(c.sum()), 3))

    def fetch(rows, names):
        fetched.append((list(rows), tuple(names)))
        # GPU row g's field: (g, index of the field, 7)
        return {name: np.array([[g, j, 7.0] for g in rows]) for j, name in enumerate(names)}

    k = migrate.Keeper(5, pack, fetch, ("v", "omega", "f", "torque"))
    order = np.array([4, 3, 2, 1, 0])
    st.permute(order)
    k.permute(order)
    # host rows 1 and 3 (GPU rows 3 and 1) leave; one row arrives with two slots
    k.leaving(st, np.array([1, 3]))
    assert packed == [[3, 1]] and fetched == [([3, 1], ("v", "omega", "f", "torque"))]
    assert list(st.count[:5]) == [0, 2, 0, 2, 0]
    assert list(st.torque[1]) == [3, 3, 7] and list(st.v[3]) == [1, 0, 7]
    part = st.take(np.array([1, 3]))
    st.keep(np.array([0, 2, 4]))
    arrival = _slot_state([2], ids=[99]).take(np.array([0]))
    assert st.append([arrival]) == 1
    k.moved(np.array([0, 2, 4]), 1)
    assert list(k.origin) == [4, 2, 0, -1]
    # the ghosts' sources: GPU row 4 and the arrival (nothing to ask for it)
    k.sending(st, np.array([0, 3]))
    assert fetched[-1] == ([4], ("v", "omega")) and list(st.omega[0]) == [4, 1, 7]
    # a second round: the arrival leaves again (nothing to pack), GPU row 2 leaves; part comes back
    k.leaving(st, np.array([1, 3]))
    assert packed == [[3, 1], [2]] and fetched[-1][0] == [2]
    st.keep(np.array([0, 2]))
    assert st.append([part]) == 2
    k.moved(np.array([0, 2]), 2)
    origin, start, pid, ds = k.arrivals(st)
    assert list(origin) == [4, 0, -1, -2] and origin.dtype == np.int32
    assert list(st.id[:4]) == [14, 10, 13, 11]
    # the two arrivals (ids 13, 11: GPU rows 3, 1) with the slots packed from them
    assert list(start) == [0, 2, 4] and list(pid) == [50, 51, 50, 51]
    assert not np.signbit(ds).any()


def test_no_gpu_ends_a_run_in_one_line(tmp_path):
    """Without a usable GPU (none visible), ``--device gpu`` is one line and exit status 1."""
    env = {"NUMBA_ENABLE_CUDASIM": "0", "CUDA_VISIBLE_DEVICES": ""}
    r = pour(tmp_path / "r", "run.max_steps=10", "engine.device=gpu", check=1, env=env)
    assert "engine.device = 'gpu'" in r.stderr and "Traceback" not in r.stderr, r.stderr[-2000:]
    # refused before any work: no run directory made (no bed, no state file, no lock left behind)
    assert not (tmp_path / "r").exists()
    # a directory that was there stays, as it was
    (tmp_path / "kept").mkdir()
    (tmp_path / "kept" / "notes.txt").write_text("mine")
    pour(tmp_path / "kept", "run.max_steps=10", "engine.device=gpu", check=1, env=env)
    assert sorted(p.name for p in (tmp_path / "kept").iterdir()) == ["notes.txt"]


def test_a_stiffening_rung_on_the_gpu_is_the_cpu_rung(tmp_path):
    """``mpdem stiffen --device gpu``: the ramp's laws in the GPU's launches (each within one tread,
    a tread's first step, the ramp's end included, a step of its own), the CPU's digest. The progress
    line falls on the step before the ramp's end (64 here: treads of 16 steps), so a launch starts
    there."""
    pour(tmp_path / "soft", "run.max_steps=200", "contact.mu=0.5")
    rung = ["--k_n", "2e4", "--set", "run.max_steps=100", "--set", "stiffen.ramp_time=0.02",
            "--set", "stiffen.update_interval=0.005", "--set", "output.progress_every=63", "--quiet"]
    for dev in ("cpu", "gpu"):
        mpdem("stiffen", tmp_path / "soft", *rung, "--device", dev, "--out", tmp_path / dev, check=3)
    assert "over 64 steps" in (tmp_path / "gpu" / "log.txt").read_text()
    assert summary_digest(tmp_path / "gpu") == summary_digest(tmp_path / "cpu")


def test_a_position_that_is_not_finite_stops_the_steps_without_list_work():
    """As the CPU engine (test_quiet_steps.py): from the step whose drift made a position NaN, each
    step says so (z_min NaN) with no rebuild over it, in launches and step by step."""
    phys = CASES["mu0"]
    got = []
    for quiet in (False, True):
        eng, st = stepped(gpu.Engine, phys, 5, GRIDS[0])
        eng.sync_state()
        # a mobile sphere's velocity, in the rows a new engine takes up
        st.v[int(np.flatnonzero(st.fixed[:st.n_own] == 0)[0]), 2] = np.nan
        eng = gpu.Engine(st, phys, Domain(None), **GRIDS[0])
        eng.start_from_file()
        builds = eng.n_rebuilds
        infos = eng.run_quiet(3) if quiet else [eng.step(defer_kick=True) for _ in range(3)]
        assert all(np.isnan(i.z_min) for i in infos) and eng.n_rebuilds == builds
        got.append([(i.z_max, i.max_overlap) for i in infos])
    assert got[0] == got[1]


# L lanes of a warp a row in the launches (``engine.gpu_threads = "lanesL"``, pinned): two rows' groups a block in the
# first two, so that groups of one warp diverge (rows of different lengths); the first and the third rebuild inside the
# launches (the third with room for 8 entries at first, so that a rebuild overflows), the second between them
# through the host, with Hertz, the wall and a lid; the second, the third and the fourth (a thread a row) reduce the
# steps' values by warp shuffles (``engine.gpu_reductions = "warp"``)
LANE_GRIDS = ([dict(block=4, threads="lanes2", pinned=True, reductions="fused", drift="fused", rebuilds="launch"),
               dict(block=8, threads="lanes4", pinned=True, reductions="warp"),
               dict(block=8, threads="lanes8", pinned=True, reductions="warp", drift="fused", rebuilds="launch",
                    sort="device", list_capacity=8),
               dict(block=8, threads="row", pinned=True, reductions="warp", drift="fused", rebuilds="launch")]
              if runtime.SIMULATOR else
              [dict(block=128, threads="lanes2", pinned=True, reductions="fused", drift="fused", rebuilds="launch"),
               dict(block=256, threads="lanes4", pinned=True, reductions="warp"),
               dict(block=256, threads="lanes8", pinned=True, reductions="warp", drift="fused", rebuilds="launch",
                    sort="device", list_capacity=8),
               dict(block=128, threads="row", pinned=True, reductions="warp", drift="fused", rebuilds="launch")])


@pytest.mark.parametrize("grid, phys", [
    (0, physics(mu=0.5, gamma_t=20.0, skin=0.002)),
    (1, physics(mu=0.5, model="hertz", gamma_t=10.0, wall=True, planes=(Plane.lid(2.99),), skin=0.002)),
    (2, physics(mu=0.0, skin=0.002)),
    (3, physics(mu=0.5, gamma_t=20.0, skin=0.002))])
def test_lanes_a_row_give_every_step_record_and_the_bits_of_the_cpu(grid, phys):
    """``engine.gpu_threads = "lanesL"``: each ``StepInfo`` of ``run_quiet`` across list rebuilds (a skin of
    0.002 d; 27 spheres), the contact counts read between, the digest, the kinetic sums and the force ratio
    are the CPU engine's, with friction (the torques through the shuffles too) and without, Hooke and Hertz,
    the wall and a lid, rebuilds inside the launches or between them."""
    kw_gpu = LANE_GRIDS[grid]
    x, v, omega, fixed, L = tight_lattice(m=3)
    runs = []
    for engine, kw in ((cpu.Engine, {}), (gpu.Engine, kw_gpu)):
        st = State(np.arange(len(x)), x.copy(), 40 * v, 40 * omega, fixed.copy(), L, L)
        eng = engine(st, phys, Domain(None), **kw)
        eng.start()
        infos = []
        for _ in range(3):
            infos += eng.run_quiet(8)
            infos.append(eng.info._replace(n_contacts=eng.contacts()))
        infos.append(eng.step(keep_pairs=True))
        runs.append((eng, st, infos))
    (want, st_c, a), (got, st_g, b) = runs
    threads = kw_gpu["threads"]
    assert got.lanes == (int(threads[5:]) if threads.startswith("lanes") else 0)
    assert got.n_rebuilds == want.n_rebuilds >= 8
    assert (got.n_rebuilds_in_launch > 4) == (kw_gpu.get("rebuilds") == "launch")
    assert got.n_overflows > 0 or "list_capacity" not in kw_gpu
    for s, (p, q) in enumerate(zip(a, b)):
        assert p == q, f"record {s}: CPU {p}, GPU {q}"
    assert len(a) == len(b) == 28
    g = checkpoint.gather_state(st_g)
    assert int(g["count"].sum()) > 50 and (phys.law.mu == 0.0 or np.any(g["ds"] != 0.0)), "a pile in contact"
    assert checkpoint.digest(checkpoint.gather_state(st_c)) == checkpoint.digest(g)
    assert got.kinetic() == want.kinetic() and got.force_ratio() == want.force_ratio()


def test_lanes_need_the_pinned_launches_and_whole_groups_a_block():
    """"lanesL" without ``pinned``, or in a block of fewer than L threads, is one clear error before any work."""
    x, v, omega, fixed, L = tight_lattice(m=3)
    st = State(np.arange(len(x)), x, v, omega, fixed, L, L)
    with pytest.raises(ValueError, match="needs pinned = True"):
        gpu.Engine(st, physics(), Domain(None), threads="lanes4")
    with pytest.raises(ValueError, match="8 threads or more"):
        gpu.Engine(st, physics(), Domain(None), threads="lanes8", pinned=True, block=4, blocks=1)


# a module global, which the simulator swaps for its own in the kernels below
cuda = runtime.cuda


@pytest.mark.parametrize("block", [8, 64])
def test_the_warps_reductions_are_the_trees(block):
    """``reduce.drift_into_warp`` and ``contact_into_warp`` (engine.gpu_reductions = "warp") leave in their slots
    the extremes and the count of every thread's values, as the trees do: one warp of 8 threads, and two of
    32 (the block's warps then reduced by thread 0)."""
    from mpdem.kernels.gpu import reduce

    @cuda.jit
    def both(vals, counts, tree, warp):
        room = cuda.shared.array(reduce.ROOM, np.float64)
        t = cuda.threadIdx.x
        reduce.drift_into(tree, 0, vals[t, 0], 1, vals[t, 1], 2, vals[t, 2], room)
        reduce.contact_into(tree, 3, vals[t, 0], 4, counts[t], room)
        reduce.drift_into_warp(warp, 0, vals[t, 0], 1, vals[t, 1], 2, vals[t, 2], room)
        reduce.contact_into_warp(warp, 3, vals[t, 0], 4, counts[t], room)

    rng = np.random.default_rng(block)
    vals = rng.normal(size=(block, 3))
    vals[block // 2 + 1, 1] = 7.5          # the largest in the second warp, or late in the first
    counts = rng.integers(0, 9, size=block)
    start = np.array([0.0, -np.inf, np.inf, 0.0, 0.0])
    tree, warp = cuda.to_device(start.copy()), cuda.to_device(start.copy())
    both[1, block](cuda.to_device(vals), cuda.to_device(counts), tree, warp)
    want = [max(0.0, vals[:, 0].max()), vals[:, 1].max(), vals[:, 2].min(), max(0.0, vals[:, 0].max()),
            float(counts.sum())]
    assert list(warp.copy_to_host()) == list(tree.copy_to_host()) == want
