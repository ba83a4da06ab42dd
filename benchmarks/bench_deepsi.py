"""The two measured benchmarks, side by side with deepSI's SUBNET.

deepSI (PyPI, PyTorch) fits SUBNET models: a state-space model whose state
map f and output map h are residual multilayer perceptrons, trained by Adam on
the simulation error of short windows (``T`` samples) whose initial states an
encoder network computes from the ``na`` outputs and ``nb`` inputs before each
window. This script runs the example of deepSI's README with its settings
(``nb = na = 20``, 10,000 Adam iterations of batches of 256 windows of
``T = 20`` samples, the model kept at its best validation error, checked every
100 iterations), with the number of states of the accuracy benchmark's models
(3 on the Cascaded Tanks, 2 on the Silverbox), at random states 0-4:

- trained on the first three quarters of the estimation record and validated
  on the last quarter (the held-out end sknlss's estimators rank their starts
  on is between a quarter and 35 %);
- scored as the accuracy benchmark scores sknlss: the encoder reads the 20
  samples before the 50th of each test record (the first 50 may set the
  state), and the RMS error is taken over the samples after them, in V on the
  Cascaded Tanks, in mV on the Silverbox.

The sknlss rows are read from the accuracy benchmark's runs file (every
estimator with its defaults, random states 0-9, the same protocol; ``--runs``
names another), not refitted. The fit times are wall-clock seconds on this
machine, one fit per core.

Needs ``pip install deepSI`` (which installs PyTorch) and the measured data
(``SKNLSS_DATA`` or the user cache folder). Takes about twenty minutes on two
cores. deepSI writes its checkpoints to ``~/.deepSI-checkpoints``.

Run: ``python benchmarks/bench_deepsi.py``; with ``--output FILE`` the printed
table is also written to FILE, headed by the machine and versions it was
measured with. ``--benchmarks``, ``--random-states`` and ``--iterations``
(Adam iterations per fit) narrow or extend the run.
"""

import argparse
import contextlib
import io
import json
import time
import warnings
from pathlib import Path

import numpy as np
from joblib import Parallel, delayed

from bench_accuracy import _models
from bench_peers import _check_peer, _publish, _row

from sknlss.__main__ import _seed
from sknlss.datasets import fetch_cascaded_tanks, fetch_silverbox
from sknlss.metrics import rms_error

RANDOM_STATES = (0, 1, 2, 3, 4)
#: deepSI README's settings.
PAST = 20
SETTINGS = {"n_its": 10_000, "T": 20, "batch_size": 256, "val_freq": 100}
VALIDATION_SHARE = 0.25
RUNS = Path(__file__).resolve().parents[1] / "doc" / "_generated" / \
    "bench_accuracy_threads1_runs.jsonl"


def _benchmarks(names):
    """Per benchmark: data, states, test records ``{name: (X, y)}``, scale, unit."""
    found = {}
    if "cascaded_tanks" in names:
        tanks = fetch_cascaded_tanks(download_if_missing=False)
        found["cascaded_tanks"] = (tanks, 3, {"test[50:]": (tanks.X_test, tanks.y_test)},
                                   1.0, "V")
    if "silverbox" in names:
        silverbox = fetch_silverbox(download_if_missing=False)
        found["silverbox"] = (silverbox, 2,
                              {name: (r.X, r.y) for name, r in silverbox.tests.items()},
                              1e3, "mV")
    return found


