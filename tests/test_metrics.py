import warnings

import numpy as np
import pytest
from sklearn.base import BaseEstimator, RegressorMixin

from sknlss.metrics import fit_percent, make_transient_scorer, nrmse, rms_error


def test_rms_error_hand_values():
    assert rms_error([1.0, 2.0, 3.0, 4.0], [1.0, 2.0, 3.0, 6.0]) == pytest.approx(1.0)
    assert rms_error([0.0, 0.0], [3.0, 4.0]) == pytest.approx(np.sqrt(12.5))
    # The first sample of every sequence is skipped.
    y_true = [9.0, 1.0, 1.0, 9.0, 2.0, 2.0]
    y_pred = [0.0, 1.0, 3.0, 0.0, 2.0, 2.0]
    assert rms_error(y_true, y_pred, n_transient=1,
                     sequence_id=[0, 0, 0, 1, 1, 1]) == pytest.approx(1.0)


def test_multioutput():
    y_true = np.array([[0.0, 0.0], [0.0, 0.0]])
    y_pred = np.array([[1.0, 2.0], [1.0, 2.0]])
    np.testing.assert_allclose(rms_error(y_true, y_pred, multioutput="raw_values"), [1, 2])
    assert rms_error(y_true, y_pred) == pytest.approx(1.5)
    with pytest.raises(ValueError, match="multioutput"):
        rms_error(y_true, y_pred, multioutput="variance_weighted")


def test_nrmse_and_fit_hand_values():
    y_true = [0.0, 2.0, 0.0, 2.0]  # std 1
    y_pred = [0.0, 2.0, 0.0, 0.0]  # RMS error 1
    assert nrmse(y_true, y_pred) == pytest.approx(1.0)
    assert fit_percent(y_true, y_pred) == pytest.approx(0.0)
    y_pred = [0.5, 2.0, 0.0, 2.0]  # RMS error 0.25
    assert nrmse(y_true, y_pred) == pytest.approx(0.25)
    assert fit_percent(y_true, y_pred) == pytest.approx(75.0)
    assert fit_percent(y_true, y_true) == pytest.approx(100.0)
    # Predicting the mean gives fit 0.
    assert fit_percent(y_true, np.ones(4)) == pytest.approx(0.0)
    # A constant output has no scale: exact, or infinitely far, in any units.
    for scale in (1.0, 1e3):
        assert nrmse(scale * np.array([2.0, 2.0, 2.0]), scale * np.array([2.0, 2.0, 3.0])) == np.inf
        assert fit_percent(scale * np.array([2.0, 2.0]), scale * np.array([3.0, 3.0])) == -np.inf
    assert nrmse([2.0, 2.0], [2.0, 2.0]) == 0.0
    assert fit_percent([2.0, 2.0], [2.0, 2.0]) == 100.0
    np.testing.assert_array_equal(
        nrmse([[2.0, 0.0], [2.0, 2.0]], [[2.0, 1.0], [2.0, 1.0]], multioutput="raw_values"),
        [0.0, 1.0])


def test_metric_errors():
    with pytest.raises(ValueError, match="different shapes"):
        rms_error([1.0, 2.0], [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="'n_transient' parameter"):
        rms_error([1.0, 2.0], [1.0, 2.0], n_transient=-1)
    with pytest.raises(ValueError, match="leaves no sample"):
        rms_error([1.0, 2.0], [1.0, 2.0], n_transient=2)
    with pytest.raises(ValueError, match=r"y_true: Found array with 0 sample"):
        rms_error([], [])
    with pytest.raises(ValueError, match="sequence_id"):
        nrmse([1.0, 2.0], [1.0, 2.0], sequence_id=[0])


class _Shift(RegressorMixin, BaseEstimator):
    """Predicts X[:, 0] + shift, and NaN everywhere when ``shift`` is NaN."""

    def __init__(self, shift=0.0):
        self.shift = shift

    def fit(self, X, y):
        return self

    def predict(self, X):
        return np.asarray(X, dtype=float)[:, 0] + self.shift


def test_transient_scorer():
    X = np.arange(10.0).reshape(-1, 1)
    y = X[:, 0].copy()
    y[:3] += 100.0  # wrong only in the transient
    model = _Shift(1.0)
    assert make_transient_scorer("rms", n_transient=3)(model, X, y) == pytest.approx(-1.0)
    assert make_transient_scorer("rms")(model, X, y) < -50
    assert make_transient_scorer("nrmse", n_transient=3)(model, X, y) == pytest.approx(
        -1.0 / np.std(y[3:]))
    assert make_transient_scorer("fit", n_transient=3)(model, X, y) == pytest.approx(
        100.0 * (1.0 - 1.0 / np.std(y[3:])))


def test_transient_scorer_divergent_model_scores_worst():
    X = np.arange(10.0).reshape(-1, 1)
    model = _Shift(np.nan)
    for metric in ("rms", "nrmse", "fit"):
        assert make_transient_scorer(metric)(model, X, X[:, 0]) == -np.inf
    # Non-finite values only in the skipped transient are skipped with it.
    X_late = X.copy()
    X_late[:2] = np.nan
    assert make_transient_scorer("rms", n_transient=3)(_Shift(1.0), X_late, X[:, 0]) == (
        pytest.approx(-1.0))


def test_fit_percent_of_a_huge_finite_error_is_minus_inf_without_a_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for multioutput in ("uniform_average", "raw_values"):
            assert fit_percent([1.0, -1.0, 1.0], [1e307, -1e307, 1e307],
                               multioutput=multioutput) == -np.inf


def test_transient_scorer_bad_arguments():
    with pytest.raises(ValueError, match="'metric' parameter"):
        make_transient_scorer("mse")
    with pytest.raises(ValueError, match="'n_transient' parameter"):
        make_transient_scorer("rms", n_transient=-1)
