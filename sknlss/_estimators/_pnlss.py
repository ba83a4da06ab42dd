"""Polynomial nonlinear state-space (PNLSS) models.

Paper §3.1, §4.1 and §5.1: the linear part is initialised from the Best Linear
Approximation, the polynomial coefficients E and F from zero, and all of them
(optionally with the initial state, PNLSS-I) are refined by Levenberg-Marquardt
on the simulation error, in the time domain or, for periodic data, in the
frequency domain with noise weighting (paper eq. 17).
"""

import numpy as np
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import StrOptions

from .._terms._polynomial import STRUCTURES, PolynomialTerms, monomial_exponents, n_monomials
from .._validation import Integers, naming
from ._nonlinear import _BaseNonlinearStateSpace, ranged_prediction_terms

# Size of the random polynomial coefficients of the starts after the first,
# relative to the RMS of each monomial along the linear model's trajectory: a
# nudge off the linear model that keeps every start close to it.
_START_SCALE = 0.01


class PNLSSRegressor(_BaseNonlinearStateSpace):
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
        Total degrees of the monomials in zeta and eta. The full terms grow
        fast with the order: ``n_zeta = sum_d C(n + n_u + d - 1, d)``
        monomials over the degrees d, each with a coefficient per state and
        output. With one input and output and ``degree=(2, 3)``, that is 30
        monomials and 136 parameters at ``n_states=3``, 833 parameters at 6
        and 1971 at 8, where one iteration on 8192 samples took about 0.8 and
        6.8 s (the factorisations of the Jacobian cost about ``rows * p^2 +
        p^3`` for ``p`` parameters). ``"no_cross_products"`` terms or a
        :class:`DecoupledPNLSS` keep a high order small.
    state_terms : {"full", "states_only", "no_cross_products", "inputs_only", \
            "empty"} or array-like of shape (n_zeta, n_states + n_inputs), \
            default="full"
        Monomials of the state equation: all of them, those in x only, pure
        powers only, those in u only, none (the equation stays linear), or an
        explicit exponent array.
    output_terms : same as ``state_terms``, default="full"
        Monomials of the output equation.
    extrapolation : {"bounded", "continue", "linear"}, default="bounded"
        How the polynomials go on beyond the box that the states and inputs
        filled on the estimation record (``polynomial_input_range_``, each
        variable's range). ``"bounded"``: as themselves out to twice the box
        (each range widened twice about its centre), and beyond it held at
        their value on its edge, so that the prediction of a model whose
        ``A_`` is stable stays bounded for any bounded input, while moderate
        extrapolation keeps the polynomials' curvature. ``"continue"``: as
        themselves everywhere (a polynomial keeps its curvature, which suits
        a hardening law such as a cubic spring, but its powers can carry a
        prediction away). ``"linear"``: along their tangent planes at the
        nearest point of the box, so that where the data did not go the terms
        grow no faster than linearly (for saturation, friction, or a state,
        such as a position, that leaves its range without the law changing).
        The fit is the same whichever is chosen; only predictions beyond the
        box differ. ``fit`` fixes the continuation of the fitted model: a
        change after the fit takes effect at the next one.
    estimate_x0 : bool, default=False
        Estimate the initial state of every sequence (PNLSS-I), and a
        constant output offset with it (``output_offset_``); ``predict``
        then starts from the fitted ``x0_`` (their mean, for several). A
        long ``n_transient`` holds it (see ``n_transient``).
    center : bool, default=True
        Expand the polynomials around the mean of the signals (zero mean, unit
        standard deviation) instead of around the signals' own zero (only
        scaled, as in the PNLSS toolbox, ``center=False``). Centring gives a
        model class (no offset terms) that does not depend on the signals'
        offsets, matches the BLA initialisation to the data's mean level and
        makes a zero initial state the mean operating point, which matters for
        records that do not start at rest; without it, a polynomial system
        whose zero is a rest state is exactly representable.
    refine_linear : bool, default=False
        Before the nonlinear terms are freed, refine A, B, C, D (and x0,
        unless held, and the output offset) on the same cost with E = F = 0,
        unless that would make a stable linear part unstable. This recovers from a poor
        nonparametric BLA (short or noisy records); ``False`` starts the
        nonlinear optimisation from the BLA itself, as in the paper.
    period : int, default=None
        Number of samples per period of a periodic excitation. When set, every
        sequence must be a whole number of periods, the same number in every
        sequence (the linear start's robust method averages them); each
        sequence is then simulated in steady state by prepending its last
        ``n_transient`` samples (excluded from the cost), in ``fit`` and in
        ``predict`` (for sequences whose input repeats with ``period``, unless
        ``x0`` is passed).
    cost : {"time", "frequency"}, default="time"
        Time-domain simulation error, or its per-period DFT at all lines
        weighted by the inverse noise standard deviation (paper eq. 17; needs
        ``period``). The noise variance comes from the variation over the
        periods of each sequence; with one period only the weights are 1.
    stability_penalty : float, default=1.0
        Weight of a penalty on local instability along the fitted trajectory:
        the mean squared excess over 1 of the spectral radius of the state
        map's Jacobian ``A + E dzeta/dx`` at every fitted sample, relative to
        the mean squared residual. Positive values steer the search towards
        models that are locally contracting wherever the data take the states,
        so that they do not blow up on inputs that push the states a little
        beyond the estimation data. 0 (the paper's cost) disables it.
    weight_decay : float, default=10.0
        Weight of a penalty on the size of the polynomial terms (the coefficients of E and F), added to the sum of squared
        residuals (normalised units): ``sum_k (c_k theta_k)^2``, with ``c_k``
        the RMS of the direct effect of parameter k on the model's equations
        along the trajectory of the starting point, so that it acts on each
        term's contribution whatever the units. Like a prior, it does not grow
        with the record: it restrains the terms on a short record and fades on
        a long one. Its share of the cost grows as the noise falls: lower it
        on long, clean records (see the user guide).
    bla : BLAEstimator, default=None
        Settings of the linear model used for the initialisation; it is given
        this model's ``n_states``, ``input_delay``, ``estimate_x0`` (a value of
        its own is replaced, with a warning) and (if its own is None)
        ``period``. ``None`` uses
        :class:`~sknlss.BLAEstimator`'s defaults.
    max_iter : int, default=200
        Maximum number of Levenberg-Marquardt iterations of each start.
    tol : float, default=1e-9
        Relative cost decrease below which the iterations stop.
    validation_fraction : float or "auto", default="auto"
        Fraction at the end of every sequence held out from the cost; the
        iterate with the lowest simulation error there is kept (the held-out
        tail continues the simulation of the fitted part). 0 keeps the last
        iterate. ``"auto"`` gives the starts the shares 0.25, 0.3, 0.35, 0.275
        and 0.325 in turn and ranks them on the end they all held out (no
        hold-out with ``period``, set here or in the ``bla`` template,
        periodic records being fitted in whole periods, nor when every
        sequence is shorter than 100 samples).
    refit : bool, default=False
        After the search, refine the kept start on all the rows, the held-out
        ends included, for up to ``max_iter`` iterations (no effect without
        hold-out); a refinement that fails or leaves the boundedness guard is
        dropped. Off by default: on splits of the Cascaded Tanks estimation record
        it made this model worse on some (see the user guide).
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
        Stop once the validation loss has not improved for this many
        iterations (early stopping; it has no effect when
        ``validation_fraction=0``). ``None`` iterates until ``max_iter`` or
        ``tol``.
    n_init : int, default=5
        Number of starts: the first from the linear model (E = F = 0), the
        others from small random polynomial terms around it; the start with
        the lowest simulation error on the held-out end (training cost
        without hold-out) is kept, unless the linear model does better there:
        it is then kept instead (``fell_back_to_linear_``).
    n_jobs : int, default=None
        Number of joblib workers for the starts.
    random_state : int, RandomState instance or None, default=None
        Seeds the starts after the first.
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
        of the slowest mode of ``bla_`` that shows in its output (to 1 %)
        leaves the initial state undetermined: the search then holds it at its
        starting value (see the user guide). Without ``estimate_x0`` and
        ``period``, the cost also skips the settling time of the linear
        model's slowest mode that shows in its output (to 1 %, at most a tenth
        of each sequence, with a DataWarning when it is over twice as long): a
        record rarely starts at rest.
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
    E_ : ndarray of shape (n_states, n_zeta)
        Coefficients of the state-equation monomials.
    F_ : ndarray of shape (n_outputs, n_eta)
        Coefficients of the output-equation monomials.
    state_exponents_ : ndarray of shape (n_zeta, n_states + n_inputs)
        Exponents of the monomials in zeta.
    output_exponents_ : ndarray of shape (n_eta, n_states + n_inputs)
        Exponents of the monomials in eta.
    polynomial_input_range_ : ndarray of shape (2, n_states + n_inputs)
        Lowest and highest value of each state and input (in the scaled units
        the polynomials see) on the estimation record simulated by the fitted
        model: beyond this box the polynomials go on as ``extrapolation``
        says.
    x0_ : ndarray of shape (n_states,) or (n_sequences, n_states)
        Initial state (zero unless ``estimate_x0``); with ``estimate_x0``,
        one per sequence when the model was fitted on several: ``predict``
        starts any record from their mean then, unless given ``x0`` (e.g.
        ``x0_`` itself).
    output_offset_ : ndarray of shape (n_outputs,)
        Constant output offset estimated with ``x0_`` (normalised units, zero
        unless ``estimate_x0``), as the BLA estimates it; ``fit`` adds it to
        ``y_offset_``.
    n_params_ : int
        Number of free parameters:
        ``n^2 + n n_u + n_y n + n_y n_u + n n_zeta + n_y n_eta``, plus ``n``
        per sequence for x0 with ``estimate_x0`` and ``n_y`` for the output
        offset estimated with it (the paper's table adds one parameter for
        PNLSS-I's initial state; see the user guide).
    n_iter_ : int
        Number of accepted Levenberg-Marquardt steps.
    loss_history_ : ndarray of shape (n_iter_ + 1,)
        Cost per iteration: the squared simulation error on the fitted rows
        (weighted spectra for ``cost="frequency"``) plus the
        ``stability_penalty`` and ``weight_decay`` terms, divided by the
        number of fitted residuals.
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
        The fitted linear model used for the initialisation (fitted on the rows
        before the held-out tails, in this model's state coordinates); it
        predicts and reports its FRF in the user's units.
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

    The simulation error is well below that of the linear model it started from:

    >>> from sknlss.metrics import nrmse
    >>> bool(nrmse(y, model.predict(u)) < 0.7 * nrmse(y, model.bla_.predict(u)))
    True
    """

    _parameter_constraints: dict = {
        **_BaseNonlinearStateSpace._parameter_constraints,
        "degree": [Integers(2, None, closed="left"), "array-like"],
        "state_terms": [StrOptions(set(STRUCTURES)), "array-like"],
        "output_terms": [StrOptions(set(STRUCTURES)), "array-like"],
        "center": ["boolean"],
        "extrapolation": [StrOptions({"bounded", "continue", "linear"})],
    }

    _label = "PNLSS"
    _structure_params = ("n_states", "degree", "state_terms", "output_terms")

    def __init__(
        self,
        n_states=2,
        *,
        degree=(2, 3),
        state_terms="full",
        output_terms="full",
        extrapolation="bounded",
        estimate_x0=False,
        center=True,
        refine_linear=False,
        period=None,
        cost="time",
        stability_penalty=1.0,
        weight_decay=10.0,
        bla=None,
        max_iter=200,
        tol=1e-9,
        validation_fraction="auto",
        refit=False,
        check_bounded=True,
        n_iter_no_change=None,
        n_init=5,
        n_jobs=None,
        random_state=None,
        input_delay=0,
        n_transient=0,
        verbose=0,
    ):
        self.n_states = n_states
        self.degree = degree
        self.state_terms = state_terms
        self.output_terms = output_terms
        self.extrapolation = extrapolation
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
        self.refit = refit
        self.check_bounded = check_bounded
        self.n_iter_no_change = n_iter_no_change
        self.n_init = n_init
        self.n_jobs = n_jobs
        self.random_state = random_state
        self.input_delay = input_delay
        self.n_transient = n_transient
        self.verbose = verbose

    def _centred(self):
        return self.center

    def _make_terms(self, n_inputs, n_outputs):
        n = self.n_states
        self.state_exponents_ = monomial_exponents(n, n_inputs, self.degree, self.state_terms)
        self.output_exponents_ = monomial_exponents(n, n_inputs, self.degree,
                                                    self.output_terms)
        return PolynomialTerms(n, n_outputs, self.state_exponents_, self.output_exponents_)

    def _n_terms_params(self, n_inputs, n_outputs):
        n = self.n_states
        counts = {}
        for name in ("state_terms", "output_terms"):
            structure = getattr(self, name)
            # The degree matters only for the named structures (its errors name it).
            with naming(name if not isinstance(structure, str) else "degree"):
                counts[name] = n_monomials(n, n_inputs, self.degree, structure)
        return n * counts["state_terms"] + n_outputs * counts["output_terms"]

    def _prepare_starts(self, context):
        problem, theta = context["problem"], context["theta"]
        if self.n_init > 1:
            points = np.hstack([problem.simulate(theta)[1], problem.U])[problem.fit_rows]
            context["monomial_rms"] = problem.model.parameter_rms(theta, points)

    def _starting_points(self, context, start, seed):
        theta = context["theta"]
        if start == 0:
            return [theta]
        # Later starts: small random polynomial terms around the linear model,
        # smaller still, then none, if the model cannot be simulated with them.
        columns = context["model"].terms_columns
        rms = np.maximum(context["monomial_rms"], np.finfo(float).tiny)
        noise = check_random_state(seed).standard_normal(columns.size)
        candidates = []
        for scale in (_START_SCALE, 0.1 * _START_SCALE, 0.0):
            candidate = theta.copy()
            candidate[columns] = scale * noise / rms
            candidates.append(candidate)
        return candidates

    def _prediction_terms(self, model, theta, U, starts):
        return ranged_prediction_terms(model, theta, U, starts, self.extrapolation)

    def _set_terms(self, values):
        self.E_, self.F_ = values["E"], values["F"]
        self.polynomial_input_range_ = self._model.terms.input_range

    def _terms_values(self):
        return {"E": self.E_, "F": self.F_}
