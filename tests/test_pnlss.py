import warnings

import numpy as np
import pytest
from _numeric import central_differences
from sklearn.base import clone
from sklearn.exceptions import ConvergenceWarning

import sknlss._pnlss as pnlss_module
from sknlss import BLAEstimator, PNLSSRegressor, SimulationDivergedWarning
from sknlss.__main__ import MODELS
from sknlss._base import DIVERGENCE_BOUND
from sknlss._pnlss import _local_spectral_radius, _PNLSSProblem, _steady_state_rows
from sknlss._pnlss_kernels import jacobian_pnlss, monomial_state_derivatives, simulate_pnlss
from sknlss._polynomial import evaluate_monomials, monomial_exponents, monomial_jacobian
from sknlss.datasets import make_cascaded_tanks, make_pnlss_reference
from sknlss.metrics import rms_error

STRUCTURES = ["full", "states_only", "no_cross_products", "inputs_only"]


def _random_model(n, n_u, n_y, state_terms, output_terms, seed):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    A *= 0.7 / max(abs(np.linalg.eigvals(A)))
    ez = monomial_exponents(n, n_u, (2, 3), state_terms)
    ee = monomial_exponents(n, n_u, (2, 3), output_terms)
    matrices = [
        A,
        rng.normal(size=(n, n_u)),
        rng.normal(size=(n_y, n)),
        rng.normal(size=(n_y, n_u)),
        0.05 * rng.normal(size=(n, len(ez))),
        0.05 * rng.normal(size=(n_y, len(ee))),
    ]
    return matrices, ez, ee


def _reference_simulation(A, B, C, D, E, F, ez, ee, U, x0):
    """Plain NumPy simulation of one sequence, independent of the kernels."""
    x = x0.copy()
    Y = np.empty((len(U), C.shape[0]))
    for t, u in enumerate(U):
        s = np.concatenate([x, u])[None]
        Y[t] = C @ x + D @ u + F @ evaluate_monomials(s, ee)[0]
        x = A @ x + B @ u + E @ evaluate_monomials(s, ez)[0]
    return Y


def _pack(matrices, x0=None):
    parts = [m.ravel() for m in matrices]
    if x0 is not None:
        parts.append(x0)
    return np.concatenate(parts)


