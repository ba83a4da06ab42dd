"""The fit shared by the nonlinear state-space estimators.

Every nonlinear estimator identifies ``x(t+1) = A x + B u + h_x(x, u)``,
``y(t) = C x + D u + h_y(x, u)`` with its own terms ``h`` the same way:

1. the rows of the fit: the cost rows, the held-out tail of every sequence and
   the transient (dropped, or replaced by a steady-state extension for
   periodic data);
2. the Best Linear Approximation on the rows before the held-out tails,
   exposed as ``bla_`` in the user's units;
3. optionally, the linear part (and x0, unless held, and the output offset)
   refined on the simulation error with the terms switched off;
4. one or more starting points of the terms (the estimator's own
   initialisation), each refined by Levenberg-Marquardt on the shared
   :class:`~sknlss._core._problem.SimulationErrorProblem`; the start with the
   lowest held-out loss is kept;
5. optionally (``refit``), the kept start refined further on all the rows,
   the held-out ends included.

A subclass provides its terms (``_make_terms``, or several candidate
structures that the starts take in turn through ``_candidate_terms``), its
starting points
(``_prepare_starts`` and ``_starting_points``) and its fitted attributes
(``_set_terms`` and ``_terms_values``).
"""

import time
import warnings
from abc import abstractmethod
from numbers import Real

import numpy as np
from joblib import effective_n_jobs
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import Interval, StrOptions

from .._core._memory import check_memory
from .._core._model import StateSpaceModel, parameter_count
from .._core._multistart import START_ERRORS, fit_from, recorded_warnings, run_starts
from .._core._problem import SimulationErrorProblem, fit_rows
from .._core._sequences import (PERIODIC_TOLERANCE, every_sequence, holdout_masks,
                                part_before_holdout, periodic_sequences, steady_state_rows,
                                transient_mask)
from .._linear._realization import estimate_initial_state, simulate_linear, spectral_radius
from .._validation import ANY_INTEGER, Integers, explained
from ..exceptions import DataWarning, LinearFallbackWarning, warn_at_caller
from ..metrics import nrmse
from ._base import _BaseStateSpace, check_delay_fits, normalisation_of
from ._bla import _MEAN_LEVEL, BLAEstimator, check_excitation, fit_linear_model, fitted_bla


#: Held-out shares of the end of every sequence given to the starts in turn
#: with ``validation_fraction="auto"``; the starts are ranked on the end that
#: all of them held out. On a short record, the model a single held-out end
#: selects changes a lot when that end moves by a few samples.
_AUTO_SHARES = (0.25, 0.3, 0.35, 0.275, 0.325)
#: Sequences shorter than this are not split by ``validation_fraction="auto"``.
_MIN_SPLIT_LENGTH = 100
#: Without an estimated initial state, the cost skips the samples in which the
#: slowest mode of the linear model that shows in its output (by at least this
#: fraction of the output's scale, see ``_settling_time``) decays to this
#: fraction, at most this share of each sequence.
_SETTLED = 1e-2
_MAX_TRANSIENT_SHARE = 0.1
#: Without an estimated initial state, a DataWarning says that the cost sees
#: the start transient when more than this share of it is left where the
#: skipped samples end (the slowest mode decaying geometrically).
_TRANSIENT_LEFT = 0.1
#: Relative margin above the linear start's error on the cost rows within which
#: a model still counts as fitting them as well (rounding of the simulations).
_ROUNDING_MARGIN = 1e-9
#: A selected model must stay within ten times the measured output's range
#: when the estimation input is enlarged by a fifth (see ``stays_bounded``).
_GUARD_GAIN = 1.2
_GUARD_RANGE = 10.0
#: Of the starts within this factor of the best held-out loss, one whose
#: simulation stays finite on the doubled estimation input is preferred (see
#: ``_prefer_finite_when_doubled``); the changes of selection this made on
#: fresh simulated records came from starts within 1.5 times the best.
_ESCAPE_GAIN = 2.0
_ESCAPE_TOLERANCE = 2.0
#: With ``center=False``, a signal whose mean exceeds this many standard
#: deviations warns: its zero, around which the model is expanded, then lies
#: outside the bulk of its samples.
_OFFSET_LIMIT = 1.0
#: Copies of the Jacobian a Levenberg-Marquardt step holds at its peak: the
#: one the kernel fills, the same stacked with the penalty rows, and the
#: optimiser's column-scaled working copy that its QR factorisation overwrites.
_JACOBIAN_COPIES = 3


