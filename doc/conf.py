"""Sphinx configuration of the sknlss documentation.

Build with ``sphinx-build -W --keep-going -b html doc doc/_build/html``. The
build needs no network: intersphinx is not used, and the real Cascaded Tanks
data are read from ``$SKNLSS_DATA`` when set (the examples fall back to the
simulated tanks otherwise).

The examples gallery runs the example scripts. Which ones run is chosen by the
environment variable ``SKNLSS_DOCS_EXAMPLES``:

``all`` (default)
    run every example (about a minute in total on two cores once numba's
    cache is warm; each example takes at most about a minute);
``fast``
    run only the quickest examples; the others are rendered with their code
    and text but without output;
``none``
    run none.
"""

import os
import re

import sknlss

project = "sknlss"
author = "The sknlss developers"
copyright = "2026, The sknlss developers"
version = release = sknlss.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.doctest",
    "sphinx.ext.mathjax",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
]

templates_path = ["_templates"]
exclude_patterns = ["_build"]
root_doc = "index"

# --- API reference -----------------------------------------------------------
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
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "matplotlib_animations": False,
    # Show what the examples print, not the repr of a cell's last expression
    # (an Axes title, a Legend).
    "capture_repr": (),
}

# --- HTML output ---------------------------------------------------------------
html_theme = "alabaster"
html_theme_options = {
    "description": "Nonlinear state-space identification for scikit-learn",
    "fixed_sidebar": True,
}
html_static_path = []
html_title = f"sknlss {release}"
