"""Several starts of one fit, run in parallel; one start from candidate points;
the initial state of a fitted model on a record."""

import threading
import warnings
from contextlib import contextmanager

import numpy as np
from sklearn.utils.parallel import Parallel, delayed

from ._model import StateSpaceModel
from ._optimize import levenberg_marquardt
from ._problem import SimulationErrorProblem, fit_rows

# What a start may raise and still leave the others standing: a starting
# point from which a simulation or a factorisation fails numerically.
START_ERRORS = (ValueError, FloatingPointError, np.linalg.LinAlgError)


def _guarded(fit_one, *args):
    try:
        return fit_one(*args)
    except START_ERRORS as error:
        return error


@contextmanager
def recorded_warnings():
    """Record the warnings raised in the block, for the caller to issue again.

    Yields the list that receives them as ``(message, category)`` pairs once
    the block ends: a joblib worker process's warnings reach the caller only
    so. In a thread other than the main one (the threading backend) they are
    issued as they come and the list stays empty: ``warnings.catch_warnings``
    swaps state of the whole process, so that threads recording side by side
    would lose one another's warnings.
    """
    caught = []
    if threading.current_thread() is not threading.main_thread():
        yield caught
        return
    with warnings.catch_warnings(record=True) as records:
        warnings.simplefilter("always")
        yield caught
    caught.extend((record.message, record.category) for record in records)


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
        The parameters in its ``held`` keep their starting values.
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
        if problem.weight_decay:
            # The decay weighs each term's contribution from this start.
            problem = problem.with_decay_scale(theta0)
        initial = problem.residual(theta0, True)
        if _finite(*initial):
            break
    else:
        raise ValueError(
            f"{label}: no starting point can be simulated on the data (X, y) it is fitted to."
        )
    searched, start = problem, theta0
    held = problem.held
    if held.size:
        # The search steps in the other parameters only.
        searched = problem.restricted(theta0, np.setdiff1d(np.arange(theta0.size), held))
        start, initial = searched.free_part(theta0), (initial[0], searched.free_part(initial[1]))
    result = levenberg_marquardt(searched.residual, start,
                                 validation_loss=searched.validation_loss, label=label,
                                 initial=initial, n_residuals=problem.n_residuals,
                                 **options)
    if held.size:
        result.theta = searched.full(result.theta)
    return result.theta, result


def fit_initial_state(model, theta, U, Y, x0, *, max_iter):
    """The initial state minimising the simulation error of a fitted model.

    Parameters
    ----------
    model : StateSpaceModel
        The fitted structure (without an estimated initial state).
    theta : ndarray
        Its parameters, kept fixed.
    U, Y : ndarray of shape (n_samples, n_inputs), (n_samples, n_outputs)
        One normalised sequence.
    x0 : ndarray of shape (n_states,)
        Where the search starts; zero is tried next if the model cannot be
        simulated from it.
    max_iter : int
        Maximum number of Levenberg-Marquardt iterations.

    Returns
    -------
    x0 : ndarray of shape (n_states,)
    """
    with_x0 = StateSpaceModel(model.n_states, model.n_inputs, model.n_outputs, model.terms,
                              estimate_x0=True)
    rows = fit_rows(U, Y, np.array([0, len(U)]), n_transient=0, validation_fraction=0.0)
    free = with_x0.columns("x0")
    # The output offset of the fitted model is already in the signals' offsets
    # (or in the biases of NLSS2's output networks, which stay as fitted).
    start = with_x0.pack({**model.unpack(theta), "x0": x0, "y0": np.zeros(model.n_outputs)})
    problem = SimulationErrorProblem(with_x0, rows).restricted(start, free)
    return fit_from(problem, [x0, np.zeros_like(x0)], label="initial state",
                    max_iter=max_iter)[0]
