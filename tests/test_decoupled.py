"""Decoupled PNLSS: compiled kernels and the estimator."""

import numpy as np
import pytest
from _numeric import central_differences
from sklearn.base import clone

from sknlss import DecoupledPNLSS, PNLSSRegressor
from sknlss._decoupled import _initial_parameters, _stack_polynomials
from sknlss._decoupled_kernels import (
    jacobian_decoupled,
    parameter_sizes,
    simulate_decoupled,
)
from sknlss._polynomial import evaluate_monomials
from sknlss.metrics import rms_error

# Several fits below use few iterations on purpose.
pytestmark = pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")


def _random_model(seed, n=3, n_u=2, n_y=2, rank=4, n_coef=3):
    rng = np.random.default_rng(seed)
    A = 0.6 * np.linalg.qr(rng.standard_normal((n, n)))[0]
    return (
        A,
        rng.standard_normal((n, n_u)),
        rng.standard_normal((n_y, n)),
        rng.standard_normal((n_y, n_u)),
        0.5 * rng.standard_normal((n + n_u, rank)),
        0.1 * rng.standard_normal((n + n_y, rank)),
        0.3 * rng.standard_normal((rank, n_coef)),
    )


def _blocks(theta, n, n_u, n_y, rank, n_coef):
    sizes = parameter_sizes(n, n_u, n_y, rank, n_coef)
    shapes = [(n, n), (n, n_u), (n_y, n), (n_y, n_u), (n + n_u, rank), (n + n_y, rank),
              (rank, n_coef), (n,)]
    parts = np.split(theta, np.cumsum(sizes[:-1]))
    return [p.reshape(s) for p, s in zip(parts, shapes)]


def test_jacobian_matches_central_differences():
    n, n_u, n_y, rank, n_coef = 3, 2, 2, 4, 3
    matrices = _random_model(0, n, n_u, n_y, rank, n_coef)
    rng = np.random.default_rng(1)
    U = 0.5 * rng.standard_normal((70, n_u))
    starts = np.array([0, 30, 70])
    x0 = 0.2 * rng.standard_normal(n)
    theta = np.concatenate([m.ravel() for m in (*matrices, x0)])

    def simulate(theta):
        *ms, x0 = _blocks(theta, n, n_u, n_y, rank, n_coef)
        return simulate_decoupled(*ms, U, starts, np.tile(x0, (2, 1)))[0]

    Y, dY, diverged = jacobian_decoupled(*matrices, U, starts, np.tile(x0, (2, 1)))
    assert not diverged
    assert dY.shape == (70, n_y, theta.size)
    np.testing.assert_array_equal(Y, simulate(theta))
    numeric = central_differences(simulate, theta)
    error = np.abs(numeric - dY).max() / np.abs(dY).max()
    assert error < 1e-6


def test_simulation_follows_the_equations():
    A, B, C, D, V, W, c = _random_model(2, 2, 1, 1, 2, 2)
    U = np.random.default_rng(0).standard_normal((5, 1))
    x = np.array([0.1, -0.2])
    expected = []
    for u in U:
        z = V.T @ np.concatenate([x, u])
        g = c[:, 0] * z**2 + c[:, 1] * z**3
        expected.append(C @ x + D @ u + W[2:] @ g)
        x = A @ x + B @ u + W[:2] @ g
    Y, X, diverged = simulate_decoupled(A, B, C, D, V, W, c, U, np.array([0, 5]),
                                        np.array([[0.1, -0.2]]))
    assert not diverged
    np.testing.assert_allclose(Y, np.array(expected), rtol=1e-12)
    assert X.shape == (5, 2)


def test_divergence_is_reported_and_filled_with_nan():
    A, B, C, D, V, W, c = _random_model(3, 2, 1, 1, 1, 2)
    W = 10.0 * np.ones_like(W)
    c = np.ones_like(c)
    U = 3.0 * np.ones((200, 1))
    starts = np.array([0, 100, 200])
    Y, X, diverged = simulate_decoupled(A, B, C, D, V, W, c, U, starts, np.zeros((2, 2)))
    assert diverged
    assert np.isnan(Y[99]) and np.isfinite(Y[0]).all()
    Y_j, dY, diverged_j = jacobian_decoupled(A, B, C, D, V, W, c, U, starts, np.zeros((2, 2)))
    assert diverged_j
    np.testing.assert_array_equal(np.isnan(Y_j), np.isnan(Y))


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


