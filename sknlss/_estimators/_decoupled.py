"""PNLSS models with decoupled polynomials (paper §6).

The multivariate polynomials ``E zeta`` and ``F eta`` of a fitted PNLSS model
are replaced by ``W g(V^T [x; u])`` with ``r`` univariate branches, computed from
the CPD of their Jacobians (:func:`~sknlss._terms._cpd.decouple_polynomial`); the
decoupled model is then re-optimised on the simulation error.
"""

import warnings

import numpy as np
from sklearn.base import clone
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import StrOptions

from .._core._model import parameter_count
from .._core._multistart import recorded_warnings
from .._core._sequences import undelayed_input
from .._terms._bases import PolynomialBasis
from .._terms._branches import BranchTerms
from .._terms._cpd import decouple_polynomial
from .._validation import Integers
from ..exceptions import DataWarning, warn_at_caller
from ._base import _unfitted_on_error
from ._nonlinear import _BaseNonlinearStateSpace, ranged_prediction_terms
from ._pnlss import PNLSSRegressor

# Factors applied to W when the decoupled initial model diverges on the
# estimation data: the branches are shrunk until the simulation stays bounded
# (the last factor leaves the PNLSS's linear part).
_SHRINK_FACTORS = (1.0, 0.5, 0.25, 0.1, 0.01, 0.0)

# The PNLSS settings that the decoupled model passes on to its PNLSS model.
_FORWARDED = ("n_states", "input_delay", "estimate_x0", "period", "cost",
              "validation_fraction", "check_bounded", "n_transient", "n_jobs",
              "random_state")


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


def _sampling_points(points, sampling, n_points, rng):
    """Sampling points in the region where the PNLSS model operates.

    The PNLSS states are not normalised (they may have large offsets and
    spreads), so the points follow the distribution of the model's own
    simulated ``[x; u]`` on the fitted rows (``points``): the rows themselves
    (``"trajectory"``) or a normal distribution with their mean and
    covariance (``"normal"``).
    """
    points = points[np.all(np.isfinite(points), axis=1)]
    if len(points) < 2:
        return rng.standard_normal((n_points, points.shape[1]))
    if sampling == "normal":
        return rng.multivariate_normal(points.mean(axis=0), np.cov(points, rowvar=False),
                                       size=n_points)
    if len(points) > n_points:
        points = points[rng.choice(len(points), n_points, replace=False)]
    return points