def test_simulation_matches_plain_numpy():
    matrices, ez, ee = _random_model(3, 2, 2, "full", "states_only", seed=0)
    rng = np.random.default_rng(1)
    U = 0.3 * rng.normal(size=(60, 2))
    starts = np.array([0, 25, 60])
    x0 = rng.normal(size=(2, 3)) * 0.1
    Y, X, diverged = simulate_pnlss(*matrices, ez, ee, U, starts, x0, DIVERGENCE_BOUND)
    assert not diverged
    for k in range(2):
        rows = slice(starts[k], starts[k + 1])
        expected = _reference_simulation(*matrices, ez, ee, U[rows], x0[k])
        np.testing.assert_allclose(Y[rows], expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(X[starts[:-1]], x0)
    Yj, Xj, _, _ = jacobian_pnlss(*matrices, ez, ee, U, starts, x0, True,
                                  DIVERGENCE_BOUND, np.arange(60))
    np.testing.assert_allclose(Yj, Y, rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(Xj, X, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("dims", [(2, 1, 1), (3, 2, 2)], ids=["SISO", "MIMO"])
@pytest.mark.parametrize("structure", STRUCTURES)
@pytest.mark.parametrize("estimate_x0", [False, True])
def test_jacobian_matches_central_differences(dims, structure, estimate_x0):
    n, n_u, n_y = dims
    output_terms = STRUCTURES[(STRUCTURES.index(structure) + 1) % 4]
    matrices, ez, ee = _random_model(n, n_u, n_y, structure, output_terms, seed=n + 1)
    rng = np.random.default_rng(2)
    U = 0.3 * rng.normal(size=(80, n_u))
    starts = np.array([0, 30, 80])
    x0_value = 0.2 * rng.normal(size=n)
    theta = _pack(matrices, x0_value if estimate_x0 else None)
    shapes = [m.shape for m in matrices]
    fixed_x0 = np.zeros((2, n))

    def simulate(th):
        mats, x0 = pnlss_module._unpack(th, shapes, estimate_x0)
        x0 = fixed_x0 if x0 is None else np.tile(x0, (2, 1))
        return simulate_pnlss(*mats, ez, ee, U, starts, x0, DIVERGENCE_BOUND)[0]

    x0 = np.tile(x0_value, (2, 1)) if estimate_x0 else fixed_x0
    # Rows outside the cost (here the first 5 of each sequence) are not stored.
    kept = np.ones(80, dtype=bool)
    kept[[0, 1, 2, 3, 4, 30, 31, 32, 33, 34]] = False
    rows = np.where(kept, np.cumsum(kept) - 1, -1)
    Y, _, J, diverged = jacobian_pnlss(*matrices, ez, ee, U, starts, x0, estimate_x0,
                                    DIVERGENCE_BOUND, rows)
    assert not diverged
    assert J.shape == (70, n_y, theta.size)
    J_fd = central_differences(simulate, theta)[kept]
    scale = np.abs(J).max(axis=(0, 1))
    assert np.all(np.abs(J - J_fd).max(axis=(0, 1)) <= 1e-6 * np.maximum(scale, 1e-3))


def test_frequency_residual_jacobian_matches_central_differences():
    # The frequency-domain residual with steady-state prepending and weights:
    # its Jacobian is the weighted DFT of the time-domain one.
    matrices, ez, ee = _random_model(2, 1, 1, "full", "full", seed=3)
    rng = np.random.default_rng(4)
    period = 16
    U = 0.5 * rng.normal(size=(3 * period, 1))
    starts = np.array([0, 3 * period])
    index, sim_starts, original = _steady_state_rows(starts, period)
    Y = simulate_pnlss(*matrices, ez, ee, U[index], sim_starts, np.zeros((1, 2)),
                       DIVERGENCE_BOUND)[0] + 0.01 * rng.normal(size=(len(index), 1))
    problem = _PNLSSProblem(
        np.ascontiguousarray(U[index]), Y, sim_starts, ez, ee, 2, True, original,
        np.zeros(len(index), dtype=bool), period,
    )
    assert not np.allclose(problem.weights, 1.0)
    theta = _pack(matrices, np.array([0.1, -0.1]))
    r, J = problem.residual(theta, True)
    assert r.shape == (2 * 3 * (period // 2 + 1),)
    J_fd = central_differences(lambda th: problem.residual(th, False)[0], theta)
    np.testing.assert_allclose(J, J_fd, rtol=1e-6, atol=1e-6 * np.abs(J).max())


def test_local_spectral_radius_gradient_matches_central_differences():
    (A, _, _, _, E, _), ez, _ = _random_model(3, 1, 1, "full", "full", seed=5)
    E *= 10  # a strongly state-dependent Jacobian, with complex eigenvalues
    S = 0.5 * np.random.default_rng(6).normal(size=(40, 4))
    radius, gradient, dzeta = _local_spectral_radius(A, E, ez, S)
    jacobians = A + np.einsum("iz,tzj->tij", E, dzeta)
    np.testing.assert_allclose(radius, np.abs(np.linalg.eigvals(jacobians)).max(axis=1))
    h = 1e-7
    for i, j in [(0, 0), (1, 2), (2, 1)]:
        step = np.zeros_like(A)
        step[i, j] = h
        fd = (_local_spectral_radius(A + step, E, ez, S)[0]
              - _local_spectral_radius(A - step, E, ez, S)[0]) / (2 * h)
        np.testing.assert_allclose(gradient[:, i, j], fd, rtol=1e-6, atol=1e-7)
    for i, k in [(0, 3), (2, 17)]:
        step = np.zeros_like(E)
        step[i, k] = h
        fd = (_local_spectral_radius(A, E + step, ez, S)[0]
              - _local_spectral_radius(A, E - step, ez, S)[0]) / (2 * h)
        expected = np.einsum("tj,tj->t", gradient[:, i, :], dzeta[:, k, :])
        np.testing.assert_allclose(expected, fd, rtol=1e-6, atol=1e-7)


def test_weight_decay_rows_have_an_exact_jacobian():
    matrices, ez, ee = _random_model(2, 1, 1, "full", "full", seed=7)
    rng = np.random.default_rng(8)
    U = 0.3 * rng.normal(size=(60, 1))
    starts = np.array([0, 60])
    Y = simulate_pnlss(*matrices, ez, ee, U, starts, np.zeros((1, 2)), DIVERGENCE_BOUND)[0]
    rows = np.ones(60, dtype=bool)
    problem = _PNLSSProblem(U, Y + 0.01 * rng.normal(size=Y.shape), starts, ez, ee, 2,
                            False, rows, ~rows, None, weight_decay=0.5)
    theta = _pack(matrices)
    problem.set_coefficient_scale(theta)
    assert np.all(problem.coefficient_scale > 0)
    r, J = problem.residual(theta, True)
    assert r.shape == (60 + len(problem.polynomial_columns),)
    J_fd = central_differences(lambda th: problem.residual(th, False)[0], theta)
    np.testing.assert_allclose(J, J_fd, rtol=1e-6, atol=1e-6 * np.abs(J).max())


def test_compiled_state_derivatives_match_the_monomial_jacobian():
    exponents = monomial_exponents(3, 2, (2, 3), "full")
    S = np.random.default_rng(9).normal(size=(20, 5))
    np.testing.assert_allclose(monomial_state_derivatives(S, exponents, 3),
                               monomial_jacobian(S, exponents)[:, :, :3], rtol=1e-13)


def _max_local_radius(model, u):
    _, states = model.simulate(u, return_states=True)
    S = np.hstack([states, (u - model.u_offset_) / model.u_scale_])
    return _local_spectral_radius(model.A_, model.E_, model.state_exponents_, S)[0].max()


def test_stability_penalty_makes_the_model_locally_contracting():
    # This system is locally expanding (0.6 + 0.4 x > 1) where x > 1, which
    # these data reach: the penalty trades some accuracy for a contracting model.
    rng = np.random.default_rng(0)
    u = 0.3 * rng.normal(size=(400, 1))
    y = _quadratic_system(u)
    options = dict(n_states=1, degree=2, max_iter=40)
    free = _fit_quiet(PNLSSRegressor(**options), u, y)
    penalised = _fit_quiet(PNLSSRegressor(stability_penalty=1e4, **options), u, y)
    assert _max_local_radius(free, u) > 1.2
    assert _max_local_radius(penalised, u) < 1.01
    assert penalised.score(u, y) > 0.95
    assert penalised.loss_history_[-1] < penalised.loss_history_[0]


def test_weight_decay_shrinks_the_polynomial_terms():
    rng = np.random.default_rng(1)
    u = 0.4 * rng.normal(size=(300, 1))
    y = _quadratic_system(u) + 0.02 * rng.normal(size=300)
    sizes = []
    for weight_decay in (0.0, 0.1, 10.0):
        model = _fit_quiet(PNLSSRegressor(1, degree=(2, 3), weight_decay=weight_decay,
                                          max_iter=40), u, y)
        sizes.append(np.abs(np.r_[model.E_.ravel(), model.F_.ravel()]).sum())
    assert sizes[0] > sizes[1] > sizes[2]


def test_divergence_is_reported():
    matrices, ez, ee = _random_model(2, 1, 1, "full", "full", seed=0)
    matrices[0] = 1.5 * np.eye(2)
    U = np.ones((200, 1))
    starts = np.array([0, 100, 200])
    x0 = np.zeros((2, 2))
    x0[1] = 1e-3
    Y, X, diverged = simulate_pnlss(*matrices, ez, ee, U, starts, x0, DIVERGENCE_BOUND)
    assert diverged
    assert np.isnan(Y[99]) and np.isnan(X[199, 0])
    assert np.all(np.isfinite(Y[:5]))
    assert jacobian_pnlss(*matrices, ez, ee, U, starts, x0, False, DIVERGENCE_BOUND,
                          np.arange(200))[3]


@pytest.fixture(scope="module")
def reference():
    data = make_pnlss_reference()
    period = data.period
    estimation = data.sequence_id <= 1
    test = data.sequence_id == 3
    return data, period, estimation, test


def _reference_test_rms(model, data, test, period):
    X_test = data.X[test][-period:]
    return rms_error(data.y[test][-period:], model.predict(X_test))


def test_reference_system_time_cost(reference):
    data, period, estimation, test = reference
    # Estimation data averaged over the periods, one period per realization,
    # simulated in steady state (one prepended period).
    X = data.X[estimation].reshape(2, 3, period)[:, 0].reshape(-1, 1)
    y = data.y[estimation].reshape(2, 3, period).mean(axis=1).ravel()
    model = PNLSSRegressor(2, period=period, n_transient=period, max_iter=60)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(X, y, sequence_id=np.repeat([0, 1], period))
    assert model.n_params_ == 4 + 2 + 2 + 1 + 2 * 16 + 16 == 57
    bla = BLAEstimator(2, period=period).fit(X, y, sequence_id=np.repeat([0, 1], period))
    linear = _reference_test_rms(bla, data, test, period)
    assert _reference_test_rms(model, data, test, period) <= 3e-4 < 0.1 * linear
    assert model.loss_history_[-1] < 1e-3 * model.loss_history_[0]


def test_reference_system_frequency_cost(reference):
    data, period, estimation, test = reference
    # Two periods per realization: the noise weights come from their difference.
    keep = estimation & (np.arange(len(data.y)) % (3 * period) >= period)
    model = PNLSSRegressor(2, period=period, n_transient=period, cost="frequency",
                           max_iter=100)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(data.X[keep], data.y[keep], sequence_id=data.sequence_id[keep])
    assert _reference_test_rms(model, data, test, period) <= 3e-4


def test_attributes_and_parameter_count():
    rng = np.random.default_rng(0)
    U = rng.normal(size=(300, 2))
    y = np.column_stack([np.convolve(U[:, 0], [0.5, 0.3], "same"), U[:, 1] ** 2])
    model = PNLSSRegressor(3, degree=2, state_terms="states_only",
                           output_terms=np.array([[0, 0, 0, 2, 0], [1, 0, 0, 0, 1]]),
                           estimate_x0=True, max_iter=5)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(U, y)
    assert model.A_.shape == (3, 3) and model.B_.shape == (3, 2)
    assert model.C_.shape == (2, 3) and model.D_.shape == (2, 2)
    assert model.E_.shape == (3, 6) and model.F_.shape == (2, 2)
    assert model.state_exponents_.shape == (6, 5)
    assert model.x0_.shape == (3,)
    assert model.n_params_ == 9 + 6 + 6 + 4 + 18 + 4 + 3
    assert model.loss_history_.shape == (model.n_iter_ + 1,)
    assert model.validation_loss_history_ is None
    assert isinstance(model.bla_, BLAEstimator)
    assert model.predict(U).shape == (300, 2)


def _quadratic_system(u, x0=0.0):
    y = np.empty(len(u))
    x = x0
    for t, ut in enumerate(u[:, 0]):
        y[t] = x
        x = 0.6 * x + ut + 0.2 * x**2
    return y


def _fit_quiet(model, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        return model.fit(*args, **kwargs)


def test_initial_state_and_validation_split():
    rng = np.random.default_rng(0)
    u = 0.2 * rng.normal(size=(500, 1))
    y = _quadratic_system(u, x0=1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        with_x0 = PNLSSRegressor(1, degree=2, estimate_x0=True, max_iter=30,
                                 validation_fraction=0.2).fit(u, y)
        without = PNLSSRegressor(1, degree=2, max_iter=30).fit(u, y)
    assert rms_error(y, with_x0.predict(u)) < 1e-4
    assert rms_error(y, with_x0.predict(u)) < 0.1 * rms_error(y, without.predict(u))
    history = with_x0.validation_loss_history_
    assert history.shape == with_x0.loss_history_.shape
    assert with_x0.best_iteration_ == int(np.argmin(history))


def test_center_makes_model_offset_invariant():
    rng = np.random.default_rng(0)
    u = 0.2 * rng.normal(size=(300, 1))
    y = _quadratic_system(u)
    model = PNLSSRegressor(1, degree=2, center=True, max_iter=10)
    a = _fit_quiet(clone(model), u, y).predict(u)
    b = _fit_quiet(clone(model), u + 3.0, y - 1.0).predict(u + 3.0)
    np.testing.assert_allclose(b, a - 1.0, atol=1e-8)
    raw = _fit_quiet(clone(model).set_params(center=False), u + 3.0, y - 1.0)
    assert raw.u_offset_ == 0.0 and raw.y_offset_ == 0.0
    assert raw.u_scale_ == pytest.approx((u + 3.0).std())


def test_refine_linear_starts_from_a_better_linear_model():
    rng = np.random.default_rng(0)
    u = 0.2 * rng.normal(size=(300, 1))
    y = _quadratic_system(u)
    # A BLA without its parametric refinement is a rougher initial model.
    template = BLAEstimator(max_iter=0)
    plain = _fit_quiet(PNLSSRegressor(1, degree=2, bla=template, max_iter=5), u, y)
    staged = _fit_quiet(
        PNLSSRegressor(1, degree=2, bla=template, max_iter=5, refine_linear=True), u, y
    )
    assert staged.loss_history_[0] <= plain.loss_history_[0]
    np.testing.assert_array_equal(staged.bla_.A_, plain.bla_.A_)


def test_unstable_input_warns_without_crash():
    rng = np.random.default_rng(0)
    u = 0.2 * rng.normal(size=(400, 1))
    y = _quadratic_system(u)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model = PNLSSRegressor(1, degree=2, max_iter=20).fit(u, y)
    with pytest.warns(SimulationDivergedWarning):
        y_big = model.predict(np.full((100, 1), 5.0))
    assert np.isnan(y_big[-1]) and np.isfinite(y_big[0])


def test_fit_recovers_from_diverging_steps(monkeypatch):
    # Simulated tanks with overflow: some trial steps of the search make the
    # polynomial model blow up; they must be rejected and the fit continue.
    data = make_cascaded_tanks(n_samples=400, random_state=0)
    diverged = []
    original = pnlss_module.simulate_pnlss

    def recording(*args):
        out = original(*args)
        diverged.append(out[2])
        return out

    monkeypatch.setattr(pnlss_module, "simulate_pnlss", recording)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model = PNLSSRegressor(3, max_iter=50).fit(data.X_est, data.y_est)
    assert any(diverged)
    assert np.all(np.isfinite(model.loss_history_))
    assert np.all(np.diff(model.loss_history_) <= 0)
    assert model.loss_history_[-1] < 0.5 * model.loss_history_[0]
    assert np.all(np.isfinite(model.predict(data.X_est)))


def test_periodic_prediction_is_steady_state(reference):
    data, period, estimation, _ = reference
    X = data.X[data.sequence_id == 0][:period]
    y = data.y_noiseless[data.sequence_id == 0][:period]
    model = PNLSSRegressor(2, period=period, n_transient=period, max_iter=0).fit(X, y)
    # The last samples of one period and of two periods coincide in steady state.
    one = model.predict(X)
    two = model.predict(np.vstack([X, X]))
    np.testing.assert_allclose(one, two[period:], atol=1e-10)


@pytest.mark.parametrize(
    "params, match",
    [
        ({"cost": "frequency"}, "period"),
        ({"period": 7}, "whole number of periods"),
        ({"state_terms": np.array([[1, 0]])}, "shape"),
        ({"degree": (1, 2)}, ">= 2"),
        ({"stability_penalty": -1.0}, "stability_penalty"),
        ({"weight_decay": -0.1}, "weight_decay"),
        ({"n_iter_no_change": 0}, "n_iter_no_change"),
    ],
)
def test_bad_parameters(params, match):
    rng = np.random.default_rng(0)
    u = rng.normal(size=(100, 1))
    with pytest.raises(ValueError, match=match):
        PNLSSRegressor(2, **params).fit(u, u[:, 0])


def test_frequency_cost_needs_whole_periods():
    rng = np.random.default_rng(0)
    u = rng.normal(size=(64, 1))
    model = PNLSSRegressor(1, period=16, cost="frequency", validation_fraction=0.1)
    with pytest.raises(ValueError, match="whole number of periods"):
        model.fit(u, u[:, 0])


# Cascaded Tanks, DESIGN.md section 3: the test record is used for nothing but
# the final number; iterates and settings are selected on the end of the
# estimation record. center=True was chosen by the validation error over four
# splits of the estimation record (500/600/700/717 samples).
#
# With a single split (70/30) the held-out error is a poor guide: PNLSS-I gives
# 0.55-0.75 V or a model that diverges on the test input over held-out shares
# 0.25-0.35, PNLSS without x0 0.64-0.75 V or divergent. A stability penalty
# (the local spectral radius along the fitted trajectory) with weight decay
# removes the divergence: over stability_penalty in {0.1, 1, 10} x
# weight_decay in {0, 1e-3, 1e-2, 0.1} x held-out shares {0.25, 0.3, 0.35} no
# model diverged on the test input (4 of 12 without it); the weights with the
# lowest median held-out error are 1 and 0.01.
#
# The main job fits each PNLSS model with and without those penalties, at
# held-out shares 0.25 to 0.35, and keeps the fit with the smallest error on
# the last 25 % of the estimation record, which none of them fitted
# (HoldoutSearch; benchmarks/bench_cascaded_tanks_splits.py shows the spread
# over the shares).


def _fit_main_job_model(name, data):
    factory = dict(MODELS)[name]
    model = factory()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(data.X_est, data.y_est)
    return model


@pytest.mark.slow
@pytest.mark.realdata
def test_cascaded_tanks_pnlss_i(cascaded_tanks):
    data = cascaded_tanks
    model = _fit_main_job_model("PNLSS-I", data)
    assert model.n_params_ == 9 + 3 + 3 + 1 + 3 * 30 + 30 + 3
    with warnings.catch_warnings():
        warnings.simplefilter("error", SimulationDivergedWarning)
        y_test = model.predict(data.X_test)
    assert rms_error(data.y_test, y_test) <= 0.40


@pytest.mark.slow
@pytest.mark.realdata
def test_cascaded_tanks_pnlss_without_x0(cascaded_tanks):
    data = cascaded_tanks
    model = _fit_main_job_model("PNLSS", data)
    assert model.n_params_ == 9 + 3 + 3 + 1 + 3 * 30 + 30
    with warnings.catch_warnings():
        warnings.simplefilter("error", SimulationDivergedWarning)
        y_test = model.predict(data.X_test)
    assert rms_error(data.y_test, y_test) <= 0.62
