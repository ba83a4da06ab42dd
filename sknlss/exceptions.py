"""Warnings of sknlss.

The library also issues scikit-learn's
:class:`~sklearn.exceptions.ConvergenceWarning` when an optimisation stops at
its iteration limit while it is still improving.
"""

__all__ = ["LinearFallbackWarning", "SimulationDivergedWarning"]


class SimulationDivergedWarning(RuntimeWarning):
    """Warning raised when a simulated trajectory leaves the bounded region.

    The outputs from the first divergent sample to the end of that sequence are
    set to NaN.
    """


class LinearFallbackWarning(UserWarning):
    """Warning raised when a record cannot identify the nonlinear terms.

    The cost of the fit holds fewer values than the model has parameters: the
    estimator keeps its linear model (the nonlinear terms are zero, the linear
    part is refined on the simulation error) and sets
    ``fell_back_to_linear_``. A nonlinear model that the record can identify
    but that does not beat its linear start on the held-out data is not
    returned either; that is recorded in ``fell_back_to_linear_`` without a
    warning, as a result of the selection.
    """
