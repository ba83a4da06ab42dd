"""Robustness: bad and extreme inputs thrown at every public estimator and function.

The contract, for every generated input (shapes, dtypes, non-finite and
extreme values, constant signals, empty records, wrong sequence labels,
out-of-range and wrong-typed hyperparameters, huge model sizes): a call

- raises a ValueError or a TypeError whose message names the offending
  argument,
- or returns a finite result,
- or warns :class:`~sknlss.SimulationDivergedWarning`, the non-finite samples
  of its result being NaN (a metric gives a diverged simulation an infinite
  error, a scorer or ``score`` minus infinity),

and never raises anything else nor lets a NumPy RuntimeWarning (overflow,
invalid value) escape. Cases that could allocate much memory run in a forked
child whose address space is limited to 2 GB, so that a regression fails the
test instead of the machine.

The default hypothesis profile keeps the module fast. The full run is
``SKNLSS_HYPOTHESIS_PROFILE=full pytest tests/test_robustness.py``;
``SKNLSS_ROBUSTNESS_REPORT=<file>`` writes the outcome counts per class of
input there (JSON).
"""

import json
import os
import pickle
import re
import resource
import subprocess
import sys
import warnings
from collections import Counter
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.exceptions import ConvergenceWarning, FitFailedWarning, NotFittedError
from sklearn.utils.validation import check_is_fitted

import sknlss
from sknlss import (
    BLAEstimator,
    DecoupledPNLSS,
    LegendreBasis,
    LinearFallbackWarning,
    NLLFRRegressor,
    NLSS2Regressor,
    PNLSSRegressor,
    PolynomialBasis,
    SimulationDivergedWarning,
    decouple_polynomial,
)
from sknlss import benchmarks, metrics, plotting
from sknlss._core._model import StateSpaceModel
from sknlss._core._optimize import levenberg_marquardt
from sknlss.datasets import fetch_cascaded_tanks, fetch_silverbox, make_cascaded_tanks
from sknlss.model_selection import HoldoutSearch
from sknlss.signals import multisine

pytestmark = pytest.mark.filterwarnings(
    "ignore::sklearn.exceptions.ConvergenceWarning",
    "ignore::sknlss.exceptions.LinearFallbackWarning",
)

# ------------------------------------------------------------------ settings
_PROFILE = os.environ.get("SKNLSS_HYPOTHESIS_PROFILE", "quick")
_HEALTH = [HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much]
settings.register_profile("sknlss-quick", deadline=None, database=None, derandomize=True,
                          suppress_health_check=_HEALTH)
settings.register_profile("sknlss-full", deadline=None, database=None,
                          suppress_health_check=_HEALTH)
if _PROFILE not in ("quick", "full"):
    raise ValueError(
        f"SKNLSS_HYPOTHESIS_PROFILE must be 'quick' or 'full', got {_PROFILE!r}.")


def _examples(quick, full):
    """Settings of a property: ``quick`` examples by default, ``full`` in the full run."""
    return settings(settings.get_profile(f"sknlss-{_PROFILE}"),
                    max_examples=quick if _PROFILE == "quick" else full)


# Cheap settings: the contract does not depend on how far the search goes.
ESTIMATORS = {
    "BLA": lambda: BLAEstimator(),
    "PNLSS": lambda: PNLSSRegressor(n_states=1, degree=2, max_iter=2, n_init=1),
    "NLSS2": lambda: NLSS2Regressor(n_states=1, max_iter=2, n_init=1, random_state=0),
    "Decoupled": lambda: DecoupledPNLSS(
        n_states=1, rank=1, max_iter=2, n_init=1, n_restarts=1, n_sampling_points=40,
        pnlss=PNLSSRegressor(degree=2, max_iter=2, n_init=1), random_state=0),
    "NL-LFR": lambda: NLLFRRegressor(n_states=1, max_iter=2, n_init=1, random_state=0),
    "HoldoutSearch": lambda: HoldoutSearch(
        PNLSSRegressor(n_states=1, degree=2, max_iter=2, n_init=1),
        validation_fractions=(0.25, 0.3)),
}

# Warnings the library documents; anything else, in particular a NumPy
# RuntimeWarning, breaks the contract.
_DOCUMENTED = (SimulationDivergedWarning, LinearFallbackWarning, ConvergenceWarning,
               FitFailedWarning)

#: Outcome counts per class of input (one per generated input), for the report.
TALLY = Counter()
#: The heaviest case run in a capped child: its peak resident memory.
PEAK = {"bytes": 0, "case": None}


@pytest.fixture(scope="module", autouse=True)
def _report():
    yield
    path = os.environ.get("SKNLSS_ROBUSTNESS_REPORT")
    if path:
        counts = {}
        for (kind, outcome), count in sorted(TALLY.items()):
            counts.setdefault(kind, {})[outcome] = count
        peak = {"case": PEAK["case"], "peak_rss_mb": round(PEAK["bytes"] / 2**20)}
        with open(path, "w", encoding="utf-8") as report:
            json.dump({"profile": _PROFILE, "counts": counts, "heaviest": peak}, report,
                      indent=2)


# ------------------------------------------------------------------ contract
def _names_one_of(error, names):
    message = str(error)
    named = [name for name in names
             if re.search(rf"(?<![\w.]){re.escape(name)}(?!\w)", message)]
    assert named, f"{type(error).__name__} does not name any of {sorted(names)}: {message}"


def _numbers(result):
    """The numeric arrays in a result (arrays, floats, and tuples of them)."""
    if isinstance(result, (tuple, list)):
        return [array for item in result for array in _numbers(item)]
    if isinstance(result, (float, np.floating, np.ndarray)):
        return [np.asarray(result, dtype=np.float64)]
    return []


