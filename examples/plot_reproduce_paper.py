"""
Reproducing the paper's tables on the Cascaded Tanks
====================================================

The analogues of Tables 2, 3 and 4 of Relan et al. (2018), with the
estimators' defaults and the paper's model structures:

* **Table 2** -- BLA against PNLSS (no initial state), both fitted on the first
  70% of the estimation record ("Model Est"), with the last 30% ("Model Val")
  used to select the PNLSS iterate, and the benchmark test record ("Model
  Test");
* **Table 3** -- PNLSS-I fitted on the first 500, 600 or 700 samples of the
  estimation record, with monomials of degree 2 only or 2 and 3;
* **Table 4** -- the comparison of all models on the full benchmark records,
  by :func:`sknlss.benchmarks.reproduce` (the function behind
  ``python -m sknlss reproduce``).

The test record is never used for fitting or selection. All RMS errors are in
volts; the paper's values are shown in parentheses.
"""

# %%
# Data
# ----
import time
import warnings

import matplotlib.pyplot as plt
import numpy as np

from sknlss import BLAEstimator, DataWarning, LinearFallbackWarning, PNLSSRegressor
from sknlss.benchmarks import load_benchmark, reproduce
from sknlss.metrics import rms_error

data, source = load_benchmark("cascaded_tanks")
print(f"Cascaded Tanks, data: {source}")
n_est = data.y_est.shape[0]


def split_errors(model, n_fit):
    """RMS on the fitted part, the rest of the estimation record and the test record."""
    y_est = model.predict(data.X_est)
    y_test = model.predict(data.X_test)
    return (rms_error(data.y_est[:n_fit], y_est[:n_fit]),
            rms_error(data.y_est[n_fit:], y_est[n_fit:]),
            rms_error(data.y_test, y_test))


def show(value):
    return f"{value:.4f}" if np.isfinite(value) else "diverged"


# %%
# Table 2: BLA and PNLSS on a 70/30 split
# ---------------------------------------
# The BLA is fitted on the first 70% only. The PNLSS model holds out the last
# 30% (``validation_fraction=0.3``, the paper's split, for all its starts
# instead of the shares the default gives them in turn): its cost uses the
# first 70%, and the start and iterate with the lowest error on the last 30%
# are kept. As in the paper, neither estimates the initial state: the PNLSS
# cost leaves out the first tenth of the record, less than its linear start
# takes to settle, which the fit's :class:`~sknlss.DataWarning` would point
# out (silenced here: Table 3 and Table 4 estimate the state).
start = time.perf_counter()
n_fit = n_est - int(round(0.3 * n_est))
bla = BLAEstimator(n_states=3).fit(data.X_est[:n_fit], data.y_est[:n_fit])
pnlss = PNLSSRegressor(n_states=3, degree=(2, 3), validation_fraction=0.3,
                       random_state=0)
with warnings.catch_warnings():
    warnings.simplefilter("ignore", DataWarning)
    pnlss.fit(data.X_est, data.y_est)
table2 = {"BLA": (bla.n_params_, *split_errors(bla, n_fit)),
          "PNLSS": (pnlss.n_params_, *split_errors(pnlss, n_fit))}
paper2 = {"BLA": (16, 0.54708, 0.75743, 0.75331),
          "PNLSS": (131, 0.1133, 0.75063, 0.69737)}
print(f"Table 2 ({time.perf_counter() - start:.1f} s)")
print(f"{'':12s}{'BLA':>22s}{'PNLSS':>22s}")
for row, label in enumerate(["parameters", "Model Est", "Model Val", "Model Test"]):
    cells = []
    for name in ("BLA", "PNLSS"):
        ours, theirs = table2[name][row], paper2[name][row]
        if row == 0:
            cells.append(f"{ours} ({theirs})")
        else:
            cells.append(f"{show(ours)} ({theirs:.4f})")
    print(f"{label:12s}{cells[0]:>22s}{cells[1]:>22s}")

