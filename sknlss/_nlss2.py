"""Nonlinear state space with neural-network nonlinearities (NLSS2).

The model (paper §3.2, Marconato et al., IEEE TIM 2014) is

    x(t+1) = A x(t) + B u(t) + f_NL(x(t), u(t))
    y(t)   = C x(t) + D u(t) + g_NL(x(t), u(t)),

with every component of ``f_NL`` and ``g_NL`` a one-hidden-layer network. It is
identified in three steps: the states of the Best Linear Approximation are
estimated by regularised least squares (paper eq. 14); the networks are fitted
to the residuals of the linear model by static regression on those states
(paper eq. 15-16); finally all parameters are refined by minimising the
simulation error (paper eq. 18) with Levenberg-Marquardt.
"""

import warnings
from numbers import Integral, Real

import numpy as np
from sklearn.base import clone
from sklearn.exceptions import ConvergenceWarning
from sklearn.neural_network import MLPRegressor
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import HasMethods, Interval, StrOptions
from sklearn.utils.parallel import Parallel, delayed
from threadpoolctl import threadpool_limits

from ._base import _BaseStateSpace, holdout_masks, part_before_holdout
from ._bla import BLAEstimator
from ._nlss2_kernels import ACTIVATIONS, simulate_nlss2, simulate_nlss2_jacobian
from ._optimize import levenberg_marquardt
from ._state_estimation import estimate_states

#: Candidate state-estimation weights tried by ``alpha="auto"``.
ALPHA_GRID = np.logspace(-2, 3, 6)

_MLP_ACTIVATION = {"sigmoid": "logistic", "tanh": "tanh"}


# --------------------------------------------------------------- parameters
def _n_hidden(n_states, n_outputs, n_neurons):
    return (n_states + n_outputs) * n_neurons


def _pack(model):
    """Parameter vector of a model given as a dict of arrays."""
    parts = [model[k].ravel() for k in ("A", "B", "C", "D", "W", "b", "v", "c")]
    if "x0" in model:
        parts.append(model["x0"])
    return np.concatenate(parts)


def _unpack(theta, shapes, estimate_x0):
    """Inverse of :func:`_pack` for the given array shapes (a dict)."""
    model, offset = {}, 0
    for key, shape in shapes.items():
        if key == "x0" and not estimate_x0:
            continue
        size = int(np.prod(shape))
        model[key] = theta[offset : offset + size].reshape(shape)
        offset += size
    return model


def _shapes(n_states, n_inputs, n_outputs, n_neurons):
    n_hidden = _n_hidden(n_states, n_outputs, n_neurons)
    return {
        "A": (n_states, n_states), "B": (n_states, n_inputs),
        "C": (n_outputs, n_states), "D": (n_outputs, n_inputs),
        "W": (n_hidden, n_states + n_inputs), "b": (n_hidden,), "v": (n_hidden,),
        "c": (n_states + n_outputs,), "x0": (n_states,),
    }


def _simulate(model, U, starts, x0, n_neurons, activation):
    return simulate_nlss2(
        U, starts, x0, model["A"], model["B"], model["C"], model["D"], model["W"],
        model["b"], model["v"], model["c"], n_neurons, ACTIVATIONS[activation],
    )


def _broadcast_x0(model, n_sequences):
    return np.ascontiguousarray(
        np.broadcast_to(model["x0"], (n_sequences, model["A"].shape[0]))
    )


