"""NL-LFR on the Silverbox, side by side with freq-statespace.

freq-statespace (PyPI, JAX) identifies the same model structure as
:class:`~sknlss.NLLFRRegressor`: a linear state-space model with a static
nonlinearity in feedback. Its published Silverbox recipe takes six steady-state
periods of 8192 samples from the estimation record (each after a transient of
500 samples), fits the BLA by frequency-domain subspace identification and
optimisation, initialises one polynomial branch of degree 3 by frequency-domain
inference and learning, and optimises all parameters on the time-domain
simulation error (100 Levenberg-Marquardt iterations). This script runs that
recipe with the package's defaults on the estimation record of
:func:`~sknlss.datasets.fetch_silverbox`, and ``NLLFRRegressor(n_states=2)``
with its defaults, at random states 0-2: on the same record (all of it, as in
the accuracy benchmark), and on the recipe's six periods as six sequences
(``period=8192``, each simulated in steady state after 500 samples of its own
end); with the recipe's branch structure, a cubic polynomial of ``tanh(z)``
with its constant (``basis=LegendreBasis(3, constant=True)``); and with the
recipe's initialisation (``init="inference"``), with either basis, the
recipe's also with ``extrapolation="continue"`` (the basis itself beyond the
estimation range, as freq-statespace extrapolates).

Both models are scored on the three test records, RMS error over ``y[50:]`` in
mV, under two protocols:

- *window state*: the state fits the first 50 samples of the record (the
  accuracy benchmark's protocol, ``estimate_initial_state``); freq-statespace
  has no initial-state estimation, so it has no entry here;
- *zero state*: the simulation starts from the zero state, and the first 50
  samples are not scored.

The fit times are wall-clock seconds on this machine, compilation included for
freq-statespace (JAX compiles at the first call).

Needs ``pip install freq-statespace`` (which installs JAX) and the measured
Silverbox data (``SKNLSS_DATA`` or the user cache folder). Takes about five
minutes on two cores.

Run: ``python benchmarks/bench_peers.py``; with ``--output FILE`` the printed
table is also written to FILE, headed by the machine and versions it was
measured with.
"""

import argparse
import contextlib
import io
import time
import warnings
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np

from bench_pnlss import _machine

from sknlss import LegendreBasis, NLLFRRegressor
from sknlss.benchmarks import _simulate_record
from sknlss.datasets import fetch_silverbox
from sknlss.metrics import rms_error

RANDOM_STATES = (0, 1, 2)
# The recipe's layout of the estimation record (freq-statespace's Silverbox
# loader): the first period starts 164 samples in, the next ones 500 samples
# (a transient) after the end of the previous one.
PERIOD = 8192
N_REALIZATIONS = 6
FIRST_START = 164
GAP = 500
#: The multisine's excited DFT lines: the odd ones from 1 to 2683.
EXCITED_LINES = np.arange(1, 2 * 1342, 2)


def _steady_state_periods(u, y):
    """The recipe's six periods, shaped (N, 1, R, 1) as freq-statespace wants."""
    starts = FIRST_START + (PERIOD + GAP) * np.arange(N_REALIZATIONS)
    U = np.stack([u[s:s + PERIOD] for s in starts], axis=1)
    Y = np.stack([y[s:s + PERIOD] for s in starts], axis=1)
    return U[:, None, :, None], Y[:, None, :, None]


def _fit_nllfr(X, y, sequence_id, settings, seed):
    start = time.perf_counter()
    model = NLLFRRegressor(n_states=2, random_state=seed, **settings)
    model.fit(X, y, sequence_id=sequence_id)
    return model, time.perf_counter() - start


def _fit_freq_statespace(data, U, Y):
    import freq_statespace as fss

    start = time.perf_counter()
    io_data = fss.create_data_object(U, Y, EXCITED_LINES, 1.0 / data.sampling_time)
    bla = fss.lin.optimize(fss.lin.subspace_id(io_data, 2), io_data)
    phi = fss.static.basis.Polynomial(1, degree=3)
    model = fss.nonlin.inference_and_learning(bla, io_data, phi, 1)
    model = fss.nonlin.optimize(model, io_data)
    return model, time.perf_counter() - start


def _mv(y, y_model, skip):
    y_model = np.ravel(y_model)
    if not np.all(np.isfinite(y_model)):
        return np.inf
    return 1e3 * rms_error(y[skip:], y_model[skip:])


def _sknlss_errors(model, record, skip):
    return {"window state": _mv(record.y, _simulate_record(model, record.X, record.y, skip),
                                skip),
            "zero state": _mv(record.y, model.predict(record.X), skip)}


def _row(label, errors, names, fit_time, n_params):
    cells = "".join(f"{_cell(errors, name):>13}" for name in names)
    return f"{label:<60}{cells}{fit_time:>10.1f}{n_params:>8}"


