"""Initial configurations: rough bed, random insertion, initial files.

Everything here is serial and deterministic: random numbers come from
streams keyed by (seed, purpose) that do not depend on the rank count.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .config import gamma_n_from_epsilon
from .decomp import Domain
from .engine import Engine, Physics
from .kernels.insert import rsa_insert
from .state import State

STREAM_BED, STREAM_POUR, STREAM_VELOCITY = 1, 2, 3
SPHERE_VOLUME = math.pi / 6.0


class InputError(ValueError):
    """An initial configuration that cannot be run."""


def rng(seed, purpose):
    """The random stream of one purpose (bed, pour, velocity) for a seed."""
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, purpose])))


def insert_random(gen, n, L_x, L_y, z_lo, z_hi, obstacles=None, max_tries=2000):
    """Place n non-overlapping unit spheres uniformly in a box by RSA.

    Parameters
    ----------
    gen : numpy Generator
    n : int
    L_x, L_y, z_lo, z_hi : float
        Centres go in [0, L_x) x [0, L_y) x [z_lo, z_hi] [d].
    obstacles : (K, 3) array or None
        Spheres to avoid (the bed).
    max_tries : int
        Give up after ``max_tries * n`` candidates.

    Returns
    -------
    (n, 3) float64 centres, in insertion order.
    """
    out = np.zeros((n, 3))
    obs = np.zeros((0, 3)) if obstacles is None else np.ascontiguousarray(obstacles, float)
    done, tried, batch = 0, 0, max(1024, 2 * n)
    while done < n:
        if tried > max_tries * n:
            raise InputError(f"random insertion placed only {done} of {n} spheres after {tried} tries; "
                             f"lower pour.phi_i")
        cand = gen.random((batch, 3))
        done = rsa_insert(cand, obs, out, done, L_x, L_y, z_lo, z_hi)
        tried += batch
    return out


def insertion_height(n, L_x, L_y, phi_i):
    """H = N pi d^3 / (6 L_x L_y phi_i) [d] (physics.md 5.3)."""
    return n * SPHERE_VOLUME / (L_x * L_y * phi_i)


def initial_velocities(gen, n, K0):
    """Gaussian velocities rescaled to mean translational KE exactly K0 (m = 1)."""
    if K0 == 0 or n == 0:
        return np.zeros((n, 3))
    v = gen.normal(0.0, math.sqrt(2.0 * K0 / 3.0), (n, 3))
    ke = 0.5 * np.sum(v * v) / n
    return v * math.sqrt(K0 / ke)


@dataclass
class Bed:
    """Frozen bed spheres: centres (K, 3) [d] and the settle that made them."""
    x: np.ndarray
    note: str = ""

    @property
    def z_top(self):
        """z_bed: the highest bed centre [d] (0 without a bed)."""
        return float(self.x[:, 2].max()) if len(self.x) else 0.0

    @property
    def z_mean(self):
        return float(self.x[:, 2].mean()) if len(self.x) else -math.inf


def make_bed(cfg, progress=None):
    """Build the rough bed by the recipe of physics.md 5.2.

    Settles ``settle_density * L_x * L_y`` frictionless spheres onto a flat
    frictionless floor at z = 0, cuts the slab of centres in
    [gap, gap + thickness], and shifts it so the lowest centre is at z = 0.
    """
    b, L_x, L_y = cfg.bed, cfg.box.L_x, cfg.box.L_y
    n = max(1, round(b.settle_density * L_x * L_y))
    gen = rng(cfg.run.seed, STREAM_BED)
    h = insertion_height(n, L_x, L_y, 0.3)
    x = insert_random(gen, n, L_x, L_y, 0.5, 0.5 + h)
    k_n = b.settle_k_n
    phys = Physics(k_n=k_n, k_t=0.0, gamma_n=gamma_n_from_epsilon(b.settle_epsilon, k_n),
                   gamma_t=0.0, mu=0.0, dt=1e-4 * math.sqrt(2e5 / k_n), skin=0.3,
                   gravity=1.0, floor=True)
    state = State(np.arange(n), x, L_x=L_x, L_y=L_y)
    eng = Engine(state, phys, Domain(None))
    eng.setup()
    steps = int(math.ceil(b.settle_time / phys.dt))
    chunk = max(1, steps // 10)
    for done in range(0, steps, chunk):
        eng.run(min(chunk, steps - done))
        if progress:
            progress(f"bed: settling {n} spheres, step {min(done + chunk, steps)}/{steps}")
    xs = state.x[:n]
    sel = (xs[:, 2] >= b.gap) & (xs[:, 2] <= b.gap + b.thickness)
    bed = xs[sel].copy()
    if len(bed) == 0:
        raise InputError("bed: the settled packing has no sphere in the cut slab; raise bed.settle_density")
    bed[:, 2] -= bed[:, 2].min()
    # sort for a stable id order
    bed = bed[np.lexsort((bed[:, 0], bed[:, 1], bed[:, 2]))]
    ek = eng.kinetic()
    return Bed(bed, note=f"settled {n} spheres for {b.settle_time:g} tau (E_k/N = {sum(ek) / n:.2e})")


def read_table(path):
    """Read a text table of particles.

    Columns ``id x y z`` with optional ``vx vy vz`` and ``fixed`` (1 = bed).
    A first line naming the columns (``#`` optional) sets their order;
    without it, 4, 5, 7 or 8 columns are read as id x y z [vx vy vz] [fixed].

    Returns
    -------
    dict with ids (N,) int64, x (N, 3), v (N, 3), fixed (N,) uint8.
    """
    with open(path) as fh:
        lines = [ln for ln in fh if ln.strip()]
    if not lines:
        raise InputError(f"{path}: empty particle table")
    first = lines[0].lstrip("#").split()
    names = None
    try:
        [float(t) for t in first]
    except ValueError:
        names = [t.lower() for t in first]
        lines = lines[1:]
    lines = [ln for ln in lines if not ln.lstrip().startswith("#")]
    try:
        data = np.loadtxt(lines, ndmin=2) if lines else np.zeros((0, len(names or [0] * 4)))
    except ValueError as e:
        raise InputError(f"{path}: unreadable particle table: {e}") from None
    if names is None:
        names = {4: "id x y z", 5: "id x y z fixed", 7: "id x y z vx vy vz",
                 8: "id x y z vx vy vz fixed"}.get(data.shape[1], "").split()
        if not names:
            raise InputError(f"{path}: {data.shape[1]} columns; expected a header line or "
                             f"id x y z [vx vy vz] [fixed]")
    if len(names) != data.shape[1]:
        raise InputError(f"{path}: header names {len(names)} columns but rows have {data.shape[1]}")
    known = {"id", "x", "y", "z", "vx", "vy", "vz", "fixed"}
    unknown = set(names) - known
    if unknown or not {"id", "x", "y", "z"} <= set(names):
        raise InputError(f"{path}: columns {names}; need id x y z, optional vx vy vz fixed")
    col = {n: data[:, i] for i, n in enumerate(names)}
    if not np.all(np.isfinite(data)):
        raise InputError(f"{path}: non-finite values in the particle table")
    ids = col["id"]
    if np.any(ids != np.round(ids)) or np.any(ids < 0):
        raise InputError(f"{path}: ids must be non-negative integers")
    ids = ids.astype(np.int64)
    if len(np.unique(ids)) != len(ids):
        raise InputError(f"{path}: duplicate particle ids")
    n = len(ids)
    v = np.zeros((n, 3))
    for a, nm in enumerate(("vx", "vy", "vz")):
        if nm in col:
            v[:, a] = col[nm]
    fixed = col.get("fixed", np.zeros(n))
    if np.any((fixed != 0) & (fixed != 1)):
        raise InputError(f"{path}: column fixed must be 0 or 1")
    return {"ids": ids, "x": np.stack([col["x"], col["y"], col["z"]], axis=1), "v": v,
            "fixed": fixed.astype(np.uint8)}


def write_table(path, ids, x, v=None, fixed=None):
    """Write a particle table readable by ``read_table`` (exact: repr of doubles)."""
    n = len(ids)
    v = np.zeros((n, 3)) if v is None else v
    fixed = np.zeros(n, np.uint8) if fixed is None else fixed
    with open(path, "w") as fh:
        fh.write("# id x y z vx vy vz fixed\n")
        for k in range(n):
            row = [float(a) for a in (*x[k], *v[k])]
            fh.write(f"{int(ids[k])} " + " ".join(map(repr, row)) + f" {int(fixed[k])}\n")


def check_initial(ids, x, fixed, L_x, L_y, z_floor, allow_overlap=False):
    """physics.md section 8, initial-state checks; raises InputError naming the problem.

    ``z_floor`` is the lowest allowed mobile centre: z_bed + d/2 for a poured
    pile, the mean bed height for a given file (a settled pile rests in the
    bed's hollows). ``allow_overlap`` skips the overlap test, for mpdem
    state files (a settled pile overlaps by design).
    """
    if not np.all(np.isfinite(x)):
        raise InputError("initial state: non-finite positions")
    mob = fixed == 0
    xm = x[mob]
    bad = (xm[:, 0] < 0) | (xm[:, 0] >= L_x) | (xm[:, 1] < 0) | (xm[:, 1] >= L_y)
    if bad.any():
        k = np.flatnonzero(mob)[np.flatnonzero(bad)[0]]
        raise InputError(f"initial state: particle {ids[k]} at x = {float(x[k, 0])!r}, y = {float(x[k, 1])!r} "
                         f"is outside [0, {L_x:g}) x [0, {L_y:g})")
    if fixed.any():
        low = xm[:, 2] <= z_floor
        if low.any():
            k = np.flatnonzero(mob)[np.flatnonzero(low)[0]]
            raise InputError(f"initial state: particle {ids[k]} at z = {float(x[k, 2])!r} is not above "
                             f"{z_floor:g} (the bed)")
    from scipy.spatial import cKDTree
    if len(x) < 2 or not mob.any() or allow_overlap:
        return
    span = x[:, 2].max() - x[:, 2].min() + 10.0
    pts = x.copy()
    pts[:, 0] %= L_x
    pts[:, 1] %= L_y
    pts[:, 2] -= pts[:, 2].min()
    tree = cKDTree(pts, boxsize=[L_x, L_y, 2 * span])
    pairs = tree.query_pairs(1.0, output_type="ndarray")
    if len(pairs):
        keep = ~(fixed[pairs[:, 0]].astype(bool) & fixed[pairs[:, 1]].astype(bool))
        pairs = pairs[keep]
    if len(pairs):
        i, j = pairs[0]
        d = pts[i] - pts[j]
        d[0] -= L_x * round(d[0] / L_x)
        d[1] -= L_y * round(d[1] / L_y)
        r = float(np.sqrt(d @ d))
        if r < 1.0:
            raise InputError(f"initial state: particles {ids[i]} and {ids[j]} overlap by "
                             f"{1.0 - r:.6g} d ({len(pairs)} overlapping pairs in all)")
