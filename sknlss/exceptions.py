"""Warnings of sknlss.

The library also issues scikit-learn's
:class:`~sklearn.exceptions.ConvergenceWarning` when an optimisation stops at
its iteration limit while it is still improving.
"""

import sys
import warnings
from pathlib import Path

__all__ = ["DataWarning", "LinearFallbackWarning", "SimulationDivergedWarning"]

_PACKAGE = str(Path(__file__).resolve().parent)


class SimulationDivergedWarning(RuntimeWarning):
    """Warning raised when a simulated trajectory leaves the bounded region.

    The outputs from the first divergent sample to the end of that sequence are
    set to NaN.
    """


class DataWarning(UserWarning):
    """Warning raised when the training data do not suit the settings.

    A signal whose mean exceeds its standard deviation with ``center=False``;
    ``period`` without ``n_transient``, which prepends nothing for the steady
    state; an input that does not repeat with ``period``; a linear model that
    settles over more than twice the start of a record that a fit without an
    estimated initial state leaves out of its cost. The fit goes on as the
    settings say.
    """


class LinearFallbackWarning(UserWarning):
    """Warning raised when the linear model is kept for a reason other than the data.

    Either the cost of the fit holds fewer values than the model has
    parameters: the estimator keeps its linear model (the nonlinear terms are
    zero, the linear part is refined on the simulation error unless that would
    make a stable linear part unstable). Or every start that beat the linear
    model on the held-out data ran away on the estimation input enlarged by a
    fifth, and the boundedness guard excluded it (``start_status_`` says
    ``"unbounded"``). Both set ``fell_back_to_linear_``. A nonlinear model
    that does not beat its linear start on the held-out data is not returned
    either; that is recorded in ``fell_back_to_linear_`` without a warning,
    as a result of the selection.
    """


def warn_at_caller(message, category):
    """Issue a warning attributed to the first caller outside sknlss: the user's
    line (or the scikit-learn tool that called the estimator), whatever the
    depth of the library's own calls in between."""
    frame, stacklevel = sys._getframe(1), 2
    while frame is not None and Path(frame.f_code.co_filename).resolve().is_relative_to(
            _PACKAGE):
        frame, stacklevel = frame.f_back, stacklevel + 1
    warnings.warn(message, category, stacklevel=stacklevel)
