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
    """Warning raised when a nonlinear model does not beat its linear start.

    No start of the nonlinear optimisation simulated the held-out data better
    than the linear model it started from, or the cost holds fewer values than
    the model has parameters (no start is then tried); the estimator keeps
    that linear model (its nonlinear terms are zero) and sets
    ``fell_back_to_linear_``.
    """
