"""Polynomial nonlinear state-space (PNLSS) models.

Paper §3.1, §4.1 and §5.1: the linear part is initialised from the Best Linear
Approximation, the polynomial coefficients E and F from zero, and all of them
(optionally with the initial state, PNLSS-I) are refined by Levenberg-Marquardt
on the simulation error, in the time domain or, for periodic data, in the
frequency domain with noise weighting (paper eq. 17).
"""

from numbers import Integral, Real

import numpy as np
from sklearn.base import clone
from sklearn.utils._param_validation import HasMethods, Interval, StrOptions

from ._base import DIVERGENCE_BOUND, _BaseStateSpace, holdout_masks, part_before_holdout
from ._bla import BLAEstimator
from ._optimize import levenberg_marquardt
from ._pnlss_kernels import jacobian_pnlss, monomial_state_derivatives, simulate_pnlss
from ._polynomial import evaluate_monomials, monomial_exponents

_TERM_OPTIONS = {"full", "states_only", "no_cross_products", "inputs_only"}


def _unpack(theta, shapes, estimate_x0):
    """Split theta into (A, B, C, D, E, F) and x0 (None when not estimated)."""
    matrices = []
    offset = 0
    for rows, cols in shapes:
        matrices.append(theta[offset : offset + rows * cols].reshape(rows, cols))
        offset += rows * cols
    x0 = theta[offset:] if estimate_x0 else None
    return matrices, x0


def _steady_state_rows(starts, n_prepend):
    """Row indices of the sequences, each preceded by its last ``n_prepend`` samples.

    Simulating a periodic signal from this extension starts every sequence in
    (approximately) steady state. Returns the row index into the original
    arrays per extended row, the extended ``starts`` and a mask of the extended
    rows that are original samples.
    """
    index, original, new_starts = [], [], [0]
    for begin, end in zip(starts[:-1], starts[1:]):
        length = end - begin
        head = begin + (np.arange(length - n_prepend, length) % length)
        index.append(head)
        index.append(np.arange(begin, end))
        original.append(np.zeros(n_prepend, dtype=bool))
        original.append(np.ones(length, dtype=bool))
        new_starts.append(new_starts[-1] + n_prepend + length)
    return (
        np.concatenate(index).astype(np.int64),
        np.asarray(new_starts, dtype=np.int64),
        np.concatenate(original),
    )


