"""Levenberg-Marquardt for simulation-error (output-error) problems.

One private optimiser serves every estimator: it minimises ``||r(theta)||^2``
given a function that simulates the model and returns the residual and its
Jacobian. The step is computed from the SVD of the column-scaled Jacobian (via
the triangular factor of its QR), so a whole sweep of damping values costs one
factorisation, and the smallest singular directions can be discarded (the
``n^2`` directions along which a similarity transform of the states leaves the
output unchanged).
"""

import threading
from contextlib import contextmanager
from dataclasses import dataclass
from functools import cache

import numpy as np
import threadpoolctl
from scipy.linalg import LinAlgError, qr, svd
from sklearn.exceptions import ConvergenceWarning
from threadpoolctl import ThreadpoolController

from ..exceptions import warn_at_caller


@cache
def _threadpools():
    """The loaded thread pools, found once, at the first call (after NumPy's
    and SciPy's BLAS have loaded): finding them scans the loaded libraries,
    about 2 ms, more than a small search takes (an initial state per sequence
    of a long record)."""
    return ThreadpoolController()


_limit_lock = threading.Lock()
_limit_holders = {"count": 0, "limiter": None}


def _free_blas_control():
    """Let the next thread that sets the OpenBLAS limits take the control.

    From version 3.8, threadpoolctl lets a single thread change the limits of
    a pthreads OpenBLAS pool (shared by the process), the first to try, and
    silently ignores the others while it lives (a pool worker lives on). The
    count of :func:`one_blas_thread` decides which thread sets the limit and
    which lifts it; afterwards no thread keeps the control.
    """
    controller = getattr(threadpoolctl, "OpenBLASController", None)
    if hasattr(controller, "clear_controlling_thread"):
        controller.clear_controlling_thread(force=True)


@contextmanager
def one_blas_thread():
    """A context in which BLAS runs on one thread: the factorisations of the
    library are small, and threads only add synchronisation (tenfold on two
    cores, see DESIGN.md §2).

    The limit is the process's: contexts that overlap, in the threads that
    run starts side by side, share it, and the last to leave restores the
    limits found by the first (each restoring its own would leave the last
    restored, one thread, in place).
    """
    with _limit_lock:
        if _limit_holders["count"] == 0:
            _free_blas_control()
            _limit_holders["limiter"] = _threadpools().limit(limits=1, user_api="blas")
        _limit_holders["count"] += 1
    try:
        yield
    finally:
        with _limit_lock:
            _limit_holders["count"] -= 1
            if _limit_holders["count"] == 0:
                _free_blas_control()
                _limit_holders["limiter"].restore_original_limits()
                _free_blas_control()


# Damping is raised by this factor after a rejected step and lowered by
# _DAMPING_DOWN after an accepted one (the usual asymmetric schedule).
_DAMPING_UP = 10.0
_DAMPING_DOWN = 0.5
# After this many rejected steps in a row the damped step is negligible and the
# search has stalled: no direction decreases the cost.
_MAX_REJECTED = 14
# The iteration limit is worth a warning only when the last tenth of the
# iterations still improved the loss that selects the iterate by 1 %.
_RECENT_SHARE = 0.1
_RECENT_GAIN = 1e-2


@dataclass
class LMResult:
    """Outcome of :func:`levenberg_marquardt`.

    Attributes
    ----------
    theta : ndarray of shape (n_params,)
        Selected parameters: the iterate with the lowest validation loss when a
        validation function was given, else the last (lowest-cost) iterate.
    loss_history : ndarray of shape (n_iter + 1,)
        Cost (sum of squared residuals) of the current iterate divided by the
        number of residuals, starting with the initial one.
    validation_history : ndarray of shape (n_iter + 1,) or None
        Validation loss of each iterate.
    best_iter : int
        Iteration at which ``theta`` was found (0 is the initial guess).
    n_iter : int
        Number of accepted steps.
    converged : bool
        False when the iteration limit stopped the search.
    stopped_early : bool
        True when the validation loss stopped improving (``n_iter_no_change``).
    """

    theta: np.ndarray
    loss_history: np.ndarray
    validation_history: np.ndarray | None
    best_iter: int
    n_iter: int
    converged: bool
    stopped_early: bool = False