class DecoupledPNLSS(_BaseNonlinearStateSpace):
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
    (:func:`~sknlss.decouple_polynomial`), and finally re-optimises
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
        Number of points in which the Jacobians are evaluated (with
        ``sampling="trajectory"``, at most the number of fitted rows).
    sampling : {"normal", "trajectory"}, default="normal"
        Where the Jacobians are evaluated: normally distributed points (as in
        the paper) with the mean and covariance of the PNLSS model's own
        simulated ``[x; u]`` on the fitted rows, or points drawn from that
        trajectory itself. The PNLSS states are not normalised, so a standard
        normal distribution could miss the region where the model operates.
    extrapolation : {"linear", "continue"}, default="linear"
        How each branch function goes on beyond the range its input took on
        the estimation record (``branch_input_range_``): along its tangent at
        the nearer end of that range, so that where the data did not go the
        branch grows no faster than linearly, or as the basis combination
        itself (a polynomial keeps its curvature). The fit is the same either
        way; only predictions beyond that range differ. ``fit`` fixes the
        continuation of the fitted model: a change after the fit takes effect
        at the next one.
    estimate_x0 : bool, default=False
        Estimate the initial state of every sequence (forwarded to the
        PNLSS model) and a constant output offset with it
        (``output_offset_``); ``predict`` then starts from ``x0_`` (their
        mean, for several). A long ``n_transient`` holds it (see
        ``n_transient``).
    pnlss : PNLSSRegressor, default=None
        Template of the PNLSS model that is decoupled; it receives
        ``n_states``, ``input_delay``, ``estimate_x0``, ``period``, ``cost``,
        ``validation_fraction``, ``check_bounded``, ``n_transient``,
        ``n_jobs`` and ``random_state`` from this estimator, and its
        normalisation of the signals (``center``) is used by the decoupled
        model too. ``None`` uses ``PNLSSRegressor()``. The template's own
        hyperparameters are tunable as ``pnlss__degree`` and so on once a
        template is given (``pnlss=PNLSSRegressor()``): as with scikit-learn's
        meta-estimators, ``None`` has no parameters to set.
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
    stability_penalty : float, default=1.0
        Weight of a penalty on local instability along the fitted trajectory:
        the mean squared excess over 1 of the spectral radius of the state
        map's Jacobian ``A + W_x diag(g'(V^T s)) V_x^T`` at every fitted
        sample, relative to the mean squared residual.
    weight_decay : float, default=10.0
        Weight of a penalty on the size of the branches (their output directions W and coefficients), added to the sum of squared
        residuals (normalised units): ``sum_k (c_k theta_k)^2``, with ``c_k``
        the RMS of the direct effect of parameter k on the model's equations
        along the trajectory of the starting point, so that it acts on each
        term's contribution whatever the units. Like a prior, it does not grow
        with the record: it restrains the terms on a short record and fades on
        a long one. Its share of the cost grows as the noise falls: lower it
        on long, clean records (see the user guide).
    max_iter : int, default=100
        Maximum number of Levenberg-Marquardt iterations of the re-optimisation.
    tol : float, default=1e-9
        Relative cost decrease below which the iterations stop.
    validation_fraction : float or "auto", default="auto"
        Fraction at the end of every sequence held out from the cost; the
        iterate with the lowest simulation error there is kept (the held-out
        tail continues the simulation of the fitted part). 0 keeps the last
        iterate. ``"auto"`` gives the starts the shares 0.25, 0.3, 0.35, 0.275
        and 0.325 in turn and ranks them on the end they all held out (no
        hold-out with ``period``, periodic records being fitted in whole
        periods, nor when every sequence is shorter than 100 samples).
    refit : bool, default=False
        After the search, refine the kept start on all the rows, the held-out
        ends included, for up to ``max_iter`` iterations (no effect without
        hold-out); a refinement that fails or leaves the boundedness guard is
        dropped. Off by default: on splits of the Cascaded Tanks estimation record
        it made this model worse on some (see the user guide).
    check_bounded : bool, default=True
        Exclude from the ranking the starts that run away beyond the
        estimation amplitude (see :class:`~sknlss.PNLSSRegressor`), in this
        model's search and in that of the PNLSS model it starts from, which
        receives it. ``False`` ranks the starts of both on the held-out end
        alone.
    n_iter_no_change : int, default=None
        Stop a search once the validation loss has not improved for this many
        iterations (early stopping; it has no effect when
        ``validation_fraction=0``). ``None`` iterates until ``max_iter`` or
        ``tol``.
    n_restarts : int, default=10
        Number of random initialisations of the CPD within one start.
    n_init : int, default=5
        Number of starts: decouplings with independent random sampling points
        and CPD initialisations, each followed by the re-optimisation; the
        PNLSS model is fitted once. The start with the lowest simulation error
        on the held-out end is kept, unless the BLA (``bla_``, the linear model
        the PNLSS fit started from) does better there (it is then kept
        instead, see ``fell_back_to_linear_``).
    n_jobs : int or None, default=None
        Number of joblib workers for the starts (of the PNLSS model too).
    random_state : int, RandomState instance or None, default=None
        Seeds the sampling points and the CPD initialisations.
    input_delay : int or array-like of int, default=0
        Dead time in samples between each input column and its first effect
        (one value for every column, or one per column), as MATLAB's
        ``InputDelay``: the model is identified on, and simulates, ``u(t - d)``
        (the output can respond at lag ``d`` through the feedthrough), so the
        delay costs no states. ``A_``, ``B_``, ``C_``, ``D_`` are those of the
        delay-free part; ``bla_`` has the same ``input_delay_``. Before the
        start of a sequence the delayed input was not measured: a sequence
        whose input repeats with ``period`` is continued periodically, any
        other takes ``u_offset_`` (the training input's mean; zero with
        ``center=False``). Without ``estimate_x0`` and ``period``, the cost
        also skips the largest delay (see the user guide).
    n_transient : int, default=0
        Samples per sequence excluded from the cost and the score; with
        ``period``, the number of samples prepended for the steady state
        (every sample of a sequence simulated in steady state then counts, in
        the cost and in the score).
        With ``estimate_x0``, a transient at least as long as the settling time
        of the slowest mode of the PNLSS model's linear part that shows in its
        output (to 1 %; never when a mode does not decay) leaves the initial
        state undetermined: the search then holds it at the PNLSS model's
        ``x0_``. Without ``estimate_x0`` and ``period``, the cost also skips
        the settling time of the linear model's slowest mode that shows in its
        output (to 1 %, at most a tenth of each sequence, with a DataWarning
        when it is over twice as long).
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
    V_ : ndarray of shape (n_states + n_inputs, rank)
        Input transformation of the branches.
    W_ : ndarray of shape (n_states + n_outputs, rank)
        Output transformation, ``W_x`` stacked over ``W_y``.
    branch_coefficients_ : ndarray of shape (rank, branch_degree - 1)
        ``branch_coefficients_[l, k]`` multiplies ``(v_l^T s)**(k + 2)``.
    branch_input_range_ : ndarray of shape (2, rank)
        Lowest and highest value of each branch input on the estimation
        record simulated by the fitted model: beyond it the branches go on as
        ``extrapolation_`` says.
    extrapolation_ : {"linear", "continue"}
        The continuation of the branches beyond ``branch_input_range_``: the
        ``extrapolation`` of the fit.
    x0_ : ndarray of shape (n_states,) or (n_sequences, n_states)
        Initial state (zero unless ``estimate_x0``); with ``estimate_x0``,
        one per sequence when the model was fitted on several: ``predict``
        starts any record from their mean then, unless given ``x0`` (e.g.
        ``x0_`` itself).
    output_offset_ : ndarray of shape (n_outputs,)
        Constant output offset estimated with ``x0_`` (normalised units, zero
        unless ``estimate_x0``), as the BLA estimates it; ``fit`` adds it to
        ``y_offset_``.
    pnlss_ : PNLSSRegressor
        The fitted PNLSS model that was decoupled.
    bla_ : BLAEstimator
        The fitted linear model of the PNLSS model's initialisation, which
        the decoupled model must beat on the held-out end; it predicts and
        reports its FRF in the user's units.
    branch_degree_ : int
        Degree of the branches used.
    decoupling_error_ : float
        Relative error of the decoupled Jacobian tensor in the sampling points
        (of the kept start); not set when the linear model is kept
        (``fell_back_to_linear_``), there being no kept start.
    n_params_ : int
        Number of parameters: ``n^2 + n n_u + n_y n + n_y n_u`` (linear part)
        ``+ (n + n_u) r + (n + n_y) r`` (V, W) ``+ (d - 1) r`` (branches)
        ``+ n + n_y`` (x0 and the output offset, with ``estimate_x0``; ``n``
        per sequence for several).
    n_iter_ : int
        Number of accepted Levenberg-Marquardt steps.
    loss_history_ : ndarray of shape (n_iter_ + 1,)
        Cost per iteration: the squared simulation error on the fitted rows
        plus the ``stability_penalty`` and ``weight_decay`` terms, divided by
        the number of fitted residuals; ``loss_history_[0]`` is that of the
        decoupled model (of the kept start) before the re-optimisation.
    validation_loss_history_ : ndarray of shape (n_iter_ + 1,) or None
        Mean squared simulation error on the held-out rows per iteration
        (``inf`` where the error on the fitted rows exceeds the linear model's).
    best_iteration_ : int
        Iteration whose parameters were kept.
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
        :class:`~sknlss.LinearFallbackWarning`): the linear model is kept (its
        nonlinear terms are zero).
    linear_loss_ : float
        Mean squared simulation error of the BLA on that end.
    refit_n_iter_ : int
        Iterations of the refit on all the rows that were kept (0 without one).
    fit_transient_ : int
        Samples left out of the cost at the start of the longest sequences
        (see ``n_transient``): without ``estimate_x0`` and ``period``, the
        larger of ``n_transient`` and the linear model's settling time plus
        the largest ``input_delay``, this at most a tenth of the sequence.
        Every other sequence leaves out ``max(n_transient, min(fit_transient_,
        a tenth of its length))``.
    n_features_in_ : int
        Number of inputs seen during ``fit``.
    n_outputs_ : int
        Number of outputs.
    input_delay_ : ndarray of shape (n_inputs,), dtype int
        Dead time of each input in samples (``input_delay`` per input column).
    u_offset_, u_scale_ : ndarray of shape (n_inputs,)
        Normalisation of the inputs.
    y_offset_, y_scale_ : ndarray of shape (n_outputs,)
        Normalisation of the outputs.

    See Also
    --------
    PNLSSRegressor : The coupled polynomial model decoupled here.
    decouple_polynomial : The decoupling step alone.

    Notes
    -----
    The paper counts ``(2 n + n_u + n_y + d) r`` nonlinear parameters; here a
    branch has ``d - 1`` coefficients (powers 2 to ``d``: no linear term), so
    ``n_params_`` has ``(2 n + n_u + n_y + d - 1) r`` of them. For the
    Cascaded Tanks model of the paper (``n = 3``, ``n_u = n_y = 1``,
    ``r = 5``, x0 estimated), cubic branches give 16 + 3 + 1 + 50 = 70
    parameters (the linear part, x0, the output offset estimated with it and
    the branches); the paper's 84 is its formula with ``d = 5`` (its 65
    nonlinear parameters are reached with ``branch_degree=6``, 85 in all).
    Scaling a branch's input or output direction (with the inverse scaling
    of its coefficients) and similarity transforms of
    the states leave the model unchanged; the re-optimisation discards these
    ``n^2 + 2 r`` directions (``n^2 - n + 2 r`` when a long ``n_transient``
    holds the initial state: only the similarity transforms that keep it).

    Examples
    --------
    >>> import numpy as np
    >>> from sknlss import DecoupledPNLSS, PNLSSRegressor
    >>> u = np.random.default_rng(0).normal(size=(300, 1))
    >>> y = np.zeros(300)
    >>> x = 0.0
    >>> for t in range(300):
    ...     y[t] = x + 0.1 * x**3
    ...     x = 0.5 * x + u[t, 0]
    >>> model = DecoupledPNLSS(
    ...     n_states=1, rank=1, pnlss=PNLSSRegressor(degree=3, max_iter=20),
    ...     max_iter=20, random_state=0).fit(u, y)

    The simulation error is a small part of that of the linear model it
    started from:

    >>> from sknlss.metrics import nrmse
    >>> bool(nrmse(y, model.predict(u)) < 0.2 * nrmse(y, model.bla_.predict(u)))
    True
    """

    _parameter_constraints: dict = {
        **{key: value for key, value in _BaseNonlinearStateSpace._parameter_constraints.items()
           if key not in ("bla", "refine_linear")},
        "rank": [Integers(1, None, closed="left")],
        "branch_degree": [Integers(2, None, closed="left"), None],
        "n_sampling_points": [Integers(1, None, closed="left")],
        "sampling": [StrOptions({"normal", "trajectory"})],
        "pnlss": [PNLSSRegressor, None],
        "n_restarts": [Integers(1, None, closed="left")],
        "extrapolation": [StrOptions({"linear", "continue"})],
    }

    _label = "DecoupledPNLSS"
    _structure_params = ("n_states", "rank", "branch_degree")

    def __init__(
        self,
        n_states=2,
        *,
        rank=5,
        branch_degree=None,
        n_sampling_points=500,
        sampling="normal",
        extrapolation="linear",
        estimate_x0=False,
        pnlss=None,
        period=None,
        cost="time",
        stability_penalty=1.0,
        weight_decay=10.0,
        max_iter=100,
        tol=1e-9,
        validation_fraction="auto",
        refit=False,
        check_bounded=True,
        n_iter_no_change=None,
        n_restarts=10,
        n_init=5,
        n_jobs=None,
        random_state=None,
        input_delay=0,
        n_transient=0,
        verbose=0,
    ):
        self.n_states = n_states
        self.rank = rank
        self.branch_degree = branch_degree
        self.n_sampling_points = n_sampling_points
        self.sampling = sampling
        self.extrapolation = extrapolation
        self.estimate_x0 = estimate_x0
        self.pnlss = pnlss
        self.period = period
        self.cost = cost
        self.stability_penalty = stability_penalty
        self.weight_decay = weight_decay
        self.max_iter = max_iter
        self.tol = tol
        self.validation_fraction = validation_fraction
        self.refit = refit
        self.check_bounded = check_bounded
        self.n_iter_no_change = n_iter_no_change
        self.n_restarts = n_restarts
        self.n_init = n_init
        self.n_jobs = n_jobs
        self.random_state = random_state
        self.input_delay = input_delay
        self.n_transient = n_transient
        self.verbose = verbose

    @_unfitted_on_error
    def fit(self, X, y, *, sequence_id=None):
        """Fit the PNLSS model, decouple it and re-optimise the decoupled model.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs)
            Input signal u; rows are time samples.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs)
            Measured output signal.
        sequence_id : array-like of shape (n_samples,), default=None
            Label (an integer or a string) of the experiment each row belongs
            to; each label occupies one contiguous block of rows.

        Returns
        -------
        self : object
            The fitted estimator.
        """
        self._validate_params()
        # Bad data, or a transient that leaves nothing to fit, is reported in
        # this estimator's name, not its template's.
        starts = self._validate_training_data(X, y, sequence_id)[2]
        self._check_transient(starts, self._validation_shares(starts))
        # Before the PNLSS fit, with the degree its settings give (monomials
        # listed explicitly are checked once it is fitted).
        self._check_sampling_points(self.branch_degree if self.branch_degree is not None
                                    else max(2, int(np.max(self._template().degree))))
        pnlss = clone(self._template())
        pnlss.set_params(**{name: getattr(self, name) for name in _FORWARDED})
        with recorded_warnings() as caught:
            self.pnlss_ = pnlss.fit(X, y, sequence_id=sequence_id)
        for message, category in caught:
            # The PNLSS model is the starting point of the decoupling, which is
            # optimised again: whether its own iterations had settled is not
            # the result (the final optimisation warns for itself), and its
            # data are this estimator's, which checks them itself. What else
            # it says concerns this estimator's user, in its name.
            if not issubclass(category, (ConvergenceWarning, DataWarning)):
                warn_at_caller(f"{type(self).__name__}: the PNLSS model it starts from: "
                               f"{message}", category)
        return self._fit(X, y, sequence_id)

    def _template(self):
        return self.pnlss if self.pnlss is not None else PNLSSRegressor()

    def _centred(self):
        # The decoupled model replaces the PNLSS polynomials in the PNLSS's own
        # coordinates: those of the template, of which pnlss_ is a clone (and
        # which the data validation before the PNLSS fit can already read).
        return self._template().get_params()["center"]

    def _branch_degree(self):
        if self.branch_degree is not None:
            return self.branch_degree
        pnlss = self.pnlss_
        exponents = np.vstack([pnlss.state_exponents_, pnlss.output_exponents_])
        return max(2, int(exponents.sum(axis=1).max())) if len(exponents) else 2

    def _check_sampling_points(self, degree):
        if self.n_sampling_points < degree:
            raise ValueError(
                f"{type(self).__name__}: n_sampling_points={self.n_sampling_points} cannot "
                f"determine branches of degree {degree}; use at least {degree}.")

    def _make_terms(self, n_inputs, n_outputs):
        self.branch_degree_ = self._branch_degree()
        self._check_sampling_points(self.branch_degree_)
        return BranchTerms(self.n_states, n_inputs, n_outputs, self.rank,
                           PolynomialBasis(self.branch_degree_))

    def _n_terms_params(self, n_inputs, n_outputs):
        n_functions = PolynomialBasis(self._branch_degree()).n_functions
        return parameter_count(BranchTerms.layout(self.n_states, n_inputs, n_outputs,
                                                  self.rank, n_functions))

    def _prediction_terms(self, model, theta, U, starts):
        return ranged_prediction_terms(model, theta, U, starts, self.extrapolation)

    def _n_drop(self, problem):
        # Similarity transforms of the states and the scaling of each branch's
        # input and output leave the simulated output unchanged.
        return super()._n_drop(problem) + 2 * self.rank

    def _linear_start(self, U, Y, starts, fit_mask):
        pnlss = self.pnlss_
        self.bla_ = pnlss.bla_
        return {"A": pnlss.A_, "B": pnlss.B_, "C": pnlss.C_, "D": pnlss.D_, "x0": pnlss.x0_,
                "y0": pnlss.output_offset_}

    def _linear_model(self, model, theta):
        # The starts begin at the PNLSS model's linear part, whose polynomials
        # are written in its states; without them that linear part need not
        # even be stable. The model to beat is the BLA the PNLSS started from.
        bla = self.bla_
        return model.pack_linear({"A": bla.A_, "B": bla.B_, "C": bla.C_, "D": bla.D_,
                                  "x0": bla.x0_, "y0": bla.output_offset_})

    def _prepare_starts(self, context):
        pnlss, starts, rows = self.pnlss_, context["starts"], context["rows"]
        # The PNLSS model delays its input itself: it is given the user's input.
        X = (undelayed_input(context["U"], starts, self.input_delay_) * self.u_scale_
             + self.u_offset_)
        sequence_id = np.repeat(np.arange(len(starts) - 1), np.diff(starts))
        with warnings.catch_warnings():
            # The rows are the user's, rebuilt as an array: a PNLSS model
            # fitted on a DataFrame would warn about their missing column names.
            warnings.filterwarnings("ignore", message="X does not have valid feature names",
                                    category=UserWarning)
            states = pnlss.simulate(X, sequence_id=sequence_id, return_states=True)[1]
        context["points"] = np.hstack([states, context["U"]])[rows.fit_rows[rows.original]]
        context["polynomial"] = _stack_polynomials(pnlss.E_, pnlss.state_exponents_,
                                                   pnlss.F_, pnlss.output_exponents_)

    def _refined_linear_start(self, problem, theta):
        # The PNLSS model's own settings decide how its linear part is refined.
        return theta

    def _decoupling(self, context, seed):
        """The PNLSS polynomials decoupled with one random draw of the sampling
        points and CPD initialisations: ``V, W, c`` and the decoupling error,
        kept by seed (the kept start's error is recorded after the search)."""
        found = context.setdefault("decouplings", {})
        if seed not in found:
            found[seed] = self._decouple(context, seed)
        return found[seed]

    def _decouple(self, context, seed):
        rng = check_random_state(seed)
        model = context["model"]
        n, n_u, n_y = model.n_states, model.n_inputs, model.n_outputs
        coefficients, exponents = context["polynomial"]
        if not len(exponents):
            # A PNLSS without monomials: zero branches in random directions.
            V, W = rng.standard_normal((n + n_u, self.rank)), np.zeros((n + n_y, self.rank))
            return V, W, np.zeros((self.rank, self.branch_degree_ - 1)), 0.0
        return decouple_polynomial(
            coefficients, exponents, self.rank, degree=self.branch_degree_,
            sampling_points=_sampling_points(context["points"], self.sampling,
                                             self.n_sampling_points, rng),
            n_restarts=self.n_restarts, random_state=rng,
        )

    def _record_start(self, context, start, seed):
        self.decoupling_error_ = self._decoupling(context, seed)[3]

    def _starting_points(self, context, start, seed):
        """The decoupled PNLSS, then with its branches shrunk towards the PNLSS's
        linear part, and finally a static model (A = B = C = 0), which cannot
        diverge."""
        model = context["model"]
        V, W, c, _ = self._decoupling(context, seed)
        values = model.unpack(context["theta"])
        values.update(V=V, coefficients=c)
        for factor in _SHRINK_FACTORS:
            yield model.pack(dict(values, W=factor * W))
        static = {key: np.zeros_like(values[key]) for key in "ABC"}
        yield model.pack(dict(values, W=0 * W, **static))

    def _set_terms(self, values):
        self.V_, self.W_ = values["V"], values["W"]
        self.branch_coefficients_ = values["coefficients"]
        self.branch_input_range_ = self._model.terms.input_range
        self.extrapolation_ = "continue" if self._model.terms.continued else "linear"

    def _terms_values(self):
        return {"V": self.V_, "coefficients": self.branch_coefficients_, "W": self.W_}
