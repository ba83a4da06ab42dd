"""The simulation-error least-squares problem shared by every nonlinear model.

:class:`SimulationErrorProblem` turns a parameter vector of a
:class:`~sknlss._core._model.StateSpaceModel` into residuals and their
Jacobian in the form :func:`~sknlss._core._optimize.levenberg_marquardt`
expects, and into the held-out (validation) loss. Its options hold for every
model:

- the cost: the time-domain simulation error on the fitted rows, or for
  periodic data its per-period DFT weighted by the inverse noise level (paper
  eq. 17);
- the transient: dropped from the cost, or, for periodic data, replaced by the
  last samples of every sequence prepended to it (steady state);
- the initial state, estimated (it ends theta) or fixed;
- a stability penalty on the local linearisation along the fitted trajectory;
- a weight decay on the nonlinear terms;
- the restriction to a subset of the parameters (e.g. the linear part first).
"""

import copy
from dataclasses import dataclass

import numpy as np

from ._sequences import holdout_masks, period_blocks, steady_state_rows


@dataclass
class FitRows:
    """The rows a fit simulates, and which of them enter the cost and the hold-out.

    Attributes
    ----------
    U, Y : ndarray of shape (n_rows, n_inputs), (n_rows, n_outputs)
        The simulated rows (with the prepended steady-state samples, if any).
    starts : ndarray of shape (n_sequences + 1,)
        Boundaries of the simulated sequences.
    fit_rows, val_rows : ndarray of bool of shape (n_rows,)
        Rows of the cost and of the held-out loss.
    original : ndarray of bool of shape (n_rows,)
        Rows that are samples of the data (not prepended ones).
    """

    U: np.ndarray
    Y: np.ndarray
    starts: np.ndarray
    fit_rows: np.ndarray
    val_rows: np.ndarray
    original: np.ndarray


def fit_rows(U, Y, starts, *, n_transient, validation_fraction, steady_state=False):
    """The rows of a fit: cost, hold-out, and the transient handling.

    Parameters
    ----------
    U, Y : ndarray
        Normalised signals.
    starts : ndarray
        Sequence boundaries.
    n_transient : int or ndarray of shape (n_sequences,)
        Samples per sequence kept out of the cost. With ``steady_state``,
        the last ``n_transient`` samples of every
        sequence are prepended to it instead, so that it starts in (nearly)
        periodic steady state and all its samples enter the cost.
    validation_fraction : float or ndarray of shape (n_sequences,)
        Share of the end of every sequence held out.
    steady_state : bool, default=False
        Whether the excitation is periodic (every sequence a whole number of
        periods); else the transient is cut from the records.

    Returns
    -------
    rows : FitRows
    """
    periodic = steady_state and np.any(np.asarray(n_transient) > 0)
    fit_mask, val_mask = holdout_masks(starts, 0 if periodic else n_transient,
                                       validation_fraction)
    if not periodic:
        return FitRows(U, Y, starts, fit_mask, val_mask, np.ones(len(U), dtype=bool))
    index, sim_starts, original = steady_state_rows(starts, n_transient)
    fit_sim = np.zeros(len(index), dtype=bool)
    val_sim = np.zeros(len(index), dtype=bool)
    fit_sim[original], val_sim[original] = fit_mask, val_mask
    return FitRows(np.ascontiguousarray(U[index]), np.ascontiguousarray(Y[index]),
                   sim_starts, fit_sim, val_sim, original)


