"""mpdem: MPI-parallel discrete-element simulator for sphere packings.

Reduced units throughout: particle diameter d = 1, mass m = 1, gravity g = 1.
The model is described in docs/model.md; the code map and its invariants in
ARCHITECTURE.md. The Python API (docs/python.md)::

    import mpdem
    cfg = mpdem.load_config(**{"pour.N": 200, "run.max_steps": 20000})
    r = mpdem.run(cfg, out="runs/small")
    a = mpdem.analyze(r.final)
    s = mpdem.read_state(r.final)

``load_config``, ``run``, ``restart``, ``stiffen_config``, ``read_state``, ``analyze``,
``collect`` (``mpdem.api``; the reference: docs/reference.md, ``make docs``); errors are
``mpdem.errors.MpdemError`` and its kinds.
"""
import hashlib
import os
from pathlib import Path

from ._version import __version__


def _numba_cache_dir():
    # numba does not recompile a cached kernel when a kernel it calls (in
    # another file) changes, so the cache is keyed by all kernel sources.
    h = hashlib.sha256()
    for p in sorted((Path(__file__).parent / "kernels").glob("*.py")):
        h.update(p.read_bytes())
    base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "mpdem" / "numba"
    return str(base / h.hexdigest()[:16])


os.environ.setdefault("NUMBA_CACHE_DIR", _numba_cache_dir())


API = ("load_config", "run", "restart", "stiffen_config", "read_state", "analyze", "collect", "RunRecord",
       "StateArrays")
__all__ = ["__version__", *API]


def __getattr__(name):
    # the API on first use: `import mpdem` stays light (no MPI, no numba) until a function is called
    if name in API:
        from . import api
        return getattr(api, name)
    raise AttributeError(f"module 'mpdem' has no attribute {name!r}")


def __dir__():
    # the lazily loaded API among the names, so that tab completion and dir() show it
    return sorted(set(globals()) | set(API))
