import threading
import warnings

import numpy as np
import pytest
from sklearn.exceptions import ConvergenceWarning
from threadpoolctl import threadpool_info, threadpool_limits

from sknlss import DecoupledPNLSS, NLSS2Regressor, PNLSSRegressor
from sknlss._core._optimize import (_damped_step, _scaled_step_factors, levenberg_marquardt,
                                    one_blas_thread)


def _rosenbrock(theta, jacobian):
    r = np.array([10.0 * (theta[1] - theta[0] ** 2), 1.0 - theta[0]])
    if not jacobian:
        return r, None
    return r, np.array([[-20.0 * theta[0], 10.0], [-1.0, 0.0]])


def _distance_to_start(theta):
    # A validation loss that is best near the start, so that the search moves
    # away from the validation optimum as it converges to the training one.
    return float(np.sum((theta - [-1.2, 1.0]) ** 2))


def test_minimises_a_nonlinear_least_squares_problem():
    result = levenberg_marquardt(_rosenbrock, np.array([-1.2, 1.0]), max_iter=200, tol=1e-15)
    np.testing.assert_allclose(result.theta, [1.0, 1.0], atol=1e-6)
    assert result.converged and not result.stopped_early
    assert np.all(np.diff(result.loss_history) < 0)
    assert result.best_iter == result.n_iter


def test_zero_rows_leave_the_step_unchanged():
    # An inactive penalty adds rows that are zero in J and r; they are left
    # out of the factorisation, and the step must not notice.
    rng = np.random.default_rng(0)
    J, r = rng.standard_normal((40, 6)), rng.standard_normal(40)
    padded_J, padded_r = np.zeros((100, 6)), np.zeros(100)
    rows = np.sort(rng.choice(100, size=40, replace=False))
    padded_J[rows], padded_r[rows] = J, r
    for damping in (1e-3, 1.0, 10.0):
        np.testing.assert_allclose(
            _damped_step(*_scaled_step_factors(padded_J, padded_r), damping),
            _damped_step(*_scaled_step_factors(J, r), damping), rtol=1e-12, atol=1e-14)


def test_the_step_survives_a_failed_divide_and_conquer_svd(monkeypatch):
    # LAPACK's gesdd can fail to converge on a nearly singular triangular
    # factor (seen with a BLA of 19 states on a MIMO record); the step then
    # comes from the QR-iteration driver, with the same factors.
    from scipy.linalg import LinAlgError, svd

    from sknlss._core import _optimize

    rng = np.random.default_rng(0)
    J, r = rng.standard_normal((40, 6)), rng.standard_normal(40)
    expected = _damped_step(*_scaled_step_factors(J, r), 0.1)

    def failing_gesdd(a, **kwargs):
        if kwargs.get("lapack_driver") == "gesdd":
            raise LinAlgError("SVD did not converge")
        return svd(a, **kwargs)

    monkeypatch.setattr(_optimize, "svd", failing_gesdd)
    np.testing.assert_allclose(_damped_step(*_scaled_step_factors(J, r), 0.1), expected,
                               rtol=1e-10, atol=1e-12)


def test_a_flat_zero_problem_stops_without_a_step():
    result = levenberg_marquardt(
        lambda theta, jacobian: (np.zeros(5), np.zeros((5, 2)) if jacobian else None),
        np.ones(2), max_iter=3)
    assert result.converged and result.n_iter == 0
    np.testing.assert_array_equal(result.theta, np.ones(2))


def test_iteration_limit_warns():
    with pytest.warns(ConvergenceWarning, match="max_iter=2"):
        result = levenberg_marquardt(_rosenbrock, np.array([-1.2, 1.0]), max_iter=2)
    assert result.n_iter == 2 and not result.converged


