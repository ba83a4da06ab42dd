"""Accuracy of every estimator with its defaults, over random states.

Every estimator is given the model structure only (the number of states, and
the paper's PNLSS degrees, decoupling rank and initial-state setting on the
Cascaded Tanks) and fitted at random states 0-9 on:

- Cascaded Tanks (DESIGN.md §3): fitted on the estimation record; the initial
  state, when estimated, is reused on the test record; RMS error over the whole
  test record and without its first 50 samples (V);
- Silverbox: fitted on the estimation record; each test record (multisine,
  arrow, full arrow) simulated from its start; RMS error without the first 50
  samples (mV);
- the simulated systems of ``sknlss.datasets`` (Wiener-Hammerstein, Duffing,
  Bouc-Wen, closed-loop drive): fitted on the estimation record of
  ``random_state=0``, RMS error on its test record without the first 50
  samples, relative to the test output's standard deviation.

It prints, per benchmark, estimator and test record, the median, minimum and
maximum of the errors and the median fit time, and writes them to
``--output`` as CSV and Markdown. A diverging simulation counts as an
infinite error. The BLAS thread setting is printed with the results: run the
script with ``OPENBLAS_NUM_THREADS=1`` and ``=2`` and compare the medians.

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_accuracy.py --output doc/_generated``
(about an hour on 2 cores; ``--benchmarks`` and ``--random-states`` narrow it).
"""

import argparse
import csv
import json
import os
import platform
import time
import warnings
from pathlib import Path

import numpy as np
from joblib import Parallel, delayed

from sknlss import (
    BLAEstimator,
    DecoupledPNLSS,
    NLLFRRegressor,
    NLSS2Regressor,
    PNLSSRegressor,
)
from sknlss import datasets as sd
from sknlss.benchmarks import load_benchmark

#: Number of states of each simulated system's models.
SIMULATED = {"wiener_hammerstein": 4, "duffing": 2, "bouc_wen": 3, "closed_loop_drive": 2}


def _models(n_states, estimate_x0=False, tanks=False):
    structure = dict(n_states=n_states, estimate_x0=estimate_x0)
    models = {
        "BLA": lambda seed: BLAEstimator(**structure),
        "PNLSS": lambda seed: PNLSSRegressor(degree=(2, 3), random_state=seed, **structure),
        "decoupled PNLSS": lambda seed: DecoupledPNLSS(rank=5, random_state=seed, **structure),
        "NLSS2": lambda seed: NLSS2Regressor(random_state=seed, **structure),
        "NL-LFR": lambda seed: NLLFRRegressor(random_state=seed, **structure),
    }
    if tanks:
        # The paper's two PNLSS models: without and with the initial state.
        models["PNLSS (no x0)"] = lambda seed: PNLSSRegressor(
            n_states=n_states, degree=(2, 3), random_state=seed)
    return models


def _benchmarks(names, data_home):
    """Per benchmark: data, models, test records ``{name: (X, y, skip)}`` and scale."""
    found = {}
    for name in names:
        if name == "cascaded_tanks":
            data, _ = load_benchmark(name, data_home, download_if_missing=False)
            records = {"test": (data.X_test, data.y_test, 0),
                       "test[50:]": (data.X_test, data.y_test, data.init_window)}
            found[name] = (data, _models(3, estimate_x0=True, tanks=True), records, 1.0, "V")
        elif name == "silverbox":
            data, _ = load_benchmark(name, data_home, download_if_missing=False)
            records = {key: (r.X, r.y, data.init_window) for key, r in data.tests.items()}
            found[name] = (data, _models(2), records, 1e3, "mV")
        else:
            data = getattr(sd, f"make_{name}")(random_state=0)
            records = {"test": (data.X_test, data.y_test, data.init_window)}
            found[name] = (data, _models(SIMULATED[name]), records,
                           1.0 / np.std(data.y_test[data.init_window:]), "relative")
    return found