def _scaled_step_factors(J, r):
    """SVD factors of the column-scaled Jacobian needed for the damped step.

    With ``Js = J / col_scale = U diag(s) Vt``, the damped step is
    ``-Vt.T @ (s / (s**2 + d**2) * (U.T @ r))``. A Householder QR of the
    augmented matrix ``[Js, r]`` gives the triangular factor ``R`` of ``Js``
    and ``Q.T @ r``; the SVD of the small ``R = Ur diag(s) Vt`` then gives
    ``U.T @ r = Ur.T @ (Q.T @ r)``. This is as accurate as the SVD of ``Js``
    but never forms the tall ``U`` (as large as J), which halves the work and
    the memory of a step on long records.

    Returns
    -------
    factors : tuple or None
        None when ``J`` holds a value that is not finite, else

        s : ndarray of shape (k,)
            Singular values, decreasing.
        Vt : ndarray of shape (k, n_params)
        col_scale : ndarray of shape (n_params,)
        projected : ndarray of shape (k,)
            ``U.T @ r``.
    """
    p = J.shape[1]
    squares = np.einsum("ij,ij->j", J, J)
    # A value of J that is not finite makes its column's sum so; only then is
    # J itself scanned (the sums of a finite J can overflow).
    if not np.all(np.isfinite(squares)) and not np.all(np.isfinite(J)):
        return None
    col_scale = np.sqrt(squares)
    col_scale[col_scale == 0.0] = 1.0
    # Rows that are zero in J and r (e.g. the imaginary parts of the DFT's
    # real bins) change neither factor; the QR's cost grows with the rows.
    # Only rows with a zero residual can be such rows.
    kept = r != 0.0
    if not kept.all():
        kept[~kept] = np.any(J[~kept] != 0.0, axis=1)
        if kept.any() and not kept.all():
            J, r = J[kept], r[kept]
    augmented = np.empty((r.size, p + 1), order="F")
    np.divide(J, col_scale, out=augmented[:, :p])
    augmented[:, p] = r
    # mode="raw" returns the economic triangular factor; "r" would pad it with
    # zero rows to the full height of J.
    R = qr(augmented, mode="raw", overwrite_a=True, check_finite=False)[1]
    try:
        Ur, s, Vt = svd(R[:, :p], full_matrices=False, check_finite=False,
                        lapack_driver="gesdd")
    except LinAlgError:
        # The divide-and-conquer driver can fail to converge on a nearly
        # singular factor (condition numbers near 1e19); the QR-iteration
        # driver is slower but converges there.
        Ur, s, Vt = svd(R[:, :p], full_matrices=False, check_finite=False,
                        lapack_driver="gesvd")
    return s, Vt, col_scale, Ur.T @ R[:, p]


def _damped_step(s, Vt, col_scale, projected, damping):
    """Levenberg-Marquardt step for the factors of :func:`_scaled_step_factors`."""
    return -(Vt.T @ (s / (s**2 + damping**2) * projected)) / col_scale


def warn_if_still_improving(label, max_iter, losses, validation):
    """ConvergenceWarning when the iteration limit stopped a search that was
    still improving: the held-out loss reached a new best in the last tenth of
    the iterations (the cost, without hold-out), by a relative margin that
    matters."""
    window = max(1, int(np.ceil(_RECENT_SHARE * max_iter)))
    history = np.asarray(losses if validation is None else validation)
    before = np.min(history[:-window]) if history.size > window else history[0]
    recent = np.min(history[-window:])
    if not recent < (1.0 - _RECENT_GAIN) * before:
        return
    what = "cost" if validation is None else "held-out loss"
    warn_at_caller(
        f"{label}: the iteration limit max_iter={max_iter} was reached while the "
        f"{what} was still improving ({before:.4g} to {recent:.4g} over the last "
        f"{window} iterations); increase max_iter to refine the fit.",
        ConvergenceWarning)


def _finite_residual(residual, theta, jacobian):
    """Residual at ``theta`` and, if ``jacobian``, its Jacobian; None for
    both when the simulation diverged."""
    r, J = residual(theta, jacobian)
    if r is None or not np.all(np.isfinite(r)):
        return None, None
    return r, J