# ------------------------------------------------------ static initialisation
def _fit_networks(states, U, Y, starts, linear, n_neurons, activation, random_state):
    """Fit one network per component of f_NL and g_NL (paper eq. 15-16).

    The targets are the residuals of the linear model on the estimated states:
    ``x(t+1) - A x(t) - B u(t)`` (within each sequence) and
    ``y(t) - C x(t) - D u(t)``.

    Returns the stacked ``W, b, v, c`` of :mod:`sknlss._nlss2_kernels`.
    """
    A, B, C, D = linear
    n_states = A.shape[0]
    Z = np.hstack([states, U])
    has_next = np.ones(len(U), dtype=bool)
    has_next[starts[1:] - 1] = False
    state_residual = states[1:] - Z[:-1] @ np.hstack([A, B]).T
    targets = [(Z[has_next], state_residual[has_next[:-1]][:, j]) for j in range(n_states)]
    output_residual = Y - Z @ np.hstack([C, D]).T
    targets += [(Z, output_residual[:, j]) for j in range(Y.shape[1])]

    # The regressors are deliberately not standardised: on the Cascaded Tanks
    # data, networks fitted to standardised states gave starting points from
    # which far fewer simulation-error searches reached a good optimum.
    rng = check_random_state(random_state)
    W, b, v, c = [], [], [], []
    for inputs, target in targets:
        net = MLPRegressor(
            hidden_layer_sizes=(n_neurons,), activation=_MLP_ACTIVATION[activation],
            solver="lbfgs", max_iter=500, random_state=rng.randint(np.iinfo(np.int32).max),
        )
        # Only a starting point: an unconverged fit is as good as any other.
        # These tiny problems run several times faster on one BLAS thread.
        with warnings.catch_warnings(), threadpool_limits(limits=1, user_api="blas"):
            warnings.simplefilter("ignore", ConvergenceWarning)
            net.fit(inputs, target)
        W.append(net.coefs_[0].T)
        b.append(net.intercepts_[0])
        v.append(net.coefs_[1][:, 0])
        c.append(net.intercepts_[1][0])
    return np.vstack(W), np.concatenate(b), np.concatenate(v), np.array(c)


def _state_ridge(linear, alpha):
    """A ridge negligible against the normal equations' scale.

    It keeps the state estimate defined when the linear model has states
    that do not reach the output (e.g. a BLA fitted to an unrelated output).
    """
    A, _, C, _ = linear
    return 1e-9 * (np.sum(C**2) + alpha * (1.0 + np.sum(A**2)))


def _initial_model(U_fit, Y_fit, starts_fit, linear, alpha, n_neurons, activation,
                   random_state):
    """Linear model plus networks fitted on the estimated states.

    The initial state is the mean of the estimated first states of the fitted
    sequences (the model has one initial state shared by all sequences).
    """
    A, B, C, D = linear
    states = estimate_states(U_fit, Y_fit, starts_fit, A, B, C, D, alpha,
                             ridge=_state_ridge(linear, alpha))
    W, b, v, c = _fit_networks(states, U_fit, Y_fit, starts_fit, linear, n_neurons,
                               activation, random_state)
    return {"A": A, "B": B, "C": C, "D": D, "W": W, "b": b, "v": v, "c": c,
            "x0": states[starts_fit[:-1]].mean(axis=0)}


def _simulation_mse(model, U, Y, starts, rows, n_neurons, activation):
    """Mean squared simulation error on ``rows``; ``inf`` when it diverges."""
    Y_sim, _, diverged = _simulate(model, U, starts, _broadcast_x0(model, len(starts) - 1),
                                   n_neurons, activation)
    error = Y_sim[rows] - Y[rows]
    if diverged or not np.all(np.isfinite(error)):
        return np.inf
    return float(np.mean(error**2))


def select_alpha(U, Y, starts, linear, alphas, *, fit_mask, validation_mask=None,
                 n_neurons=2, activation="sigmoid", estimate_x0=False,
                 random_state=None):
    """Choose the state-estimation weight on validation data (paper §4.2).

    For every candidate, the states are estimated on the fitted rows, the
    networks are fitted on them, and the resulting initialised model is
    simulated over the whole sequences. The candidate whose simulation has the
    smallest mean squared error on the validation rows (the fitted rows when
    there are none) wins.

    Parameters
    ----------
    U : ndarray of shape (n_samples, n_inputs)
        Normalised input.
    Y : ndarray of shape (n_samples, n_outputs)
        Normalised output.
    starts : ndarray of shape (n_sequences + 1,)
        Sequence boundaries.
    linear : tuple of ndarray
        ``(A, B, C, D)`` of the linear model.
    alphas : array-like of float
        Candidate weights.
    fit_mask : ndarray of bool of shape (n_samples,)
        Rows the states and networks are fitted on.
    validation_mask : ndarray of bool of shape (n_samples,), default=None
        Rows the candidates are compared on.
    n_neurons : int, default=2
        Hidden units per network.
    activation : {"sigmoid", "tanh"}, default="sigmoid"
        Activation of the hidden units.
    estimate_x0 : bool, default=False
        Start the simulation from the estimated first state instead of zero.
    random_state : int, RandomState instance or None, default=None
        Seed of the network fits (the same for every candidate).

    Returns
    -------
    best_alpha : float
        Selected weight.
    losses : ndarray of shape (n_alphas,)
        Mean squared simulation error of each candidate (``inf`` if divergent).
    """
    rows = validation_mask if validation_mask is not None and validation_mask.any() else fit_mask
    U_fit, Y_fit, starts_fit = part_before_holdout(U, Y, starts, fit_mask)
    seed = check_random_state(random_state).randint(np.iinfo(np.int32).max)
    losses = []
    for alpha in alphas:
        model = _initial_model(U_fit, Y_fit, starts_fit, linear, alpha, n_neurons,
                               activation, seed)
        if not estimate_x0:
            model["x0"] = np.zeros_like(model["x0"])
        losses.append(_simulation_mse(model, U, Y, starts, rows, n_neurons, activation))
    losses = np.asarray(losses)
    return float(alphas[int(np.argmin(losses))]), losses


