"""HoldoutSearch: fits with different held-out ends, ranked on their common end."""

import warnings

import joblib
import numpy as np
import pytest
from sklearn.base import clone
from sklearn.exceptions import ConvergenceWarning

from sknlss import BLAEstimator, DataWarning, PNLSSRegressor
from sknlss.metrics import rms_error
from sknlss.model_selection import HoldoutSearch, _holdout_errors

pytestmark = pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")


def _quadratic_system(n_samples=300, n_sequences=1, seed=0):
    """x(t+1) = 0.5 x + u + 0.1 x^2, y = x: a 1-state PNLSS system."""
    rng = np.random.default_rng(seed)
    u = 0.3 * rng.standard_normal((n_samples * n_sequences, 1))
    y = np.zeros(len(u))
    for begin in range(0, len(u), n_samples):
        x = 0.0
        for t in range(begin, begin + n_samples):
            y[t] = x
            x = 0.5 * x + u[t, 0] + 0.1 * x**2
    return u, y, np.repeat(np.arange(n_sequences), n_samples)


def _common_end_rms(model, u, y, fraction):
    """RMS error of the model on the last ``fraction`` of a single record."""
    tail = len(y) - int(round(fraction * len(y)))
    return rms_error(y[tail:], model.predict(u)[tail:])


def test_keeps_the_candidate_with_the_smallest_error_on_the_common_end():
    u, y, _ = _quadratic_system()
    search = HoldoutSearch(
        PNLSSRegressor(n_states=1, degree=2, max_iter=3, random_state=0),
        validation_fractions=[0.2, 0.3],
        param_grid={"max_iter": [0, 3]},
    ).fit(u, y)
    params = search.results_["params"]
    assert params == [
        {"max_iter": 0, "validation_fraction": 0.2},
        {"max_iter": 0, "validation_fraction": 0.3},
        {"max_iter": 3, "validation_fraction": 0.2},
        {"max_iter": 3, "validation_fraction": 0.3},
    ]
    assert search.holdout_fraction_ == 0.2
    # The recorded errors are those of each candidate refitted on its own.
    for setting, rms in zip(params, search.results_["holdout_rms"]):
        candidate = clone(search.estimator).set_params(**setting).fit(u, y)
        assert rms == pytest.approx(_common_end_rms(candidate, u, y, 0.2), rel=1e-10)
    best = int(np.argmax(search.results_["holdout_score"]))
    assert search.best_index_ == best and search.best_params_ == params[best]
    assert search.results_["holdout_rms"][best] == min(search.results_["holdout_rms"])
    # The nonlinear fits beat the linear starts (max_iter=0) on this system.
    assert search.best_params_["max_iter"] == 3
    np.testing.assert_array_equal(search.predict(u), search.best_estimator_.predict(u))
    # The state of each of several records, as the selected model gives it.
    labels = np.repeat([0, 1], [40, 60])
    np.testing.assert_array_equal(
        search.estimate_initial_state(u[:100], y[:100], sequence_id=labels),
        search.best_estimator_.estimate_initial_state(u[:100], y[:100], sequence_id=labels))
    assert search.score(u, y) == search.best_estimator_.score(u, y)
    assert search.n_params_ == search.best_estimator_.n_params_ == 1 + 1 + 1 + 1 + 3 + 3


def test_ranks_the_end_of_every_sequence():
    u, y, sequence_id = _quadratic_system(n_samples=200, n_sequences=2)
    search = HoldoutSearch(PNLSSRegressor(n_states=1, degree=2, max_iter=2),
                           validation_fractions=[0.25]).fit(u, y, sequence_id=sequence_id)
    model = search.best_estimator_
    y_model = model.predict(u, sequence_id=sequence_id)
    rows = np.r_[150:200, 350:400]
    assert search.results_["holdout_rms"][0] == pytest.approx(
        rms_error(y[rows], y_model[rows]), rel=1e-10)
    assert search.predict(u, sequence_id=sequence_id).shape == y.shape


def test_ranks_the_training_records_from_their_own_states():
    # With a state per record, the candidates simulate the records they were
    # fitted on from those states, not from their mean.
    u, y, sequence_id = _quadratic_system(n_samples=200, n_sequences=2)
    y = y + np.repeat([0.4, -0.4], 200) * 0.6 ** np.tile(np.arange(200), 2)
    search = HoldoutSearch(PNLSSRegressor(n_states=1, degree=2, max_iter=2, estimate_x0=True),
                           validation_fractions=[0.9]).fit(u, y, sequence_id=sequence_id)
    model = search.best_estimator_
    assert model.x0_.shape == (2, 1)
    rows = np.r_[20:200, 220:400]
    own = model.predict(u, sequence_id=sequence_id, x0=model.x0_)
    assert search.results_["holdout_rms"][0] == pytest.approx(
        rms_error(y[rows], own[rows]), rel=1e-12)
    # From the mean of the states, the decayed starts still differ by 1e-9.
    mean = model.predict(u, sequence_id=sequence_id)
    assert rms_error(y[rows], mean[rows]) != pytest.approx(rms_error(y[rows], own[rows]),
                                                            rel=1e-12)