def _cell(errors, name):
    values = [e[name] for e in errors]
    return f"{np.median(values):.4f}" if np.all(np.isfinite(values)) else "diverged"


def _versions(*packages):
    """The line naming the peer packages' versions, the first one the peer itself."""
    try:
        peers = ", ".join(f"{name} {version(name)}" for name in packages)
    except PackageNotFoundError:
        peers = f"{packages[0]} not installed"
    return f"Peer versions: {peers}\n"


def _check_peer(parser, args, package):
    """Refuse ``--output`` without the peer's package: the file would replace
    a published table with one that lacks its side-by-side rows. Without
    ``--output``, the sknlss rows are printed and the peer said missing."""
    if args.output is None:
        return
    try:
        version(package)
    except PackageNotFoundError:
        parser.error(f"--output {args.output} needs {package} (pip install {package}): "
                     "without it the table would have no side-by-side rows.")


def _publish(lines, output, peers):
    """Print the table's lines as they come; with ``output``, also write them to
    that file, headed by the machine and the versions of the ``peers``."""
    printed = []
    for line in lines:
        print(line, flush=True)
        printed.append(line)
    if output is not None:
        output.parent.mkdir(parents=True, exist_ok=True)
        output.write_text(_machine() + _versions(*peers) + "\n" + "\n".join(printed) + "\n",
                          encoding="utf-8")


def _table(data):
    """The lines of the side-by-side table."""
    skip = data.init_window
    names = list(data.tests)
    header = f"{'model, data (protocol)':<60}" + "".join(f"{n:>13}" for n in names) \
        + f"{'fit (s)':>10}{'params':>8}"
    yield ("Silverbox, NL-LFR with 2 states: RMS error over y[50:] (mV); sknlss: median "
           f"over random states {list(RANDOM_STATES)}\n")
    yield header
    yield "-" * len(header)

    U, Y = _steady_state_periods(data.X_est.ravel(), data.y_est)
    layouts = {
        "whole record": (data.X_est, data.y_est, None, {}),
        "six periods": (U.transpose(2, 0, 1, 3).reshape(-1, 1), Y.transpose(2, 0, 1, 3).ravel(),
                        np.repeat(np.arange(N_REALIZATIONS), PERIOD),
                        {"period": PERIOD, "n_transient": GAP}),
        # The recipe's branch structure: a cubic polynomial of tanh(z) with
        # its constant, spanned by the Legendre polynomials of degrees 0-3.
        "whole record, tanh basis": (data.X_est, data.y_est, None,
                                     {"basis": LegendreBasis(3, constant=True)}),
        # The recipe's initialisation, inference and learning.
        "whole record, inference": (data.X_est, data.y_est, None, {"init": "inference"}),
        "whole record, tanh basis, inference": (
            data.X_est, data.y_est, None,
            {"basis": LegendreBasis(3, constant=True), "init": "inference"}),
        # The same, extrapolated as freq-statespace does: the bounded basis
        # itself beyond the estimation range.
        "same, extrapolation=\"continue\"": (
            data.X_est, data.y_est, None,
            {"basis": LegendreBasis(3, constant=True), "init": "inference",
             "extrapolation": "continue"}),
    }
    for layout, fit_data in layouts.items():
        fits = [_fit_nllfr(*fit_data, seed) for seed in RANDOM_STATES]
        fit_time = float(np.median([t for _, t in fits]))
        per_record = [{name: _sknlss_errors(model, record, skip)
                       for name, record in data.tests.items()} for model, _ in fits]
        for protocol in ("window state", "zero state"):
            errors = [{name: e[name][protocol] for name in names} for e in per_record]
            yield _row(f"sknlss, {layout} ({protocol})", errors, names, fit_time,
                       fits[0][0].n_params_)

    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
            # The package prints every iteration and warns that no noise
            # estimate weights its frequency-domain cost (one period per
            # realization).
            warnings.simplefilter("ignore")
            peer, peer_time = _fit_freq_statespace(data, U, Y)
    except ImportError:
        yield ("freq-statespace is not installed (pip install freq-statespace): no "
               "side-by-side row.")
        return
    errors = [{name: _mv(record.y, peer.simulate(record.X)[0], skip)
               for name, record in data.tests.items()}]
    yield _row("freq-statespace, six periods (zero state)", errors, names, peer_time,
               peer.num_parameters())


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output", type=Path, metavar="FILE",
                        help="also write the printed table to FILE")
    args = parser.parse_args(argv)
    _check_peer(parser, args, "freq-statespace")
    _publish(_table(fetch_silverbox(download_if_missing=False)), args.output,
             ("freq-statespace", "jax"))


if __name__ == "__main__":
    main()
