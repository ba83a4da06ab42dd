"""Neural-network terms of the NLSS2 model.

Each of the ``n_states + n_outputs`` components of ``h = [h_x; h_y]`` is its
own one-hidden-layer network of ``n_neurons`` units on ``s = [x; u]``:

    h_j(s) = sum_{k in block j} v_k act(W_k s + b_k) + c_j.

The terms' parameters are those of the state networks (``h_x``), then those
of the output networks (``h_y``), each part laid out as ``[vec(W), b, v, c]``
with the hidden units of component ``j`` in rows ``j * n_neurons`` to
``(j + 1) * n_neurons - 1``.
"""

import math

import numpy as np
from numba import njit

from .._core._kernels import CACHE, EVALUATE, PARAMETER_JACOBIAN, STATE_JACOBIAN
from .._core._model import Terms

#: Activation codes understood by the compiled functions.
ACTIVATIONS = {"sigmoid": 0, "tanh": 1}


@njit(cache=CACHE, inline="always")
def _part_offsets(base, n_components, n_neurons, n_vars):
    """Offsets of W, b, v, c of a part (state or output networks) and its end."""
    n_hidden = n_components * n_neurons
    o_b = base + n_hidden * n_vars
    o_v = o_b + n_hidden
    o_c = o_v + n_hidden
    return base, o_b, o_v, o_c, o_c + n_components


@njit(cache=CACHE, inline="always")
def _activate(a, activation):
    """Unit output and its derivative for the pre-activation ``a``."""
    if activation == 0:
        # exp(-a) overflows to inf for very negative a, giving the right limit 0.
        value = 1.0 / (1.0 + math.exp(-a))
        return value, value * (1.0 - value)
    value = math.tanh(a)
    return value, 1.0 - value * value


@njit(cache=CACHE, inline="always")
def _evaluate_part(theta, base, n_components, n_neurons, activation, s, work, first_unit,
                   h, first_row):
    n_vars = s.shape[0]
    o_w, o_b, o_v, o_c, _ = _part_offsets(base, n_components, n_neurons, n_vars)
    n_hidden = work.shape[0] // 2
    for j in range(n_components):
        acc_out = theta[o_c + j]
        for k in range(j * n_neurons, (j + 1) * n_neurons):
            acc = theta[o_b + k]
            for i in range(n_vars):
                acc += theta[o_w + k * n_vars + i] * s[i]
            value, slope = _activate(acc, activation)
            work[first_unit + k] = value
            work[n_hidden + first_unit + k] = slope
            acc_out += theta[o_v + k] * value
        h[first_row + j] = acc_out


@njit(cache=CACHE, inline="always")
def _state_jacobian_part(theta, base, n_components, n_neurons, n, n_vars, work,
                         first_unit, dh_dx, first_row):
    o_w, _, o_v, _, _ = _part_offsets(base, n_components, n_neurons, n_vars)
    n_hidden = work.shape[0] // 2
    for j in range(n_components):
        for i in range(n):
            acc = 0.0
            for k in range(j * n_neurons, (j + 1) * n_neurons):
                acc += (theta[o_v + k] * work[n_hidden + first_unit + k]
                        * theta[o_w + k * n_vars + i])
            dh_dx[first_row + j, i] = acc


@njit(cache=CACHE, inline="always")
def _parameter_jacobian_part(theta, base, n_components, n_neurons, s, work, first_unit,
                             out, out_offset):
    n_vars = s.shape[0]
    o_w, o_b, o_v, o_c, _ = _part_offsets(base, n_components, n_neurons, n_vars)
    n_hidden = work.shape[0] // 2
    for j in range(n_components):
        row = out[j]
        for k in range(j * n_neurons, (j + 1) * n_neurons):
            g = theta[o_v + k] * work[n_hidden + first_unit + k]
            for i in range(n_vars):
                row[out_offset + o_w + k * n_vars + i] += g * s[i]
            row[out_offset + o_b + k] += g
            row[out_offset + o_v + k] += work[first_unit + k]
        row[out_offset + o_c + j] += 1.0


# spec = [n_neurons, activation]; work = [unit outputs, unit slopes] of all
# (n_states + n_outputs) * n_neurons units.
@njit(EVALUATE, cache=CACHE)
def _evaluate(theta, spec, s, n, h, work):
    n_neurons, activation = spec[0], spec[1]
    n_y = h.shape[0] - n
    end = _part_offsets(0, n, n_neurons, s.shape[0])[4]
    _evaluate_part(theta, 0, n, n_neurons, activation, s, work, 0, h, 0)
    _evaluate_part(theta, end, n_y, n_neurons, activation, s, work, n * n_neurons, h, n)


@njit(STATE_JACOBIAN, cache=CACHE)
def _state_jacobian(theta, spec, s, n, dh_dx, work):
    n_neurons = spec[0]
    n_y = dh_dx.shape[0] - n
    n_vars = s.shape[0]
    end = _part_offsets(0, n, n_neurons, n_vars)[4]
    _state_jacobian_part(theta, 0, n, n_neurons, n, n_vars, work, 0, dh_dx, 0)
    _state_jacobian_part(theta, end, n_y, n_neurons, n, n_vars, work, n * n_neurons,
                         dh_dx, n)


@njit(PARAMETER_JACOBIAN, cache=CACHE)
def _parameter_jacobian(theta, spec, s, n, work, state_out, state_offset, output_out,
                        output_offset):
    n_neurons = spec[0]
    end = _part_offsets(0, n, n_neurons, s.shape[0])[4]
    _parameter_jacobian_part(theta, 0, n, n_neurons, s, work, 0, state_out, state_offset)
    if output_offset >= 0:
        _parameter_jacobian_part(theta, end, output_out.shape[0], n_neurons, s, work,
                                 n * n_neurons, output_out, output_offset)


class NetworkTerms(Terms):
    """One one-hidden-layer network per component of ``h_x`` and ``h_y``.

    Parameters
    ----------
    n_states, n_inputs, n_outputs : int
        Dimensions.
    n_neurons : int
        Hidden units per network.
    activation : {"sigmoid", "tanh"}
        Activation of the hidden units.
    """

    evaluate = staticmethod(_evaluate)
    state_jacobian = staticmethod(_state_jacobian)
    parameter_jacobian = staticmethod(_parameter_jacobian)
    # With zero output weights, the output networks are their biases.
    output_constant = "g_c"

    def __init__(self, n_states, n_inputs, n_outputs, n_neurons, activation):
        n_vars = n_states + n_inputs
        self.blocks = self.layout(n_states, n_inputs, n_outputs, n_neurons)
        self.spec = np.array([n_neurons, ACTIVATIONS[activation]], dtype=np.int64)
        self.work_size = 2 * (n_states + n_outputs) * n_neurons
        self.n_state_params = n_states * n_neurons * (n_vars + 2) + n_states

    @staticmethod
    def layout(n_states, n_inputs, n_outputs, n_neurons):
        """The parameter blocks ``(name, shape)``, known before the terms are built."""
        n_vars = n_states + n_inputs
        blocks = []
        for part, n_components in (("f", n_states), ("g", n_outputs)):
            n_hidden = n_components * n_neurons
            blocks += [(f"{part}_W", (n_hidden, n_vars)), (f"{part}_b", (n_hidden,)),
                       (f"{part}_v", (n_hidden,)), (f"{part}_c", (n_components,))]
        return blocks

    def decay_mask(self):
        """The weights W and v are decayed, the biases are not."""
        return np.concatenate([np.full(int(np.prod(shape)), name.endswith(("_W", "_v")))
                               for name, shape in self.blocks])