# ------------------------------------------------------------ frequency cost
def _output_noise_weights(Y, blocks, period):
    """Inverse noise standard deviation per DFT line and output.

    The noise variance of the per-period DFT of the output is estimated from its
    variation over the periods of each sequence (pooled over the sequences that
    have at least two periods). Returns None when no sequence has two periods:
    the noise cannot be estimated.
    """
    n_outputs = Y.shape[1]
    total = np.zeros((period // 2 + 1, n_outputs))
    dof = 0
    for begin, n_periods in blocks:
        if n_periods < 2:
            continue
        spectra = np.fft.rfft(
            Y[begin : begin + n_periods * period].reshape(n_periods, period, n_outputs),
            axis=1,
        )
        total += np.sum(np.abs(spectra - spectra.mean(axis=0)) ** 2, axis=0) / period
        dof += n_periods - 1
    if dof == 0:
        return None
    variance = total / dof
    peak = variance.max(axis=0)
    # A line whose variance is numerically zero (noiseless data) must not get
    # an infinite weight: floor it far below the typical noise level.
    floor = np.where(peak > 0, 1e-10 * peak, 1.0)
    return 1.0 / np.sqrt(np.maximum(variance, floor))


def _frequency_rows(values, blocks, period, weights):
    """Weighted per-period DFT of time-domain rows, stacked as real and imaginary parts.

    ``values`` has shape (n_samples, n_outputs, ...) (residuals, or Jacobian rows
    with a trailing parameter axis); the DFT is taken over the samples of each
    period, scaled by ``1 / sqrt(period)``, at the lines from DC to Nyquist (paper
    eq. 17): unweighted, the cost is about half the time-domain one (Parseval
    counts the lines between DC and Nyquist twice), and the imaginary parts of
    DC and Nyquist are rows of zeros.
    """
    parts = []
    extra = (1,) * (values.ndim - 2)
    w = weights.reshape(weights.shape + extra)
    for begin, n_periods in blocks:
        block = values[begin : begin + n_periods * period]
        spectra = np.fft.rfft(block.reshape((n_periods, period) + values.shape[1:]), axis=1)
        spectra *= w / np.sqrt(period)
        parts.append(spectra.real.reshape((-1,) + values.shape[2:]))
        parts.append(spectra.imag.reshape((-1,) + values.shape[2:]))
    return np.concatenate(parts)


# --------------------------------------------------------- stability penalty
def spectral_radius(J, complex_arithmetic=False):
    """Spectral radius of each matrix of ``J`` and its derivative.

    Parameters
    ----------
    J : ndarray of shape (n_points, n, n)
    complex_arithmetic : bool, default=False
        Compute the eigenvectors' inverse in complex arithmetic even when every
        eigenvalue is real (as a stack containing complex ones does), so that
        the result does not depend on the other matrices of a stack.

    Returns
    -------
    radius : ndarray of shape (n_points,)
    gradient : ndarray of shape (n_points, n, n)
        Derivative of the radius with respect to the entries of each matrix,
        from the eigenvector formula ``d lambda = w^H dJ v / (w^H v)`` for the
        eigenvalue of largest modulus.
    """
    eigenvalues, right = np.linalg.eig(J)
    if complex_arithmetic:
        eigenvalues, right = eigenvalues.astype(complex), right.astype(complex)
    rows = np.arange(len(J))
    top = np.argmax(np.abs(eigenvalues), axis=1)
    largest = eigenvalues[rows, top]
    radius = np.abs(largest)
    # Rows of the inverse of the right eigenvectors are the left eigenvectors
    # normalised so that w^H v = 1.
    left = np.linalg.inv(right)[rows, top]
    phase = np.conj(largest) / np.maximum(radius, np.finfo(float).tiny)
    gradient = np.real(phase[:, None, None] * left[:, :, None] * right[rows, :, top][:, None, :])
    return radius, gradient


# Relative size of a 2 x 2 matrix's discriminant under which its eigenvalues
# count as nearly double: whether LAPACK returns them as a real or a complex
# pair is then a rounding decision, which only LAPACK itself can make.
_NEARLY_DOUBLE = 1e-8


def screening_radius(J):
    """Spectral radius of each matrix of ``J``, without eigenvectors, and whether
    LAPACK's eigenvalues of the whole stack are complex.

    The 1 x 1 and 2 x 2 cases (the most common state dimensions, on the longest
    records) are solved in closed form, unless a 2 x 2 matrix has a nearly
    double eigenvalue; the others through ``numpy.linalg.eigvals``.

    Parameters
    ----------
    J : ndarray of shape (n_points, n, n)

    Returns
    -------
    radius : ndarray of shape (n_points,)
    complex_stack : bool
        Whether ``numpy.linalg.eigvals(J)`` is complex (some matrix has a
        complex pair): see ``complex_arithmetic`` of :func:`spectral_radius`.
    """
    n = J.shape[1]
    if n == 1:
        return np.abs(J[:, 0, 0]), False
    if n == 2:
        half_trace = 0.5 * (J[:, 0, 0] + J[:, 1, 1])
        half_gap = 0.5 * (J[:, 0, 0] - J[:, 1, 1])
        coupling = J[:, 0, 1] * J[:, 1, 0]
        # The discriminant (half_trace**2 - det), without its cancellation.
        discriminant = half_gap**2 + coupling
        nearly_double = ((coupling < 0.0)
                         & (np.abs(discriminant) <= _NEARLY_DOUBLE * (half_gap**2 - coupling)))
        if not np.any(nearly_double):
            pair = discriminant < 0.0
            # Eigenvalues half_trace +- root, real or (with a complex pair)
            # half_trace +- i root.
            root = np.sqrt(np.abs(discriminant))
            radius = np.where(pair, np.hypot(half_trace, root), np.abs(half_trace) + root)
            return radius, bool(np.any(pair))
    eigenvalues = np.linalg.eigvals(J)
    return np.max(np.abs(eigenvalues), axis=1), np.iscomplexobj(eigenvalues)


# Step in the (normalised) states of the central differences that give the
# penalty's dependence on the terms' parameters (the penalty's Jacobian is a
# Gauss-Newton approximation in any case: the states' own dependence is left
# out).
_PENALTY_STEP = 1e-5

# Margin below 1 of the spectral radius, computed without eigenvectors, under
# which a point is known to be stable: far above the rounding differences of
# the two LAPACK paths, even for a defective local Jacobian of a few states.
_SCREEN_MARGIN = 1e-3


class SimulationErrorProblem:
    """Simulation-error least squares of a state-space model on given rows.

    Parameters
    ----------
    model : StateSpaceModel
        Model structure and parameter layout.
    rows : FitRows
        The simulated rows, with the cost and hold-out masks.
    frequency_period : int, default=None
        When set, the cost is the weighted per-period DFT of the simulation
        error (every sequence's cost rows a whole number of periods); the noise
        weights come from the variation over the periods (``noise_weighted``
        says whether a sequence keeps two periods to estimate it; every line
        counts alike otherwise).
    stability_penalty : float, default=0.0
        Weight of the mean squared excess over 1 of the spectral radius of the
        state map's local Jacobian ``A + dh_x/dx`` at the fitted samples,
        relative to the mean squared residual.
    weight_decay : float, default=0.0
        Weight of the squared size of the terms' contributions, added to the
        sum of squared residuals: each parameter the terms decay
        (``decay_mask``) is scaled by the RMS of its direct effect on the
        terms along the trajectory of the starting point (see
        :meth:`with_decay_scale`), so that the decay does not depend on the
        units of the signals or the parametrisation. Like a prior, its weight
        does not grow with the number of samples: it matters on short records
        and fades on long ones.
    held : ndarray of int, default=None
        Parameters that a search holds at their starting values (see
        :func:`~sknlss._core._multistart.fit_from`); None holds none.
    """

    def __init__(self, model, rows, *, frequency_period=None, stability_penalty=0.0,
                 weight_decay=0.0, held=None):
        self.model = model
        self.held = np.zeros(0, dtype=np.int64) if held is None else np.asarray(held)
        self.rows = rows
        self.U, self.Y, self.starts = rows.U, rows.Y, rows.starts
        self.fit_rows, self.val_rows = rows.fit_rows, rows.val_rows
        self.period = frequency_period
        self.stability_penalty = stability_penalty
        self.weight_decay = weight_decay
        # The Jacobian holds the cost rows only, in order.
        self.jacobian_rows = np.where(self.fit_rows, np.cumsum(self.fit_rows) - 1,
                                      -1).astype(np.int64)
        Y_fit = self.Y[self.fit_rows]
        if frequency_period is None:
            self.target = Y_fit.ravel()
        else:
            # Periods of every sequence's cost rows, as offsets into those rows.
            self.blocks = [
                (int(self.jacobian_rows[begin]), n_periods)
                for begin, n_periods in period_blocks(self.fit_rows, self.starts,
                                                      frequency_period)
            ]
            weights = _output_noise_weights(Y_fit, self.blocks, frequency_period)
            self.noise_weighted = weights is not None
            self.weights = (weights if self.noise_weighted
                            else np.ones((frequency_period // 2 + 1, Y_fit.shape[1])))
            self.target = _frequency_rows(Y_fit, self.blocks, frequency_period,
                                          self.weights).ravel()
        # The losses are averaged over the simulation-error residuals only: the
        # penalties add a varying number of rows.
        self.n_residuals = self.target.size
        # Mean squared error on the cost rows above which a model is not judged
        # on the held-out rows (see ``held_out_loss``); set by the estimators.
        self.fit_loss_limit = np.inf
        self.decay_scale = None
        # (theta, outputs, diverged) of the last residual: the optimiser asks
        # for the held-out loss of the iterate whose residual it has just
        # computed, and the same simulation serves both. It is replaced as a
        # whole, so that concurrent callers can at worst miss it.
        self._last_simulation = None

    # ----------------------------------------------------------- simulation
    def simulate(self, theta):
        """Outputs, states and the divergence flag over the simulated rows."""
        return self.model.simulate(theta, self.U, self.starts)

    def simulate_input(self, theta, U):
        """Outputs, states and divergence flag for another input on the same rows."""
        return self.model.simulate(theta, U, self.starts)

    def _fitted_points(self, X):
        """``[x; u]`` at the cost rows, from the simulated states X."""
        return np.hstack([X[self.fit_rows], self.U[self.fit_rows]])

    @property
    def validation_loss(self):
        """The held-out loss as a function of the parameters, None without
        held-out rows; bound to this problem (a copy's to the copy, whose last
        simulation it reuses)."""
        return self._validation_loss if self.val_rows.any() else None

    def with_decay_scale(self, theta):
        """The problem with the scale of its weight decay fixed from the
        trajectory of ``theta`` (a starting point), as a copy: the starts that
        share a problem, in threads too, each keep their own scale."""
        problem = copy.copy(self)
        problem.decay_scale = self._decay_scale(theta)
        return problem

    def _decay_scale(self, theta):
        points = self._fitted_points(self.simulate(theta)[1])
        points = points[np.all(np.isfinite(points), axis=1)]
        scale = self.model.parameter_rms(theta, points) * self.model.terms.decay_mask()
        return np.nan_to_num(scale)

    # ------------------------------------------------------------- residual
    def residual(self, theta, jacobian):
        """Residual vector and (when ``jacobian``) its Jacobian; ``(None, None)``
        when the simulation diverges."""
        model = self.model
        local = None
        if jacobian:
            Y_model, X, J, local, diverged = model.sensitivities(
                theta, self.U, self.starts, self.jacobian_rows,
                with_local=bool(self.stability_penalty))
        else:
            Y_model, X, diverged = self.simulate(theta)
            J = None
        self._last_simulation = (theta.copy(), Y_model, diverged)
        if diverged:
            return None, None
        Y_fit = Y_model[self.fit_rows]
        if self.period is None:
            r = Y_fit.ravel() - self.target
        else:
            r = _frequency_rows(Y_fit, self.blocks, self.period, self.weights).ravel()
            r -= self.target
            if jacobian:
                J = _frequency_rows(J, self.blocks, self.period, self.weights)
        if jacobian:
            J = J.reshape(r.size, -1)
        extra = []
        if self.stability_penalty:
            stability = self._stability_rows(theta, X, r.size, jacobian, local)
            if stability is None:
                return None, None
            extra.append(stability)
        if self.weight_decay:
            extra.append(self._decay_rows(theta, jacobian))
        if extra:
            r = np.concatenate([r] + [rows for rows, _ in extra])
            if jacobian:
                J = np.vstack([J] + [rows for _, rows in extra])
        return r, J

    def _stability_rows(self, theta, X, n_residuals, jacobian, local=None):
        """Rows of the stability penalty and their Jacobian.

        The rows are the excess over 1 of the local spectral radius of the
        state map at the fitted samples where it exceeds 1 (elsewhere they
        are zero, with a zero Jacobian, and are left out: the penalty is
        inactive at most samples, and the optimiser's factorisation costs in
        proportion to the rows). Their Jacobian holds the direct
        dependence on A and on the terms' parameters (by central differences
        in the states of the terms' parameter Jacobian); the states' own
        dependence on the parameters is neglected (a Gauss-Newton-type
        approximation: the cost itself is exact, so every accepted step still
        lowers it).

        None when the local Jacobians overflow along the trajectory: the state
        map is then as unstable as a divergence. ``local``, when given, holds
        the state map's local Jacobians at the fitted points (from the
        sensitivities).
        """
        model = self.model
        n = model.n_states
        S = self._fitted_points(X)
        if local is None:
            local = model.local_jacobians(theta, S)[:, :n]
        if not np.all(np.isfinite(local)):
            return None
        # The radius without eigenvectors costs far less and differs from the
        # one with them by rounding only: a point whose radius is below
        # 1 - _SCREEN_MARGIN without them has a zero row either way.
        screened, complex_stack = screening_radius(local)
        near = np.flatnonzero(screened > 1.0 - _SCREEN_MARGIN)
        radius, gradient = spectral_radius(local[near], complex_stack)
        above = radius > 1.0
        active = near[above]
        weight = np.sqrt(self.stability_penalty * n_residuals / len(S))
        rows = weight * (radius[above] - 1.0)
        if not jacobian:
            return rows, None
        J = np.zeros((active.size, theta.size))
        if active.size:
            G = weight * gradient[above]
            J[:, : n * n] = G.reshape(active.size, -1)
            terms_state = model.terms_columns[: model.terms.n_state_params]
            J[:, terms_state] = model.curvature_contraction(theta, S[active], G,
                                                            _PENALTY_STEP)
        return rows, J

    def _decay_rows(self, theta, jacobian):
        """Rows of the weight decay (scaled terms' parameters) and their Jacobian."""
        decayed = np.flatnonzero(self.decay_scale)
        columns = self.model.terms_columns[decayed]
        weight = np.sqrt(self.weight_decay) * self.decay_scale[decayed]
        rows = weight * theta[columns]
        if not jacobian:
            return rows, None
        J = np.zeros((decayed.size, theta.size))
        J[np.arange(decayed.size), columns] = weight
        return rows, J

    def restricted(self, theta, free):
        """The problem in the parameters ``free`` only, the others fixed at ``theta``.

        Returns an object with the ``residual`` and ``validation_loss`` of the
        free parameters, and the weight decay of this problem (its scale set
        as for a start, see :meth:`with_decay_scale`).
        """
        return _Restricted(self, theta, free)

    def fit_loss(self, theta):
        """Mean squared simulation error of ``theta`` on the cost rows; inf when
        it diverges."""
        Y_model, _, diverged = self.simulate(theta)
        if diverged:
            return np.inf
        return _mean_squared_error(Y_model, self.Y, self.fit_rows)

    def held_out_loss(self, theta, simulation=None):
        """Mean squared simulation error of ``theta`` on the held-out rows (the
        cost rows when nothing is held out).

        It is inf when the simulation diverges, and when its error on the cost
        rows exceeds ``fit_loss_limit``: among the many iterates and starts
        judged on a short held-out end, one that has not learnt its own cost
        rows (as well as the linear model has) can match that end by accident.
        ``simulation``, when given, is the ``(outputs, diverged)`` of ``theta``.
        """
        if simulation is None:
            Y_model, _, diverged = self.simulate(theta)
        else:
            Y_model, diverged = simulation
        if diverged:
            return np.inf
        if _mean_squared_error(Y_model, self.Y, self.fit_rows) > self.fit_loss_limit:
            return np.inf
        rows = self.val_rows if self.val_rows.any() else self.fit_rows
        return _mean_squared_error(Y_model, self.Y, rows)

    def _validation_loss(self, theta):
        last = self._last_simulation
        if last is not None and np.array_equal(last[0], theta):
            return self.held_out_loss(theta, last[1:])
        return self.held_out_loss(theta)


def _mean_squared_error(Y_model, Y, rows):
    return float(np.mean((Y_model[rows] - Y[rows]) ** 2))


class _Restricted:
    """A problem in a subset of its parameters (see ``SimulationErrorProblem.restricted``)."""

    #: The parameters it does not free are outside its vector: it holds none.
    held = np.zeros(0, dtype=np.int64)

    def __init__(self, problem, theta, free):
        self._problem, self._base, self._free = problem, theta.copy(), free
        self.n_residuals = problem.n_residuals
        self.weight_decay = problem.weight_decay
        self.validation_loss = (None if problem.validation_loss is None
                                else self._validation_loss)

    def full(self, phi):
        """The whole parameter vector for the free parameters ``phi``."""
        full = self._base.copy()
        full[self._free] = phi
        return full

    def free_part(self, values):
        """The entries (columns, for a Jacobian) of ``values`` that belong to
        the free parameters."""
        return values[..., self._free]

    def with_decay_scale(self, phi):
        """The restricted problem with its decay scaled from ``phi`` (see
        ``SimulationErrorProblem.with_decay_scale``)."""
        return _Restricted(self._problem.with_decay_scale(self.full(phi)), self._base,
                           self._free)

    def residual(self, phi, jacobian):
        r, J = self._problem.residual(self.full(phi), jacobian)
        return r, (self.free_part(J) if J is not None else None)

    def _validation_loss(self, phi):
        return self._problem.validation_loss(self.full(phi))