# --------------------------------------------------------------- optimisation
def _optimise(model, U, Y, starts, fit_mask, validation_mask, *, n_neurons, activation,
              estimate_x0, weight_decay, max_iter, tol, verbose, label,
              n_iter_no_change=None, linear_only=False):
    """Simulation-error minimisation of all parameters (paper eq. 18).

    With ``weight_decay``, the cost also holds ``weight_decay * n_residuals``
    times the squared norm of the networks' weights (not their biases), as
    extra residual rows. With ``linear_only``, the networks stay fixed and only
    A, B, C, D (and x0) move.
    """
    n_states, n_inputs = model["B"].shape
    shapes = _shapes(n_states, n_inputs, model["C"].shape[0], n_neurons)
    n_sequences = len(starts) - 1
    code = ACTIVATIONS[activation]
    fixed_x0 = _broadcast_x0(model, n_sequences)
    Y_fit = Y[fit_mask].ravel()
    offsets = dict(zip(shapes, np.cumsum([0] + [int(np.prod(s)) for s in shapes.values()])))
    theta_full = _pack(model if estimate_x0 else {k: a for k, a in model.items() if k != "x0"})
    if linear_only:
        free = np.r_[0 : offsets["W"], offsets["x0"] : theta_full.size]
    else:
        free = np.arange(theta_full.size)
    decay_rows = np.zeros((0, theta_full.size))
    if weight_decay:
        decayed = np.r_[offsets["W"] : offsets["b"], offsets["v"] : offsets["c"]]
        decay_rows = np.zeros((decayed.size, theta_full.size))
        decay_rows[np.arange(decayed.size), decayed] = np.sqrt(weight_decay * Y_fit.size)
    decay_rows = decay_rows[:, free]

    def current(theta):
        full = theta_full.copy()
        full[free] = theta
        params = _unpack(full, shapes, estimate_x0)
        x0 = _broadcast_x0(params, n_sequences) if estimate_x0 else fixed_x0
        return params, x0

    def residual(theta, jacobian):
        p, x0 = current(theta)
        args = (U, starts, x0, p["A"], p["B"], p["C"], p["D"], p["W"], p["b"], p["v"],
                p["c"], n_neurons, code)
        if jacobian:
            Y_sim, dY, diverged = simulate_nlss2_jacobian(*args, estimate_x0)
        else:
            Y_sim, _, diverged = simulate_nlss2(*args)
        if diverged:
            return None, None
        r = np.concatenate([Y_sim[fit_mask].ravel() - Y_fit, decay_rows @ theta])
        if not jacobian:
            return r, None
        J = dY[fit_mask].reshape(Y_fit.size, theta_full.size)[:, free]
        return r, np.vstack([J, decay_rows])

    def validation_loss(theta):
        p, x0 = current(theta)
        p["x0"] = x0[0]
        return _simulation_mse(p, U, Y, starts, validation_mask, n_neurons, activation)

    # Similarity transforms of the states leave the output of a linear model
    # unchanged (n_states**2 directions); with the networks, only diagonal
    # rescalings compensated in their weights remain (n_states directions), and
    # the weight decay removes those too.
    if linear_only:
        n_drop = n_states**2
    else:
        n_drop = 0 if weight_decay else n_states
    result = levenberg_marquardt(
        residual, theta_full[free],
        validation_loss=validation_loss if validation_mask.any() else None,
        max_iter=max_iter, tol=tol, n_drop=n_drop, n_iter_no_change=n_iter_no_change,
        verbose=verbose, label=label,
    )
    fitted = current(result.theta)[0]
    if not estimate_x0:
        fitted["x0"] = model["x0"]
    return fitted, result


