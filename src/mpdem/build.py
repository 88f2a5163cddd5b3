"""Initial configurations: rough bed, random insertion, initial files.

Everything here is serial and deterministic: random numbers come from
streams keyed by (seed, purpose) that do not depend on the rank count.
"""
from __future__ import annotations

import gzip
import math
import warnings
from dataclasses import dataclass

import numpy as np

from .config import gamma_n_from_epsilon
from .decomp import Domain
from .engine import Engine, Physics
from .errors import InputError
from .kernels.bundles import make_box
from .kernels.insert import rsa_insert
from .kernels.particle import VOLUME as SPHERE_VOLUME
from .rundir import write_atomic
from .state import INITIAL, State

STREAM_BED, STREAM_POUR, STREAM_VELOCITY = 1, 2, 3


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
        done = rsa_insert(cand, obs, out, done, make_box(L_x, L_y), z_lo, z_hi)
        tried += batch
    return out


def insertion_height(n, L_x, L_y, phi_i):
    """H = N pi d^3 / (6 L_x L_y phi_i) [d] (docs/model.md 5.3)."""
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
    """Build the rough bed by the recipe of docs/model.md 5.2.

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
    eng.start()
    steps = int(math.ceil(b.settle_time / phys.dt))
    chunk = max(1, steps // 10)
    for done in range(0, steps, chunk):
        eng.advance(min(chunk, steps - done))
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


def _open_text(path):
    """A text file handle of ``path``, decompressing gzip (magic bytes 1f 8b).

    Raises
    ------
    InputError for a file named ``.gz`` that is not gzip-compressed.
    """
    with open(path, "rb") as fh:
        magic = fh.read(2)
    if magic == b"\x1f\x8b":
        return gzip.open(path, "rt")
    if str(path).endswith(".gz"):
        raise InputError(f"{path}: named .gz but not gzip-compressed (it begins {magic!r}, gzip begins "
                         f"b'\\x1f\\x8b'); compress it with gzip or drop the .gz")
    return open(path)


def read_table(path):
    """Read a text table of particles.

    Columns ``id x y z`` with optional ``vx vy vz``, ``omegax omegay omegaz``
    and ``fixed`` (1 = bed). A first line naming the columns (``#``
    optional) sets their order; without it, 4, 5, 7 or 8 columns are read
    as id x y z [vx vy vz] [fixed].

    A gzip-compressed table (any name; recognised by its magic bytes) is
    read the same way.

    Returns
    -------
    dict with id (N,) int64, x (N, 3), v (N, 3), omega (N, 3) (zero when
    not in the table), fixed (N,) uint8.
    """
    try:
        with _open_text(path) as fh:
            lines = [ln for ln in fh if ln.strip()]
    except (OSError, EOFError, UnicodeDecodeError) as e:
        raise InputError(f"{path}: cannot read the particle table: {e}") from None
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
    known = {"id", "x", "y", "z", "vx", "vy", "vz", "omegax", "omegay", "omegaz", "fixed"}
    unknown = set(names) - known
    if unknown or not {"id", "x", "y", "z"} <= set(names):
        raise InputError(f"{path}: columns {names}; need id x y z, optional vx vy vz omegax omegay omegaz fixed")
    col = {n: data[:, i] for i, n in enumerate(names)}
    if not np.all(np.isfinite(data)):
        raise InputError(f"{path}: non-finite values in the particle table")
    ids = particle_ids(col["id"], path)
    n = len(ids)
    v = np.zeros((n, 3))
    omega = np.zeros((n, 3))
    for a, nm in enumerate(("vx", "vy", "vz")):
        if nm in col:
            v[:, a] = col[nm]
        if "omega" + "xyz"[a] in col:
            omega[:, a] = col["omega" + "xyz"[a]]
    fixed = col.get("fixed", np.zeros(n))
    if np.any((fixed != 0) & (fixed != 1)):
        raise InputError(f"{path}: column fixed must be 0 or 1")
    return {"id": ids, "x": np.stack([col["x"], col["y"], col["z"]], axis=1), "v": v, "omega": omega,
            "fixed": fixed.astype(np.uint8)}


def particle_ids(values, path):
    """Particle ids read as floats, checked: non-negative integers, each once. (N,) int64."""
    if np.any(values != np.round(values)) or np.any(values < 0):
        raise InputError(f"{path}: ids must be non-negative integers")
    ids = values.astype(np.int64)
    if len(np.unique(ids)) != len(ids):
        raise InputError(f"{path}: duplicate particle ids")
    return ids


def write_table(path, ids, x, v=None, fixed=None, omega=None):
    """Write a particle table readable by ``read_table`` (exact: repr of doubles);
    with ``omega``, the columns omegax omegay omegaz too. Atomic: written to
    ``path.tmp``, then renamed."""
    n = len(ids)
    v = np.zeros((n, 3)) if v is None else v
    fixed = np.zeros(n, np.uint8) if fixed is None else fixed

    def lines():
        yield "# id x y z vx vy vz" + (" omegax omegay omegaz" if omega is not None else "") + " fixed\n"
        for k in range(n):
            row = [float(a) for a in (*x[k], *v[k], *(omega[k] if omega is not None else ()))]
            yield f"{int(ids[k])} " + " ".join(map(repr, row)) + f" {int(fixed[k])}\n"
    write_atomic(path, lines())


def tile_table(table, L_x, L_y, nx, ny):
    """Copies of an x-y periodic particle table side by side: nx along x, ny along y.

    Parameters
    ----------
    table : dict
        ``read_table``'s arrays: id (N,) int64, x (N, 3) [d], v (N, 3)
        [sqrt(g d)], fixed (N,) uint8, in a box periodic in [0, L_x) x [0, L_y).
    L_x, L_y : float
        The table's box [d].
    nx, ny : int
        Copies along x and y, >= 1.

    Returns
    -------
    dict like ``table`` with nx * ny * N rows in a box nx L_x by ny L_y:
    copy k = j nx + i is shifted by (i L_x, j L_y, 0) and its ids by
    k (max id + 1), so copy 0 keeps the table's ids and all ids are unique.
    """
    if nx < 1 or ny < 1:
        raise InputError(f"tiling {nx} x {ny}: accepted at least one copy along x and y")
    x0 = table["x"].copy()
    x0[:, 0] %= L_x
    x0[:, 1] %= L_y
    k = np.arange(nx * ny)
    shift = np.stack([(k % nx) * L_x, (k // nx) * L_y, np.zeros(nx * ny)], axis=1)   # (K, 3)
    span = int(table["id"].max(initial=-1)) + 1
    # every field of the table copied as it is, then ids and positions shifted
    out = {k: np.tile(table[k], (nx * ny,) + (1,) * (np.ndim(table[k]) - 1)) for k in INITIAL if k in table}
    out["id"] = (table["id"][None, :] + span * k[:, None]).reshape(-1)
    out["x"] = (x0[None, :, :] + shift[:, None, :]).reshape(-1, 3)
    return out


def check_initial(ids, x, fixed, L_x, L_y, z_floor, allow_overlap=False, overlap_warn=0.0, warn=None,
                  wall=False):
    """docs/model.md section 8, initial-state checks; raises InputError naming the problem.

    Parameters
    ----------
    ids : (N,) int64
    x : (N, 3) float64
        Centres [d].
    fixed : (N,) uint8
        1 for bed spheres (bed-bed pairs are not checked).
    L_x, L_y : float
        Periodic box [d]; mobile centres must lie in [0, L_x) x [0, L_y).
    z_floor : float
        The lowest allowed mobile centre [d]: z_bed + d/2 for a poured pile,
        the mean bed height for a given file (a settled pile rests in the
        bed's hollows).
    allow_overlap : bool
        Skip the overlap test, for mpdem state files (a settled pile
        overlaps by design, and the file carries its contact histories).
    overlap_warn : float
        Overlaps delta = d - r up to this depth [d] are accepted with one
        warning naming the largest (a settled table: ``checks.overlap_warn``);
        a deeper one is an error naming the pair. 0 refuses any overlap.
    warn : callable or None
        Takes the warning line; default ``warnings.warn``.
    wall : bool
        The run has the wall plane z = 0 (``bed.wall``): mobile spheres may
        be below the bed, but not in the wall deeper than ``overlap_warn``.
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
    if wall:
        low = xm[:, 2] < 0.5 - overlap_warn
        if low.any():
            k = np.flatnonzero(mob)[np.argmin(xm[:, 2])]
            raise InputError(f"initial state: particle {ids[k]} at z = {float(x[k, 2])!r} overlaps the wall plane "
                             f"z = 0 by {0.5 - float(x[k, 2]):.6g} d; accepted up to checks.overlap_warn = "
                             f"{overlap_warn:g}")
    elif fixed.any():
        low = xm[:, 2] <= z_floor
        if low.any():
            k = np.flatnonzero(mob)[np.flatnonzero(low)[0]]
            raise InputError(f"initial state: particle {ids[k]} at z = {float(x[k, 2])!r} is not above "
                             f"{z_floor:g} (the bed); under a sparse bed, bed.wall = true puts a wall "
                             f"plane at z = 0 to rest on")
    if len(x) < 2 or not mob.any() or allow_overlap:
        return
    from .analysis import find_contacts
    pairs, r = find_contacts(x, L_x, L_y)
    bed_pair = (fixed[pairs[:, 0]] == 1) & (fixed[pairs[:, 1]] == 1)
    pairs, r = pairs[~bed_pair], r[~bed_pair]
    if not len(pairs):
        return
    k = int(np.argmin(r))
    i, j = pairs[k]
    depth = 1.0 - float(r[k])
    worst = f"particles {ids[i]} and {ids[j]} overlap by {depth:.6g} d"
    if depth > overlap_warn:
        raise InputError(f"initial state: {worst} ({len(pairs)} overlapping pairs in all); accepted "
                         f"overlaps up to checks.overlap_warn = {overlap_warn:g} d")
    (warn or warnings.warn)(f"initial state: {len(pairs)} overlapping pairs accepted (each at most "
                            f"checks.overlap_warn = {overlap_warn:g} d); the largest: {worst}")
