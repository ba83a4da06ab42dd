"""Command line: ``python -m sknlss reproduce`` fits the models on Cascaded Tanks.

The benchmark protocol is followed: every model is fitted on the estimation
record only, its initial state estimated there and reused on the test record,
and the RMS error of the simulated output is reported on the whole test record
(and, as in the nonlinear_benchmarks protocol, on the test record without its
first 50 samples).
"""

import argparse
import csv
import json
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from sklearn.exceptions import ConvergenceWarning

from . import BLAEstimator, DecoupledPNLSS, NLSS2Regressor, PNLSSRegressor
from .datasets import load_cascaded_tanks, make_cascaded_tanks
from .metrics import rms_error
from .model_selection import HoldoutSearch

#: Samples of the test record that the nonlinear_benchmarks protocol may use to
#: set the state; its RMS error is computed on the rest.
_BENCHMARK_WINDOW = 50

#: Shares of the end of the estimation record held out to select iterations,
#: starts and settings: every nonlinear model is fitted once per share and the
#: fit with the smallest error on the end that all of them held out (the last
#: 25 %) is kept (:class:`~sknlss.model_selection.HoldoutSearch`). The test
#: record is never used for any choice.
_HOLDOUT_FRACTIONS = (0.25, 0.275, 0.3, 0.325, 0.35)

#: The PNLSS models are fitted on the paper's cost and with the stability
#: penalty and weight decay (weights chosen earlier by the median held-out
#: error over held-out shares 0.25, 0.3 and 0.35); the held-out end decides.
_PNLSS_VARIANTS = [
    {"stability_penalty": [0.0], "weight_decay": [0.0]},
    {"stability_penalty": [1.0], "weight_decay": [0.01]},
]


def _holdout_search(estimator, param_grid=None):
    return HoldoutSearch(estimator, validation_fractions=_HOLDOUT_FRACTIONS,
                         param_grid=param_grid)


#: The models of the comparison (paper Tables 2 and 4): (name, factory
#: returning an unfitted estimator). Each one is fitted on the estimation
#: record only. The BLA order and x0 setting, and the NLSS2 settings, were
#: chosen on the held-out end of the estimation record (see the tests).
MODELS = [
    ("BLA", lambda: BLAEstimator(n_states=2, estimate_x0=True)),
    ("PNLSS", lambda: _holdout_search(
        PNLSSRegressor(n_states=3, degree=(2, 3), center=True, max_iter=300),
        _PNLSS_VARIANTS)),
    ("PNLSS-I", lambda: _holdout_search(
        PNLSSRegressor(n_states=3, degree=(2, 3), center=True, estimate_x0=True,
                       max_iter=300),
        _PNLSS_VARIANTS)),
    ("PNLSS-I decoupled", lambda: _holdout_search(DecoupledPNLSS(
        n_states=3, rank=5, estimate_x0=True, n_init=8,
        pnlss=PNLSSRegressor(degree=(2, 3)), random_state=0))),
    ("NLSS2", lambda: _holdout_search(NLSS2Regressor(
        n_states=3, alpha=0.3, weight_decay=1e-3, refine_linear=True, estimate_x0=True,
        n_init=10, max_iter=300, random_state=0))),
]

_COLUMNS = [
    ("model", "model", "{}"),
    ("n_params", "n_params", "{}"),
    ("rms_est", "RMS est (V)", "{:.4f}"),
    ("rms_test", "RMS test (V)", "{:.4f}"),
    ("rms_test_50", "RMS test[50:] (V)", "{:.4f}"),
    ("fit_time", "fit time (s)", "{:.2f}"),
]


def _load_data(data_home, download, out):
    """The measured records, or simulated ones when they cannot be had."""
    try:
        data = load_cascaded_tanks(data_home, download=download)
    except FileNotFoundError as exc:
        print(f"{exc}\n", file=out)
        print(
            "FALLING BACK TO SIMULATED DATA: make_cascaded_tanks(random_state=0). "
            "The numbers below are NOT the Cascaded Tanks benchmark results.\n",
            file=out,
        )
        return make_cascaded_tanks(random_state=0), "simulated (make_cascaded_tanks)"
    return data, f"measured ({data.filename})"


