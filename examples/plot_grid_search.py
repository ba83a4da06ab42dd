"""
Choosing hyperparameters with GridSearchCV
==========================================

The hyperparameters of the sknlss estimators are ordinary constructor
arguments, so scikit-learn's model selection tools apply, with two cautions
for dynamical models:

* folds must be blocks of consecutive samples (or whole records), never
  shuffled rows;
* every validation fold is simulated from an initial state that is not the
  true state at its first sample, so the score must skip a transient
  (:func:`sknlss.metrics.make_transient_scorer`).

This example tunes NLSS2 and PNLSS models on the single Cascaded Tanks
estimation record with ``TimeSeriesSplit``; the test record is used only once,
for each chosen model. For several records (realizations) labelled by
``sequence_id``, see
:ref:`sphx_glr_auto_examples_plot_grid_search_realizations.py`, which routes
the labels with scikit-learn's metadata routing and leaves one realization
out per fold.
"""

# %%
# Data
# ----
import time

import matplotlib.pyplot as plt
import numpy as np
from sklearn.model_selection import GridSearchCV, TimeSeriesSplit

from sknlss import NLSS2Regressor, PNLSSRegressor
from sknlss.datasets import load_cascaded_tanks, make_cascaded_tanks
from sknlss.metrics import make_transient_scorer, rms_error

try:
    data = load_cascaded_tanks()
    print(f"Measured Cascaded Tanks data from {data.filename}")
except FileNotFoundError as exc:
    print(f"{exc}\nTHE REAL DATA ARE ABSENT: using simulated tanks (make_cascaded_tanks).")
    data = make_cascaded_tanks(random_state=0)

# %%
# Time-ordered folds
# ------------------
# Three folds whose validation blocks are the last 600 samples of the
# estimation record, 200 at a time, each model fitted on everything before
# its block. Within each fit, the last 30% of the training part selects the
# Levenberg-Marquardt iterate. The score is the RMS error after the first 100
# samples of the validation block (the state needs that long to settle).
cv = TimeSeriesSplit(n_splits=3, test_size=200)
scoring = make_transient_scorer("rms", n_transient=100)


def run_search(estimator, param_grid):
    """Search on the estimation record, then evaluate the refitted model once."""
    search = GridSearchCV(estimator, param_grid, cv=cv, scoring=scoring)
    start = time.perf_counter()
    search.fit(data.X_est, data.y_est)
    print(f"{type(estimator).__name__}: grid search on the estimation record in "
          f"{time.perf_counter() - start:.1f} s")
    for params, score in zip(search.cv_results_["params"],
                             search.cv_results_["mean_test_score"]):
        # A simulation that diverges on a validation block scores -inf.
        shown = f"{-score:.4f} V" if np.isfinite(score) else "diverged"
        print(f"  {params}: validation RMS {shown}")
    # The best candidate, refitted on the whole estimation record, is
    # evaluated on the test record; nothing was chosen with it.
    rms_test = rms_error(data.y_test, search.predict(data.X_test))
    print(f"Chosen: {search.best_params_}; test RMS {rms_test:.4f} V")
    return search


# %%
# NLSS2: the state-estimation weight ``alpha`` and the number of neurons, with
# the initial state estimated (third order, as in the paper).
nlss2_search = run_search(
    NLSS2Regressor(n_states=3, estimate_x0=True, validation_fraction=0.3, max_iter=50,
                   random_state=0),
    {"alpha": [1.0, 10.0, 100.0], "n_neurons": [1, 2]},
)

# %%
# The validation RMS of the NLSS2 candidates (lower is better):
results = nlss2_search.cv_results_
alphas, neurons = [1.0, 10.0, 100.0], [1, 2]
scores = np.full((len(neurons), len(alphas)), np.nan)
for params, score in zip(results["params"], results["mean_test_score"]):
    scores[neurons.index(params["n_neurons"]), alphas.index(params["alpha"])] = -score
fig, ax = plt.subplots(figsize=(5, 3), layout="constrained")
image = ax.imshow(scores, cmap="viridis_r")
ax.set_xticks(range(len(alphas)), [f"{a:g}" for a in alphas])
ax.set_yticks(range(len(neurons)), neurons)
ax.set_xlabel("alpha (state-estimation weight)")
ax.set_ylabel("neurons per network")
for (i, j), value in np.ndenumerate(scores):
    ax.text(j, i, f"{value:.3f}", ha="center", va="center",
            bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "none"})
fig.colorbar(image, ax=ax, label="validation RMS (V)")

# %%
# PNLSS: the model order and the polynomial degrees.
pnlss_search = run_search(
    PNLSSRegressor(validation_fraction=0.3, max_iter=30),
    {"n_states": [2, 3], "degree": [2, 3, (2, 3)]},
)
