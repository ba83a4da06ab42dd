"""Validation helpers shared by the public estimators and functions."""

import re
from contextlib import contextmanager
from numbers import Integral, Real

import numpy as np
from sklearn.utils._param_validation import Interval


class Integers(Interval):
    """An :class:`~sklearn.utils._param_validation.Interval` of integers that
    refuses booleans and unsigned NumPy integers: Python counts ``True`` as the
    integer 1, so a plain ``Interval(Integral, ...)`` would let
    ``n_states=True`` through, and NumPy turns the sum of an unsigned and a
    signed integer into a float, which no index accepts.

    Parameters
    ----------
    left, right : int or None
        Bounds of the interval; None for no bound.
    closed : {"left", "right", "both", "neither"}
        Which bounds belong to the interval.
    """

    def __init__(self, left, right, *, closed):
        super().__init__(Integral, left, right, closed=closed)

    def is_satisfied_by(self, val):
        return (not isinstance(val, (bool, np.bool_, np.unsignedinteger))
                and super().is_satisfied_by(val))

    def __str__(self):
        return f"{super().__str__()} (a Python int or a signed NumPy int)"


def binary_magnitude(values, axis=0):
    """A power of two near the largest magnitude of ``values`` along ``axis``.

    Dividing by it is exact, so statistics of the divided values are bit for
    bit those of the values, scaled; but their squares cannot overflow (the
    divided values lie within [-2, 2]). The exponent less one keeps the power
    of two finite for the largest floats.
    """
    return np.ldexp(1.0, np.frexp(np.max(np.abs(values), axis=axis))[1] - 1)


#: Any integer, not a boolean (e.g. ``n_jobs``).
ANY_INTEGER = Integers(None, None, closed="neither")

#: A positive finite number (``Interval`` bounds alone would admit infinity).
POSITIVE_FINITE = Interval(Real, 0, np.inf, closed="neither")


@contextmanager
def naming(argument):
    """Make the ValueError or TypeError raised in the block name ``argument``.

    scikit-learn's and NumPy's conversion errors ("could not convert string to
    float", "Complex data not supported") do not say which argument was at
    fault; the message is prefixed with its name when it does not name it.
    """
    try:
        yield
    except (TypeError, ValueError) as error:
        if re.search(rf"\b{re.escape(argument)}\b", str(error)):
            raise
        kind = TypeError if isinstance(error, TypeError) else ValueError
        raise kind(f"{argument}: {error}") from error


@contextmanager
def explained(note):
    """Append ``note()``, the likely cause, to a ValueError raised in the block.

    ``note`` is called only when the block fails; when it returns an empty
    string the error is raised unchanged (its type kept).
    """
    try:
        yield
    except ValueError as error:
        cause = note()
        if not cause:
            raise
        raise ValueError(f"{error}{cause}") from error
