"""Benchmark reproductions: the models of the library on the real benchmarks.

Each benchmark fits every model on its estimation record only, with the
estimators' defaults and the model structure of the paper, at several random
states, and reports the RMS error of the simulated output on its test records
as the median and the range over the random states. ``python -m sknlss
reproduce`` is a thin command line over :func:`reproduce`.

- Cascaded Tanks (the paper's protocol): the initial state is estimated on
  the estimation record and reused on the test record (except for the PNLSS
  model without it, the paper's PNLSS); the RMS error is reported
  over all test samples and, as in the nonlinear_benchmarks protocol, over the
  samples after the first ``init_window``, which set the state. Volts.
- Silverbox: every test record is simulated from its start, from the initial
  state that fits its first ``init_window`` samples (the protocol lets them
  set the state: the records start mid-motion, and the oscillator's transient
  from rest outlasts them); the RMS error is reported over the rest, in
  millivolts.

A test record ``(X, y, n_skip)`` with ``n_skip > 0`` is simulated from the
state that :meth:`~sknlss.PNLSSRegressor.estimate_initial_state` fits to its
first ``n_skip`` samples, and scored on the others.

When the measured data cannot be found or downloaded, a simulated stand-in of
the same kind is used instead, and said so.
"""

import math
import numbers
import os
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils._param_validation import HasMethods, validate_params
from sklearn.utils.parallel import Parallel, delayed

from ._validation import POSITIVE_FINITE, Integers
from .datasets import fetch_cascaded_tanks, fetch_silverbox, make_cascaded_tanks, make_duffing
from .exceptions import DataWarning, SimulationDivergedWarning
from .metrics import rms_error

__all__ = ["Benchmark", "evaluate", "format_table", "load_benchmark", "reproduce"]


def _tanks_models():
    from . import BLAEstimator, DecoupledPNLSS, NLLFRRegressor, NLSS2Regressor, PNLSSRegressor

    return [
        ("BLA", lambda seed: BLAEstimator(n_states=3, estimate_x0=True)),
        ("PNLSS", lambda seed: PNLSSRegressor(n_states=3, degree=(2, 3),
                                              random_state=seed)),
        ("PNLSS-I", lambda seed: PNLSSRegressor(n_states=3, degree=(2, 3),
                                                estimate_x0=True, random_state=seed)),
        ("decoupled PNLSS-I", lambda seed: DecoupledPNLSS(n_states=3, rank=5,
                                                          estimate_x0=True,
                                                          random_state=seed)),
        ("NLSS2", lambda seed: NLSS2Regressor(n_states=3, estimate_x0=True,
                                              random_state=seed)),
        ("NL-LFR", lambda seed: NLLFRRegressor(n_states=3, estimate_x0=True,
                                               random_state=seed)),
    ]


def _silverbox_models():
    from . import BLAEstimator, DecoupledPNLSS, NLLFRRegressor, NLSS2Regressor, PNLSSRegressor

    return [
        ("BLA", lambda seed: BLAEstimator(n_states=2)),
        ("PNLSS", lambda seed: PNLSSRegressor(n_states=2, random_state=seed)),
        ("decoupled PNLSS", lambda seed: DecoupledPNLSS(n_states=2, random_state=seed)),
        ("NLSS2", lambda seed: NLSS2Regressor(n_states=2, random_state=seed)),
        ("NL-LFR", lambda seed: NLLFRRegressor(n_states=2, random_state=seed)),
    ]


def _tanks_records(data):
    window = data.init_window
    return {"test": (data.X_test, data.y_test, 0),
            f"test[{window}:]": (data.X_test, data.y_test, window)}


def _silverbox_records(data):
    return {name: (record.X, record.y, data.init_window) for name, record in data.tests.items()}


def _duffing_stand_in(random_state=0):
    """Simulated Duffing oscillator with the Silverbox's fields."""
    data = make_duffing(random_state=random_state)
    data.tests = {"test": data.__class__(X=data.X_test, y=data.y_test)}
    return data


@dataclass
class Benchmark:
    """A benchmark: where its data come from, its models and how it is scored.

    Parameters
    ----------
    title : str
        Name printed with the results.
    fetch : callable
        ``fetch(data_home, download_if_missing=...)`` returns the measured data.
    simulate : callable
        Returns a simulated stand-in of the same kind (used when the data
        cannot be had).
    models : callable
        Returns the list of ``(label, factory)``; ``factory(random_state)``
        returns an unfitted estimator.
    records : callable
        ``records(data)`` returns ``{name: (X, y, n_skip)}``: the test records
        and the samples at their start that set the state and are not scored.
    unit : str, default="V"
        Unit of the reported errors.
    scale : float, default=1.0
        Factor from the data's unit to ``unit``.
    """

    title: str
    fetch: object
    simulate: object
    models: object
    records: object
    unit: str = "V"
    scale: float = 1.0