def _evaluate(name, factory, data):
    """Fit one model; return its table row, the fitted model and its simulations."""
    model = factory()
    start = time.perf_counter()
    with warnings.catch_warnings():
        # The iteration limits are part of the protocol (the iterate is chosen
        # on held-out data), not a sign of an unfinished fit.
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(data.X_est, data.y_est)
    fit_time = time.perf_counter() - start
    y_est = model.predict(data.X_est)
    y_test = model.predict(data.X_test)
    row = {
        "model": name,
        "n_params": int(model.n_params_),
        "rms_est": rms_error(data.y_est, y_est),
        "rms_test": rms_error(data.y_test, y_test),
        "rms_test_50": rms_error(data.y_test[_BENCHMARK_WINDOW:],
                                 y_test[_BENCHMARK_WINDOW:]),
        "fit_time": fit_time,
    }
    return row, model, (y_est, y_test)


def _noise_floor(y, sampling_time):
    """Standard deviation of the output noise, from the bins above the excited band.

    The benchmark input holds no power above 0.0144 Hz; well above that band
    (four times its edge), the output spectrum is the noise floor.
    """
    spectrum = np.fft.rfft(y - y.mean())
    frequencies = np.fft.rfftfreq(y.size, d=sampling_time)
    quiet = frequencies > 4 * 0.0144
    return float(np.sqrt(np.mean(np.abs(spectrum[quiet]) ** 2) / y.size))