class _DivergingModel:
    """Stands for a fitted candidate whose simulation diverges near the end."""

    def predict(self, X, sequence_id=None):
        y = np.ones(len(X))
        y[-3:] = np.nan
        return y


def test_a_diverging_candidate_is_ranked_last():
    X, Y = np.zeros((20, 1)), np.ones((20, 1))
    rows = np.zeros(20, dtype=bool)
    rows[-5:] = True
    assert _holdout_errors(_DivergingModel(), X, Y, None, rows) == (-np.inf, np.inf)
    # Outside the ranked rows a divergence does not matter.
    rows[-5:], rows[:5] = False, True
    assert _holdout_errors(_DivergingModel(), X, Y, None, rows) == (1.0, 0.0)


def test_is_a_clonable_estimator_with_nested_parameters():
    search = HoldoutSearch(PNLSSRegressor(n_states=2), validation_fractions=(0.3,))
    params = search.get_params()
    assert params["estimator__n_states"] == 2
    twin = clone(search).set_params(estimator__n_states=3)
    assert twin.estimator.n_states == 3 and search.estimator.n_states == 2


@pytest.mark.parametrize(
    "fractions, message",
    [([], "at least one share"), ([0.0, 0.3], "strictly between"),
     ([0.3, 1.0], "strictly between")],
)
def test_rejects_invalid_fractions(fractions, message):
    u, y, _ = _quadratic_system(n_samples=60)
    with pytest.raises(ValueError, match=message):
        HoldoutSearch(PNLSSRegressor(n_states=1, degree=2),
                      validation_fractions=fractions).fit(u, y)


def test_rejects_a_share_that_holds_out_no_sample():
    u, y, _ = _quadratic_system(n_samples=60)
    with pytest.raises(ValueError, match=r"validation_fractions: the smallest share, 0.001, "
                                         "holds out no sample"):
        HoldoutSearch(PNLSSRegressor(n_states=1, degree=2, max_iter=2, n_init=1),
                      validation_fractions=[0.001, 0.3]).fit(u, y)


def test_rejects_an_estimator_without_a_held_out_end():
    u, y, _ = _quadratic_system(n_samples=60)
    with pytest.raises(ValueError, match="no validation_fraction parameter"):
        HoldoutSearch(BLAEstimator(n_states=1)).fit(u, y)


def test_rejects_the_fraction_in_the_grid():
    u, y, _ = _quadratic_system(n_samples=60)
    with pytest.raises(ValueError, match="must not set validation_fraction"):
        HoldoutSearch(PNLSSRegressor(n_states=1, degree=2),
                      param_grid={"validation_fraction": [0.2]}).fit(u, y)


def test_predict_before_fit_raises():
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError):
        HoldoutSearch(PNLSSRegressor()).predict(np.zeros((5, 1)))


def test_a_periodic_model_prepends_its_transient_to_the_ranked_end():
    # With a period, n_transient samples are simulated before each sequence,
    # none is left out of it: half of each two-period sequence holds out one
    # whole period to rank on, even with a transient of one period.
    u, y, sequence_id = _quadratic_system(n_samples=100, n_sequences=2)
    model = PNLSSRegressor(n_states=1, degree=2, period=50, n_transient=50, max_iter=3,
                           n_init=1, random_state=0)
    search = HoldoutSearch(model, validation_fractions=(0.5,)).fit(
        u, y, sequence_id=sequence_id)
    assert search.holdout_fraction_ == 0.5 and np.isfinite(search.best_score_)


def test_a_dataframe_keeps_its_column_names():
    pd = pytest.importorskip("pandas")
    u, y, _ = _quadratic_system()
    X = pd.DataFrame(u, columns=["voltage"])
    with warnings.catch_warnings():
        # Predicting an array with a model fitted on named columns would warn.
        warnings.simplefilter("error", UserWarning)
        warnings.simplefilter("ignore", ConvergenceWarning)
        search = HoldoutSearch(PNLSSRegressor(n_states=1, degree=2, max_iter=3, n_init=1),
                               validation_fractions=(0.2, 0.3)).fit(X, y)
    np.testing.assert_array_equal(search.feature_names_in_, ["voltage"])


@pytest.mark.parametrize("n_jobs, backend", [(None, "loky"), (2, "loky"), (2, "threading")])
def test_the_candidates_warnings_reach_the_caller(n_jobs, backend):
    # Uncentred signals far from zero: every candidate's fit says so, from a
    # worker process or thread too.
    u, y, _ = _quadratic_system(n_samples=200)
    search = HoldoutSearch(PNLSSRegressor(n_states=1, degree=2, max_iter=2, center=False),
                           validation_fractions=[0.2, 0.3, 0.25, 0.35], n_jobs=n_jobs)
    with pytest.warns(DataWarning, match="the mean of output 0 is") as caught:
        with joblib.parallel_config(backend=backend):
            search.fit(u, y + 50.0)
    offsets = [w for w in caught if "the mean of output 0 is" in str(w.message)]
    assert len(offsets) == 4
    if backend == "loky":
        # Issued again by the search itself, at the user's line (a thread
        # issues them from the fit).
        assert all(w.filename == __file__ for w in offsets)