#: The benchmarks of :func:`reproduce`, by name (``"cascaded_tanks"``,
#: ``"silverbox"``): dict of :class:`Benchmark`.
BENCHMARKS = {
    "cascaded_tanks": Benchmark("Cascaded Tanks", fetch_cascaded_tanks,
                                lambda: make_cascaded_tanks(random_state=0), _tanks_models,
                                _tanks_records, unit="V"),
    "silverbox": Benchmark("Silverbox", fetch_silverbox, _duffing_stand_in,
                           _silverbox_models, _silverbox_records, unit="mV", scale=1e3),
}


def _benchmark(name, argument):
    """The benchmark called ``name``; a ValueError naming ``argument`` for another name."""
    if not (isinstance(name, str) and name in BENCHMARKS):
        raise ValueError(f"{argument} must name one of {sorted(BENCHMARKS)}, got {name!r}.")
    return BENCHMARKS[name]


_OUT = [HasMethods(["write"]), None]
#: joblib's n_jobs: a number of workers, or -1 (one per core) and below; joblib refuses 0.
_N_JOBS = [Integers(1, None, closed="left"), Integers(None, -1, closed="right"), None]


@validate_params(
    {"name": [str], "data_home": [str, os.PathLike, None], "download_if_missing": ["boolean"],
     "out": _OUT},
    prefer_skip_nested_validation=True,
)
def load_benchmark(name, data_home=None, *, download_if_missing=True, out=None):
    """The measured records of a benchmark, or a simulated stand-in when they cannot be had.

    Parameters
    ----------
    name : {"cascaded_tanks", "silverbox"}
        The benchmark.
    data_home : str or path-like, default=None
        First folder searched for the data (see the ``fetch_*`` loaders).
    download_if_missing : bool, default=True
        Whether to download the data when they are absent.
    out : file-like, default=None
        Where to say that simulated data are used; standard output when None.

    Returns
    -------
    data : Bunch
        The records, as the dataset loader returns them.
    source : str
        ``"measured (<file name>)"`` or ``"simulated"``. Only the file's name:
        the text goes into printed tables and logs, where a path of the
        machine says nothing to the reader.
    """
    benchmark = _benchmark(name, "name")
    out = sys.stdout if out is None else out
    try:
        data = benchmark.fetch(data_home, download_if_missing=download_if_missing)
    except FileNotFoundError as exc:
        print(f"{exc}\n", file=out)
        print(f"FALLING BACK TO SIMULATED DATA for {benchmark.title}: the numbers below "
              "are NOT the benchmark's results.\n", file=out)
        return benchmark.simulate(), "simulated"
    filename = data.get("filename")
    return data, "measured" if filename is None else f"measured ({Path(filename).name})"


def _window_state(model, X, y):
    """The initial state that fits the samples ``(X, y)`` at the start of a
    record; the model's own (``x0_``) when there are none, or when the model
    cannot be simulated from any start (its simulation of the record then
    diverges anyway)."""
    if not len(X):
        return None
    try:
        return model.estimate_initial_state(X, y)
    except ValueError:
        return None


def _simulate_record(model, X, y, n_skip):
    """The simulation of a test record from the state that fits its first
    ``n_skip`` samples (see ``_window_state``)."""
    return model.predict(X, x0=_window_state(model, X[:n_skip], y[:n_skip]))


def _fit_and_score(factory, seed, data, records, scale):
    """Fit ``factory(seed)`` on the estimation record and score it on ``records``.

    Returns a dict: ``model``, ``errors`` (scaled RMS error per record, inf
    for a diverging simulation), ``fit_time`` (s) and ``still_improving``
    (whether ``max_iter`` stopped the fit while it was still improving).
    """
    model = factory(seed)
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        # A reproduction runs fixed settings: that a fit stopped at max_iter
        # while still improving is a fact for the table, not advice, and so is
        # what the data say about the settings (the paper's PNLSS without its
        # initial state, whose start transient the cost partly sees).
        warnings.simplefilter("always", ConvergenceWarning)
        warnings.simplefilter("ignore", DataWarning)
        model.fit(data["X_est"], data["y_est"])
    fit_time = time.perf_counter() - start
    for warning in caught:
        if not issubclass(warning.category, ConvergenceWarning):
            warnings.warn_explicit(warning.message, warning.category, warning.filename,
                                   warning.lineno)
    errors = {}
    with warnings.catch_warnings():
        # A diverging simulation is reported as such in the table.
        warnings.simplefilter("ignore", SimulationDivergedWarning)
        for name, (X, y, skip) in records.items():
            errors[name] = scale * rms_error(y[skip:],
                                             _simulate_record(model, X, y, skip)[skip:])
    return {"model": model, "errors": errors, "fit_time": fit_time,
            "still_improving": any(issubclass(w.category, ConvergenceWarning)
                                   for w in caught)}