def _write_figures(data, fitted, simulations, output, out):
    """Paper-style figures: the BLA's FRF, simulations and error spectra (PNG)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed (pip install 'sknlss[plot]'): "
              "no figures written.", file=out)
        return
    from .plotting import plot_error_spectrum, plot_frf, plot_simulation

    Ts = data.sampling_time
    finite = {name: sims for name, sims in simulations.items()
              if all(np.all(np.isfinite(sim)) for sim in sims)}
    paths = []
    if "BLA" in fitted:
        fig, ax = plt.subplots(figsize=(8, 4.5))
        plot_frf(fitted["BLA"], sampling_time=Ts, ax=ax)
        ax.set_title("Best Linear Approximation (estimation record)")
        paths.append(output / "bla_frf.png")
        fig.savefig(paths[-1], dpi=120, bbox_inches="tight")
        plt.close(fig)
    for record, index, measured in (("estimation", 0, data.y_est),
                                    ("test", 1, data.y_test)):
        fig, ax = plt.subplots(figsize=(10, 5))
        plot_simulation(measured, {name: sims[index] for name, sims in finite.items()},
                        sampling_time=Ts, unit="V", ax=ax)
        ax.set_title(f"Cascaded Tanks, {record} record: simulated outputs and errors")
        paths.append(output / f"simulation_{record}.png")
        fig.savefig(paths[-1], dpi=120, bbox_inches="tight")
        plt.close(fig)
    fig, ax = plt.subplots(figsize=(10, 5))
    plot_error_spectrum(data.y_test, {name: sims[1] for name, sims in finite.items()},
                        noise_level=_noise_floor(data.y_test, Ts), sampling_time=Ts,
                        unit="V", ax=ax)
    ax.set_title("Test record: spectra of the output and of the simulation errors")
    paths.append(output / "error_spectrum_test.png")
    fig.savefig(paths[-1], dpi=120, bbox_inches="tight")
    plt.close(fig)
    skipped = sorted(set(simulations) - set(finite))
    if skipped:
        print(f"Not drawn (diverged): {', '.join(skipped)}", file=out)
    print("Figures: " + ", ".join(str(path) for path in paths), file=out)


def _print_selection(fitted, out):
    """The settings each search kept, chosen on the held-out end of the estimation record."""
    searches = {name: model for name, model in fitted.items()
                if isinstance(model, HoldoutSearch)}
    if not searches:
        return
    print("\nKept by the held-out end of the estimation record (never fitted):",
          file=out)
    for name, search in searches.items():
        settings = ", ".join(f"{key}={value}" for key, value in search.best_params_.items())
        rms = search.results_["holdout_rms"][search.best_index_]
        print(f"  {name}: {settings} (RMS {rms:.4f} on the last "
              f"{search.holdout_fraction_:.0%})", file=out)


def _format_cell(value, fmt):
    if isinstance(value, float) and not math.isfinite(value):
        return "diverged"
    return fmt.format(value)


def _format_table(rows):
    cells = [[header for _, header, _ in _COLUMNS]]
    cells += [[_format_cell(row[key], fmt) for key, _, fmt in _COLUMNS] for row in rows]
    widths = [max(len(line[i]) for line in cells) for i in range(len(_COLUMNS))]
    lines = ["  ".join(cell.rjust(width) for cell, width in zip(line, widths))
             for line in cells]
    lines.insert(1, "  ".join("-" * width for width in widths))
    return "\n".join(lines)


def _write_results(rows, source, output):
    output.mkdir(parents=True, exist_ok=True)
    with open(output / "cascaded_tanks.csv", "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=[key for key, _, _ in _COLUMNS])
        writer.writeheader()
        writer.writerows(rows)
    (output / "cascaded_tanks.json").write_text(
        json.dumps({"data": source, "results": rows}, indent=2), encoding="utf-8"
    )


def reproduce(data_home=None, output=None, *, download=True, models=None, out=None):
    """Fit the models on Cascaded Tanks and print the comparison table.

    Parameters
    ----------
    data_home : str or path-like, default=None
        First folder searched for the data (see
        :func:`sknlss.datasets.load_cascaded_tanks`).
    output : str or path-like, default=None
        Folder where ``cascaded_tanks.csv``, ``cascaded_tanks.json`` and the
        figures (PNG, with matplotlib) are written; nothing is written when
        None.
    download : bool, default=True
        Whether to download the data when they are absent.
    models : list of (str, callable), default=None
        The models to compare; None means :data:`MODELS`.
    out : file-like, default=None
        Where to print; standard output when None.

    Returns
    -------
    rows : list of dict
        One dict per model with the keys ``model``, ``n_params``, ``rms_est``,
        ``rms_test``, ``rms_test_50`` and ``fit_time``.
    """
    out = sys.stdout if out is None else out
    data, source = _load_data(data_home, download, out)
    print(f"Cascaded Tanks, data: {source}", file=out)
    print("Fitted on the estimation record only; x0 estimated there and reused on "
          "the test record.\n", file=out)
    rows, fitted, simulations = [], {}, {}
    for name, factory in MODELS if models is None else models:
        row, fitted[name], simulations[name] = _evaluate(name, factory, data)
        rows.append(row)
        print(f"  fitted {name} in {row['fit_time']:.2f} s", file=out, flush=True)
    print("\n" + _format_table(rows), file=out)
    _print_selection(fitted, out)
    if output is not None:
        output = Path(output)
        _write_results(rows, source, output)
        print(f"\nResults written to {output.resolve()}", file=out)
        _write_figures(data, fitted, simulations, output, out)
    return rows


def main(argv=None):
    """Entry point of ``python -m sknlss`` and of the ``sknlss`` command.

    Parameters
    ----------
    argv : list of str, default=None
        Command-line arguments; ``None`` reads ``sys.argv``.

    Returns
    -------
    status : int
        Exit status, 0 on success.
    """
    parser = argparse.ArgumentParser(
        prog="sknlss",
        description="Nonlinear state-space identification (sknlss).",
    )
    commands = parser.add_subparsers(dest="command", required=True)
    command = commands.add_parser(
        "reproduce",
        help="fit the models on the Cascaded Tanks benchmark and print their errors",
        description=__doc__,
    )
    command.add_argument("--data-home", default=None,
                         help="folder holding cascaded_tanks/dataBenchmark.mat "
                              "(default: $SKNLSS_DATA, then the user cache folder)")
    command.add_argument("--output", default="sknlss_output",
                         help="folder for the results (CSV, JSON and PNG figures; "
                              "default: %(default)s)")
    command.add_argument("--no-download", action="store_true",
                         help="never download the data; simulate them when absent")
    args = parser.parse_args(argv)
    reproduce(args.data_home, args.output, download=not args.no_download)
    return 0


if __name__ == "__main__":
    sys.exit(main())
