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
NLLFRRegressor
    Linear state space with a static nonlinearity in feedback (NL-LFR).

Bases of the static nonlinearities
----------------------------------
PolynomialBasis, LegendreBasis, ChebyshevBasis

Functions
---------
decouple_polynomial
    Decoupling of a multivariate polynomial map into univariate branches
    through the CPD of its Jacobian tensor.
"""

from ._estimators._bla import BLAEstimator
from ._estimators._decoupled import DecoupledPNLSS
from ._estimators._nllfr import NLLFRRegressor
from ._estimators._nlss2 import NLSS2Regressor
from ._estimators._pnlss import PNLSSRegressor
from ._terms._bases import ChebyshevBasis, LegendreBasis, PolynomialBasis
from ._terms._cpd import decouple_polynomial
from .exceptions import DataWarning, LinearFallbackWarning, SimulationDivergedWarning

__version__ = "0.1.0"

__all__ = [
    "BLAEstimator",
    "ChebyshevBasis",
    "DataWarning",
    "DecoupledPNLSS",
    "LegendreBasis",
    "LinearFallbackWarning",
    "NLLFRRegressor",
    "NLSS2Regressor",
    "PNLSSRegressor",
    "PolynomialBasis",
    "SimulationDivergedWarning",
    "decouple_polynomial",
]