def _period_blocks(mask, starts, period):
    """(begin, n_periods) of the masked block of each sequence, in whole periods."""
    blocks = []
    for begin, end in zip(starts[:-1], starts[1:]):
        rows = np.flatnonzero(mask[begin:end])
        if rows.size == 0:
            continue
        if rows.size % period or rows[-1] - rows[0] + 1 != rows.size:
            raise ValueError(
                f"cost='frequency' needs the fitted rows of every sequence to be a "
                f"whole number of periods (period={period}); got {rows.size} "
                "rows. Adjust validation_fraction or the record lengths."
            )
        blocks.append((begin + rows[0], rows.size // period))
    return blocks


def _output_noise_weights(Y, blocks, period):
    """Inverse noise standard deviation per DFT line and output.

    The noise variance of the per-period DFT of the output is estimated from its
    variation over the periods of each sequence (pooled over the sequences that
    have at least two periods). Returns ones when no sequence has two periods.
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
        return np.ones_like(total)
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
    period, scaled by ``1 / sqrt(period)`` so that the cost keeps the size of the
    time-domain cost.
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


def _local_spectral_radius(A, E, state_exponents, S):
    """Spectral radius of the state map's Jacobian at each row of ``S``.

    The Jacobian of ``x -> A x + B u + E zeta(x, u)`` with respect to x is
    ``J(t) = A + E dzeta/dx(s(t))`` for the rows ``s(t) = [x(t); u(t)]`` of
    ``S``. Returns the spectral radii (n_rows,) and their derivatives with
    respect to the entries of J, of shape (n_rows, n, n), from the
    eigenvector formula ``d lambda = w^H dJ v / (w^H v)`` for the eigenvalue
    of largest modulus; and the monomial derivatives (n_rows, n_zeta, n)
    that carry these to E.
    """
    n = A.shape[0]
    dzeta = monomial_state_derivatives(np.ascontiguousarray(S), state_exponents, n)
    J = A + np.einsum("iz,tzj->tij", E, dzeta)
    eigenvalues, right = np.linalg.eig(J)
    rows = np.arange(len(S))
    top = np.argmax(np.abs(eigenvalues), axis=1)
    largest = eigenvalues[rows, top]
    radius = np.abs(largest)
    # Rows of the inverse of the right eigenvectors are the left eigenvectors
    # normalised so that w^H v = 1.
    left = np.linalg.inv(right)[rows, top]
    phase = np.conj(largest) / np.maximum(radius, np.finfo(float).tiny)
    gradient = np.real(phase[:, None, None] * left[:, :, None] * right[rows, :, top][:, None, :])
    return radius, gradient, dzeta


class _PNLSSProblem:
    """Simulation-error least-squares problem of a PNLSS model.

    Holds the data of one fit and turns a parameter vector into residuals (time
    or frequency domain), their Jacobian and the validation loss, in the form
    :func:`~sknlss._optimize.levenberg_marquardt` expects.
    """

    def __init__(self, U, Y, starts, state_exponents, output_exponents, n_states,
                 estimate_x0, fit_rows, val_rows, period, stability_penalty=0.0,
                 weight_decay=0.0):
        n_u, n_y = U.shape[1], Y.shape[1]
        n = n_states
        self.U, self.Y, self.starts = U, Y, starts
        self.exponents = (state_exponents, output_exponents)
        self.shapes = [(n, n), (n, n_u), (n_y, n), (n_y, n_u),
                       (n, len(state_exponents)), (n_y, len(output_exponents))]
        self.n_states = n
        self.estimate_x0 = estimate_x0
        self.fit_rows, self.val_rows = fit_rows, val_rows
        self.period = period
        self.n_sequences = len(starts) - 1
        # The Jacobian holds the cost rows only, in order.
        self.jacobian_rows = np.where(fit_rows, np.cumsum(fit_rows) - 1, -1).astype(np.int64)
        Y_fit = Y[fit_rows]
        if period is None:
            self.target = Y_fit.ravel()
        else:
            # Periods of every sequence's cost rows, as offsets into those rows.
            self.blocks = [
                (int(self.jacobian_rows[begin]), n_periods)
                for begin, n_periods in _period_blocks(fit_rows, starts, period)
            ]
            self.weights = _output_noise_weights(Y_fit, self.blocks, period)
            self.target = _frequency_rows(Y_fit, self.blocks, period, self.weights).ravel()
        self.validation_loss = self._validation_loss if val_rows.any() else None
        self.stability_penalty = stability_penalty
        self.weight_decay = weight_decay
        self.coefficient_scale = None
        sizes = [rows * cols for rows, cols in self.shapes]
        self.polynomial_columns = np.arange(sum(sizes[:4]), sum(sizes))

    def unpack(self, theta):
        return _unpack(theta, self.shapes, self.estimate_x0)

    def linear_columns(self):
        """Indices of A, B, C, D and x0 in theta."""
        n_linear = sum(r * c for r, c in self.shapes[:4])
        n_total = sum(r * c for r, c in self.shapes)
        n_x0 = self.n_states if self.estimate_x0 else 0
        return np.r_[np.arange(n_linear), np.arange(n_total, n_total + n_x0)]

    def _initial_states(self, x0):
        if x0 is None:
            return np.zeros((self.n_sequences, self.n_states))
        return np.ascontiguousarray(np.broadcast_to(x0, (self.n_sequences, x0.size)))

    def _fitted_points(self, X):
        """``[x; u]`` at the cost rows, from the simulated states X."""
        return np.hstack([X, self.U])[self.fit_rows]

    def set_coefficient_scale(self, theta):
        """Scale the weight decay of each coefficient of E and F by the RMS of its
        monomial along the trajectory of ``theta`` (the initial model), so that
        the decay acts on the size of each term's contribution."""
        S = self._fitted_points(self.simulate(theta, False)[1])
        rms = [np.sqrt(np.mean(evaluate_monomials(S, exponents) ** 2, axis=0))
               for exponents in self.exponents]
        self.coefficient_scale = np.concatenate(
            [np.tile(rms[0], self.shapes[4][0]), np.tile(rms[1], self.shapes[5][0])]
        )

    def _penalty_rows(self, theta, X, n_residuals, jacobian):
        """Residual rows (and their Jacobian) of the stability penalty and the
        weight decay, both relative to the mean squared residual, for the
        parameters ``theta`` whose simulated states are ``X``.

        The stability rows are the excess over 1 of the local spectral radius
        of the state map along the fitted trajectory. Their Jacobian holds the
        direct dependence on A and E; the states' own dependence on the
        parameters is neglected (a Gauss-Newton-type approximation: the cost
        itself is exact, so every accepted step still lowers it).
        """
        rows, jacobians = [], []
        if self.stability_penalty:
            (A, _, _, _, E, _), _ = self.unpack(theta)
            S = self._fitted_points(X)
            radius, gradient, dzeta = _local_spectral_radius(A, E, self.exponents[0], S)
            excess = np.maximum(radius - 1.0, 0.0)
            weight = np.sqrt(self.stability_penalty * n_residuals / len(S))
            rows.append(weight * excess)
            if jacobian:
                gradient *= (weight * (excess > 0))[:, None, None]
                J = np.zeros((len(S), theta.size))
                J[:, : A.size] = gradient.reshape(len(S), -1)
                start = self.polynomial_columns[0]
                J[:, start : start + E.size] = np.einsum(
                    "tij,tzj->tiz", gradient, dzeta
                ).reshape(len(S), -1)
                jacobians.append(J)
        if self.weight_decay:
            weight = np.sqrt(self.weight_decay * n_residuals) * self.coefficient_scale
            rows.append(weight * theta[self.polynomial_columns])
            if jacobian:
                J = np.zeros((weight.size, theta.size))
                J[np.arange(weight.size), self.polynomial_columns] = weight
                jacobians.append(J)
        return np.concatenate(rows), (np.vstack(jacobians) if jacobian else None)

    def simulate(self, theta, jacobian):
        """Simulated outputs, states, output Jacobian (None unless ``jacobian``)
        and the divergence flag."""
        matrices, x0 = self.unpack(theta)
        x0 = self._initial_states(x0)
        if jacobian:
            return jacobian_pnlss(*matrices, *self.exponents, self.U, self.starts, x0,
                                  self.estimate_x0, DIVERGENCE_BOUND, self.jacobian_rows)
        Y_model, X, diverged = simulate_pnlss(*matrices, *self.exponents, self.U,
                                              self.starts, x0, DIVERGENCE_BOUND)
        return Y_model, X, None, diverged

    def residual(self, theta, jacobian):
        Y_model, X, J, diverged = self.simulate(theta, jacobian)
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
        if self.stability_penalty or self.weight_decay:
            r_penalty, J_penalty = self._penalty_rows(theta, X, r.size, jacobian)
            r = np.concatenate([r, r_penalty])
            if jacobian:
                J = np.vstack([J, J_penalty])
        return r, J

    def restricted(self, theta, free):
        """Residual function of the parameters ``free`` only, the others fixed at ``theta``."""
        base = theta.copy()

        def residual(phi, jacobian):
            full = base.copy()
            full[free] = phi
            r, J = self.residual(full, jacobian)
            return r, (J[:, free] if J is not None else None)

        return residual

    def _validation_loss(self, theta):
        Y_model, _, _, diverged = self.simulate(theta, False)
        if diverged:
            return np.inf
        return float(np.mean((Y_model[self.val_rows] - self.Y[self.val_rows]) ** 2))


class PNLSSRegressor(_BaseStateSpace):
    """Polynomial nonlinear state-space model (PNLSS, PNLSS-I).

    The model is, in scaled signal units (see ``center``),

    .. math::

        x(t+1) &= A x(t) + B u(t) + E \\zeta(x(t), u(t)) \\\\
        y(t)   &= C x(t) + D u(t) + F \\eta(x(t), u(t))

    where :math:`\\zeta` and :math:`\\eta` hold monomials in :math:`[x; u]`.
    A, B, C, D are initialised from the Best Linear Approximation, E and F from
    zero, and all of them are refined by Levenberg-Marquardt on the simulation
    error with an analytic Jacobian.

    Parameters
    ----------
    n_states : int, default=2
        Model order n.
    degree : int or tuple of int, default=(2, 3)
        Total degrees of the monomials in zeta and eta.
    state_terms : {"full", "states_only", "no_cross_products", "inputs_only"} \
            or array-like of shape (n_zeta, n_states + n_inputs), default="full"
        Monomials of the state equation: all of them, those in x only, pure
        powers only, those in u only, or an explicit exponent array.
    output_terms : same as ``state_terms``, default="full"
        Monomials of the output equation.
    estimate_x0 : bool, default=False
        Estimate the initial state, shared by all sequences (PNLSS-I);
        ``predict`` then starts from the fitted ``x0_``.
    center : bool, default=False
        Expand the polynomials around the mean of the signals (zero mean, unit
        standard deviation) instead of around the signals' own zero (only
        scaled, as in the PNLSS toolbox). By default a polynomial system whose
        zero is a rest state is exactly representable; centring gives a
        different model class (no offset terms) that does not depend on the
        signals' offsets, matches the BLA initialisation to the data's mean
        level and makes a zero initial state the mean operating point, which
        matters for records that do not start at rest when x0 is not
        estimated.
    refine_linear : bool, default=False
        Before the nonlinear terms are freed, refine A, B, C, D (and x0) on
        the same cost with E = F = 0. This recovers from a poor nonparametric
        BLA (short or noisy records); ``False`` starts the nonlinear
        optimisation from the BLA itself, as in the paper.
    period : int, default=None
        Number of samples per period of a periodic excitation. When set, every
        sequence must be a whole number of periods; each sequence is then
        simulated in steady state by prepending its last ``n_transient``
        samples (excluded from the cost), in ``fit`` and in ``predict`` (for
        sequences whose length is a multiple of ``period``).
    cost : {"time", "frequency"}, default="time"
        Time-domain simulation error, or its per-period DFT at all lines
        weighted by the inverse noise standard deviation (paper eq. 17; needs
        ``period``). The noise variance comes from the variation over the
        periods of each sequence; with one period only the weights are 1.
    stability_penalty : float, default=0.0
        Weight of a penalty on local instability along the fitted trajectory:
        the mean squared excess over 1 of the spectral radius of the state
        map's Jacobian ``A + E dzeta/dx`` at every fitted sample, relative to
        the mean squared residual. Positive values steer the search towards
        models that are locally contracting wherever the data take the states,
        so that they do not blow up on inputs that push the states a little
        beyond the estimation data. 0 (the paper's cost) disables it.
    weight_decay : float, default=0.0
        Weight of the squared size of the polynomial terms, relative to the
        mean squared residual: ``sum_k (c_k e_k)^2`` over the coefficients
        ``e_k`` of E and F, with ``c_k`` the RMS of the k-th monomial along
        the trajectory of the initial (linear) model.
    bla : estimator, default=None
        Template of the linear model used for the initialisation. It is cloned
        and given ``n_states``, ``estimate_x0=True`` for PNLSS-I (if it has
        that parameter) and this model's ``period`` (if its own is None).
        ``None`` uses :class:`~sknlss.BLAEstimator`.
    max_iter : int, default=100
        Maximum number of Levenberg-Marquardt iterations.
    tol : float, default=1e-9
        Relative cost decrease below which the iterations stop.
    validation_fraction : float, default=0.0
        Fraction at the end of every sequence held out from the cost; the
        iterate with the lowest simulation error there is kept (the held-out
        tail continues the simulation of the fitted part). 0 keeps the last
        iterate.
    n_iter_no_change : int, default=None
        Stop once the validation loss has not improved for this many
        iterations (early stopping; it has no effect when
        ``validation_fraction=0``). ``None`` iterates until ``max_iter`` or
        ``tol``.
    n_transient : int, default=0
        Samples per sequence excluded from the cost and the score; with
        ``period``, the number of samples prepended for the steady state.
    verbose : int, default=0
        Print the progress of the optimisation.

    Attributes
    ----------
    A_ : ndarray of shape (n_states, n_states)
    B_ : ndarray of shape (n_states, n_inputs)
    C_ : ndarray of shape (n_outputs, n_states)
    D_ : ndarray of shape (n_outputs, n_inputs)
    E_ : ndarray of shape (n_states, n_zeta)
        Coefficients of the state-equation monomials.
    F_ : ndarray of shape (n_outputs, n_eta)
        Coefficients of the output-equation monomials.
    state_exponents_ : ndarray of shape (n_zeta, n_states + n_inputs)
        Exponents of the monomials in zeta.
    output_exponents_ : ndarray of shape (n_eta, n_states + n_inputs)
        Exponents of the monomials in eta.
    x0_ : ndarray of shape (n_states,)
        Initial state (zero unless ``estimate_x0``).
    n_params_ : int
        Number of free parameters, as counted in the paper:
        ``n^2 + n n_u + n_y n + n_y n_u + n n_zeta + n_y n_eta`` (plus ``n``
        when x0 is estimated).
    n_iter_ : int
        Number of accepted Levenberg-Marquardt steps.
    loss_history_ : ndarray of shape (n_iter_ + 1,)
        Cost per iteration (mean squared residual; weighted spectra for
        ``cost="frequency"``), including the ``stability_penalty`` and
        ``weight_decay`` terms.
    validation_loss_history_ : ndarray of shape (n_iter_ + 1,) or None
        Mean squared simulation error on the held-out rows per iteration.
    best_iteration_ : int
        Iteration whose parameters were kept.
    bla_ : estimator
        The fitted linear model used for the initialisation (fitted on the rows
        before the held-out tails, in this model's coordinates; it predicts in
        the user's units).
    n_features_in_ : int
        Number of inputs seen during ``fit``.
    u_offset_, u_scale_ : ndarray of shape (n_inputs,)
        Normalisation of the inputs.
    y_offset_, y_scale_ : ndarray of shape (n_outputs,)
        Normalisation of the outputs.

    See Also
    --------
    BLAEstimator : The linear model used for the initialisation.
    DecoupledPNLSS : PNLSS with decoupled polynomials (fewer parameters).
    NLSS2Regressor : Nonlinear state space with neural-network terms.

    Examples
    --------
    >>> import numpy as np
    >>> from sknlss import PNLSSRegressor
    >>> rng = np.random.default_rng(0)
    >>> u = 0.3 * rng.normal(size=(400, 1))
    >>> y = np.zeros(400)
    >>> x = 0.0
    >>> for t in range(400):
    ...     y[t] = x
    ...     x = 0.5 * x + u[t, 0] + 0.1 * x**2
    >>> model = PNLSSRegressor(n_states=1, degree=2, max_iter=20).fit(u, y)
    >>> bool(model.score(u, y) > 0.99)
    True
    """

    _parameter_constraints: dict = {
        **_BaseStateSpace._parameter_constraints,
        "n_states": [Interval(Integral, 1, None, closed="left")],
        "degree": [Interval(Integral, 2, None, closed="left"), "array-like"],
        "state_terms": [StrOptions(_TERM_OPTIONS), "array-like"],
        "output_terms": [StrOptions(_TERM_OPTIONS), "array-like"],
        "estimate_x0": ["boolean"],
        "center": ["boolean"],
        "refine_linear": ["boolean"],
        "period": [Interval(Integral, 1, None, closed="left"), None],
        "cost": [StrOptions({"time", "frequency"})],
        "stability_penalty": [Interval(Real, 0, None, closed="left")],
        "weight_decay": [Interval(Real, 0, None, closed="left")],
        "bla": [HasMethods(["fit", "get_params"]), None],
        "max_iter": [Interval(Integral, 0, None, closed="left")],
        "tol": [Interval(Real, 0, None, closed="left")],
        "validation_fraction": [Interval(Real, 0, 1, closed="left")],
        "n_iter_no_change": [Interval(Integral, 1, None, closed="left"), None],
        "verbose": ["verbose"],
    }

    def __init__(
        self,
        n_states=2,
        *,
        degree=(2, 3),
        state_terms="full",
        output_terms="full",
        estimate_x0=False,
        center=False,
        refine_linear=False,
        period=None,
        cost="time",
        stability_penalty=0.0,
        weight_decay=0.0,
        bla=None,
        max_iter=100,
        tol=1e-9,
        validation_fraction=0.0,
        n_iter_no_change=None,
        n_transient=0,
        verbose=0,
    ):
        self.n_states = n_states
        self.degree = degree
        self.state_terms = state_terms
        self.output_terms = output_terms
        self.estimate_x0 = estimate_x0
        self.center = center
        self.refine_linear = refine_linear
        self.period = period
        self.cost = cost
        self.stability_penalty = stability_penalty
        self.weight_decay = weight_decay
        self.bla = bla
        self.max_iter = max_iter
        self.tol = tol
        self.validation_fraction = validation_fraction
        self.n_iter_no_change = n_iter_no_change
        self.n_transient = n_transient
        self.verbose = verbose

    # ------------------------------------------------------------------ fit
    def _validate_training_data(self, X, y, sequence_id):
        U, Y, starts = super()._validate_training_data(X, y, sequence_id)
        if not self.center:
            # Scale only: the polynomials are expanded around the signals' own
            # zero, not around their means (see the ``center`` parameter).
            U = np.ascontiguousarray(U + self.u_offset_ / self.u_scale_)
            Y = np.ascontiguousarray(Y + self.y_offset_ / self.y_scale_)
            self.u_offset_ = np.zeros_like(self.u_offset_)
            self.y_offset_ = np.zeros_like(self.y_offset_)
        return U, Y, starts

    def _check_periodic(self, starts):
        lengths = np.diff(starts)
        if np.any(lengths % self.period):
            raise ValueError(
                f"With period={self.period}, every sequence must hold a whole number "
                f"of periods; got sequence lengths {lengths.tolist()}."
            )

    def _fit_linear(self, U, Y, starts, fit_mask):
        """Fit the BLA template on the rows before the held-out tails."""
        bla = clone(self.bla if self.bla is not None else BLAEstimator())
        params = bla.get_params()
        bla.set_params(n_states=self.n_states)
        if self.estimate_x0 and "estimate_x0" in params:
            bla.set_params(estimate_x0=True)
        if self.period is not None and params.get("period", 0) is None:
            bla.set_params(period=self.period)
        bla._fit_normalized(*part_before_holdout(U, Y, starts, fit_mask))
        # Same coordinates as this model: it predicts in the user's units too.
        for name in ("n_features_in_", "n_outputs_", "_y_was_1d", "u_offset_",
                     "u_scale_", "y_offset_", "y_scale_"):
            setattr(bla, name, getattr(self, name))
        return bla

    def _fit_normalized(self, U, Y, starts):
        n, n_u, n_y = self.n_states, U.shape[1], Y.shape[1]
        if self.cost == "frequency" and self.period is None:
            raise ValueError("cost='frequency' needs the period of the excitation.")
        periodic = self.period is not None
        if periodic:
            self._check_periodic(starts)
        self.state_exponents_ = monomial_exponents(n, n_u, self.degree, self.state_terms)
        self.output_exponents_ = monomial_exponents(n, n_u, self.degree, self.output_terms)
        n_zeta, n_eta = len(self.state_exponents_), len(self.output_exponents_)

        # Cost and hold-out rows of the original samples: with a period, the
        # transient is prepended rather than cut from the record.
        fit_mask, val_mask = holdout_masks(
            starts, 0 if periodic else self.n_transient, self.validation_fraction
        )
        self.bla_ = self._fit_linear(U, Y, starts, fit_mask)

        if periodic and self.n_transient:
            index, sim_starts, original = _steady_state_rows(starts, self.n_transient)
            U_sim, Y_sim = U[index], Y[index]
            fit_rows = np.zeros(len(index), dtype=bool)
            val_rows = np.zeros(len(index), dtype=bool)
            fit_rows[original], val_rows[original] = fit_mask, val_mask
        else:
            U_sim, Y_sim, sim_starts = U, Y, starts
            fit_rows, val_rows = fit_mask, val_mask
        problem = _PNLSSProblem(
            np.ascontiguousarray(U_sim), Y_sim, sim_starts,
            self.state_exponents_, self.output_exponents_, n,
            bool(self.estimate_x0), fit_rows, val_rows,
            self.period if self.cost == "frequency" else None,
            stability_penalty=self.stability_penalty, weight_decay=self.weight_decay,
        )
        bla = self.bla_
        blocks = [bla.A_, bla.B_, bla.C_, bla.D_, np.zeros((n, n_zeta)),
                  np.zeros((n_y, n_eta))]
        if self.estimate_x0:
            blocks.append(bla.x0_)
        theta = np.concatenate([np.asarray(b, dtype=np.float64).ravel() for b in blocks])
        if self.weight_decay:
            problem.set_coefficient_scale(theta)
        lm_options = dict(tol=self.tol, n_drop=n * n, n_iter_no_change=self.n_iter_no_change,
                          verbose=self.verbose)
        if self.refine_linear and self.max_iter > 0:
            # Linear parameters (and x0) only: a poor nonparametric BLA, e.g. on
            # a short record, would otherwise start the nonlinear search far away.
            free = problem.linear_columns()
            linear = levenberg_marquardt(
                problem.restricted(theta, free), theta[free], max_iter=self.max_iter,
                label="PNLSS (linear part)", **lm_options,
            )
            theta[free] = linear.theta
        result = levenberg_marquardt(
            problem.residual, theta, validation_loss=problem.validation_loss,
            max_iter=self.max_iter, label="PNLSS", **lm_options,
        )
        (A, B, C, D, E, F), x0 = problem.unpack(result.theta)
        self.A_, self.B_, self.C_, self.D_, self.E_, self.F_ = (
            m.copy() for m in (A, B, C, D, E, F)
        )
        self.x0_ = np.zeros(n) if x0 is None else x0.copy()
        self.n_params_ = int(result.theta.size)
        self._set_search_result(result)

    # ----------------------------------------------------------- simulation
    def _simulate_normalized(self, U, starts, x0):
        lengths = np.diff(starts)
        steady = (
            self.period is not None
            and self.n_transient > 0
            and not np.any(lengths % self.period)
        )
        args = (
            self.A_, self.B_, self.C_, self.D_, self.E_, self.F_,
            self.state_exponents_, self.output_exponents_,
        )
        if not steady:
            return simulate_pnlss(*args, U, starts, x0, DIVERGENCE_BOUND)
        index, sim_starts, original = _steady_state_rows(starts, self.n_transient)
        Y, X, diverged = simulate_pnlss(
            *args, np.ascontiguousarray(U[index]), sim_starts, x0, DIVERGENCE_BOUND
        )
        return Y[original], X[original], diverged
