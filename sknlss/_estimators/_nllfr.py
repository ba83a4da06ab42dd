"""Nonlinear linear-fractional (NL-LFR) state-space models.

A linear state-space model with a static nonlinearity in feedback:

    x(t+1) = A x + B u + Bw w,   y(t) = C x + D u + Dw w,
    z(t) = Cz x + Dz u,          w_l(t) = f_l(z_l(t)),

each ``f_l`` a combination of the functions of a univariate basis (with a
fitted bias of its input for a shifting basis; branches of one ``tanh`` each
then form a one-hidden-layer network in feedback). The model covers
Wiener-Hammerstein chains and Duffing-type oscillators with a few dozen
parameters, and its nonlinearity is explicit, which makes it extrapolate
better than a full multivariate polynomial.

The initialisation needs no nonlinear search: along the trajectory of the Best
Linear Approximation, the branch inputs ``z`` are fixed (the first branches
along the outputs, the others in random directions, the best of several draws),
and the contribution of ``w = f(z)`` to the output is linear in the products
``[Bw; Dw] c_l^T`` of the output directions and the basis coefficients, each
basis function entering through the linear dynamics. These products follow by
linear least squares, and their best rank-one factors give ``Bw``, ``Dw`` and
the coefficients.
Levenberg-Marquardt then minimises the simulation error over all parameters.
With ``init="inference"``, each start first searches the branch directions
by inference and learning (M. Floren, J.-P. Noël and J. Swevers, "Inference
and learning of nonlinear LFR state-space models", 2025): the branch outputs
are inferred from the linear model's output error per DFT line, so that the
search needs no recursive simulation.
"""

import numpy as np
from scipy.optimize import least_squares
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import StrOptions

from .._core._model import StateSpaceModel, parameter_count
from .._linear._realization import simulate_linear, ss_frf
from .._terms._bases import BasisConstraint, LegendreBasis, PolynomialBasis, check_basis
from .._terms._branches import BranchTerms
from .._validation import Integers
from ._nonlinear import _BaseNonlinearStateSpace, ranged_prediction_terms

#: The bases that ``basis=None`` chooses from, the starts taking them in turn.
#: Decided on the estimation records (Silverbox and Cascaded Tanks, each split
#: into a fitted head and a scored tail) and on fresh draws of the simulated
#: systems: powers are best on the Silverbox and the Duffing oscillator, the
#: bounded Legendre basis on the tanks (overflow), the drive (friction) and
#: the hysteresis; choosing on the held-out loss was never worse there than
#: the powers alone.
_DEFAULT_BASES = (PolynomialBasis(3), LegendreBasis(3))

#: Random branch directions that each start but the first draws, keeping the
#: one whose least-squares start simulates best: a single draw often starts a
#: bounded basis in a poor basin (closed-loop drive), and the screen costs
#: one linear regression and one simulation per draw.
_SCREENED_DIRECTIONS = 20

# Relative ridge of the least squares of the initialisation: it only keeps
# the regression defined when basis functions are nearly collinear.
_RIDGE = 1e-8
#: Inference and learning (``init="inference"``): weight of the penalty on
#: the inferred branch outputs, a floor that keeps it invertible, fixed-point
#: iterations per evaluation, samples used, the search's budget (residual
#: evaluations besides those of its finite-difference Jacobians) and relative
#: tolerance, and the residual given to directions whose fixed point runs
#: away.
_INFERENCE_RIDGE = 1e-2
_INFERENCE_EPS = 1e-8
_FIXED_POINT_ITERATIONS = 10
_INFERENCE_SAMPLES = 8192
_INFERENCE_STEPS = 40
_INFERENCE_TOL = 1e-6
_INFERENCE_PENALTY = 1e3


def _continuation(extrapolation, basis):
    """How branches of ``basis`` go on beyond their estimation range.

    With ``"auto"`` a power series keeps its curvature and a bounded basis
    goes on along its tangent: the basis the held-out end preferred tells a
    hardening law from a saturating one, which the continuation follows.
    Decided on simulated records whose test input leaves the estimation range
    (see the user guide).
    """
    if extrapolation != "auto":
        return extrapolation
    return "linear" if basis.bounded else "continue"


