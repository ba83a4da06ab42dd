"""sknlss: nonlinear state-space system identification as scikit-learn estimators.

Estimators
----------
BLAEstimator
    Best Linear Approximation and its balanced state-space realization.
PNLSSRegressor
    Polynomial nonlinear state space, optionally with the initial state (PNLSS-I).
NLSS2Regressor
    Linear state space plus neural-network nonlinearities, initialised from
    estimated states.
DecoupledPNLSS
    PNLSS whose multivariate polynomials are decoupled into univariate branches.

Functions
---------
decouple_polynomial
    Decoupling of a multivariate polynomial map into univariate branches
    through the CPD of its Jacobian tensor.
"""

from ._base import SimulationDivergedWarning
from ._bla import BLAEstimator
from ._decouple import decouple_polynomial
from ._decoupled import DecoupledPNLSS
from ._nlss2 import NLSS2Regressor
from ._pnlss import PNLSSRegressor

__version__ = "0.1.0"

__all__ = [
    "BLAEstimator",
    "DecoupledPNLSS",
    "NLSS2Regressor",
    "PNLSSRegressor",
    "SimulationDivergedWarning",
    "decouple_polynomial",
]
