"""
A plant with dead time
======================

A transport delay between the input and its first effect is common in
process data. A discrete-time state-space model holds a delay of ``d``
samples in up to ``d`` extra states, so a model whose order is chosen for the
dynamics fits badly. ``input_delay`` gives every estimator the delay instead:
the model is identified on the delayed input and needs no states for it.

The plant here is a second-order low-pass filter behind a three-sample delay,
with a static nonlinearity ``w = v + 0.3 v**3`` at its input (a Hammerstein
system): its output first responds to an input three samples later.
"""

# %%
# The data
# --------
# Low-pass random inputs, an estimation record with 1 % output noise and a
# noise-free test record from another input realization.
import textwrap
import warnings

import matplotlib.pyplot as plt
import numpy as np
from scipy.signal import lfilter
from sklearn.model_selection import GridSearchCV, TimeSeriesSplit

from sknlss import BLAEstimator, NLLFRRegressor, PNLSSRegressor
from sknlss.metrics import nrmse

DELAY = 3
rng = np.random.default_rng(1)


def low_pass_input(n_samples):
    u = lfilter([1.0], [1.0, -0.5], rng.standard_normal(n_samples))
    return u / u.std()


def plant(u):
    v = np.concatenate([np.zeros(DELAY), u[:-DELAY]])
    return lfilter([0.1], [1.0, -1.6, 0.68], v + 0.3 * v**3)


u_est, u_test = low_pass_input(2000), low_pass_input(1000)
y_est = plant(u_est)
y_est += 0.01 * y_est.std() * rng.standard_normal(y_est.size)
y_test = plant(u_test)
X_est, X_test = u_est[:, None], u_test[:, None]

# %%
# Finding the delay
# -----------------
# A BLA fitted without ``input_delay`` notices a late response by itself:
# when it simulates its data with an RMS error above half the output's
# standard deviation, its fit tries the input delayed by up to 20 samples and
# names the delays that halve the error. The plant has no zeros, so two states
# can themselves delay the response by up to two samples: delays of 1, 2 and
# 3 give the same model here, and any of them holds the dead time.
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    BLAEstimator(n_states=2).fit(X_est, y_est)
hint = next(str(w.message) for w in caught if "responds to the input late" in str(w.message))
print(textwrap.fill(hint, 79))

# %%
# An unknown delay is also a structure parameter like the model order, which
# a grid search on the BLA finds quickly. Each fold of the time-series split
# starts from rest, so it is scored after a transient. The fits without a
# delay warn as above (and as worse than the output's mean); the warnings are
# counted here.
search = GridSearchCV(BLAEstimator(n_states=2, n_transient=50),
                      {"input_delay": range(8)}, cv=TimeSeriesSplit(3))
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    delay = search.fit(X_est, y_est).best_params_["input_delay"]
print(f"delay found on the estimation record: {delay} samples "
      f"({len(caught)} warnings from the 25 fits of the search)")

# %%
# Models with and without the delay
# ---------------------------------
# Two states each; the test error is the normalised RMS error after the first
# 100 samples (the models start from rest, the test record too). The fits
# without the delay repeat the hint above, which is not printed again.
models = {
    "BLA": lambda d: BLAEstimator(n_states=2, input_delay=d),
    "PNLSS": lambda d: PNLSSRegressor(n_states=2, degree=3, random_state=0, input_delay=d),
    "NL-LFR": lambda d: NLLFRRegressor(n_states=2, random_state=0, input_delay=d),
}
predictions = {}
for name, make in models.items():
    for d in (0, delay):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            y_sim = make(d).fit(X_est, y_est).predict(X_test)
        predictions[name, d] = y_sim
        print(f"{name:7s} input_delay={d}: test NRMSE "
              f"{nrmse(y_test[100:], y_sim[100:]):.4f}")

# %%
# Without the delay the two-state BLA is no better than the output's mean (an
# NRMSE of 1), and the nonlinear models start from it; with the delay, the
# errors drop by a factor of three to thirteen.
t = np.arange(200, 400)
fig, ax = plt.subplots(figsize=(8, 3.5))
ax.plot(t, y_test[t], "k", label="test output")
ax.plot(t, predictions["NL-LFR", 0][t], label="NL-LFR, input_delay=0")
ax.plot(t, predictions["NL-LFR", delay][t], "--", label=f"NL-LFR, input_delay={delay}")
ax.set_xlabel("sample")
ax.set_ylabel("output")
ax.legend(loc="upper right")
fig.tight_layout()
plt.show()
