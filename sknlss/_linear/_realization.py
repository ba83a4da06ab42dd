"""Parametric linear state-space models from frequency response data.

- :func:`frf_subspace`: the frequency-domain subspace method (McKelvey, Akçay,
  Ljung, IEEE TAC 1996) with the noise weighting of Pintelon (Automatica 2002),
  for FRF samples on any set of frequencies;
- :func:`refine_frf`: weighted nonlinear least squares of the state-space FRF on
  the nonparametric FRF (the criterion of paper eq. 9, in a state-space rather
  than a polynomial parametrisation, which stays well conditioned for MIMO and
  high orders), solved by the shared Levenberg-Marquardt optimiser;
- :func:`pole_radius_limit` and :func:`stabilize`: the poles the FRF data can
  support, and the projection of a model onto them;
- :func:`balanced_realization`: square-root balancing of a stable discrete-time
  model;
- :func:`simulate_linear` and :func:`estimate_initial_state`: free-run
  simulation and the least-squares initial state.

Frequencies are in cycles per sample: ``z = exp(2j pi f)``.
"""

import warnings

import numpy as np
from scipy.linalg import solve_discrete_lyapunov
from sklearn.exceptions import ConvergenceWarning

from .._core._memory import check_memory
from .._core._model import StateSpaceModel
from .._core._optimize import LMResult, levenberg_marquardt, warn_if_still_improving

# Spectral radius allowed for any fitted BLA whatever the data: the model must
# be simulated, so the refinement rejects steps that leave the unit disc with
# this margin (the data usually bound the poles more tightly, see
# `pole_radius_limit`).
_MAX_SPECTRAL_RADIUS = 1.0 - 1e-9
# Relative distance below its limit at which `stabilize` places a pole it moves,
# so that the refinement starts strictly inside the admissible region.
_LIMIT_MARGIN = 1e-6
# Levenberg-Marquardt steps between two re-balancings of the model.
_ROUND_ITER = 20
# Relative singular value of the initial-state regression below which a
# direction counts as undetermined (see `estimate_initial_state`).
_STATE_RCOND = 1e-8
# Weight of the penalty on the initial state's free response from the start of
# its sequence when the cost rows skip that start (see `estimate_initial_state`):
# the 1 % to which a mode has settled in the rule of the automatic transient.
_SKIPPED_START_WEIGHT = 0.01


def spectral_radius(A):
    """Largest pole magnitude of the state matrix ``A`` (0 without states)."""
    return float(np.max(np.abs(np.linalg.eigvals(A)), initial=0.0))


def ss_frf(A, B, C, D, frequencies):
    """FRF ``C (zI - A)^-1 B + D`` of a discrete-time model.

    Parameters
    ----------
    A, B, C, D : ndarray
        State-space matrices of shapes (n, n), (n, n_u), (n_y, n), (n_y, n_u).
    frequencies : ndarray of shape (n_freq,)
        Frequencies in cycles per sample.

    Returns
    -------
    frf : ndarray of shape (n_freq, n_y, n_u), complex
    """
    z = np.exp(2j * np.pi * np.asarray(frequencies))
    n = A.shape[0]
    resolvent_B = np.linalg.solve(z[:, None, None] * np.eye(n) - A, B.astype(complex))
    return C @ resolvent_B + D


def _column_weights(weight):
    """One weight per frequency and input from element weights (n_freq, n_y,
    n_u): the RMS of the frequency's weights over the inputs whose FRF is
    estimated there (a nonzero weight), zero for the others."""
    estimated = np.any(weight > 0, axis=1)
    n_estimated = np.maximum(np.sum(estimated, axis=1), 1)
    rms = np.sqrt(np.sum(weight**2, axis=(1, 2)) / (weight.shape[1] * n_estimated))
    return rms[:, None] * estimated


def _fit_bd(A, C, frequencies, G, weight):
    """Weighted linear least squares of B and D for fixed A and C."""
    n, n_y, n_u = A.shape[0], C.shape[0], G.shape[2]
    z = np.exp(2j * np.pi * frequencies)
    CX = C @ np.linalg.inv(z[:, None, None] * np.eye(n) - A)  # (F, n_y, n)
    regressor = np.concatenate(
        [CX, np.broadcast_to(np.eye(n_y), (len(z), n_y, n_y)).astype(complex)], axis=2
    )
    B, D = np.empty((n, n_u)), np.empty((n_y, n_u))
    for j in range(n_u):
        w = weight[:, :, j, None]
        lhs = (w * regressor).reshape(-1, n + n_y)
        rhs = (weight[:, :, j] * G[:, :, j]).ravel()
        sol = np.linalg.lstsq(np.vstack([lhs.real, lhs.imag]),
                              np.concatenate([rhs.real, rhs.imag]), rcond=None)[0]
        B[:, j], D[:, j] = sol[:n], sol[n:]
    return B, D


