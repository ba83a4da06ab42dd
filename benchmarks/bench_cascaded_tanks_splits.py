"""How much the Cascaded Tanks results depend on the held-out split.

With ``validation_fraction="auto"`` (the default), the starts of a nonlinear
estimator hold out the shares 0.25, 0.3, 0.35, 0.275 and 0.325 of the end of
the estimation record in turn and are ranked on the end that all of them held
out. This script fits every nonlinear model of the main job (``python -m
sknlss reproduce``) at random state 0 with each of these shares alone, and
prints per share the RMS error on that common end (the last 25 % of the
estimation record, what the default ranking compares) and on the test record.

This is an analysis of the protocol, not a selection: no setting is chosen
from the test column. It shows how far a single split decides the result on a
record this short: the held-out end of the estimation record holds one of its
two overflow episodes, and the iterate a held-out end prefers changes with a
few dozen samples more or less.

Needs the measured data (``SKNLSS_DATA`` or the user cache folder). Takes
about five minutes on two cores.

Run: ``python benchmarks/bench_cascaded_tanks_splits.py``
"""

import warnings

import numpy as np
from sklearn.base import clone

from sknlss.benchmarks import BENCHMARKS
from sknlss.datasets import fetch_cascaded_tanks
from sknlss.metrics import rms_error

SHARES = (0.25, 0.275, 0.3, 0.325, 0.35)


def _rms(y, y_model):
    """RMS error (V); inf when the simulation diverged."""
    return rms_error(y, y_model) if np.all(np.isfinite(y_model)) else np.inf


def _format(value):
    return "diverged" if not np.isfinite(value) else f"{value:.3f}"


def main():
    data = fetch_cascaded_tanks(download_if_missing=False)
    end = len(data.y_est) - int(round(min(SHARES) * len(data.y_est)))
    print("Cascaded Tanks, random state 0: RMS on the common held-out end / RMS on "
          "the test record (V), per held-out share of the estimation record\n")
    header = f"{'model':<20}" + "".join(f"{share:>19}" for share in SHARES)
    print(header)
    print("-" * len(header))
    for label, factory in BENCHMARKS["cascaded_tanks"].models():
        model = factory(0)
        if "validation_fraction" not in model.get_params():
            continue
        cells = []
        for share in SHARES:
            single = clone(model).set_params(validation_fraction=share)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                single.fit(data.X_est, data.y_est)
                y_est, y_test = single.predict(data.X_est), single.predict(data.X_test)
            cells.append(f"{_format(_rms(data.y_est[end:], y_est[end:]))} / "
                         f"{_format(_rms(data.y_test, y_test))}")
        print(f"{label:<20}" + "".join(f"{cell:>19}" for cell in cells), flush=True)


if __name__ == "__main__":
    main()
