"""Best Linear Approximation: nonparametric FRF, then a balanced state-space model.

:func:`fit_linear_model` does the work on normalised signals and returns a
:class:`LinearFit`; :class:`BLAEstimator` wraps it, and the nonlinear
estimators call it for their initialisation and expose the result as a fitted
:class:`BLAEstimator` in the user's units (:func:`fitted_bla`).
"""

import warnings
from dataclasses import dataclass, replace
from numbers import Real

import numpy as np
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted

from .._core._model import StateSpaceModel, parameter_count
from .._core._optimize import one_blas_thread
from .._core._sequences import delayed_input, transient_mask
from .._linear._frf import (
    EXCITATION_THRESHOLD,
    LPM_POWER_THRESHOLD,
    lpm_estimate,
    lpm_records,
    robust_frf,
)
from .._linear._realization import (
    balanced_realization,
    estimate_initial_state,
    frf_subspace,
    n_block_rows,
    refine_frf,
    simulate_linear,
    spectral_radius,
    ss_frf,
)
from .._validation import Integers, explained
from ..exceptions import warn_at_caller
from ..metrics import nrmse
from ._base import _BaseStateSpace, normalisation_of

# Variances below this fraction of the mean squared FRF magnitude (a relative
# standard deviation of 1e-6) are treated as this floor, so that noise-free
# lines do not receive unbounded weights.
_RELATIVE_VARIANCE_FLOOR = 1e-12
# The signals are normalised to unit variance: a variance below the squared
# machine precision is rounding, not noise. Without this floor, a record with
# (nearly) no linear response gives weights beyond 1e150 whose squares overflow.
_ABSOLUTE_VARIANCE_FLOOR = np.finfo(float).eps ** 2
# Normalised RMS error of a simulation as poor as the output's mean.
_MEAN_LEVEL = 1.0
# Samples of the shortest record that has a frequency bin below Nyquist.
_LPM_MIN_SAMPLES = 3
# Relative window power of the LPM's second model (see _fit_linear_model).
_STRICT_POWER_THRESHOLD = 1e-2
# A linear model fitted without input_delay whose simulation leaves more than
# this normalised RMS error is tried on the input delayed by up to
# _MAX_CHECKED_DELAY samples (and a tenth of the shortest sequence); a delay
# that brings the error down to _DELAY_GAIN times it is named in a warning.
# The linear models of the benchmarks stay at 0.31 or below; a plant whose
# dead time is left to two states gives about 1.
_DEAD_TIME_LEVEL = 0.5
_DELAY_GAIN = 0.5
_MAX_CHECKED_DELAY = 20
# Delays whose errors are within this factor of the best are named beside it.
_DELAY_TIE = 1.05


def _weights(estimate, weighting):
    """Inverse standard deviation of each FRF sample, or ones; zero for the
    samples not estimated."""
    if weighting == "noise":
        var = estimate.noise_variance
        var = estimate.total_variance if var is None else var
    elif weighting == "total":
        var = estimate.total_variance
        if var is None or (estimate.total_variance_dof == 1
                           and estimate.noise_variance is not None):
            # From two groups of realizations the total variance has one
            # degree of freedom: its inverse, of infinite mean, would weight
            # the lines at random.
            var = estimate.noise_variance
    else:
        var = None
    estimated = estimate.estimated
    if var is None:
        return np.ones(estimate.frf.shape) if estimated is None else estimated * 1.0
    frf = estimate.frf if estimated is None else estimate.frf[estimated]
    floor = max(_RELATIVE_VARIANCE_FLOOR * np.mean(np.abs(frf) ** 2), _ABSOLUTE_VARIANCE_FLOOR)
    weight = 1.0 / np.sqrt(np.maximum(var, floor))
    return weight if estimated is None else np.where(estimated, weight, 0.0)


