"""Sphinx configuration: furo + MyST Markdown, warnings are errors (`sphinx-build -W`).

Generated at build time (never kept in git) by `_ext/mexone_docs.py`: the CLI reference from
each verb's argparse parser, the Python API pages from every public `__all__`, the valid
ranges from `mexone.ranges`, the example gallery and the list of topic pages.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))
if (HERE.parent / "src" / "mexone").is_dir():  # a checkout: document this source, not an install
    sys.path.insert(0, str(HERE.parent / "src"))

project = "mexone"
author = "the mexone authors"
copyright = "the mexone authors, BSD-3-Clause"
extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.viewcode", "mexone_docs"]
source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "_ext", "_generated/layout.md", "Thumbs.db", ".DS_Store"]  # layout: included
html_theme = "furo"
html_title = "mexone"
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"members": True, "undoc-members": True, "show-inheritance": True}
# a field named `type` on several classes makes the builtin `type` in a signature ambiguous
suppress_warnings = ["ref.python"]
