"""Initial configurations: rough bed, random insertion, initial velocities, the initial-state checks.

Everything here is serial and deterministic: random numbers come from
streams keyed by (seed, purpose) that do not depend on the rank count.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from .config import bed_seed, gamma_n_from_epsilon
from .decomp import Domain
from .engine.base import Physics
from .engine.cpu import Engine
from .errors import InputError
from .kernels.bundles import make_box
from .kernels.insert import rsa_batch, rsa_cells
from .kernels.particle import VOLUME as SPHERE_VOLUME
from .parallel import channel
from .state import State

STREAM_BED, STREAM_POUR, STREAM_VELOCITY = 1, 2, 3
# the streams of a tiled pour's tiles (``fill_tile``: one of each a tile)
STREAM_POUR_TILE, STREAM_VELOCITY_TILE = 4, 5
# candidates of one batch of the random insertion (``insert_random``): about a tenth of a second
RSA_BATCH = 1 << 17
# sphere-steps of one call of the bed-making settle between the caller's looks (``make_bed``)
SETTLE_ROW_STEPS = 2_000_000


def rng(seed, purpose):
    """The random stream of one purpose (bed, pour, velocity) for a seed."""
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, purpose])))


def insert_random(gen, n, L_x, L_y, z_lo, z_hi, obstacles=None, max_tries=2000, progress=None, batch=None):
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
    progress : callable or None
        Called as ``progress(placed, n)`` after every batch of candidates (a set-up's
        ``watch.Watch`` says progress and honours stop signals there).
    batch : int or None
        Candidates drawn and tried at a time (default ``RSA_BATCH``, about a tenth of a second of
        work). Any size gives the same centres: the candidates are one stream, consumed in order.

    Returns
    -------
    (n, 3) float64 centres, in insertion order.
    """
    out = np.zeros((n, 3))
    for done in rsa_batches(gen, out, make_box(L_x, L_y), np.array([0.0, 0.0, z_lo]),
                            np.array([L_x, L_y, z_hi - z_lo]), obstacles, max_tries, batch):
        if progress is not None:
            progress(done, n)
    return out


def rsa_batches(gen, out, box, lo, span, obstacles=None, max_tries=2000, batch=None):
    """Fill ``out`` ((n, 3), in place) with non-overlapping unit spheres by RSA, centres uniform in
    [lo, lo + span] [d] (periodic ``box``, ``kernels.bundles.make_box``), a batch of candidates at a
    time: a generator of the spheres placed after each batch (``insert_random``)."""
    n = len(out)
    obs = np.zeros((0, 3)) if obstacles is None else np.ascontiguousarray(obstacles, float)
    z_lo, z_hi = float(lo[2]), float(lo[2] + span[2])
    head, nxt, pos, m, geo = rsa_cells(obs, n, box, z_lo, z_hi)
    done, tried = 0, 0
    batch = max(1, min(int(RSA_BATCH if batch is None else batch), max(1024, 2 * n)))
    while done < n:
        if tried > max_tries * n:
            raise InputError(f"random insertion placed only {done} of {n} spheres after {tried} tries; "
                             f"lower pour.phi_i")
        cand = gen.random((batch, 3))
        done, m = rsa_batch(cand, out, done, head, nxt, pos, m, geo, box, lo, span)
        tried += batch
        yield done


