"""PNLSS models with decoupled polynomials (paper §6).

The multivariate polynomials ``E zeta`` and ``F eta`` of a fitted PNLSS model
are replaced by ``W g(V^T [x; u])`` with ``r`` univariate branches, computed from
the CPD of their Jacobians (:func:`~sknlss._decouple.decouple_polynomial`); the
decoupled model is then re-optimised on the simulation error.
"""

from numbers import Integral, Real

import numpy as np
from sklearn.base import clone
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import HasMethods, Interval, StrOptions
from sklearn.utils.parallel import Parallel, delayed

from ._base import _BaseStateSpace, holdout_masks
from ._decouple import decouple_polynomial
from ._decoupled_kernels import jacobian_decoupled, parameter_sizes, simulate_decoupled
from ._optimize import levenberg_marquardt

# Factors applied to W when the decoupled initial model diverges on the
# estimation data: the branches are shrunk until the simulation stays bounded
# (the last factor leaves the PNLSS's linear part).
_SHRINK_FACTORS = (1.0, 0.5, 0.25, 0.1, 0.01, 0.0)


def _stack_polynomials(E, state_exponents, F, output_exponents):
    """Coefficients of ``[E zeta; F eta]`` over the union of the monomials.

    Returns
    -------
    coefficients : ndarray of shape (n_states + n_outputs, n_terms)
    exponents : ndarray of shape (n_terms, n_states + n_inputs)
    """
    exponents, inverse = np.unique(
        np.vstack([state_exponents, output_exponents]), axis=0, return_inverse=True
    )
    inverse = inverse.ravel()
    n_zeta = len(state_exponents)
    coefficients = np.zeros((E.shape[0] + F.shape[0], len(exponents)))
    coefficients[: E.shape[0], inverse[:n_zeta]] = E
    coefficients[E.shape[0] :, inverse[n_zeta:]] = F
    return coefficients, exponents


def _sampling_points(pnlss, U, starts, fit_mask, sampling, n_points, rng):
    """Sampling points in the region where the PNLSS model operates.

    The PNLSS states are not normalised (they may have large offsets and
    spreads), so the points follow the distribution of the model's own
    simulated ``[x; u]`` on the fitted rows: the rows themselves
    (``"trajectory"``) or a normal distribution with their mean and
    covariance (``"normal"``).
    """
    x0 = np.tile(pnlss.x0_, (len(starts) - 1, 1))
    _, states, _ = pnlss._simulate_normalized(U, starts, x0)
    S = np.hstack([states, U])[fit_mask]
    S = S[np.all(np.isfinite(S), axis=1)]
    if len(S) < 2:
        return rng.standard_normal((n_points, S.shape[1]))
    if sampling == "normal":
        return rng.multivariate_normal(S.mean(axis=0), np.cov(S, rowvar=False), size=n_points)
    if len(S) > n_points:
        S = S[rng.choice(len(S), n_points, replace=False)]
    return S


def _initial_parameters(pnlss, V, W, c, estimate_x0):
    """Starting points of the re-optimisation, tried in turn until one
    simulates without diverging: the decoupled PNLSS, then with its branches
    shrunk towards the PNLSS's linear part, and finally a static model
    (A = B = C = 0), which cannot diverge."""
    x0 = [pnlss.x0_] if estimate_x0 else []
    linear = [pnlss.A_, pnlss.B_, pnlss.C_, pnlss.D_]
    for factor in _SHRINK_FACTORS:
        yield np.concatenate([np.ravel(m) for m in (*linear, V, factor * W, c, *x0)])
    static = [np.zeros_like(m) for m in linear[:3]] + [pnlss.D_]
    yield np.concatenate([np.ravel(m) for m in (*static, V, 0 * W, c, *x0)])