@dataclass
class LinearFit:
    """A linear model fitted by :func:`fit_linear_model`, in normalised units.

    Attributes
    ----------
    A, B, C, D : ndarray
        Balanced realization.
    x0 : ndarray of shape (n_states,) or (n_sequences, n_states)
        Initial state (zero unless estimated), one per sequence for several.
    output_offset : ndarray of shape (n_outputs,)
        Output offset estimated with ``x0`` (zero unless estimated).
    hankel_singular_values : ndarray or None
    frequencies, frf, noise_variance, total_variance, frf_model
        The nonparametric estimate and the model's FRF at its frequencies.
    n_iter : int
    loss_history : ndarray or None
    simulation_error : float
        Largest normalised RMS error over the outputs of the model's
        simulation of its estimation rows, from the least-squares initial
        state shared by all sequences (inf for a diverging simulation); above ``_MEAN_LEVEL`` the
        model is worse than the output's mean.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    x0: np.ndarray
    output_offset: np.ndarray
    hankel_singular_values: np.ndarray | None
    frequencies: np.ndarray
    frf: np.ndarray
    noise_variance: np.ndarray | None
    total_variance: np.ndarray | None
    frf_model: np.ndarray
    n_iter: int
    loss_history: np.ndarray | None
    simulation_error: float


def _span(starts, k, first_rows=None):
    """The rows of sequence ``k``, for messages: in the user's ``X`` when
    ``first_rows`` gives the row of ``X`` at which every sequence starts."""
    begin = starts[k] if first_rows is None else first_rows[k]
    return f"{begin} to {begin + starts[k + 1] - starts[k] - 1}"


def _rows(starts, k, first_rows=None):
    """How an error names sequence ``k`` (see :func:`_span`)."""
    if len(starts) == 2 and first_rows is None:
        return "The record (X, y)"
    return f"The sequence of rows {_span(starts, k, first_rows)} (sequence_id)"


def _frf_method(params):
    if params["method"] == "auto":
        return "lpm" if params["period"] is None else "robust"
    return params["method"]


def _nonparametric(U, Y, starts, params, first_rows=None):
    """The nonparametric estimates to fit: the robust method's, or the LPM's
    on the bins whose window holds at least 1e-3 and 1e-2 of the largest
    window's input power (see :func:`_fit_linear_model`); ``first_rows`` as
    in :func:`_span`."""
    period, n_transient = params["period"], params["n_transient"]
    if _frf_method(params) == "robust":
        if period is None:
            raise ValueError('method="robust" needs the `period` of the excitation.')
        return [robust_frf(U, Y, starts, period, n_transient=n_transient,
                           max_frequency=params["max_frequency"])]
    lengths = np.diff(starts)
    if lengths.min() - n_transient < _LPM_MIN_SAMPLES:
        k = int(np.argmin(lengths))
        raise ValueError(
            f"{_rows(starts, k, first_rows)} has {lengths[k]} sample(s), "
            f"{max(lengths[k] - n_transient, 0)} after n_transient={n_transient}: the "
            f"Local Polynomial Method needs at least {_LPM_MIN_SAMPLES} per sequence (one "
            "frequency bin). Lower n_transient or leave that sequence out."
        )
    records = lpm_records(U, Y, starts, order=params["lpm_order"],
                          bandwidth=params["lpm_bandwidth"], n_transient=n_transient,
                          max_frequency=params["max_frequency"])
    without_variance = [k for k, record in enumerate(records) if record[2] is None]
    if 0 < len(without_variance) < len(records):
        # An estimate whose variance is unknown cannot be weighted against the
        # others; unweighted, its few bins would decide the fit.
        rows = ", ".join(_span(starts, k, first_rows) for k in without_variance)
        warn_at_caller(
            f"{len(without_variance)} sequence(s) too short for a variance estimate of "
            f"the Local Polynomial Method (sequence_id; rows {rows}) are left out of the "
            "nonparametric FRF.", UserWarning)
        records = [record for k, record in enumerate(records) if k not in without_variance]
    return [lpm_estimate(records, threshold)
            for threshold in (LPM_POWER_THRESHOLD, _STRICT_POWER_THRESHOLD)]


def fit_linear_model(U, Y, starts, params, first_rows=None):
    """Fit the BLA on normalised signals.

    Parameters
    ----------
    U, Y : ndarray
        Normalised input and output.
    starts : ndarray
        Sequence boundaries.
    params : dict
        The parameters of a :class:`BLAEstimator`.
    first_rows : ndarray of int, default=None
        The row of the user's ``X`` at which every sequence starts, for the
        messages, when the sequences are parts of it; None when they are its
        rows.

    Returns
    -------
    fit : LinearFit
    """
    with (one_blas_thread(),
          explained(lambda: _delay_note(starts, params))):
        try:
            return _fit_linear_model(U, Y, starts, params, first_rows)
        except np.linalg.LinAlgError as error:
            # Records far from any linear system (a spike that dwarfs the rest of
            # the record) can leave the FRF without a usable factorisation.
            raise ValueError(
                f"The Best Linear Approximation cannot be computed from these data "
                f"(X, y): {error}."
            ) from error


def _delay_note(starts, params):
    """What an error adds when ``input_delay`` leaves most samples of a
    sequence without a measured input, the likely cause."""
    delay = int(np.max(params["input_delay"]))
    shortest = int(np.min(np.diff(starts)))
    if 2 * delay <= shortest:
        return ""
    return (f" (input_delay={np.ravel(params['input_delay']).tolist()} leaves "
            f"{max(shortest - delay, 0)} of the {shortest} samples of the shortest sequence "
            "a measured input.)")


def _fit_linear_model(U, Y, starts, params, first_rows=None):
    estimates = _nonparametric(U, Y, starts, params, first_rows)
    fit = _best_linear_fit(estimates, U, Y, starts, params)
    if fit.simulation_error > _DEAD_TIME_LEVEL and not np.any(params["input_delay"]):
        _check_dead_time(estimates[0], U, Y, starts, params, fit.simulation_error)
    return fit


def _check_dead_time(estimate, U, Y, starts, params, error):
    """Warn when a model of the same order fitted to the inputs delayed by a
    few samples simulates the estimation rows far better: the output responds
    late, which the model's states cannot hold.

    The FRF from the delayed inputs is ``estimate`` with the delay's phase
    removed, so each trial costs a parametric fit, not a nonparametric one.
    """
    longest = min(_MAX_CHECKED_DELAY, int(np.min(np.diff(starts))) // 10)
    mask = transient_mask(starts, params["n_transient"])
    # The subspace model alone ranks the delays; its refinement would cost
    # more than the rest of the trial.
    trial = {**params, "max_iter": 0}
    errors = {}
    # What the trial fits would warn about was said by the fit itself.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for delay in range(1, longest + 1):
            advance = np.exp(2j * np.pi * estimate.frequencies * delay)[:, None, None]
            U_delayed = delayed_input(U, starts, np.full(U.shape[1], delay),
                                      params["period"])
            try:
                errors[delay] = _parametric(replace(estimate, frf=estimate.frf * advance),
                                            U_delayed, Y, starts, mask,
                                            trial).simulation_error
            except (ValueError, np.linalg.LinAlgError):
                continue
    best = min(errors, key=errors.get, default=None)
    if best is None or errors[best] > _DELAY_GAIN * error:
        return
    # States delay a response themselves (a model without zeros by up to its
    # order), so several delays can give the same model: all those near the
    # best are named.
    others = [delay for delay, value in errors.items()
              if delay != best and value <= _DELAY_TIE * errors[best]]
    tied = "" if not others else (
        f", and by {_listed(others)} sample(s) within {100 * (_DELAY_TIE - 1):.0f} % of "
        "that (any of them holds the dead time; a grid search over input_delay chooses)")
    warn_at_caller(
        f"The linear model (n_states={params['n_states']}) simulates its estimation "
        f"record with a normalised RMS error of {error:.3g}; a model of the same order "
        f"fitted to the input delayed by {best} sample(s) gives {errors[best]:.3g}{tied}. "
        f"The output responds to the input late, which n_states={params['n_states']} "
        f"cannot hold: set input_delay={best} (see the user guide, 'Dead time'), or use "
        "more states.", UserWarning)


def _listed(delays):
    """``[1, 2, 4]`` as "1, 2 or 4"."""
    words = [str(delay) for delay in delays]
    return words[0] if len(words) == 1 else f"{', '.join(words[:-1])} or {words[-1]}"


def _best_linear_fit(estimates, U, Y, starts, params):
    """The linear model of the nonparametric ``estimates`` that simulates the
    estimation rows best (see :func:`fit_linear_model`)."""
    mask = transient_mask(starts, params["n_transient"])
    first, *others = estimates
    fits = [_parametric(first, U, Y, starts, mask, params)]
    # A few far-off lines can pull the LPM model away, typically the leakage
    # of an input that is not periodic in the record just above its band edge
    # (a cut multisine, a band-limited reference with a slow drift): the
    # LPM's windows there hold input power above the default threshold.
    # Keeping only the strongest windows removes them, but can also drop
    # lines the model needs (or leave too few for it); the model that
    # simulates the estimation rows better wins, the first on a tie.
    for estimate in others:
        try:
            fits.append(_parametric(estimate, U, Y, starts, mask, params))
        except (ValueError, np.linalg.LinAlgError):
            pass
    best = min(fits, key=lambda fit: fit.simulation_error)
    if best.simulation_error == np.inf:
        radius = spectral_radius(best.A)
        raise ValueError(
            f"n_states={params['n_states']}: the linear model fitted to the FRF "
            f"({best.frequencies.size} lines) is unstable (a pole of magnitude "
            f"{radius:.4g}) and diverges when simulated on the estimation record. "
            "Use fewer states, or check that the data hold a stable linear relation "
            "from X to y."
        )
    return best


def _check_lines(n_lines, which, n, n_u, n_y):
    """Refuse a linear model of ``n`` states that ``n_lines`` frequency lines
    (``which``, for the message) cannot determine."""
    n_free = n * (n_u + n_y) + n_y * n_u
    if 2 * n_lines * n_y * n_u < n_free:
        raise ValueError(
            f"n_states={n} is too large for the {n_lines} frequency line(s) {which}: "
            f"{2 * n_lines * n_y * n_u} real FRF values cannot determine "
            f"{n_free} identifiable parameters. Use a longer record, an input that "
            "excites more frequencies, or fewer states."
        )


def check_excitation(U, starts, n_states, n_outputs):
    """Refuse normalised inputs ``U`` whose records excite too few frequency
    lines for a linear model of ``n_states`` states.

    The lines are the DFT bins (DC aside) of every sequence where the inputs
    hold more than ``EXCITATION_THRESHOLD`` of that sequence's strongest
    bin's power. A nonlinear estimator fits its BLA on part of the record,
    where the leakage of a periodic input that does not fill that part whole
    spreads over every bin; counted on the whole record, a sine of whole
    periods is one line.
    """
    n_lines = 0
    for begin, end in zip(starts[:-1], starts[1:]):
        power = np.sum(np.abs(np.fft.rfft(U[begin:end], axis=0)[1:]) ** 2, axis=1)
        n_lines += int(np.sum(power > EXCITATION_THRESHOLD * power.max(initial=0.0)))
    _check_lines(n_lines, "that the input excites", n_states, U.shape[1], n_outputs)


def _parametric(estimate, U, Y, starts, mask, params):
    """Balanced state-space model fitted to the nonparametric ``estimate``,
    checked on the estimation rows ``mask``."""
    n, n_u, n_y = params["n_states"], U.shape[1], Y.shape[1]
    n_freq = estimate.frequencies.size
    _check_lines(n_freq, "of the FRF", n, n_u, n_y)
    n_block_rows(n, n_freq, n_u)
    weight = _weights(estimate, params["weighting"])
    G, freqs = estimate.frf, estimate.frequencies
    A, B, C, D = frf_subspace(freqs, G, weight, n)
    n_iter, loss_history = 0, None
    if params["max_iter"] > 0:
        A, B, C, D, result = refine_frf(A, B, C, D, freqs, G, weight,
                                        max_iter=params["max_iter"], tol=params["tol"],
                                        verbose=params["verbose"])
        n_iter, loss_history = result.n_iter, result.loss_history
    A, B, C, D, hsv = balanced_realization(A, B, C, D)
    # The least-squares initial state, one for all sequences, checks every
    # model (a state per sequence would let a nearly integrating model absorb
    # each record's drift and win); the fit keeps one per sequence, and only
    # with estimate_x0.
    x0, output_offset = estimate_initial_state(A, B, C, D, U, Y, starts, mask)
    error = _simulation_nrmse(A, B, C, D, U, Y, starts, mask, x0, output_offset)
    if not params["estimate_x0"]:
        x0, output_offset = np.zeros(n), np.zeros(n_y)
    elif len(starts) > 2:
        x0, output_offset = estimate_initial_state(A, B, C, D, U, Y, starts, mask,
                                                   per_sequence=True)
    noise, total = estimate.noise_variance, estimate.total_variance
    if estimate.estimated is not None:
        # The entries not estimated are shown as such.
        G, noise, total = (None if value is None else np.where(estimate.estimated, value, np.nan)
                           for value in (G, noise, total))
    return LinearFit(A, B, C, D, x0, output_offset, hsv, freqs, G, noise, total,
                     ss_frf(A, B, C, D, freqs), n_iter, loss_history, error)


def _simulation_nrmse(A, B, C, D, U, Y, starts, mask, x0, offset):
    """Largest RMS error over the outputs, relative to each output's standard
    deviation, of the model's simulation over the rows ``mask`` from ``x0``
    with the output ``offset``; inf for a diverging simulation."""
    Y_sim, _, diverged = simulate_linear(
        A, B, C, D, U, starts, np.broadcast_to(x0, (len(starts) - 1, A.shape[0])))
    if diverged:
        return np.inf
    return float(np.max(nrmse(Y[mask], Y_sim[mask] + offset, multioutput="raw_values")))


def _set_fitted(bla, fit, normalisation):
    """Set the fitted attributes of ``bla`` from a fit on signals normalised by
    ``normalisation`` (see :func:`normalisation_of`); FRFs in the user's units."""
    for name, value in normalisation.items():
        setattr(bla, name, value)
    n, n_y = fit.A.shape[0], fit.C.shape[0]
    bla.A_, bla.B_, bla.C_, bla.D_ = fit.A, fit.B, fit.C, fit.D
    bla.x0_, bla.output_offset_ = fit.x0, fit.output_offset
    bla.y_offset_ = normalisation["y_offset_"] + normalisation["y_scale_"] * fit.output_offset
    bla.hankel_singular_values_ = fit.hankel_singular_values
    bla.frequencies_ = fit.frequencies
    # In the user's units, an FRF or a variance beyond the floating-point range
    # (outputs of 1e200 for inputs of 1e-200) is infinite; the model itself
    # works in normalised units.
    with np.errstate(over="ignore", invalid="ignore"):
        scale = normalisation["y_scale_"][:, None] / normalisation["u_scale_"][None, :]
        bla.frf_ = fit.frf * scale
        bla.frf_model_ = fit.frf_model * scale
        noise, total = fit.noise_variance, fit.total_variance
        bla.noise_variance_ = None if noise is None else noise * scale**2
        if total is None:
            bla.total_variance_ = None
        else:
            bla.total_variance_ = bla.noise_variance_ if total is noise else total * scale**2
    bla.n_iter_, bla.loss_history_ = fit.n_iter, fit.loss_history
    bla.n_params_ = parameter_count(StateSpaceModel.layout(
        n, fit.B.shape[1], n_y, estimate_x0=bla.estimate_x0,
        n_sequences=len(np.atleast_2d(fit.x0))))


