"""Benchmark metrics for simulated outputs, and scorers that skip a transient.

The metrics follow the conventions of the nonlinear system identification
benchmarks: the RMS error of the simulated output in the output's units, the
normalised RMS error and the "fit" percentage of the System Identification
Toolbox. Each accepts ``n_transient`` (samples dropped at the start of every
sequence) and ``sequence_id``.
"""

import numpy as np
from sklearn.utils._param_validation import StrOptions, validate_params
from sklearn.utils.metadata_routing import MetadataRequest, _MetadataRequester
from sklearn.utils.metadata_routing import _routing_enabled
from sklearn.utils.validation import check_array

from ._core._sequences import sequence_bounds, transient_mask
from ._validation import Integers, binary_magnitude, naming

__all__ = ["rms_error", "nrmse", "fit_percent", "make_transient_scorer"]

_METRIC_CONSTRAINTS = {
    "y_true": ["array-like"],
    "y_pred": ["array-like"],
    "n_transient": [Integers(0, None, closed="left")],
    "sequence_id": ["array-like", None],
    "multioutput": [StrOptions({"uniform_average", "raw_values"})],
}


def _kept_pairs(y_true, y_pred, n_transient, sequence_id):
    """The kept samples as 2-D arrays, and which outputs' simulations diverged.

    A non-finite simulated output (a diverged simulation) is replaced by the
    measured one, so that the metrics stay finite; the caller gives those
    outputs an infinite error.
    """
    with naming("y_true"):
        y_true = check_array(y_true, ensure_2d=False, dtype=np.float64, input_name="y_true")
    with naming("y_pred"):
        y_pred = check_array(y_pred, ensure_2d=False, dtype=np.float64,
                             ensure_all_finite=False, input_name="y_pred")
    if y_true.shape != y_pred.shape:
        raise ValueError(
            f"y_true and y_pred have different shapes: {y_true.shape} and {y_pred.shape}."
        )
    keep = transient_mask(sequence_bounds(sequence_id, y_true.shape[0]), n_transient)
    if not keep.any():
        raise ValueError(f"n_transient={n_transient} leaves no sample to evaluate.")
    y_true = y_true[keep].reshape(int(keep.sum()), -1)
    y_pred = y_pred[keep].reshape(y_true.shape)
    finite = np.isfinite(y_pred)
    return y_true, np.where(finite, y_pred, y_true), ~finite.all(axis=0)


def _rms(values):
    """RMS of every column, on values divided by their binary magnitude (an
    exact scaling) so that the squares cannot overflow."""
    unit = binary_magnitude(values)
    return unit * np.sqrt(np.mean((values / unit) ** 2, axis=0))


def _rms_errors(y_true, y_pred, diverged):
    """RMS error of every output; infinite for the diverged ones (and for
    errors beyond the floating-point range)."""
    with np.errstate(over="ignore"):
        rms = _rms(y_true - y_pred)
    rms[diverged] = np.inf
    return rms


def _aggregate(values, multioutput):
    return values if multioutput == "raw_values" else float(np.mean(values))


