"""scikit-learn integration: estimator checks, searches, pipelines, persistence."""

import pickle

import joblib
import numpy as np
import pytest
import sklearn
from sklearn.base import clone
from sklearn.compose import TransformedTargetRegressor
from sklearn.model_selection import (
    GridSearchCV,
    GroupKFold,
    LeaveOneGroupOut,
    TimeSeriesSplit,
    cross_val_score,
)
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import MinMaxScaler, StandardScaler
from sklearn.utils.estimator_checks import parametrize_with_checks

from sknlss import (
    BLAEstimator,
    DecoupledPNLSS,
    LegendreBasis,
    NLLFRRegressor,
    NLSS2Regressor,
    PNLSSRegressor,
)
from sknlss.metrics import make_transient_scorer, rms_error
from sknlss.model_selection import HoldoutSearch

# A dynamical model's output at a sample depends on the samples before it, so
# predicting a permuted or a partial record cannot give the permuted or partial
# predictions: these two checks cannot hold, every other one must.
EXPECTED_FAILED_CHECKS = {
    "check_methods_sample_order_invariance": "a simulation depends on sample order",
    "check_methods_subset_invariance": "a simulation of a sub-record starts elsewhere",
}

ESTIMATORS = [
    BLAEstimator(),
    PNLSSRegressor(),
    NLSS2Regressor(),
    DecoupledPNLSS(),
    NLLFRRegressor(),
    # The search takes over its estimator's tags (a short search: the checks
    # test the wrapper, whose candidates are the estimators above).
    HoldoutSearch(NLLFRRegressor(n_init=1, max_iter=5), validation_fractions=(0.2, 0.3)),
]


@parametrize_with_checks(
    ESTIMATORS, expected_failed_checks=lambda estimator: EXPECTED_FAILED_CHECKS
)
def test_check_estimator(estimator, check):
    check(estimator)


def _second_order_system(u, *, noise=0.0, seed=0):
    """Weakly nonlinear second-order system (a Wiener-type output)."""
    rng = np.random.default_rng(seed)
    x = np.zeros(2)
    y = np.empty(len(u))
    for t, ut in enumerate(u[:, 0]):
        y[t] = x[0] + 0.2 * x[0] ** 2
        x = np.array([1.5 * x[0] - 0.7 * x[1] + ut, x[0]])
    return y + noise * rng.standard_normal(len(u))


@pytest.fixture(scope="module")
def three_records():
    rng = np.random.default_rng(1)
    u = rng.standard_normal((3 * 300, 1)) * 0.3
    sequence_id = np.repeat([0, 1, 2], 300)
    y = np.concatenate(
        [_second_order_system(u[sequence_id == k], noise=1e-3, seed=k) for k in range(3)]
    )
    return u, y, sequence_id


def test_grid_search_time_series_split_on_one_record(three_records):
    u, y, _ = three_records
    search = GridSearchCV(
        BLAEstimator(),
        {"n_states": [1, 2, 4]},
        cv=TimeSeriesSplit(n_splits=3),
        scoring=make_transient_scorer("rms", n_transient=20),
    )
    search.fit(u[:300], y[:300])
    # The system is second order: one state cannot describe it.
    assert search.best_params_["n_states"] in (2, 4)
    scores = search.cv_results_["mean_test_score"]
    assert scores[0] < max(scores[1], scores[2])


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
@pytest.mark.parametrize(
    "estimator, grid",
    [
        (PNLSSRegressor(n_states=2, max_iter=10), {"degree": [2, (2, 3)]}),
        (
            NLSS2Regressor(n_states=2, max_iter=10, random_state=0),
            {"alpha": [0.1, 1.0], "n_neurons": [1, 3]},
        ),
        (
            DecoupledPNLSS(n_states=2, max_iter=10, n_restarts=2, random_state=0,
                           pnlss=PNLSSRegressor(max_iter=10)),
            {"rank": [1, 2], "pnlss__degree": [2, (2, 3)]},
        ),
    ],
    ids=lambda value: type(value).__name__ if hasattr(value, "fit") else "",
)
def test_grid_search_tunes_nonlinear_hyperparameters(three_records, estimator, grid):
    u, y, _ = three_records
    search = GridSearchCV(
        estimator, grid, cv=TimeSeriesSplit(n_splits=2),
        scoring=make_transient_scorer("rms", n_transient=20), error_score="raise",
    ).fit(u[:300], y[:300])
    n_candidates = int(np.prod([len(values) for values in grid.values()]))
    assert len(search.cv_results_["params"]) == n_candidates
    assert np.all(np.isfinite(search.cv_results_["mean_test_score"]))
    assert set(search.best_params_) == set(grid)
    # The refitted model is the best candidate, fitted on the whole record.
    assert search.best_estimator_.get_params()[next(iter(grid))] == search.best_params_[
        next(iter(grid))
    ]