@dataclass(frozen=True)
class PourTiles:
    """A pour's insertion region cut into tiles that are filled on their own (``pour.insertion =
    "tiles"``, docs/model.md 5.3): ``n`` = (n_x, n_y, n_z) tiles of ``w`` = (L_x / n_x, L_y / n_y,
    H / n_z) [d] over [0, L_x) x [0, L_y) x [z_lo, z_lo + H]. Where an axis has several tiles, the
    centres keep d / 2 from each face between two tiles (the periodic faces in x and y included), so
    that spheres of two tiles never overlap; H is raised by those gaps so that the space the centres
    may take holds the N spheres at phi_i. Tile k = (i_z n_y + i_y) n_x + i_x holds ``counts[k]``
    spheres, N split in proportion to the tiles' spaces, ids ``start[k]`` on; what it holds depends on
    (seed, k) alone, never on which rank fills it.
    """
    N: int
    L_x: float
    L_y: float
    z_lo: float
    H: float
    n: tuple
    counts: np.ndarray

    @property
    def w(self):
        return (self.L_x / self.n[0], self.L_y / self.n[1], self.H / self.n[2])

    @property
    def start(self):
        """First id of each tile's spheres, (T + 1,) int64 (the last: N)."""
        return np.concatenate([[0], np.cumsum(self.counts)]).astype(np.int64)

    def region(self, k):
        """Tile k's (origin, lo, span, period): its spheres' centres are ``origin + c`` with c in
        [lo, lo + span] in a periodic box of ``period`` ((2,): x and y) [d]."""
        nx, ny, nz = self.n
        iz, rem = divmod(k, nx * ny)
        iy, ix = divmod(rem, nx)
        wx, wy, wz = self.w
        origin, lo, span, period = np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(2)
        for a, (i, m, w, L) in enumerate(((ix, nx, wx, self.L_x), (iy, ny, wy, self.L_y))):
            if m == 1:      # the whole periodic axis
                lo[a], span[a], period[a] = 0.0, L, L
            else:           # a gap of d / 2 at both faces; a period that no two centres can wrap across
                origin[a], lo[a], span[a], period[a] = i * w, 0.5, w - 1.0, w + 1.0
        below, above = (0.5 if iz > 0 else 0.0), (0.5 if iz < nz - 1 else 0.0)
        lo[2] = self.z_lo + iz * wz + below
        span[2] = wz - below - above
        return origin, lo, span, period


def pour_tiles(N, L_x, L_y, z_lo, phi_i, tile):
    """The PourTiles of a pour of ``N`` spheres at ``phi_i`` above ``z_lo`` [d] in tiles of about
    ``tile`` d (``pour.tile``): as many whole tiles of at least that edge as the box and the
    insertion's height H (``insertion_height``) hold along each axis, at least one."""
    nx, ny = max(1, int(L_x // tile)), max(1, int(L_y // tile))
    nz = max(1, int(insertion_height(N, L_x, L_y, phi_i) // tile))
    ux = L_x if nx == 1 else L_x - nx
    uy = L_y if ny == 1 else L_y - ny
    # the centres' space: (ux uy) (H - (nz - 1)), holding N at phi_i
    H = insertion_height(N, ux, uy, phi_i) + (nz - 1)
    wz = H / nz
    space = np.array([wz - (0.5 if iz > 0 else 0.0) - (0.5 if iz < nz - 1 else 0.0) for iz in range(nz)])
    per_tile = np.repeat(space, nx * ny)
    cum = np.cumsum(per_tile)
    ends = np.floor(N * (cum / cum[-1])).astype(np.int64)
    ends[-1] = N
    counts = np.diff(np.concatenate([[0], ends]))
    return PourTiles(int(N), float(L_x), float(L_y), float(z_lo), float(H), (nx, ny, nz), counts)


def fill_tile(tiles, k, seed, K0, out, v_out, batch=None):
    """Fill tile ``k`` of ``tiles``: centres into ``out`` and velocities into ``v_out`` ((counts[k], 3)
    each, in place), from the streams of (``seed``, k) alone (``STREAM_POUR_TILE``,
    ``STREAM_VELOCITY_TILE``); the velocities' mean kinetic energy is ``K0`` within the tile. A
    generator of the spheres placed after each batch of candidates."""
    origin, lo, span, period = tiles.region(k)
    gen = tile_rng(seed, STREAM_POUR_TILE, k)
    yield from rsa_batches(gen, out, make_box(period[0], period[1]), lo, span, batch=batch)
    out[:, :2] += origin[:2]
    v_out[:] = initial_velocities(tile_rng(seed, STREAM_VELOCITY_TILE, k), len(out), K0)


def tile_rng(seed, purpose, k):
    """The random stream of tile ``k`` of a purpose for a seed."""
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, purpose, k])))


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