def _branch_inputs(V, S, rows):
    """Branch inputs ``S @ V`` with each direction scaled so that ``|z| <= 1``
    on ``rows``."""
    Z = S @ V
    peak = np.max(np.abs(Z[rows]), axis=0)
    V = V / np.where(peak > 0, peak, 1.0)
    return V, S @ V


def _branch_functions(basis, z, bias=None):
    """The basis functions at the branch inputs ``z`` (their bias included);
    for a shifting basis, less their values at the bias: the branches are
    anchored at zero, as the kernels evaluate them."""
    values = basis.evaluate(z)[0]
    return values if bias is None else values - basis.evaluate(bias)[0]


def _linear_trajectory(problem, theta):
    """States and inputs ``[x, u]`` and outputs of the linear model ``theta``
    (its terms switched off) along the estimation record."""
    Y_lin, X_lin, _ = problem.simulate(theta)
    return np.hstack([X_lin, problem.U]), Y_lin


def _least_squares_terms(problem, theta, V, trajectory, bias=None):
    """Output directions W and basis coefficients for fixed branch directions V.

    Along the linear model's ``trajectory`` (parameters ``theta``), basis
    function ``m`` of branch ``l`` enters state ``i`` through the linear
    dynamics and output ``j`` directly; the output error of the linear model
    is regressed on these responses, and each branch's block of products
    ``W[:, l] c[l]`` is factored by its best rank-one approximation. The
    branch inputs are ``S @ V`` scaled to ``|z| <= 1``, plus ``bias`` for a
    shifting basis.

    Returns the terms' parameter blocks (``V`` scaled, ``W``,
    ``coefficients`` and, when given, ``bias``).
    """
    model = problem.model
    n, n_y = model.n_states, model.n_outputs
    basis = model.terms.basis
    values = model.unpack(theta)
    S, Y_lin = trajectory
    rows = problem.fit_rows
    V, Z = _branch_inputs(V, S, rows)
    terms = {"V": V}
    if bias is not None:
        Z = Z + bias
        terms["bias"] = bias
    rank, n_fun = V.shape[1], basis.n_functions
    x0 = np.zeros(n)
    pulses = StateSpaceModel(n, 1, n_y)
    columns = []
    for l in range(rank):
        phi = _branch_functions(basis, Z[:, l], None if bias is None else bias[l])
        for m in range(n_fun):
            for i in range(n):
                e = np.zeros((n, 1))
                e[i] = 1.0
                theta_i = pulses.pack({"A": values["A"], "B": e, "C": values["C"],
                                       "D": np.zeros((n_y, 1))})
                columns.append(pulses.simulate(theta_i, phi[:, m : m + 1], problem.starts,
                                               x0)[0][rows])
            for j in range(n_y):
                direct = np.zeros((len(phi), n_y))
                direct[:, j] = phi[:, m]
                columns.append(direct[rows])
    regressors = np.stack([c.ravel() for c in columns], axis=1)
    target = (problem.Y - Y_lin)[rows].ravel()
    gram = regressors.T @ regressors
    gram[np.diag_indices_from(gram)] += _RIDGE * np.trace(gram) / len(gram)
    products = np.linalg.solve(gram, regressors.T @ target)
    # products[l, m, k] multiplies W[k, l] c[l, m] (k over states, then outputs).
    products = products.reshape(rank, n_fun, n + n_y)
    W = np.empty((n + n_y, rank))
    coefficients = np.empty((rank, n_fun))
    for l in range(rank):
        left, sigma, right = np.linalg.svd(products[l].T, full_matrices=False)
        W[:, l] = left[:, 0] * np.sqrt(sigma[0])
        coefficients[l] = right[0] * np.sqrt(sigma[0])
    return dict(terms, W=W, coefficients=coefficients)


def _response(A, B, C, D, U, starts):
    """Output of the linear system ``(A, B, C, D)`` driven by ``U`` from rest."""
    return simulate_linear(A, B, C, D, U, starts, np.zeros((len(starts) - 1, A.shape[0])))[0]


def _inferred_branch_outputs(A, C, Bw, Dw, R):
    """The branch outputs that explain the spectrum ``R`` of the linear model's
    output error best, per DFT line, with a Tikhonov penalty on their size
    (weighted by the size of the output directions, so that it does not
    depend on their scale)."""
    r = Bw.shape[1]
    G = ss_frf(A, Bw, C, Dw, np.arange(R.shape[0]) / (2 * (R.shape[0] - 1)))
    GH = np.conj(np.transpose(G, (0, 2, 1)))
    directions = np.vstack([Bw, Dw])
    penalty = _INFERENCE_RIDGE * (directions.T @ directions) + _INFERENCE_EPS * np.eye(r)
    return np.linalg.solve(GH @ G + penalty, GH @ R[:, :, None])[..., 0]


