"""Sphinx configuration of the dolfinx_meshfree documentation site.

Build it with ``bash .ci/docs.sh`` (warnings are errors), or by hand from the repository root::

    .venv-a/bin/python docs/generate_results.py          # results pages from docs/results/data
    .venv-a/bin/python -m sphinx -W --keep-going -b html docs docs/_build/html

Pages are Markdown (myst-parser). Two kinds of pages are generated rather than typed:

* ``docs/demos/<name>.md``, one per demo script ``demos/<name>.py`` (not ``bench_*``, not
  ``*_common.py``), written here, at every build, from the script's header comment by
  ``generate_demo_pages.py``: they cannot go stale and are not committed (``docs/.gitignore``);
* ``docs/results/*.md``, rendered from the JSON under ``docs/results/data/`` by
  ``generate_results.py`` (``--run`` re-runs the demos that produce the JSON). They are
  committed: the JSON is the data of the site.

``docs/archive/`` (the hand-typed development log) is kept in the repository but is not part of
the site.
"""

from __future__ import annotations

import os
import pathlib
import sys

DOCS = pathlib.Path(__file__).resolve().parent
ROOT = DOCS.parent

# Autodoc imports the package; the checkout comes first (it is also installed in editable mode
# in .venv-a). One thread: the machine may be shared with a test run.
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(DOCS))
os.environ.setdefault("OMP_NUM_THREADS", "1")

import generate_demo_pages  # noqa: E402  (docs/generate_demo_pages.py)

generate_demo_pages.write_pages(ROOT / "demos", DOCS / "demos")

project = "dolfinx_meshfree"
author = "the dolfinx_meshfree developers"
copyright = "the dolfinx_meshfree developers"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
]

source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "archive", "results/data"]

# Markdown: headings get anchors for links such as guide/solvers.md#work-balanced-mpi.
myst_heading_anchors = 3

# API reference: the docstrings are Google style (Args:, Returns:, Raises:).
napoleon_google_docstring = True
napoleon_numpy_docstring = False
autodoc_member_order = "bysource"
autodoc_default_options = {"show-inheritance": False}

html_theme = "alabaster"
html_theme_options = {
    "description": "Mesh-free particle methods (EFG, SPH) coupled with DOLFINx finite elements",
    "page_width": "1180px",
    "sidebar_width": "240px",
    "fixed_sidebar": True,
}
html_title = "dolfinx_meshfree"
html_static_path = ["_static"]  # custom.css: wide tables scroll (alabaster loads it)