def _fit_one_start(pnlss, U, Y, starts, fit_mask, val_mask, seed, *, rank, degree,
                   sampling, n_sampling_points, n_restarts, estimate_x0, max_iter, tol,
                   verbose, label, n_iter_no_change=None):
    """Decouple the fitted PNLSS with one random draw, then re-optimise.

    Returns the parameter matrices ``(A, B, C, D, V, W, c)``, ``x0``, the
    optimiser's :class:`~sknlss._optimize.LMResult` and the decoupling error.
    """
    rng = check_random_state(seed)
    n, n_u, n_y = pnlss.A_.shape[0], U.shape[1], Y.shape[1]
    coefficients, exponents = _stack_polynomials(
        pnlss.E_, pnlss.state_exponents_, pnlss.F_, pnlss.output_exponents_
    )
    if len(exponents):
        V, W, c, error = decouple_polynomial(
            coefficients, exponents, rank, degree=degree,
            sampling_points=_sampling_points(pnlss, U, starts, fit_mask, sampling,
                                             n_sampling_points, rng),
            n_restarts=n_restarts, random_state=rng,
        )
    else:
        # A PNLSS without monomials: zero branches in random directions.
        V, W = rng.standard_normal((n + n_u, rank)), np.zeros((n + n_y, rank))
        c, error = np.zeros((rank, degree - 1)), 0.0

    sizes = parameter_sizes(n, n_u, n_y, rank, degree - 1)
    shapes = [(n, n), (n, n_u), (n_y, n), (n_y, n_u), (n + n_u, rank), (n + n_y, rank),
              (rank, degree - 1)]
    splits = np.cumsum(sizes[:-1])
    n_theta = splits[-1] + (n if estimate_x0 else 0)
    n_seq = len(starts) - 1
    target = Y[fit_mask].ravel()

    def unpack(theta):
        blocks = np.split(theta, splits)
        matrices = [np.ascontiguousarray(b.reshape(s)) for b, s in zip(blocks, shapes)]
        x0 = blocks[-1] if estimate_x0 else np.zeros(n)
        return matrices, np.ascontiguousarray(np.tile(x0, (n_seq, 1)))

    def residual(theta, jacobian):
        matrices, x0 = unpack(theta)
        if jacobian:
            Y_model, dY, diverged = jacobian_decoupled(*matrices, U, starts, x0)
        else:
            Y_model, _, diverged = simulate_decoupled(*matrices, U, starts, x0)
        if diverged:
            return None, None
        r = Y_model[fit_mask].ravel() - target
        if not jacobian:
            return r, None
        return r, dY[fit_mask][:, :, :n_theta].reshape(r.size, n_theta)

    validation_loss = None
    if val_mask.any():
        def validation_loss(theta):
            matrices, x0 = unpack(theta)
            Y_model, _, diverged = simulate_decoupled(*matrices, U, starts, x0)
            if diverged:
                return np.inf
            return float(np.mean((Y_model[val_mask] - Y[val_mask]) ** 2))

    for theta0 in _initial_parameters(pnlss, V, W, c, estimate_x0):
        r, J = residual(theta0, True)
        if r is not None and np.all(np.isfinite(r)) and np.all(np.isfinite(J)):
            break
    result = levenberg_marquardt(
        residual, theta0, validation_loss=validation_loss, max_iter=max_iter, tol=tol,
        n_iter_no_change=n_iter_no_change,
        # Similarity transforms of the states and the scaling of each branch's
        # input and output leave the simulated output unchanged.
        n_drop=n * n + 2 * rank, verbose=verbose, label=label,
    )
    matrices, x0 = unpack(result.theta)
    return matrices, x0[0].copy(), result, error


