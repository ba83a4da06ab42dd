"""Benchmark metrics for simulated outputs, and scorers that skip a transient.

The metrics follow the conventions of the nonlinear system identification
benchmarks: the RMS error of the simulated output in the output's units, the
normalised RMS error and the "fit" percentage of the System Identification
Toolbox. Each accepts ``n_transient`` (samples dropped at the start of every
sequence) and ``sequence_id``.
"""

import numpy as np
from sklearn.metrics import make_scorer

from ._base import sequence_bounds, transient_mask

__all__ = ["rms_error", "nrmse", "fit_percent", "make_transient_scorer"]


def _kept_pairs(y_true, y_pred, n_transient, sequence_id):
    y_true = np.asarray(y_true, dtype=np.float64)
    y_pred = np.asarray(y_pred, dtype=np.float64)
    if y_true.shape != y_pred.shape:
        raise ValueError(
            f"y_true and y_pred have different shapes: {y_true.shape} and {y_pred.shape}."
        )
    if y_true.ndim not in (1, 2) or y_true.shape[0] == 0:
        raise ValueError(
            f"y_true must be a non-empty 1-D or 2-D array, got shape {y_true.shape}."
        )
    if n_transient < 0:
        raise ValueError(f"n_transient must be non-negative, got {n_transient}.")
    keep = transient_mask(sequence_bounds(sequence_id, y_true.shape[0]), n_transient)
    if not keep.any():
        raise ValueError(f"n_transient={n_transient} leaves no sample to evaluate.")
    y_true = y_true[keep].reshape(int(keep.sum()), -1)
    y_pred = y_pred[keep].reshape(y_true.shape)
    return y_true, y_pred


def _aggregate(values, multioutput):
    if multioutput == "raw_values":
        return values
    if multioutput == "uniform_average":
        return float(np.mean(values))
    raise ValueError(
        f"multioutput must be 'uniform_average' or 'raw_values', got {multioutput!r}."
    )


def rms_error(y_true, y_pred, *, n_transient=0, sequence_id=None,
              multioutput="uniform_average"):
    """Root-mean-square error of the simulated output.

    Parameters
    ----------
    y_true : array-like of shape (n_samples,) or (n_samples, n_outputs)
        Measured output.
    y_pred : array-like of the same shape
        Simulated output.
    n_transient : int, default=0
        Samples skipped at the start of each sequence.
    sequence_id : array-like of shape (n_samples,), default=None
        Sequence labels, for ``n_transient``.
    multioutput : {"uniform_average", "raw_values"}, default="uniform_average"
        Average over the outputs, or one value per output.

    Returns
    -------
    rms : float or ndarray of shape (n_outputs,)
        RMS error in the units of ``y_true``.

    Examples
    --------
    >>> from sknlss.metrics import rms_error
    >>> rms_error([1.0, 2.0, 3.0, 4.0], [1.0, 2.0, 3.0, 6.0])
    1.0
    >>> rms_error([1.0, 2.0, 3.0, 4.0], [9.0, 2.0, 3.0, 4.0], n_transient=1)
    0.0
    """
    y_true, y_pred = _kept_pairs(y_true, y_pred, n_transient, sequence_id)
    return _aggregate(np.sqrt(np.mean((y_true - y_pred) ** 2, axis=0)), multioutput)


def nrmse(y_true, y_pred, *, n_transient=0, sequence_id=None,
          multioutput="uniform_average"):
    """RMS error divided by the standard deviation of the measured output.

    Parameters
    ----------
    y_true : array-like of shape (n_samples,) or (n_samples, n_outputs)
        Measured output.
    y_pred : array-like of the same shape
        Simulated output.
    n_transient : int, default=0
        Samples skipped at the start of each sequence.
    sequence_id : array-like of shape (n_samples,), default=None
        Sequence labels, for ``n_transient``.
    multioutput : {"uniform_average", "raw_values"}, default="uniform_average"
        Average over the outputs, or one value per output.

    Returns
    -------
    nrmse : float or ndarray of shape (n_outputs,)
        Dimensionless; 1 is the error of predicting the mean.

    Examples
    --------
    >>> from sknlss.metrics import nrmse
    >>> round(nrmse([0.0, 2.0, 0.0, 2.0], [0.0, 2.0, 0.0, 0.0]), 6)
    1.0
    """
    y_true, y_pred = _kept_pairs(y_true, y_pred, n_transient, sequence_id)
    rms = np.sqrt(np.mean((y_true - y_pred) ** 2, axis=0))
    std = y_true.std(axis=0)
    return _aggregate(rms / np.where(std > 0, std, 1.0), multioutput)


def fit_percent(y_true, y_pred, *, n_transient=0, sequence_id=None,
                multioutput="uniform_average"):
    """Fit percentage ``100 (1 - ||y - y_hat|| / ||y - mean(y)||)``.

    This is the "fit" of MATLAB's ``compare``: 100 for a perfect model, 0 for
    the mean of the output, negative for worse.

    Parameters
    ----------
    y_true : array-like of shape (n_samples,) or (n_samples, n_outputs)
        Measured output.
    y_pred : array-like of the same shape
        Simulated output.
    n_transient : int, default=0
        Samples skipped at the start of each sequence.
    sequence_id : array-like of shape (n_samples,), default=None
        Sequence labels, for ``n_transient``.
    multioutput : {"uniform_average", "raw_values"}, default="uniform_average"
        Average over the outputs, or one value per output.

    Returns
    -------
    fit : float or ndarray of shape (n_outputs,)
        Fit in percent.

    Examples
    --------
    >>> from sknlss.metrics import fit_percent
    >>> fit_percent([1.0, -1.0, 1.0, -1.0], [1.0, -1.0, 1.0, -1.0])
    100.0
    """
    return 100.0 * (
        1.0 - nrmse(y_true, y_pred, n_transient=n_transient, sequence_id=sequence_id,
                    multioutput=multioutput)
    )


_METRICS = {
    "rms": (rms_error, False),
    "nrmse": (nrmse, False),
    "fit": (fit_percent, True),
}


def _finite_metric(metric, greater_is_better):
    """Wrap ``metric`` so that a divergent (non-finite) simulation scores worst."""

    def score(y_true, y_pred, **kwargs):
        if not np.all(np.isfinite(y_pred)):
            return -np.inf if greater_is_better else np.inf
        return metric(y_true, y_pred, **kwargs)

    score.__name__ = metric.__name__
    return score


def make_transient_scorer(metric="rms", *, n_transient=0):
    """Scorer for ``GridSearchCV(scoring=...)`` that skips a transient.

    Parameters
    ----------
    metric : {"rms", "nrmse", "fit"}, default="rms"
        Metric of the simulated output. Errors are negated, so that greater is
        better as scikit-learn expects.
    n_transient : int, default=0
        Samples skipped at the start of each evaluated fold; the state of a
        model started from zero needs a few samples to settle.

    Returns
    -------
    scorer : callable
        ``scorer(estimator, X, y)``.

    Examples
    --------
    >>> from sknlss.metrics import make_transient_scorer
    >>> scorer = make_transient_scorer("rms", n_transient=50)
    """
    if metric not in _METRICS:
        raise ValueError(f"metric must be one of {sorted(_METRICS)}, got {metric!r}.")
    if n_transient < 0:
        raise ValueError(f"n_transient must be non-negative, got {n_transient}.")
    function, greater_is_better = _METRICS[metric]
    return make_scorer(
        _finite_metric(function, greater_is_better),
        greater_is_better=greater_is_better,
        n_transient=n_transient,
    )
