"""Speed and memory of PNLSSRegressor.

Prints, for BLAS limited to 1 and to 2 threads (threadpoolctl):

- one simulation and one Jacobian of the reference problem (the PNLSS
  tutorial system: 2 estimation realizations of one period of 1024 samples,
  each preceded by a one-period transient, n = 2, degrees 2-3 "full",
  57 parameters);
- a 60-iteration fit of that problem on the paper's cost with one start (the
  speed of the kernels and the optimiser), also with the stability penalty
  and the weight decay switched on, and a fit with the estimator's defaults
  (five starts, both penalties);
- a 20-iteration fit at N = 131072 samples (and at N / 4, N / 2 to show how
  time and peak memory scale), each in a fresh process so that the peak
  resident memory belongs to that fit alone.

The Levenberg-Marquardt step always runs its SVD with one BLAS thread (see
``sknlss._core._optimize``); the thread setting matters for the rest (the BLA).

Run: ``python benchmarks/bench_pnlss.py``; with ``--output FILE`` the printed
table is also written to FILE, headed by the machine and versions it was
measured with (the documentation includes
``doc/_generated/bench_pnlss.txt``).
"""

import argparse
import contextlib
import json
import os
import platform
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from threadpoolctl import threadpool_limits

from sknlss import PNLSSRegressor
from sknlss._core._sequences import steady_state_rows
from sknlss.datasets import make_pnlss_reference

#: The plain paper's cost and one start: the speed of the kernels and the
#: optimiser, comparable across versions (the defaults add starts and
#: penalties, timed separately).
PLAIN = dict(center=False, stability_penalty=0.0, weight_decay=0.0, n_init=1,
             validation_fraction=0.0)


def _best_time(func, repeat):
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return min(times)


def reference_problem():
    """Period-averaged estimation data of the reference system, 2 realizations."""
    data = make_pnlss_reference(n_realizations=2, n_periods=3)
    period = data.period
    X = data.X.reshape(2, 3, period)[:, 0].reshape(-1, 1)
    y = data.y.reshape(2, 3, period).mean(axis=1).ravel()
    return X, y, np.repeat([0, 1], period), period


def bench_reference():
    X, y, sequence_id, period = reference_problem()
    model = PNLSSRegressor(2, period=period, n_transient=period, max_iter=60, **PLAIN)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(X, y, sequence_id=sequence_id)  # also compiles the kernels
        fit_time = _best_time(lambda: model.fit(X, y, sequence_id=sequence_id), 3)
        staged = PNLSSRegressor(2, period=period, n_transient=period, max_iter=60,
                                **{**PLAIN, "refine_linear": True})
        staged_time = _best_time(lambda: staged.fit(X, y, sequence_id=sequence_id), 3)
        penalised = PNLSSRegressor(2, period=period, n_transient=period, max_iter=60,
                                   **{**PLAIN, "stability_penalty": 1.0,
                                      "weight_decay": 1e-3})
        penalised_time = _best_time(lambda: penalised.fit(X, y, sequence_id=sequence_id), 3)
        # A fixed random state: the starts, hence the work, depend on it.
        defaults = PNLSSRegressor(2, period=period, n_transient=period, random_state=0)
        defaults_time = _best_time(lambda: defaults.fit(X, y, sequence_id=sequence_id), 3)
    U = (X - model.u_offset_) / model.u_scale_
    index, starts, original = steady_state_rows(np.array([0, period, 2 * period]), period)
    U = np.ascontiguousarray(U[index])
    rows = np.where(original, np.cumsum(original) - 1, -1)
    simulated, theta = model._fitted_model()
    sim = _best_time(lambda: simulated.simulate(theta, U, starts), 50)
    jac = _best_time(lambda: simulated.sensitivities(theta, U, starts, rows), 50)
    print(f"  reference problem: {U.shape[0]} simulated samples, "
          f"{model.n_params_} parameters")
    print(f"  one simulation                  {1e3 * sim:8.2f} ms")
    print(f"  one Jacobian                    {1e3 * jac:8.2f} ms")
    print(f"  60-iteration fit                {fit_time:8.2f} s   "
          f"({model.n_iter_} iterations, BLA included)")
    print(f"  same with refine_linear=True    {staged_time:8.2f} s")
    print(f"  same with both penalties        {penalised_time:8.2f} s   "
          f"({penalised.n_iter_} iterations)")
    print(f"  defaults (5 starts, penalties)  {defaults_time:8.2f} s")


_LARGE_FIT = """
import json, resource, sys, time, warnings
import numpy as np
from threadpoolctl import threadpool_limits
from sklearn.exceptions import ConvergenceWarning
from sknlss import PNLSSRegressor
from sknlss.datasets import make_pnlss_reference
n_samples, threads = int(sys.argv[1]), int(sys.argv[2])
period = 1024
data = make_pnlss_reference(n_realizations=n_samples // (2 * period), n_periods=2)
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
model = PNLSSRegressor(2, period=period, n_transient=period, max_iter=20, center=False,
                       stability_penalty=0.0, weight_decay=0.0, n_init=1,
                       validation_fraction=0.0)
with threadpool_limits(limits=threads, user_api="blas"), warnings.catch_warnings():
    warnings.simplefilter("ignore", ConvergenceWarning)
    start = time.perf_counter()
    model.fit(data.X, data.y, sequence_id=data.sequence_id)
    elapsed = time.perf_counter() - start
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"time": elapsed, "peak_mb": after / 1024, "data_mb": before / 1024,
                  "n_iter": model.n_iter_}))
"""


def bench_large(threads):
    for n_samples in (32768, 65536, 131072):
        out = subprocess.run(
            [sys.executable, "-c", _LARGE_FIT, str(n_samples), str(threads)],
            capture_output=True, text=True, check=True,
        )
        result = json.loads(out.stdout.strip().splitlines()[-1])
        print(f"  N = {n_samples:6d}: 20-iteration fit {result['time']:6.2f} s, "
              f"peak RSS {result['peak_mb']:7.1f} MB "
              f"(before the fit {result['data_mb']:6.1f} MB)")


class _Tee:
    """A text stream writing to several streams: the terminal and the results file."""

    def __init__(self, *streams):
        self._streams = streams

    def write(self, text):
        for stream in self._streams:
            stream.write(text)
        return len(text)

    def flush(self):
        for stream in self._streams:
            stream.flush()


def _machine():
    """What the figures depend on: the processor, its cores and the versions."""
    import numba
    import scipy

    import sknlss

    return (f"Machine: {platform.machine()} {platform.processor() or platform.system()}, "
            f"{os.cpu_count()} cores\n"
            f"Versions: Python {platform.python_version()}, numpy {np.__version__}, "
            f"scipy {scipy.__version__}, numba {numba.__version__}, "
            f"sknlss {sknlss.__version__}\n")


def run():
    for threads in (1, 2):
        print(f"BLAS threads: {threads}")
        with threadpool_limits(limits=threads, user_api="blas"):
            bench_reference()
        bench_large(threads)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output", type=Path, metavar="FILE",
                        help="also write the printed table to FILE")
    args = parser.parse_args(argv)
    if args.output is None:
        run()
        return
    args.output.parent.mkdir(parents=True, exist_ok=True)
    with open(args.output, "w", encoding="utf-8") as results:
        results.write(_machine() + "\n")
        with contextlib.redirect_stdout(_Tee(sys.stdout, results)):
            run()


if __name__ == "__main__":
    main()
