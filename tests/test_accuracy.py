"""Accuracy on the measured benchmarks with the estimators' defaults.

Every model is given its structure only and fitted at three random states; the
median of the test errors must stay within its bound (DESIGN.md §3 protocol:
nothing but the final number uses a test record). The margin between a bound
and the median measured by ``benchmarks/bench_accuracy.py`` over random states
0-9 is at least the spread it measured (see each test). The Cascaded Tanks
models, whose test errors spread over tenths of a volt between random states,
are followed by that benchmark, not here.
"""

import pytest

from sknlss import NLLFRRegressor, PNLSSRegressor
from sknlss.benchmarks import evaluate

pytestmark = [pytest.mark.slow, pytest.mark.realdata]

SEEDS = (0, 1, 2)


def _silverbox_medians(factory, data):
    """Median over SEEDS of the RMS error (mV) on each Silverbox test record,
    with the number of parameters."""
    records = {name: (record.X, record.y, data.init_window)
               for name, record in data.tests.items()}
    rows, _ = evaluate(data, [("model", factory)], records, random_states=SEEDS,
                       scale=1e3, n_jobs=2)
    return rows[0]


def test_silverbox_pnlss(silverbox):
    """Silverbox, PNLSS with ``n_states=2`` and its defaults: <= 0.35 mV on the
    multisine and on the arrow without extrapolation. Over random states 0-9
    ``benchmarks/bench_accuracy.py`` measured medians of 0.221 mV [0.220,
    0.223] and 0.241 mV [0.239, 0.242] (each record's state set from its
    first 50 samples): the margin is thirty times the spread."""
    medians = _silverbox_medians(
        lambda seed: PNLSSRegressor(n_states=2, random_state=seed), silverbox)
    assert medians["multisine"] <= 0.35
    assert medians["arrow"] <= 0.35
    assert medians["n_params"] == 57


def test_silverbox_nllfr(silverbox):
    """Silverbox, NL-LFR with ``n_states=2`` and its defaults, 17 parameters.

    Over random states 0-9 the benchmark measured 0.2541 mV [0.2537, 0.2541]
    on the multisine and 0.3660 mV [0.3644, 0.3660] on the full arrow (each
    record's state set from its first 50 samples). The multisine bound is the
    target, 0.29 mV (the frequency-domain NL-LFR recipe of freq-statespace
    reaches 0.288 mV), with a margin of about a hundred times the spread. The
    full arrow leaves the range of the branch input on the estimation record;
    the held-out end chooses the powers, which the default continues as they
    are beyond it. Its bound, 0.38 mV, holds what is reached with a margin of
    ten times the spread, short of the target of 0.34 mV (freq-statespace:
    0.334 mV).
    """
    medians = _silverbox_medians(
        lambda seed: NLLFRRegressor(n_states=2, random_state=seed), silverbox)
    assert medians["multisine"] <= 0.29
    assert medians["arrow_full"] <= 0.38
    assert medians["n_params"] <= 25
