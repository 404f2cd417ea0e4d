"""Sphinx configuration: nsdrake's documentation site (``sphinx-build -W docs docs/_build``).

Markdown (MyST) pages, the notebook stored without outputs and not executed here (the
tests execute it: tests/docs/test_tutorial.py), the API reference from the docstrings,
and the local extension docs/_ext/nsdrake_docs.py that renders port tables and the
scenario fields from the code. No intersphinx: the build works offline.
"""

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS.parent))
sys.path.insert(0, str(DOCS / "_ext"))

project = "nsdrake"
author = "the nsdrake authors"
copyright = "2026, the nsdrake authors"

extensions = [
    "myst_nb",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "nsdrake_docs",
]

source_suffix = {".md": "myst-nb", ".ipynb": "myst-nb"}
# docs/results/FAMILY/table.md: included by the nsdrake-results directive, not pages of their own
exclude_patterns = ["_build", "**/.ipynb_checkpoints", "results/**"]
myst_enable_extensions = ["colon_fence", "dollarmath"]
# Links to a page's sections by their heading ([…](page.md#the-contract)).
myst_heading_anchors = 3
nb_execution_mode = "off"

autodoc_member_order = "bysource"
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False}
autodoc_typehints = "description"
napoleon_google_docstring = True
napoleon_numpy_docstring = False

html_theme = "furo"
html_title = "nsdrake"
html_static_path = ["_static"]
