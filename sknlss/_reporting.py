"""Files written by the benchmark reproductions: result tables and figures."""

import csv
import warnings
from pathlib import Path

import numpy as np

from .exceptions import SimulationDivergedWarning

# The output noise is read from the spectrum above the excited band, from this
# multiple of its upper edge up to the Nyquist frequency.
_QUIET_BAND_FACTOR = 1.5


def noise_level(y, sampling_time, band_edge):
    """Standard deviation of the output noise, from the bins above the excited band.

    Returns None when the band is not known or no bin lies above
    ``1.5 * band_edge``.
    """
    if band_edge is None:
        return None
    spectrum = np.fft.rfft(y - y.mean())
    frequencies = np.fft.rfftfreq(y.size, d=sampling_time)
    quiet = frequencies > _QUIET_BAND_FACTOR * band_edge
    if not quiet.any():
        return None
    return float(np.sqrt(np.mean(np.abs(spectrum[quiet]) ** 2) / y.size))


def _write_table(rows, path):
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def _write_figures(name, benchmark, data, fitted, output):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .benchmarks import _simulate_record
    from .plotting import plot_error_spectrum, plot_frf, plot_simulation

    paths = []
    Ts = data.sampling_time
    record, (X, y, skip) = next(iter(benchmark.records(data).items()))
    # As in the tables: the first samples of the record set the state. A
    # diverging simulation is said once, in the list of models not drawn.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SimulationDivergedWarning)
        simulations = {label: _simulate_record(model, X, y, skip)
                       for label, model in fitted.items()}
    finite = {label: y_sim for label, y_sim in simulations.items()
              if np.all(np.isfinite(y_sim))}
    bla = next((model for model in fitted.values() if hasattr(model, "frf_")), None)
    if bla is not None:
        figure = plot_frf(bla, sampling_time=Ts)
        paths.append(output / f"{name}_bla_frf.png")
        figure.savefig(paths[-1], dpi=120, bbox_inches="tight")
        plt.close(figure)
    figure = plot_simulation(y, finite, sampling_time=Ts, unit=data.get("output_unit"))
    paths.append(output / f"{name}_simulation_{record}.png")
    figure.savefig(paths[-1], dpi=120, bbox_inches="tight")
    plt.close(figure)
    figure = plot_error_spectrum(y, finite, sampling_time=Ts, unit=data.get("output_unit"),
                                 noise_level=noise_level(y, Ts, data.get("excited_band", (None, None))[1]))
    paths.append(output / f"{name}_error_spectrum_{record}.png")
    figure.savefig(paths[-1], dpi=120, bbox_inches="tight")
    plt.close(figure)
    return paths, sorted(set(simulations) - set(finite))


def write_results(name, benchmark, data, rows, fitted, output, out):
    """Write the table (CSV) and, with matplotlib, the figures of one benchmark."""
    # reproduce has created the folder before any fit.
    output = Path(output)
    _write_table(rows, output / f"{name}.csv")
    print(f"Table written to {output / f'{name}.csv'}", file=out)
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        print("matplotlib is not installed (pip install 'sknlss[plot]'): no figures written.",
              file=out)
        return
    paths, diverged = _write_figures(name, benchmark, data, fitted, output)
    if diverged:
        print(f"Not drawn (diverged): {', '.join(diverged)}", file=out)
    print("Figures: " + ", ".join(str(path) for path in paths), file=out)