def levenberg_marquardt(
    residual,
    theta0,
    *,
    validation_loss=None,
    max_iter=100,
    tol=1e-9,
    n_drop=0,
    n_iter_no_change=None,
    verbose=0,
    label="LM",
    initial=None,
    n_residuals=None,
):
    """Minimise ``sum(residual(theta)**2)`` by Levenberg-Marquardt.

    Parameters
    ----------
    residual : callable
        ``residual(theta, jacobian)`` returns ``(r, J)``: the residual vector of
        shape (m,) and, when ``jacobian`` is True, its Jacobian of shape
        (m, n_params) (else None). ``r`` is None when the simulation diverged.
    theta0 : ndarray of shape (n_params,)
        Starting point; its simulation must not diverge.
    validation_loss : callable, default=None
        ``validation_loss(theta)`` returns a float (``inf`` for a divergent
        model); the iterate minimising it is returned.
    max_iter : int, default=100
        Maximum number of accepted steps.
    tol : float, default=1e-9
        Stop when an accepted step lowers the cost by less than ``tol`` relative.
    n_drop : int, default=0
        Number of smallest singular values of the scaled Jacobian to discard
        (``n_states**2`` removes the similarity-transform invariance).
    n_iter_no_change : int, default=None
        With ``validation_loss``, stop once this many accepted steps in a row
        have not lowered the best validation loss (early stopping). ``None``
        runs until ``max_iter`` or ``tol``.
    verbose : int, default=0
        Print one line per iteration when positive.
    label : str, default="LM"
        Prefix of the progress lines.
    initial : tuple of ndarray, default=None
        ``residual(theta0, True)`` when the caller has it already.
    n_residuals : int, default=None
        Number of residuals the reported losses are averaged over; ``None``
        uses the length of the initial residual (give it when penalty rows
        come and go).

    Returns
    -------
    result : LMResult
    """
    theta = np.array(theta0, dtype=np.float64)
    r, J = residual(theta, True) if initial is None else initial
    if r is None or not np.all(np.isfinite(r)) or not np.all(np.isfinite(J)):
        raise ValueError(
            "The initial model diverges or gives non-finite values on the "
            "estimation data (X, y); it cannot start the optimisation."
        )
    m = r.size if n_residuals is None else n_residuals
    cost = float(r @ r)
    losses = [cost / m]
    val_losses = None
    best_theta, best_val, best_iter = theta.copy(), np.inf, 0
    if validation_loss is not None:
        best_val = validation_loss(theta)
        val_losses = [best_val]

    damping = None
    converged = stopped_early = False
    n_iter = 0
    with one_blas_thread():
        while n_iter < max_iter:
            factors = _scaled_step_factors(J, r)
            if factors is None:
                # The sensitivities of the current iterate overflowed although
                # its outputs are finite: no step can be computed from them
                # (LAPACK would reject the NaN), so the search ends here.
                converged = True
                break
            s, Vt, col_scale, projected = factors
            if s[0] == 0.0:
                # The residual does not depend on the parameters here: no
                # step can lower the cost.
                converged = True
                break
            rank = int(np.sum(s > s[0] * max(J.shape) * np.finfo(float).eps))
            # Of the parameters' directions, n_drop leave the output as it is.
            rank = max(1, min(rank, Vt.shape[1] - n_drop))
            s, Vt, projected = s[:rank], Vt[:rank], projected[:rank]
            if damping is None:
                damping = s[0]
            # The factors hold what the step needs: the Jacobian can go
            # before the trials compute the next one.
            J = None
            for trial in range(_MAX_REJECTED):
                step = _damped_step(s, Vt, col_scale, projected, damping)
                candidate = theta + step
                # Most first trials are accepted (the damping fell after the
                # last accepted step), and the Jacobian of an accepted one is
                # needed next: the first trial computes it with the residual,
                # which costs less than simulating the step twice.
                r_new, J_new = _finite_residual(residual, candidate, trial == 0)
                if r_new is not None and r_new @ r_new < cost:
                    break
                damping *= _DAMPING_UP
            else:
                converged = True
                break
            cost_new = float(r_new @ r_new)
            decrease = (cost - cost_new) / cost
            theta = candidate
            r, J = (r_new, J_new) if J_new is not None else residual(theta, True)
            cost = float(r @ r)
            n_iter += 1
            damping *= _DAMPING_DOWN
            losses.append(cost / m)
            line = f"{label} iter {n_iter:4d}  loss {cost / m:.6e}"
            if validation_loss is not None:
                val = validation_loss(theta)
                val_losses.append(val)
                line += f"  validation {val:.6e}"
                if val < best_val:
                    best_theta, best_val, best_iter = theta.copy(), val, n_iter
            if verbose:
                print(line + f"  damping {damping:.3e}", flush=True)
            if decrease < tol:
                converged = True
                break
            if (validation_loss is not None and n_iter_no_change is not None
                    and n_iter - best_iter >= n_iter_no_change):
                converged = stopped_early = True
                break
    if validation_loss is None:
        best_theta, best_iter = theta, n_iter
    if not converged and max_iter > 0:
        warn_if_still_improving(label, max_iter, losses, val_losses)
    return LMResult(
        theta=best_theta,
        loss_history=np.asarray(losses),
        validation_history=None if val_losses is None else np.asarray(val_losses),
        best_iter=best_iter,
        n_iter=n_iter,
        converged=converged,
        stopped_early=stopped_early,
    )
