"""Benchmark data and simulated data sets.

fetch_cascaded_tanks
    The measured Cascaded Tanks benchmark records (``load_cascaded_tanks`` is
    an alias).
fetch_silverbox
    The measured Silverbox benchmark records: estimation and three test records.
make_cascaded_tanks
    Simulated records of the two-tank system, with overflow and noise.
make_pnlss_reference
    Steady-state multisine data of the reference PNLSS system.
"""

from ._cascaded_tanks import fetch_cascaded_tanks, load_cascaded_tanks, make_cascaded_tanks
from ._pnlss_reference import make_pnlss_reference
from ._silverbox import fetch_silverbox

__all__ = [
    "fetch_cascaded_tanks",
    "fetch_silverbox",
    "load_cascaded_tanks",
    "make_cascaded_tanks",
    "make_pnlss_reference",
]
