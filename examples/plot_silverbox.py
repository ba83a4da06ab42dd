"""
The Silverbox: an NL-LFR model with 17 parameters
=================================================

The Silverbox is an electronic circuit that behaves like a mass on a
hardening spring: second-order linear dynamics with a cubic static
nonlinearity in feedback. That is exactly the structure of the NL-LFR model
of :class:`~sknlss.NLLFRRegressor`,

.. math::

   x(t+1) &= A\\,x(t) + B\\,u(t) + B_w\\,w(t), \\qquad
   y(t) = C\\,x(t) + D\\,u(t) + D_w\\,w(t), \\\\
   z(t) &= C_z\\,x(t) + D_z\\,u(t), \\qquad w(t) = f\\bigl(z(t)\\bigr),

with two states and one branch :math:`f(z) = c_2 z^2 + c_3 z^3`: 9 parameters
for the linear part, 3 for :math:`[B_w; D_w]`, 3 for :math:`[C_z, D_z]` and 2
coefficients, 17 in all. This example fits it, and a full second-order PNLSS
model (all monomials of degree 2 and 3 in :math:`[x; u]`), on the estimation
record with the estimators' defaults, and compares both with the Best Linear
Approximation on the three test records of the benchmark.
"""

# %%
# Data
# ----
# Estimation: 65,062 samples of odd random-phase multisines. Tests: a
# multisine, the "arrow" (filtered noise of growing amplitude) and the full
# arrow, whose end exceeds the amplitude of the estimation data. Each test
# record is simulated from its start, from the initial state that fits its
# first ``init_window`` (50) samples (``estimate_initial_state``: the records
# start mid-motion); the error is the RMS over the other samples, in
# millivolts.
import time

import matplotlib.pyplot as plt
import numpy as np

from sknlss import BLAEstimator, NLLFRRegressor, PNLSSRegressor, PolynomialBasis
from sknlss.benchmarks import load_benchmark
from sknlss.metrics import rms_error
from sknlss.plotting import plot_simulation

data, source = load_benchmark("silverbox")
print(f"Silverbox, data: {source}")
print(f"{len(data.y_est)} estimation samples; test records: {', '.join(data.tests)}")
skip = data.init_window

# %%
# Fitting
# -------
# Only the model structure is given. The record starts mid-motion and the
# initial state is not estimated, so the nonlinear models leave the settling
# time of the linear model's slowest pole out of their cost
# (``fit_transient_``).
models = {
    "BLA": BLAEstimator(n_states=2),
    "NL-LFR": NLLFRRegressor(n_states=2, random_state=0),
    "PNLSS": PNLSSRegressor(n_states=2, random_state=0),
}
for name, model in models.items():
    start = time.perf_counter()
    model.fit(data.X_est, data.y_est)
    print(f"{name:6s} {model.n_params_:3d} parameters, fitted in "
          f"{time.perf_counter() - start:5.1f} s")

# %%
# Test errors
# -----------
# RMS errors in mV over ``y[50:]`` of each test record, simulated from the
# state that fits ``y[:50]``.
simulations = {
    name: {record: model.predict(
        test.X, x0=model.estimate_initial_state(test.X[:skip], test.y[:skip]))
        for record, test in data.tests.items()}
    for name, model in models.items()
}
print(f"{'model':8s}" + "".join(f"{record:>12s}" for record in data.tests))
for name, simulated in simulations.items():
    errors = [1e3 * rms_error(test.y[skip:], simulated[record][skip:])
              for record, test in data.tests.items()]
    print(f"{name:8s}" + "".join(f"{error:12.3f}" for error in errors))

# %%
# The full arrow
# --------------
# The simulation errors of the two nonlinear models on the last test record
# (the full arrow). The dotted line marks the first sample whose measured
# output leaves the range of the estimation output: from there on the models
# extrapolate.
record = list(data.tests)[-1]
test = data.tests[record]
outside = np.flatnonzero((test.y < data.y_est.min()) | (test.y > data.y_est.max()))
nonlinear = {name: 1e3 * simulations[name][record] for name in ("NL-LFR", "PNLSS")}
fig = plot_simulation(1e3 * test.y, nonlinear, sampling_time=data.sampling_time,
                      unit="mV")
fig.suptitle(f"Test record '{record}'")
if outside.size:
    for ax in fig.axes:
        ax.axvline(outside[0] * data.sampling_time, color="k", linestyle=":",
                   linewidth=1.0)
    print(f"'{record}': the output leaves the estimation range at "
          f"{outside[0] * data.sampling_time:.1f} s ({outside.size} samples outside)")

# %%
# The static nonlinearity of the NL-LFR model
# -------------------------------------------
# The branch input :math:`z = C_z x + D_z u` along the model's own simulation,
# in the model's normalised coordinates (the states of ``simulate`` and the
# input scaled by ``u_offset_`` and ``u_scale_``), and the fitted
# :math:`w = f(z)` from ``coefficients_`` and the basis of the kept model,
# ``basis_`` (with ``basis=None``, the held-out loss chose between the powers
# 2 and 3 and the Legendre polynomials of degrees 1 to 3 of ``tanh(z)``).
nllfr = models["NL-LFR"]
basis = nllfr.basis_


def branch_input(X):
    _, states = nllfr.simulate(X, return_states=True)
    u = (X - nllfr.u_offset_) / nllfr.u_scale_
    return (states @ nllfr.Cz_.T + u @ nllfr.Dz_.T)[:, 0]


# Beyond the range of z on the estimation record, ``branch_input_range_``, a
# power series keeps its curvature and a bounded basis goes on along its
# tangent (``extrapolation="auto"``, the default; ``extrapolation_`` says
# which the model applies). For a cubic spring the curvature is the physical
# law. The figure shows both continuations of the fitted f.
z_test = branch_input(test.X)
low, high = nllfr.branch_input_range_[:, 0]
grid = np.linspace(min(low, z_test.min()), max(high, z_test.max()), 400)
inside = np.clip(grid, low, high)
values, slopes = basis.evaluate(inside)
coefficients = nllfr.coefficients_[0]
w_tangent = values @ coefficients + (slopes @ coefficients) * (grid - inside)
w_basis = basis.evaluate(grid)[0] @ coefficients
term = "z^{}" if isinstance(basis, PolynomialBasis) else "P_{}(tanh z)"
print("f(z) = " + " + ".join(f"{c:.4g} {term.format(d)}"
                             for c, d in zip(nllfr.coefficients_[0], basis.degrees)))
print(f"z on the estimation record: {low:.3f} to {high:.3f}; "
      f"on '{record}': {z_test.min():.3f} to {z_test.max():.3f}")
print(f"'{record}' takes z below the estimation range in "
      f"{np.count_nonzero(z_test < low)} samples, above it in "
      f"{np.count_nonzero(z_test > high)}; the model continues f with "
      f"extrapolation_={nllfr.extrapolation_!r}")

applied = {"continue": "basis combination", "linear": "tangent"}[nllfr.extrapolation_]
fig, ax = plt.subplots(figsize=(8, 4), layout="constrained")
ax.axvspan(low, high, color="0.9", label="range on the estimation record")
ax.plot(grid, w_basis, "C1--", label='basis combination ("continue")')
ax.plot(grid, w_tangent, "C0:", label='tangent beyond the range ("linear")')
ax.set_xlabel("branch input z (normalised units)")
ax.set_ylabel("branch output w = f(z)")
ax.grid(True, alpha=0.3)
ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
ax.set_title(f"NL-LFR branch f(z) on '{record}'\n(the model: {applied})")
plt.show()
