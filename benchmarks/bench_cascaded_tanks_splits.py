"""How much the Cascaded Tanks results depend on the held-out split.

The main job (``python -m sknlss reproduce``) fits every nonlinear model at
held-out shares 0.25 to 0.35 of the estimation record (and the PNLSS models
with and without the stability penalty), then keeps the fit with the smallest
error on the last 25 % of the estimation record
(:class:`~sknlss.model_selection.HoldoutSearch`). This script prints every
candidate of those searches: per held-out share, the RMS error on that common
held-out end (what the search compares) and on the test record.

This is an analysis of the protocol, not a selection: no setting of the main
job is chosen from the test column. It shows how far a single split decides
the result on a record this short: the held-out end of the estimation record
holds one of its two overflow episodes, and the iterate a held-out end prefers
changes with a few dozen samples more or less.

Needs the measured data (``SKNLSS_DATA`` or the user cache folder). Takes
about three minutes on two cores.

Run: ``python benchmarks/bench_cascaded_tanks_splits.py``
"""

import warnings

import numpy as np
from sklearn.exceptions import ConvergenceWarning

from sklearn.base import clone
from sklearn.model_selection import ParameterGrid

from sknlss.__main__ import MODELS
from sknlss.datasets import load_cascaded_tanks
from sknlss.metrics import rms_error
from sknlss.model_selection import HoldoutSearch



def _test_rms(model, data):
    """RMS error (V) on the test record; inf when the simulation diverges."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        y_test = model.predict(data.X_test)
    if not np.all(np.isfinite(y_test)):
        return np.inf
    return rms_error(data.y_test, y_test)


def _format(value):
    return "diverged" if not np.isfinite(value) else f"{value:.3f}"


def main():
    data = load_cascaded_tanks()
    print("Cascaded Tanks: RMS on the common held-out end / RMS on the test record "
          "(V), per held-out share of the estimation record\n")
    header = None
    for name, factory in MODELS:
        search = factory()
        if not isinstance(search, HoldoutSearch):
            continue
        fractions = search.validation_fractions
        if header is None:
            header = f"{'model':<46}" + "".join(f"{f:>19}" for f in fractions)
            print(header)
            print("-" * len(header))
        for setting in ParameterGrid(search.param_grid or {}):
            cells = []
            for fraction in fractions:
                single = clone(search).set_params(
                    validation_fractions=[fraction], param_grid=[
                        {key: [value] for key, value in setting.items()}])
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", ConvergenceWarning)
                    single.fit(data.X_est, data.y_est)
                # Rank on the end held out at every share, as the search does.
                end = len(data.y_est) - int(round(min(fractions) * len(data.y_est)))
                y_est = single.predict(data.X_est)
                held_out = (rms_error(data.y_est[end:], y_est[end:])
                            if np.all(np.isfinite(y_est)) else np.inf)
                cells.append(f"{_format(held_out)} / "
                             f"{_format(_test_rms(single, data))}")
            label = name + "".join(f" {key}={value}" for key, value in setting.items())
            print(f"{label:<46}" + "".join(f"{cell:>19}" for cell in cells), flush=True)


if __name__ == "__main__":
    main()
