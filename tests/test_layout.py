"""The package layout (ARCHITECTURE.md): imports point downwards, between packages and between modules."""
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "mpdem"


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


def _modules():
    """{module name: path} of every module of the package (a package by its name, not ``.__init__``)."""
    out = {}
    for path in SRC.rglob("*.py"):
        mod = ".".join(path.relative_to(SRC.parent).with_suffix("").parts)
        out[mod.removesuffix(".__init__")] = path
    return out


def _module_imports(mods, path):
    """The modules of the package that a file imports (a name imported from a package counts as its
    module when it is one, else as the package)."""
    out = set()
    for t in _imports(path):
        parts = t.split(".")
        while parts and ".".join(parts) not in mods:
            parts.pop()
        if parts:
            out.add(".".join(parts))
    return out


def test_no_module_imports_back_up():
    """The modules' imports (at any depth in a file, lazy ones included) form no cycle, no module
    imports the package ``mpdem`` itself (the version is ``mpdem._version``), and none calls
    ``__import__``: a module never reaches, however indirectly, one that imports it."""
    mods = _modules()
    graph = {m: _module_imports(mods, p) - {m} for m, p in mods.items()}
    for m, p in mods.items():
        if m != "mpdem":
            assert "mpdem" not in graph[m], f"{m} imports the package mpdem"
        assert "__import__(" not in p.read_text(), f"{m} calls __import__"
    graph["mpdem"] = set()      # the package's API functions load api.py on first use, downwards
    done, path = set(), []

    def visit(m):
        if m in path:
            raise AssertionError("an import cycle: " + " -> ".join(path[path.index(m):] + [m]))
        if m in done:
            return
        path.append(m)
        for n in sorted(graph[m]):
            visit(n)
        path.pop()
        done.add(m)
    for m in sorted(graph):
        visit(m)
