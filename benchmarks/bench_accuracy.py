"""Accuracy of every estimator with its defaults, over random states.

Every estimator is given the model structure only (the number of states, and
the paper's PNLSS degrees, decoupling rank and initial-state setting on the
Cascaded Tanks) and fitted at random states 0-9 on:

- Cascaded Tanks (DESIGN.md §3): fitted on the estimation record; the initial
  state, when estimated, is reused on the test record; RMS error over the whole
  test record, and over its samples after the first 50, from the state that
  fits those 50 (V);
- Silverbox: fitted on the estimation record; each test record (multisine,
  arrow, full arrow) simulated from its start, from the state that fits its
  first 50 samples; RMS error over the others (mV);
- the simulated systems of ``sknlss.datasets`` (Wiener-Hammerstein, Duffing,
  Bouc-Wen, closed-loop drive): fitted on the estimation record of
  ``random_state=0`` (with ``--redraw``, each random state on the records of
  its own ``random_state``: the spread then includes the noise and the input
  realisation); the test record scored like a Silverbox one, relative to the
  test output's standard deviation.

It prints, per benchmark, estimator and test record, the median, minimum and
maximum of the errors and the median fit time, and writes them to
``--output`` as CSV and Markdown, with every fit as it finishes (JSON lines).
A diverging simulation counts as an infinite error. The benchmarks are the
measured records: a missing data file stops the run. The BLAS setting is
printed with the results and names the files: run the script with
``OPENBLAS_NUM_THREADS=1`` and ``=2`` (or with another ``OPENBLAS_CORETYPE``,
whose kernels round differently), then ``--compare`` the two runs files.

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_accuracy.py --output doc/_generated``
(about an hour on 2 cores; ``--benchmarks`` and ``--random-states`` narrow it).
"""

import argparse
import csv
import json
import os
import platform
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
from sknlss.__main__ import _seed
from sknlss.benchmarks import _fit_and_score, _prepare_output

#: Number of states of each simulated system's models (for the drive, whose
#: loop holds four, chosen among 2-4 on fresh draws: see doc/benchmarks.rst).
SIMULATED = {"wiener_hammerstein": 4, "duffing": 2, "bouc_wen": 3, "closed_loop_drive": 4}


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


def _measured(name, data_home):
    """The measured records; a missing file stops the run (never simulated stand-ins)."""
    return getattr(sd, f"fetch_{name}")(data_home, download_if_missing=False)


def _benchmarks(names, data_home):
    """Per benchmark: data, models, test records ``{name: (X, y, skip)}`` and scale."""
    found = {}
    for name in names:
        if name == "cascaded_tanks":
            data = _measured(name, data_home)
            records = {"test": (data.X_test, data.y_test, 0),
                       "test[50:]": (data.X_test, data.y_test, data.init_window)}
            found[name] = (data, _models(3, estimate_x0=True, tanks=True), records, 1.0, "V")
        elif name == "silverbox":
            data = _measured(name, data_home)
            records = {key: (r.X, r.y, data.init_window) for key, r in data.tests.items()}
            found[name] = (data, _models(2), records, 1e3, "mV")
        else:
            data, records, scale = _simulated(name, 0)
            found[name] = (data, _models(SIMULATED[name]), records, scale, "relative")
    return found


def _simulated(name, draw):
    """The records of a simulated system drawn with ``random_state=draw``, its
    test record and the scale of its errors (one over the test output's
    standard deviation)."""
    data = getattr(sd, f"make_{name}")(random_state=draw)
    records = {"test": (data.X_test, data.y_test, data.init_window)}
    return data, records, 1.0 / np.std(data.y_test[data.init_window:])


#: Fields of a run that are not test records.
_RUN_FIELDS = ("benchmark", "model", "seed", "fit_time", "n_params", "error", "fallback")


def _run(benchmark, label, seed, data, records, scale, factory):
    warnings.simplefilter("ignore")
    try:
        result = _fit_and_score(factory, seed, data, records, scale)
    except Exception as error:  # a failed fit is a result too: reported, not fatal
        return {"benchmark": benchmark, "model": label, "seed": seed, "fit_time": 0.0,
                "n_params": 0, "fallback": False, "error": repr(error),
                **{name: float("nan") for name in records}}
    model = result["model"]
    return {"benchmark": benchmark, "model": label, "seed": seed,
            "fit_time": result["fit_time"], "n_params": int(model.n_params_), "error": "",
            "fallback": bool(getattr(model, "fell_back_to_linear_", False)),
            **{name: float(value) for name, value in result["errors"].items()}}


