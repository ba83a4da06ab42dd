"""Decoupled PNLSS: the branch terms and the estimator."""

import warnings

import numpy as np
import pytest
from scipy.signal import lfilter
from sklearn.base import clone
from sklearn.exceptions import ConvergenceWarning

from sknlss import (BLAEstimator, ChebyshevBasis, DecoupledPNLSS, LegendreBasis,
                    LinearFallbackWarning, PNLSSRegressor, PolynomialBasis)
from sknlss._core._model import StateSpaceModel
from sknlss._estimators._decoupled import _stack_polynomials
from sknlss._terms._branches import BranchTerms
from sknlss._terms._polynomial import evaluate_monomials
from sknlss.metrics import rms_error

# Several fits below use few iterations on purpose.
pytestmark = pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")


def test_branch_terms_follow_the_equations():
    rng = np.random.default_rng(2)
    model = StateSpaceModel(2, 1, 1, BranchTerms(2, 1, 1, 2, PolynomialBasis(3)))
    values = {name: 0.3 * rng.standard_normal(shape) for name, shape in model.blocks}
    values["A"] = 0.5 * np.eye(2)
    A, B, C, D, V, W, c = (values[k] for k in ("A", "B", "C", "D", "V", "W",
                                               "coefficients"))
    U = rng.standard_normal((5, 1))
    x = np.array([0.1, -0.2])
    expected = []
    for u in U:
        z = V.T @ np.concatenate([x, u])
        g = c[:, 0] * z**2 + c[:, 1] * z**3
        expected.append(C @ x + D @ u + W[2:] @ g)
        x = A @ x + B @ u + W[:2] @ g
    Y, X, diverged = model.simulate(model.pack(values), U, np.array([0, 5]),
                                    x0=np.array([0.1, -0.2]))
    assert not diverged
    np.testing.assert_allclose(Y, np.array(expected), rtol=1e-12)
    assert X.shape == (5, 2)


@pytest.mark.parametrize("basis", [PolynomialBasis(3), LegendreBasis(3),
                                   ChebyshevBasis(2, constant=True)])
def test_branch_terms_continue_along_tangents_beyond_their_input_range(basis):
    # The kernels apply the functions that the basis's evaluate() gives, for
    # every family, inside the range and along the tangents beyond it.
    rng = np.random.default_rng(3)
    input_range = np.array([[-0.1, -0.3], [0.2, 0.1]])
    model = StateSpaceModel(2, 1, 1, BranchTerms(2, 1, 1, 2, basis, input_range))
    values = {name: 0.3 * rng.standard_normal(shape) for name, shape in model.blocks}
    values["A"] = 0.5 * np.eye(2)
    U = 2.0 * rng.standard_normal((40, 1))
    x0 = np.array([0.1, -0.2])
    Y, X, _ = model.simulate(model.pack(values), U, np.array([0, 40]), x0=x0)
    Z = np.hstack([X, U]) @ values["V"]
    assert np.any(Z < input_range[0]) and np.any(Z > input_range[1])
    inside = np.clip(Z, *input_range)
    g = np.empty_like(Z)
    for l in range(2):
        phi, slopes = basis.evaluate(inside[:, l])
        c = values["coefficients"][l]
        g[:, l] = phi @ c + (slopes @ c) * (Z[:, l] - inside[:, l])
    C, D, W = values["C"], values["D"], values["W"]
    expected = X @ C.T + U @ D.T + g @ W[2:].T
    np.testing.assert_allclose(Y, expected, rtol=1e-12, atol=1e-14)


def test_stack_polynomials_takes_the_union_of_monomials():
    E = np.array([[1.0, 2.0]])
    F = np.array([[3.0, 4.0]])
    zeta = np.array([[2, 0], [1, 1]])
    eta = np.array([[1, 1], [0, 2]])
    coefficients, exponents = _stack_polynomials(E, zeta, F, eta)
    S = np.random.default_rng(0).standard_normal((10, 2))
    np.testing.assert_allclose(
        evaluate_monomials(S, exponents) @ coefficients.T,
        np.column_stack([evaluate_monomials(S, zeta) @ E.T, evaluate_monomials(S, eta) @ F.T]),
    )


