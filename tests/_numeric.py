"""Numerical reference derivatives shared by the tests."""

import numpy as np


def central_differences(func, theta, relative_step=1e-6):
    """Jacobian of ``func`` at ``theta`` by central differences.

    The step of parameter k is ``relative_step * max(1, |theta[k]|)``. The
    parameter axis is the last axis of the result, after the shape of
    ``func(theta)``.
    """
    columns = []
    for k in range(theta.size):
        step = relative_step * max(1.0, abs(theta[k]))
        up, down = theta.copy(), theta.copy()
        up[k] += step
        down[k] -= step
        columns.append((func(up) - func(down)) / (2 * step))
    return np.stack(columns, axis=-1)