@pytest.fixture
def routing():
    with sklearn.config_context(enable_metadata_routing=True):
        yield


@pytest.mark.parametrize("cv", [GroupKFold(n_splits=3), LeaveOneGroupOut()])
def test_grid_search_routes_sequence_id(routing, three_records, cv):
    u, y, sequence_id = three_records
    model = BLAEstimator().set_fit_request(sequence_id=True)
    scorer = make_transient_scorer("rms", n_transient=20).set_score_request(
        sequence_id=True
    )
    search = GridSearchCV(model, {"n_states": [1, 2]}, cv=cv, scoring=scorer)
    search.fit(u, y, groups=sequence_id, sequence_id=sequence_id)
    assert search.best_params_ == {"n_states": 2}
    assert np.isfinite(search.best_score_)


def test_routed_scorer_simulates_each_sequence_from_its_own_start(routing, three_records):
    u, y, sequence_id = three_records
    model = BLAEstimator(n_states=2).fit(u, y, sequence_id=sequence_id)
    scorer = make_transient_scorer("rms").set_score_request(sequence_id=True)
    per_sequence = -scorer(model, u, y, sequence_id=sequence_id)
    y_pred = model.predict(u, sequence_id=sequence_id)
    assert per_sequence == pytest.approx(rms_error(y, y_pred))
    assert per_sequence == pytest.approx(
        rms_error(y, np.concatenate([model.predict(u[sequence_id == k]) for k in range(3)]))
    )


def test_estimator_score_uses_routed_sequence_id(routing, three_records):
    u, y, sequence_id = three_records
    model = (
        BLAEstimator(n_states=2)
        .set_fit_request(sequence_id=True)
        .set_score_request(sequence_id=True)
    )
    scores = cross_val_score(
        model, u, y, cv=LeaveOneGroupOut(),
        params={"sequence_id": sequence_id, "groups": sequence_id},
    )
    by_hand = []
    for left_out in range(3):
        fitted = sequence_id != left_out
        by_hand.append(
            BLAEstimator(n_states=2)
            .fit(u[fitted], y[fitted], sequence_id=sequence_id[fitted])
            .score(u[~fitted], y[~fitted], sequence_id=sequence_id[~fitted]))
    np.testing.assert_allclose(scores, by_hand, rtol=1e-12)
    # The output's quadratic term bounds a linear model's R2 (0.90 to 0.94
    # over the three folds).
    assert np.all(scores > 0.85)


def test_unrequested_metadata_is_refused(routing, three_records):
    u, y, sequence_id = three_records
    search = GridSearchCV(BLAEstimator(), {"n_states": [1, 2]}, cv=GroupKFold(3))
    with pytest.raises(ValueError, match="sequence_id"):
        search.fit(u, y, groups=sequence_id, sequence_id=sequence_id)


def test_bad_sequence_id_in_search_is_reported(routing, three_records):
    u, y, sequence_id = three_records
    model = BLAEstimator().set_fit_request(sequence_id=True)
    search = GridSearchCV(model, {"n_states": [2]}, cv=GroupKFold(3), error_score="raise")
    with pytest.raises(ValueError, match="sequence_id"):
        search.fit(u, y, groups=sequence_id, sequence_id=sequence_id[:-1])
    interleaved = np.tile([0, 1, 2], 300)
    with pytest.raises(ValueError, match="contiguous"):
        model.fit(u, y, sequence_id=interleaved)


