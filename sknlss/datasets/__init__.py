"""Benchmark data and simulated data sets.

Measured benchmarks (read from a data folder, downloaded where a network is
available, checked by SHA-256):

fetch_cascaded_tanks
    The Cascaded Tanks records (``load_cascaded_tanks`` is an alias).
fetch_silverbox
    The Silverbox records: estimation and three test records.

Simulated systems (each with estimation and test records that start
mid-motion, a stated noise level and a test input that leaves the estimation
amplitude):

make_wiener_hammerstein
    Linear filter, soft saturation, linear filter.
make_duffing
    A Duffing oscillator like the Silverbox.
make_bouc_wen
    The hysteretic Bouc-Wen oscillator of the Noël-Schoukens benchmark.
make_closed_loop_drive
    A positioning drive with friction under PID control, in closed loop.

Stand-ins of the other benchmarks:

make_cascaded_tanks
    The two-tank system, with overflow and noise; like the measured
    benchmark, both records start from the same levels and the test input
    has the estimation input's amplitude.
make_pnlss_reference
    Steady-state multisine data of the reference PNLSS system.
"""

from ._cascaded_tanks import fetch_cascaded_tanks, load_cascaded_tanks, make_cascaded_tanks
from ._closed_loop_drive import make_closed_loop_drive
from ._oscillators import make_bouc_wen, make_duffing
from ._pnlss_reference import make_pnlss_reference
from ._silverbox import fetch_silverbox
from ._wiener_hammerstein import make_wiener_hammerstein

__all__ = [
    "fetch_cascaded_tanks",
    "fetch_silverbox",
    "load_cascaded_tanks",
    "make_bouc_wen",
    "make_cascaded_tanks",
    "make_closed_loop_drive",
    "make_duffing",
    "make_pnlss_reference",
    "make_wiener_hammerstein",
]