@pytest.mark.parametrize("patience", [1, 3])
def test_early_stopping_on_the_validation_loss(patience):
    start = np.array([-1.2, 1.0])
    full = levenberg_marquardt(_rosenbrock, start, validation_loss=_distance_to_start,
                               max_iter=200, tol=1e-15)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ConvergenceWarning)
        early = levenberg_marquardt(_rosenbrock, start, validation_loss=_distance_to_start,
                                    max_iter=200, tol=1e-15, n_iter_no_change=patience)
    assert early.stopped_early and early.converged
    assert early.n_iter == early.best_iter + patience < full.n_iter
    # Same search up to the stop, and the same selected iterate.
    np.testing.assert_array_equal(early.loss_history, full.loss_history[: early.n_iter + 1])
    assert early.best_iter == full.best_iter
    np.testing.assert_array_equal(early.theta, full.theta)


def test_early_stopping_needs_a_validation_loss():
    result = levenberg_marquardt(_rosenbrock, np.array([-1.2, 1.0]), max_iter=200,
                                 tol=1e-15, n_iter_no_change=1)
    assert not result.stopped_early and result.best_iter == result.n_iter > 1


def _quadratic_system(u):
    y = np.empty(len(u))
    x = 0.0
    for t, ut in enumerate(u[:, 0]):
        y[t] = x
        x = 0.6 * x + ut + 0.2 * x**2
    return y


@pytest.mark.parametrize(
    "estimator",
    [
        PNLSSRegressor(1, degree=2),
        NLSS2Regressor(1, random_state=0),
        DecoupledPNLSS(1, rank=1, pnlss=PNLSSRegressor(degree=2, max_iter=5), random_state=0),
    ],
    ids=["PNLSS", "NLSS2", "Decoupled"],
)
def test_estimators_stop_early(estimator):
    rng = np.random.default_rng(0)
    u = 0.3 * rng.normal(size=(300, 1))
    y = _quadratic_system(u) + 0.05 * rng.normal(size=300)
    # The paper's cost (no penalties, no boundedness check), whose search goes
    # on long enough; the history is that of the start kept.
    estimator.set_params(validation_fraction=0.3, n_iter_no_change=2, max_iter=200, tol=0.0,
                         stability_penalty=0.0, weight_decay=0.0, check_bounded=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        estimator.fit(u, y)
    assert not estimator.fell_back_to_linear_
    history = estimator.validation_loss_history_
    assert estimator.n_iter_ < 200
    assert estimator.n_iter_ == int(np.argmin(history)) + 2


def _blas_threads():
    return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]


def test_one_blas_thread_in_overlapping_threads():
    # Starts run in threads: the first to enter leaves first and lives on (a
    # pool worker); the limit holds while any start runs, in whichever thread,
    # and the last to leave restores the limits found by the first.
    seen = {}
    first_in, second_in, first_out = threading.Event(), threading.Event(), threading.Event()

    def first():
        with one_blas_thread():
            seen["first"] = _blas_threads()
            first_in.set()
            second_in.wait()
        first_out.set()
        second_done.wait()

    def second():
        first_in.wait()
        with one_blas_thread():
            second_in.set()
            first_out.wait()
            seen["second, after the first left"] = _blas_threads()
        second_done.set()

    second_done = threading.Event()
    with threadpool_limits(limits=2, user_api="blas"):
        before = _blas_threads()
        with one_blas_thread():
            # The calling thread has limited BLAS before (a linear start).
            pass
        threads = [threading.Thread(target=first), threading.Thread(target=second)]
        for thread in threads:
            thread.start()
        second_done.wait()
        after = _blas_threads()
        for thread in threads:
            thread.join()
    assert set(before) == {2}
    assert set(seen["first"]) == set(seen["second, after the first left"]) == {1}
    assert after == before


def test_directions_dropped_from_fewer_residuals_than_parameters():
    # Six residuals, ten parameters of which four leave the residual as it
    # is: the six others are all identifiable, and none may be dropped.
    rng = np.random.default_rng(0)
    J = np.hstack([rng.standard_normal((6, 6)), np.zeros((6, 4))])
    b = rng.standard_normal(6)
    result = levenberg_marquardt(lambda theta, jacobian: (J @ theta - b, J if jacobian else None),
                                 np.zeros(10), n_drop=4, max_iter=200, tol=0)
    assert result.loss_history[-1] < 1e-20
