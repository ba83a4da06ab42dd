"""Benchmark data and simulated data sets.

load_cascaded_tanks
    The measured Cascaded Tanks benchmark records.
make_cascaded_tanks
    Simulated records of the two-tank system, with overflow and noise.
make_pnlss_reference
    Steady-state multisine data of the reference PNLSS system.
"""

from ._cascaded_tanks import load_cascaded_tanks, make_cascaded_tanks
from ._pnlss_reference import make_pnlss_reference

__all__ = ["load_cascaded_tanks", "make_cascaded_tanks", "make_pnlss_reference"]