def _summary(runs, found):
    """One row per benchmark, model and test record (long format)."""
    lines = []
    for benchmark, (_, models, records, _, unit) in found.items():
        for label in models:
            rows = [r for r in runs if r["benchmark"] == benchmark and r["model"] == label]
            if not rows:
                continue
            for name in records:
                values = np.array([r[name] for r in rows])
                lines.append({
                    "benchmark": benchmark, "model": label, "record": name, "unit": unit,
                    "params": max(r["n_params"] for r in rows),
                    "median": float(np.median(values)), "min": float(values.min()),
                    "max": float(values.max()),
                    "fit time (s)": round(float(np.median([r["fit_time"] for r in rows])), 1),
                    "fallbacks": f"{sum(r['fallback'] for r in rows)}/{len(rows)}",
                    "failed": sum(bool(r["error"]) for r in rows)})
    return lines


def _blas_setting():
    """The BLAS setting of this run, as it ends the output files' names."""
    setting = os.environ.get("OPENBLAS_NUM_THREADS", "unset")
    core_type = os.environ.get("OPENBLAS_CORETYPE")
    return f"{setting}_{core_type}" if core_type else setting


def _markdown(summary, setting):
    threads, _, core_type = setting.partition("_")
    described = f"BLAS threads: {threads}" + (f", OpenBLAS core type {core_type}"
                                               if core_type else "")
    text = [f"{described}; {platform.machine()}, Python {platform.python_version()}", ""]
    for benchmark in dict.fromkeys(s["benchmark"] for s in summary):
        rows = [s for s in summary if s["benchmark"] == benchmark]
        records = list(dict.fromkeys(s["record"] for s in rows))
        text += [f"### {benchmark} ({rows[0]['unit']})", "",
                 "| model | params | " + " | ".join(f"{name} median [min, max]"
                                                   for name in records)
                 + " | fit (s) | fallbacks | failed |",
                 "|---|---|" + "---|" * len(records) + "---|---|---|"]
        for label in dict.fromkeys(s["model"] for s in rows):
            cells = {s["record"]: s for s in rows if s["model"] == label}
            first = cells[records[0]]
            text.append(f"| {label} | {first['params']} | " + " | ".join(
                f"{cells[name]['median']:.4g} [{cells[name]['min']:.4g}, "
                f"{cells[name]['max']:.4g}]" for name in records)
                + f" | {first['fit time (s)']} | {first['fallbacks']} | {first['failed']} |")
        text.append("")
    return "\n".join(text)


def _table_rows(summary):
    """The summary as the documentation shows it: the unit with the record and
    the range in one column, so that the table fits the page."""
    return [{"benchmark": s["benchmark"], "model": s["model"],
             "record": f"{s['record']} ({s['unit']})", "params": s["params"],
             "median": f"{s['median']:.4g}", "range": f"{s['min']:.4g} - {s['max']:.4g}",
             "fit (s)": s["fit time (s)"], "fallbacks": s["fallbacks"], "failed": s["failed"]}
            for s in summary]


def _write_csv(path, rows):
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows({key: (f"{value:.4g}" if isinstance(value, float) else value)
                          for key, value in row.items()} for row in rows)


def _read_runs(path):
    """The fits of a runs file, by (benchmark, model, seed)."""
    with open(path, encoding="utf-8") as handle:
        return {(r["benchmark"], r["model"], r["seed"]): r for r in map(json.loads, handle)}


