"""Several starts of one fit, run in parallel; one start from candidate points."""

import numpy as np
from sklearn.utils.parallel import Parallel, delayed

from ._optimize import levenberg_marquardt

# What a start may raise and still leave the others standing: a starting
# point from which a simulation or a factorisation fails numerically.
START_ERRORS = (ValueError, FloatingPointError, np.linalg.LinAlgError)


def _guarded(fit_one, *args):
    try:
        return fit_one(*args)
    except START_ERRORS as error:
        return error


def run_starts(fit_one, starts, n_jobs=None):
    """Run ``fit_one(*start)`` for every start, in parallel with joblib.

    Parameters
    ----------
    fit_one : callable
    starts : list of tuple
        Arguments of each start.
    n_jobs : int, default=None
        Joblib workers.

    Returns
    -------
    outcomes : list
        The return value of every start, or the exception it raised (a start
        whose numerics fail leaves the others standing).
    """
    return Parallel(n_jobs=n_jobs)(delayed(_guarded)(fit_one, *start) for start in starts)


def _finite(r, J):
    return r is not None and np.all(np.isfinite(r)) and np.all(np.isfinite(J))


def fit_from(problem, candidates, *, label, **options):
    """Levenberg-Marquardt on ``problem`` from the first candidate that simulates.

    Parameters
    ----------
    problem : SimulationErrorProblem
    candidates : iterable of ndarray
        Starting points, tried in turn until one gives a finite residual and
        Jacobian (e.g. a model, then the same with its nonlinear terms
        shrunk). With weight decay, its scale is set from the point used.
    label : str
        Prefix of the progress lines and warnings.
    **options
        Passed to :func:`~sknlss._core._optimize.levenberg_marquardt`.

    Returns
    -------
    theta : ndarray
        The selected parameters.
    result : LMResult
    """
    for theta0 in candidates:
        if getattr(problem, "weight_decay", 0):
            # The decay weighs each term's contribution from this start.
            problem.set_decay_scale(theta0)
        initial = problem.residual(theta0, True)
        if _finite(*initial):
            break
    else:
        raise ValueError(
            f"{label}: no starting point can be simulated on the estimation data (X, y)."
        )
    result = levenberg_marquardt(problem.residual, theta0,
                                 validation_loss=problem.validation_loss, label=label,
                                 initial=initial, **options)
    return result.theta, result