def _fit_subnet(data, n_states, records, scale, n_iterations, seed):
    import deepSI as dsi
    import torch

    torch.set_num_threads(1)
    u, y = data.X_est.ravel(), data.y_est.ravel()
    cut = int(round((1.0 - VALIDATION_SHARE) * u.size))
    train = dsi.Input_output_data(u=u[:cut], y=y[:cut])
    # The validation windows' encoder reads the samples before the held-out end.
    validation = dsi.Input_output_data(u=u[cut - PAST:], y=y[cut - PAST:])
    np.random.seed(seed)
    torch.manual_seed(seed)
    n_inputs, n_outputs, norm = dsi.get_nu_ny_and_auto_norm(train)
    model = dsi.SUBNET(n_inputs, n_outputs, norm, nx=n_states, nb=PAST, na=PAST)
    start = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        dsi.fit(model, train, validation, **{**SETTINGS, "n_its": n_iterations})
    fit_time = time.perf_counter() - start
    skip = data.init_window
    errors = {}
    for name, (X, y_test) in records.items():
        window = dsi.Input_output_data(u=X.ravel()[skip - PAST:], y=y_test[skip - PAST:])
        y_model = model.simulate(window).y[PAST:]
        finite = np.all(np.isfinite(y_model))
        errors[name] = scale * rms_error(y_test[skip:], y_model) if finite else np.inf
    return errors, fit_time, sum(p.numel() for p in model.parameters())


def _sknlss_rows(runs, names):
    # In the accuracy benchmark's order of its models (the tanks have them all).
    for label in _models(n_states=1, tanks=True):
        rows = [r for r in runs if r["model"] == label]
        if not rows:
            continue
        yield _row(f"sknlss {label}", [{n: r[n] for n in names} for r in rows], names,
                   float(np.median([r["fit_time"] for r in rows])), rows[0]["n_params"])


def _table(runs_file, benchmarks, n_iterations, random_states):
    """The lines of the side-by-side tables."""
    every_run = [json.loads(line)
                 for line in runs_file.read_text(encoding="utf-8").splitlines()]
    for benchmark, (data, n_states, records, scale, unit) in _benchmarks(benchmarks).items():
        names = list(records)
        runs = [r for r in every_run if r["benchmark"] == benchmark and not r["error"]]
        header = f"{'model':<60}" + "".join(f"{n:>13}" for n in names) \
            + f"{'fit (s)':>10}{'params':>8}"
        yield (f"{benchmark}, {n_states} states: RMS error after the first "
               f"{data.init_window} test samples ({unit}); median over random states "
               f"(sknlss {sorted({r['seed'] for r in runs})}, deepSI "
               f"{list(random_states)})\n")
        yield header
        yield "-" * len(header)
        yield from _sknlss_rows(runs, names)
        try:
            import deepSI  # noqa: F401
        except ImportError:
            yield "deepSI is not installed (pip install deepSI): no side-by-side row.\n"
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fits = Parallel(n_jobs=2)(
                delayed(_fit_subnet)(data, n_states, records, scale, n_iterations, seed)
                for seed in random_states)
        settings = ("README settings" if n_iterations == SETTINGS["n_its"]
                    else f"README settings but {n_iterations:,} iterations")
        errors = [e for e, _, _ in fits]
        yield _row(f"deepSI SUBNET ({settings})", errors, names,
                   float(np.median([t for _, t, _ in fits])), fits[0][2])
        yield f"{'  range over the random states':<60}" + "".join(
            f"{min(e[n] for e in errors):>6.3g}-{max(e[n] for e in errors):<6.3g}"
            for n in names)
        yield ""


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=Path, default=RUNS, metavar="FILE",
                        help="the accuracy benchmark's runs file (JSON lines) for the "
                             "sknlss rows")
    parser.add_argument("--benchmarks", nargs="+", choices=["cascaded_tanks", "silverbox"],
                        default=["cascaded_tanks", "silverbox"])
    parser.add_argument("--iterations", type=int, default=SETTINGS["n_its"],
                        help="Adam iterations of every deepSI fit (the README's 10,000 by "
                             "default)")
    parser.add_argument("--random-states", type=_seed, nargs="+", default=RANDOM_STATES)
    parser.add_argument("--output", type=Path, metavar="FILE",
                        help="also write the printed table to FILE")
    args = parser.parse_args(argv)
    _check_peer(parser, args, "deepSI")
    _publish(_table(args.runs, args.benchmarks, args.iterations, args.random_states),
             args.output, ("deepSI", "torch"))


if __name__ == "__main__":
    main()
