"""The documentation site (``make docs``, docs/reference.md): the reference documents every public name
of ``mpdem`` with its parameters. (The build itself, warnings as errors, is ``make docs``, which
``make test`` runs.)"""
import inspect
import re

import mpdem
from mpdem import api
from helpers import ROOT


def test_the_reference_documents_every_public_name():
    """docs/reference.md has an autodoc entry for each name of ``mpdem.__all__``, and each public
    function's docstring a Parameters section naming each of its parameters."""
    text = (ROOT / "docs" / "reference.md").read_text()
    documented = set(re.findall(r"^\.\. auto(?:function|class):: mpdem\.(\w+)$", text, re.M))
    assert documented == set(mpdem.__all__) - {"__version__"} == set(api.__all__)
    for name in documented:
        obj = getattr(mpdem, name)
        if inspect.isfunction(obj):
            doc = inspect.getdoc(obj)
            assert "Parameters\n----------" in doc and "Returns\n-------" in doc, name
            for param in inspect.signature(obj).parameters.values():
                shown = "**" + param.name if param.kind is param.VAR_KEYWORD else param.name
                assert re.search(rf"(^|[ ,]){re.escape(shown)}\b", doc, re.M), f"{name}: {param.name}"


def test_every_page_of_docs_is_in_the_site():
    """Each markdown file of docs/ is in a toctree of docs/index.md (Sphinx warns on one left out
    only when it is built; this names it before)."""
    index = (ROOT / "docs" / "index.md").read_text()
    listed = set(re.findall(r"^([a-z][\w-]*)$", index, re.M))
    pages = {p.stem for p in (ROOT / "docs").glob("*.md")} - {"index"}
    assert pages <= listed, pages - listed


def test_links_between_the_markdown_files_resolve():
    """Every relative link of the README, ARCHITECTURE, jobs/, examples/ and docs/ pages names a file
    that exists (the site's build does not check links out of docs/: docs/reference.md)."""
    pages = [ROOT / "README.md", ROOT / "ARCHITECTURE.md", ROOT / "jobs" / "README.md",
             ROOT / "examples" / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    broken = []
    for page in pages:
        text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)      # code blocks hold no links
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            path = target.split("#")[0]
            if path and not re.match(r"[a-z]+:", target) and not (page.parent / path).exists():
                broken.append(f"{page.relative_to(ROOT)}: {target}")
    assert not broken, broken
