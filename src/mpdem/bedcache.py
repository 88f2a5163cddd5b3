"""Beds made once: a bed made by ``build.make_bed`` kept on disk and read back by later runs.

Making the rough bed (docs/model.md 5.2) settles some thousands of spheres for 40 tau:
seconds on a small box, half a minute on the paper's 20 d x 20 d, the same bits every
time for the same values. A sweep's rows, a series of runs on one box and the test
suite make the same beds over and over; this keeps each one, under a key of everything
it is a function of:

- the bed-making keys (``bed.thickness``, ``bed.gap``, ``bed.settle_*``), the box's
  L_x and L_y, and the bed's seed (``config.bed_seed``);
- the source of every module of mpdem (any change of the code makes new keys) and the
  versions of numpy and numba.

The directory is ``$MPDEM_BED_CACHE`` if set (``off`` or ``0``: no cache), else
``$XDG_CACHE_HOME/mpdem/beds`` (``~/.cache/mpdem/beds``). A bed is written to a
temporary name and renamed, so a reader sees a whole file or none; a file that cannot
be read, or does not hold a bed, is made again and replaced. A cache that cannot be
written changes nothing but the time.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np

from . import build
from .config import bed_seed
from .parallel import channel

ENV = "MPDEM_BED_CACHE"
# the bed keys make_bed reads (bed.seed through config.bed_seed)
MAKING_KEYS = ("thickness", "gap", "settle_density", "settle_k_n", "settle_epsilon", "settle_time")

_source = None


def _source_digest():
    """sha256 of every module of the mpdem package (paths and contents), computed once."""
    global _source
    if _source is None:
        root = Path(__file__).parent
        h = hashlib.sha256()
        for p in sorted(root.rglob("*.py")):
            h.update(str(p.relative_to(root)).encode() + b"\0" + p.read_bytes() + b"\0")
        _source = h.hexdigest()
    return _source


def key(cfg):
    """The cache key of the bed ``cfg`` makes (hex)."""
    import numba
    values = [(k, getattr(cfg.bed, k)) for k in MAKING_KEYS]
    h = hashlib.sha256(repr((values, cfg.box.L_x, cfg.box.L_y, bed_seed(cfg), np.__version__,
                              numba.__version__)).encode())
    h.update(_source_digest().encode())
    return h.hexdigest()[:32]


def directory():
    """The cache's directory, or None when ``$MPDEM_BED_CACHE`` turns it off."""
    where = os.environ.get(ENV)
    if where is not None:
        return None if where.strip().lower() in ("", "0", "off", "no", "false") else Path(where)
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "mpdem" / "beds"


def _read(path):
    """The Bed kept at ``path``, or None if there is none or it does not hold one."""
    try:
        with np.load(path, allow_pickle=False) as f:
            x, note = f["x"], str(f["note"])
    except Exception:   # not a whole npz of a bed, whatever numpy or zipfile says: made again
        return None
    if x.dtype != np.float64 or x.ndim != 2 or x.shape[1] != 3 or not len(x) or not np.all(np.isfinite(x)):
        return None
    return build.Bed(x, note=note)


def _write(path, bed):
    """Keep ``bed`` at ``path`` (a temporary name, then renamed); quietly nothing if it cannot."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(tmp, "wb") as fh:
            np.savez(fh, x=bed.x, note=np.array(bed.note))
        os.replace(tmp, path)
    except OSError:
        try:
            tmp.unlink()
        except OSError:
            pass


def made_bed(cfg, progress=None, net=None):
    """The bed of ``build.make_bed(cfg, progress, net)``, read from the cache when it was made before
    with the same values and code, else made (by the ranks of ``net`` together: collective) and kept
    there. Rank 0 alone reads and writes the cache; every rank gets the bed."""
    net = channel(net)
    kept = path = None
    if net.rank == 0:       # rank 0's environment decides where the cache is, for every rank
        where = directory()
        path = None if where is None else where / f"bed-{key(cfg)}.npz"
        bed = _read(path) if path is not None and path.exists() else None
        kept = None if bed is None else (bed.x, f"{bed.note}; kept from its first making ({path})")
    if net.parallel:
        kept = net.bcast(kept)
    if kept is not None:
        return build.Bed(*kept)
    bed = build.make_bed(cfg, progress=progress, net=net)
    if path is not None:
        _write(path, bed)
    return bed