def fitted_bla(params, fit, normalisation):
    """A fitted :class:`BLAEstimator` with the given parameters, from ``fit``.

    Parameters
    ----------
    params : dict
        Parameters of the estimator.
    fit : LinearFit
        Result of :func:`fit_linear_model` on signals normalised by
        ``normalisation``.
    normalisation : dict
        The normalisation attributes of the estimator whose data were used
        (:func:`normalisation_of`).

    Returns
    -------
    bla : BLAEstimator
        Predicts and reports its FRF in the user's units.
    """
    bla = BLAEstimator(**params)
    _set_fitted(bla, fit, normalisation)
    return bla


class BLAEstimator(_BaseStateSpace):
    """Best Linear Approximation as a balanced linear state-space model.

    The fit has two steps (paper §3.3). First, the nonparametric BLA: the
    frequency response function (FRF) with its variance, by the robust method
    when the data are periodic (``period`` given: every sequence is one
    realization of whole periods) or else by the Local Polynomial Method (LPM),
    which also removes the transient of a record that does not start at rest.
    Second, the parametric BLA: a frequency-domain subspace estimate of
    (A, B, C, D) refined by weighted nonlinear least squares of the model FRF
    on the nonparametric FRF (paper eq. 9, in a state-space parametrisation),
    weighted by the inverse variance, and converted to a balanced realization.
    All fitting happens on signals normalised to zero mean and unit standard
    deviation; the FRF attributes are in the user's units.

    Parameters
    ----------
    n_states : int, default=2
        Model order n.
    period : int, default=None
        Samples per period of a periodic excitation. Every sequence must then
        hold the same whole number of periods. ``None`` for non-periodic data.
        ``predict`` still starts every sequence from its initial state: to
        simulate a periodic record in steady state, prepend its last period
        and drop it from the output.
    method : {"auto", "robust", "lpm"}, default="auto"
        Nonparametric method: ``"auto"`` is ``"robust"`` when ``period`` is
        given and ``"lpm"`` otherwise. ``"lpm"`` with ``period`` given ignores
        the periodicity.
    lpm_order : int, default=2
        Degree of the local polynomials of the LPM (FRF and transient). It is
        lowered on records too short for it.
    lpm_bandwidth : int, default=None
        Half-width n of the LPM window of ``2 n + 1`` bins. ``None`` takes the
        smallest window leaving three or four degrees of freedom for the noise
        variance (nine bins for one input and ``lpm_order=2``). Records too
        short for the window shrink it, then lower the degree; a record too
        short even for that gives an FRF without variance.
    max_frequency : float, default=None
        Highest frequency used, in cycles per sample (0.5 is Nyquist). Within
        it, only the bins where the input has power are used: the excited lines
        of a periodic excitation, or the LPM bins that hold input power of
        their own (more than 1e-8 of the strongest bin's: the lines between
        those of a periodic input given without ``period`` are left out) and
        whose window holds input power (at least 1e-3 of the largest window's,
        so that the leakage of a band-limited input is left out; 1e-2 in the
        second attempt described in the Notes). DC is never used (the offsets
        are removed separately).
    weighting : {"total", "noise"} or None, default="total"
        Variance weighting the parametric fit: ``"total"`` (noise plus
        nonlinear distortions) or ``"noise"``; each falls back on the other
        when it cannot be estimated, and ``None`` (or no variance at all, e.g.
        one realization of one period) gives a uniform weighting. From two
        realizations (two groups of ``n_inputs``), whose total variance has
        one degree of freedom per line, ``"total"`` weights by the noise
        variance (see the user guide).
    max_iter : int, default=100
        Levenberg-Marquardt iterations refining the subspace estimate (0 keeps
        the subspace estimate).
    tol : float, default=1e-10
        Relative cost decrease below which the refinement stops.
    estimate_x0 : bool, default=False
        Estimate the initial state of every sequence and a correction of
        the output offset by linear least squares on the
        estimation data; else ``x0_`` is zero.
    input_delay : int or array-like of int, default=0
        Dead time in samples between each input column and its first effect
        (one value for every column, or one per column), as MATLAB's
        ``InputDelay``: the model is identified on, and simulates, ``u(t - d)``
        (the output can respond at lag ``d`` through ``D_``), so the delay
        costs no states. ``frf_``, ``frf_model_``, the variances, the poles
        and ``A_``, ``B_``, ``C_``, ``D_`` are those of the delay-free part (the
        user guide gives the FRF from the undelayed input). Before the start
        of a sequence the delayed input was not measured: a sequence whose
        input repeats with ``period`` is continued periodically, any other
        takes the training input's mean. With the default 0, a model that
        simulates its data with a normalised RMS error above 0.5 is tried on
        delayed inputs, and a delay that halves that error is named in a
        warning.
    n_transient : int, default=0
        Samples at the start of each sequence left out: of the least-squares
        initial state and the score, and of the FRF (with ``period``, the first
        ``ceil(n_transient / period)`` periods of every sequence are dropped;
        for the LPM, the first ``n_transient`` samples). The initial state's
        least squares then shrink the directions whose free response has
        settled below about 1 % by the first counted sample (see the user
        guide's initial-state section).
    verbose : int, default=0
        Print the refinement's progress when positive.

    Attributes
    ----------
    A_ : ndarray of shape (n_states, n_states)
        State matrix (balanced realization, normalised signal units).
    B_ : ndarray of shape (n_states, n_inputs)
        Input matrix.
    C_ : ndarray of shape (n_outputs, n_states)
        Output matrix.
    D_ : ndarray of shape (n_outputs, n_inputs)
        Feed-through matrix.
    x0_ : ndarray of shape (n_states,) or (n_sequences, n_states)
        Initial state, zero unless ``estimate_x0``; with ``estimate_x0``, one
        per sequence when the model was fitted on several (``predict`` starts
        any record from their mean then, unless given ``x0``, e.g. ``x0_``
        itself).
    output_offset_ : ndarray of shape (n_outputs,)
        Correction of the output offset estimated with ``x0_`` (normalised
        units, zero unless ``estimate_x0``): the mean of a record that does not
        start in steady state contains the mean of its transient. ``fit`` adds
        it to ``y_offset_``.
    poles_ : ndarray of shape (n_states,)
        Eigenvalues of ``A_`` (discrete-time poles), sorted by decreasing
        magnitude.
    hankel_singular_values_ : ndarray of shape (n_states,) or None
        Hankel singular values of the balanced model (None when the model
        could not be balanced).
    frequencies_ : ndarray of shape (n_freq,)
        Frequencies of the nonparametric FRF, in cycles per sample.
    frf_ : ndarray of shape (n_freq, n_outputs, n_inputs), complex
        Nonparametric BLA in the user's units; NaN (as its variances) where
        an input has no power of its own while others do (Local Polynomial
        Method with inputs of different bands, see the user guide).
    noise_variance_ : ndarray of shape (n_freq, n_outputs, n_inputs) or None
        Variance of ``frf_`` due to the noise (robust method with at least two
        periods). For the LPM, the noise and the nonlinear distortions cannot
        be told apart: it equals ``total_variance_``.
    total_variance_ : ndarray of shape (n_freq, n_outputs, n_inputs) or None
        Variance of ``frf_`` due to the noise and the nonlinear distortions
        (robust method with at least two groups of ``n_inputs`` realizations,
        or the LPM).
    frf_model_ : ndarray of shape (n_freq, n_outputs, n_inputs), complex
        FRF of the parametric model at ``frequencies_``, in the user's units.
    n_params_ : int
        Number of parameters, ``n^2 + n n_u + n_y n + n_y n_u`` (plus
        ``n + n_y``, the initial state and the output offset, with
        ``estimate_x0``; ``n`` per sequence for several).
    n_iter_ : int
        Levenberg-Marquardt iterations performed.
    loss_history_ : ndarray of shape (n_iter_ + 1,) or None
        Weighted FRF cost per iteration (mean squared weighted residual);
        None with ``max_iter=0``, which keeps the subspace model unrefined.
    n_features_in_ : int
        Number of inputs.
    n_outputs_ : int
        Number of outputs.
    input_delay_ : ndarray of shape (n_inputs,), dtype int
        Dead time of each input in samples (``input_delay`` per input column).
    u_offset_, u_scale_, y_offset_, y_scale_ : ndarray
        Offsets and scales of the normalisation.

    See Also
    --------
    PNLSSRegressor : Polynomial nonlinear state space initialised from the BLA.
    NLSS2Regressor : Neural-network nonlinear state space initialised from it.

    Notes
    -----
    The robust method needs at least ``n_inputs`` realizations; with more,
    they are grouped ``n_inputs`` at a time (the realizations left over are
    not used), and the spread over groups gives the total variance. The LPM
    treats each sequence as one record; estimates of several records at the
    same frequencies are averaged with inverse-variance weights.

    The LPM model is checked in the time domain. The LPM keeps the bins
    whose window holds at least 1e-3 of the largest window's input power; a
    few lines far from the rest can pull the model away: the leakage of an
    input that is not periodic in the record just above its band edge (a cut
    multisine, a slow drift of a reference in closed loop). So the LPM is
    also run on the windows with at least 1e-2 of it, which leaves those lines
    out, and of the two models the one that simulates the estimation record
    better (from the least-squares initial state) is kept. A model that is
    still worse than the output's mean warns.

    The parametric step minimises the weighted FRF error of paper eq. 9 over
    the state-space matrices rather than over the coefficients of a rational
    transfer function: the subspace estimate gives a good start for any order
    and for MIMO data, and the state-space parametrisation stays well
    conditioned where polynomial coefficients do not. Steps that would make
    the model unstable are rejected, so the BLA can always be simulated.
    Moreover, every pole's damping is kept large enough for its half-power
    band to reach a measured frequency: the data do not determine the damping
    of a pole farther from them, and an unconstrained fit lets such a pole
    (typically one the order does not need) drift to the unit circle, where
    it amplifies the little input content outside the measured band. Near
    DC this bounds the slowest time constant by ``1 / (2 pi f_min)`` samples,
    ``f_min`` being the lowest frequency of ``frequencies_``; outside the
    measured band the bound tightens with the distance to it, so to identify
    poles there, excite and measure up to them.

    The fit warns when the model simulates its own estimation record worse
    than the output's mean (from the least-squares initial state). Besides
    data with little linear relation from input to output, this happens when
    a few FRF lines far from the rest, at the edge of the excited band, pull
    the fit onto an almost undamped resonance: the LPM lines where the
    input's power fades (a band-limited reference in closed loop, leakage)
    are the usual ones. A lower ``lpm_order``, whose window is
    narrower, or a ``max_frequency`` below the band edge removes them. The
    model is returned as fitted; the nonlinear estimators start from such a
    model all the same.

    References
    ----------
    R. Pintelon and J. Schoukens, *System Identification: A Frequency Domain
    Approach*, 2nd ed., Wiley-IEEE Press, 2012 (ch. 3-4 and 7).

    T. McKelvey, H. Akçay and L. Ljung, "Subspace-based multivariable system
    identification from frequency response data", IEEE TAC 41(7), 1996.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> from sknlss import BLAEstimator
    >>> from sknlss.signals import multisine
    >>> u, lines = multisine(256, n_periods=2, n_realizations=2, random_state=0)
    >>> y = lfilter([0.0, 0.5], [1.0, -1.2, 0.5], u, axis=1)
    >>> X, sequence_id = u.reshape(-1, 1), np.repeat([0, 1], u.shape[1])
    >>> bla = BLAEstimator(n_states=2, period=256, n_transient=256)
    >>> bla = bla.fit(X, y.ravel(), sequence_id=sequence_id)
    >>> bla.n_params_
    9
    >>> np.round(np.sort_complex(bla.poles_), 6)
    array([0.6-0.374166j, 0.6+0.374166j])
    """

    _parameter_constraints: dict = {
        **_BaseStateSpace._parameter_constraints,
        "n_states": [Integers(1, None, closed="left")],
        "period": [Integers(3, None, closed="left"), None],
        "method": [StrOptions({"auto", "robust", "lpm"})],
        "lpm_order": [Integers(0, None, closed="left")],
        "lpm_bandwidth": [Integers(1, None, closed="left"), None],
        "max_frequency": [Interval(Real, 0, 0.5, closed="right"), None],
        "weighting": [StrOptions({"total", "noise"}), None],
        "max_iter": [Integers(0, None, closed="left")],
        "tol": [Interval(Real, 0, None, closed="left")],
        "estimate_x0": ["boolean"],
        "verbose": ["verbose"],
    }

    def __init__(
        self,
        n_states=2,
        *,
        period=None,
        method="auto",
        lpm_order=2,
        lpm_bandwidth=None,
        max_frequency=None,
        weighting="total",
        max_iter=100,
        tol=1e-10,
        estimate_x0=False,
        input_delay=0,
        n_transient=0,
        verbose=0,
    ):
        self.n_states = n_states
        self.period = period
        self.method = method
        self.lpm_order = lpm_order
        self.lpm_bandwidth = lpm_bandwidth
        self.max_frequency = max_frequency
        self.weighting = weighting
        self.max_iter = max_iter
        self.tol = tol
        self.estimate_x0 = estimate_x0
        self.input_delay = input_delay
        self.n_transient = n_transient
        self.verbose = verbose

    def _fit_normalized(self, U, Y, starts):
        params = self.get_params()
        fit = fit_linear_model(U, Y, starts, params)
        _set_fitted(self, fit, normalisation_of(self))
        self._warn_if_worse_than_the_mean(fit, params)

    def _warn_if_worse_than_the_mean(self, fit, params):
        """Warn when the model simulates its own estimation record worse than the
        output's mean: such a model should not be taken silently."""
        error = fit.simulation_error
        if error <= _MEAN_LEVEL:
            return
        remedy = "a max_frequency below the edge of the excited band"
        if _frf_method(params) == "lpm" and self.lpm_order > 0:
            remedy = f"a lower lpm_order (its narrower window), or {remedy}"
        warn_at_caller(
            f"BLAEstimator(n_states={self.n_states}) simulates its estimation record "
            f"worse than the output's mean (normalised RMS error {error:.3g} from the "
            "least-squares initial state). Either the data hold little linear relation "
            "from X to y, or a few FRF lines far from the rest pull the fit, typically "
            "at the edge of the excited band (input leakage, closed-loop data): compare "
            f"frf_ with frf_model_ and try {remedy}; or the output responds to the input "
            "only after a dead time, which these states cannot hold: set input_delay "
            "(see the user guide).",
            UserWarning)

    def _fitted_model(self):
        model = StateSpaceModel(self.A_.shape[0], self.B_.shape[1], self.C_.shape[0])
        return model, model.pack({"A": self.A_, "B": self.B_, "C": self.C_, "D": self.D_})

    @property
    def poles_(self):
        """Discrete-time poles (eigenvalues of ``A_``), by decreasing magnitude."""
        check_is_fitted(self)
        poles = np.linalg.eigvals(self.A_)
        return poles[np.argsort(-np.abs(poles), kind="stable")]
