"""
Best Linear Approximation of the Cascaded Tanks
===============================================

The first step of every identification in sknlss is linear: the Best Linear
Approximation (BLA) of the system. Cascaded Tanks has one non-periodic
estimation record that does not start at rest, so the nonparametric BLA is
estimated with the Local Polynomial Method, which also removes the transient.
A third-order balanced state-space model is then fitted to it (16 parameters,
as in the paper's Table 2), and simulated on the estimation and test records.
"""

# %%
# The data
# --------
# The measured benchmark records are read from ``$SKNLSS_DATA`` (or
# downloaded); without them the example runs on the simulated tanks.
import time

import matplotlib.pyplot as plt

from sknlss import BLAEstimator
from sknlss.datasets import load_cascaded_tanks, make_cascaded_tanks
from sknlss.metrics import rms_error
from sknlss.plotting import plot_frf, plot_simulation

try:
    data = load_cascaded_tanks()
    print(f"Measured Cascaded Tanks data from {data.filename}")
except FileNotFoundError as exc:
    print(f"{exc}\nTHE REAL DATA ARE ABSENT: using simulated tanks (make_cascaded_tanks).")
    data = make_cascaded_tanks(random_state=0)

# %%
# Fitting the BLA
# ---------------
# ``estimate_x0=True`` estimates the unknown initial state on the estimation
# record; the test record starts from the same state, so ``predict`` reuses it.
start = time.perf_counter()
bla = BLAEstimator(n_states=3, estimate_x0=True).fit(data.X_est, data.y_est)
fit_time = time.perf_counter() - start

y_est = bla.predict(data.X_est)
y_test = bla.predict(data.X_test)
print(f"BLA: {bla.n_params_} parameters, fitted in {fit_time:.2f} s")
print(f"RMS error on the estimation record: {rms_error(data.y_est, y_est):.4f} V")
print(f"RMS error on the test record:       {rms_error(data.y_test, y_test):.4f} V")
print("(paper, Table 2: 0.547 V on its estimation part, 0.753 V on the test record)")

# %%
# The frequency response
# ----------------------
# The nonparametric BLA, the parametric model and the level of the total
# distortion (noise plus nonlinear distortions): the Local Polynomial Method
# cannot tell noise and nonlinear distortions apart on a single non-periodic
# record, so one level is drawn (the paper's Fig. 2 uses periodic data for
# separate levels).
fig = plot_frf(bla, sampling_time=data.sampling_time)
fig.axes[0].set_xscale("log")

# %%
# Simulation on the estimation and test records
# ---------------------------------------------
# The linear model follows the slow dynamics but misses the overflow
# (saturation near 10 V) and the square-root characteristic of the outflows.
fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=True, layout="constrained")
plot_simulation(data.y_est, y_est, sampling_time=data.sampling_time, unit="V",
                label="BLA", ax=axes[0])
axes[0].set_title("Estimation record")
plot_simulation(data.y_test, y_test, sampling_time=data.sampling_time, unit="V",
                label="BLA", ax=axes[1])
axes[1].set_title("Test record")
plt.show()