def n_block_rows(n_states, n_freq, n_inputs):
    """Block rows ``q`` of the subspace method for ``n_freq`` frequencies.

    ``q = 2 n + 1`` where the data allow it, at least ``n + 1``; the projection
    must leave ``2 n_freq n_u - q n_u >= n`` columns.
    """
    q = min(2 * n_states + 1, (2 * n_freq * n_inputs - n_states) // n_inputs)
    if q < n_states + 1:
        raise ValueError(
            f"n_states={n_states} is too large for {n_freq} frequency line(s) "
            f"with {n_inputs} input(s): the frequency-domain subspace method needs "
            f"at least {-(-(n_states * (n_inputs + 1)) // (2 * n_inputs))} lines."
        )
    return q


def frf_subspace(frequencies, G, weight, n_states):
    """Frequency-domain subspace estimate of (A, B, C, D) from FRF data.

    Parameters
    ----------
    frequencies : ndarray of shape (n_freq,)
        Frequencies in cycles per sample.
    G : ndarray of shape (n_freq, n_y, n_u), complex
        FRF samples.
    weight : ndarray of shape (n_freq, n_y, n_u)
        Inverse standard deviation of each FRF sample; zero for the samples
        not estimated (an input without power of its own at a frequency).
    n_states : int
        Model order.

    Returns
    -------
    A, B, C, D : ndarray
    """
    n_freq, n_y, n_u = G.shape
    q = n_block_rows(n_states, n_freq, n_u)
    z = np.exp(2j * np.pi * frequencies)
    w = _column_weights(weight)
    Wz = z[None, :] ** np.arange(q)[:, None]  # (q, F)
    # column (k, j): [G_k e_j; z G_k e_j; ...] and [e_j; z e_j; ...], scaled by
    # w_kj; scaling a column of both data matrices keeps the subspace equation
    # exact, and an input's FRF that is not estimated at k drops out
    Yb = (Wz[:, None, :, None] * (w[:, None, :] * G).transpose(1, 0, 2)[None])
    Yb = Yb.reshape(q * n_y, n_freq * n_u)
    Ub = (Wz[:, None, :, None] * (w[:, None, :] * np.eye(n_u)[None]).transpose(1, 0, 2)[None])
    Ub = Ub.reshape(q * n_u, n_freq * n_u)
    data = np.vstack([np.hstack([Ub.real, Ub.imag]), np.hstack([Yb.real, Yb.imag])])
    R = np.linalg.qr(data.T, mode="r").T
    R22 = R[q * n_u :, q * n_u :]
    # Pintelon (2002): whiten the rows by the covariance of the weighted noise,
    # Re(sum_k m_k W_k W_k^H) (x) I (each weighted sample has unit variance;
    # m_k the share of the inputs whose FRF is estimated at k)
    # (a clipped eigen-factor: with frequencies crowded near DC the rows of the
    # data matrix are nearly collinear and the covariance is ill-conditioned)
    share = np.mean(w > 0, axis=1)
    vals, vecs = np.linalg.eigh(np.kron(np.real((Wz * share) @ Wz.conj().T), np.eye(n_y)))
    root = np.sqrt(np.clip(vals, 1e-12 * vals[-1], None))
    left = np.linalg.svd((vecs / root).T @ R22, full_matrices=False)[0]
    O = (vecs * root) @ left[:, :n_states]
    C = O[:n_y]
    A = np.linalg.lstsq(O[:-n_y], O[n_y:], rcond=None)[0]
    A = stabilize(A, frequencies)
    B, D = _fit_bd(A, C, frequencies, G, weight)
    return A, B, C, D


def pole_radius_limit(poles, frequencies):
    """Largest radius of each pole that FRF data at ``frequencies`` can support.

    A pole ``p = exp(-sigma + 2j pi phi)`` shapes the FRF over about
    ``sigma / (2 pi)`` cycles per sample around ``phi`` (its half-power
    half-width). When no measured frequency lies that close to ``phi``, the
    data see only the pole's far field ``R / (z - p)``, which hardly depends
    on ``sigma``: the damping is not determined, and a least-squares fit is
    free to drift towards ``sigma = 0``: a mode on the stability limit that
    amplifies any input content near ``phi`` by about ``1 / sigma`` in
    simulation (out of the excited band, or, near DC, a near-integrator with
    a time constant far beyond the record). The damping is therefore kept at least ``2 pi d``,
    with ``d`` the distance from ``phi`` to the nearest measured frequency:
    the half-power band of every pole reaches the data. For a real pole near
    ``z = 1`` this bounds its time constant by ``1 / (2 pi f_min)`` samples,
    ``f_min`` being the lowest measured frequency (the corner frequency of the
    mode is not below it). The limit costs accuracy where the data would
    have determined the damping: with noise-free periodic data of period
    256, a real pole at 0.99 is fitted at 0.976, and a resonance of radius
    0.995 midway between two lines at 0.988, each with a largest error of
    the model's FRF at the lines of about 40 % of the FRF's largest value.
    A mode slower than ``N / (2 pi)`` samples, or narrower than half the
    line spacing, needs a longer period or record.

    Parameters
    ----------
    poles : ndarray of shape (n,), complex
        Discrete-time poles.
    frequencies : ndarray of shape (n_freq,)
        Measured frequencies in cycles per sample.

    Returns
    -------
    limit : ndarray of shape (n,)
        Radius limit of each pole, at most ``1 - 1e-9``.
    """
    phase = np.abs(np.angle(poles)) / (2 * np.pi)
    distance = np.min(np.abs(phase[:, None] - np.asarray(frequencies)[None, :]), axis=1)
    return np.minimum(np.exp(-2 * np.pi * distance), _MAX_SPECTRAL_RADIUS)


def _admissible(A, frequencies):
    poles = np.linalg.eigvals(A)
    return bool(np.all(np.abs(poles) < pole_radius_limit(poles, frequencies)))


def stabilize(A, frequencies=None):
    """Move the poles of ``A`` into the admissible region.

    Poles outside the unit disc are reflected into it (``1 / conj(p)``), then
    poles beyond their radius limit are pulled in, at the same angle, to just
    below it: the limit of :func:`pole_radius_limit` when ``frequencies`` is
    given, else ``1 - 1e-9``.

    Parameters
    ----------
    A : ndarray of shape (n, n)
        State matrix.
    frequencies : ndarray of shape (n_freq,), default=None
        Measured frequencies in cycles per sample.

    Returns
    -------
    A : ndarray
        ``A`` itself when all its poles are admissible.
    """
    poles, vectors = np.linalg.eig(A)
    if frequencies is None:
        limit = np.full(poles.shape, _MAX_SPECTRAL_RADIUS)
    else:
        limit = pole_radius_limit(poles, frequencies)
    outside = np.abs(poles) > 1.0
    poles = np.where(outside, 1.0 / np.conj(np.where(outside, poles, 1.0)), poles)
    radius = np.abs(poles)
    # the reflection keeps the angle, hence the limit
    beyond = radius >= limit
    if not (outside.any() or beyond.any()):
        return A
    poles = np.where(beyond, poles / np.where(beyond, radius, 1.0)
                     * limit * (1.0 - _LIMIT_MARGIN), poles)
    return np.real(vectors @ np.diag(poles) @ np.linalg.inv(vectors))


def _unpack(theta, n, n_u, n_y):
    sizes = np.cumsum([n * n, n * n_u, n_y * n])
    A, B, C, D = np.split(theta, sizes)
    return A.reshape(n, n), B.reshape(n, n_u), C.reshape(n_y, n), D.reshape(n_y, n_u)


def refine_frf(A, B, C, D, frequencies, G, weight, *, max_iter=100, tol=1e-10,
               verbose=0):
    """Weighted nonlinear least squares of the model FRF on ``G``.

    Minimises ``sum |weight (G_model - G)|^2`` over all entries of (A, B, C, D)
    by Levenberg-Marquardt, dropping the ``n^2`` directions of the similarity
    transform and rejecting steps that take a pole beyond the limit that the
    data support (:func:`pole_radius_limit`; a starting ``A`` beyond it is
    first moved by :func:`stabilize`). The iterations run
    in rounds of at most ``_ROUND_ITER`` steps, the model being re-balanced
    between rounds: the similarity freedom otherwise lets the realization
    drift into poorly conditioned coordinates, where the steps become tiny
    (with poles close to 1, hundreds of iterations instead of tens).

    Returns
    -------
    A, B, C, D : ndarray
    result : LMResult
    """
    n, n_u, n_y = B.shape[0], B.shape[1], C.shape[0]
    n_params = (n + n_y) * (n + n_u)
    n_values = len(frequencies) * n_y * n_u
    # The Jacobian's complex blocks, their concatenation, their weighted copy
    # and its real and imaginary rows stacked: four copies of 16 bytes.
    check_memory(
        64 * n_values * n_params,
        f"The refinement of the BLA's model (n_states={n}, {n_u} input(s), {n_y} "
        f"output(s): {n_params:,} parameters fitted to the FRF's {n_values:,} values)",
        "Use fewer states, or max_iter=0 to keep the subspace model.")
    z = np.exp(2j * np.pi * frequencies)
    eye = np.eye(n)
    w = weight
    A = stabilize(A, frequencies)

    def residual(theta, jacobian):
        A_, B_, C_, D_ = _unpack(theta, n, n_u, n_y)
        if not _admissible(A_, frequencies):
            return None, None
        X = np.linalg.inv(z[:, None, None] * eye - A_)  # (F, n, n)
        P = C_ @ X  # (F, n_y, n)
        Q = X @ B_  # (F, n, n_u)
        err = w * (C_ @ Q + D_ - G)
        r = np.concatenate([err.real.ravel(), err.imag.ravel()])
        if not jacobian:
            return r, None
        F = len(z)
        dA = np.einsum("fia,fbj->fijab", P, Q).reshape(F, n_y, n_u, n * n)
        dB = np.einsum("fia,jb->fijab", P, np.eye(n_u)).reshape(F, n_y, n_u, n * n_u)
        dC = np.einsum("ia,fbj->fijab", np.eye(n_y), Q).reshape(F, n_y, n_u, n_y * n)
        dD = np.broadcast_to(np.eye(n_y * n_u).reshape(1, n_y, n_u, n_y * n_u),
                             (F, n_y, n_u, n_y * n_u))
        J = w[..., None] * np.concatenate([dA, dB, dC, dD], axis=3)
        J = J.reshape(-1, J.shape[-1])
        return r, np.vstack([J.real, J.imag])

    losses, n_iter, converged = [], 0, False
    while n_iter < max_iter:
        theta = np.concatenate([A.ravel(), B.ravel(), C.ravel(), D.ravel()])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            result = levenberg_marquardt(residual, theta, max_iter=min(
                _ROUND_ITER, max_iter - n_iter), tol=tol, n_drop=n * n,
                verbose=verbose, label="BLA")
        losses.append(result.loss_history[1:] if losses else result.loss_history)
        n_iter += result.n_iter
        A, B, C, D = _unpack(result.theta, n, n_u, n_y)
        if result.converged:
            converged = True
            break
        A, B, C, D = balanced_realization(A, B, C, D)[:4]
    loss_history = np.concatenate(losses) if losses else np.empty(0)
    if not converged and max_iter > 0:
        warn_if_still_improving("BLA", max_iter, loss_history, None)
    result = LMResult(theta=np.concatenate([A.ravel(), B.ravel(), C.ravel(), D.ravel()]),
                      loss_history=loss_history, validation_history=None,
                      best_iter=n_iter, n_iter=n_iter, converged=converged)
    return A, B, C, D, result


def _psd_sqrt(M):
    """A factor L with L L^T = M for a symmetric positive semi-definite M."""
    vals, vecs = np.linalg.eigh((M + M.T) / 2)
    return vecs * np.sqrt(np.clip(vals, 0.0, None))


def balanced_realization(A, B, C, D):
    """Square-root balanced realization of a stable discrete-time model.

    The controllability and observability Gramians of the result are equal and
    diagonal, with decreasing Hankel singular values; the sign of each state is
    fixed so that the first nonzero entry of its column of C (or of its row of
    B) is positive. A model that is unstable or not minimal is returned as is.

    Returns
    -------
    A, B, C, D : ndarray
    hankel_singular_values : ndarray of shape (n,) or None
    """
    if spectral_radius(A) >= 1.0:
        return A, B, C, D, None
    Lc = _psd_sqrt(solve_discrete_lyapunov(A, B @ B.T))
    Lo = _psd_sqrt(solve_discrete_lyapunov(A.T, C.T @ C))
    U, s, Vt = np.linalg.svd(Lo.T @ Lc)
    if s.size == 0 or s[-1] <= 1e-12 * s[0]:
        return A, B, C, D, None
    root = np.sqrt(s)
    T = (Lc @ Vt.T) / root
    T_inv = (U.T @ Lo.T) / root[:, None]
    Ab, Bb, Cb = T_inv @ A @ T, T_inv @ B, C @ T
    lead = np.vstack([Cb, Bb.T])
    idx = np.argmax(np.abs(lead) > 1e-12 * np.abs(lead).max(axis=0), axis=0)
    sign = np.sign(lead[idx, np.arange(lead.shape[1])])
    sign[sign == 0] = 1.0
    return sign[:, None] * Ab * sign, sign[:, None] * Bb, Cb * sign, D.copy(), s


def simulate_linear(A, B, C, D, U, starts, x0):
    """Free-run simulation of a linear model over the sequences.

    Parameters
    ----------
    A, B, C, D : ndarray
        State-space matrices.
    U : ndarray of shape (n_samples, n_u)
        Input.
    starts : ndarray of shape (n_sequences + 1,)
        Sequence boundaries.
    x0 : ndarray of shape (n_sequences, n)
        Initial state of every sequence.

    Returns
    -------
    Y : ndarray of shape (n_samples, n_y)
    states : ndarray of shape (n_samples, n)
    diverged : bool
    """
    model = StateSpaceModel(A.shape[0], B.shape[1], C.shape[0])
    theta = model.pack({"A": A, "B": B, "C": C, "D": D})
    return model.simulate(theta, U, starts, x0)


def estimate_initial_state(A, B, C, D, U, Y, starts, mask, *, per_sequence=False):
    """Least-squares initial state (shared by all sequences, or one per
    sequence), with an output offset.

    The output is linear in the initial state: ``y = y_forced + Phi x0 + d``,
    where column ``i`` of ``Phi`` is the zero-input response from ``e_i``. The
    constant ``d`` is estimated with it because the mean of a record that does
    not start in steady state, used as the output offset, contains the mean of
    the transient: without ``d`` the free response would be counted twice.

    When ``mask`` skips the first samples of a sequence (a transient left out),
    a fast mode may have decayed there below what the noise lets the cost rows
    determine; the least squares then also penalise ``0.01 Phi_0 x0``, with
    ``Phi_0`` the free response on the first rows of each sequence, as many as
    its cost rows: a mode still at a tenth of its starting size or more keeps
    99 % of its fit, one settled to 1 % (the settling time the estimators use)
    half, and one settled further is shrunk towards zero.

    Parameters
    ----------
    A, B, C, D : ndarray
        State-space matrices.
    U : ndarray of shape (n_samples, n_u)
        Input.
    Y : ndarray of shape (n_samples, n_y)
        Measured output.
    starts : ndarray of shape (n_sequences + 1,)
        Sequence boundaries.
    mask : ndarray of bool of shape (n_samples,)
        Rows entering the least-squares cost.
    per_sequence : bool, default=False
        Estimate the initial state of every sequence; else every sequence
        starts from the same state.

    Returns
    -------
    x0 : ndarray of shape (n,), or (n_sequences, n) with ``per_sequence`` and
        several sequences
    offset : ndarray of shape (n_y,)
        Output offset ``d``, one for all sequences. Both are zero for a
        model whose simulation diverges on the record.
    """
    n, n_y, n_seq = A.shape[0], C.shape[0], len(starts) - 1
    zeros = np.zeros((n_seq, n))
    forced, _, diverged = simulate_linear(A, B, C, D, U, starts, zeros)
    no_input = np.zeros_like(U)
    free_responses = []
    for i in range(n):
        e = zeros.copy()
        e[:, i] = 1.0
        free, _, free_diverged = simulate_linear(A, B, C, D, no_input, starts, e)
        diverged |= free_diverged
        free_responses.append(free)
    per_sequence = per_sequence and n_seq > 1
    if diverged:
        # No initial state fits a model that diverges on the record.
        return np.zeros((n_seq, n) if per_sequence else n), np.zeros(n_y)
    target = Y - forced
    leading = _leading_rows(starts, mask)
    # The cost rows skip the start of a sequence (see the docstring): a
    # direction that has decayed to a fraction f of its response from the
    # start keeps f^2 / (f^2 + weight^2) of its fit.
    penalised = not np.array_equal(leading, mask)
    if per_sequence:
        return _states_per_sequence(np.stack(free_responses, axis=-1), target, starts, mask,
                                    leading if penalised else None)
    Phi, target = _state_rows(np.stack(free_responses, axis=-1), target, mask,
                              leading if penalised else None)
    # A direction of the state whose free response on the cost rows is below
    # _STATE_RCOND of the largest (usually the offset's) is not determined by
    # them: the minimum-norm solution leaves it out instead of fitting the
    # noise with a huge state.
    sol = np.linalg.lstsq(Phi, target, rcond=_STATE_RCOND)[0]
    return sol[:n], sol[n:]


def _state_rows(free, target, mask, leading):
    """The least-squares rows of :func:`estimate_initial_state` for one state:
    the free responses ``free`` (n_samples, n_y, n) on the rows ``mask``, a
    constant per output, and the penalty on the rows ``leading`` (None for
    none); and the ``target`` on them."""
    n, n_y = free.shape[2], free.shape[1]
    Phi = np.hstack([free[mask].reshape(-1, n), np.tile(np.eye(n_y), (int(mask.sum()), 1))])
    target = target[mask].ravel()
    if leading is not None:
        reference = free[leading].reshape(-1, n)
        Phi = np.vstack([Phi, np.hstack([_SKIPPED_START_WEIGHT * reference,
                                         np.zeros((reference.shape[0], n_y))])])
        target = np.concatenate([target, np.zeros(reference.shape[0])])
    return Phi, target


def _states_per_sequence(free, target, starts, mask, leading):
    """The least squares of :func:`estimate_initial_state` with one state per
    sequence, solved sequence by sequence.

    Each state moves only its own sequence's rows: the states are eliminated
    block by block (a truncated SVD each), the offset shared by all
    sequences is fitted to what no state explains, and each state then to
    what the offset leaves. The cost grows linearly with the number of
    sequences, where the joint least squares has a column per state.
    Directions below ``_STATE_RCOND`` of a bound on the joint matrix's
    largest singular value are left out, as there.
    """
    n = free.shape[2]
    factors, offset_columns, targets = [], [], []
    for begin, end in zip(starts[:-1], starts[1:]):
        rows = slice(begin, end)
        Phi, t = _state_rows(free[rows], target[rows], mask[rows],
                             None if leading is None else leading[rows])
        factors.append(np.linalg.svd(Phi[:, :n], full_matrices=False))
        offset_columns.append(Phi[:, n:])
        targets.append(t)
    # The joint matrix is the states' block diagonal beside the offset's
    # columns (the square root of the cost rows' count in norm).
    threshold = _STATE_RCOND * np.sqrt(
        max((S[0] ** 2 for _, S, _ in factors if S.size), default=0.0) + mask.sum())
    # Each block's directions above the threshold.
    bases = [(U[:, S > threshold], S[S > threshold], Vt[S > threshold])
             for U, S, Vt in factors]

    def unexplained(U, values):
        return values - U @ (U.T @ values)

    left = np.vstack([unexplained(U, E) for (U, _, _), E in zip(bases, offset_columns)])
    right = np.concatenate([unexplained(U, t) for (U, _, _), t in zip(bases, targets)])
    # The same absolute threshold: an offset that the states explain (a mode
    # at 1 that the output sees) is left to them, as in the joint problem.
    largest = np.linalg.norm(left, 2)
    if largest > threshold:
        offset = np.linalg.lstsq(left, right, rcond=threshold / largest)[0]
    else:
        offset = np.zeros(left.shape[1])
    states = np.array([Vt.T @ ((U.T @ (t - E @ offset)) / S)
                       for (U, S, Vt), E, t in zip(bases, offset_columns, targets)])
    return states, offset


def _leading_rows(starts, mask):
    """The first rows of every sequence, as many as ``mask`` holds in it."""
    leading = np.zeros_like(mask)
    for begin, end in zip(starts[:-1], starts[1:]):
        leading[begin : begin + int(np.count_nonzero(mask[begin:end]))] = True
    return leading