@pytest.fixture(scope="module")
def wiener_model(wiener_data):
    u, y = wiener_data
    return DecoupledPNLSS(
        n_states=2, rank=1, pnlss=PNLSSRegressor(degree=2, max_iter=30), max_iter=30,
        n_restarts=3, random_state=0,
    ).fit(u, y)


def test_fit_recovers_a_decoupled_system(wiener_data, wiener_model):
    u, y = wiener_data
    model = wiener_model
    assert model.score(u, y) > 0.999
    # The re-optimisation starts from the decoupled PNLSS and only improves it.
    assert np.all(np.diff(model.loss_history_) <= 0)
    u_new = 0.3 * np.random.default_rng(5).standard_normal((300, 1))
    assert rms_error(_wiener_system(u_new), model.predict(u_new)) < 0.05 * np.std(y)


def test_fitted_attributes(wiener_model):
    model = wiener_model
    n, n_u, n_y, rank, d = 2, 1, 1, 1, 2
    assert model.V_.shape == (n + n_u, rank)
    assert model.W_.shape == (n + n_y, rank)
    assert model.branch_coefficients_.shape == (rank, d - 1)
    assert model.n_params_ == n * n + n * n_u + n_y * n + n_y * n_u + (
        n + n_u + n + n_y + d - 1) * rank
    assert model.n_iter_ == len(model.loss_history_) - 1
    assert model.validation_loss_history_ is None
    assert isinstance(model.pnlss_, PNLSSRegressor)
    assert 0.0 <= model.decoupling_error_ < 1.0
    np.testing.assert_array_equal(model.x0_, 0.0)


def test_paper_parameter_count():
    # n = 3, n_u = n_y = 1, r = 5, cubic branches, x0 estimated.
    linear, x0 = 9 + 3 + 3 + 1, 3
    sizes = parameter_sizes(3, 1, 1, 5, 2)
    assert sum(sizes) == linear + 20 + 20 + 10 + x0 == 69


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
    assert model.x0_.shape == (2,)
    assert model.n_params_ == 4 + 2 + 2 + 1 + (3 + 3 + 2) * 2 + 2
    assert model.score(u, y) > 0.99


def test_fallback_starting_points_end_with_a_static_model(wiener_model):
    model = wiener_model
    pnlss = model.pnlss_
    V, W, c = model.V_, model.W_, model.branch_coefficients_
    candidates = list(_initial_parameters(pnlss, V, W, c, False))
    first, last = candidates[0], candidates[-1]
    np.testing.assert_array_equal(first[:4], pnlss.A_.ravel())
    # The last one has A = B = C = 0 and no branches: it cannot diverge.
    np.testing.assert_array_equal(last[: 4 + 2 + 2], 0.0)
    np.testing.assert_array_equal(last[8], pnlss.D_.ravel())


def test_pnlss_hyperparameters_are_nested():
    model = DecoupledPNLSS(pnlss=PNLSSRegressor())
    assert "pnlss__degree" in model.get_params()
    model.set_params(pnlss__degree=2, rank=3)
    assert clone(model).pnlss.degree == 2


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
    np.testing.assert_allclose(parallel.predict(u), sequential.predict(u))
    single = DecoupledPNLSS(**{**params, "n_init": 1}).fit(u, y)
    # The first start is the same in both; the kept one is at least as good.
    assert sequential.loss_history_[-1] <= single.loss_history_[-1]


@pytest.mark.slow
@pytest.mark.realdata
def test_cascaded_tanks(cascaded_tanks):
    data = cascaded_tanks
    # The paper's model: n = 3, r = 5, PNLSS-I of degrees 2 and 3; iterations
    # and starts are selected on the last 30 % of the estimation record.
    model = DecoupledPNLSS(
        n_states=3, rank=5, estimate_x0=True, validation_fraction=0.3, n_init=8,
        pnlss=PNLSSRegressor(degree=(2, 3)), random_state=0,
    ).fit(data.X_est, data.y_est)
    assert model.n_params_ <= 84
    assert rms_error(data.y_test, model.predict(data.X_test)) <= 0.497
