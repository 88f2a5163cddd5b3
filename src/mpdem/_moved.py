"""Old import paths of modules that moved into packages keep working.

``import mpdem.checkpoint`` (or ``from mpdem import checkpoint``, or
``from mpdem.analysis.collect import collect``) gives the module at its new
home, the same module object, with a ``DeprecationWarning`` that names the
new path. The table ``MOVED`` is the one record of the moves (ARCHITECTURE.md,
module map); ``mpdem/__init__.py`` installs the finder.
"""
from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

# old name -> new name
MOVED = {
    **{f"mpdem.{m}": f"mpdem.io.{m}"
       for m in ("checkpoint", "export", "lammps", "lammps_input", "network", "packing", "rundir")},
    **{f"mpdem.{m}": f"mpdem.driver.{m}"
       for m in ("simulation", "schedule", "resume", "summary", "runstate")},
    "mpdem.sweep": "mpdem.campaign.sweep",
    **{f"mpdem.analysis.{m}": f"mpdem.campaign.{m}"
       for m in ("collect", "figures", "comparison", "paper", "runs", "pooled")},
}


class MovedFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds an old module name and loads it as the module at its new name."""

    def __init__(self):
        self._specs = {}   # old name -> the new module's own spec, between create and exec

    def find_spec(self, name, path=None, target=None):
        if name not in MOVED:
            return None
        return importlib.util.spec_from_loader(name, self)

    def create_module(self, spec):
        new = MOVED[spec.name]
        # level 2 is the importing line: warnings skips importlib's own frames
        warnings.warn(f"{spec.name} has moved to {new}; import it from there", DeprecationWarning, stacklevel=2)
        module = importlib.import_module(new)
        self._specs[spec.name] = module.__spec__
        return module

    def exec_module(self, module):
        # the import machinery gave the module the old name's spec: give it back its own
        module.__spec__ = self._specs.pop(module.__spec__.name)


def install():
    """Put the finder on ``sys.meta_path`` once."""
    if not any(isinstance(f, MovedFinder) for f in sys.meta_path):
        sys.meta_path.append(MovedFinder())