def _refine_linear(linear, U, Y, starts, fit_mask, validation_mask, *, estimate_x0,
                   max_iter, tol, verbose, n_iter_no_change=None):
    """The linear model refined by simulation-error minimisation.

    The same search as the full optimisation with the networks switched off
    (zero output weights), as the PNLSS toolbox refines its BLA in the time
    domain before adding nonlinear terms.
    """
    A, B, C, D = linear
    n_states, n_outputs = A.shape[0], C.shape[0]
    shapes = _shapes(n_states, B.shape[1], n_outputs, 1)
    model = {key: np.zeros(shape) for key, shape in shapes.items()}
    model.update(A=A, B=B, C=C, D=D)
    fitted, _ = _optimise(model, U, Y, starts, fit_mask, validation_mask, n_neurons=1,
                          activation="sigmoid", estimate_x0=estimate_x0, weight_decay=0.0,
                          max_iter=max_iter, tol=tol, n_iter_no_change=n_iter_no_change,
                          verbose=verbose,
                          label="NLSS2 linear", linear_only=True)
    return tuple(fitted[k].copy() for k in "ABCD")


def _fit_one_start(U, Y, starts, fit_mask, validation_mask, linear, alpha, seed, *,
                   n_neurons, activation, estimate_x0, weight_decay, max_iter, tol, verbose,
                   label, n_iter_no_change=None):
    """Initialise from the estimated states with one random seed, then optimise."""
    U_fit, Y_fit, starts_fit = part_before_holdout(U, Y, starts, fit_mask)
    model = _initial_model(U_fit, Y_fit, starts_fit, linear, alpha, n_neurons,
                           activation, seed)
    if not estimate_x0:
        model["x0"] = np.zeros_like(model["x0"])
    if not np.isfinite(_simulation_mse(model, U, Y, starts, fit_mask, n_neurons,
                                       activation)):
        # The fitted networks can destabilise the model; without their output
        # weights it is the linear model again, and the search can grow them.
        model["v"] = np.zeros_like(model["v"])
        model["c"] = np.zeros_like(model["c"])
    return _optimise(model, U, Y, starts, fit_mask, validation_mask, n_neurons=n_neurons,
                     activation=activation, estimate_x0=estimate_x0,
                     weight_decay=weight_decay, max_iter=max_iter, tol=tol,
                     n_iter_no_change=n_iter_no_change, verbose=verbose,
                     label=label)


