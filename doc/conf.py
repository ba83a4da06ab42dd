"""Sphinx configuration of the sknlss documentation.

Build with ``sh doc/build.sh [OUTDIR]``, which runs ``sphinx-build -W
--keep-going -b html doc OUTDIR`` and then checks the pages with
``doc/check_html.py``. Neither the build nor the pages need a network:
intersphinx is not used, MathJax is copied into ``_static/mathjax`` (package
``sphinx-mathjax-offline``), the theme ships its own scripts and fonts, and
the measured Cascaded Tanks and Silverbox data are read from
``$SKNLSS_DATA`` when set (the examples fall back to simulated stand-ins
otherwise, through :func:`sknlss.benchmarks.load_benchmark`).

The examples gallery runs the example scripts. Which ones run is chosen by the
environment variable ``SKNLSS_DOCS_EXAMPLES``:

``all`` (default)
    run every example (a few minutes in total on two cores once numba's
    cache is warm; the longest, the Silverbox and the paper's tables, take
    a minute or more each);
``fast``
    run only the quickest examples; the others are rendered with their code
    and text but without output;
``none``
    run none.
"""

import os
import re
import sys
from pathlib import Path

import sknlss

# Local extensions (the benchmark-result directive).
sys.path.insert(0, str(Path(__file__).parent / "_ext"))

project = "sknlss"
author = "The sknlss developers"
copyright = "2026, The sknlss developers"
version = release = sknlss.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.doctest",
    "sphinx.ext.mathjax",
    # Copies MathJax 3 into _static/mathjax and points mathjax_path at it, so
    # formulas render without a network (no CDN).
    "sphinx-mathjax-offline",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
    "benchmark_results",
]

templates_path = ["_templates"]
# sg_execution_times.rst: left by builds that wrote the gallery's timing page.
exclude_patterns = ["_build", "_generated", "sg_execution_times.rst"]
root_doc = "index"

# --- API reference -----------------------------------------------------------
# One page per public name, from the template of its kind in
# _templates/autosummary/ (class.rst, function.rst, exception.rst).
autosummary_generate = True
autodoc_default_options = {"member-order": "bysource"}
# Members are documented by the class template; numpydoc's member tables would
# point at pages that are not generated.
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False


_TYPE_LINE = re.compile(r"^(\s*\**\w+(?:, \**\w+)* : )(.*)$")
_TRAILING_UNDERSCORE = re.compile(r"\b(\w*[A-Za-z0-9])_(?=[\s,)+\-*/]|$)")


def _escape_attribute_names_in_types(app, what, name, obj, options, lines):
    """Escape names such as ``n_iter_`` in "name : type" lines of docstrings.

    Shapes like ``ndarray of shape (n_iter_ + 1,)`` are written in plain text,
    where reStructuredText reads ``n_iter_`` as a hyperlink reference.
    """
    for i, line in enumerate(lines):
        match = _TYPE_LINE.match(line)
        if match:
            lines[i] = match.group(1) + _TRAILING_UNDERSCORE.sub(r"\1\\_", match.group(2))


def setup(app):
    # Before numpydoc (priority 500), which parses the raw lines.
    app.connect("autodoc-process-docstring", _escape_attribute_names_in_types, priority=400)


# --- examples gallery --------------------------------------------------------
# The quickest examples, run with SKNLSS_DOCS_EXAMPLES=fast.
_FAST_EXAMPLES = ["plot_bla_cascaded_tanks", "plot_pnlss_cascaded_tanks"]
_run = os.environ.get("SKNLSS_DOCS_EXAMPLES", "all").lower()
if _run not in ("fast", "all", "none"):
    raise ValueError(
        f"SKNLSS_DOCS_EXAMPLES must be 'fast', 'all' or 'none', got {_run!r}."
    )
_pattern = {
    "all": r"/plot_",
    "fast": "/(" + "|".join(re.escape(name) for name in _FAST_EXAMPLES) + r")\.py$",
    "none": r"(?!)",
}[_run]

sphinx_gallery_conf = {
    "examples_dirs": "../examples",
    "gallery_dirs": "auto_examples",
    "filename_pattern": _pattern,
    "plot_gallery": "True",
    # A failing example is reported as a warning (an error under -W) after all
    # examples have run, rather than stopping at the first one.
    "abort_on_example_error": False,
    "download_all_examples": False,
    # The timing pages load jQuery and DataTables from CDNs; the build log
    # gives the same timings.
    "write_computation_times": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    # "Examples using X" at the end of each API page (the templates'
    # minigallery directive).
    "backreferences_dir": "gen_modules/backreferences",
    "doc_module": ("sknlss",),
    "matplotlib_animations": False,
    # Show what the examples print, not the repr of a cell's last expression
    # (an Axes title, a Legend).
    "capture_repr": (),
}

# --- HTML output ---------------------------------------------------------------
html_theme = "pydata_sphinx_theme"
html_theme_options = {
    "navbar_align": "left",
    "navigation_with_keys": False,
    "show_toc_level": 2,
    # The page's table of contents only: no "show source" or edit links.
    "secondary_sidebar_items": ["page-toc"],
    "footer_start": ["copyright"],
    "footer_end": ["sphinx-version", "theme-version"],
}
# Pages without sub-pages have nothing to show in the left sidebar; leaving it
# out gives their text and code the width.
html_sidebars = {
    page: [] for page in ("index", "install", "user_guide", "benchmarks")
}
html_static_path = ["_static"]
# Width of the text column: code lines of 88 characters fit without scrolling.
html_css_files = ["sknlss.css"]
html_title = f"sknlss {release}"
html_show_sourcelink = False
