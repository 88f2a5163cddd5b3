"""Sphinx configuration of mpdem's documentation site: the markdown of docs/ (MyST) and the API
reference generated from the numpy-style docstrings (autodoc + napoleon). Built by ``make docs``
(docs/reference.md says how and why Sphinx)."""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
# autodoc reads the package from the source tree: ``import mpdem`` and ``mpdem.api`` import nothing
# heavy (numpy, numba, MPI come in when a function is called), so the docs environment needs no mpdem
sys.path.insert(0, os.path.join(HERE, "..", "src"))

from mpdem import __version__  # noqa: E402

project = "mpdem"
author = "the mpdem authors"
release = version = __version__

extensions = ["sphinx.ext.autodoc", "sphinx.ext.napoleon", "myst_parser"]
source_suffix = {".md": "markdown"}
root_doc = "index"
# measurements/: dated records of one machine (their raw files beside them), read from the pages, not pages
exclude_patterns = ["_build", "measurements/**"]

# numpy-style docstrings (Parameters, Returns, Raises, Attributes sections)
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
autodoc_member_order = "bysource"
autodoc_typehints = "none"          # the docstrings name the types and their units

# "## 5.5 Flow arrest" headings get anchors, as GitHub gives them, so that docs/x.md#anchor links resolve
myst_heading_anchors = 4
myst_enable_extensions = ["dollarmath"]
# the pages link to files of the repository outside docs/ (src/..., jobs/README.md, tests/...): links
# GitHub follows and a site without those files cannot; they stay plain text here, not warnings
suppress_warnings = ["myst.xref_missing"]

html_theme = "alabaster"
html_title = f"mpdem {release}"
html_theme_options = {"description": "MPI-parallel DEM of granular sphere packings", "fixed_sidebar": True}
