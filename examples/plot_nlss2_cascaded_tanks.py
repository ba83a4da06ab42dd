"""
NLSS2 on the Cascaded Tanks
===========================

NLSS2 (paper §3.2, §4.2) adds small neural networks :math:`f_{NL}` and
:math:`g_{NL}` to a linear state-space model. Instead of starting the
nonlinear optimisation with zero nonlinearity, it first estimates a state
sequence from the BLA by regularised least squares (weight ``alpha`` on the
state equation), fits the networks to what the linear model leaves
unexplained along those states, and only then minimises the simulation error.

``alpha="auto"`` chooses the weight on the held-out last 30% of the
estimation record, which also selects the iteration and the best of
``n_init`` random initialisations of the networks. The test record is used
for the final evaluation only.
"""

# %%
# Data
# ----
import time

import matplotlib.pyplot as plt
import numpy as np

from sknlss import NLSS2Regressor
from sknlss.datasets import load_cascaded_tanks, make_cascaded_tanks
from sknlss.metrics import rms_error
from sknlss.plotting import plot_error_spectrum, plot_simulation

try:
    data = load_cascaded_tanks()
    print(f"Measured Cascaded Tanks data from {data.filename}")
except FileNotFoundError as exc:
    print(f"{exc}\nTHE REAL DATA ARE ABSENT: using simulated tanks (make_cascaded_tanks).")
    data = make_cascaded_tanks(random_state=0)

# %%
# Fitting
# -------
# Third order, two sigmoid neurons per network, initial state estimated:
# 71 parameters, as in the paper.
model = NLSS2Regressor(n_states=3, n_neurons=2, alpha="auto", estimate_x0=True,
                       validation_fraction=0.3, n_init=3, random_state=0)
start = time.perf_counter()
model.fit(data.X_est, data.y_est)
elapsed = time.perf_counter() - start

y_est = model.predict(data.X_est)
y_test = model.predict(data.X_test)
print(f"NLSS2: {model.n_params_} parameters, alpha={model.alpha_:g}, "
      f"{model.n_iter_} iterations, fitted in {elapsed:.1f} s")
print(f"RMS error on the estimation record: {rms_error(data.y_est, y_est):.4f} V")
print(f"RMS error on the test record:       {rms_error(data.y_test, y_test):.4f} V")
print("(paper: 0.117 V on the estimation record, 0.343 V on the test record)")

# %%
# Estimated and simulated states
# ------------------------------
# The states estimated from the linear model (the starting point of the
# networks) against the states of the final model simulated on the fitted part
# of the estimation record. They are in the normalised state coordinates of
# the BLA's balanced realization.
_, states = model.simulate(data.X_est, return_states=True)
n_fitted = model.states_init_.shape[0]
time_axis = data.sampling_time * np.arange(n_fitted)
fig, axes = plt.subplots(model.n_states, 1, figsize=(8, 6), sharex=True,
                         layout="constrained")
for i, ax in enumerate(axes):
    ax.plot(time_axis, model.states_init_[:, i], "k-", linewidth=1.0,
            label="estimated from the BLA")
    ax.plot(time_axis, states[:n_fitted, i], "C1-", linewidth=1.0,
            label="simulated, final model")
    ax.set_ylabel(f"$x_{i + 1}$ (normalised)")
    ax.grid(True, alpha=0.3)
axes[0].legend()
axes[-1].set_xlabel("Time (s)")

# %%
# Test record in time and frequency
# ---------------------------------
fig, axes = plt.subplots(2, 1, figsize=(8, 7), layout="constrained")
plot_simulation(data.y_test, y_test, sampling_time=data.sampling_time, unit="V",
                label="NLSS2", ax=axes[0])
axes[0].set_title("Test record")
plot_error_spectrum(data.y_test, y_test, sampling_time=data.sampling_time, unit="V",
                    label="NLSS2", ax=axes[1])
axes[1].set_xscale("log")
plt.show()