def _run(benchmark, label, seed, data, factory, records, scale):
    warnings.simplefilter("ignore")
    model = factory(seed)
    start = time.perf_counter()
    try:
        model.fit(data.X_est, data.y_est)
    except Exception as error:  # a failed fit is a result too: reported, not fatal
        return {"benchmark": benchmark, "model": label, "seed": seed, "fit_time": 0.0,
                "n_params": 0, "fallback": False, "error": repr(error),
                **{name: float("nan") for name in records}}
    elapsed = time.perf_counter() - start
    row = {"benchmark": benchmark, "model": label, "seed": seed, "fit_time": elapsed,
           "n_params": int(model.n_params_), "error": "",
           "fallback": bool(getattr(model, "fell_back_to_linear_", False))}
    for name, (X, y, skip) in records.items():
        error = model.predict(X)[skip:] - y[skip:]
        row[name] = (float(scale * np.sqrt(np.mean(error**2)))
                     if np.all(np.isfinite(error)) else float("inf"))
    return row


def _summary(runs, found):
    lines = []
    for benchmark, (_, models, records, _, unit) in found.items():
        for label in models:
            rows = [r for r in runs if r["benchmark"] == benchmark and r["model"] == label]
            if not rows:
                continue
            summary = {"benchmark": benchmark, "model": label, "unit": unit,
                       "n_params": max(r["n_params"] for r in rows), "runs": len(rows),
                       "failed": sum(bool(r["error"]) for r in rows),
                       "fallbacks": sum(r["fallback"] for r in rows),
                       "fit_time": float(np.median([r["fit_time"] for r in rows]))}
            for name in records:
                values = np.array([r[name] for r in rows])
                summary[f"{name} median"] = float(np.median(values))
                summary[f"{name} min"] = float(values.min())
                summary[f"{name} max"] = float(values.max())
            lines.append(summary)
    return lines


def _markdown(summary, found, setting):
    text = [f"BLAS threads: {setting}; {platform.machine()}, Python {platform.python_version()}",
            ""]
    for benchmark, (_, _, records, _, unit) in found.items():
        rows = [s for s in summary if s["benchmark"] == benchmark]
        text += [f"### {benchmark} ({unit})", "",
                 "| model | params | " + " | ".join(f"{name} median [min, max]"
                                                   for name in records)
                 + " | fit (s) | fallbacks | failed |",
                 "|---|---|" + "---|" * len(records) + "---|---|---|"]
        for s in rows:
            cells = [f"{s[f'{name} median']:.4g} [{s[f'{name} min']:.4g}, "
                     f"{s[f'{name} max']:.4g}]" for name in records]
            text.append(f"| {s['model']} | {s['n_params']} | " + " | ".join(cells)
                        + f" | {s['fit_time']:.1f} | {s['fallbacks']}/{s['runs']} "
                        f"| {s['failed']} |")
        text.append("")
    return "\n".join(text)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--benchmarks", nargs="+",
                        default=["cascaded_tanks", "silverbox", *SIMULATED])
    parser.add_argument("--random-states", type=int, nargs="+", default=list(range(10)))
    parser.add_argument("--models", nargs="+", default=None)
    parser.add_argument("--data-home", default=None)
    parser.add_argument("--n-jobs", type=int, default=2)
    parser.add_argument("--output", default=None,
                        help="folder for bench_accuracy.csv/.md and the raw runs (JSON lines)")
    args = parser.parse_args()
    setting = os.environ.get("OPENBLAS_NUM_THREADS", "unset")
    found = _benchmarks(args.benchmarks, args.data_home)
    jobs = [(benchmark, label, seed, data, factory, records, scale)
            for benchmark, (data, models, records, scale, _) in found.items()
            for label, factory in models.items()
            if args.models is None or label in args.models
            for seed in args.random_states]
    runs = Parallel(n_jobs=args.n_jobs)(delayed(_run)(*job) for job in jobs)
    if args.output:
        Path(args.output).mkdir(parents=True, exist_ok=True)
    summary = _summary(runs, found)
    text = _markdown(summary, found, setting)
    print(text)
    if args.output:
        output = Path(args.output)
        output.mkdir(parents=True, exist_ok=True)
        stem = f"bench_accuracy_threads{setting}"
        with open(output / f"{stem}_runs.jsonl", "w", encoding="utf-8") as handle:
            handle.writelines(json.dumps(run) + "\n" for run in runs)
        with open(output / f"{stem}.csv", "w", newline="", encoding="utf-8") as handle:
            writer = csv.DictWriter(handle, fieldnames=list(summary[0]))
            writer.writeheader()
            writer.writerows(summary)
        (output / f"{stem}.md").write_text(text + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