def test_pipeline_and_transformed_target(three_records):
    u, y, _ = three_records
    u, y = u[:300], y[:300]
    reference = BLAEstimator(n_states=2).fit(u, y).predict(u)
    # The estimators remove offsets and scales themselves, so affine input and
    # output transforms around them leave the simulation unchanged.
    piped = make_pipeline(MinMaxScaler(), BLAEstimator(n_states=2)).fit(u, y).predict(u)
    wrapped = TransformedTargetRegressor(
        regressor=BLAEstimator(n_states=2), transformer=StandardScaler()
    ).fit(u, y).predict(u)
    np.testing.assert_allclose(piped, reference, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(wrapped, reference, rtol=1e-6, atol=1e-8)


def test_nested_parameters_and_clone():
    model = make_pipeline(StandardScaler(), DecoupledPNLSS(rank=3))
    model.set_params(decoupledpnlss__rank=4, decoupledpnlss__n_states=3)
    params = model.get_params()
    assert params["decoupledpnlss__rank"] == 4
    twin = clone(model)
    assert twin.get_params()["decoupledpnlss__n_states"] == 3
    # A nested parameter of a sub-object left at None (its defaults) is refused
    # by name, also when a search sets it; given the object, it is set.
    with pytest.raises(ValueError, match="pnlss__degree sets a parameter of pnlss, which is "
                                         "None"):
        DecoupledPNLSS().set_params(pnlss__degree=2)
    with pytest.raises(ValueError, match="bla__n_transient .* bla, which is None"):
        GridSearchCV(PNLSSRegressor(), {"bla__n_transient": [0, 10]}).fit(
            np.zeros((200, 1)), np.zeros(200))
    tuned = DecoupledPNLSS().set_params(pnlss=PNLSSRegressor(), pnlss__degree=2)
    assert tuned.pnlss.degree == 2


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
@pytest.mark.parametrize(
    "estimator",
    [
        BLAEstimator(n_states=2),
        PNLSSRegressor(n_states=2, max_iter=5),
        NLSS2Regressor(n_states=2, max_iter=5, random_state=0),
        DecoupledPNLSS(n_states=2, rank=2, max_iter=5, random_state=0),
        NLLFRRegressor(n_states=2, max_iter=5, random_state=0),
        NLLFRRegressor(n_states=2, n_branches=2, basis=LegendreBasis(1, shift=True),
                       max_iter=5, random_state=0),
        HoldoutSearch(NLLFRRegressor(n_states=2, max_iter=5, n_init=1),
                      validation_fractions=(0.2, 0.3), param_grid={"n_branches": [1, 2]}),
    ],
    ids=lambda est: type(est).__name__,
)
def test_pickle_and_joblib_round_trip(estimator, three_records, tmp_path):
    u, y, _ = three_records
    u, y = u[:300], y[:300]
    fitted = clone(estimator).fit(u, y)
    expected = fitted.predict(u)
    restored = pickle.loads(pickle.dumps(fitted))
    np.testing.assert_array_equal(restored.predict(u), expected)
    path = tmp_path / "model.joblib"
    joblib.dump(fitted, path)
    np.testing.assert_array_equal(joblib.load(path).predict(u), expected)


def test_a_transient_scorer_without_a_score_request_refuses_sequence_id(routing,
                                                                        three_records):
    # As scikit-learn's own scorers do: not silently scoring a fold of
    # several records as one record.
    u, y, sequence_id = three_records
    search = GridSearchCV(BLAEstimator().set_fit_request(sequence_id=True),
                          {"n_states": [1, 2]}, cv=GroupKFold(3),
                          scoring=make_transient_scorer("rms", n_transient=20))
    with pytest.raises(ValueError, match=r"sequence_id.*set_score_request"):
        search.fit(u, y, groups=sequence_id, sequence_id=sequence_id)