def _check_random_states(random_states):
    """A ValueError naming ``random_states`` unless it holds non-negative integers."""
    if len(random_states) == 0:
        raise ValueError("random_states must hold at least one random state.")
    for seed in random_states:
        if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, numbers.Integral) or (
                seed < 0):
            raise ValueError(f"random_states must hold non-negative integers, got {seed!r}.")


def _prepare_output(output):
    """Create the folder ``output`` and check that files can be written there:
    before the fits, which take minutes (OSError otherwise)."""
    Path(output).mkdir(parents=True, exist_ok=True)
    tempfile.TemporaryFile(dir=output).close()


def _check_evaluation(data, models, records, random_states):
    """ValueErrors that name the argument of :func:`evaluate` that cannot be used."""
    missing = [key for key in ("X_est", "y_est") if key not in data]
    if missing:
        raise ValueError(f"data must hold the estimation record X_est, y_est; it lacks "
                         f"{', '.join(missing)}.")
    _check_random_states(random_states)
    for label_and_factory in models:
        if not (isinstance(label_and_factory, tuple) and len(label_and_factory) == 2
                and callable(label_and_factory[1])):
            raise ValueError("models must hold (label, factory) pairs, factory(random_state) "
                             f"returning an estimator; got {label_and_factory!r}.")
    for name, record in records.items():
        if not (isinstance(record, tuple) and len(record) == 3):
            raise ValueError(f"records[{name!r}] must be a tuple (X, y, n_skip).")
        n_samples, n_skip = len(record[1]), record[2]
        if (not isinstance(n_skip, numbers.Integral) or isinstance(n_skip, bool)
                or not 0 <= n_skip < n_samples):
            raise ValueError(
                f"records[{name!r}]: n_skip must be an integer from 0 to {n_samples - 1} "
                f"(the record has {n_samples} samples), got {n_skip!r}.")


@validate_params(
    {"data": [HasMethods(["keys"])], "models": [list], "records": [dict],
     "random_states": ["array-like"], "scale": [POSITIVE_FINITE], "n_jobs": _N_JOBS,
     "out": _OUT},
    prefer_skip_nested_validation=True,
)
def evaluate(data, models, records, *, random_states=(0, 1, 2), scale=1.0, n_jobs=None,
             out=None):
    """Fit every model at every random state and summarise its test errors.

    Parameters
    ----------
    data : Bunch or dict
        With ``X_est``, ``y_est``.
    models : list of (str, callable)
        ``(label, factory)``; ``factory(random_state)`` returns an estimator.
    records : dict
        ``{name: (X, y, n_skip)}``, the test records; the first ``n_skip``
        samples (an integer from 0 to ``len(y) - 1``) set the initial state
        and are not scored.
    random_states : sequence of int, default=(0, 1, 2)
        Random states of the fits, at least one.
    scale : float, default=1.0
        Factor applied to the RMS errors (e.g. 1e3 for mV).
    n_jobs : int, default=None
        Number of fits run at once (joblib), over models and random states.
    out : file-like, default=None
        Where to print the results per model; nothing is printed when None.

    Returns
    -------
    rows : list of dict
        One per model: ``model``, ``n_params``, ``fit_time`` (median, s),
        ``fallbacks`` (fits that kept their linear model), ``still_improving``
        (fits stopped by ``max_iter`` while still improving), and per test record
        ``<name>`` (median), ``<name> min``, ``<name> max``; a diverging
        simulation counts as an infinite error.
    fitted : dict
        The fitted model of the first random state, by label.
    """
    _check_evaluation(data, models, records, random_states)
    # Every (model, random state) pair is one job: the slow models do not
    # leave workers idle while the fast ones wait for their turn.
    jobs = [(label, factory, seed) for label, factory in models for seed in random_states]
    results = Parallel(n_jobs=n_jobs)(
        delayed(_fit_and_score)(factory, seed, data, records, scale)
        for _, factory, seed in jobs)
    rows, fitted = [], {}
    for label, _ in models:
        runs = [result for (name, _, _), result in zip(jobs, results) if name == label]
        fitted[label] = runs[0]["model"]
        errors = {name: [value if math.isfinite(value) else math.inf
                         for value in (run["errors"][name] for run in runs)]
                  for name in records}
        row = {"model": label, "n_params": int(fitted[label].n_params_),
               "fit_time": float(np.median([run["fit_time"] for run in runs])),
               "fallbacks": sum(bool(getattr(run["model"], "fell_back_to_linear_", False))
                                for run in runs),
               "still_improving": sum(run["still_improving"] for run in runs)}
        for name, values in errors.items():
            row[name] = float(np.median(values))
            row[f"{name} min"], row[f"{name} max"] = float(min(values)), float(max(values))
        rows.append(row)
        if out is not None:
            print(f"  {label}: {len(random_states)} fit(s), median {row['fit_time']:.1f} s",
                  file=out, flush=True)
    return rows, fitted