class NLSS2Regressor(_BaseStateSpace):
    """Nonlinear state-space model with neural-network nonlinearities (NLSS2).

    The model, in normalised signal units, is

    .. math::

        x(t+1) = A x(t) + B u(t) + f_{NL}(x(t), u(t)), \\quad
        y(t) = C x(t) + D u(t) + g_{NL}(x(t), u(t)),

    where each of the ``n_states`` components of :math:`f_{NL}` and the
    ``n_outputs`` components of :math:`g_{NL}` is its own one-hidden-layer
    network of ``n_neurons`` units on :math:`[x; u]`. Fitting follows the
    paper: the states of the Best Linear Approximation are estimated by
    regularised least squares, the networks are fitted to the linear model's
    residuals on those states, and all parameters are then refined by
    minimising the simulation error with Levenberg-Marquardt.

    Parameters
    ----------
    n_states : int, default=2
        Model order.
    alpha : float or "auto", default=0.3
        Weight of the state-equation residuals in the state estimation (the
        paper's lambda), in normalised units. Smaller values let the states
        follow the measured output more closely, so that the networks see
        more of the nonlinearity. ``"auto"`` follows the paper: it tries
        ``ALPHA_GRID`` and keeps the value whose *initialised* model simulates
        best on the validation rows (on the fitted rows when
        ``validation_fraction=0``). That criterion favours large values, whose
        initial model is close to the linear one; on the Cascaded Tanks data
        the optimised models from ``alpha`` around 0.3 validated better.
    n_neurons : int, default=2
        Hidden units of each network.
    activation : {"sigmoid", "tanh"}, default="sigmoid"
        Activation of the hidden units.
    estimate_x0 : bool, default=False
        Estimate the initial state shared by all sequences (as in PNLSS-I).
    weight_decay : float, default=0.0
        Weight of the squared norm of the networks' weights (not their
        biases) added to the simulation-error cost, relative to the mean
        squared residual. It keeps the sigmoids smooth where the data are
        short, so that the model extrapolates more gently.
    refine_linear : bool, default=False
        Before estimating the states, refine the linear model by minimising
        its simulation error (with its own initial state when
        ``estimate_x0``), keeping the iterate best on the validation rows.
        This makes the initialisation less dependent on the details of the
        frequency-domain BLA.
    bla : estimator or None, default=None
        Linear estimator used for the initialisation; ``None`` uses
        :class:`BLAEstimator`. It is cloned and given ``n_states``.
    max_iter : int, default=100
        Maximum number of Levenberg-Marquardt iterations of each start.
    tol : float, default=1e-9
        Relative decrease of the cost below which the search stops.
    validation_fraction : float in [0, 1), default=0.0
        Fraction at the end of every sequence held out to select ``alpha``,
        the iteration and the start. ``0`` selects on the training cost.
    n_iter_no_change : int, default=None
        Stop a search once the validation loss has not improved for this many
        iterations (early stopping; it has no effect when
        ``validation_fraction=0``). ``None`` iterates until ``max_iter`` or
        ``tol``.
    n_init : int, default=1
        Number of random initialisations of the networks, optimised in
        parallel; the best one is kept.
    n_jobs : int or None, default=None
        Number of joblib workers for the starts.
    random_state : int, RandomState instance or None, default=None
        Seeds the network initialisations.
    n_transient : int, default=0
        Samples at the start of every sequence excluded from the cost and
        from ``score``.
    verbose : int, default=0
        Print the progress of the optimisation when positive.

    Attributes
    ----------
    A_ : ndarray of shape (n_states, n_states)
    B_ : ndarray of shape (n_states, n_inputs)
    C_ : ndarray of shape (n_outputs, n_states)
    D_ : ndarray of shape (n_outputs, n_inputs)
        Linear part of the model (normalised units).
    f_hidden_weights_ : ndarray of shape (n_states, n_neurons, n_states + n_inputs)
        Hidden-layer weights of the network of each state component.
    f_hidden_biases_ : ndarray of shape (n_states, n_neurons)
    f_output_weights_ : ndarray of shape (n_states, n_neurons)
    f_output_biases_ : ndarray of shape (n_states,)
    g_hidden_weights_ : ndarray of shape (n_outputs, n_neurons, n_states + n_inputs)
        Hidden-layer weights of the network of each output component.
    g_hidden_biases_ : ndarray of shape (n_outputs, n_neurons)
    g_output_weights_ : ndarray of shape (n_outputs, n_neurons)
    g_output_biases_ : ndarray of shape (n_outputs,)
    x0_ : ndarray of shape (n_states,)
        Initial state (zero unless ``estimate_x0``).
    alpha_ : float
        State-estimation weight used.
    alpha_losses_ : ndarray of shape (len(ALPHA_GRID),)
        Selection losses of the candidates, when ``alpha="auto"``.
    states_init_ : ndarray of shape (n_fitted_rows, n_states)
        States estimated from the linear model on the fitted rows (of the
        kept start's initialisation).
    n_params_ : int
        Number of free parameters: ``(n_states + n_outputs) * (n_states +
        n_inputs + 1 + n_neurons * (n_states + n_inputs + 2))``, plus
        ``n_states`` with ``estimate_x0``. For ``n_states=3``, one input, one
        output and ``n_neurons=2``: 68, or 71 with the initial state (the
        paper's count).
    n_iter_ : int
        Iterations of the kept start.
    loss_history_ : ndarray of shape (n_iter_ + 1,)
        Mean squared training residual per iteration of the kept start.
    validation_loss_history_ : ndarray of shape (n_iter_ + 1,) or None
        Validation loss per iteration, when ``validation_fraction > 0``.
    best_iteration_ : int
        Iteration of the kept start whose parameters were kept.
    linear_estimator_ : estimator
        The fitted linear estimator of the initialisation.
    n_features_in_ : int
        Number of inputs.

    See Also
    --------
    PNLSSRegressor : Polynomial nonlinearities initialised from the BLA.
    BLAEstimator : The linear model this estimator starts from.

    Notes
    -----
    One network per component (rather than one network per function with
    shared hidden units) reproduces the paper's count of 71 parameters for the
    Cascaded Tanks model: 16 linear, 4 networks of 13 and the initial state.

    Fitting: the linear estimator is fitted on the rows that are not held
    out (and, with ``refine_linear``, refined in the time domain). Then, for
    each of the ``n_init`` starts, its states are estimated on the same rows
    (:func:`~sknlss._state_estimation.estimate_states`, paper eq. 14);
    every network is fitted to its linear-model residual by
    :class:`~sklearn.neural_network.MLPRegressor` (L-BFGS, a different random
    initialisation per start); the initial state starts at the estimated
    first state. Levenberg-Marquardt then minimises the simulation error on
    the fitted rows with the analytic Jacobian; with ``validation_fraction``,
    the iterate and the start with the lowest validation error are kept.
    Diagonal rescalings of the states leave the output unchanged, so the
    ``n_states`` smallest singular directions of the Jacobian are dropped
    (unless ``weight_decay`` fixes the scale).

    On the Cascaded Tanks benchmark (``n_states=3``, ``estimate_x0=True``,
    ``validation_fraction=0.3``), the result depends strongly on the linear
    starting point and on the start: use several starts (``n_init``), and
    ``refine_linear`` and a small ``weight_decay`` gave lower validation
    errors there.

    References
    ----------
    A. Marconato, J. Sjöberg, J. A. K. Suykens and J. Schoukens, "Improved
    initialization for nonlinear state-space modeling", IEEE Transactions on
    Instrumentation and Measurement 63(4), 2014.

    M. Relan, K. Tiels, A. Marconato, P. Dreesen and J. Schoukens, "Data
    driven discrete-time parsimonious identification of a nonlinear
    state-space model for a weakly nonlinear system with short data record",
    Mechanical Systems and Signal Processing 104, 2018.

    Examples
    --------
    >>> import numpy as np
    >>> from sknlss import NLSS2Regressor
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal((300, 1))
    >>> x = np.zeros(2)
    >>> y = np.empty(300)
    >>> for t in range(300):
    ...     y[t] = x[0] + 0.1 * np.tanh(2 * x[0])
    ...     x = np.array([0.7 * x[0] + 0.2 * x[1], -0.2 * x[0] + 0.5 * x[1] + u[t, 0]])
    >>> model = NLSS2Regressor(n_states=2, max_iter=30, random_state=0).fit(u, y)
    >>> model.n_params_
    42
    >>> bool(model.score(u, y) > 0.99)
    True
    """

    _parameter_constraints: dict = {
        **_BaseStateSpace._parameter_constraints,
        "n_states": [Interval(Integral, 1, None, closed="left")],
        "alpha": [Interval(Real, 0, None, closed="neither"), StrOptions({"auto"})],
        "n_neurons": [Interval(Integral, 1, None, closed="left")],
        "activation": [StrOptions(set(ACTIVATIONS))],
        "estimate_x0": ["boolean"],
        "weight_decay": [Interval(Real, 0, None, closed="left")],
        "refine_linear": ["boolean"],
        "bla": [HasMethods(["fit"]), None],
        "max_iter": [Interval(Integral, 0, None, closed="left")],
        "tol": [Interval(Real, 0, None, closed="left")],
        "validation_fraction": [Interval(Real, 0, 1, closed="left")],
        "n_iter_no_change": [Interval(Integral, 1, None, closed="left"), None],
        "n_init": [Interval(Integral, 1, None, closed="left")],
        "n_jobs": [Integral, None],
        "random_state": ["random_state"],
        "verbose": ["verbose"],
    }

    def __init__(self, n_states=2, *, alpha=0.3, n_neurons=2, activation="sigmoid",
                 estimate_x0=False, weight_decay=0.0, refine_linear=False, bla=None,
                 max_iter=100, tol=1e-9,
                 validation_fraction=0.0, n_iter_no_change=None, n_init=1, n_jobs=None,
                 random_state=None,
                 n_transient=0, verbose=0):
        self.n_states = n_states
        self.alpha = alpha
        self.n_neurons = n_neurons
        self.activation = activation
        self.estimate_x0 = estimate_x0
        self.weight_decay = weight_decay
        self.refine_linear = refine_linear
        self.bla = bla
        self.max_iter = max_iter
        self.tol = tol
        self.validation_fraction = validation_fraction
        self.n_iter_no_change = n_iter_no_change
        self.n_init = n_init
        self.n_jobs = n_jobs
        self.random_state = random_state
        self.n_transient = n_transient
        self.verbose = verbose

    def _fit_normalized(self, U, Y, starts):
        fit_mask, validation_mask = holdout_masks(starts, self.n_transient,
                                                  self.validation_fraction)
        U_fit, Y_fit, starts_fit = part_before_holdout(U, Y, starts, fit_mask)
        bla = clone(self.bla if self.bla is not None else BLAEstimator())
        bla.set_params(n_states=self.n_states)
        bla._fit_normalized(U_fit, Y_fit, starts_fit)
        self.linear_estimator_ = bla
        linear = tuple(np.array(M, dtype=np.float64) for M in (bla.A_, bla.B_, bla.C_, bla.D_))
        if self.refine_linear:
            linear = _refine_linear(linear, U, Y, starts, fit_mask, validation_mask,
                                    estimate_x0=self.estimate_x0, max_iter=self.max_iter,
                                    tol=self.tol, n_iter_no_change=self.n_iter_no_change,
                                    verbose=self.verbose)

        rng = check_random_state(self.random_state)
        seeds = rng.randint(np.iinfo(np.int32).max, size=self.n_init)
        if self.alpha == "auto":
            self.alpha_, self.alpha_losses_ = select_alpha(
                U, Y, starts, linear, ALPHA_GRID, fit_mask=fit_mask,
                validation_mask=validation_mask, n_neurons=self.n_neurons,
                activation=self.activation, estimate_x0=self.estimate_x0,
                random_state=seeds[0],
            )
        else:
            self.alpha_ = float(self.alpha)

        options = dict(n_neurons=self.n_neurons, activation=self.activation,
                       estimate_x0=self.estimate_x0, weight_decay=self.weight_decay,
                       max_iter=self.max_iter, tol=self.tol,
                       n_iter_no_change=self.n_iter_no_change, verbose=self.verbose)
        runs = Parallel(n_jobs=self.n_jobs)(
            delayed(_fit_one_start)(U, Y, starts, fit_mask, validation_mask, linear,
                                    self.alpha_, seed, label=f"NLSS2 start {i}", **options)
            for i, seed in enumerate(seeds)
        )
        scores = [result.selection_loss for _, result in runs]
        model, result = runs[int(np.argmin(scores))]
        self._set_model(model, Y.shape[1])
        self._set_search_result(result)
        self.n_params_ = (
            sum(model[k].size for k in ("A", "B", "C", "D", "W", "b", "v", "c"))
            + (self.n_states if self.estimate_x0 else 0)
        )
        self.states_init_ = estimate_states(U_fit, Y_fit, starts_fit, *linear, self.alpha_,
                                            ridge=_state_ridge(linear, self.alpha_))
        return self

    def _set_model(self, model, n_outputs):
        n_states = model["A"].shape[0]
        nn = self.n_neurons
        self.A_, self.B_, self.C_, self.D_ = (model[k].copy() for k in "ABCD")
        self.x0_ = np.array(model["x0"], dtype=np.float64)
        W = model["W"].reshape(n_states + n_outputs, nn, -1)
        b = model["b"].reshape(n_states + n_outputs, nn)
        v = model["v"].reshape(n_states + n_outputs, nn)
        self.f_hidden_weights_, self.g_hidden_weights_ = W[:n_states].copy(), W[n_states:].copy()
        self.f_hidden_biases_, self.g_hidden_biases_ = b[:n_states].copy(), b[n_states:].copy()
        self.f_output_weights_, self.g_output_weights_ = v[:n_states].copy(), v[n_states:].copy()
        self.f_output_biases_ = model["c"][:n_states].copy()
        self.g_output_biases_ = model["c"][n_states:].copy()

    def _model(self):
        """Fitted parameters in the stacked layout of the kernels."""
        return {
            "A": self.A_, "B": self.B_, "C": self.C_, "D": self.D_,
            "W": np.ascontiguousarray(np.concatenate(
                [self.f_hidden_weights_, self.g_hidden_weights_]).reshape(
                    -1, self.f_hidden_weights_.shape[2])),
            "b": np.concatenate([self.f_hidden_biases_, self.g_hidden_biases_]).ravel(),
            "v": np.concatenate([self.f_output_weights_, self.g_output_weights_]).ravel(),
            "c": np.concatenate([self.f_output_biases_, self.g_output_biases_]),
        }

    def _simulate_normalized(self, U, starts, x0):
        return _simulate(self._model(), U, starts, x0, self.n_neurons, self.activation)