def _wiener_system(u):
    """Second-order linear dynamics with a quadratic output: rank one."""
    x = np.zeros(2)
    y = np.empty(len(u))
    for t, ut in enumerate(u[:, 0]):
        y[t] = x[0] + 0.2 * x[0] ** 2
        x = np.array([1.5 * x[0] - 0.7 * x[1] + ut, x[0]])
    return y


@pytest.fixture(scope="module")
def wiener_data():
    u = 0.3 * np.random.default_rng(0).standard_normal((400, 1))
    return u, _wiener_system(u)


# The paper's cost, one start, no hold-out: exact recovery of a system of the
# model's class, without the regularisation the defaults add.
PLAIN = dict(stability_penalty=0.0, weight_decay=0.0, n_init=1, validation_fraction=0.0)


@pytest.fixture(scope="module")
def wiener_model(wiener_data):
    u, y = wiener_data
    return DecoupledPNLSS(
        n_states=2, rank=1,
        pnlss=PNLSSRegressor(degree=2, max_iter=30, center=False, **PLAIN),
        max_iter=30, n_restarts=3, random_state=0, **PLAIN,
    ).fit(u, y)


def test_fit_recovers_a_decoupled_system(wiener_data, wiener_model):
    u, y = wiener_data
    model = wiener_model
    # A noise-free system of the model's class: recovered to rounding (errors
    # of 4e-16 times the output's standard deviation at random states 0-4).
    assert rms_error(y, model.predict(u)) < 1e-8 * np.std(y)
    # The re-optimisation starts from the decoupled PNLSS and only improves it.
    assert np.all(np.diff(model.loss_history_) <= 0)
    u_new = 0.3 * np.random.default_rng(5).standard_normal((300, 1))
    assert rms_error(_wiener_system(u_new), model.predict(u_new)) < 1e-8 * np.std(y)