def _inference_and_learning(problem, theta, V, bias, basis, seed):
    """Branch directions and coefficients by inference and learning.

    With the linear part of ``theta`` fixed, each evaluation infers the branch
    outputs ``w`` from the linear model's output error per DFT line (no
    recursive simulation), takes the branch inputs ``z`` along the linear
    trajectory plus the response to ``w``, fits the coefficients of
    ``w ~ f(z)`` by least squares, makes ``z`` and ``f(z)`` consistent by a
    few fixed-point iterations, and returns the output error that ``f(z)``
    leaves. The output directions ``W`` and the input directions ``V``
    minimise it (``scipy.optimize.least_squares``) from the given ``V`` (and
    branch input ``bias``, for a shifting basis; else None) and random ``W``
    drawn from ``seed``. A basis without a degree-1 function gets
    a linear term during the search, moved into the linear part at the end
    (``fold``: ``[A B; C D] += W diag(fold) V^T``).

    The inference treats the first sequence's first ``_INFERENCE_SAMPLES``
    samples as one period: exact for a periodic record in steady state, an
    approximation otherwise, which the following search on the simulation
    error corrects.

    Returns
    -------
    terms : dict
        The terms' parameter blocks ``V``, ``W``, ``coefficients`` (and
        ``bias`` when given).
    fold : ndarray of shape (r,)
        Both None when the search ends where the least squares fail.
    """
    model = problem.model
    n, r = model.n_states, V.shape[1]
    values = model.unpack(theta)
    A, C = values["A"], values["C"]
    Y_lin, X_lin, _ = problem.simulate(theta)
    stop = min(problem.starts[1], problem.starts[0] + _INFERENCE_SAMPLES)
    stop -= (stop - problem.starts[0]) % 2
    window = slice(problem.starts[0], stop)
    rows = np.flatnonzero(problem.fit_rows[window])
    error = (problem.Y - Y_lin)[window]
    S = np.hstack([X_lin, problem.U])[window]
    spectrum = np.fft.rfft(error, axis=0)
    starts = np.array([0, len(error)])
    V, _ = _branch_inputs(V, S, rows)
    linear = 1 not in basis.degrees
    W_size = (n + model.n_outputs) * r
    V_end = W_size + V.size

    def features(z, b):
        phi = _branch_functions(basis, z, b)
        return np.hstack([z[:, None], phi]) if linear else phi

    def branch_outputs(z, b, coefficients):
        return np.column_stack([features(z[:, l], b[l]) @ coefficients[l] for l in range(r)])

    def evaluate(p):
        W = p[: W_size].reshape(n + model.n_outputs, r)
        Vp = p[W_size:V_end].reshape(V.shape)
        b = [None] * r if bias is None else p[V_end:]
        Bw, Dw, Cz = W[:n], W[n:], Vp[:n].T
        w = np.fft.irfft(_inferred_branch_outputs(A, C, Bw, Dw, spectrum), n=len(error), axis=0)
        z_linear = S @ Vp if bias is None else S @ Vp + b
        z = z_linear + _response(A, Bw, Cz, np.zeros((r, r)), w, starts)
        coefficients = [np.linalg.lstsq(features(z[rows, l], b[l]), w[rows, l], rcond=None)[0]
                        for l in range(r)]
        for _ in range(_FIXED_POINT_ITERATIONS):
            w = branch_outputs(z, b, coefficients)
            z = z_linear + _response(A, Bw, Cz, np.zeros((r, r)), w, starts)
        w = branch_outputs(z, b, coefficients)
        residual = (error - _response(A, Bw, C, Dw, w, starts))[rows].ravel()
        terms = {"V": Vp, "W": W, "coefficients": np.array(coefficients)}
        if bias is not None:
            terms["bias"] = b.copy()
        return residual, terms

    def residual(p):
        # Directions whose fixed point runs away are bad directions.
        try:
            e = evaluate(p)[0]
        except np.linalg.LinAlgError:
            return np.full(rows.size * model.n_outputs, _INFERENCE_PENALTY)
        return e if np.all(np.isfinite(e)) else np.full(e.shape, _INFERENCE_PENALTY)

    p0 = np.concatenate([check_random_state(seed).standard_normal(W_size), V.ravel(),
                         [] if bias is None else bias])
    with np.errstate(all="ignore"):
        found = least_squares(residual, p0, x_scale="jac", ftol=_INFERENCE_TOL,
                              max_nfev=_INFERENCE_STEPS)
        try:
            terms = evaluate(found.x)[1]
        except np.linalg.LinAlgError:
            return None, None
    coefficients = terms["coefficients"]
    if linear:
        return dict(terms, coefficients=coefficients[:, 1:]), coefficients[:, 0]
    return terms, np.zeros(r)


