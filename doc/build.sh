#!/bin/sh
# Build the HTML documentation as CI does, then check the pages. Usage:
# doc/build.sh [output-folder]
#
# Step 1 builds with Sphinx: warnings are errors, a fresh environment, no
# network. Step 2 (doc/check_html.py) fails when a page shows raw TeX, loads
# a script from another host, or shows a warning or a path of this machine in
# an example's output; it lists each page and snippet.
#
# SKNLSS_DOCS_EXAMPLES=fast|all|none chooses which gallery examples run
# (default all; see doc/conf.py). Set SKNLSS_DATA to the folder holding
# cascaded_tanks/ and silverbox/ for the examples to use the measured
# benchmark data.
set -eu
cd "$(dirname "$0")/.."
out="${1:-doc/_build/html}"
echo "== 1/2 sphinx-build -> $out"
python -m sphinx -W --keep-going -E -b html doc "$out"
echo "== 2/2 check the pages (doc/check_html.py)"
python doc/check_html.py "$out"
