"""The shared simulation-error core: kernels, terms contract, problem, starts."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from _numeric import central_differences

from sknlss import ChebyshevBasis, LegendreBasis, PolynomialBasis
from sknlss._core._kernels import DIVERGENCE_BOUND
from sknlss._core._model import StateSpaceModel
from sknlss._core._multistart import fit_from, run_starts
from sknlss._core._problem import (SimulationErrorProblem, fit_rows, screening_radius,
                                   spectral_radius)
from sknlss._core._sequences import steady_state_rows
from sknlss._terms._branches import BranchTerms
from sknlss._terms._network import NetworkTerms
from sknlss._terms._polynomial import PolynomialTerms, evaluate_monomials, monomial_exponents

TERMS = {
    "polynomial": lambda n, n_u, n_y: PolynomialTerms(
        n, n_y, monomial_exponents(n, n_u, (2, 3)), monomial_exponents(n, n_u, 2)),
    "polynomial-states": lambda n, n_u, n_y: PolynomialTerms(
        n, n_y, monomial_exponents(n, n_u, (2, 3), "states_only"),
        monomial_exponents(n, n_u, 3, "no_cross_products")),
    "network-sigmoid": lambda n, n_u, n_y: NetworkTerms(n, n_u, n_y, 3, "sigmoid"),
    "network-tanh": lambda n, n_u, n_y: NetworkTerms(n, n_u, n_y, 2, "tanh"),
    "branches-powers": lambda n, n_u, n_y: BranchTerms(n, n_u, n_y, 3, PolynomialBasis(3)),
    "branches-odd": lambda n, n_u, n_y: BranchTerms(n, n_u, n_y, 2,
                                                    PolynomialBasis(5, kind="odd")),
    "branches-legendre": lambda n, n_u, n_y: BranchTerms(n, n_u, n_y, 2, LegendreBasis(3)),
    "branches-chebyshev": lambda n, n_u, n_y: BranchTerms(n, n_u, n_y, 1,
                                                          ChebyshevBasis(4)),
    "branches-shifted": lambda n, n_u, n_y: BranchTerms(n, n_u, n_y, 3,
                                                        LegendreBasis(2, shift=True)),
    # A box that the states and inputs of the test data leave on both sides,
    # one or several variables at a time.
    "polynomial-bounded": lambda n, n_u, n_y: PolynomialTerms(
        n, n_y, monomial_exponents(n, n_u, (2, 3)), monomial_exponents(n, n_u, (2, 3)),
        input_range=np.array([[-0.3], [0.2]]).repeat(n + n_u, axis=1)),
    # The same box widened to twice its half-width, which the test data leave
    # too, the monomials held beyond it.
    "polynomial-held": lambda n, n_u, n_y: PolynomialTerms(
        n, n_y, monomial_exponents(n, n_u, (2, 3)), monomial_exponents(n, n_u, (2, 3)),
        input_range=np.array([[-0.3], [0.2]]).repeat(n + n_u, axis=1), reach=2.0, held=True),
    # Ranges that the branch inputs of the test data leave on both sides.
    "branches-continued": lambda n, n_u, n_y: BranchTerms(
        n, n_u, n_y, 2, PolynomialBasis(3), input_range=np.array([[-0.02, -0.01],
                                                                 [0.01, 0.03]])),
    "branches-shifted-continued": lambda n, n_u, n_y: BranchTerms(
        n, n_u, n_y, 2, ChebyshevBasis(3, shift=True),
        input_range=np.array([[-0.02, -0.01], [0.01, 0.03]])),
}
DIMS = {"SISO": (2, 1, 1), "MIMO": (3, 2, 2)}


def _model(terms, dims, estimate_x0=False, seed=0, n_sequences=1):
    n, n_u, n_y = dims
    model = StateSpaceModel(n, n_u, n_y, TERMS[terms](n, n_u, n_y), estimate_x0=estimate_x0,
                            n_sequences=n_sequences)
    rng = np.random.default_rng(seed)
    theta = 0.2 * rng.standard_normal(model.n_params)
    A = rng.standard_normal((n, n))
    theta[model.columns("A")] = (0.7 * A / max(abs(np.linalg.eigvals(A)))).ravel()
    theta[model.terms_columns] *= 0.3
    return model, theta


def _data(n_u, seed=1, n_samples=90):
    rng = np.random.default_rng(seed)
    return 0.5 * rng.standard_normal((n_samples, n_u)), np.array([0, 35, n_samples])


@pytest.mark.parametrize("dims", DIMS.values(), ids=DIMS.keys())
@pytest.mark.parametrize("terms", TERMS)
@pytest.mark.parametrize("x0", ["zero", "shared", "per sequence"])
def test_jacobian_matches_central_differences(terms, dims, x0):
    U, starts = _data(dims[1])
    model, theta = _model(terms, dims, x0 != "zero",
                          n_sequences=len(starts) - 1 if x0 == "per sequence" else 1)
    # Rows outside the cost (here every fifth) are not stored.
    kept = np.arange(len(U)) % 5 != 0
    rows = np.where(kept, np.cumsum(kept) - 1, -1)
    Y, X, J, local, diverged = model.sensitivities(theta, U, starts, rows, with_local=True)
    assert not diverged
    Y_sim, X_sim, diverged = model.simulate(theta, U, starts)
    assert not diverged
    np.testing.assert_array_equal(Y, Y_sim)
    np.testing.assert_array_equal(X, X_sim)
    # The stability penalty takes these for those of local_jacobians.
    S = np.hstack([X, U])[kept]
    np.testing.assert_array_equal(local, model.local_jacobians(theta, S)[:, : dims[0]])
    assert model.sensitivities(theta, U, starts, rows)[3].shape == (0, dims[0], dims[0])
    assert J.shape == (kept.sum(), dims[2], model.n_params)
    J_fd = central_differences(lambda th: model.simulate(th, U, starts)[0], theta)[kept]
    scale = np.abs(J_fd).max()
    np.testing.assert_allclose(J, J_fd, rtol=0, atol=1e-6 * scale)


@pytest.mark.parametrize("terms", TERMS)
def test_local_jacobians_and_curvature_match_central_differences(terms):
    dims = DIMS["MIMO"]
    n, n_u, n_y = dims
    model, theta = _model(terms, dims, seed=3)
    S = 0.5 * np.random.default_rng(4).standard_normal((6, n + n_u))
    L = model.local_jacobians(theta, S)
    assert L.shape == (6, n + n_y, n)

    def one_step(x, u):
        """[x(t+1); y(t)] from x(t) = x."""
        Y, X, _ = model.simulate(theta, np.vstack([u, u]), np.array([0, 2]), x0=x)
        return np.r_[X[1], Y[0]]

    for t in range(len(S)):
        step = central_differences(lambda x: one_step(x, S[t, n:]), S[t, :n])
        np.testing.assert_allclose(L[t], step, atol=1e-7)
    G = np.random.default_rng(5).standard_normal((6, n, n))
    contraction = model.curvature_contraction(theta, S, G, 1e-5)
    columns = model.terms_columns[: model.terms.n_state_params]

    def weighted(th):
        return np.einsum("tij,tij->t", G, model.local_jacobians(th, S)[:, :n])

    expected = central_differences(weighted, theta)[:, columns]
    np.testing.assert_allclose(contraction, expected, atol=1e-6 * np.abs(expected).max())


# The two structures share some monomials: each distinct one is evaluated once.
@pytest.mark.parametrize("terms", ["polynomial", "polynomial-states"])
def test_polynomial_terms_match_plain_numpy(terms):
    model, theta = _model(terms, DIMS["MIMO"])
    U, starts = _data(2)
    values = model.unpack(theta)
    exponents = model.terms.exponents
    Y, X, _ = model.simulate(theta, U, starts)
    for begin, end in zip(starts[:-1], starts[1:]):
        x = np.zeros(3)
        for t in range(begin, end):
            s = np.r_[x, U[t]][None]
            expected = (values["C"] @ x + values["D"] @ U[t]
                        + values["F"] @ evaluate_monomials(s, exponents[1])[0])
            np.testing.assert_allclose(Y[t], expected, rtol=1e-12, atol=1e-12)
            x = (values["A"] @ x + values["B"] @ U[t]
                 + values["E"] @ evaluate_monomials(s, exponents[0])[0])


def test_reach_widens_the_box_about_its_centre():
    n, n_u, n_y = DIMS["MIMO"]
    exponents = [monomial_exponents(n, n_u, (2, 3))] * 2
    box, wider = (np.array(ends).repeat(n + n_u, axis=1) for ends in ([[-0.3], [0.1]],
                                                                        [[-0.5], [0.3]]))
    _, theta = _model("polynomial-bounded", DIMS["MIMO"])
    U, starts = _data(n_u)

    def simulation(input_range, reach, held=False):
        terms = PolynomialTerms(n, n_y, *exponents, input_range=input_range, reach=reach,
                                held=held)
        return StateSpaceModel(n, n_u, n_y, terms).simulate(theta, U, starts)

    for held in (False, True):
        Y, X, _ = simulation(box, 2.0, held)
        S = np.hstack([X, U])
        assert np.any((S < wider[0] - 1e-9) | (S > wider[1] + 1e-9))
        np.testing.assert_allclose(Y, simulation(wider, 1.0, held)[0], rtol=1e-12, atol=1e-12)
        assert not np.allclose(Y, simulation(box, 1.0, held)[0])
        assert not np.allclose(Y, simulation(box, np.inf)[0])


def test_held_monomials_keep_their_value_on_the_box():
    n, n_u, n_y = DIMS["MIMO"]
    model, theta = _model("polynomial-held", DIMS["MIMO"])
    theta[model.columns("C", "D")] = 0.0
    U, starts = _data(n_u)
    Y, X, _ = model.simulate(theta, U, starts)
    lower, upper = model.terms.input_range
    wider = np.vstack([1.5 * lower - 0.5 * upper, 1.5 * upper - 0.5 * lower])
    S = np.hstack([X, U])
    assert np.any((S < wider[0]) | (S > wider[1]))
    F = model.unpack(theta)["F"]
    expected = evaluate_monomials(np.clip(S, *wider), model.terms.exponents[1]) @ F.T
    np.testing.assert_allclose(Y, expected, rtol=1e-12, atol=1e-12)


@settings(max_examples=25, deadline=None)
@given(gain=st.floats(1.0, 1e4), seed=st.integers(0, 2**16))
def test_held_terms_keep_a_stable_model_bounded_on_any_input(gain, seed):
    model, theta = _model("polynomial-held", DIMS["MIMO"], seed=seed)
    U, starts = _data(2, seed=seed)
    Y, X, diverged = model.simulate(theta, gain * U, starts)
    assert not diverged
    assert np.all(np.isfinite(Y)) and np.all(np.isfinite(X))


def test_divergence_rule_on_states_and_outputs():
    n_u = 1
    model = StateSpaceModel(2, n_u, 1)
    theta = model.pack({"A": 1.5 * np.eye(2), "B": np.ones((2, 1)), "C": np.ones((1, 2)),
                        "D": np.zeros((1, 1))})
    U = np.ones((200, 1))
    starts = np.array([0, 100, 200])
    Y, X, diverged = model.simulate(theta, U, starts)
    assert diverged
    assert np.all(np.isfinite(Y[:5])) and np.isnan(Y[99]) and np.isnan(X[199, 0])
    first = np.flatnonzero(np.isnan(Y[:100, 0]))[0]
    assert np.all(np.abs(X[first - 1]) <= DIVERGENCE_BOUND)
    assert model.sensitivities(theta, U, starts, np.arange(200))[4]
    # An output that leaves the bound at the last sample (the state stays
    # bounded) is divergence as well.
    feedthrough = model.pack({"A": np.zeros((2, 2)), "B": np.zeros((2, 1)),
                              "C": np.zeros((1, 2)), "D": np.ones((1, 1))})
    U_last = np.ones((10, 1))
    U_last[-1] = 10 * DIVERGENCE_BOUND
    Y, _, diverged = model.simulate(feedthrough, U_last, np.array([0, 10]))
    assert diverged and np.isnan(Y[-1, 0]) and np.all(np.isfinite(Y[:-1]))


def _problem(terms="polynomial", estimate_x0=True, period=None, **options):
    model, theta = _model(terms, DIMS["SISO"], estimate_x0, seed=7)
    period_length = 16
    U = 0.5 * np.random.default_rng(8).standard_normal((3 * period_length, 1))
    starts = np.array([0, 3 * period_length])
    index, sim_starts, original = steady_state_rows(starts, period_length)
    Y = model.simulate(theta, U[index], sim_starts)[0][original]
    Y = Y + 0.01 * np.random.default_rng(9).standard_normal(Y.shape)
    rows = fit_rows(U, Y, starts, n_transient=period_length, validation_fraction=0.0,
                    steady_state=True)
    problem = SimulationErrorProblem(model, rows, frequency_period=period and period_length,
                                     **options)
    if problem.weight_decay:
        problem = problem.with_decay_scale(theta)
    return problem, theta


# Factors on A that make these test models locally expanding (spectral radius
# of the local map above 1 at some samples) without diverging.
_EXPANDING = {"polynomial": 1.4, "network-tanh": 1.45, "branches-powers": 1.45}


@pytest.mark.parametrize("terms", list(_EXPANDING))
@pytest.mark.parametrize("options", [
    {"period": True}, {"stability_penalty": 1.0}, {"weight_decay": 0.3},
    {"period": True, "weight_decay": 0.1},
], ids=["frequency", "stability", "decay", "frequency+decay"])
def test_problem_jacobian_matches_central_differences(terms, options):
    problem, theta = _problem(terms, **options)
    if "stability_penalty" in options:
        # A locally expanding map at some samples, so that the penalty acts.
        theta[problem.model.columns("A")] *= _EXPANDING[terms]
        theta[problem.model.columns("B", "C")] *= 0.1
    r, J = problem.residual(theta, True)
    assert r is not None
    assert r.size > problem.fit_rows.sum()
    # The penalty's Jacobian leaves out the states' own dependence
    # (Gauss-Newton), so with the penalty only the simulation-error rows are
    # compared; its rows are checked in A and the terms' parameters below.
    n_compared = problem.n_residuals if "stability_penalty" in options else r.size
    J_fd = central_differences(lambda th: problem.residual(th, False)[0][:n_compared], theta)
    J = J[:n_compared]
    np.testing.assert_allclose(J, J_fd, rtol=1e-5, atol=1e-6 * np.abs(J_fd).max())


@pytest.mark.parametrize("terms", TERMS)
@pytest.mark.parametrize("options", [{}, {"period": True}, {"stability_penalty": 1.0},
                                     {"weight_decay": 0.3}],
                         ids=["time", "frequency", "stability", "decay"])
def test_residual_is_the_same_with_and_without_the_jacobian(terms, options):
    # The optimiser takes an accepted first trial's residual from the
    # sensitivities and the others' from the simulation alone: the fits are
    # those of always simulating only if the two residuals are equal to the bit.
    problem, theta = _problem(terms, **options)
    theta[problem.model.columns("A")] *= 1.4
    theta[problem.model.columns("B", "C")] *= 0.1
    r_plain = problem.residual(theta, False)[0]
    r_with_jacobian = problem.residual(theta, True)[0]
    assert r_plain is not None
    np.testing.assert_array_equal(r_plain, r_with_jacobian)


def test_stability_penalty_rows_direct_dependence():
    problem, theta = _problem(stability_penalty=1.0)
    model = problem.model
    theta[model.columns("A")] *= _EXPANDING["polynomial"]
    theta[model.columns("B", "C")] *= 0.1
    X = problem.simulate(theta)[1]
    r, J = problem._stability_rows(theta, X, problem.fit_rows.sum(), True)
    assert np.any(r > 0)
    columns = np.r_[model.columns("A"), model.terms_columns[: model.terms.n_state_params]]
    J_fd = central_differences(
        lambda th: problem._stability_rows(th, X, problem.fit_rows.sum(), False)[0], theta)
    np.testing.assert_allclose(J[:, columns], J_fd[:, columns], rtol=1e-5,
                               atol=1e-6 * np.abs(J_fd).max())


def test_spectral_radius_gradient():
    J = np.random.default_rng(0).standard_normal((30, 3, 3))
    radius, gradient = spectral_radius(J)
    np.testing.assert_allclose(radius, np.abs(np.linalg.eigvals(J)).max(axis=1))
    for i, j in [(0, 0), (1, 2)]:
        step = np.zeros((3, 3))
        step[i, j] = 1e-7
        fd = (spectral_radius(J + step)[0] - spectral_radius(J - step)[0]) / 2e-7
        np.testing.assert_allclose(gradient[:, i, j], fd, rtol=1e-5, atol=1e-7)


def test_spectral_radius_of_a_subset_does_not_depend_on_the_stack():
    # The stability penalty computes the radius only where it may exceed 1;
    # those matrices must give what the whole stack gives them.
    J = np.random.default_rng(1).standard_normal((40, 3, 3))
    real = np.flatnonzero(np.all(np.linalg.eigvals(J).imag == 0, axis=1))
    assert real.size and np.iscomplexobj(np.linalg.eigvals(J))
    whole = spectral_radius(J)
    alone = spectral_radius(J[real], complex_arithmetic=True)
    np.testing.assert_array_equal(alone[0], whole[0][real])
    np.testing.assert_array_equal(alone[1], whole[1][real])


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 3), seed=st.integers(0, 2**32 - 1), scale=st.floats(1e-3, 1e3),
       structure=st.sampled_from(["random", "triangular", "rotation", "double"]))
def test_screening_radius_agrees_with_lapack(n, seed, scale, structure):
    # The screen decides which points get eigenvectors and whether they are
    # computed in complex arithmetic: both must be what eigvals would give.
    rng = np.random.default_rng(seed)
    J = scale * rng.standard_normal((25, n, n))
    if structure == "triangular":
        J = np.triu(J)
    elif structure == "rotation" and n == 2:
        angle = rng.uniform(0, np.pi, 25)
        J = scale * np.stack([[np.cos(angle), -np.sin(angle)],
                              [np.sin(angle), np.cos(angle)]]).transpose(2, 0, 1)
    elif structure == "double" and n == 2:
        # A double eigenvalue moved by a few ulps, where the discriminant
        # cancels: whether the pair is real or complex is LAPACK's call.
        ulps = rng.integers(-4, 5, 25) * np.finfo(float).eps
        J = scale * np.stack([np.full(25, 1.5), np.ones(25), -0.0625 * (1 + ulps),
                              np.ones(25)], axis=1).reshape(25, 2, 2)
    eigenvalues = np.linalg.eigvals(J)
    with np.errstate(all="raise"):
        radius, complex_stack = screening_radius(J)
    np.testing.assert_allclose(radius, np.abs(eigenvalues).max(axis=1), rtol=1e-10)
    assert complex_stack == np.iscomplexobj(eigenvalues)


def test_restricted_problem():
    problem, theta = _problem()
    free = problem.model.linear_columns
    restricted = problem.restricted(theta, free)
    r_full, J_full = problem.residual(theta, True)
    r, J = restricted.residual(theta[free], True)
    np.testing.assert_array_equal(r, r_full)
    np.testing.assert_array_equal(J, J_full[:, free])
    assert restricted.validation_loss is None


def test_a_restricted_problem_scales_its_decay_as_a_start():
    model, theta = _model("polynomial", DIMS["SISO"], seed=7)
    U = 0.5 * np.random.default_rng(8).standard_normal((48, 1))
    rows = fit_rows(U, model.simulate(theta, U, np.array([0, 48]))[0], np.array([0, 48]),
                    n_transient=0, validation_fraction=0.0)
    problem = SimulationErrorProblem(model, rows, weight_decay=1.0)
    # A search in the linear part holds the terms: the decay's rows stay
    # constant, weighed from its starting point as a start's are.
    linear = model.linear_columns
    restricted = problem.restricted(theta, linear)
    assert restricted.weight_decay == problem.weight_decay
    start = restricted.with_decay_scale(theta[linear])
    r, J = start.residual(theta[linear], True)
    r_full, J_full = problem.with_decay_scale(theta).residual(theta, True)
    assert r.size > problem.n_residuals and problem.decay_scale is None
    np.testing.assert_array_equal(r, r_full)
    np.testing.assert_array_equal(J, J_full[:, linear])


def _held_out_problem():
    """A problem with its last 30 % held out, its true parameters and data."""
    model, theta = _model("polynomial", DIMS["SISO"], seed=7)
    U = 0.5 * np.random.default_rng(8).standard_normal((80, 1))
    starts = np.array([0, 80])
    Y = model.simulate(theta, U, starts)[0] + 0.01 * np.random.default_rng(9).normal(size=U.shape)
    problem = SimulationErrorProblem(model, fit_rows(U, Y, starts, n_transient=0,
                                                     validation_fraction=0.3))
    return problem, theta, U, Y, starts


@pytest.mark.parametrize("jacobian", [True, False])
def test_validation_loss_reuses_only_the_same_iterate(jacobian):
    problem, theta, U, Y, starts = _held_out_problem()
    model = problem.model

    def fresh_loss(th):
        Y_model = model.simulate(th, U, starts)[0]
        return np.mean((Y_model[problem.val_rows] - Y[problem.val_rows]) ** 2)

    other = theta.copy()
    other[model.columns("A")] *= 0.9
    problem.residual(theta, jacobian)
    assert problem.validation_loss(theta) == fresh_loss(theta)
    assert problem.validation_loss(other) == fresh_loss(other)
    problem.residual(other, jacobian)
    assert problem.validation_loss(theta) == fresh_loss(theta)
    assert fresh_loss(theta) != fresh_loss(other)


def test_a_start_with_its_own_decay_scale_reuses_its_own_simulations(monkeypatch):
    # Each start fits a copy of the shared problem (its own weight-decay
    # scale): the copy's held-out loss is served by the copy's last residual.
    problem, theta, U, Y, starts = _held_out_problem()
    problem.weight_decay = 1.0
    start = problem.with_decay_scale(theta)
    assert start is not problem and problem.decay_scale is None
    simulated = []
    monkeypatch.setattr(start.model, "simulate",
                        lambda *args: simulated.append(1) or StateSpaceModel.simulate(
                            start.model, *args))
    start.residual(theta, False)
    start.validation_loss(theta)
    assert len(simulated) == 1


def test_held_out_loss_needs_the_cost_rows_fitted_within_the_limit():
    problem, theta, U, Y, starts = _held_out_problem()
    model = problem.model
    worse = theta.copy()
    worse[model.columns("C")] *= 0.5
    Y_worse = model.simulate(worse, U, starts)[0]
    fit_error = np.mean((Y_worse[problem.fit_rows] - Y[problem.fit_rows]) ** 2)
    held_out_error = np.mean((Y_worse[problem.val_rows] - Y[problem.val_rows]) ** 2)
    assert problem.fit_loss(worse) == fit_error
    assert problem.held_out_loss(worse) == held_out_error
    problem.fit_loss_limit = fit_error
    assert problem.held_out_loss(worse) == held_out_error
    problem.fit_loss_limit = 0.99 * fit_error
    assert problem.held_out_loss(worse) == np.inf
    assert problem.validation_loss(worse) == np.inf
    assert problem.held_out_loss(theta) < held_out_error


def test_early_stopping_keeps_only_iterates_within_the_fit_limit():
    problem, theta = _held_out_problem()[:2]
    start = theta.copy()
    start[problem.model.columns("C")] *= 0.5
    # No iterate can fit the cost rows this well: none is judged on the
    # held-out rows, and the start point is returned.
    problem.fit_loss_limit = 0.0
    theta_kept, result = fit_from(problem, [start], label="test", max_iter=5)
    np.testing.assert_array_equal(theta_kept, start)
    assert np.all(np.isinf(result.validation_history))
    problem.fit_loss_limit = np.inf
    theta_kept, result = fit_from(problem, [start], label="test", max_iter=5)
    assert np.isfinite(result.validation_history).all()
    assert not np.array_equal(theta_kept, start)


def test_fit_from_skips_candidates_that_diverge():
    problem, theta = _problem()
    exploding = theta.copy()
    exploding[problem.model.columns("A")] = (3.0 * np.eye(2)).ravel()
    _, result = fit_from(problem, [exploding, theta], label="test", max_iter=3)
    assert result.loss_history[0] == pytest.approx(
        np.mean(problem.residual(theta, False)[0] ** 2))
    with pytest.raises(ValueError, match="no starting point"):
        fit_from(problem, [exploding], label="test", max_iter=3)


def test_fit_from_holds_the_held_parameters():
    problem, theta = _held_out_problem()[:2]
    start = theta.copy()
    start[problem.model.columns("C")] *= 0.5
    held = problem.model.columns("A", "C")
    problem.held = held
    theta_kept, result = fit_from(problem, [start], label="test", max_iter=5)
    np.testing.assert_array_equal(theta_kept[held], start[held])
    assert not np.array_equal(theta_kept, start)
    np.testing.assert_array_equal(result.theta, theta_kept)
    assert result.loss_history[-1] < result.loss_history[0]


def _start(value, fail=False):
    if fail:
        raise ValueError("a start that fails")
    return value


def test_run_starts_survives_failures():
    outcomes = run_starts(_start, [(3.0,), (2.0, True), (1.0,)])
    assert outcomes[0] == 3.0 and outcomes[2] == 1.0
    assert isinstance(outcomes[1], ValueError)


def test_linear_part_refined_alone_recovers_a_perturbed_model():
    rng = np.random.default_rng(5)
    A = np.array([[0.7, 0.2], [-0.2, 0.5]])
    B, C, D = np.array([[1.0], [0.5]]), np.array([[1.0, -0.5]]), np.array([[0.1]])
    model = StateSpaceModel(2, 1, 1, NetworkTerms(2, 1, 1, 2, "tanh"), estimate_x0=True)
    values = {name: np.zeros(shape) for name, shape in model.blocks}
    truth = model.pack(dict(values, A=A, B=B, C=C, D=D, x0=np.array([0.5, -0.3])))
    U = rng.standard_normal((300, 1))
    starts = np.array([0, 300])
    Y = model.simulate(truth, U, starts)[0]
    rows = fit_rows(U, Y, starts, n_transient=0, validation_fraction=0.0)
    problem = SimulationErrorProblem(model, rows)
    theta = model.pack(dict(values, A=A + 0.05, B=1.1 * B, C=0.9 * C, D=D + 0.05))
    free = model.linear_columns
    refined = theta.copy()
    refined[free] = fit_from(problem.restricted(theta, free), [theta[free]], label="linear",
                             max_iter=100, tol=1e-14, n_drop=4)[0]
    fitted = model.unpack(refined)
    # The same input-output behaviour (equal Markov parameters); the terms stay 0
    # but for the output networks' biases, which hold the output offset (0 here).
    markov = [C @ np.linalg.matrix_power(A, k) @ B for k in range(5)]
    refined_markov = [fitted["C"] @ np.linalg.matrix_power(fitted["A"], k) @ fitted["B"]
                      for k in range(5)]
    np.testing.assert_allclose(refined_markov, markov, atol=1e-6)
    np.testing.assert_allclose(fitted["D"], D, atol=1e-6)
    assert model.offset_block == "g_c"
    offset = model.columns("g_c")
    np.testing.assert_array_equal(refined[np.setdiff1d(model.terms_columns, offset)], 0.0)
    np.testing.assert_allclose(refined[offset], 0.0, atol=1e-6)


@pytest.mark.parametrize("terms, offset_block", [
    (PolynomialTerms(2, 1, monomial_exponents(2, 1, 2), monomial_exponents(2, 1, 2)), "y0"),
    (NetworkTerms(2, 1, 1, 2, "tanh"), "g_c"),
])
def test_the_output_offset_lives_in_one_block(terms, offset_block):
    # Terms with a constant of their own per output hold the offset there: a
    # separate y0 would duplicate it (two equal Jacobian columns).
    model = StateSpaceModel(2, 1, 1, terms, estimate_x0=True)
    assert model.offset_block == offset_block
    assert ("y0" in model.offsets) == (offset_block == "y0")
    rng = np.random.default_rng(0)
    linear = {"A": np.array([[0.5, 0.1], [0.0, 0.3]]), "B": np.ones((2, 1)),
              "C": np.array([[1.0, -1.0]]), "D": np.zeros((1, 1)),
              "x0": np.array([0.2, -0.1]), "y0": np.array([0.7])}
    theta = model.pack_linear(linear)
    for name, value in model.linear_values(theta).items():
        np.testing.assert_array_equal(value, linear[name])
    # The same outputs as the linear model with its offset added.
    U = rng.standard_normal((50, 1))
    starts = np.array([0, 50])
    plain = StateSpaceModel(2, 1, 1)
    expected = plain.simulate(plain.pack(linear), U, starts, x0=linear["x0"])[0] + 0.7
    np.testing.assert_allclose(model.simulate(theta, U, starts)[0], expected, atol=1e-14)
    # A refinement of the linear part frees the offset with it.
    offset = model.columns(offset_block)
    assert np.isin(offset, model.linear_columns).all()
    np.testing.assert_array_equal(theta[offset], [0.7])