def make_bed(cfg, progress=None, net=None):
    """Build the rough bed by the recipe of docs/model.md 5.2.

    Settles ``settle_density * L_x * L_y`` frictionless spheres onto a flat
    frictionless floor at z = 0, cuts the slab of centres in
    [gap, gap + thickness], and shifts it so the lowest centre is at z = 0.
    On several ranks (``net``) they settle it together, each the spheres of its
    domain (the grid chosen for a layer this low: columns), and every rank gets
    the whole bed: the same bits as on one rank, as every run's.

    Parameters
    ----------
    cfg : Config
    progress : callable or None
        Takes a line of progress, after every short call of the settle (about
        ``SETTLE_ROW_STEPS`` sphere-steps, the bed's on one rank, in all) and of the
        insertion; the caller decides which to show (``watch.Watch`` shows one every
        half minute and honours stop signals there). On several ranks every rank calls
        it at the same points (a collective look may be made there).
    net : parallel.Channel, mpi4py communicator or None
        The ranks that make the bed together (collective); None is one rank.
    """
    net = channel(net)
    b, L_x, L_y = cfg.bed, cfg.box.L_x, cfg.box.L_y
    n = max(1, round(b.settle_density * L_x * L_y))
    gen = rng(bed_seed(cfg), STREAM_BED)
    h = insertion_height(n, L_x, L_y, 0.3)
    say = progress or (lambda line: None)
    x = insert_random(gen, n, L_x, L_y, 0.5, 0.5 + h,
                      progress=lambda done, want: say(f"bed: inserting {n} spheres to settle, {done} placed"))
    k_n = b.settle_k_n
    phys = Physics.of(k_n=k_n, k_t=0.0, gamma_n=gamma_n_from_epsilon(b.settle_epsilon, k_n),
                      gamma_t=0.0, mu=0.0, dt=1e-4 * math.sqrt(2e5 / k_n), skin=0.3,
                      gravity=1.0, floor=True)
    if net.parallel:
        dom = Domain(net, r_list=1.0 + phys.skin, grid="auto")
        still = np.zeros((n, 3))
        state = dom.scatter({"id": np.arange(n, dtype=np.int64), "x": x, "v": still, "omega": still.copy(),
                             "fixed": np.zeros(n, np.uint8)}, L_x, L_y)
    else:
        dom, state = Domain(None), State(np.arange(n), x, L_x=L_x, L_y=L_y)
    eng = Engine(state, phys, dom)
    eng.start()
    steps = int(math.ceil(b.settle_time / phys.dt))
    # the deferred half-kicks are completed every tenth of the settle (the bed's bits depend on
    # where), in calls short enough for the caller to look at signals and the clock between them
    tenth = max(1, steps // 10)
    per_call = max(1, SETTLE_ROW_STEPS // n)
    for done in range(0, steps, tenth):
        end = min(done + tenth, steps)
        for at in range(done, end, per_call):
            eng.run_quiet(min(per_call, end - at))
            if at + per_call < end:
                say(f"bed: settling {n} spheres, step {min(at + per_call, end)}/{steps}")
        eng.complete()
        say(f"bed: settling {n} spheres, step {end}/{steps}")
    xs = state.x[:state.n_own]
    if net.parallel:
        # the bed is a layer (some L_x L_y spheres), wanted whole on every rank: each rank's rows to all
        parts = net.allgather((state.id[:state.n_own].copy(), xs.copy()))
        ids = np.concatenate([p[0] for p in parts])
        xs = np.concatenate([p[1] for p in parts])[np.argsort(ids, kind="stable")]
    sel = (xs[:, 2] >= b.gap) & (xs[:, 2] <= b.gap + b.thickness)
    bed = xs[sel].copy()
    if len(bed) == 0:
        # every rank has the same bed: the same error on all of them together
        raise InputError("bed: the settled packing has no sphere in the cut slab; raise bed.settle_density",
                         agreed=net.parallel)
    bed[:, 2] -= bed[:, 2].min()
    # sort for a stable id order
    bed = bed[np.lexsort((bed[:, 0], bed[:, 1], bed[:, 2]))]
    ek = eng.kinetic()
    dom.free()
    return Bed(bed, note=f"settled {n} spheres for {b.settle_time:g} tau (E_k/N = {sum(ek) / n:.2e})")


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
