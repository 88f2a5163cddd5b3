"""A run directory: its layout, file numbering, and where a restart starts.

::

    RUN/config.toml              resolved config (rewritten by a restart with --set)
    RUN/log.txt, RUN/thermo.csv  log and thermo table (continued by restarts)
    RUN/bed.txt                  the bed as a text table
    RUN/checkpoints/ckpt-NNNNN.h5    the newest output.checkpoint_keep checkpoints
    RUN/snapshots/snap-NNNNN.h5 (+ .xmf, series.xmf)   snapshots for analysis
    RUN/final.h5 (+ .xmf), RUN/summary.json            the end of the run

Everything here runs on one rank (rank 0 decides, or every rank reads the
same small files); collective reading is ``checkpoint``'s.
"""
from __future__ import annotations

import csv
import glob
import io
import math
import os
import re
import tomllib

import numpy as np

from . import config
from .checkpoint import StateFileError

CKPT_DIR, SNAP_DIR = "checkpoints", "snapshots"
# keys a restart may change with --set: none of them alters a step's arithmetic
MUTABLE = ("run.max_steps", "stop.", "checks.", "decomp.", "output.", "analysis.")


def write_atomic(path, chunks):
    """Write a string, or an iterable of strings, to ``path`` via ``path.tmp`` and a rename."""
    tmp = f"{path}.tmp"
    with open(tmp, "w") as fh:
        fh.writelines([chunks] if isinstance(chunks, str) else chunks)
    os.replace(tmp, path)


def _cell(v):
    """One CSV cell: full precision, empty for nan or None (not available)."""
    if v is None:
        return ""
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (float, np.floating)):
        return repr(float(v)) if math.isfinite(v) else ""
    if isinstance(v, np.integer):
        return str(int(v))
    return str(v)


def write_csv(path, header, rows):
    """Rows as CSV with a header line, written atomically (``write_atomic``)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows([[_cell(v) for v in row] for row in rows])
    write_atomic(path, buf.getvalue())


def checkpoint_path(run, k):
    return os.path.join(run, CKPT_DIR, f"ckpt-{k:05d}.h5")


def snapshot_path(run, k):
    return os.path.join(run, SNAP_DIR, f"snap-{k:05d}.h5")


def final_path(run):
    return os.path.join(run, "final.h5")


def _numbered(run, sub, prefix):
    out = []
    for p in glob.glob(os.path.join(run, sub, f"{prefix}-*.h5")):
        m = re.fullmatch(rf"{prefix}-(\d+)\.h5", os.path.basename(p))
        if m:
            out.append((int(m.group(1)), p))
    return sorted(out)


def checkpoints(run):
    """[(number, path)] of the run's checkpoints, oldest first (no .tmp files)."""
    return _numbered(run, CKPT_DIR, "ckpt")


def snapshots(run):
    return _numbered(run, SNAP_DIR, "snap")


def prune(run, keep):
    """Delete all but the newest ``keep`` checkpoints and any stale .tmp files."""
    for _, p in checkpoints(run)[:-keep]:
        os.remove(p)
    for p in glob.glob(os.path.join(run, CKPT_DIR, "*.tmp")):
        os.remove(p)


def clear(run):
    """Remove the outputs of an earlier run in ``run`` (a new run with --force)."""
    for p in ([p for _, p in checkpoints(run) + snapshots(run)]
              + glob.glob(os.path.join(run, CKPT_DIR, "*.tmp")) + glob.glob(os.path.join(run, SNAP_DIR, "*"))
              + [os.path.join(run, n) for n in ("final.h5", "final.xmf", "summary.json", "thermo.csv")]):
        if os.path.isfile(p):
            os.remove(p)


def candidates(target):
    """Files a restart of ``target`` may start from, newest first, and the run directory.

    A directory gives its checkpoints and final.h5, ordered by step (from
    the file attributes; a file whose attributes cannot be read is tried
    last). A file gives itself; its run directory is the parent of
    ``checkpoints/`` or the directory it is in.
    """
    from .checkpoint import read_attrs
    if os.path.isdir(target):
        run = target
        files = [p for _, p in checkpoints(run)]
        if os.path.exists(final_path(run)):
            files.append(final_path(run))
        if not files:
            raise StateFileError(f"{run}: no checkpoints/ckpt-*.h5 and no final.h5 to restart from")

        def step(p):
            try:
                return int(read_attrs(p)["step"])
            except (StateFileError, KeyError):
                return -1
        # newest first; at equal steps the final state (it knows the run ended)
        return sorted(files, key=lambda p: (step(p), p == final_path(run)), reverse=True), run
    if not os.path.exists(target):
        raise StateFileError(f"{target}: no such file or directory")
    d = os.path.dirname(os.path.abspath(target))
    run = os.path.dirname(d) if os.path.basename(d) in (CKPT_DIR, SNAP_DIR) else d
    return [target], run


def restart_config(attrs, path, run, sets):
    """The config of a restart: the file's, checked against RUN/config.toml, with --set.

    Raises StateFileError when the run directory's config differs from the
    checkpoint's in a key that changes the arithmetic, and ConfigError when
    --set tries to change such a key.
    """
    try:
        # the keys derived in the run stay derived: a restart leaves config.toml as it was
        raw = config.raw_from_toml(attrs.get("config", ""), origin=path)
        cfg = config.resolve(raw)
    except (tomllib.TOMLDecodeError, config.ConfigError) as e:
        raise StateFileError(f"{path}: its config is unusable ({e})") from None
    ours = os.path.join(run, "config.toml")
    if os.path.exists(ours):
        try:
            mine = config.load(ours)
        except config.ConfigError as e:
            raise StateFileError(f"{ours}: {e}") from None
        diff = _fixed_keys_differing(cfg, mine)
        if diff:
            k = diff[0]
            raise StateFileError(f"{path} does not match {ours}: {k} = {cfg.values[k]!r} in the checkpoint, "
                                 f"{mine.values[k]!r} in the run directory ({len(diff)} keys differ); "
                                 f"restart from a checkpoint of this run")
    if sets:
        new = config.load(None, sets, base=raw)
        bad = _fixed_keys_differing(new, cfg)
        if bad:
            raise config.ConfigError(
                f"--set {bad[0]}={new.values[bad[0]]!r}: a restart can change only {', '.join(m.rstrip('.') for m in MUTABLE)}; "
                f"to continue with other physics start a new run with --set run.initial_file={path}")
        cfg = new
    return cfg


def _fixed_keys_differing(a, b):
    """Keys outside MUTABLE whose values differ between two Configs."""
    return [k for k in config.KEYS if not k.startswith(MUTABLE) and a.values[k] != b.values[k]]


def truncate_thermo(path, step):
    """Drop thermo rows after ``step`` (written after the checkpoint a restart starts from)."""
    if not os.path.exists(path):
        return
    with open(path) as fh:
        lines = fh.readlines()
    width = lines[0].count(",") if lines else 0
    # whole rows only (a kill may have cut the last one), up to the checkpoint's step
    keep = lines[:1] + [ln for ln in lines[1:] if ln.endswith("\n") and ln.count(",") == width
                        and ln.split(",", 1)[0].isdigit() and int(ln.split(",", 1)[0]) <= step]
    write_atomic(path, keep)
