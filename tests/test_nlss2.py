import warnings

import numpy as np
import pytest
from scipy.signal import lfilter
from sklearn.base import clone
from sklearn.exceptions import ConvergenceWarning

from sknlss import BLAEstimator, LinearFallbackWarning, NLSS2Regressor
from sknlss._core._model import StateSpaceModel
from sknlss._estimators._nlss2 import ALPHA_GRID
from sknlss._terms._network import NetworkTerms
from sknlss.metrics import rms_error


def test_zero_output_weights_give_the_linear_model():
    model = StateSpaceModel(3, 1, 1, NetworkTerms(3, 1, 1, 2, "sigmoid"))
    rng = np.random.default_rng(1)
    values = {name: 0.5 * rng.standard_normal(shape) for name, shape in model.blocks}
    for name in ("f_v", "f_c", "g_v", "g_c"):
        values[name][:] = 0.0
    U = rng.standard_normal((30, 1))
    x0 = np.array([0.1, -0.2, 0.3])
    Y, X, diverged = model.simulate(model.pack(values), U, np.array([0, 30]), x0=x0)
    x = x0
    for t in range(30):
        np.testing.assert_allclose(X[t], x)
        np.testing.assert_allclose(Y[t], values["C"] @ x + values["D"] @ U[t])
        x = values["A"] @ x + values["B"] @ U[t]
    assert not diverged


