"""Sphinx configuration: nsdrake's documentation site (``sphinx-build -W docs docs/_build``).

Markdown (MyST) pages, the notebooks of docs/tutorials/ stored without outputs and
executed here (their outputs are the site's; tests/docs/test_tutorial.py runs them too and
checks what they show against physics), the API reference from the docstrings,
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
# Every notebook (docs/tutorials/*.ipynb, stored without outputs) runs at build, in a fresh
# kernel of this Python, in a temporary folder; its outputs (plots, printed figures) are
# what the site shows. A cell that raises, or runs longer than the timeout, fails the
# build. About 10 s per notebook once the kernels are compiled (.ci/run builds the docs
# after the tests, which compile them); the first run after an install compiles them.
nb_execution_mode = "force"
nb_execution_timeout = 900
nb_execution_raise_on_error = True
nb_execution_show_tb = True
nb_execution_in_temp = True
# A notebook's log lines (Meshcat's "listening at http://localhost:7000", a link dead on the
# site) are not shown; an error still fails the build.
nb_output_stderr = "remove"

autodoc_member_order = "bysource"
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False}
autodoc_typehints = "description"
napoleon_google_docstring = True
napoleon_numpy_docstring = False

html_theme = "furo"
html_title = "nsdrake"
html_static_path = ["_static"]
# Tables: a port or field name never breaks (the table scrolls instead), display math apart.
html_css_files = ["nsdrake.css"]
