#!/bin/sh
# Build the HTML documentation as CI does: warnings are errors, a fresh
# environment, no network. Usage: doc/build.sh [output-folder]
#
# SKNLSS_DOCS_EXAMPLES=fast|all|none chooses which gallery examples run
# (default all; see doc/conf.py). Set SKNLSS_DATA to the folder holding
# cascaded_tanks/ for the examples to use the measured benchmark data.
set -eu
cd "$(dirname "$0")/.."
python -m sphinx -W --keep-going -E -b html doc "${1:-doc/_build/html}"