def _nonlinear_system(n_samples, seed, noise=0.0):
    """Second-order system with a saturating state equation and output."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n_samples, 1))
    x = np.zeros(2)
    y = np.empty(n_samples)
    for t in range(n_samples):
        y[t] = x[0] + 0.3 * np.tanh(x[0])
        x = np.array([0.6 * x[0] + 0.3 * x[1] + 0.2 * np.tanh(x[1]),
                      -0.3 * x[0] + 0.4 * x[1] + u[t, 0]])
    return u, y + noise * rng.standard_normal(n_samples)


@pytest.fixture(scope="module")
def nonlinear_records():
    return _nonlinear_system(400, seed=0), _nonlinear_system(400, seed=1)


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_fit_beats_the_linear_model(nonlinear_records):
    (u, y), (u_test, y_test) = nonlinear_records
    # The paper's cost on 400 noise-free samples of a weakly nonlinear system
    # (the defaults' weight decay, a prior, restrains a record this short).
    # The test error over the BLA's was 0.229, 0.452, 0.247, 0.309 and 0.133
    # at random states 0-4 (median 0.247; medians of three consecutive
    # random states 0.247 to 0.309).
    models = [NLSS2Regressor(n_states=2, max_iter=50, weight_decay=0.0, n_init=1,
                             validation_fraction=0.0, random_state=seed).fit(u, y)
              for seed in range(5)]
    linear_error = rms_error(y_test, BLAEstimator(n_states=2).fit(u, y).predict(u_test))
    ratios = [rms_error(y_test, model.predict(u_test)) / linear_error for model in models]
    assert np.median(ratios) < 0.4
    model = models[0]
    assert model.loss_history_[-1] < model.loss_history_[0]
    assert model.n_iter_ == len(model.loss_history_) - 1
    assert model.validation_loss_history_ is None
    assert model.states_init_.shape == (400, 2)


def test_fitted_attributes_and_parameter_count():
    rng = np.random.default_rng(0)
    u = rng.standard_normal((200, 1))
    y = np.convolve(u[:, 0], [0.0, 1.0, 0.5], mode="full")[:200]
    model = NLSS2Regressor(n_states=3, estimate_x0=True, max_iter=3, random_state=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(u, y)
    # The paper's count for the Cascaded Tanks model (n = 3, SISO, 2 neurons):
    # the output networks' biases hold the output offset.
    assert model.n_params_ == 71
    assert model.f_hidden_weights_.shape == (3, 2, 4)
    assert model.f_hidden_biases_.shape == (3, 2)
    assert model.f_output_weights_.shape == (3, 2)
    assert model.f_output_biases_.shape == (3,)
    assert model.g_hidden_weights_.shape == (1, 2, 4)
    assert model.g_hidden_biases_.shape == (1, 2)
    assert model.g_output_weights_.shape == (1, 2)
    assert model.g_output_biases_.shape == (1,)
    assert model.x0_.shape == (3,)
    np.testing.assert_array_equal(model.output_offset_, [0.0])
    n_free = sum(getattr(model, name).size for name in (
        "A_", "B_", "C_", "D_", "x0_", "f_hidden_weights_", "f_hidden_biases_",
        "f_output_weights_", "f_output_biases_", "g_hidden_weights_", "g_hidden_biases_",
        "g_output_weights_", "g_output_biases_"))
    assert n_free == model.n_params_


def test_the_linear_model_to_fall_back_on_is_the_bla_with_its_offset():
    # Noisy data of a linear system that starts away from rest and varies about
    # a level of its own: without re-optimisation (max_iter=0) the network
    # starts do worse than the BLA on the held-out end (at random states 0-3).
    rng = np.random.default_rng(0)
    u = 0.3 * rng.standard_normal((200, 1))
    y = (lfilter([0.0, 1.0], [1.0, -1.5, 0.7], u[:, 0], zi=[2.0, -1.0])[0] + 0.5
         + 0.2 * rng.standard_normal(200))
    model = NLSS2Regressor(n_states=2, estimate_x0=True, refine_linear=False, max_iter=0,
                           validation_fraction=0.25, n_init=2, random_state=0)
    # The starts fit their own rows worse than the linear model: a verdict of
    # the data, recorded without a warning.
    with warnings.catch_warnings():
        warnings.simplefilter("error", LinearFallbackWarning)
        model.fit(u, y)
    assert model.fell_back_to_linear_
    assert np.all(np.isinf(model.start_losses_))
    # The output networks' biases hold the BLA's output offset; there is no
    # separate offset to duplicate them.
    np.testing.assert_array_equal(model.output_offset_, [0.0])
    np.testing.assert_allclose(model.g_output_biases_, model.bla_.output_offset_)
    np.testing.assert_allclose(model.predict(u), model.bla_.predict(u), atol=1e-12)


def test_mimo_with_sequences_and_holdout():
    rng = np.random.default_rng(3)
    u = rng.standard_normal((300, 2))
    y = np.column_stack([
        np.convolve(u[:, 0], [0.0, 1.0, 0.4], mode="full")[:300],
        np.tanh(np.convolve(u[:, 1], [0.0, 0.5, 0.5], mode="full")[:300]),
    ])
    sequence_id = np.repeat([0, 1], 150)
    model = NLSS2Regressor(n_states=4, activation="tanh", validation_fraction=0.2,
                           estimate_x0=True, refine_linear=True, max_iter=10,
                           n_transient=5, random_state=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(u, y, sequence_id=sequence_id)
    assert model.predict(u, sequence_id=sequence_id).shape == (300, 2)
    assert model.validation_loss_history_.shape == model.loss_history_.shape
    # 0.9978 to 0.9989 at random states 0-4; the BLA's 0.979.
    assert model.score(u, y, sequence_id=sequence_id) > 0.99


def test_multistart_is_reproducible_and_parallel(nonlinear_records):
    (u, y), _ = nonlinear_records
    params = dict(n_states=2, max_iter=5, n_init=3, random_state=42)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        serial = NLSS2Regressor(**params).fit(u, y)
        parallel = NLSS2Regressor(n_jobs=2, **params).fit(u, y)
        single = NLSS2Regressor(**{**params, "n_init": 1}).fit(u, y)
    np.testing.assert_array_equal(serial.predict(u), parallel.predict(u))
    # the best of three starts includes the first one
    assert serial.loss_history_[-1] <= single.loss_history_[-1]


def test_weight_decay_shrinks_the_network_weights(nonlinear_records):
    (u, y), _ = nonlinear_records

    def weight_norm(model):
        return sum(np.sum(getattr(model, f"{f}_{kind}_weights_") ** 2)
                   for f in "fg" for kind in ("hidden", "output"))

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        free = NLSS2Regressor(n_states=2, max_iter=20, weight_decay=0.0,
                              random_state=0).fit(u, y)
        decayed = NLSS2Regressor(n_states=2, max_iter=20, weight_decay=100.0,
                                 random_state=0).fit(u, y)
    assert weight_norm(decayed) < weight_norm(free)


def test_alpha_auto_selects_from_the_grid(nonlinear_records):
    (u, y), _ = nonlinear_records
    model = NLSS2Regressor(n_states=2, alpha="auto", validation_fraction=0.25, max_iter=5,
                           random_state=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(u, y)
    assert model.alpha_ in ALPHA_GRID
    assert model.alpha_losses_.shape == ALPHA_GRID.shape
    assert model.alpha_losses_[list(ALPHA_GRID).index(model.alpha_)] == model.alpha_losses_.min()


def test_bad_input():
    u = np.random.default_rng(0).standard_normal((50, 1))
    y = u[:, 0].copy()
    y[3] = np.nan
    with pytest.raises(ValueError):
        NLSS2Regressor().fit(u, y)
    with pytest.raises(ValueError, match="alpha"):
        NLSS2Regressor(alpha=-1.0).fit(u, u[:, 0])
    with pytest.raises(ValueError, match="activation"):
        NLSS2Regressor(activation="relu").fit(u, u[:, 0])


@pytest.mark.slow
def test_reference_pnlss_system():
    from sknlss.datasets import make_pnlss_reference

    data = make_pnlss_reference()
    sid, period = data.sequence_id, data.period
    # Steady-state records simulated from rest: the first period of every
    # sequence is a transient, left out of the costs and of the test error.
    bla = BLAEstimator(n_states=2, period=period, n_transient=period)
    linear = clone(bla).fit(data.X[sid <= 1], data.y[sid <= 1], sequence_id=sid[sid <= 1])
    model = NLSS2Regressor(n_states=2, max_iter=100, n_transient=period, bla=bla,
                           random_state=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(data.X[sid <= 2], data.y[sid <= 2], sequence_id=sid[sid <= 2])
    test = sid == 3
    linear_rms = rms_error(data.y[test], linear.predict(data.X[test]), n_transient=period)
    rms = rms_error(data.y[test], model.predict(data.X[test]), n_transient=period)
    assert rms < 0.1 * linear_rms
