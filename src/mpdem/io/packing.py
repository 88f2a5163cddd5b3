"""Packing files: what the analyses of a final state need, compressed (``RUN/packing.npz``).

A campaign keeps one per run beside its summaries, so that ``mpdem analyze``
and ``mpdem collect`` can measure it again after the state file is gone: the
positions, ids and bed flags of every sphere, the contact list with its forces
(ids, overlap, F_n, F_t), and the state file's attributes (config, box, step,
time, converged). Velocities, contact histories and checkpoint data are left
out: a packing file cannot restart a run.

Format: numpy ``.npz`` (zip, deflate), rows sorted by id; the attributes as
JSON in ``attrs``; ``format`` = "mpdem-packing", version 1. Written under
``<name>.tmp`` and renamed. Sizes: about 1.5 MB for a paper-size pile
(20 000 spheres, 60 000 contacts).
"""
from __future__ import annotations

import json
import zipfile

import numpy as np

from ..errors import PackingFileError
from .rundir import atomic, starts_with

FORMAT = "mpdem-packing"
VERSION = 1
FIELDS = {"id": np.int64, "x": np.float64, "fixed": np.uint8, "id_i": np.int64, "id_j": np.int64,
          "delta": np.float64, "F_n": np.float64, "F_t": np.float64}
SUFFIX = ".npz"


def is_packing(path):
    """True if ``path`` is a zip archive (a packing file, by its signature)."""
    return starts_with(path, b"PK\x03\x04")


def write(path, arrays, attrs):
    """Write the packing of a state (``checkpoint.read_state(..., pairs=True)``) to ``path``.

    Raises
    ------
    PackingFileError when the state has no contact list (a checkpoint).
    """
    if "id_i" not in arrays:
        raise PackingFileError(f"{path}: the state has no contact list (a checkpoint); a final state or a "
                               f"snapshot has one")
    meta = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in attrs.items()
            if not k.startswith("checksum_")}
    meta.update(format=FORMAT, version=VERSION, source_kind=attrs.get("kind"))
    data = {k: np.asarray(arrays[k], dtype=t) for k, t in FIELDS.items()}
    with atomic(path, "wb") as fh:
        np.savez_compressed(fh, attrs=np.array(json.dumps(meta, default=str)), **data)
    return path


def read_attrs(path):
    """The attributes of a packing file (its step, config, ...), without its arrays.

    Raises
    ------
    PackingFileError naming the file when it is not a packing file, or damaged.
    """
    try:
        with np.load(path, allow_pickle=False) as z:
            attrs = json.loads(str(z["attrs"])) if "attrs" in z.files else {}
    except (OSError, ValueError, KeyError, zipfile.BadZipFile, json.JSONDecodeError) as e:
        raise PackingFileError(f"{path}: unreadable as a packing file ({e})") from None
    if attrs.get("format") != FORMAT:
        raise PackingFileError(f"{path}: not an mpdem packing file")
    return attrs


def read(path):
    """(arrays, attrs) of a packing file, in the form of ``checkpoint.read_state(..., pairs=True)``
    for the fields it keeps.

    Raises
    ------
    PackingFileError naming the file when it is not a packing file of this version, or damaged.
    """
    try:
        with np.load(path, allow_pickle=False) as z:
            attrs = json.loads(str(z["attrs"])) if "attrs" in z.files else {}
            missing = [k for k in FIELDS if k not in z.files]
            if attrs.get("format") != FORMAT or missing:
                raise PackingFileError(f"{path}: not an mpdem packing file"
                                       + (f" (no {', '.join(missing)})" if missing else ""))
            if attrs.get("version") != VERSION:
                raise PackingFileError(f"{path}: packing file version {attrs.get('version')}; this mpdem "
                                       f"reads version {VERSION}")
            arrays = {k: z[k] for k in FIELDS}
    except (OSError, ValueError, KeyError, zipfile.BadZipFile, json.JSONDecodeError) as e:
        raise PackingFileError(f"{path}: unreadable as a packing file ({e})") from None
    return arrays, attrs