# %%
# Table 3: PNLSS-I with shorter estimation parts
# ----------------------------------------------
# The estimation record is split into 500, 600 or 700 samples for fitting and
# the rest for selecting the start and the iterate; "degree 2" has only
# quadratic monomials, "degree 2, 3" quadratic and cubic ones. The paper
# varies the degree of the state equation (its table does not give the output
# equation's); here ``degree`` sets both equations.
paper3 = {(500, 2): (0.044729, 0.86985, 0.66801),
          (500, (2, 3)): (0.018701, 0.87438, 0.66404),
          (600, 2): (0.046441, 0.88059, 0.67691),
          (600, (2, 3)): (0.020913, 0.83852, 0.75611),
          (700, 2): (0.041328, 0.75957, 0.47088),
          (700, (2, 3)): (0.021346, 0.74075, 0.64381)}
start = time.perf_counter()
table3, linear_kept = {}, []
for n_fit, degree in paper3:
    model = PNLSSRegressor(n_states=3, degree=degree, estimate_x0=True,
                           validation_fraction=(n_est - n_fit) / n_est, random_state=0)
    with warnings.catch_warnings():
        # Said below the table instead.
        warnings.simplefilter("ignore", LinearFallbackWarning)
        model.fit(data.X_est, data.y_est)
    table3[n_fit, degree] = split_errors(model, n_fit)
    if model.fell_back_to_linear_:
        linear_kept.append(f"{n_fit} samples, degree {degree}; starts: "
                           f"{', '.join(model.start_status_)}")
print(f"Table 3 ({time.perf_counter() - start:.1f} s)")
print(f"{'':22s}{'degree 2':>24s}{'degree 2, 3':>24s}")
for n_fit in (500, 600, 700):
    print(f"estimation length {n_fit}")
    for row, label in enumerate(["Model Est", "Model Val", "Model Test"]):
        cells = [f"{show(table3[n_fit, d][row])} ({paper3[n_fit, d][row]:.4f})"
                 for d in (2, (2, 3))]
        print(f"  {label:20s}{cells[0]:>24s}{cells[1]:>24s}")
# A fit whose starts all ran away beyond the estimation amplitude, or did
# not beat the linear model on the held-out samples, keeps its linear model.
for fit in linear_kept:
    print(f"linear model kept ({fit})")

# %%
# Table 4: all models on the benchmark records
# --------------------------------------------
# Every model is fitted on the whole estimation record with its defaults and
# the paper's structure (selection on held-out ends of that record, initial
# state estimated there and reused on the test record, except for the PNLSS
# model, the paper's PNLSS without it). ``test[50:]`` is the
# nonlinear_benchmarks variant that lets the first 50 test samples set the
# state (the initial state that fits them). One random state keeps this
# example short; the main job (``python -m sknlss reproduce``) fits every
# model at several random states and reports the median and the range of the
# errors.
rows = reproduce(["cascaded_tanks"], random_states=(0,))["cascaded_tanks"]

# %%
# Test errors against the paper
# -----------------------------
# The paper has no NL-LFR model and no PNLSS model without initial state on
# the full records; a diverging simulation is drawn as a missing bar.
paper4 = {"BLA": 0.753, "PNLSS-I": 0.450, "decoupled PNLSS-I": 0.497, "NLSS2": 0.343}
names = [row["model"] for row in rows]
ours = np.array([row["test"] for row in rows])
theirs = np.array([paper4.get(name, np.nan) for name in names])
positions = np.arange(len(names))
fig, ax = plt.subplots(figsize=(8, 4), layout="constrained")
ax.bar(positions - 0.2, np.where(np.isfinite(ours), ours, 0.0), width=0.4,
       label="sknlss")
ax.bar(positions + 0.2, np.nan_to_num(theirs), width=0.4, label="Relan et al. (2018)")
ax.set_xticks(positions, names, rotation=20)
ax.set_ylabel("RMS error on the test record (V)")
ax.set_title("Cascaded Tanks benchmark")
ax.grid(True, axis="y", alpha=0.3)
ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
plt.show()