def test_a_delayed_input_is_decoupled_in_step_with_the_states(wiener_data, monkeypatch):
    # The branches are sampled where the PNLSS model goes: its states on the
    # user's input, which it delays itself, beside the input delayed once.
    u, y = wiener_data
    delay = 3
    y_late = np.concatenate([np.zeros(delay), y[:-delay]])
    seen = {}
    prepare = DecoupledPNLSS._prepare_starts

    def spy(self, context):
        prepare(self, context)
        seen.update(context)

    monkeypatch.setattr(DecoupledPNLSS, "_prepare_starts", spy)
    model = DecoupledPNLSS(
        n_states=2, rank=1, input_delay=delay,
        pnlss=PNLSSRegressor(degree=2, max_iter=30, center=False, **PLAIN),
        max_iter=30, n_restarts=3, random_state=0, **PLAIN,
    ).fit(u, y_late)
    rows = seen["rows"].fit_rows[seen["rows"].original]
    states = model.pnlss_.simulate(u, return_states=True)[1]
    np.testing.assert_allclose(seen["points"][:, :2], states[rows], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(seen["points"][:, 2:], seen["U"][rows])
    # Noise-free data of the model's class, delayed: recovered as without delay.
    assert rms_error(y_late, model.predict(u)) < 1e-8 * np.std(y)


def test_a_dataframe_fit_warns_nothing_about_feature_names(wiener_data):
    pd = pytest.importorskip("pandas")
    u, y = wiener_data
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model = DecoupledPNLSS(n_states=2, rank=2, max_iter=5, n_init=1, n_restarts=1,
                               random_state=0).fit(pd.DataFrame({"u": u[:, 0]}), y)
    assert not [w for w in caught if "feature names" in str(w.message)]
    assert list(model.feature_names_in_) == ["u"]


def test_too_few_sampling_points_are_refused_before_the_pnlss_fit(wiener_data, monkeypatch):
    u, y = wiener_data
    monkeypatch.setattr(PNLSSRegressor, "fit", lambda *args, **kwargs: pytest.fail("fitted"))
    with pytest.raises(ValueError, match=r"n_sampling_points=2 cannot determine branches of "
                                         r"degree 3; use at least 3"):
        DecoupledPNLSS(n_states=2, rank=2, n_sampling_points=2).fit(u, y)


def test_fitted_attributes(wiener_model):
    model = wiener_model
    n, n_u, n_y, rank, d = 2, 1, 1, 1, 2
    assert model.V_.shape == (n + n_u, rank)
    assert model.W_.shape == (n + n_y, rank)
    assert model.branch_coefficients_.shape == (rank, d - 1)
    lower, upper = model.branch_input_range_
    assert lower.shape == (rank,) and np.all(lower < upper)
    assert model.extrapolation_ == "linear"
    assert model.n_params_ == n * n + n * n_u + n_y * n + n_y * n_u + (
        n + n_u + n + n_y + d - 1) * rank
    assert model.n_iter_ == len(model.loss_history_) - 1
    assert model.validation_loss_history_ is None
    assert isinstance(model.pnlss_, PNLSSRegressor)
    assert 0.0 <= model.decoupling_error_ < 1.0
    np.testing.assert_array_equal(model.x0_, 0.0)


def test_paper_parameter_count():
    # n = 3, n_u = n_y = 1, r = 5, cubic branches, x0 and the output offset
    # estimated: within the paper's 84.
    linear, x0, offset = 9 + 3 + 3 + 1, 3, 1
    model = StateSpaceModel(3, 1, 1, BranchTerms(3, 1, 1, 5, PolynomialBasis(3)),
                            estimate_x0=True)
    assert model.n_params == linear + 20 + 20 + 10 + x0 + offset == 70


def test_options_x0_validation_and_trajectory_sampling(wiener_data):
    u, y = wiener_data
    model = DecoupledPNLSS(
        n_states=2, rank=2, branch_degree=3, sampling="trajectory", estimate_x0=True,
        validation_fraction=0.25, pnlss=PNLSSRegressor(degree=2, max_iter=10),
        max_iter=10, n_restarts=2, random_state=0,
    ).fit(u, y)
    assert model.pnlss_.estimate_x0 and model.pnlss_.validation_fraction == 0.25
    assert model.branch_coefficients_.shape == (2, 2)
    assert len(model.validation_loss_history_) == model.n_iter_ + 1
    assert model.x0_.shape == (2,) and model.output_offset_.shape == (1,)
    assert model.n_params_ == 4 + 2 + 2 + 1 + (3 + 3 + 2) * 2 + 2 + 1
    assert model.score(u, y) > 0.99


def test_the_model_to_beat_and_to_fall_back_on_is_the_bla():
    # Noisy data of a linear system: without re-optimisation (max_iter=0) the
    # decoupled starts do worse than the BLA on the held-out end at this seed
    # (they fit their own rows worse than it does).
    rng = np.random.default_rng(0)
    u = 0.3 * rng.standard_normal((400, 1))
    y = lfilter([0.0, 1.0], [1.0, -1.5, 0.7], u[:, 0]) + 0.05 * rng.standard_normal(400)
    model = DecoupledPNLSS(n_states=2, rank=1, estimate_x0=True, validation_fraction=0.25,
                           pnlss=PNLSSRegressor(degree=(2, 3), max_iter=10), max_iter=0,
                           n_restarts=2, n_init=2, random_state=0).fit(u, y)
    # Both fits hold out the same end, on which the PNLSS fit judged the same BLA.
    assert not model.pnlss_.fell_back_to_linear_
    assert model.linear_loss_ == pytest.approx(model.pnlss_.linear_loss_, rel=1e-12)
    assert model.fell_back_to_linear_
    assert np.all(model.branch_coefficients_ == 0)
    # The BLA itself: its dynamics, initial state and output offset.
    np.testing.assert_allclose(model.output_offset_, model.bla_.output_offset_)
    np.testing.assert_allclose(model.predict(u), model.bla_.predict(u), atol=1e-12)


def test_pnlss_hyperparameters_are_nested():
    model = DecoupledPNLSS(pnlss=PNLSSRegressor())
    assert "pnlss__degree" in model.get_params()
    model.set_params(pnlss__degree=2, rank=3)
    assert clone(model).pnlss.degree == 2


def test_errors_name_the_decoupled_model(wiener_data):
    u, y = wiener_data
    with pytest.raises(ValueError, match="'pnlss' parameter of DecoupledPNLSS must be an "
                                         "instance of .*PNLSSRegressor"):
        DecoupledPNLSS(pnlss=BLAEstimator()).fit(u, y)
    with pytest.raises(ValueError, match="This DecoupledPNLSS estimator requires y"):
        DecoupledPNLSS().fit(u, None)


def test_random_state_makes_the_fit_reproducible(wiener_data):
    u, y = wiener_data
    params = dict(n_states=2, rank=1, pnlss=PNLSSRegressor(degree=2, max_iter=5),
                  max_iter=5, n_restarts=2, random_state=3)
    first = DecoupledPNLSS(**params).fit(u, y)
    second = DecoupledPNLSS(**params).fit(u, y)
    np.testing.assert_array_equal(first.predict(u), second.predict(u))


def test_several_starts_in_parallel_match_sequential(wiener_data):
    u, y = wiener_data
    params = dict(n_states=2, rank=1, pnlss=PNLSSRegressor(degree=2, max_iter=5),
                  max_iter=5, n_restarts=2, n_init=2, random_state=1)
    sequential = DecoupledPNLSS(**params).fit(u, y)
    parallel = DecoupledPNLSS(**params, n_jobs=2).fit(u, y)
    # The PNLSS model's starts run on the same workers.
    assert parallel.pnlss_.n_jobs == 2
    np.testing.assert_allclose(parallel.predict(u), sequential.predict(u))
    single = DecoupledPNLSS(**{**params, "n_init": 1}).fit(u, y)
    assert sequential.start_losses_.shape == (2,) and single.start_losses_.shape == (1,)
    assert np.all(np.isfinite(sequential.start_losses_))


def test_only_the_final_optimisation_warns(wiener_data):
    u, y = wiener_data
    # The PNLSS starting point stops at max_iter while improving; only the
    # decoupled model's own optimisation may say so.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        DecoupledPNLSS(n_states=2, rank=1, pnlss=PNLSSRegressor(degree=2, max_iter=2, **PLAIN),
                       max_iter=30, random_state=0, **PLAIN).fit(u, y)
    from_pnlss = [w for w in caught if issubclass(w.category, ConvergenceWarning)
                  and str(w.message).startswith("PNLSS")]
    assert not from_pnlss


def test_the_pnlss_fit_warns_in_the_decoupled_models_name(wiener_data):
    # 40 samples are too few for the PNLSS model's terms: it warns that it
    # keeps its linear model, and the user who fitted a DecoupledPNLSS reads
    # it in that name.
    u, y = wiener_data
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        DecoupledPNLSS(n_states=2, rank=1, n_init=1, random_state=0).fit(u[:40], y[:40])
    messages = [str(w.message) for w in caught if w.category is LinearFallbackWarning]
    assert any(m.startswith("DecoupledPNLSS: the PNLSS model it starts from: PNLSSRegressor(")
               for m in messages)
    assert not any(m.startswith("PNLSSRegressor(") for m in messages)
    assert all(w.filename == __file__ for w in caught)
