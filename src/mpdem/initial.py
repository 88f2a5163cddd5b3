"""The initial state of a new run: poured onto a bed, or read from a file.

``particles`` reads a particle file of any kind mpdem takes (a text table,
an mpdem state file, a LAMMPS data file or dump); the runs and the bench
share it. ``initial_state`` builds the whole state of a new run (every rank
alike) with the pile's geometry, which the run keeps for its checks.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from . import bedcache, build, state, stiffen
from .errors import InputError
from .watch import Watch
from .io import tables
from .io import checkpoint, lammps, packing
from .io.pilefile import file_facts


@dataclass
class Pile:
    """The pile's geometry, fixed at the start (a restart record of the run).

    Attributes
    ----------
    z_bed : float
        Highest bed centre [d] (-inf without a bed).
    z_bed_mean : float
        Mean bed height [d]: a mobile sphere below it fell through.
    h_insert : float
        Height of the insertion region [d] (escape check).
    """
    z_bed: float = -math.inf
    z_bed_mean: float = -math.inf
    h_insert: float = 0.0


@dataclass
class Initial:
    """A new run's whole initial state (the same on every rank).

    Attributes
    ----------
    whole : dict of arrays
        ``Domain.scatter``'s input, a state-array dict: the ``state.INITIAL``
        fields id (N,), x, v, omega (N, 3), fixed (N,) uint8; from a state
        file also its contact history (``Field.history``: count, partner, ds,
        and wall_ds (N, 3) when it has them and the run has the wall).
    pile : Pile
    n_mobile, n_bed : int
    shared : bool
        ``whole`` holds this rank's share of the rows only (a tiled pour, ``pour_tiled``): together the
        ranks hold each row once (``Domain.distribute``'s input), ids mobile first, then the bed's.
    bed : build.Bed or None
        The bed of a pour (every rank holds it whole).
    """
    whole: dict
    pile: Pile
    n_mobile: int
    n_bed: int
    shared: bool = False
    bed: object = None


def particles(path, cfg, all_fixed=False, lammps_table=None, log=print):
    """The particles of a file, whatever its kind.

    Parameters
    ----------
    path : str
        Text table (``tables.read_table``), mpdem state file, packing file
        (``from_packing``), or LAMMPS data file or text dump (``lammps.read``,
        types from ``run.fixed_types``).
    cfg : Config
    all_fixed : bool
        Every particle is a bed sphere (``bed.file``).
    lammps_table : dict or None
        The LAMMPS file, already read (``lammps.initial_for``).
    log : callable
        Takes a line about what was read.

    Returns
    -------
    A state-array dict: id (N,) int64, x, v, omega (N, 3) float64, fixed (N,)
    uint8 (``state.INITIAL``); from a state file also the contact history it
    has (``Field.history``: count, partner, ds, wall_ds).
    """
    if not os.path.exists(path):
        raise InputError(f"initial file {path}: no such file")
    if checkpoint.is_state_file(path):
        t, _ = checkpoint.read_state(path)
    elif packing.is_packing(path):
        t = from_packing(path, cfg, log)
    elif lammps.kind(path):
        t = lammps_table
        if t is None or all_fixed:
            t = lammps.read(path, () if all_fixed else cfg.run.fixed_types,
                            what="bed.file" if all_fixed else "run.initial_file")
        log(f"read {path}: {t['note']}" if all_fixed else
            f"read {path}: {t['note']}; {int(t['fixed'].sum())} bed spheres (types {list(cfg.run.fixed_types)})")
    else:
        t = tables.read_table(path)
    out = {f.name: t[f.name] for f in state.FIELDS if (f.initial or f.history) and f.name in t}
    if all_fixed:
        out["fixed"] = np.ones(len(out["id"]), np.uint8)
    elif len(out["fixed"]) and np.all(out["fixed"] == 1):
        how = f"of types {list(cfg.run.fixed_types)}" if lammps.kind(path) else "fixed = 1"
        raise InputError(f"initial file {path}: no mobile sphere: all {len(out['fixed'])} are bed "
                               f"spheres ({how})")
    return out


def check_file(cfg):
    """Refuse, before any work, a ``run.initial_file`` that is a packing file (``from_packing``) under
    friction.

    Raises
    ------
    InputError
        Naming the file, contact.mu and what is accepted.
    """
    path = cfg.run.initial_file
    if path and cfg.contact.mu > 0 and os.path.exists(path) and packing.is_packing(path):
        raise InputError(f"run.initial_file {path}: a packing file keeps no contact histories, so a frictional "
                         f"pile (contact.mu = {cfg.contact.mu:g}) would start with every tangential spring at zero"
                         f" and settle again; accepted: contact.mu = 0, or a state file (final.h5, a checkpoint)")


def config_for(cfg, net=None):
    """The config of a new run with its ``run.initial_file``'s box and sphere count, and a LAMMPS file's
    particles already read (``lammps.initial_for``).

    The file's pile is the run's: ``box.L_x``, ``box.L_y`` and ``pour.N`` (its mobile spheres, the count
    ``collect`` groups runs by) are taken from it where the user did not give them, and must agree with
    it where given. A text table keeps no box: the config's is used. Rank 0 of ``net`` reads what the
    file says, so every rank has the same config (collective).

    Returns
    -------
    (Config, dict or None)

    Raises
    ------
    ConfigError
        A given key that disagrees with the file, naming both values.
    InputError
        A file without a mobile sphere.
    """
    from .config import ConfigError
    from .errors import PackingFileError, StateFileError
    cfg, table = lammps.initial_for(cfg)
    path = cfg.run.initial_file
    catch = (InputError, StateFileError, PackingFileError)
    facts = net.on_root(file_facts, path, table, catch=catch) if net is not None else file_facts(path, table)
    if facts.get("pour.N") == 0:
        how = f"of types {list(cfg.run.fixed_types)}" if table is not None else "fixed = 1"
        raise InputError(f"initial file {path}: no mobile sphere: every sphere is a bed sphere ({how})")
    for key, value in facts.items():
        if key in cfg.given and cfg.values[key] != value:
            said = (f"run.initial_file {path} has {value!r} mobile spheres" if key == "pour.N"
                    else f"the box of {path} is {value!r} long in {key[-1]}")
            raise ConfigError(f"{key} = {cfg.values[key]!r}, but {said}; leave {key} unset to take the file's")
    missing = {k: v for k, v in facts.items() if k not in cfg.given and cfg.values[k] != v}
    if not missing:
        return cfg, table
    try:
        return cfg.replace(**missing), table
    except ConfigError as e:    # a file's box the config refuses (below 3 d): say where it came from
        raise ConfigError(f"{e} (from run.initial_file {path})") from None


def from_packing(path, cfg, log=print):
    """The particles of a packing file (``io.packing``, a run's kept ``packing.npz``), at rest.

    A packing keeps positions, ids and bed flags, not velocities nor contact histories: the spheres
    start at rest (a settled pile's speeds are of order sqrt(E_stop)) and every tangential spring at
    zero. Without friction (contact.mu = 0) no tangential force depends on a history, so the pile is
    the settled one; with friction its contacts carry no tangential load until they move, so the pile
    settles again, a change of protocol: refused unless ``contact.mu`` = 0.

    Returns
    -------
    dict: id (N,) int64, x, v, omega (N, 3) float64, fixed (N,) uint8.

    Raises
    ------
    InputError
        ``contact.mu`` > 0 (naming the file and the value).
    """
    check_file(cfg)
    arrays, _ = packing.read(path)
    x = np.ascontiguousarray(arrays["x"], dtype=np.float64)
    log(f"read {path}: a packing of {len(x)} spheres ({int(arrays['fixed'].sum())} bed), at rest (a packing keeps"
        f" no velocities)")
    return {"id": np.asarray(arrays["id"], np.int64), "x": x, "v": np.zeros_like(x), "omega": np.zeros_like(x),
            "fixed": np.asarray(arrays["fixed"], np.uint8)}


def bed(cfg, net, log, watch=None):
    """The frozen bed of a pour: from ``bed.file``, or made by the ranks together (or read by rank 0
    from the beds made before, ``bedcache``, and sent to all).

    ``watch`` (``watch.Watch``) sees the making of the bed between its short calls (progress, a
    stop signal agreed over the ranks, so that a stop there ends every rank at once).
    Warns when its areal density is outside [bed.density_min, bed.density_max].
    """
    watch = watch or Watch(log, net)
    if cfg.bed.file:
        b = build.Bed(particles(cfg.bed.file, cfg, all_fixed=True, log=log)["x"].copy(),
                      note=f"from {cfg.bed.file}")
    else:
        n = max(1, round(cfg.bed.settle_density * cfg.box.L_x * cfg.box.L_y))
        watch.begin("the making of the bed",
                    f"bed: making it on {net.size} rank(s), or reading it from the beds made before ({n} spheres "
                    f"settled for {cfg.bed.settle_time:g} tau)")
        # every rank makes it together, each looking at the signals with the others at the same points
        b = bedcache.made_bed(cfg, lambda line=None: watch(line, everywhere=True), net)
    dens = len(b.x) / (cfg.box.L_x * cfg.box.L_y)
    log(f"bed: {len(b.x)} frozen spheres, {dens:.3f} per d^2, z_bed = {b.z_top:.4f}; {b.note}")
    if not cfg.bed.density_min <= dens <= cfg.bed.density_max:
        log.warn(f"bed areal density {dens:.3f} per d^2 is outside "
                 f"[{cfg.bed.density_min:g}, {cfg.bed.density_max:g}]")
    return b


def pour(cfg, b, log, watch=None):
    """Mobile spheres inserted at random above bed ``b`` (docs/model.md 5.3): whole-state arrays.

    Every rank inserts the same spheres; ``watch`` (``watch.Watch``) sees every batch of candidates,
    on every rank together (progress, a stop signal agreed over the ranks)."""
    N, L_x, L_y = cfg.pour.N, cfg.box.L_x, cfg.box.L_y
    H = build.insertion_height(N, L_x, L_y, cfg.pour.phi_i)
    z0 = b.z_top + 1.0
    watch = watch or Watch(log, None)
    watch.begin("the pour's insertion", f"pour: inserting {N} spheres at phi_i = {cfg.pour.phi_i:g} in z in "
                                        f"[{z0:.3f}, {z0 + H:.3f}]")
    xm = build.insert_random(build.rng(cfg.run.seed, build.STREAM_POUR), N, L_x, L_y, z0, z0 + H, obstacles=b.x,
                             progress=lambda done, n: watch(lambda: f"pour: {done} of {n} spheres placed",
                                                            everywhere=True))
    vm = build.initial_velocities(build.rng(cfg.run.seed, build.STREAM_VELOCITY), N, cfg.pour.K0)
    return _poured_rows(np.arange(N + len(b.x), dtype=np.int64), xm, vm, b.x), H


def _poured_rows(ids, xm, vm, xb):
    """A state-array dict of a pour's rows: mobile centres ``xm`` and velocities ``vm`` (m, 3), then bed
    centres ``xb`` (k, 3) at rest, with ids ``ids`` (m + k,); omega zero."""
    m, k = len(xm), len(xb)
    x = np.concatenate([xm, xb])
    return {"id": ids, "x": x, "v": np.concatenate([vm, np.zeros((k, 3))]), "omega": np.zeros_like(x),
            "fixed": np.concatenate([np.zeros(m, np.uint8), np.ones(k, np.uint8)])}


def pour_tiled(cfg, b, net, log, watch=None):
    """This rank's share of a tiled pour (``pour.insertion = "tiles"``, docs/model.md 5.3) above bed
    ``b``: the tiles of ``build.pour_tiles`` in ``net.size`` runs of consecutive tiles, this rank's
    filled, and this rank's run of the bed's rows (ids N on, in the bed's order). A rank holds only
    its share: the set-up's memory does not grow with the pile's size at a fixed share.

    The ranks fill their tiles a batch of candidates a round, all together, each round ending with a
    look of ``watch`` on every rank (progress, the stop signals agreed) and the sum of the spheres
    placed and of the ranks still filling (one exact sum). Returns (rows, H) as ``pour``.
    """
    N, L_x, L_y = cfg.pour.N, cfg.box.L_x, cfg.box.L_y
    tiles = build.pour_tiles(N, L_x, L_y, b.z_top + 1.0, cfg.pour.phi_i, cfg.pour.tile)
    watch = watch or Watch(log, net)
    T, P, r = len(tiles.counts), (net.size if net is not None else 1), (net.rank if net is not None else 0)
    mine = range(T * r // P, T * (r + 1) // P)
    start = tiles.start
    lo, hi = int(start[mine.start]), int(start[mine.stop])
    watch.begin("the pour's insertion",
                f"pour: inserting {N} spheres at phi_i = {cfg.pour.phi_i:g} in {T} tiles of "
                f"{' x '.join(f'{w:.3g}' for w in tiles.w)} d ({' x '.join(map(str, tiles.n))}) in z in "
                f"[{tiles.z_lo:.3f}, {tiles.z_lo + tiles.H:.3f}], on {P} rank(s)")
    x, v = np.zeros((hi - lo, 3)), np.zeros((hi - lo, 3))

    def batches():
        placed = 0
        for k in mine:
            at = slice(int(start[k]) - lo, int(start[k + 1]) - lo)
            for done in build.fill_tile(tiles, k, cfg.run.seed, cfg.pour.K0, x[at], v[at]):
                yield placed + done
            placed += int(tiles.counts[k])

    work, placed, going, failed = batches(), 0, True, False
    while True:
        if going:
            try:
                placed = next(work, None)
            except InputError:      # a tile that cannot hold its spheres: said on every rank together
                failed, placed = True, None
            going = placed is not None
            placed = hi - lo if placed is None else placed
        here = np.array([int(going), placed, int(failed)])
        total = net.sum_int(here) if net is not None and net.parallel else here
        if total[2]:
            raise InputError(f"pour: a tile's random insertion could not place its spheres (pour.insertion = "
                             f"'tiles': {N} spheres in {T} tiles at pour.phi_i = {cfg.pour.phi_i:g}); lower "
                             f"pour.phi_i", agreed=net is not None and net.parallel)
        watch(f"pour: {int(total[1])} of {N} spheres placed", everywhere=True)
        if not total[0]:
            break
    nb = len(b.x)
    bed = range(nb * r // P, nb * (r + 1) // P)
    ids = np.concatenate([np.arange(lo, hi, dtype=np.int64), N + np.arange(bed.start, bed.stop, dtype=np.int64)])
    return _poured_rows(ids, x, v, b.x[bed.start:bed.stop]), tiles.H


def initial_state(cfg, net, log, lammps_table=None, watch=None):
    """A new run's initial state, checked (docs/model.md 8), identical on every rank (a tiled pour's:
    each rank's share, ``Initial.shared``).

    Parameters
    ----------
    cfg : Config
    net : parallel.Channel
        The ranks make the bed together (or rank 0 reads it from the beds made before and sends it).
    log : schedule.Logger
    lammps_table : dict or None
        A LAMMPS ``run.initial_file`` already read (``lammps.initial_for``).
    watch : watch.Watch or None
        Sees the set-up's short calls of work: progress lines, stop signals (``Interrupted``).

    Returns
    -------
    Initial
    """
    L_x, L_y = cfg.box.L_x, cfg.box.L_y
    if cfg.run.initial_file:
        # a settled pile met by a stiffer spring needs the ramp (docs/model.md 6.6)
        stiffen.check_initial(cfg, cfg.run.initial_file)
        p = particles(cfg.run.initial_file, cfg, lammps_table=lammps_table, log=log)
        fixed, x = p["fixed"], p["x"]
        b = build.Bed(x[fixed == 1].copy(), note=f"from {cfg.run.initial_file}")
        z_bed = float(x[fixed == 1, 2].max()) if fixed.any() else -math.inf
        zm = x[fixed == 0, 2]
        h_insert = float(zm.max() - max(z_bed, zm.min())) if len(zm) else 0.0
        # a given settled pile rests in the bed's hollows
        z_floor = b.z_mean
    else:
        b = bed(cfg, net, log, watch)
        tiled = cfg.pour.insertion == "tiles"
        p, h_insert = pour_tiled(cfg, b, net, log, watch) if tiled else pour(cfg, b, log, watch)
        fixed, x = p["fixed"], p["x"]
        z_bed = b.z_top
        z_floor = z_bed + 0.5
    # a pour overlaps nothing by construction (``kernels.insert``: a candidate closer than d to a placed
    # sphere or a bed sphere, in the minimum image, is refused), so its search for overlaps, the
    # longest part of the check, is left out
    poured = not cfg.run.initial_file
    build.check_initial(p["id"], x, fixed, L_x, L_y, z_floor, allow_overlap="count" in p or poured,
                        overlap_warn=cfg.checks.overlap_warn, warn=log.warn, wall=cfg.bed.wall)
    # the fields of this run: without the wall, a state file's wall histories are left out
    whole = {k: a for k, a in p.items() if state.optional_in(state.FIELD[k], {"wall": cfg.bed.wall})}
    n_bed = len(b.x)
    pile = Pile(z_bed=z_bed, z_bed_mean=b.z_mean if n_bed else -math.inf, h_insert=h_insert)
    if poured and cfg.pour.insertion == "tiles":
        return Initial(whole, pile, n_mobile=cfg.pour.N, n_bed=n_bed, shared=True, bed=b)
    return Initial(whole, pile, n_mobile=int((fixed == 0).sum()), n_bed=n_bed, bed=b)