@validate_params(_METRIC_CONSTRAINTS, prefer_skip_nested_validation=True)
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
        RMS error in the units of ``y_true``; infinite for an output whose
        simulation diverged (non-finite values in ``y_pred``).

    Examples
    --------
    >>> from sknlss.metrics import rms_error
    >>> rms_error([1.0, 2.0, 3.0, 4.0], [1.0, 2.0, 3.0, 6.0])
    1.0
    >>> rms_error([1.0, 2.0, 3.0, 4.0], [9.0, 2.0, 3.0, 4.0], n_transient=1)
    0.0
    """
    return _aggregate(_rms_errors(*_kept_pairs(y_true, y_pred, n_transient, sequence_id)),
                      multioutput)


@validate_params(_METRIC_CONSTRAINTS, prefer_skip_nested_validation=True)
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
        Dimensionless; 1 is the error of predicting the mean; infinite for an
        output whose simulation diverged. An output that is constant over the
        scored samples has no scale: 0 if it is simulated exactly, else
        infinite.

    Examples
    --------
    >>> from sknlss.metrics import nrmse
    >>> round(nrmse([0.0, 2.0, 0.0, 2.0], [0.0, 2.0, 0.0, 0.0]), 6)
    1.0
    """
    y_true, y_pred, diverged = _kept_pairs(y_true, y_pred, n_transient, sequence_id)
    rms = _rms_errors(y_true, y_pred, diverged)
    std = _rms(y_true - y_true.mean(axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(std > 0, rms / std, np.where(rms > 0, np.inf, 0.0))
    return _aggregate(ratio, multioutput)


@validate_params(_METRIC_CONSTRAINTS, prefer_skip_nested_validation=True)
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
        Fit in percent; ``-inf`` for an output whose simulation diverged, or
        that is constant over the scored samples and not simulated exactly.

    Examples
    --------
    >>> from sknlss.metrics import fit_percent
    >>> fit_percent([1.0, -1.0, 1.0, -1.0], [1.0, -1.0, 1.0, -1.0])
    100.0
    """
    error = nrmse(y_true, y_pred, n_transient=n_transient, sequence_id=sequence_id,
                  multioutput=multioutput)
    # An error near the floating-point limit is a fit of -inf, without an
    # overflow warning.
    with np.errstate(over="ignore"):
        return 100.0 * (1.0 - error)


_METRICS = {
    "rms": (rms_error, False),
    "nrmse": (nrmse, False),
    "fit": (fit_percent, True),
}


class _SimulationScorer(_MetadataRequester):
    """Scorer that simulates each evaluated sequence and skips its transient.

    Unlike a scorer made by :func:`sklearn.metrics.make_scorer`, it passes a
    routed ``sequence_id`` to ``predict`` as well as to the metric, so that each
    sequence of a test fold is simulated from its own initial state.
    """

    def __init__(self, metric, *, n_transient):
        self.metric = metric
        self.n_transient = n_transient
        # Unset until set_score_request: routing then refuses a routed
        # sequence_id instead of dropping it, as for scikit-learn's scorers.
        self._metadata_request = MetadataRequest(owner=self)
        self._metadata_request.score.add_request(param="sequence_id", alias=None)

    def __call__(self, estimator, X, y_true, sequence_id=None):
        function, greater_is_better = _METRICS[self.metric]
        if sequence_id is None:
            y_pred = estimator.predict(X)
        else:
            y_pred = estimator.predict(X, sequence_id=sequence_id)
        sign = 1.0 if greater_is_better else -1.0
        # A diverged simulation gets the metric's infinite error, unless its
        # non-finite values lie in the transient the metric skips.
        value = function(
            y_true, y_pred, n_transient=self.n_transient, sequence_id=sequence_id
        )
        return sign * value

    def set_score_request(self, *, sequence_id=True):
        """Request ``sequence_id`` from the caller (metadata routing).

        Parameters
        ----------
        sequence_id : bool, str or None, default=True
            Whether the scorer receives the routed ``sequence_id`` (or the name
            of the metadata to use as such).

        Returns
        -------
        self : object
            The scorer.
        """
        if not _routing_enabled():
            raise RuntimeError(
                "set_score_request needs metadata routing: call "
                "sklearn.set_config(enable_metadata_routing=True) first."
            )
        self._metadata_request.score.add_request(param="sequence_id", alias=sequence_id)
        return self

    def __repr__(self):
        return (
            f"make_transient_scorer({self.metric!r}, n_transient={self.n_transient})"
        )


@validate_params(
    {"metric": [StrOptions(set(_METRICS))], "n_transient": [Integers(0, None, closed="left")]},
    prefer_skip_nested_validation=True,
)
def make_transient_scorer(metric="rms", *, n_transient=0):
    """Scorer for ``GridSearchCV(scoring=...)`` that skips a transient.

    Parameters
    ----------
    metric : {"rms", "nrmse", "fit"}, default="rms"
        Metric of the simulated output. Errors are negated, so that greater is
        better as scikit-learn expects; a divergent simulation scores ``-inf``.
    n_transient : int, default=0
        Samples skipped at the start of each evaluated sequence; the state of a
        model started from zero needs a few samples to settle.

    Returns
    -------
    scorer : callable
        ``scorer(estimator, X, y, sequence_id=None)``. With metadata routing
        enabled, ``scorer.set_score_request(sequence_id=True)`` makes a search
        route ``sequence_id`` to it, and the scorer passes it on to ``predict``.

    Examples
    --------
    >>> import numpy as np
    >>> from sknlss import BLAEstimator
    >>> from sknlss.metrics import make_transient_scorer
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal((400, 1))
    >>> y = np.convolve(u[:, 0], [0.0, 1.0, 0.5, 0.25], mode="full")[:400]
    >>> scorer = make_transient_scorer("rms", n_transient=20)
    >>> model = BLAEstimator(n_states=2).fit(u, y)
    >>> bool(scorer(model, u, y) <= 0.0)
    True
    """
    return _SimulationScorer(metric, n_transient=n_transient)
