"""
Model selection across realizations with metadata routing
==========================================================

Periodic experiments are usually repeated with several random-phase
realizations of the multisine. The realizations are concatenated as rows and
labelled by ``sequence_id``; scikit-learn's metadata routing passes the labels
to ``fit`` and to the scorer, and :class:`~sklearn.model_selection.LeaveOneGroupOut`
holds one realization out per fold. The scorer from
:func:`sknlss.metrics.make_transient_scorer` simulates each held-out
realization from its own start and skips its first period (the transient).

The data come from the reference PNLSS system of the PNLSS toolbox tutorial:
realizations 0-2 serve the search, realization 3 is the test.
"""

import warnings

import sklearn
from sklearn.model_selection import GridSearchCV, LeaveOneGroupOut

from sknlss import BLAEstimator, LinearFallbackWarning, PNLSSRegressor
from sknlss.datasets import make_pnlss_reference
from sknlss.metrics import make_transient_scorer, rms_error

sklearn.set_config(enable_metadata_routing=True)

data = make_pnlss_reference(random_state=0)
period = data.period
search_rows = data.sequence_id <= 2
test_rows = data.sequence_id == 3

# %%
# The search: model order and polynomial degree, one realization held out per
# fold. ``n_transient=period`` drops the first period of every sequence from
# the cost and from the score. The folds judge the candidates, so nothing is
# held out within a fit (``validation_fraction=0``): a held-out end would also
# cut the whole periods that the BLA's robust method needs. Each candidate is
# a small fit (one start, 40 iterations) so that the search runs in seconds.
model = PNLSSRegressor(
    n_transient=period,
    bla=BLAEstimator(period=period, n_transient=period),
    validation_fraction=0.0,
    max_iter=40,
    n_init=1,
    random_state=0,
).set_fit_request(sequence_id=True)
scorer = make_transient_scorer("rms", n_transient=period).set_score_request(
    sequence_id=True
)
search = GridSearchCV(
    model,
    {"n_states": [1, 2], "degree": [2, (2, 3)]},
    cv=LeaveOneGroupOut(),
    scoring=scorer,
)
with warnings.catch_warnings(record=True) as caught:
    # A candidate whose every start runs away just beyond the estimation
    # amplitude keeps its linear model and says so; counted here.
    warnings.simplefilter("always", LinearFallbackWarning)
    search.fit(
        data.X[search_rows],
        data.y[search_rows],
        groups=data.sequence_id[search_rows],
        sequence_id=data.sequence_id[search_rows],
    )
linear = [w for w in caught if issubclass(w.category, LinearFallbackWarning)]
for other in caught:
    if other not in linear:
        warnings.warn(other.message, other.category)

for params, score in zip(search.cv_results_["params"],
                         search.cv_results_["mean_test_score"]):
    print(f"{params}: held-out RMS {-score:.2e}")
print(f"{len(linear)} of the fold fits kept their linear model")
print("chosen:", search.best_params_)

# %%
# The refitted best model on the test realization, after its first period.
y_test = search.predict(data.X[test_rows])
print(f"test RMS: {rms_error(data.y[test_rows], y_test, n_transient=period):.2e}")

sklearn.set_config(enable_metadata_routing=False)