def _compare(a, b):
    """Medians of two runs (their fits as :func:`_read_runs` gives them) over the
    fits they share, with their relative change, and the largest relative
    change of a single fit."""
    shared = sorted(a.keys() & b.keys())
    rows = []
    for benchmark, model in dict.fromkeys(key[:2] for key in shared):
        keys = [key for key in shared if key[:2] == (benchmark, model)]
        names = [name for name in a[keys[0]] if name not in _RUN_FIELDS]
        for name in names:
            median_a = float(np.median([a[key][name] for key in keys]))
            median_b = float(np.median([b[key][name] for key in keys]))
            change = abs(median_b - median_a) / median_a if np.isfinite(median_a) else np.nan
            with np.errstate(invalid="ignore"):
                fits = [abs(b[key][name] - a[key][name]) / a[key][name] for key in keys]
            rows.append({"benchmark": benchmark, "model": model, "record": name,
                         "random states": len(keys), "median (1st)": median_a,
                         "median (2nd)": median_b, "relative change": change,
                         "largest change of one fit": float(np.nanmax(fits))})
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    benchmarks = ["cascaded_tanks", "silverbox", *SIMULATED]
    labels = list(_models(1, tanks=True))
    parser.add_argument("--benchmarks", nargs="+", choices=benchmarks, default=benchmarks,
                        metavar="NAME", help=f"from {benchmarks} (default: all)")
    parser.add_argument("--random-states", type=_seed, nargs="+", default=list(range(10)),
                        metavar="SEED", help="random states of the fits (default: 0 to 9)")
    parser.add_argument("--models", nargs="+", choices=labels, default=None, metavar="LABEL",
                        help=f"from {labels} (default: all; on the Cascaded Tanks, PNLSS "
                             "and decoupled PNLSS estimate the initial state)")
    parser.add_argument("--data-home", default=None,
                        help="folder holding the measured data (default: $SKNLSS_DATA, then "
                             "the user cache folder)")
    parser.add_argument("--n-jobs", type=int, default=2, help="fits run at once")
    parser.add_argument("--output", default=None,
                        help="folder for bench_accuracy_threads<SETTING>.csv/.md and the raw "
                             "runs (JSON lines, written as the fits finish); SETTING is "
                             "OPENBLAS_NUM_THREADS ('unset' when it is), followed by "
                             "OPENBLAS_CORETYPE when that is set")
    parser.add_argument("--redraw", action="store_true",
                        help="fit each random state of a simulated system on its own "
                             "draw of the records (random_state of the data = that of "
                             "the estimator) instead of the records of random_state=0")
    parser.add_argument("--compare", nargs=2, metavar="RUNS", default=None,
                        help="instead of fitting, compare the medians of two runs "
                             "(their *_runs.jsonl files) over the fits they share; "
                             "with --output, written as <second run>_compare.csv")
    parser.add_argument("--summarize", metavar="RUNS", default=None,
                        help="instead of fitting, summarise a runs file (e.g. of an "
                             "interrupted run) into the tables")
    args = parser.parse_args()
    try:
        if args.output:
            _prepare_output(args.output)
        runs_files = [args.summarize] if args.summarize else args.compare or []
        read = [_read_runs(path) for path in runs_files]
    except OSError as error:
        parser.error(f"{error.filename}: {error.strerror or error}")
    except (ValueError, KeyError) as error:
        parser.error(f"{' or '.join(runs_files)}: not a runs file of this script ({error!r})")
    if args.summarize:
        if not read[0]:
            parser.error(f"--summarize: {args.summarize} holds no fit")
        _write_tables(read[0].values(), args.data_home,
                      Path(args.summarize).name.removesuffix("_runs.jsonl"), args.output)
        return
    if args.compare:
        rows = _compare(*read)
        if not rows:
            parser.error("--compare: the two runs files share no fit")
        print("  ".join(rows[0]))
        for row in rows:
            print("  ".join(f"{v:.4g}" if isinstance(v, float) else str(v)
                            for v in row.values()))
        if args.output:
            second = Path(args.compare[1]).name.removesuffix("_runs.jsonl")
            _write_csv(Path(args.output) / f"{second}_compare.csv", rows)
        return
    setting = _blas_setting()
    found = _benchmarks(args.benchmarks, args.data_home)
    jobs = [(benchmark, label, seed, *(_simulated(benchmark, seed)
                                       if args.redraw and benchmark in SIMULATED
                                       else (data, records, scale)), factory)
            for benchmark, (data, models, records, scale, _) in found.items()
            for label, factory in models.items()
            if args.models is None or label in args.models
            for seed in args.random_states]
    if not jobs:
        parser.error(f"--models {args.models} are not run on --benchmarks {args.benchmarks}")
    output = Path(args.output) if args.output else None
    stem = f"bench_accuracy_threads{setting}"
    runs = []
    if output:
        output.mkdir(parents=True, exist_ok=True)
        (output / f"{stem}_runs.jsonl").write_text("", encoding="utf-8")
    for run in Parallel(n_jobs=args.n_jobs, return_as="generator_unordered")(
            delayed(_run)(*job) for job in jobs):
        runs.append(run)
        if output:
            # Each fit is kept as it finishes: an interrupted run loses nothing done.
            with open(output / f"{stem}_runs.jsonl", "a", encoding="utf-8") as handle:
                handle.write(json.dumps(run) + "\n")
    _write_tables(runs, args.data_home, stem, output, found)


def _write_tables(runs, data_home, stem, output, found=None):
    runs = list(runs)
    if found is None:
        found = _benchmarks(list(dict.fromkeys(r["benchmark"] for r in runs)), data_home)
    summary = _summary(runs, found)
    text = _markdown(summary, stem.removeprefix("bench_accuracy_threads"))
    print(text)
    if output:
        output = Path(output)
        _write_csv(output / f"{stem}.csv", _table_rows(summary))
        (output / f"{stem}.md").write_text(text + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