def run(call, names, *, infinite_means_diverged=False):
    """Call ``call()`` under the contract and return ``(outcome, result)``; the
    outcome is the error's type name, ``"finite"`` or ``"warning"`` (a
    divergence, its samples marked NaN)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            result = call()
        except (ValueError, TypeError) as error:
            _names_one_of(error, names)
            # scikit-learn's InvalidParameterError is both; it counts as a ValueError.
            return ("ValueError" if isinstance(error, ValueError) else "TypeError"), None
    undocumented = [f"{w.category.__name__}: {w.message} ({w.filename}:{w.lineno})"
                    for w in caught
                    if not issubclass(w.category, _DOCUMENTED)
                    and issubclass(w.category, RuntimeWarning)]
    assert not undocumented, undocumented
    diverged = any(issubclass(w.category, SimulationDivergedWarning) for w in caught)
    for values in _numbers(result):
        bad = ~np.isfinite(values)
        if infinite_means_diverged:
            # A metric's infinite error, or a score of minus infinity, for a
            # simulation that diverged.
            bad &= ~np.isinf(values)
        elif bad.any():
            assert diverged, "non-finite result without a SimulationDivergedWarning"
            assert np.all(np.isnan(values[bad])), "non-finite samples must be NaN"
            bad[:] = False
        assert not bad.any(), f"non-finite result: {values}"
    return ("warning" if diverged else "finite"), result


def run_input(kind, *calls):
    """Run the calls made with one generated input, each ``(call, names,
    infinite_means_diverged)`` and each only when the one before it returned,
    and count the input's outcome under ``kind``: the error that stopped it,
    or ``"warning"`` when a call warned of a divergence, else ``"finite"``.
    A call is a function of the result of the one before it."""
    outcomes, result = [], None
    for call, names, *infinite in calls:
        outcome, result = run(lambda: call(result), names,
                              infinite_means_diverged=bool(infinite and infinite[0]))
        outcomes.append(outcome)
        if outcome.endswith("Error"):
            break
    overall = outcomes[-1] if outcomes[-1].endswith("Error") else (
        "warning" if "warning" in outcomes else "finite")
    TALLY[kind, overall] += 1
    return overall, result


# --------------------------------------------------------------------- data
def _clean_record(seed, n_samples, n_inputs, n_outputs):
    """A record of a stable, weakly nonlinear system with a little noise."""
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n_samples, n_inputs))
    y = np.zeros((n_samples, n_outputs))
    for t in range(1, n_samples):
        y[t] = (0.6 * y[t - 1] + 0.2 * np.tanh(y[t - 1])
                + X[t - 1].sum() * np.arange(1, n_outputs + 1))
    y += 0.01 * rng.standard_normal(y.shape)
    return X, y


@st.composite
def records(draw, min_samples=2, max_samples=120):
    n = draw(st.integers(min_samples, max_samples))
    n_inputs, n_outputs = draw(st.integers(1, 2)), draw(st.integers(1, 2))
    X, y = _clean_record(draw(st.integers(0, 2**16)), n, n_inputs, n_outputs)
    return X, (y[:, 0] if n_outputs == 1 and draw(st.booleans()) else y)


def _as_dtype(values, dtype):
    if dtype == "str letters":
        return np.full(values.shape, "a")
    if dtype == "str numbers":
        return values.astype(str)
    if dtype == "object None":
        out = values.astype(object)
        out.flat[:1] = None
        return out
    if dtype == "list":
        return values.tolist()
    return values.astype(dtype)


_DTYPES = ["float32", "int64", "bool", "object", "complex128", "str letters", "str numbers",
           "object None", "list"]


@st.composite
def bad_dtypes(draw):
    X, y = draw(records(min_samples=10))
    target = draw(st.sampled_from(["X", "y"]))
    dtype = draw(st.sampled_from(_DTYPES))
    if target == "X":
        X = _as_dtype(X, dtype)
    else:
        y = _as_dtype(y, dtype)
    return X, y, None


@st.composite
def non_finite(draw):
    X, y = draw(records(min_samples=10))
    values = X if draw(st.booleans()) else y
    flat = values.reshape(-1)
    for _ in range(draw(st.integers(1, 3))):
        flat[draw(st.integers(0, flat.size - 1))] = draw(st.sampled_from([np.nan, np.inf,
                                                                            -np.inf]))
    return X, y, None


@st.composite
def magnitudes(draw):
    X, y = draw(records(min_samples=10))
    X = X * 10.0 ** draw(st.integers(-300, 300))
    y = y * 10.0 ** draw(st.integers(-300, 300))
    if draw(st.booleans()):
        # One sample at the edge of the floating-point range.
        values = X if draw(st.booleans()) else y
        values.reshape(-1)[draw(st.integers(0, values.size - 1))] = draw(
            st.sampled_from([1e300, -1e300, 1.7e308, 5e-324]))
    return X, y, None


@st.composite
def constant(draw):
    X, y = draw(records(min_samples=10))
    level = draw(st.sampled_from([0.0, 1.0, -3.5, 1e200]))
    if draw(st.booleans()):
        X[:, draw(st.integers(0, X.shape[1] - 1))] = level
    else:
        Y = y.reshape(len(y), -1)  # a view: y changes with it
        Y[:, draw(st.integers(0, Y.shape[1] - 1))] = level
    return X, y, None


@st.composite
def shapes(draw):
    X, y = draw(records(min_samples=2, max_samples=20))
    case = draw(st.sampled_from(["X 1-D", "X 3-D", "y 3-D", "y short", "empty", "one sample",
                                 "no input", "no output", "scalar X", "None X", "None y",
                                 "tiny"]))
    if case == "X 1-D":
        X = X[:, 0]
    elif case == "X 3-D":
        X = X[:, :, None]
    elif case == "y 3-D":
        y = y.reshape(len(y), -1)[:, :, None]
    elif case == "y short":
        y = y[:-1]
    elif case == "empty":
        X, y = X[:0], y[:0]
    elif case == "one sample":
        X, y = X[:1], y[:1]
    elif case == "no input":
        X = X[:, :0]
    elif case == "no output":
        y = y.reshape(len(y), -1)[:, :0]
    elif case == "scalar X":
        X = 1.0
    elif case == "None X":
        X = None
    elif case == "None y":
        y = None
    else:
        X, y = X[:3], y[:3]
    return X, y, None


@st.composite
def sequence_ids(draw):
    X, y = draw(records(min_samples=12))
    n = len(X)
    case = draw(st.sampled_from(["short", "2-D", "split label", "fractional", "strings", "NaN",
                                 "booleans", "singletons", "negative", "valid"]))
    sequence_id = {
        "short": lambda: np.zeros(n - 1, dtype=int),
        "2-D": lambda: np.zeros((n, 2), dtype=int),
        "split label": lambda: np.r_[np.zeros(n // 3), np.ones(n // 3),
                                     np.zeros(n - 2 * (n // 3))].astype(int),
        "fractional": lambda: np.linspace(0, 1.5, n),
        "strings": lambda: np.repeat(["a", "b"], [n // 2, n - n // 2]),
        "NaN": lambda: np.r_[np.zeros(n - 1), np.nan],
        "booleans": lambda: np.arange(n) >= n // 2,
        "singletons": lambda: np.arange(n),
        "negative": lambda: np.repeat([-5, 7], [n // 2, n - n // 2]),
        "valid": lambda: np.repeat([0, 1], [n // 2, n - n // 2]),
    }[case]()
    return X, y, sequence_id


_DATA = {"dtype": bad_dtypes(), "non-finite": non_finite(), "magnitude": magnitudes(),
         "constant": constant(), "shape": shapes(), "sequence_id": sequence_ids()}


def _fit_and_use(kind, name, X, y, sequence_id):
    """Fit, then predict and score on the same data, each under the contract."""
    estimator = ESTIMATORS[name]()
    inner = estimator.estimator if isinstance(estimator, HoldoutSearch) else estimator
    run_input(
        kind,
        (lambda _: estimator.fit(X, y, sequence_id=sequence_id),
         {"X", "y", "sequence_id", *inner.get_params()}),
        (lambda fitted: (fitted.predict(X, sequence_id=sequence_id), fitted),
         {"X", "sequence_id"}),
        (lambda previous: previous[1].score(X, y, sequence_id=sequence_id),
         {"X", "y", "sequence_id", "n_transient"}, True),
    )


@pytest.mark.parametrize("kind", sorted(_DATA))
@pytest.mark.parametrize("name", sorted(ESTIMATORS))
def test_fit_on_bad_data(kind, name):
    @_examples(quick=3, full=30)
    @given(data=_DATA[kind])
    def check(data):
        _fit_and_use(kind, name, *data)

    check()


# ------------------------------------------------------ predicting hostile data
_FITTED = {}


def _fitted(name):
    """Each estimator fitted once on a clean record."""
    if name not in _FITTED:
        X, y = _clean_record(0, 200, 1, 1)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            _FITTED[name] = ESTIMATORS[name]().fit(X, y[:, 0])
    return _FITTED[name]


@st.composite
def prediction_inputs(draw):
    n = draw(st.integers(0, 60))
    X = np.random.default_rng(draw(st.integers(0, 2**16))).standard_normal((n, 1))
    X = X * 10.0 ** draw(st.integers(-300, 300))
    case = draw(st.sampled_from(["plain", "dtype", "shape", "x0", "sequence_id"]))
    x0, sequence_id = None, None
    if case == "dtype":
        X = _as_dtype(X, draw(st.sampled_from(_DTYPES)))
    elif case == "shape":
        X = draw(st.sampled_from([X[:, 0], X[:, :, None], np.hstack([X, X]), X[:, :0]]))
    elif case == "x0":
        x0 = draw(st.sampled_from([np.zeros(5), np.full(1, np.nan), np.full(1, 1e300),
                                   np.full((2, 1), 1.0), "a", np.ones(1)]))
    elif case == "sequence_id" and n:
        sequence_id = draw(st.sampled_from([np.zeros(n + 1), np.arange(n) % 2,
                                            np.full(n, 0.5), np.arange(n)]))
    return X, x0, sequence_id


@pytest.mark.parametrize("name", sorted(ESTIMATORS))
@_examples(quick=10, full=60)
@given(data=prediction_inputs())
def test_predict_hostile_inputs(name, data):
    X, x0, sequence_id = data
    model = _fitted(name)
    run_input("predict", (lambda _: model.predict(X, sequence_id=sequence_id, x0=x0),
                          {"X", "x0", "sequence_id"}))


# ------------------------------------------------------------------ units
@pytest.mark.parametrize("name", ["BLA", "PNLSS", "NL-LFR"])
@_examples(quick=4, full=40)
@given(gain=st.floats(1e-3, 1e3), offset=st.floats(-100.0, 100.0),
       output_gain=st.floats(1e-3, 1e3), output_offset=st.floats(-100.0, 100.0))
def test_predictions_follow_the_units_of_the_signals(name, gain, offset, output_gain,
                                                     output_offset):
    # Fitted on normalised signals, a model does not depend on their units
    # or offsets: measured to 3e-12 of the output's standard deviation. (Not
    # NLSS2: its networks' static fits turn the last-bit differences into
    # other networks, see the user guide. Not a sign change either: it may
    # let another random start win.)
    X, y = _clean_record(0, 200, 1, 1)
    reference = _fitted(name).predict(X)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scaled = ESTIMATORS[name]().fit(gain * X + offset, output_gain * y[:, 0] + output_offset)
    predicted = (scaled.predict(gain * X + offset) - output_offset) / output_gain
    np.testing.assert_allclose(predicted, reference, rtol=0, atol=1e-8 * np.std(y))


# ------------------------------------------------------------- hyperparameters
# Huge sizes are thrown at the models in a capped child (test_huge_models).
_HOSTILE = [True, False, -1, 0, 1, 1.5, np.nan, np.inf, "a", None, [], {}, object(), -1e300,
            2.5, np.uint64(3)]


@st.composite
def hyperparameters(draw):
    name = draw(st.sampled_from(sorted(ESTIMATORS)))
    estimator = ESTIMATORS[name]()
    params = sorted(key for key in estimator.get_params(deep=False)
                    if key not in ("verbose", "n_jobs"))
    param = draw(st.sampled_from(params))
    return name, param, draw(st.sampled_from(_HOSTILE))


@_examples(quick=25, full=150)
@given(case=hyperparameters())
def test_hostile_hyperparameters(case):
    name, param, value = case
    X, y = _clean_record(1, 60, 1, 1)
    estimator = ESTIMATORS[name]().set_params(**{param: value})
    run_input("hyperparameter", (lambda _: estimator.fit(X, y[:, 0]), {param, "X", "y"}),
              (lambda fitted: fitted.predict(X), {"X"}))


# ------------------------------------------------------------- huge model sizes
_CAP = 2 * 2**30


def in_capped_child(function):
    """Run ``function()`` in a forked child limited to 2 GB of address space.

    Returns what it returned (or the exception it raised) and the child's
    peak resident memory in bytes.
    """
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        os.close(read_end)
        status = 0
        try:
            resource.setrlimit(resource.RLIMIT_AS, (_CAP, _CAP))
            try:
                outcome = function()
            except BaseException as error:  # noqa: BLE001 - every outcome goes back
                outcome = error
            peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
            payload = pickle.dumps((outcome, peak))
        except BaseException as error:  # noqa: BLE001
            payload = pickle.dumps((RuntimeError(f"unpicklable outcome: {error!r}"), 0))
            status = 1
        with os.fdopen(write_end, "wb") as pipe:
            pipe.write(payload)
        os._exit(status)
    os.close(write_end)
    with os.fdopen(read_end, "rb") as pipe:
        payload = pipe.read()
    os.waitpid(pid, 0)
    return pickle.loads(payload)


_HUGE = {
    "PNLSS": ("n_states", "degree", "state_terms"),
    "NLSS2": ("n_states", "n_neurons"),
    "NL-LFR": ("n_states", "n_branches", "basis"),
    "Decoupled": ("n_states", "rank", "branch_degree"),
}


@st.composite
def huge_models(draw):
    name = draw(st.sampled_from(sorted(_HUGE)))
    param = draw(st.sampled_from(_HUGE[name]))
    size = draw(st.sampled_from([10**3, 10**4, 10**6, 10**9, 10**12]))
    if param == "degree":
        value = (2, draw(st.integers(3, 1023)))
    elif param == "state_terms":
        value = np.array([[min(size, 1023), 0]] if size < 10**6 else [[size, 0]])
    elif param == "basis":
        value = draw(st.sampled_from([PolynomialBasis, LegendreBasis]))(size)
    else:
        value = size
    return name, param, value


def _fit_huge(name, param, value):
    """The prediction of the fitted model and whether it warned of a divergence."""
    X, y = _clean_record(2, 400, 1, 1)
    estimator = ESTIMATORS[name]().set_params(**{param: value})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        estimator.fit(X, y[:, 0])
        y_pred = estimator.predict(X)
    return y_pred, any(issubclass(w.category, SimulationDivergedWarning) for w in caught)


@_examples(quick=4, full=40)
@given(case=huge_models())
def test_huge_models(case):
    name, param, value = case
    outcome, peak = in_capped_child(lambda: _fit_huge(name, param, value))
    if peak > PEAK["bytes"]:
        PEAK.update(bytes=peak, case=f"{name}({param}={value!r})")
    if isinstance(outcome, tuple):
        y_pred, diverged = outcome
        finite = np.isfinite(y_pred)
        assert finite.all() or (diverged and np.isnan(y_pred[~finite]).all())
        TALLY["model size", "finite" if finite.all() else "warning"] += 1
        return
    assert isinstance(outcome, (ValueError, TypeError)), repr(outcome)
    _names_one_of(outcome, {param})
    TALLY["model size", "ValueError" if isinstance(outcome, ValueError) else "TypeError"] += 1


def test_huge_pnlss_is_refused_before_building_it():
    X, y = _clean_record(3, 2000, 1, 1)
    for n_states in (100, 1000):
        outcome, peak = in_capped_child(
            lambda: PNLSSRegressor(n_states=n_states, max_iter=1, n_init=1).fit(X, y[:, 0]))
        assert isinstance(outcome, ValueError)
        assert re.search(r"n_states=\d+, degree=\(2, 3\)", str(outcome))
        assert "parameters" in str(outcome) and "memory" in str(outcome)
        assert peak < 1 * 2**30


def test_a_bla_refinement_beyond_the_memory_is_refused(monkeypatch):
    # Its Jacobian grows with the lines, the inputs, the outputs and the
    # square of the order: refused by name before it is built.
    monkeypatch.setattr("sknlss._core._memory.available_memory", lambda: 100_000)
    X, y = _clean_record(3, 400, 1, 1)
    with pytest.raises(ValueError, match=r"BLA's model \(n_states=2.*memory.*max_iter=0"):
        BLAEstimator(n_states=2).fit(X, y[:, 0])
    BLAEstimator(n_states=2, max_iter=0).fit(X, y[:, 0])


# ------------------------------------------------------------ public functions
_ARRAYS = [np.zeros(0), np.array([1.0, np.nan]), np.array([1.0, np.inf]), np.ones((2, 2, 2)),
           np.array(["a", "b"]), np.array([1e300, -1e300]), np.array([True, False]), 3.0,
           None, "a", [[1.0, 2.0]], np.arange(5.0), np.arange(5.0)[:, None] * [1, 2]]


@st.composite
def metric_calls(draw):
    function = draw(st.sampled_from([metrics.rms_error, metrics.nrmse, metrics.fit_percent]))
    y_true = draw(st.sampled_from(_ARRAYS))
    y_pred = draw(st.sampled_from(_ARRAYS + [y_true]))
    kwargs = {}
    if draw(st.booleans()):
        kwargs["n_transient"] = draw(st.sampled_from([0, 1, 3, -1, 1.5, True, "2", None]))
    if draw(st.booleans()):
        kwargs["sequence_id"] = draw(st.sampled_from([np.zeros(5), [0, 1], "x", np.nan]))
    if draw(st.booleans()):
        kwargs["multioutput"] = draw(st.sampled_from(["raw_values", "mean", 1]))
    return function, y_true, y_pred, kwargs


@_examples(quick=40, full=200)
@given(case=metric_calls())
def test_metrics(case):
    function, y_true, y_pred, kwargs = case
    run_input("metrics", (lambda _: function(y_true, y_pred, **kwargs),
                          {"y_true", "y_pred", "n_transient", "sequence_id", "multioutput"},
                          True))


@_examples(quick=15, full=60)
@given(metric=st.sampled_from(["rms", "nrmse", "fit", "mse", None, 1]),
       n_transient=st.sampled_from([0, 5, -1, 2.0, True, "1"]))
def test_transient_scorer(metric, n_transient):
    model = _fitted("BLA")
    X, y = _clean_record(4, 40, 1, 1)
    run_input("metrics",
              (lambda _: metrics.make_transient_scorer(metric, n_transient=n_transient),
               {"metric", "n_transient"}),
              (lambda scorer: scorer(model, X, y[:, 0]), {"X", "y", "n_transient"}, True))


@st.composite
def decouple_calls(draw):
    n_vars = draw(st.integers(1, 3))
    exponents = draw(st.sampled_from([
        [[2] + [0] * (n_vars - 1)], [[1] * n_vars + [0]], [[-1] + [2] * (n_vars - 1)],
        [[2.5] + [0] * (n_vars - 1)], [[2] + [0] * (n_vars - 1)] * 2, [["a"] * n_vars],
        [[2000] + [0] * (n_vars - 1)], np.zeros((0, n_vars)), [[3] + [1] * (n_vars - 1)],
    ]))
    n_terms = len(exponents)
    coefficients = draw(st.sampled_from([
        np.ones((1, n_terms)), np.full((2, n_terms), 1e300), np.full((1, n_terms), np.nan),
        np.ones((1, n_terms + 1)), np.ones((1, 1, n_terms)), "a", np.zeros((1, n_terms)),
    ]))
    kwargs = {"rank": draw(st.sampled_from([1, 2, 0, True, 1.5])),
              "n_restarts": 1, "random_state": 0}
    choice = draw(st.sampled_from(["degree", "n_samples", "sampling_points", "none"]))
    if choice == "degree":
        kwargs["degree"] = draw(st.sampled_from([2, 1, 3, 5000, "2", False]))
    elif choice == "n_samples":
        kwargs["n_samples"] = draw(st.sampled_from([1, 10, 0, -3, 2.0]))
    elif choice == "sampling_points":
        kwargs["sampling_points"] = draw(st.sampled_from([
            np.ones((20, n_vars)), np.full((20, n_vars), np.inf), np.ones((20, n_vars + 1)),
            np.ones(20), np.full((20, n_vars), 1e200)]))
    else:
        kwargs["n_samples"] = 60
    return coefficients, exponents, kwargs


@_examples(quick=20, full=100)
@given(case=decouple_calls())
def test_decouple_polynomial(case):
    coefficients, exponents, kwargs = case
    run_input("functions", (lambda _: decouple_polynomial(coefficients, exponents, **kwargs),
                            {"coefficients", "exponents", "sampling_points", "n_samples",
                             *kwargs}))


@st.composite
def multisine_calls(draw):
    kwargs = {}
    for name, values in {
        "n_periods": [1, 2, 0, True, 1.5],
        "n_realizations": [1, 3, 0, "2"],
        "lines": ["odd", "full", "even", [1, 2], [0], [1.5], "random_odd", None],
        "band": [(0.0, 0.45), (0.3, 0.1), 0.2, (np.nan, 0.2), ("a", "b")],
        "rms": [1.0, 0.0, -1.0, np.inf, np.nan, 1e300, 1e-300, "1"],
        "amplitudes": [None, [1.0], lambda f: np.ones_like(f), lambda f: f * np.nan,
                       lambda f: np.full_like(f, 1e300)],
        "group_size": [4, 1, True],
    }.items():
        if draw(st.booleans()):
            kwargs[name] = draw(st.sampled_from(values))
    n = draw(st.sampled_from([64, 2, 3, 0, True, 2.5, 1000]))
    return n, kwargs


@_examples(quick=20, full=100)
@given(case=multisine_calls())
def test_multisine(case):
    n, kwargs = case
    run_input("functions", (lambda _: multisine(n, **kwargs),
                            {"n_samples_per_period", *kwargs}))


@_examples(quick=10, full=40)
@given(name=st.sampled_from(["n_samples", "sampling_time", "process_noise", "overflow",
                             "k", "n_substeps", "x0", "input"]),
       value=st.sampled_from([np.inf, np.nan, -1.0, 0, True, "a", None, [1.0], 1e300]))
def test_make_cascaded_tanks(name, value):
    kwargs = {"n_samples": 64, name: value}
    run_input("functions", (lambda _: make_cascaded_tanks(**kwargs, random_state=0),
                            {name, "n_samples"}))


@pytest.mark.parametrize("fetch", [fetch_cascaded_tanks, fetch_silverbox])
@pytest.mark.parametrize("value", ["no", 0, 1, None, np.nan, [True]])
def test_fetch_refuses_non_boolean_download_flag(fetch, value):
    # Refused before any file is looked for or downloaded.
    outcome, _ = run_input("functions", (
        lambda _: fetch(data_home="/nonexistent", download_if_missing=value),
        {"download_if_missing"}))
    assert outcome == "ValueError"


@st.composite
def plotting_calls(draw):
    function = draw(st.sampled_from([plotting.plot_simulation, plotting.plot_error_spectrum]))
    y_true = draw(st.sampled_from(_ARRAYS))
    y_pred = draw(st.sampled_from(_ARRAYS + [y_true, {}, {"m": y_true}]))
    kwargs = {}
    for name, values in {"sampling_time": [1.0, 0.0, np.inf, -2, "a", True],
                         "output_index": [0, 1, -1, 0.5, True],
                         "unit": ["V", 3], "label": ["m", None]}.items():
        if draw(st.booleans()):
            kwargs[name] = draw(st.sampled_from(values))
    return function, y_true, y_pred, kwargs


@_examples(quick=25, full=120)
@given(case=plotting_calls())
def test_plotting(case):
    plt = pytest.importorskip("matplotlib.pyplot")
    function, y_true, y_pred, kwargs = case
    outcome, figure = run_input("functions", (lambda _: function(y_true, y_pred, **kwargs),
                                              {"y_true", "y_pred", *kwargs}))
    if figure is not None:
        plt.close(figure)


@pytest.mark.parametrize("kwargs", [
    {"sampling_time": np.inf}, {"output_index": True}, {"input_index": -1},
    {"output_index": 5}, {"sampling_time": "4"}])
def test_plot_frf_arguments(kwargs):
    pytest.importorskip("matplotlib")
    outcome, figure = run_input("functions", (
        lambda _: plotting.plot_frf(_fitted("BLA"), **kwargs), set(kwargs)))
    assert outcome == "ValueError" and figure is None


def test_plot_frf_needs_a_fitted_bla():
    bla = SimpleNamespace(frequencies_=np.zeros(0), frf_=np.zeros(0), noise_variance_=None,
                          total_variance_=None)
    outcome, _ = run_input("functions", (lambda _: plotting.plot_frf(bla),
                                         {"bla.frequencies_"}))
    assert outcome == "ValueError"


@pytest.mark.parametrize("call, names", [
    (lambda: benchmarks.load_benchmark(3), {"name"}),
    (lambda: benchmarks.load_benchmark("nowhere", download_if_missing=False), {"name"}),
    (lambda: benchmarks.load_benchmark("silverbox", download_if_missing="no"),
     {"download_if_missing"}),
    (lambda: benchmarks.reproduce("silverbox"), {"benchmarks"}),
    (lambda: benchmarks.reproduce(["nowhere"]), {"benchmarks"}),
    (lambda: benchmarks.format_table("rows", {}, "V"), {"rows"}),
    (lambda: benchmarks.evaluate({}, [], {}, scale=np.inf), {"scale"}),
])
def test_benchmarks_arguments(call, names):
    outcome, _ = run_input("functions", (lambda _: call(), names))
    assert outcome == "ValueError"


# -------------------------------------------------------------- HoldoutSearch
@st.composite
def search_settings(draw):
    return {
        "validation_fractions": draw(st.sampled_from(
            [(0.25, 0.3), (), (0.0,), (1.0,), (np.nan,), ("a",), 0.3, [[0.2, 0.3]]])),
        "param_grid": draw(st.sampled_from(
            [None, [], {}, [{}], {"degree": []}, {"degree": [2, 1]}, {"degree": 2},
             {"validation_fraction": [0.1]}, {"no_such": [1]}, "grid"])),
        "n_jobs": draw(st.sampled_from([None, 1, True])),
    }


@_examples(quick=15, full=80)
@given(params=search_settings())
def test_holdout_search_settings(params):
    X, y = _clean_record(5, 80, 1, 1)
    search = ESTIMATORS["HoldoutSearch"]().set_params(**params)
    outcome, fitted = run_input("search", (lambda _: search.fit(X, y[:, 0]),
                                           {*params, "degree", "no_such",
                                            "validation_fraction"}))
    if fitted is not None:
        assert len(fitted.results_["error"]) == len(fitted.results_["params"])


def test_holdout_search_ranks_a_failing_candidate_last():
    X, y = _clean_record(6, 200, 1, 1)
    search = HoldoutSearch(PNLSSRegressor(n_states=1, max_iter=2, n_init=1),
                           validation_fractions=(0.25,), param_grid={"degree": [1, 2]})
    with pytest.warns(FitFailedWarning, match="1 of 2 candidates failed"):
        search.fit(X, y[:, 0])
    assert search.best_params_["degree"] == 2
    assert search.results_["holdout_score"][0] == -np.inf
    assert "'degree' parameter" in search.results_["error"][0]
    assert search.results_["error"][1] is None
    # When no candidate fits, the first error is raised.
    with pytest.raises(ValueError, match="'degree' parameter"):
        search.set_params(param_grid={"degree": [1]}).fit(X, y[:, 0])


class _Diverging(RegressorMixin, BaseEstimator):
    """A model whose simulation always diverges."""

    def __init__(self, validation_fraction=0.0):
        self.validation_fraction = validation_fraction

    def fit(self, X, y, *, sequence_id=None):
        self.n_features_in_ = np.shape(X)[1]
        return self

    def predict(self, X, *, sequence_id=None, x0=None):
        warnings.warn("diverged", SimulationDivergedWarning)
        return np.full(len(X), np.nan)


def test_holdout_search_warns_when_every_candidate_diverges():
    X, y = _clean_record(7, 200, 1, 1)
    search = HoldoutSearch(_Diverging(), validation_fractions=(0.2, 0.3))
    with pytest.warns(SimulationDivergedWarning, match="every fitted candidate diverges"):
        search.fit(X, y[:, 0])
    assert search.best_index_ == 0 and search.best_score_ == -np.inf


# ------------------------------------------- divergence marked, every estimator
@pytest.mark.parametrize("where", ["state", "output"])
@pytest.mark.parametrize("name", sorted(ESTIMATORS))
def test_diverging_prediction_warns_and_marks_nan(name, where):
    X, y = _clean_record(8, 200, 1, 1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        search_or_model = ESTIMATORS[name]().fit(X, y[:, 0])
    model = getattr(search_or_model, "best_estimator_", search_or_model)
    if where == "state":
        # An unstable linear part: the state grows by 3 at every sample.
        model.A_ = 3.0 * np.eye(model.A_.shape[0])
    else:
        # Bounded states, outputs far beyond the bound.
        model.A_ = 0.0 * model.A_
        model.D_ = np.full_like(model.D_, 1e9)
    with pytest.warns(SimulationDivergedWarning, match="bounded region"):
        y_pred = search_or_model.predict(X)
    bad = ~np.isfinite(y_pred)
    assert bad.any() and np.all(np.isnan(y_pred[bad]))
    # From the first divergent sample to the end of the record.
    assert bad[np.argmax(bad):].all()
    with pytest.warns(SimulationDivergedWarning):
        assert search_or_model.score(X, y[:, 0]) == -np.inf


def test_outputs_beyond_the_floating_point_range_are_a_divergence():
    X, y = _clean_record(9, 200, 1, 1)
    model = BLAEstimator().fit(X, 1e300 * y[:, 0])
    model.y_scale_ = np.full(1, 1e308)
    with pytest.warns(SimulationDivergedWarning):
        y_pred = model.predict(X)
    assert np.isnan(y_pred).any() and not np.isinf(y_pred).any()


# ----------------------------------------------------- interrupted and failed fits
@pytest.mark.parametrize("name, target", [
    ("BLA", "sknlss._estimators._bla.fit_linear_model"),
    ("PNLSS", "sknlss._core._multistart.levenberg_marquardt"),
    ("NLSS2", "sknlss._estimators._nlss2.estimate_states"),
    ("Decoupled", "sknlss._estimators._decoupled.decouple_polynomial"),
    ("NL-LFR", "sknlss._core._multistart.levenberg_marquardt"),
    ("HoldoutSearch", "sknlss._core._multistart.levenberg_marquardt"),
])
def test_interrupted_fit_leaves_the_estimator_unfitted(name, target, monkeypatch):
    X, y = _clean_record(10, 200, 1, 1)
    estimator = ESTIMATORS[name]()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        estimator.fit(X, y[:, 0])

    def interrupt(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(target, interrupt)
    with pytest.raises(KeyboardInterrupt):
        estimator.fit(X, y[:, 0])
    with pytest.raises(NotFittedError):
        check_is_fitted(estimator)
    assert not hasattr(estimator, "_model") and not hasattr(estimator, "_y_was_1d")
    with pytest.raises(NotFittedError):
        estimator.predict(X)


def test_failed_fit_leaves_the_estimator_unfitted():
    X, y = _clean_record(11, 200, 1, 1)
    model = BLAEstimator().fit(X, y[:, 0])
    with pytest.raises(ValueError, match="y is constant"):
        model.fit(X, np.zeros(200))
    with pytest.raises(NotFittedError):
        model.predict(X)


def test_a_failing_start_is_recorded_and_the_others_kept(monkeypatch):
    X, y = _clean_record(12, 300, 1, 1)
    original = PNLSSRegressor._starting_points

    def failing(self, context, start, seed):
        if start == 1:
            raise np.linalg.LinAlgError("singular start")
        return original(self, context, start, seed)

    monkeypatch.setattr(PNLSSRegressor, "_starting_points", failing)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = PNLSSRegressor(n_states=1, degree=2, max_iter=3, n_init=3,
                               random_state=0).fit(X, y[:, 0])
    assert model.start_losses_[1] == np.inf
    assert np.isfinite(model.start_losses_[[0, 2]]).all()
    assert np.isfinite(model.predict(X)).all()


def test_levenberg_marquardt_stops_at_a_non_finite_jacobian():
    calls = []

    def residual(theta, jacobian):
        calls.append(jacobian)
        r = np.array([theta[0] - 1.0, 0.1 * theta[0]])
        if not jacobian:
            return r, None
        J = np.array([[1.0], [0.1]])
        # The Jacobian overflows from the second evaluation on.
        return r, (J if calls.count(True) == 1 else np.full_like(J, np.nan))

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # LAPACK must not see the NaN
        result = levenberg_marquardt(residual, np.array([5.0]), max_iter=10)
    assert result.n_iter == 1 and result.converged
    assert abs(result.theta[0] - 1.0) < abs(5.0 - 1.0)


# ---------------------------------------------------- model size bounds and counts
@pytest.mark.parametrize("estimator", [
    PNLSSRegressor(n_states=3, degree=(2, 3, 4)),
    PNLSSRegressor(n_states=2, degree=3, state_terms="states_only",
                   output_terms="no_cross_products"),
    PNLSSRegressor(n_states=2, state_terms=np.array([[2, 0, 0], [0, 1, 1]]),
                   output_terms="inputs_only"),
    NLSS2Regressor(n_states=3, n_neurons=4),
    NLLFRRegressor(n_states=2, n_branches=3, basis=PolynomialBasis(5, kind="odd")),
    NLLFRRegressor(n_states=2, n_branches=2, basis=LegendreBasis(4)),
])
def test_parameter_counts_match_the_built_models(estimator):
    n_inputs, n_outputs = 1, 2
    terms = estimator._make_terms(n_inputs, n_outputs)
    assert estimator._n_terms_params(n_inputs, n_outputs) == terms.n_params
    model = StateSpaceModel(estimator.n_states, n_inputs, n_outputs, terms)
    assert model.n_params > terms.n_params


def test_too_few_cost_values_keep_the_linear_model():
    X, y = _clean_record(13, 120, 1, 1)
    model = PNLSSRegressor(n_states=2, n_transient=70, validation_fraction=0.3, max_iter=5,
                           n_init=1)
    with pytest.warns(LinearFallbackWarning, match=r"57 parameters but its cost holds only"):
        model.fit(X, y[:, 0])
    assert model.fell_back_to_linear_
    np.testing.assert_array_equal(model.start_losses_, [np.inf])  # no start was made
    assert not model.E_.any() and not model.F_.any()
    assert np.isfinite(model.predict(X)).all()


@pytest.mark.parametrize("Estimator", [PNLSSRegressor, NLSS2Regressor, NLLFRRegressor,
                                       DecoupledPNLSS])
@pytest.mark.parametrize("validation_fraction, held_out", [("auto", "35%"), (0.0, None)])
def test_a_transient_that_leaves_nothing_to_fit(Estimator, validation_fraction, held_out):
    X, y = _clean_record(15, 120, 1, 1)
    # The message names the estimator and the parameters as the user set them.
    expected = rf"{Estimator.__name__}: n_transient=120 leaves no sample to fit"
    if held_out is not None:
        expected += (rf" before the held-out end of each sequence of 100 samples or more "
                     rf"\(validation_fraction='auto' holds out its last {held_out}\)")
    with pytest.raises(ValueError, match=expected + "; the longest sequence has 120"):
        Estimator(n_states=2, n_transient=120,
                  validation_fraction=validation_fraction).fit(X, y[:, 0])


@pytest.mark.parametrize("Estimator", [PNLSSRegressor, NLSS2Regressor, NLLFRRegressor,
                                       DecoupledPNLSS])
def test_messages_of_the_linear_start_name_the_rows_of_X_and_the_hold_out(Estimator):
    # The linear start is fitted on every sequence cut before its held-out
    # end; its messages name the rows of the user's X, and what the hold-out
    # or the delay leaves when they are the likely cause.
    X, y = _clean_record(16, 600, 1, 1)
    y = y[:, 0]
    one_sample = np.r_[np.zeros(300, int), 1, 2 * np.ones(299, int)]
    with pytest.raises(ValueError, match=r"sequence of rows 300 to 300 \(sequence_id\) has 1 "):
        Estimator(n_states=2).fit(X, y, sequence_id=one_sample)
    with pytest.warns(UserWarning, match=r"variance estimate .*rows 597 to 599\)"):
        Estimator(n_states=2, n_init=1, max_iter=1).fit(
            X, y, sequence_id=np.r_[np.zeros(597, int), np.ones(3, int)])
    with pytest.raises(ValueError, match=r"validation_fraction=0.99 leaves 6 of the 600 "):
        Estimator(n_states=2, validation_fraction=0.99).fit(X, y)
    with pytest.raises(ValueError, match=r"input_delay=\[590\] is not shorter than a sequence "
                                         r"of 390 .* validation_fraction='auto' leaves 390 of "):
        Estimator(n_states=2, input_delay=590).fit(X, y)


def test_inputs_in_any_memory_layout_give_the_same_fit():
    # Column sums in one order whatever the layout: a C- and a Fortran-ordered
    # copy of several input columns (a DataFrame holds the latter) once gave
    # offsets a bit apart, which NLSS2's search amplified to a different model.
    X, y = _clean_record(17, 400, 3, 1)
    fits = [BLAEstimator(n_states=2).fit(Z, y[:, 0]) for Z in (X, np.asfortranarray(X))]
    for name in ("u_offset_", "u_scale_", "A_", "B_"):
        np.testing.assert_array_equal(getattr(fits[0], name), getattr(fits[1], name))


def test_booleans_are_not_integers():
    X, y = _clean_record(14, 60, 1, 1)
    for estimator, param in [(PNLSSRegressor(n_states=True), "n_states"),
                             (BLAEstimator(n_states=False), "n_states"),
                             (NLSS2Regressor(n_neurons=True), "n_neurons"),
                             (PNLSSRegressor(n_transient=True), "n_transient")]:
        with pytest.raises(ValueError, match=f"'{param}' parameter .* Got True|Got False"):
            estimator.fit(X, y[:, 0])


def test_public_names_are_covered():
    # A new public estimator or function needs its hostile inputs here.
    covered = {"BLAEstimator", "PNLSSRegressor", "NLSS2Regressor", "DecoupledPNLSS",
               "NLLFRRegressor", "decouple_polynomial", "PolynomialBasis", "LegendreBasis",
               "ChebyshevBasis", "DataWarning", "LinearFallbackWarning",
               "SimulationDivergedWarning"}
    assert set(sknlss.__all__) <= covered
    assert set(metrics.__all__) == {"rms_error", "nrmse", "fit_percent",
                                    "make_transient_scorer"}
    assert set(plotting.__all__) == {"plot_frf", "plot_simulation", "plot_error_spectrum"}


@pytest.mark.slow
def test_imports_and_simulates_where_numba_can_cache_nowhere():
    # A read-only install run by a user without a home folder: numba finds no
    # folder to cache in, and the kernels are compiled in the process instead
    # (those with a signature at import: about 20 s).
    script = """
import sys
sys.path.insert(0, sys.argv[1])
from numba.core import caching
caching.CacheImpl._locator_classes = []
import numpy as np
from sknlss._core import _kernels
from sknlss.datasets import make_duffing
data = make_duffing(n_samples=128, n_test_samples=128, random_state=0)
print(_kernels.CACHE, np.isfinite(data.y_est).all())
"""
    package_parent = os.path.dirname(os.path.dirname(sknlss.__file__))
    done = subprocess.run([sys.executable, "-c", script, package_parent],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["False", "True"]