class DecoupledPNLSS(_BaseStateSpace):
    """PNLSS model whose polynomials are decoupled into univariate branches.

    The model is, in the PNLSS model's scaled signal units, with
    ``s = [x(t); u(t)]``,

    .. math::

        x(t+1) &= A x(t) + B u(t) + W_x g(V^T s) \\\\
        y(t)   &= C x(t) + D u(t) + W_y g(V^T s)

    where :math:`g_l(z) = \\sum_{k=2}^{d} c_{l,k} z^k`, :math:`l = 1, \\ldots, r`.
    The fit (paper §6) first fits a PNLSS model (a clone of ``pnlss``), then
    decouples its stacked polynomials ``[E zeta; F eta]`` by the canonical
    polyadic decomposition of their Jacobians in ``n_sampling_points`` points
    (Dreesen, Ishteva and Schoukens, SIMAX 2015), refined on the Jacobians and
    the values of the polynomials in the same points
    (:func:`~sknlss._decouple.decouple_polynomial`), and finally re-optimises
    all parameters by Levenberg-Marquardt on the simulation error.

    The branches have no linear term: it would duplicate ``A, B, C, D``.

    Parameters
    ----------
    n_states : int, default=2
        Model order n (forwarded to the PNLSS model).
    rank : int, default=5
        Number of branches r.
    branch_degree : int, default=None
        Degree d of the branches (>= 2); ``None`` uses the largest monomial
        degree of the PNLSS model.
    n_sampling_points : int, default=500
        Number of points in which the Jacobians are evaluated.
    sampling : {"normal", "trajectory"}, default="normal"
        Where the Jacobians are evaluated: normally distributed points (as in
        the paper) with the mean and covariance of the PNLSS model's own
        simulated ``[x; u]`` on the fitted rows, or points drawn from that
        trajectory itself. The PNLSS states are not normalised, so a standard
        normal distribution could miss the region where the model operates.
    estimate_x0 : bool, default=False
        Estimate the initial state (shared by all sequences, forwarded to the
        PNLSS model); ``predict`` then starts from ``x0_``.
    pnlss : PNLSSRegressor, default=None
        Template of the PNLSS model that is decoupled; it receives
        ``n_states``, ``estimate_x0``, ``validation_fraction`` and
        ``n_transient`` from this estimator, and its normalisation of the
        signals (e.g. ``center``) is used by the decoupled model too. Its own
        hyperparameters are tunable as ``pnlss__degree`` and so on. ``None``
        uses ``PNLSSRegressor()``. The re-optimisation simulates every
        sequence from its start (the PNLSS's steady-state option for
        periodic data is not used; exclude the transient with
        ``n_transient``).
    max_iter : int, default=100
        Maximum number of Levenberg-Marquardt iterations of the re-optimisation.
    tol : float, default=1e-9
        Relative cost decrease below which the iterations stop.
    validation_fraction : float, default=0.0
        Fraction at the end of every sequence held out from the cost; the
        iterate with the lowest simulation error there is kept. 0 keeps the
        last iterate.
    n_iter_no_change : int, default=None
        Stop a search once the validation loss has not improved for this many
        iterations (early stopping; it has no effect when
        ``validation_fraction=0``). ``None`` iterates until ``max_iter`` or
        ``tol``.
    n_restarts : int, default=10
        Number of random initialisations of the CPD within one start.
    n_init : int, default=1
        Number of starts: decouplings with independent random sampling points
        and CPD initialisations, each followed by the re-optimisation. The
        start with the lowest validation loss (training loss without
        hold-out) is kept; the PNLSS model is fitted once.
    n_jobs : int or None, default=None
        Number of joblib workers for the starts.
    random_state : int, RandomState instance or None, default=None
        Seeds the sampling points and the CPD initialisations.
    n_transient : int, default=0
        Samples per sequence excluded from the cost and the score.
    verbose : int, default=0
        Print the progress of the optimisation.

    Attributes
    ----------
    A_ : ndarray of shape (n_states, n_states)
    B_ : ndarray of shape (n_states, n_inputs)
    C_ : ndarray of shape (n_outputs, n_states)
    D_ : ndarray of shape (n_outputs, n_inputs)
    V_ : ndarray of shape (n_states + n_inputs, rank)
        Input transformation of the branches.
    W_ : ndarray of shape (n_states + n_outputs, rank)
        Output transformation, ``W_x`` stacked over ``W_y``.
    branch_coefficients_ : ndarray of shape (rank, branch_degree - 1)
        ``branch_coefficients_[l, k]`` multiplies ``(v_l^T s)**(k + 2)``.
    x0_ : ndarray of shape (n_states,)
        Initial state (zero unless ``estimate_x0``).
    pnlss_ : PNLSSRegressor
        The fitted PNLSS model that was decoupled.
    decoupling_error_ : float
        Relative error of the decoupled Jacobian tensor in the sampling points
        (of the kept start).
    n_params_ : int
        Number of parameters: ``n^2 + n n_u + n_y n + n_y n_u`` (linear part)
        ``+ (n + n_u) r + (n + n_y) r`` (V, W) ``+ (d - 1) r`` (branches)
        ``+ n`` (x0, when estimated).
    n_iter_ : int
        Number of accepted Levenberg-Marquardt steps.
    loss_history_ : ndarray of shape (n_iter_ + 1,)
        Mean squared simulation error on the fitted rows per iteration;
        ``loss_history_[0]`` is that of the decoupled model (of the kept
        start) before the re-optimisation.
    validation_loss_history_ : ndarray of shape (n_iter_ + 1,) or None
        Mean squared simulation error on the held-out rows per iteration.
    best_iteration_ : int
        Iteration whose parameters were kept.
    n_features_in_ : int
        Number of inputs seen during ``fit``.
    u_offset_, u_scale_ : ndarray of shape (n_inputs,)
        Normalisation of the inputs.
    y_offset_, y_scale_ : ndarray of shape (n_outputs,)
        Normalisation of the outputs.

    See Also
    --------
    PNLSSRegressor : The coupled polynomial model decoupled here.
    sknlss._decouple.decouple_polynomial : The decoupling step alone.

    Notes
    -----
    The paper counts ``(2 n + n_u + n_y + d) r`` nonlinear parameters; here a
    branch has ``d - 1`` coefficients (powers 2 to ``d``: no linear term), so
    ``n_params_`` has ``(2 n + n_u + n_y + d - 1) r`` of them. For the
    Cascaded Tanks model of the paper (``n = 3``, ``n_u = n_y = 1``,
    ``r = 5``, x0 estimated), cubic branches give 16 + 3 + 50 = 69 parameters;
    the paper's 84 is its formula with ``d = 5`` (here reached with
    ``branch_degree=6``). Scaling a branch's input or output direction (with
    the inverse scaling of its coefficients) and similarity transforms of
    the states leave the model unchanged; the re-optimisation discards these
    ``n^2 + 2 r`` directions.

    Examples
    --------
    >>> import numpy as np
    >>> from sknlss import DecoupledPNLSS, PNLSSRegressor
    >>> u = np.random.default_rng(0).normal(size=(300, 1))
    >>> y = np.zeros(300)
    >>> x = 0.0
    >>> for t in range(300):
    ...     y[t] = x + 0.2 * x**2
    ...     x = 0.5 * x + u[t, 0]
    >>> model = DecoupledPNLSS(
    ...     n_states=1, rank=1, pnlss=PNLSSRegressor(degree=2, max_iter=20),
    ...     max_iter=20, random_state=0).fit(u, y)
    >>> bool(model.score(u, y) > 0.99)
    True
    """

    _parameter_constraints: dict = {
        **_BaseStateSpace._parameter_constraints,
        "n_states": [Interval(Integral, 1, None, closed="left")],
        "rank": [Interval(Integral, 1, None, closed="left")],
        "branch_degree": [Interval(Integral, 2, None, closed="left"), None],
        "n_sampling_points": [Interval(Integral, 1, None, closed="left")],
        "sampling": [StrOptions({"normal", "trajectory"})],
        "estimate_x0": ["boolean"],
        "pnlss": [HasMethods(["fit", "get_params"]), None],
        "max_iter": [Interval(Integral, 0, None, closed="left")],
        "tol": [Interval(Real, 0, None, closed="left")],
        "validation_fraction": [Interval(Real, 0, 1, closed="left")],
        "n_iter_no_change": [Interval(Integral, 1, None, closed="left"), None],
        "n_restarts": [Interval(Integral, 1, None, closed="left")],
        "n_init": [Interval(Integral, 1, None, closed="left")],
        "n_jobs": [Integral, None],
        "random_state": ["random_state"],
        "verbose": ["verbose"],
    }

    def __init__(
        self,
        n_states=2,
        *,
        rank=5,
        branch_degree=None,
        n_sampling_points=500,
        sampling="normal",
        estimate_x0=False,
        pnlss=None,
        max_iter=100,
        tol=1e-9,
        validation_fraction=0.0,
        n_iter_no_change=None,
        n_restarts=10,
        n_init=1,
        n_jobs=None,
        random_state=None,
        n_transient=0,
        verbose=0,
    ):
        self.n_states = n_states
        self.rank = rank
        self.branch_degree = branch_degree
        self.n_sampling_points = n_sampling_points
        self.sampling = sampling
        self.estimate_x0 = estimate_x0
        self.pnlss = pnlss
        self.max_iter = max_iter
        self.tol = tol
        self.validation_fraction = validation_fraction
        self.n_iter_no_change = n_iter_no_change
        self.n_restarts = n_restarts
        self.n_init = n_init
        self.n_jobs = n_jobs
        self.random_state = random_state
        self.n_transient = n_transient
        self.verbose = verbose

    # ------------------------------------------------------------------ fit
    def _validate_training_data(self, X, y, sequence_id):
        """Validate and scale the data exactly as the PNLSS model does.

        The decoupled model replaces the PNLSS polynomials in the PNLSS's own
        coordinates, so the PNLSS template decides the normalisation (e.g.
        whether the signals are centred); its fitted attributes are shared.
        """
        from ._pnlss import PNLSSRegressor

        pnlss = clone(self.pnlss if self.pnlss is not None else PNLSSRegressor())
        pnlss.set_params(
            n_states=self.n_states,
            estimate_x0=self.estimate_x0,
            validation_fraction=self.validation_fraction,
            n_transient=self.n_transient,
        )
        U, Y, starts = pnlss._validate_training_data(X, y, sequence_id)
        for name in ("n_features_in_", "feature_names_in_", "n_outputs_", "_y_was_1d",
                     "u_offset_", "u_scale_", "y_offset_", "y_scale_"):
            if hasattr(pnlss, name):
                setattr(self, name, getattr(pnlss, name))
            elif hasattr(self, name):
                delattr(self, name)
        self.pnlss_ = pnlss
        return U, Y, starts

    def _fit_normalized(self, U, Y, starts):
        fit_mask, val_mask = holdout_masks(starts, self.n_transient, self.validation_fraction)
        pnlss = self.pnlss_
        pnlss._fit_normalized(U, Y, starts)
        degree = self.branch_degree
        if degree is None:
            exponents = np.vstack([pnlss.state_exponents_, pnlss.output_exponents_])
            degree = max(2, int(exponents.sum(axis=1).max())) if len(exponents) else 2

        rng = check_random_state(self.random_state)
        seeds = rng.randint(np.iinfo(np.int32).max, size=self.n_init)
        options = dict(
            rank=self.rank, degree=degree, sampling=self.sampling,
            n_sampling_points=self.n_sampling_points, n_restarts=self.n_restarts,
            estimate_x0=bool(self.estimate_x0), max_iter=self.max_iter, tol=self.tol,
            n_iter_no_change=self.n_iter_no_change,
            verbose=self.verbose,
        )
        runs = Parallel(n_jobs=self.n_jobs)(
            delayed(_fit_one_start)(pnlss, U, Y, starts, fit_mask, val_mask, seed,
                                    label=f"DecoupledPNLSS start {i}", **options)
            for i, seed in enumerate(seeds)
        )
        scores = [result.selection_loss for _, _, result, _ in runs]
        matrices, x0, result, self.decoupling_error_ = runs[int(np.argmin(scores))]
        (self.A_, self.B_, self.C_, self.D_, self.V_, self.W_,
         self.branch_coefficients_) = matrices
        self.x0_ = x0
        self.n_params_ = int(result.theta.size)
        self._set_search_result(result)
        return self

    def _simulate_normalized(self, U, starts, x0):
        return simulate_decoupled(
            self.A_, self.B_, self.C_, self.D_, self.V_, self.W_,
            self.branch_coefficients_, U, starts, x0,
        )
