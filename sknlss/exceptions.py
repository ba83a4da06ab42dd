"""Warnings of sknlss.

The library also issues scikit-learn's
:class:`~sklearn.exceptions.ConvergenceWarning` when an optimisation stops at
its iteration limit while it is still improving.
"""

__all__ = ["SimulationDivergedWarning"]


class SimulationDivergedWarning(RuntimeWarning):
    """Warning raised when a simulated trajectory leaves the bounded region.

    The outputs from the first divergent sample to the end of that sequence are
    set to NaN.
    """
