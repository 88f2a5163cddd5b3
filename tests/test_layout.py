"""The package layout (ARCHITECTURE.md): moved modules keep their old import paths."""
import ast
import json
import subprocess
import sys
from pathlib import Path

from mpdem._moved import MOVED

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "mpdem"


def test_every_old_path_gives_the_new_module_and_names_it():
    # a fresh interpreter, so that no old name is imported yet
    script = (
        "import importlib, json, sys, warnings\n"
        "from mpdem._moved import MOVED\n"
        "out = {}\n"
        "for old, new in MOVED.items():\n"
        "    with warnings.catch_warnings(record=True) as w:\n"
        "        warnings.simplefilter('always')\n"
        "        m = importlib.import_module(old)\n"
        "    out[old] = [m is importlib.import_module(new), m.__name__, m.__spec__.name,\n"
        "                [str(x.message) for x in w if x.category is DeprecationWarning]]\n"
        "from mpdem import simulation\n"
        "from mpdem.analysis.collect import collect\n"
        "from mpdem.build import read_table, write_table\n"
        "import mpdem.io.tables as t, mpdem.campaign.collect as c, mpdem.driver.simulation as s\n"
        "out['from'] = [simulation is s, collect is c.collect, read_table is t.read_table]\n"
        "print(json.dumps(out))\n")
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    out = json.loads(r.stdout)
    assert out.pop("from") == [True, True, True]
    assert set(out) == set(MOVED)
    for old, (same, name, spec, warned) in out.items():
        new = MOVED[old]
        assert same and name == new and spec == new, old
        assert warned == [f"{old} has moved to {new}; import it from there"], old


def test_the_code_itself_imports_no_old_path():
    # the finder is for users' scripts; inside the package every import names the new home
    for path in SRC.rglob("*.py"):
        old = [t for t in _imports(path) if t in MOVED]
        assert not old, f"{path}: imports {old}, now {[MOVED[t] for t in old]}"


# which packages a package may not import (ARCHITECTURE.md): files know nothing of runs or campaigns,
# one packing's measurements nothing of runs or campaigns, the run nothing of campaigns
FORBIDDEN = {
    "mpdem.kernels": ("mpdem.io", "mpdem.driver", "mpdem.analysis", "mpdem.campaign", "mpdem.engine"),
    "mpdem.io": ("mpdem.driver", "mpdem.analysis", "mpdem.campaign"),
    "mpdem.analysis": ("mpdem.driver", "mpdem.campaign"),
    "mpdem.driver": ("mpdem.campaign",),
}


def _imports(path):
    """Absolute names of the mpdem modules a source file imports (at any depth in the file)."""
    mod = ".".join(path.relative_to(SRC.parent).with_suffix("").parts)
    pkg = mod if path.name == "__init__.py" else mod.rsplit(".", 1)[0]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = pkg.split(".")
            if node.level:
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for a in node.names:
                yield f"{target}.{a.name}" if target in ("mpdem", "mpdem.io", "mpdem.driver", "mpdem.analysis",
                                                         "mpdem.campaign", "mpdem.kernels") else target
        elif isinstance(node, ast.Import):
            yield from (a.name for a in node.names)


def test_packages_import_only_downwards():
    for path in SRC.rglob("*.py"):
        mod = ".".join(path.relative_to(SRC.parent).with_suffix("").parts)
        for pkg, banned in FORBIDDEN.items():
            if mod == pkg or mod.startswith(pkg + "."):
                bad = [t for t in _imports(path) if any(t == b or t.startswith(b + ".") for b in banned)]
                assert not bad, f"{mod} imports {bad}"
