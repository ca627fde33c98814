"""Sphinx configuration of the glassdist site.

Strict build (what CI runs): ``bash scripts/build_docs.sh``, i.e.
``sphinx-build -W --keep-going -n -b html docs docs/_build/html``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS / "_ext"))
sys.path.insert(0, str(DOCS.parent / "src"))

import glassdist

os.environ.setdefault("MPLBACKEND", "Agg")

project = "glassdist"
author = "the glassdist authors"
copyright = "the glassdist authors"
release = glassdist.__version__
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "sphinxarg.ext",
    "sphinx_gallery.gen_gallery",
    "glassdist_docs",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
# option names stay as typed: no "--reference" turned into an en dash
smartquotes = False
# records/: the JSON records and the tables their scripts write; the validation pages are
# generated from them (_generated/), never read as pages themselves
exclude_patterns = ["_build", "_generated", "records", "_ext"]

# --- MyST ----------------------------------------------------------------------------------
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist", "attrs_inline"]
myst_heading_anchors = 4  # [text](page.md#a-heading) links are checked like any reference

# --- autodoc and numpydoc -------------------------------------------------------------------
autodoc_typehints = "none"  # the numpydoc sections state types and units; signatures stay readable
autodoc_member_order = "bysource"
autodoc_inherit_docstrings = False  # SQLAlchemy's and pydantic's own members stay theirs
autodoc_default_options = {"members": True, "undoc-members": False}
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set[str] = set()
numpydoc_class_members_toctree = False

# --- sphinx-gallery -------------------------------------------------------------------------
sphinx_gallery_conf = {
    "examples_dirs": str(DOCS.parent / "examples" / "gallery"),
    "gallery_dirs": "gallery",
    "filename_pattern": r"/plot_",
    "download_all_examples": False,
    "remove_config_comments": True,
    "reset_modules_order": "both",
    "within_subsection_order": "FileNameSortKey",
    "show_memory": False,
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
    "abort_on_example_error": True,
}

# --- HTML -----------------------------------------------------------------------------------
html_theme = "pydata_sphinx_theme"
html_title = f"glassdist {release}"
html_theme_options = {
    "navbar_align": "left",
    "show_toc_level": 2,
    "navigation_with_keys": False,
    "header_links_before_dropdown": 7,
    "secondary_sidebar_items": ["page-toc"],
    "footer_start": ["copyright"],
    "footer_end": [],
}
html_static_path = ["_static"]
html_css_files = ["glassdist.css"]
html_show_sourcelink = False

# --- nitpicky: names that have no target offline (no intersphinx without a network) --------
nitpicky = True
nitpick_ignore_regex = [
    # the standard library, NumPy, pydantic and typing: their inventories are on the web
    ("py:.*", (r"(numpy|np|scipy|skimage|cv2|pydantic|pydantic_core|typing|collections|pathlib|os|datetime|enum|"
               r"argparse|io|concurrent|dataclasses|sqlalchemy|dask|distributed|matplotlib|tifffile|fastapi|starlette)\..*")),
    ("py:class", (r"(ndarray|array_like|ArrayLike|Path|PathLike|Generator|Callable|Iterable|Iterator|Sequence|"
                  r"Mapping|BaseModel|Enum|Figure|Axes|Literal|Any|Self|NoneType|float64|float32|"
                  r"int|float|str|bool|dict|list|tuple|bytes|None|object|type)")),
    # a module's private helpers, named in its docstrings: they have no page of their own
    ("py:func", r"_[a-z][a-z0-9_]*"),
]
