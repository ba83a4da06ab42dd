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
from numbers import Real

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.neural_network import MLPRegressor
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import Interval, StrOptions

from .._core._model import parameter_count
from .._core._optimize import one_blas_thread
from .._core._sequences import every_sequence, part_before_holdout
from .._linear._state_estimation import estimate_states
from .._terms._network import ACTIVATIONS, NetworkTerms
from .._validation import Integers
from ._nonlinear import _BaseNonlinearStateSpace

#: Candidate state-estimation weights tried by ``alpha="auto"``.
ALPHA_GRID = np.logspace(-2, 3, 6)

_MLP_ACTIVATION = {"sigmoid": "logistic", "tanh": "tanh"}
# The networks' static regression uses at most this many samples (drawn at
# random from the estimated states of a longer record).
_MAX_REGRESSION_SAMPLES = 4000


# ------------------------------------------------------ static initialisation
def _fit_networks(states, U, Y, starts, linear, n_neurons, activation, random_state):
    """Fit one network per component of f_NL and g_NL (paper eq. 15-16).

    The targets are the residuals of the linear model on the estimated states:
    ``x(t+1) - A x(t) - B u(t)`` (within each sequence) and
    ``y(t) - C x(t) - D u(t)``.

    Returns the networks' parameter blocks keyed as in
    :class:`~sknlss._terms._network.NetworkTerms`.
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
        if len(target) > _MAX_REGRESSION_SAMPLES:
            # A starting point needs no more: a long record costs minutes of
            # L-BFGS otherwise.
            keep = rng.choice(len(target), _MAX_REGRESSION_SAMPLES, replace=False)
            inputs, target = inputs[keep], target[keep]
        net = MLPRegressor(
            hidden_layer_sizes=(n_neurons,), activation=_MLP_ACTIVATION[activation],
            solver="lbfgs", max_iter=500, random_state=rng.randint(np.iinfo(np.int32).max),
        )
        # Only a starting point: an unconverged fit is as good as any other.
        # These tiny problems run several times faster on one BLAS thread.
        with warnings.catch_warnings(), one_blas_thread():
            warnings.simplefilter("ignore", ConvergenceWarning)
            net.fit(inputs, target)
        W.append(net.coefs_[0].T)
        b.append(net.intercepts_[0])
        v.append(net.coefs_[1][:, 0])
        c.append(net.intercepts_[1][0])
    W, b, v, c = np.vstack(W), np.concatenate(b), np.concatenate(v), np.array(c)
    n_hidden = n_states * n_neurons
    return {"f_W": W[:n_hidden], "f_b": b[:n_hidden], "f_v": v[:n_hidden],
            "f_c": c[:n_states], "g_W": W[n_hidden:], "g_b": b[n_hidden:],
            "g_v": v[n_hidden:], "g_c": c[n_states:]}


def _state_ridge(linear, alpha):
    """A ridge negligible against the normal equations' scale.

    It keeps the state estimate defined when the linear model has states
    that do not reach the output (e.g. a BLA fitted to an unrelated output).
    """
    A, _, C, _ = linear
    return 1e-9 * (np.sum(C**2) + alpha * (1.0 + np.sum(A**2)))


def _linear_start_states(context, alpha):
    """The linear start's blocks keyed by name, its ``(A, B, C, D)`` and the
    states estimated from it on the fitted rows (paper eq. 14).

    The output is taken as it is: the linear start's output offset (held in
    the output biases, with ``estimate_x0``) is not removed first, which
    was tried and not adopted (see the user guide)."""
    values = context["model"].unpack(context["theta"])
    linear = tuple(values[key] for key in "ABCD")
    states = estimate_states(context["U_fit"], context["Y_fit"], context["starts_fit"],
                             *linear, alpha, ridge=_state_ridge(linear, alpha))
    return values, linear, states


def _initial_theta(context, alpha, activation, n_neurons, seed):
    """Parameters of the linear model plus networks fitted on its estimated states.

    The initial states (when estimated) are the estimated first states of
    the fitted sequences. The output networks, fitted to the whole output residual,
    hold its constant in their biases (they are the model's output offset).
    """
    model, U_fit, Y_fit, starts_fit = (context[key] for key in
                                       ("model", "U_fit", "Y_fit", "starts_fit"))
    values, linear, states = _linear_start_states(context, alpha)
    values.update(_fit_networks(states, U_fit, Y_fit, starts_fit, linear, n_neurons,
                                activation, seed))
    if model.estimate_x0:
        values["x0"] = every_sequence(states[starts_fit[:-1]], context["kept_fit"],
                                      model.n_sequences)
    return model.pack(values)


class NLSS2Regressor(_BaseNonlinearStateSpace):
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
        the six values 0.01, 0.1, 1, 10, 100 and 1000 and keeps the value
        whose *initialised* model simulates best on the validation rows (on
        the fitted rows when
        ``validation_fraction=0``). That criterion favours large values, whose
        initial model is close to the linear one; on the Cascaded Tanks data
        the optimised models from ``alpha`` around 0.3 validated better.
    n_neurons : int, default=2
        Hidden units of each network.
    activation : {"sigmoid", "tanh"}, default="sigmoid"
        Activation of the hidden units.
    estimate_x0 : bool, default=False
        Estimate the initial state of every sequence (as in PNLSS-I), and a
        constant output offset with it (the output networks' biases
        hold it). A long ``n_transient`` holds it (see ``n_transient``).
    period : int, default=None
        Number of samples per period of a periodic excitation. When set, every
        sequence must be a whole number of periods, the same number in every
        sequence (the linear start's robust method averages them); each
        sequence is then simulated in steady state by prepending its last
        ``n_transient`` samples (excluded from the cost), in ``fit`` and in
        ``predict`` (for sequences whose input repeats with ``period``, unless
        ``x0`` is passed).
    cost : {"time", "frequency"}, default="time"
        Time-domain simulation error, or its per-period DFT weighted by the
        inverse noise standard deviation (paper eq. 17; needs ``period``).
    stability_penalty : float, default=0.0
        Weight of a penalty on local instability along the fitted trajectory:
        the mean squared excess over 1 of the spectral radius of the state
        map's Jacobian ``A + df_NL/dx`` at every fitted sample, relative to the
        mean squared residual.
    weight_decay : float, default=10.0
        Weight of a penalty on the size of the networks' weights (not their
        biases), added to the sum of squared residuals (normalised units):
        ``sum_k (c_k theta_k)^2``, with ``c_k``
        the RMS of the direct effect of parameter k on the model's equations
        along the trajectory of the starting point, so that it acts on each
        term's contribution whatever the units. Like a prior, it does not grow
        with the record: it restrains the terms on a short record and fades on
        a long one. Its share of the cost grows as the noise falls: lower it
        on long, clean records (see the user guide).
    refine_linear : bool, default=True
        Before estimating the states, refine the linear model by minimising
        its simulation error (with its own initial state, unless held, and
        output offset when ``estimate_x0``), keeping the iterate best on the
        validation rows, unless that would make a stable linear part unstable.
        This makes the initialisation less dependent on the details of the
        frequency-domain BLA.
    bla : BLAEstimator, default=None
        Settings of the linear model used for the initialisation; it is given
        this model's ``n_states``, ``input_delay``, ``estimate_x0`` (a value of
        its own is replaced, with a warning) and (if its own is None)
        ``period``. ``None`` uses
        :class:`BLAEstimator`'s defaults.
    max_iter : int, default=100
        Maximum number of Levenberg-Marquardt iterations of each start.
    tol : float, default=1e-9
        Relative decrease of the cost below which the search stops.
    validation_fraction : float or "auto", default="auto"
        Fraction at the end of every sequence held out to select ``alpha``,
        the iteration and the start. ``0`` selects on the training cost.
        ``"auto"`` gives the starts the shares 0.25, 0.3, 0.35, 0.275 and
        0.325 in turn and ranks them on the end they all held out (no
        hold-out with ``period``, set here or in the ``bla`` template,
        periodic records being fitted in whole periods, nor when every
        sequence is shorter than 100 samples).
    refit : bool, default=True
        After the search, refine the kept start on all the rows, the held-out
        ends included, for up to ``max_iter`` iterations (no effect without
        hold-out). The hold-out still chooses the start and the iterate it
        is refined from; the refinement then uses the information at the
        end of the record. A refinement that fails or leaves the
        boundedness guard is dropped. Decided on the estimation records
        and on simulated systems (see the user guide).
    check_bounded : bool, default=True
        Exclude from the ranking the starts that run away beyond the
        estimation amplitude: whose output leaves ten times the measured range
        on the estimation input enlarged by a fifth, or that diverge on the
        input doubled while a start that does not is nearly as good (see the
        user guide); a refit that leaves the first bound is dropped too.
        ``False`` ranks the starts on the held-out end alone, as the PNLSS
        toolbox does, for a user who judges extrapolation on records of
        their own.
    n_iter_no_change : int, default=None
        Stop a search once the validation loss has not improved for this many
        iterations (early stopping; it has no effect when
        ``validation_fraction=0``). ``None`` iterates until ``max_iter`` or
        ``tol``.
    n_init : int, default=5
        Number of random initialisations of the networks; the start with the
        lowest simulation error on the held-out end is kept, unless the
        linear model does better there (it is then kept instead, see
        ``fell_back_to_linear_``).
    n_jobs : int or None, default=None
        Number of joblib workers for the starts.
    random_state : int, RandomState instance or None, default=None
        Seeds the network initialisations.
    input_delay : int or array-like of int, default=0
        Dead time in samples between each input column and its first effect
        (one value for every column, or one per column), as MATLAB's
        ``InputDelay``: the model is identified on, and simulates, ``u(t - d)``
        (the output can respond at lag ``d`` through the feedthrough), so the
        delay costs no states. ``A_``, ``B_``, ``C_``, ``D_`` are those of the
        delay-free part; ``bla_`` has the same ``input_delay_``. Before the
        start of a sequence the delayed input was not measured: a sequence
        whose input repeats with ``period`` is continued periodically, any
        other takes ``u_offset_``, the training input's mean. Without
        ``estimate_x0`` and ``period``, the cost also skips the largest delay
        (see the user guide).
    n_transient : int, default=0
        Samples per sequence excluded from the cost and the score; with
        ``period``, the number of samples prepended for the steady state
        (every sample of a sequence simulated in steady state then counts, in
        the cost and in the score).
        With ``estimate_x0``, a transient at least as long as the settling time
        of the slowest mode of ``bla_`` that shows in its output (to 1 %)
        leaves the initial state undetermined: the search then holds it at its
        starting value (see the user guide). Without ``estimate_x0`` and
        ``period``, the cost also skips the settling time of the linear
        model's slowest mode that shows in its output (to 1 %, at most a tenth
        of each sequence, with a DataWarning when it is over twice as long).
    verbose : int, default=0
        Print the progress of the optimisation when positive: every iteration
        of every start (where the start runs, a joblib worker with
        ``n_jobs``), then, from the calling process, each start's iterations,
        time, held-out loss and ``start_status_``, and the choice.

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
    x0_ : ndarray of shape (n_states,) or (n_sequences, n_states)
        Initial state (zero unless ``estimate_x0``); with ``estimate_x0``,
        one per sequence when the model was fitted on several: ``predict``
        starts any record from their mean then, unless given ``x0`` (e.g.
        ``x0_`` itself).
    output_offset_ : ndarray of shape (n_outputs,)
        Zero: the biases of the output networks, ``g_output_biases_``, hold
        the constant output offset that the other estimators estimate with
        ``x0_``.
    alpha_ : float
        State-estimation weight used.
    alpha_losses_ : ndarray of shape (6,)
        Selection losses of the six candidates of ``alpha="auto"``, in
        increasing order of ``alpha``.
    states_init_ : ndarray of shape (n_rows_before_holdout, n_states)
        States estimated from the linear model on each sequence up to its
        held-out end (the cost transient included; with
        ``validation_fraction="auto"``, the largest of the starts' shares),
        from which the networks are initialised. ``alpha_``, ``alpha_losses_`` and
        ``states_init_`` belong to the networks' initialisation: they are not
        set when the record is too short for the networks and the linear
        model is kept without any start.
    n_params_ : int
        Number of free parameters: ``(n_states + n_outputs) * (n_states +
        n_inputs + 1 + n_neurons * (n_states + n_inputs + 2))``, plus
        ``n_states`` per sequence with ``estimate_x0``. For ``n_states=3``, one input, one
        output and ``n_neurons=2``: 68, or 71 with the initial state, as the
        paper counts.
    n_iter_ : int
        Iterations of the kept start.
    loss_history_ : ndarray of shape (n_iter_ + 1,)
        Cost per iteration of the kept start: the squared simulation error on
        the fitted rows plus the penalty terms, divided by the number of
        fitted residuals.
    validation_loss_history_ : ndarray of shape (n_iter_ + 1,) or None
        Mean squared simulation error on the held-out rows per iteration
        (``inf`` where the error on the fitted rows exceeds the linear model's).
    best_iteration_ : int
        Iteration of the kept start whose parameters were kept.
    start_losses_ : ndarray of shape (n_init,)
        Mean squared simulation error of every start on the end of the
        sequences that all starts held out (``inf`` for every start whose
        ``start_status_`` is neither ``"kept"`` nor ``"beaten"``, and for a
        beaten one that fits its own rows worse than the linear model).
    start_status_ : ndarray of str of shape (n_init,)
        What became of every start: ``"kept"``; ``"beaten"`` (by another start
        or the linear model on the held-out end, or fits its own rows worse
        than the linear model); ``"unbounded"`` (ran away on the estimation
        input enlarged by a fifth); ``"escapes"`` (diverges on the doubled
        input while a nearly as good start does not); ``"failed"`` (its
        numerics failed); ``"not run"`` (record too short for the terms).
    fell_back_to_linear_ : bool
        True when no start beat the linear model there, or the record is too
        short for the nonlinear terms, or every start that beat it ran away on
        the enlarged input (both with a
        :class:`~sknlss.LinearFallbackWarning`): the linear model is kept (the
        networks' weights are zero; with ``estimate_x0``, the output networks'
        biases hold the BLA's output offset).
    linear_loss_ : float
        Mean squared simulation error of the linear start on that end.
    refit_n_iter_ : int
        Iterations of the refit on all the rows that were kept (0 without one).
    fit_transient_ : int
        Samples left out of the cost at the start of the longest sequences
        (see ``n_transient``): without ``estimate_x0`` and ``period``, the
        larger of ``n_transient`` and the linear model's settling time plus
        the largest ``input_delay``, this at most a tenth of the sequence.
        Every other sequence leaves out ``max(n_transient, min(fit_transient_,
        a tenth of its length))``.
    bla_ : BLAEstimator
        The fitted linear model of the initialisation (fitted on the rows
        before the held-out tails); it predicts and reports its FRF in the
        user's units.
    n_features_in_ : int
        Number of inputs.
    n_outputs_ : int
        Number of outputs.
    input_delay_ : ndarray of shape (n_inputs,), dtype int
        Dead time of each input in samples (``input_delay`` per input column).
    u_offset_, u_scale_, y_offset_, y_scale_ : ndarray
        Normalisation of the signals.

    See Also
    --------
    PNLSSRegressor : Polynomial nonlinearities initialised from the BLA.
    BLAEstimator : The linear model this estimator starts from.

    Notes
    -----
    One network per component (rather than one network per function with
    shared hidden units) gives the paper's count of 71 parameters for the
    Cascaded Tanks model (16 linear, 4 networks of 13 and the initial state).
    With ``estimate_x0``, the output offset that the BLA estimates with the
    initial state is carried by the output networks' biases, which the linear
    model the fit starts from (and may keep) sets to it: a separate offset
    would duplicate them.

    Fitting: the linear estimator is fitted on the rows that are not held
    out (and, with ``refine_linear``, refined in the time domain). Then, for
    each of the ``n_init`` starts, its states are estimated on the same rows
    (paper eq. 14, by a banded least-squares solve);
    every network is fitted to its linear-model residual by
    :class:`~sklearn.neural_network.MLPRegressor` (L-BFGS, a different random
    initialisation per start); with ``estimate_x0``, the initial state of
    every sequence starts at its own first estimated state (zero for a
    sequence with no fitted row) and stays there when a long ``n_transient``
    holds it. Levenberg-Marquardt then minimises the
    simulation error on the fitted rows with the analytic Jacobian; with
    ``validation_fraction``,
    the iterate and the start with the lowest validation error are kept;
    with ``refit``, that iterate is then refined on all the rows.
    Diagonal rescalings of the states leave the output unchanged, so the
    ``n_states`` smallest singular directions of the Jacobian are dropped
    (unless ``weight_decay`` or a held initial state fixes the scale).

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
    >>> u = rng.standard_normal((500, 1))
    >>> x = np.zeros(2)
    >>> y = np.empty(500)
    >>> for t in range(500):
    ...     y[t] = x[0] + 0.3 * np.tanh(2 * x[0])
    ...     x = np.array([0.7 * x[0] + 0.2 * x[1], -0.2 * x[0] + 0.5 * x[1] + u[t, 0]])
    >>> y += 0.01 * rng.standard_normal(500)
    >>> model = NLSS2Regressor(n_states=2, random_state=0).fit(u, y)
    >>> model.n_params_
    42

    The simulation error is well below that of the linear model it started from:

    >>> from sknlss.metrics import nrmse
    >>> bool(nrmse(y, model.predict(u)) < 0.5 * nrmse(y, model.bla_.predict(u)))
    True
    """

    _parameter_constraints: dict = {
        **_BaseNonlinearStateSpace._parameter_constraints,
        "alpha": [Interval(Real, 0, None, closed="neither"), StrOptions({"auto"})],
        "n_neurons": [Integers(1, None, closed="left")],
        "activation": [StrOptions(set(ACTIVATIONS))],
    }

    _label = "NLSS2"
    _structure_params = ("n_states", "n_neurons")

    def __init__(self, n_states=2, *, alpha=0.3, n_neurons=2, activation="sigmoid",
                 estimate_x0=False, period=None, cost="time", stability_penalty=0.0,
                 weight_decay=10.0, refine_linear=True, bla=None, max_iter=100, tol=1e-9,
                 validation_fraction="auto", refit=True, check_bounded=True,
                 n_iter_no_change=None, n_init=5, n_jobs=None, random_state=None,
                 input_delay=0, n_transient=0, verbose=0):
        self.n_states = n_states
        self.alpha = alpha
        self.n_neurons = n_neurons
        self.activation = activation
        self.estimate_x0 = estimate_x0
        self.period = period
        self.cost = cost
        self.stability_penalty = stability_penalty
        self.weight_decay = weight_decay
        self.refine_linear = refine_linear
        self.bla = bla
        self.max_iter = max_iter
        self.tol = tol
        self.validation_fraction = validation_fraction
        self.refit = refit
        self.check_bounded = check_bounded
        self.n_iter_no_change = n_iter_no_change
        self.n_init = n_init
        self.n_jobs = n_jobs
        self.random_state = random_state
        self.input_delay = input_delay
        self.n_transient = n_transient
        self.verbose = verbose

    def _make_terms(self, n_inputs, n_outputs):
        return NetworkTerms(self.n_states, n_inputs, n_outputs, self.n_neurons,
                            self.activation)

    _terms_output_constant = NetworkTerms.output_constant

    def _n_terms_params(self, n_inputs, n_outputs):
        return parameter_count(NetworkTerms.layout(self.n_states, n_inputs, n_outputs,
                                                   self.n_neurons))

    def _n_drop(self, problem):
        # Diagonal rescalings of the states compensated in the networks'
        # weights leave the output unchanged; the weight decay fixes the
        # scale, and so does a held initial state.
        return 0 if self.weight_decay or problem.held.size else problem.model.n_states

    def _prepare_starts(self, context):
        problem, rows = context["problem"], context["rows"]
        fit_mask = rows.fit_rows[rows.original]
        (context["U_fit"], context["Y_fit"], context["starts_fit"],
         context["kept_fit"]) = part_before_holdout(context["U"], context["Y"],
                                                    context["starts"], fit_mask)
        if self.alpha == "auto":
            # The same network seed for every candidate (paper §4.2).
            seed = check_random_state(self.random_state).randint(np.iinfo(np.int32).max)
            self.alpha_losses_ = np.array([
                problem.held_out_loss(_initial_theta(context, alpha, self.activation,
                                                     self.n_neurons, seed))
                for alpha in ALPHA_GRID
            ])
            self.alpha_ = float(ALPHA_GRID[int(np.argmin(self.alpha_losses_))])
        else:
            self.alpha_ = float(self.alpha)
        self.states_init_ = _linear_start_states(context, self.alpha_)[2]

    def _starting_points(self, context, start, seed):
        theta = _initial_theta(context, self.alpha_, self.activation, self.n_neurons, seed)
        # The fitted networks can destabilise the model; without their output
        # weights it is the linear model again, and the search can grow them.
        silent = theta.copy()
        model = context["model"]
        silent[model.columns("f_v", "f_c", "g_v")] = 0.0
        # The output biases keep the linear model's output offset.
        constant = model.columns("g_c")
        silent[constant] = context["theta"][constant]
        return [theta, silent]

    def _set_terms(self, values):
        n_states, nn = self.n_states, self.n_neurons
        for part, n_components in (("f", n_states), ("g", values["g_c"].size)):
            W = values[f"{part}_W"]
            setattr(self, f"{part}_hidden_weights_", W.reshape(n_components, nn, W.shape[1]))
            setattr(self, f"{part}_hidden_biases_", values[f"{part}_b"].reshape(-1, nn))
            setattr(self, f"{part}_output_weights_", values[f"{part}_v"].reshape(-1, nn))
            setattr(self, f"{part}_output_biases_", values[f"{part}_c"].copy())

    def _terms_values(self):
        values = {}
        for part in ("f", "g"):
            W = getattr(self, f"{part}_hidden_weights_")
            values.update({
                f"{part}_W": W.reshape(-1, W.shape[2]),
                f"{part}_b": getattr(self, f"{part}_hidden_biases_"),
                f"{part}_v": getattr(self, f"{part}_output_weights_"),
                f"{part}_c": getattr(self, f"{part}_output_biases_"),
            })
        return values