class NLLFRRegressor(_BaseNonlinearStateSpace):
    """Nonlinear linear-fractional model: linear dynamics, static nonlinearity in feedback.

    The model is, in normalised signal units,

    .. math::

        x(t+1) &= A x(t) + B u(t) + B_w w(t) \\\\
        y(t)   &= C x(t) + D u(t) + D_w w(t) \\\\
        z(t)   &= C_z x(t) + D_z u(t), \\qquad
        w_l(t) = \\sum_k c_{lk} \\phi_k(z_l(t)),

    with ``n_branches`` branches over a univariate basis :math:`\\phi`. With a
    shifting basis (``shift=True``), each branch input has a fitted bias
    :math:`b_l` and each branch is anchored at zero:
    :math:`w_l = \\sum_k c_{lk} (\\phi_k(z_l + b_l) - \\phi_k(b_l))`, so
    that the zero state stays the model's rest state at the mean input. A, B,
    C, D start from the Best Linear Approximation; the branch inputs start
    along the BLA's outputs (further branches and starts in random
    directions), and the branch outputs and coefficients from a linear
    least-squares fit along the BLA's trajectory. All parameters are then
    refined by Levenberg-Marquardt on the simulation error.

    Parameters
    ----------
    n_states : int, default=2
        Model order n.
    n_branches : int, default=1
        Number of branches r (the size of z and w). A system with several
        static nonlinearities that act independently (one in each channel of
        a multi-output plant, say) needs a branch for each: on a two-input,
        two-output plant with a cubic in each channel, one branch left one
        output near its BLA (normalised RMS error 0.075 against 0.085), and
        two branches fitted both (0.0015 and 0.0019).
    basis : PolynomialBasis, LegendreBasis or ChebyshevBasis, default=None
        Basis of the branch nonlinearities: :class:`~sknlss.PolynomialBasis`
        (powers from 2), :class:`~sknlss.LegendreBasis` or
        :class:`~sknlss.ChebyshevBasis` (bounded, of ``tanh(z)``; with
        ``shift=True``, of ``tanh(z + b)`` with a fitted bias per branch, and
        ``LegendreBasis(1, shift=True)`` makes each branch one ``tanh`` unit:
        ``n_branches`` of them are a small network in feedback); their
        functions are compiled into the kernels, and an object of another
        kind is refused at fit with a TypeError. ``None``
        gives the starts ``PolynomialBasis(3)`` and ``LegendreBasis(3)`` in
        turn, so that the held-out loss chooses between a power series and a
        bounded nonlinearity (with ``n_init=1``, the powers only); see
        ``basis_``.
    extrapolation : {"auto", "linear", "continue"}, default="auto"
        How each branch function goes on beyond the range its input took on
        the estimation record (``branch_input_range_``). ``"linear"``: along
        its tangent at the nearer end of that range, so that where the data
        did not go the branch grows no faster than linearly. ``"continue"``:
        as the basis combination itself (a polynomial keeps its curvature).
        ``"auto"``: a :class:`~sknlss.PolynomialBasis` continues, any other
        basis (the bounded ones) goes on along its tangent. With
        ``basis=None`` the held-out end chooses between the two kinds, and
        with it the continuation: a hardening law (a cubic spring) picks the
        powers, a saturating one the bounded basis (see the user guide). The
        fit is the same whatever the option; only predictions beyond that
        range differ (``extrapolation_``). ``fit`` fixes the continuation of
        the fitted model: a change after the fit takes effect at the next one.
    init : {"trajectory", "inference"}, default="trajectory"
        How each start sets the branches. ``"trajectory"``: the branch inputs
        are fixed along the BLA's trajectory, and the branch outputs and
        coefficients follow by linear least squares. ``"inference"``: inference
        and learning (Floren et al.) first searches the branch directions with
        the linear part fixed, inferring the branch outputs from the output
        error per DFT line (no recursive simulation), on the first 8192
        samples of the first sequence (exact for a periodic record in steady
        state, an approximation otherwise); the trajectory start remains the
        fallback. It costs a few seconds per start, and reaches optima that
        Levenberg-Marquardt approaches slowly from the trajectory start, such
        as those of a bounded basis standing in for a polynomial (see the
        user guide).
    estimate_x0 : bool, default=False
        Estimate the initial state of every sequence, and a constant output
        offset with it (``output_offset_``); ``predict`` then starts from the
        fitted ``x0_`` (their mean, for several). A long ``n_transient``
        holds it (see ``n_transient``).
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
        map's Jacobian at every fitted sample, relative to the mean squared
        residual.
    weight_decay : float, default=0.0
        Weight of a penalty on the size of the branches (Bw, Dw and the
        coefficients), added to the sum of squared residuals (normalised
        units): ``sum_k (c_k theta_k)^2``, with ``c_k``
        the RMS of the direct effect of parameter k on the model's equations
        along the trajectory of the starting point, so that it acts on each
        term's contribution whatever the units. Like a prior, it does not grow
        with the record: it restrains the terms on a short record and fades on
        a long one. Its share of the cost grows as the noise falls: lower it
        on long, clean records (see the user guide).
    refine_linear : bool, default=False
        Refine A, B, C, D (and x0, unless held, and the output offset) on the
        simulation error before the branches are initialised, unless that
        would make a stable linear part unstable.
    bla : BLAEstimator, default=None
        Settings of the linear model used for the initialisation; it is given
        this model's ``n_states``, ``input_delay``, ``estimate_x0`` (a value of
        its own is replaced, with a warning) and (if its own is None)
        ``period``. ``None`` uses
        :class:`~sknlss.BLAEstimator`'s defaults.
    max_iter : int, default=100
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
        Stop a search once the validation loss has not improved for this many
        iterations (no effect without hold-out).
    n_init : int, default=5
        Number of starts: the first of each basis with the branch inputs
        along the BLA's outputs, each other one in the best of 20 random
        directions (by the simulation error of its least-squares start). The
        start with the lowest simulation error on the held-out end is kept,
        unless the linear model
        does better there (it is then kept instead, see
        ``fell_back_to_linear_``).
    n_jobs : int, default=None
        Number of joblib workers for the starts.
    random_state : int, RandomState instance or None, default=None
        Seeds the random branch directions.
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
    Bw_ : ndarray of shape (n_states, n_branches)
        How the branch outputs enter the states.
    Dw_ : ndarray of shape (n_outputs, n_branches)
        How the branch outputs enter the outputs.
    Cz_ : ndarray of shape (n_branches, n_states)
    Dz_ : ndarray of shape (n_branches, n_inputs)
        Branch inputs ``z = Cz x + Dz u``.
    bz_ : ndarray of shape (n_branches,)
        Biases of the branch inputs with a shifting basis (``basis_.shift``):
        branch ``l`` gives ``f_l(z_l + bz_[l]) - f_l(bz_[l])``; zero
        otherwise.
    coefficients_ : ndarray of shape (n_branches, n_basis_functions)
        Basis coefficients of each branch.
    basis_ : basis object
        The basis of the kept model (the chosen one with ``basis=None``).
    branch_input_range_ : ndarray of shape (2, n_branches)
        Lowest and highest value of each branch's argument on the estimation
        record simulated by the fitted model: of ``z_l``, or with a shifting
        basis of ``z_l + bz_[l]`` (the range then includes ``bz_[l]``, the
        branch's anchor). Beyond it the branches go on as ``extrapolation_``
        says.
    extrapolation_ : {"linear", "continue"}
        The continuation of the branches beyond ``branch_input_range_``
        (``extrapolation``, with ``"auto"`` resolved for ``basis_``).
    x0_ : ndarray of shape (n_states,) or (n_sequences, n_states)
        Initial state (zero unless ``estimate_x0``); with ``estimate_x0``,
        one per sequence when the model was fitted on several: ``predict``
        starts any record from their mean then, unless given ``x0`` (e.g.
        ``x0_`` itself).
    output_offset_ : ndarray of shape (n_outputs,)
        Constant output offset estimated with ``x0_`` (normalised units, zero
        unless ``estimate_x0``), as the BLA estimates it; ``fit`` adds it to
        ``y_offset_``.
    bla_ : BLAEstimator
        The fitted linear model of the initialisation; it predicts and
        reports its FRF in the user's units.
    n_params_ : int
        Number of parameters: ``n^2 + n n_u + n_y n + n_y n_u`` (linear part)
        ``+ r (n + n_y) + r (n + n_u) + r n_basis`` (``+ r`` biases with a
        shifting basis; plus ``n + n_y``, x0 and
        the output offset, with ``estimate_x0``; ``n`` per sequence for
        several).
    n_iter_ : int
        Number of accepted Levenberg-Marquardt steps of the kept start.
    loss_history_ : ndarray of shape (n_iter_ + 1,)
        Cost per iteration: the squared simulation error on the fitted rows
        plus the penalty terms, divided by the number of fitted residuals.
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
    DecoupledPNLSS : Branches obtained by decoupling a PNLSS model.
    PNLSSRegressor : Full multivariate polynomial terms.

    References
    ----------
    M. Floren, J.-P. Noël and J. Swevers, "Inference and learning of
    nonlinear LFR state-space models", IEEE Control Systems Letters, 2025.

    L. Van Mulders, J. Schoukens and L. Vanbeylen, "Identification of systems
    with localised nonlinearity: from state-space to block-structured
    models", Automatica 49(5), 2013.

    Examples
    --------
    >>> import numpy as np
    >>> from sknlss import NLLFRRegressor
    >>> rng = np.random.default_rng(0)
    >>> u = 0.3 * rng.standard_normal((500, 1))
    >>> x = np.zeros(2)
    >>> y = np.empty(500)
    >>> for t in range(500):
    ...     y[t] = x[0]
    ...     x = np.array([1.5 * x[0] - 0.7 * x[1] - 0.1 * x[0] ** 3 + u[t, 0], x[0]])
    >>> y += 0.01 * rng.standard_normal(500)
    >>> model = NLLFRRegressor(n_states=2, random_state=0).fit(u, y)
    >>> model.n_params_
    18

    The simulation error is a small part of that of the linear model it
    started from:

    >>> from sknlss.metrics import nrmse
    >>> bool(nrmse(y, model.predict(u)) < 0.2 * nrmse(y, model.bla_.predict(u)))
    True
    """

    _parameter_constraints: dict = {
        **_BaseNonlinearStateSpace._parameter_constraints,
        "n_branches": [Integers(1, None, closed="left")],
        "basis": [BasisConstraint(), None],
        "extrapolation": [StrOptions({"auto", "linear", "continue"})],
        "init": [StrOptions({"trajectory", "inference"})],
    }

    _label = "NL-LFR"
    _structure_params = ("n_states", "n_branches", "basis")

    def __init__(self, n_states=2, *, n_branches=1, basis=None, extrapolation="auto",
                 init="trajectory", estimate_x0=False, period=None, cost="time",
                 stability_penalty=0.0, weight_decay=0.0, refine_linear=False, bla=None,
                 max_iter=100, tol=1e-9, validation_fraction="auto", refit=False,
                 check_bounded=True, n_iter_no_change=None, n_init=5, n_jobs=None,
                 random_state=None, input_delay=0, n_transient=0, verbose=0):
        self.n_states = n_states
        self.n_branches = n_branches
        self.basis = basis
        self.extrapolation = extrapolation
        self.init = init
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

    def _bases(self):
        if self.basis is None:
            return _DEFAULT_BASES
        check_basis(self.basis)
        return (self.basis,)

    def _make_terms(self, n_inputs, n_outputs, basis=None):
        return BranchTerms(self.n_states, n_inputs, n_outputs, self.n_branches,
                           self._bases()[0] if basis is None else basis)

    def _candidate_terms(self, n_inputs, n_outputs):
        return [self._make_terms(n_inputs, n_outputs, basis) for basis in self._bases()]

    def _n_terms_params(self, n_inputs, n_outputs):
        return max(parameter_count(BranchTerms.layout(
            self.n_states, n_inputs, n_outputs, self.n_branches, basis.n_functions,
            basis.shifted)) for basis in self._bases())

    def _prediction_terms(self, model, theta, U, starts):
        return ranged_prediction_terms(model, theta, U, starts,
                                       _continuation(self.extrapolation, model.terms.basis))

    def _n_drop(self, problem):
        # Similarity transforms of the states, the scaling of each branch's
        # output and, for a homogeneous basis, of each branch's input leave the
        # simulated output unchanged.
        per_branch = 2 if problem.model.terms.basis.homogeneous else 1
        return super()._n_drop(problem) + per_branch * self.n_branches

    def _start_terms(self, context, start, seed):
        """Branch directions of a start and its least-squares terms.

        The first start's branch inputs lie along the outputs of the linear
        model, without bias. Each other start takes the best of
        ``_SCREENED_DIRECTIONS`` random directions (and, for a shifting basis,
        biases drawn uniformly in [-1, 1], the range of the scaled branch
        inputs) by the simulation error of its least-squares start.

        Returns the drawn directions, their biases (None without shift) and
        the terms' parameter blocks of the start, V scaled to the range of the
        branch inputs.
        """
        problem, model, theta = context["problem"], context["model"], context["theta"]
        n, n_u, r = model.n_states, model.n_inputs, self.n_branches
        shifted = model.terms.basis.shifted
        values = model.unpack(theta)
        trajectory = _linear_trajectory(problem, theta)
        rng = check_random_state(seed)
        if start == 0:
            directions = rng.standard_normal((n + n_u, r))
            along_outputs = np.hstack([values["C"], values["D"]]).T
            k = min(r, along_outputs.shape[1])
            directions[:, :k] = along_outputs[:, :k]
            bias = np.zeros(r) if shifted else None
            return directions, bias, _least_squares_terms(problem, theta, directions,
                                                          trajectory, bias)
        best, best_loss = None, np.inf
        for _ in range(_SCREENED_DIRECTIONS):
            directions = rng.standard_normal((n + n_u, r))
            bias = rng.uniform(-1.0, 1.0, r) if shifted else None
            terms = _least_squares_terms(problem, theta, directions, trajectory, bias)
            loss = problem.fit_loss(model.pack({**values, **terms}))
            if best is None or loss < best_loss:
                best, best_loss = (directions, bias, terms), loss
        return best

    def _starting_points(self, context, start, seed):
        problem, model = context["problem"], context["model"]
        directions, bias, terms = self._start_terms(context, start, seed)
        values = model.unpack(context["theta"])
        # With weaker feedback the model is closer to the (stable) linear one;
        # without it, it is the linear model itself, a start that cannot fail to
        # simulate, from which the search grows the branches.
        candidates = [model.pack({**values, **terms, "W": factor * terms["W"]})
                      for factor in (1.0, 1e-3, 0.0)]
        if self.init == "trajectory":
            return candidates
        terms, fold = _inference_and_learning(problem, context["theta"], directions, bias,
                                              model.terms.basis, seed)
        if terms is None:
            return candidates
        n = model.n_states
        linear = np.block([[values["A"], values["B"]], [values["C"], values["D"]]])
        linear = linear + (terms["W"] * fold) @ terms["V"].T
        inferred = {**values, **terms, "A": linear[:n, :n], "B": linear[:n, n:],
                    "C": linear[n:, :n], "D": linear[n:, n:]}
        return [model.pack(inferred)] + candidates

    def _set_terms(self, values):
        n = self.n_states
        V, W = values["V"], values["W"]
        self.Cz_, self.Dz_ = V[:n].T.copy(), V[n:].T.copy()
        self.bz_ = values["bias"].copy() if "bias" in values else np.zeros(V.shape[1])
        self.Bw_, self.Dw_ = W[:n].copy(), W[n:].copy()
        self.coefficients_ = values["coefficients"]
        self.basis_ = self._model.terms.basis
        self.branch_input_range_ = self._model.terms.input_range
        self.extrapolation_ = "continue" if self._model.terms.continued else "linear"

    def _terms_values(self):
        values = {"V": np.vstack([self.Cz_.T, self.Dz_.T]), "coefficients": self.coefficients_,
                  "W": np.vstack([self.Bw_, self.Dw_])}
        if self.basis_.shifted:
            values["bias"] = self.bz_
        return values
