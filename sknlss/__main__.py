"""Command line: ``python -m sknlss reproduce`` runs the benchmark reproductions.

A thin layer over :func:`sknlss.benchmarks.reproduce`; its help text says what
the command does.
"""

import argparse
import sys

from .benchmarks import BENCHMARKS, _prepare_output, reproduce

_DESCRIPTION = (
    "Fit every model on the estimation record of each benchmark only, with the "
    "estimators' defaults and the model structure of the paper, at several random "
    "states, and print the median and the range of the test errors."
)


def _integer(text, rule):
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{rule}, got {text!r}") from None


def _seed(text):
    rule = "a random state is a non-negative integer"
    value = _integer(text, rule)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{rule}, got {value}")
    return value


def _n_jobs(text):
    value = _integer(text, "the number of fits at once is an integer")
    if value == 0:
        raise argparse.ArgumentTypeError("0 fits at once: use a positive number, or -1 for "
                                         "one per core")
    return value


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
        prog="sknlss", description="Nonlinear state-space identification (sknlss).")
    commands = parser.add_subparsers(dest="command", required=True)
    command = commands.add_parser(
        "reproduce", help="fit the models on the benchmarks and print their errors",
        description=_DESCRIPTION)
    command.add_argument("--benchmark", choices=sorted(BENCHMARKS) + ["all"], default="all",
                         help="which benchmark to run (default: %(default)s)")
    command.add_argument("--random-states", type=_seed, nargs="+", default=[0, 1, 2],
                         metavar="SEED", help="random states of the fits (default: 0 1 2)")
    command.add_argument("--data-home", default=None,
                         help="folder holding the benchmark data (default: $SKNLSS_DATA, "
                              "then the user cache folder)")
    command.add_argument("--output", default="sknlss_output",
                         help="folder for the tables (CSV) and figures (PNG) "
                              "(default: %(default)s)")
    command.add_argument("--n-jobs", type=_n_jobs, default=-1,
                         help="fits run at once (default: one per core)")
    command.add_argument("--no-download", action="store_true",
                         help="never download the data; simulate them when absent")
    args = parser.parse_args(argv)
    benchmarks = sorted(BENCHMARKS) if args.benchmark == "all" else [args.benchmark]
    try:
        # Before the fits, which take minutes: a path where files cannot be
        # written fails now.
        _prepare_output(args.output)
    except OSError as error:
        command.error(f"--output {args.output}: {error.strerror or error}")
    reproduce(benchmarks, data_home=args.data_home, output=args.output,
              download_if_missing=not args.no_download,
              random_states=tuple(args.random_states), n_jobs=args.n_jobs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