class _BaseNonlinearStateSpace(_BaseStateSpace):
    """Base class of the nonlinear state-space estimators (see the module docstring)."""

    _parameter_constraints: dict = {
        **_BaseStateSpace._parameter_constraints,
        "n_states": [Integers(1, None, closed="left")],
        "estimate_x0": ["boolean"],
        "period": [Integers(3, None, closed="left"), None],
        "cost": [StrOptions({"time", "frequency"})],
        "stability_penalty": [Interval(Real, 0, None, closed="left")],
        "weight_decay": [Interval(Real, 0, None, closed="left")],
        "refine_linear": ["boolean"],
        "bla": [BLAEstimator, None],
        "max_iter": [Integers(0, None, closed="left")],
        "tol": [Interval(Real, 0, None, closed="left")],
        "validation_fraction": [Interval(Real, 0, 1, closed="left"), StrOptions({"auto"})],
        "refit": ["boolean"],
        "check_bounded": ["boolean"],
        "n_iter_no_change": [Integers(1, None, closed="left"), None],
        "n_init": [Integers(1, None, closed="left")],
        "n_jobs": [ANY_INTEGER, None],
        "random_state": ["random_state"],
        "verbose": ["verbose"],
    }

    #: Name of the model in progress lines and warnings.
    _label = "model"
    #: The constructor parameters that set the number of parameters.
    _structure_params = ("n_states",)
    #: The terms' ``output_constant`` (see ``sknlss._core._model.Terms``),
    #: known before they are built.
    _terms_output_constant = None

    # ------------------------------------------------------------ subclass API
    @abstractmethod
    def _make_terms(self, n_inputs, n_outputs):
        """The terms object of the model for the given dimensions."""

    def _candidate_terms(self, n_inputs, n_outputs):
        """The terms of the candidate structures: the starts take them in turn,
        and the held-out loss chooses among all starts (one by default)."""
        return [self._make_terms(n_inputs, n_outputs)]

    @abstractmethod
    def _n_terms_params(self, n_inputs, n_outputs):
        """Number of parameters of the largest terms ``_candidate_terms`` would
        build, counted without building them."""

    @abstractmethod
    def _starting_points(self, context, start, seed):
        """Candidate starting parameter vectors of start number ``start``
        (random seed ``seed``), tried in turn until one simulates (see
        :func:`~sknlss._core._multistart.fit_from`)."""

    def _prepare_starts(self, context):
        """Work shared by all starts, added to the ``context`` dict in place."""

    @abstractmethod
    def _set_terms(self, values):
        """Set the fitted attributes of the terms from the unpacked parameters."""

    @abstractmethod
    def _terms_values(self):
        """The fitted terms' parameter blocks, keyed by block name."""

    def _prediction_terms(self, model, theta, U, starts):
        """The terms the fitted model predicts with, given its parameters and
        the estimation record: the fitted terms themselves by default."""
        return model.terms

    def _n_drop(self, problem):
        """Directions of the parameter space that leave the output of
        ``problem`` unchanged (discarded from the Levenberg-Marquardt step)."""
        return _similarity_directions(problem)

    def _centred(self):
        """Whether the signals are centred (else only scaled)."""
        return True

    # ------------------------------------------------------------------- fit
    def _choose_offsets(self):
        if not self._centred():
            self._warn_if_offset()
            # Scale only: the model is expanded around the signals' own zero,
            # not around their means.
            self.u_offset_ = np.zeros_like(self.u_offset_)
            self.y_offset_ = np.zeros_like(self.y_offset_)

    def _warn_if_offset(self):
        """Warn when a signal's mean exceeds its standard deviation: uncentred,
        the model has to produce that offset through its dynamics (the
        toolbox's convention expects signals around zero)."""
        relative = np.concatenate([self.u_offset_ / self.u_scale_,
                                   self.y_offset_ / self.y_scale_])
        worst = int(np.argmax(np.abs(relative)))
        if abs(relative[worst]) <= _OFFSET_LIMIT:
            return
        n_u = len(self.u_offset_)
        which = (f"input column {worst}" if worst < n_u else f"output {worst - n_u}")
        warn_at_caller(
            f"{type(self).__name__}(center=False): the mean of {which} is "
            f"{abs(relative[worst]):.3g} times its standard deviation. Uncentred, the "
            "model is expanded around the signals' zero and has to produce that offset "
            "through its dynamics; remove the offsets first, or use center=True.",
            DataWarning)

    def _check_periodic(self, U, starts):
        if self.cost == "frequency" and self.period is None:
            raise ValueError("cost='frequency' needs the period of the excitation.")
        if self.period is not None:
            lengths = np.diff(starts)
            if np.any(lengths % self.period):
                raise ValueError(
                    f"With period={self.period}, every sequence must hold a whole number "
                    f"of periods; got sequence lengths {lengths.tolist()}."
                )
            repeating = periodic_sequences(U, starts, self.period)
            if not repeating.all():
                warn_at_caller(
                    f"{type(self).__name__}: the input of sequence(s) "
                    f"{np.flatnonzero(~repeating).tolist()} (in the order of the rows) does "
                    f"not repeat with period={self.period}: its periods differ by more than "
                    f"{PERIODIC_TOLERANCE:.0%} of its standard deviation. The fit treats "
                    "every sequence as periodic; predict simulates such a sequence from "
                    "its initial state.", DataWarning)
            if self.validation_fraction != "auto":
                held_out = np.round(float(self.validation_fraction) * lengths).astype(int)
                if np.any(held_out % self.period):
                    k = int(np.argmax(held_out % self.period))
                    raise ValueError(
                        f"With period={self.period}, the held-out end of every sequence "
                        f"must be a whole number of periods: validation_fraction="
                        f"{self.validation_fraction!r} holds out {held_out[k]} of the "
                        f"{lengths[k]} samples of a sequence. Use a fraction that holds "
                        "out whole periods, or 0 (hold out whole periods or realizations "
                        "as a separate record)."
                    )

    def _linear_start(self, U, Y, starts, fit_mask):
        """The linear part, initial state and output offset the nonlinear model
        starts from, keyed by block name: the BLA on the rows before the
        held-out tails (also set as ``bla_``, in the user's units)."""
        params = (self.bla if self.bla is not None else BLAEstimator()).get_params()
        forwarded = dict(n_states=self.n_states, estimate_x0=self.estimate_x0,
                         input_delay=self.input_delay)
        _warn_if_replaced(params, forwarded)
        params.update(forwarded)
        if params["period"] is None:
            params["period"] = self.period
        *part, kept = part_before_holdout(U, Y, starts, fit_mask)
        with explained(lambda: self._holdout_note(starts, part[2], kept)):
            check_delay_fits(self.input_delay_, part[2])
            linear = fit_linear_model(*part, params, first_rows=starts[kept])
        if self.estimate_x0:
            # A sequence without a fitted row has no state of its own to fit.
            linear.x0 = every_sequence(linear.x0, kept, len(starts) - 1)
        self.bla_ = fitted_bla(params, linear, normalisation_of(self))
        return {"A": linear.A, "B": linear.B, "C": linear.C, "D": linear.D, "x0": linear.x0,
                "y0": linear.output_offset}

    def _holdout_note(self, starts, part_starts, kept):
        """What an error of the linear start adds when it was fitted on
        sequences cut before their held-out ends (see ``_linear_start``)."""
        lengths, cut = np.diff(starts)[kept], np.diff(part_starts)
        k = int(np.argmin(cut))
        if cut[k] == lengths[k]:
            return ""
        return (f" The linear start is fitted on the samples before the held-out end of "
                f"every sequence: validation_fraction={self.validation_fraction!r} leaves "
                f"{cut[k]} of the {lengths[k]} samples of the shortest.")

    def _holds_x0(self, settling_time):
        """Whether the search holds the initial state at its starting value:
        with ``estimate_x0``, when the transient left out of the cost
        (``n_transient``, also the samples prepended for the steady state)
        outlasts the ``settling_time`` of the linear start. The state's effect
        has then died out where the cost starts: a search would move it far
        away to fit the noise, and the model would run away over the
        transient."""
        return (self.estimate_x0 and self.n_transient > 0
                and settling_time <= self.n_transient)

    def _problem(self, terms, rows, x0_held):
        """The simulation-error problem of a model with ``terms`` on ``rows``;
        with ``x0_held``, the search holds the initial state."""
        model = StateSpaceModel(self.n_states, rows.U.shape[1], rows.Y.shape[1], terms,
                                estimate_x0=self.estimate_x0,
                                n_sequences=len(rows.starts) - 1)
        return SimulationErrorProblem(
            model, rows, frequency_period=self.period if self.cost == "frequency" else None,
            stability_penalty=self.stability_penalty, weight_decay=self.weight_decay,
            held=model.columns("x0") if x0_held else None)

    def _fit_linear_part(self, problem, theta):
        """``theta`` with its linear part (and x0, unless held, and the output
        offset) refined on the simulation error, the terms left as they are,
        and the search's result.

        A refinement that takes a stable linear part out of the unit circle is
        not taken (``theta`` is returned as it is, with the result of a search
        without iterations): a short record is fitted as well by a mode that
        grows over its length, and such a model runs away beyond it.
        """
        model = problem.model
        free = np.setdiff1d(model.linear_columns, problem.held)
        options = dict(self._lm_options(problem), n_drop=_similarity_directions(problem))
        restricted = problem.restricted(theta, free)
        label = f"{self._label} (linear part)"
        refined = theta.copy()
        try:
            refined[free], result = fit_from(restricted, [theta[free]], label=label, **options)
            if (spectral_radius(model.unpack(refined)["A"]) >= 1.0
                    > spectral_radius(model.unpack(theta)["A"])):
                return theta, fit_from(restricted, [theta[free]], label=label,
                                       **dict(options, max_iter=0))[1]
        except START_ERRORS as failure:
            raise self._unfittable(failure) from failure
        return refined, result

    def _refined_linear_start(self, problem, theta):
        """The starting parameters with the linear part (and x0, unless held,
        and the output offset) refined on the simulation error, the terms
        switched off (with ``refine_linear``)."""
        if not self.refine_linear or self.max_iter == 0:
            return theta
        # A poor nonparametric BLA (short or noisy records) would otherwise
        # start the nonlinear search far away.
        return self._fit_linear_part(problem, theta)[0]

    def _linear_model(self, model, theta):
        """The parameters, in ``model``'s layout, of the linear model that the
        kept start must beat on the held-out end and that is kept otherwise
        (refined on the simulation error when the record is too short for the
        terms): the linear start ``theta`` (the BLA, refined with
        ``refine_linear``)."""
        return theta

    def _record_start(self, context, start, seed):
        """Record what the kept start's initialisation found (nothing by default)."""

    def _lm_options(self, problem):
        return dict(max_iter=self.max_iter, tol=self.tol, n_drop=self._n_drop(problem),
                    n_iter_no_change=self.n_iter_no_change, verbose=self.verbose)

    def _validation_shares(self, starts):
        """The held-out share of every start."""
        if self.validation_fraction != "auto":
            return [float(self.validation_fraction)] * self.n_init
        bla = getattr(self, "bla", None)
        periodic = self.period is not None or getattr(bla, "period", None) is not None
        if periodic or np.max(np.diff(starts)) < _MIN_SPLIT_LENGTH:
            # Periodic records are fitted in whole periods, and very short
            # records have no samples to spare: the starts are ranked on the
            # cost (hold out whole periods or realizations by hand, e.g. as a
            # separate record).
            return [0.0] * self.n_init
        return [_AUTO_SHARES[i % len(_AUTO_SHARES)] for i in range(self.n_init)]

    def _sequence_fractions(self, share, starts):
        """The held-out share of each sequence for a start's ``share``: with
        ``validation_fraction="auto"``, a sequence too short to spare samples
        is fitted whole, and the others are split."""
        if self.validation_fraction != "auto":
            return share
        return np.where(np.diff(starts) < _MIN_SPLIT_LENGTH, 0.0, share)

    def _cost_transient(self, settling_time, starts):
        """Samples left out of the cost at the start of the longest sequence:
        ``n_transient``, and without an estimated initial state, at least the
        ``settling_time`` of the linear start (a record rarely starts at rest)
        after the largest input delay (whose unmeasured samples start it
        too)."""
        if self.estimate_x0 or self.period is not None:
            return self.n_transient
        limit = int(_MAX_TRANSIENT_SHARE * np.max(np.diff(starts)))
        settled = settling_time + int(np.max(self.input_delay_, initial=0))
        fit_transient = max(self.n_transient, min(settled, limit))
        # A mode that does not decay never settles: it belongs to the linear
        # part of a start (the decoupled model's PNLSS part may grow), not to
        # the data, and the tenth is left out.
        if np.isfinite(settled):
            self._warn_if_transient_left(settled, starts, fit_transient)
        return fit_transient

    def _warn_if_transient_left(self, settled, starts, fit_transient):
        """Warn when, at the end of the samples left out of the cost at the
        start of the shortest sequence, more than ``_TRANSIENT_LEFT`` of the
        response to its unknown initial state is left (the slowest mode
        decays to ``_SETTLED`` in ``settled`` samples)."""
        lengths = np.diff(starts)
        skipped = int(np.min(_transients_per_sequence(self.n_transient, fit_transient, starts)))
        if skipped >= settled or _SETTLED ** (skipped / settled) <= _TRANSIENT_LEFT:
            return
        which = "every sequence" if np.all(lengths == lengths[0]) else "the shortest sequence"
        if settled < np.max(lengths):
            advice = f"Set estimate_x0=True, or n_transient to at least {settled}."
        else:
            advice = ("Set estimate_x0=True. A mode slower than the record may also be the "
                      "linear start's alone, where the data leave its damping undetermined "
                      "(near the edge of the excited band, for one): compare bla_.frf_ with "
                      "bla_.frf_model_.")
        warn_at_caller(
            f"{type(self).__name__}: the slowest mode of the linear model that shows in the "
            f"output settles (to 1 %) in {settled} samples, and the cost leaves out only the "
            f"first {skipped} of {which} (without an estimated initial state, at most a "
            "tenth of a sequence): more than a tenth of the response to the unknown state at "
            "the start of the record enters the cost, and the fit bends the model to explain "
            f"it. {advice}", DataWarning)

    def _sequence_transients(self, starts):
        """Samples left out of the cost at the start of each sequence (see
        :func:`_transients_per_sequence`)."""
        return _transients_per_sequence(self.n_transient, self.fit_transient_, starts)

    def _structure(self):
        """The structure parameters and their values, for messages."""
        return ", ".join(f"{name}={getattr(self, name)!r}" for name in self._structure_params)

    def _unfittable(self, failure):
        """The error of a fit that failed numerically: the data or the structure
        (or both) are at fault, so it names them."""
        return ValueError(f"{type(self).__name__}({self._structure()}): the model cannot "
                          f"be fitted to the data (X, y): {failure}")

    def _check_model_size(self, U, Y, starts, shares):
        """Refuse, before anything is built, a model whose fit would not fit in memory.

        The Levenberg-Marquardt Jacobian has a row per cost value (and per
        penalty row) and a column per parameter; the number of parameters is
        counted from the structure, since listing the terms of a huge model
        alone can exhaust the memory.
        """
        n_u, n_y = U.shape[1], Y.shape[1]
        n_terms = self._n_terms_params(n_u, n_y)
        n_params = n_terms + parameter_count(StateSpaceModel.layout(
            self.n_states, n_u, n_y, estimate_x0=self.estimate_x0,
            output_offset=self._terms_output_constant is None, n_sequences=len(starts) - 1))
        # The largest Jacobian: the smallest hold-out and the shortest transient.
        n_samples = int(fit_rows(U, Y, starts, n_transient=self.n_transient,
                                 validation_fraction=self._sequence_fractions(
                                     min(self._row_shares(shares)), starts),
                                 steady_state=self.period is not None).fit_rows.sum())
        # The stability penalty has a row per fitted sample at most, the weight
        # decay one per term parameter.
        n_penalty = ((n_samples if self.stability_penalty else 0)
                     + (n_terms if self.weight_decay else 0))
        concurrent = min(self.n_init, effective_n_jobs(self.n_jobs))
        check_memory(
            8 * (n_samples * n_y + n_penalty) * n_params * _JACOBIAN_COPIES * concurrent,
            f"{type(self).__name__}({self._structure()}) has {n_params:,} parameters; "
            f"its fit on {n_samples * n_y:,} cost values and {n_penalty:,} penalty rows "
            f"(stability_penalty, weight_decay; {_JACOBIAN_COPIES} copies of the rows x "
            f"parameters Jacobian, {concurrent} start(s) at a time)",
            "Use a smaller model or a shorter record.")

    def _underdetermined(self, problem):
        """Whether the cost holds fewer values than the model has parameters
        (with a warning): the search could then fit the data exactly whatever
        the system, and its hold-out selection would rest on noise."""
        model = problem.model
        n_values = n_cost_values(problem)
        if n_values >= model.n_params:
            return False
        warn_at_caller(
            f"{type(self).__name__}({self._structure()}) has {model.n_params} parameters "
            f"but its cost holds only {n_values} values (n_transient={self.n_transient}, "
            f"validation_fraction={self.validation_fraction!r}): the nonlinear terms "
            "cannot be identified and the linear model is kept (its nonlinear terms "
            "switched off, its linear part refined on the simulation error where that "
            "keeps it stable). Use a longer record or a smaller model.",
            LinearFallbackWarning)
        return True

    def _check_transient(self, starts, shares):
        """Refuse an ``n_transient`` that, with the held-out ends, leaves no row
        to fit, in the terms of the parameters the user set."""
        if self.period is not None:
            return
        share = max(shares)
        try:
            holdout_masks(starts, self.n_transient, self._sequence_fractions(share, starts))
        except ValueError:
            split = (f" of {_MIN_SPLIT_LENGTH} samples or more"
                     if self.validation_fraction == "auto" else "")
            ends = (f" before the held-out end of each sequence{split} (validation_fraction="
                    f"{self.validation_fraction!r} holds out its last {share:.0%})"
                    if share else "")
            raise ValueError(
                f"{type(self).__name__}: n_transient={self.n_transient} leaves no sample "
                f"to fit{ends}; the longest sequence has {np.max(np.diff(starts))} "
                "samples. Lower n_transient or use a longer record.") from None

    def _fit_normalized(self, U, Y, starts):
        self._check_periodic(U, starts)
        shares = self._validation_shares(starts)
        self._check_transient(starts, shares)
        self._check_model_size(U, Y, starts, shares)
        check_excitation(U, starts, self.n_states, Y.shape[1])
        bla_rows = fit_rows(U, Y, starts, n_transient=self.n_transient,
                            validation_fraction=self._sequence_fractions(max(shares), starts),
                            steady_state=self.period is not None)
        fit_mask = bla_rows.fit_rows[bla_rows.original]
        linear = self._linear_start(U, Y, starts, fit_mask)
        # Like the linear start, it sees none of the held-out tails.
        settling_time = _settling_time(linear, *part_before_holdout(U, Y, starts, fit_mask)[:3])
        self._warn_if_not_steady(settling_time)
        self.fit_transient_ = self._cost_transient(settling_time, starts)
        rows = {share: fit_rows(U, Y, starts, n_transient=self._sequence_transients(starts),
                                validation_fraction=self._sequence_fractions(share, starts),
                                steady_state=self.period is not None)
                for share in self._row_shares(shares)}
        x0_held = self._holds_x0(settling_time)
        problem_sets = [{share: self._problem(terms, rows[share], x0_held) for share in rows}
                        for terms in self._candidate_terms(U.shape[1], Y.shape[1])]
        # The problem with the largest hold-out serves the work shared by all
        # starts: it sees only rows that none of the starts selects on.
        problem = problem_sets[0][max(shares)]
        self._warn_if_unweighted(problem)
        model = problem.model
        theta = model.pack_linear(linear)
        self.refit_n_iter_ = 0
        if self._underdetermined(problem):
            theta_best, result = self._fit_linear_part(problem, self._linear_model(model, theta))
            # No start could be made: each counts as left out.
            self.start_losses_ = np.full(self.n_init, np.inf)
            self.start_status_ = np.full(self.n_init, "not run")
            self.linear_loss_ = problem_sets[0][min(shares)].held_out_loss(theta_best)
            self.fell_back_to_linear_ = True
        else:
            # Further candidates with more parameters than cost values are left out.
            problem_sets = problem_sets[:1] + [
                problems for problems in problem_sets[1:]
                if n_cost_values(problems[max(shares)]) >= problems[max(shares)].model.n_params
            ]
            model, theta_best, result = self._search(problem_sets, shares, theta, U, Y, starts)
        values = model.unpack(theta_best)
        self.A_, self.B_, self.C_, self.D_ = (values[k] for k in "ABCD")
        self.x0_ = values["x0"] if self.estimate_x0 else np.zeros(self.n_states)
        self.output_offset_ = values.get("y0", np.zeros(Y.shape[1]))
        # The structure the predictions simulate (the initial state is passed).
        self._model = StateSpaceModel(model.n_states, model.n_inputs, model.n_outputs,
                                      self._prediction_terms(model, theta_best, U, starts))
        self._set_terms(values)
        self.n_params_ = int(model.n_params)
        self._set_search_result(result)
        # The predictions simulate without the output offset: as the BLA
        # does, it moves into the offset of the output's normalisation.
        self.y_offset_ = self.y_offset_ + self.y_scale_ * self.output_offset_
        self._warn_if_worse_than_the_mean(U, Y - self.output_offset_, starts)

    def _warn_if_not_steady(self, settling_time):
        """Warn when, with ``period`` and without estimated initial states, the
        ``n_transient`` samples prepended to every sequence are fewer than the
        linear start's settling time: the sequences then start before their
        periodic steady state, and every sample, the rest of the transient
        with them, enters the cost. Prepending nothing always warns."""
        if self.period is None or self.estimate_x0:
            return
        if self.n_transient == 0:
            warn_at_caller(
                f"{type(self).__name__}: period={self.period} with n_transient=0 "
                "prepends nothing: every sequence is simulated from the initial "
                "state, not in its periodic steady state, and the transient of that "
                f"start is fitted. Set n_transient (n_transient={self.period} "
                "prepends the last period of every sequence).", DataWarning)
            return
        if np.isinf(settling_time) or settling_time <= self.n_transient:
            return
        warn_at_caller(
            f"{type(self).__name__}: period={self.period} with n_transient="
            f"{self.n_transient} prepends fewer samples than the slowest mode of the linear "
            f"model that shows in the output takes to settle (to 1 %: {settling_time} "
            "samples): the sequences start before their periodic steady state, and what "
            "remains of the transient is fitted and scored. Set n_transient to at least "
            f"{settling_time}.", DataWarning)

    def _warn_if_unweighted(self, problem):
        """Warn when the frequency-domain cost of ``problem`` (the largest
        hold-out's, which keeps the fewest periods) cannot weight its lines."""
        if self.cost == "frequency" and not problem.noise_weighted:
            warn_at_caller(
                f"{type(self).__name__}: with cost='frequency', no sequence keeps two "
                f"periods of {self.period} samples in the cost (before its held-out end), "
                "so the noise level of the DFT lines cannot be estimated: every line is "
                "weighted alike. Fit more periods per sequence, or hold out whole records "
                "instead (validation_fraction=0).", DataWarning)

    def _warn_if_worse_than_the_mean(self, U, Y, starts):
        """Warn when the fitted model simulates its estimation record worse than
        the output's mean: such a model should not be taken silently."""
        x0 = np.broadcast_to(self.x0_, (len(starts) - 1, self.n_states))
        Y_model, _, diverged = self._simulate_normalized(U, starts, x0, steady_state=True)
        rows = self._rows_after_transients(starts, U, self._sequence_transients(starts))
        if not rows.any():
            return
        error = np.inf if diverged else float(np.max(
            nrmse(Y[rows], Y_model[rows], multioutput="raw_values")))
        if error <= _MEAN_LEVEL:
            return
        advice = ("Try center=True: with center=False the model has to produce the "
                  "signals' offsets through its dynamics." if not self._centred() else
                  "Check bla_, the linear model it starts from (compare its frf_ with its "
                  "frf_model_): an input that excites few frequencies, little linear "
                  "relation from X to y, or a dead time not given as input_delay gives a "
                  "poor start.")
        warn_at_caller(
            f"{type(self).__name__}({self._structure()}) simulates its estimation record "
            f"worse than the output's mean (normalised RMS error {error:.3g}; "
            f"fell_back_to_linear_={self.fell_back_to_linear_}). {advice}",
            UserWarning)

    def _search(self, problem_sets, shares, theta, U, Y, starts):
        """The starts from the linear start ``theta``, each refined on the
        problem of its hold-out share; the model and parameters of the best on
        the common hold-out, unless the linear start does better there.

        Start ``i`` is start number ``j = i // k`` of candidate structure
        ``i % k`` (of the ``k`` in ``problem_sets``), with the seed and the
        hold-out share of start ``j``: each candidate gets the first starts it
        would get alone.
        """
        theta = self._refined_linear_start(problem_sets[0][max(shares)], theta)
        linear = problem_sets[0][max(shares)].model.linear_values(theta)
        seeds = check_random_state(self.random_state).randint(
            np.iinfo(np.int32).max, size=self.n_init)
        contexts = []
        for problems in problem_sets:
            problem = problems[max(shares)]
            context = {"problem": problem, "model": problem.model,
                       "theta": problem.model.pack_linear(linear), "U": U, "Y": Y,
                       "starts": starts, "rows": problem.rows, "seeds": seeds}
            self._prepare_starts(context)
            contexts.append(context)
        linear_theta = self._linear_model(contexts[0]["model"], theta)
        linear_values = contexts[0]["model"].linear_values(linear_theta)
        for problems in problem_sets:
            # A model is judged on the held-out end only where it fits its own
            # rows at least as well as the linear model it must beat.
            for start_problem in problems.values():
                reference = start_problem.model.pack_linear(linear_values)
                start_problem.fit_loss_limit = (start_problem.fit_loss(reference)
                                                * (1 + _ROUNDING_MARGIN))
        k = len(problem_sets)
        runs = [(i % k, i // k, shares[i // k], seeds[i // k]) for i in range(self.n_init)]
        outcomes = run_starts(
            _fit_start,
            [(self, contexts[c], problem_sets[c][share], j, seed,
              f"{self._label} start {i}" if self.n_init > 1 else self._label,
              self._lm_options(problem_sets[c][share]))
             for i, (c, j, share, seed) in enumerate(runs)],
            n_jobs=self.n_jobs,
        )
        failures = [outcome for outcome in outcomes if isinstance(outcome, Exception)]
        if len(failures) == len(outcomes):
            raise self._unfittable(failures[0]) from failures[0]
        # Every start is judged on the end that all of them held out; a start
        # that blows up on a larger copy of the estimation input is out.
        common = [problems[min(shares)] for problems in problem_sets]
        status = ["failed" if isinstance(outcome, Exception)
                  else "beaten" if self._stays_bounded(common[c], outcome[0]) else "unbounded"
                  for (c, *_), outcome in zip(runs, outcomes)]
        # (outputs, diverged) of each start on the common rows, None if it failed.
        simulations = [None if state == "failed" else common[c].simulate(outcome[0])[::2]
                       for (c, *_), outcome, state in zip(runs, outcomes, status)]
        judged = [np.inf if simulation is None
                  else common[c].held_out_loss(outcome[0], simulation)
                  for (c, *_), outcome, simulation in zip(runs, outcomes, simulations)]
        losses = [loss if state == "beaten" else np.inf for loss, state in zip(judged, status)]
        preferred = losses if not self.check_bounded else _prefer_finite_when_doubled(
            losses, [(common[c], None if isinstance(outcome, Exception) else outcome[0])
                     for (c, *_), outcome in zip(runs, outcomes)])
        status = ["escapes" if kept != loss else state
                  for kept, loss, state in zip(preferred, losses, status)]
        losses = preferred
        best = int(np.argmin(losses))
        self.start_losses_ = np.asarray(losses)
        linear_loss = common[0].held_out_loss(linear_theta)
        # A nonlinear model that does worse than the linear model there is not
        # returned: the linear model is, and the attribute records it.
        self.linear_loss_ = linear_loss
        self.fell_back_to_linear_ = not losses[best] < linear_loss
        if not self.fell_back_to_linear_:
            status[best] = "kept"
        self.start_status_ = np.asarray(status)
        if self.verbose:
            # Printed here: the starts' own lines stay in the workers with n_jobs.
            for i, (outcome, loss, state) in enumerate(zip(outcomes, judged, status)):
                done = (f"failed ({outcome})" if isinstance(outcome, Exception) else
                        f"{outcome[1].n_iter} iterations in {outcome[3]:.1f} s, held-out "
                        f"loss {loss:.4g}, {state}")
                print(f"{self._label} start {i}: {done}", flush=True)
        if self.fell_back_to_linear_:
            # Whether any start gave a model to judge: a loss is also inf for
            # a start that fits its own rows worse than the linear model.
            none_simulated = all(simulation is None or simulation[1]
                                 for simulation in simulations)
            self._report_fallback(losses[best], linear_loss, judged,
                                  common[0].val_rows.any(), none_simulated)
            # The history describes the parameters kept: the linear model's,
            # which no iteration of a start moved.
            kept = fit_from(common[0], [linear_theta], label=self._label, max_iter=0)[1]
            return contexts[0]["model"], linear_theta, kept
        if self.verbose:
            print(f"{self._label}: start {best} kept (held-out loss {losses[best]:.4g} "
                  f"against the linear model's {linear_loss:.4g}).", flush=True)
        theta_best, result, start_warnings, _ = outcomes[best]
        c_best, j_best, _, seed_best = runs[best]
        for message, category in start_warnings:
            warn_at_caller(message, category)
        self._record_start(contexts[c_best], j_best, seed_best)
        if self._refits(shares):
            theta_best = self._refit(problem_sets[c_best][0.0], theta_best)
        return contexts[c_best]["model"], theta_best, result

    def _report_fallback(self, best_loss, linear_loss, judged, held_out, none_simulated):
        """Say why the linear model is kept: no start beat it on the held-out
        rows (``held_out``, else the cost rows), or, with a warning, every
        start that did was excluded by a boundedness check, a verdict of the
        check rather than of the data, or no start could be simulated there
        (``none_simulated``: each diverged or failed)."""
        where = "on the held-out data" if held_out else "on the cost rows"
        excluded = {state: [loss for loss, status in zip(judged, self.start_status_)
                            if status == state and loss < linear_loss]
                    for state in ("unbounded", "escapes")}
        n_excluded = sum(map(len, excluded.values()))
        if not n_excluded:
            if none_simulated:
                # Not a verdict of the data on a nonlinear model: no start gave one.
                warn_at_caller(
                    f"{type(self).__name__}({self._structure()}): none of the "
                    f"{len(judged)} starts could be simulated {where} (each diverged or "
                    "failed); the linear model is kept (see start_status_ and verbose=1). "
                    "Fewer states or terms may stay finite.", LinearFallbackWarning)
                return
            if self.verbose:
                print(f"{self._label}: no start beat the linear model {where} "
                      f"({best_loss:.4g} against {linear_loss:.4g}); the linear model "
                      "is kept.", flush=True)
            return
        reasons = []
        if excluded["unbounded"]:
            reasons.append(f"{len(excluded['unbounded'])} ran away on the estimation input "
                           f"enlarged by {_GUARD_GAIN - 1:.0%} (diverged or left "
                           f"{_GUARD_RANGE:g} times the output's range)")
        if excluded["escapes"]:
            reasons.append(f"{len(excluded['escapes'])} diverged on the input doubled, "
                           "where a start that stays finite was nearly as good")
        best = min(min(losses) for losses in excluded.values() if losses)
        # With the initial state estimated, no start transient is in the cost.
        transient = ("" if self.estimate_x0 else
                     ", or from a start transient left in the cost: set n_transient to "
                     "the settling time of bla_, or estimate_x0=True")
        warn_at_caller(
            f"{type(self).__name__}({self._structure()}): {n_excluded} of {len(judged)} "
            f"starts beat the linear model {where} (best {best:.4g} against "
            f"{linear_loss:.4g}), but {' and '.join(reasons)}; the linear model is kept "
            "(see its start_status_). A model that runs away just beyond the estimation "
            "amplitude often comes from a record too short for the structure (fewer "
            f"states or terms may stay bounded){transient}. check_bounded=False keeps "
            "the best start, if records of your own judge its extrapolation.",
            LinearFallbackWarning)

    def _stays_bounded(self, problem, theta):
        """The boundedness check of ``theta`` (see :func:`stays_bounded`), or
        True without ``check_bounded``."""
        return not self.check_bounded or stays_bounded(problem, theta)

    def _refits(self, shares):
        """Whether the kept start is refined on all the rows after the search."""
        return self.refit and self.max_iter > 0 and max(shares) > 0

    def _row_shares(self, shares):
        """The held-out shares that the fit builds rows for, increasing."""
        return sorted(set(shares) | ({0.0} if self._refits(shares) else set()))

    def _refit(self, problem, theta):
        """``theta`` refined on all the rows of ``problem`` (the held-out ends
        included), sets ``refit_n_iter_``. The start was chosen on the held-out
        ends; the data there then still inform the parameters. A refit that
        fails or leaves the boundedness guard is dropped."""
        try:
            with warnings.catch_warnings():
                # The model was chosen, and its convergence judged, on the
                # held-out ends; a cost on all rows that still falls slowly at
                # max_iter is expected and shows in refit_n_iter_.
                warnings.simplefilter("ignore", ConvergenceWarning)
                refitted, result = fit_from(problem, [theta],
                                            label=f"{self._label} (refit on all rows)",
                                            **self._lm_options(problem))
        except START_ERRORS:
            return theta
        if not self._stays_bounded(problem, refitted):
            return theta
        self.refit_n_iter_ = result.n_iter
        return refitted

    # ------------------------------------------------------------ simulation
    def _fitted_model(self):
        values = {"A": self.A_, "B": self.B_, "C": self.C_, "D": self.D_}
        values.update(self._terms_values())
        return self._model, self._model.pack(values)

    def _steady_sequences(self, starts, U):
        """Which sequences of the input ``U`` are simulated in their periodic
        steady state, as in the fit: for a model fitted with ``period`` and
        ``n_transient``, those whose input repeats with the period (a record
        whose length merely is a multiple of it starts from its initial
        state)."""
        if self.period is None or self.n_transient == 0:
            return np.zeros(len(starts) - 1, dtype=bool)
        return periodic_sequences(U, starts, self.period)

    def _scored_rows(self, starts, X):
        return self._rows_after_transients(starts, X, self.n_transient)

    def _rows_after_transients(self, starts, U, n_transient):
        """The rows of each sequence after its ``n_transient`` samples (an int,
        or one per sequence), but all of those simulated in steady state for
        the input ``U``: as in the cost, every sample of those counts."""
        return transient_mask(starts, np.where(self._steady_sequences(starts, U), 0,
                                               n_transient))

    def _simulate_normalized(self, U, starts, x0, steady_state=False):
        steady = self._steady_sequences(starts, U) & steady_state
        if not steady.any():
            return super()._simulate_normalized(U, starts, x0)
        # Periodic data: every sequence whose input repeats starts in steady
        # state, as in the fit; the others from their initial state.
        index, sim_starts, original = steady_state_rows(
            starts, np.where(steady, self.n_transient, 0))
        Y, X, diverged = super()._simulate_normalized(np.ascontiguousarray(U[index]),
                                                      sim_starts, x0)
        return Y[original], X[original], diverged


def _fit_start(estimator, context, problem, start, seed, label, options):
    """One start: the estimator's candidates, then Levenberg-Marquardt on ``problem``.

    Returns the parameters, the optimiser's result, the warnings the start
    raised, as ``(message, category)`` pairs (they concern the user only if
    this start is the one kept; a start run in a thread has issued them, see
    ``recorded_warnings``), and the seconds it took.
    """
    began = time.perf_counter()
    with recorded_warnings() as caught:
        candidates = estimator._starting_points(context, start, seed)
        theta, result = fit_from(problem, candidates, label=label, **options)
    return theta, result, caught, time.perf_counter() - began


#: How each named extrapolation continues the terms beyond the range of their
#: inputs (see ``RangedTerms``; "bounded" is for polynomial terms only).
_CONTINUATIONS = {"linear": {"reach": 1.0}, "continue": {"reach": np.inf},
                  "bounded": {"reach": 2.0, "held": True}}


def _transients_per_sequence(n_transient, fit_transient, starts):
    """Samples left out of the cost at the start of each sequence:
    ``fit_transient``, at most a tenth of each sequence where it exceeds
    ``n_transient`` (which only the settling time makes it do)."""
    limits = (_MAX_TRANSIENT_SHARE * np.diff(starts)).astype(int)
    return np.maximum(n_transient, np.minimum(fit_transient, limits))


def ranged_prediction_terms(model, theta, U, starts, extrapolation):
    """The terms of ``model`` for prediction, with the range that their inputs
    take when ``theta`` simulates the estimation record ``U``. Beyond it, with
    ``extrapolation="linear"``, the terms go on along their tangents; with
    ``"continue"``, as themselves (the range is then only recorded); with
    ``"bounded"``, as themselves out to twice the range's half-width about
    its centre, held at their value on the edge of that box beyond it."""
    _, X, _ = model.simulate(theta, U, starts)
    S = np.hstack([X, U])
    return model.terms.with_input_range(model.unpack(theta), S[np.all(np.isfinite(S), axis=1)],
                                        **_CONTINUATIONS[extrapolation])


def _warn_if_replaced(params, forwarded):
    """Warn when the ``bla`` settings ``params`` set one of the ``forwarded``
    parameters away from its default to a value that the model's own replaces
    (a grid over ``bla__n_states`` would otherwise run one candidate many
    times)."""
    defaults = BLAEstimator().get_params()
    replaced = [f"{name}={params[name]!r}" for name, value in forwarded.items()
                if not np.array_equal(params[name], defaults[name])
                and not np.array_equal(params[name], value)]
    if replaced:
        warn_at_caller(
            f"bla: {', '.join(replaced)} is replaced by this model's own "
            f"({', '.join(f'{name}={forwarded[name]!r}' for name in forwarded)}); set it on "
            "the model instead.", UserWarning)


def _settling_time(linear, U, Y, starts):
    """Samples over which the slowest mode of the ``linear`` model (keyed by
    block name) that shows in its output decays to ``_SETTLED`` of its size;
    inf when a mode does not decay.

    A mode shows when its part of an output reaches ``_SETTLED`` of that
    output's scale: in RMS, simulated from rest on the input ``U``, or at the
    start of a sequence, from the least-squares initial state that fits the
    output ``Y``. An over-ordered model has slow poles that barely reach the
    output, and the settling time of such a pole would leave a tenth of the
    record out of the cost for nothing; a slow mode that the input barely
    drives but a record starts with shows at that start.
    """
    A = linear["A"]
    radius = spectral_radius(A)
    if radius >= 1.0:
        return np.inf
    poles, shows = _modes_that_show(linear, U, Y, starts)
    moduli = np.abs(poles)
    if not shows.any() or radius == 0.0:
        return 0
    # The slowest mode's own radius when it shows (the same value as ever).
    slowest = radius if shows[moduli >= radius * (1 - _ROUNDING_MARGIN)].any() else np.max(
        moduli[shows])
    return int(np.ceil(np.log(_SETTLED) / np.log(slowest))) if slowest > 0.0 else 0


def _modes_that_show(linear, U, Y, starts):
    """The eigenvalues of ``linear["A"]`` and which of them have a part in an
    output of at least ``_SETTLED`` (normalised units: each output's scale is
    1), in RMS simulated from rest on ``U`` or at the start of a sequence from
    its least-squares initial state. All of them when the modes cannot be told
    apart (defective ``A``) or the simulation diverges."""
    A, B, C, D = (linear[name] for name in "ABCD")
    everything = np.ones(A.shape[0], dtype=bool)
    states, diverged = simulate_linear(A, B, C, D, U, starts,
                                       np.zeros((len(starts) - 1, A.shape[0])))[1:]
    poles, V = np.linalg.eig(A)
    if diverged:
        return poles, everything
    starting = np.atleast_2d(estimate_initial_state(
        A, B, C, D, U, Y, starts, np.ones(len(U), dtype=bool), per_sequence=True)[0])
    try:
        modal = np.linalg.solve(V, states.T)
        modal_start = np.linalg.solve(V, starting.T)
    except np.linalg.LinAlgError:
        return poles, everything
    # A complex pair reaches the output as twice the real part of either
    # mode's term (2 Re(c v xi)), not as the modulus of one.
    part_gain = (C @ V) * np.where(poles.imag != 0.0, 2.0, 1.0)
    with np.errstate(over="ignore", invalid="ignore"):
        driven = np.sqrt(np.mean(np.real(part_gain[:, :, None] * modal) ** 2, axis=2))
        at_start = np.max(np.abs(part_gain[:, :, None] * modal_start), axis=2)
        size = np.max(np.maximum(driven, at_start), axis=0)
    # NaN (an overflow of a nearly defective A) counts as showing.
    return poles, ~(size < _SETTLED)


def _similarity_directions(problem):
    """Directions in which a similarity transform of the states leaves the
    output of ``problem`` unchanged: ``n**2``, or, when the problem holds the
    initial states of ``k`` sequences, the ``n**2 - k n`` transforms that
    keep them (taken as independent; none for ``k >= n``)."""
    n = problem.model.n_states
    return n * n - n * min(n, problem.held.size // n)


def n_cost_values(problem):
    """Number of residual values of the simulation error (penalties aside)."""
    return int(problem.fit_rows.sum()) * problem.model.n_outputs


def stays_bounded(problem, theta):
    """Whether the model stays bounded on the fitted records' input enlarged
    ``_GUARD_GAIN`` times about its mean: its output may not leave
    ``_GUARD_RANGE`` times the range of the measured output.

    Models fitted on short records often run away as soon as the input leaves
    the estimation amplitude, while a model in its class that does not is
    nearly as good on the data; the check keeps such models out of the
    selection (the linear model it falls back on is stable).
    """
    Y, _, diverged = _simulate_enlarged(problem, theta, _GUARD_GAIN)
    if diverged:
        return False
    span = np.max(np.abs(problem.Y - problem.Y.mean(axis=0)), axis=0)
    return bool(np.all(np.abs(Y - problem.Y.mean(axis=0)) <= _GUARD_RANGE * span))


def escapes_when_doubled(problem, theta):
    """Whether the model's simulation diverges on the fitted records' input
    enlarged ``_ESCAPE_GAIN`` times about its mean.

    Polynomial models often escape to infinity just beyond the estimation
    amplitude; this asks no accuracy there, only a finite response.
    """
    return bool(_simulate_enlarged(problem, theta, _ESCAPE_GAIN)[2])


def _simulate_enlarged(problem, theta, gain):
    """Outputs, states and divergence flag on the fitted records' input
    enlarged ``gain`` times about its mean."""
    U = problem.U
    mean = U.mean(axis=0)
    return problem.simulate_input(theta, mean + gain * (U - mean))


def _prefer_finite_when_doubled(losses, starts):
    """The starts' held-out ``losses`` with those whose simulation escapes on
    the doubled input set to inf, when a start that does not escape there is
    nearly as good (within ``_ESCAPE_TOLERANCE`` times the best loss);
    otherwise unchanged. ``starts`` holds each start's ``(problem, theta)``.

    A system whose every good model escapes there (a softening cubic, say) is
    fitted as without the check, and a poor start is never preferred for
    staying finite.
    """
    best = min(losses)
    if not np.isfinite(best):
        return losses
    escapes = {i: escapes_when_doubled(*starts[i]) for i, loss in enumerate(losses)
               if loss <= _ESCAPE_TOLERANCE * best}
    if all(escapes.values()) or not any(escapes.values()):
        return losses
    return [np.inf if escapes.get(i, False) else loss for i, loss in enumerate(losses)]