@validate_params({"rows": [list], "records": [dict], "unit": [str]},
                 prefer_skip_nested_validation=True)
def format_table(rows, records, unit):
    """The rows of :func:`evaluate` as a text table: median [min, max] per record.

    Parameters
    ----------
    rows : list of dict
        The rows of :func:`evaluate`.
    records : dict
        The test records (their names head the columns).
    unit : str
        Unit of the errors.

    Returns
    -------
    table : str
    """
    header = (["model", "params"] + [f"{name} ({unit})" for name in records]
              + ["fit (s)", "linear kept", "at max_iter"])
    lines = [header]
    for row in rows:
        cells = [row["model"], str(row["n_params"])]
        for name in records:
            values = (row[name], row[f"{name} min"], row[f"{name} max"])
            text = ["diverged" if not math.isfinite(v) else f"{v:.4g}" for v in values]
            cells.append(text[0] if text[1] == text[2] else f"{text[0]} [{text[1]}, {text[2]}]")
        cells.append(f"{row['fit_time']:.1f}")
        cells.append(str(row.get("fallbacks", 0)))
        cells.append(str(row.get("still_improving", 0)))
        lines.append(cells)
    widths = [max(len(line[i]) for line in lines) for i in range(len(header))]
    text = ["  ".join(cell.rjust(width) for cell, width in zip(line, widths)) for line in lines]
    text.insert(1, "  ".join("-" * width for width in widths))
    return "\n".join(text)


@validate_params(
    {"benchmarks": ["array-like"], "data_home": [str, os.PathLike, None],
     "output": [str, os.PathLike, None], "download_if_missing": ["boolean"],
     "random_states": ["array-like"], "n_jobs": _N_JOBS, "out": _OUT},
    prefer_skip_nested_validation=True,
)
def reproduce(benchmarks=("cascaded_tanks", "silverbox"), *, data_home=None, output=None,
              download_if_missing=True, random_states=(0, 1, 2), n_jobs=None, out=None):
    """Fit the models on the benchmarks and print the result tables.

    Parameters
    ----------
    benchmarks : sequence of str, default=("cascaded_tanks", "silverbox")
        Names in :data:`BENCHMARKS`.
    data_home : str or path-like, default=None
        First folder searched for the data.
    output : str or path-like, default=None
        Folder where each benchmark's table (CSV) and figures (PNG, with
        matplotlib) are written, named after the benchmark (``<name>.csv``,
        ``<name>_simulated.csv`` for a simulated stand-in); nothing is written
        when None. It is created and checked for writing before any fit, so
        that a path where files cannot be written fails at once (``OSError``).
    download_if_missing : bool, default=True
        Whether to download the data when they are absent.
    random_states : sequence of int, default=(0, 1, 2)
        Random states of the fits; the tables give the median and the range.
    n_jobs : int, default=None
        Number of fits run at once (joblib), over models and random states.
    out : file-like, default=None
        Where to print; standard output when None.

    Returns
    -------
    tables : dict
        Per benchmark name, the rows of :func:`evaluate`.
    """
    from ._reporting import write_results

    out = sys.stdout if out is None else out
    for name in benchmarks:
        _benchmark(name, "benchmarks")
    _check_random_states(random_states)
    if output is not None:
        _prepare_output(output)
    tables = {}
    for name in benchmarks:
        benchmark = BENCHMARKS[name]
        data, source = load_benchmark(name, data_home, download_if_missing=download_if_missing,
                                      out=out)
        records = benchmark.records(data)
        # Two lines: the header stays readable in an 88-column terminal.
        print(f"{benchmark.title}, data: {source}.\nFitted on the estimation record "
              f"only, random states {list(random_states)}.", file=out, flush=True)
        rows, fitted = evaluate(data, benchmark.models(), records,
                                random_states=random_states, scale=benchmark.scale,
                                n_jobs=n_jobs, out=out)
        print("\n" + format_table(rows, records, benchmark.unit) + "\n", file=out, flush=True)
        tables[name] = rows
        if output is not None:
            # Files of a simulated stand-in say so in their names.
            stem = f"{name}_simulated" if source == "simulated" else name
            write_results(stem, benchmark, data, rows, fitted, output, out)
    return tables
