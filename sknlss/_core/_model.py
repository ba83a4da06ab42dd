"""Parameter layout of a state-space model and its calls into the kernels.

A :class:`StateSpaceModel` joins the linear part shared by every model with a
*terms* object that describes the model's nonlinear terms ``h = [h_x; h_y]``
(see :mod:`sknlss._core._kernels` for the contract). The layout of the
parameter vector is defined here once, for the kernels and for Python:

    theta = [vec(A), vec(B), vec(C), vec(D), theta_terms, x0, y0 (if estimated)]

where ``y0`` is a constant added to the outputs. It is estimated with the
initial state, as the BLA estimates it (see
:func:`sknlss._linear._realization.estimate_initial_state`): the
normalised signals are centred on their means, which are not the levels that
a record starting out of equilibrium settles about. The kernels never read
it; this module adds it to their outputs and its identity sensitivity to
their Jacobian. Terms that add a constant of their own to every output (the
biases of NLSS2's output networks, see ``Terms.output_constant``) hold the
offset there instead: a separate ``y0`` would duplicate those parameters.
"""

import math

import numpy as np

from . import _kernels


def _array(values, dtype=np.float64):
    """C-contiguous and writable, as the compiled signatures require (a read-only
    array, e.g. from a memory map, is copied)."""
    return np.require(values, dtype=dtype, requirements=["C", "W"])


def _contiguous(U, starts):
    return _array(U), _array(starts, np.int64)


def parameter_count(blocks):
    """Number of parameters in blocks ``(name, shape)`` (exact for any size)."""
    return sum(math.prod(shape) for _, shape in blocks)


class Terms:
    """Nonlinear terms of a model: their parameter blocks and compiled functions.

    Subclasses set ``blocks`` (list of ``(name, shape)`` of the terms'
    parameter blocks, in the order of ``theta_terms``), ``spec`` (int64
    structure array read by the compiled functions), ``work_size`` (or
    ``work_init``, the initial content of the work array, when the terms keep
    constants there) and the
    three compiled functions ``evaluate``, ``state_jacobian`` and
    ``parameter_jacobian``, and ``n_state_params``: the number of the
    terms' parameters that enter ``h_x`` (they come first in ``theta_terms``).
    Terms with a block of shape (n_outputs,) that adds a constant to each
    output name it ``output_constant``; with the terms' other parameters at
    zero, the terms are then that constant.
    """

    blocks = ()
    output_constant = None
    spec = np.zeros(1, dtype=np.int64)
    work_size = 0
    n_state_params = 0

    @property
    def work_init(self):
        """Initial content of the work array of every kernel call."""
        return np.zeros(self.work_size)

    evaluate = staticmethod(_kernels.no_terms_evaluate)
    state_jacobian = staticmethod(_kernels.no_terms_state_jacobian)
    parameter_jacobian = staticmethod(_kernels.no_terms_parameter_jacobian)

    @property
    def n_params(self):
        """Number of parameters of the terms."""
        return parameter_count(self.blocks)

    def decay_mask(self):
        """Which of the terms' parameters the weight decay acts on (all by default)."""
        return np.ones(self.n_params, dtype=bool)


#: The range of an input that no point leaves, shape (2, 1).
_UNBOUNDED = np.array([[-np.inf], [np.inf]])


class RangedTerms(Terms):
    """Terms that go on otherwise beyond a box around the range of their
    inputs: along their tangents, or held at their value on its edge where
    the subclass allows it.

    Subclasses call :meth:`_set_range` and set ``_range_offset``, the position
    in the work array of the box's ``2 * n_ranged`` bounds (all lower ends,
    then all upper ends).
    """

    _range_offset = 0

    def _set_range(self, input_range, reach, n_ranged):
        """``input_range`` of shape (2, n_ranged), ``None`` for no bound. The
        terms are themselves inside the box of ``reach`` times the range's
        half-width about its centre; ``reach=inf``: everywhere (the range is
        then only a record of where their inputs went)."""
        unbounded = input_range is None
        if unbounded:
            input_range = _UNBOUNDED.repeat(n_ranged, axis=1)
        self.input_range = np.asarray(input_range, dtype=np.float64)
        self.reach = float(reach)
        if self.continued:
            self._box = _UNBOUNDED.repeat(n_ranged, axis=1)
        elif unbounded or self.reach == 1.0:
            # The range itself, exactly (centre and half-width would round it).
            self._box = self.input_range
        else:
            centre = self.input_range.mean(axis=0)
            half_width = np.ptp(self.input_range, axis=0) / 2
            self._box = np.vstack([centre - self.reach * half_width,
                                   centre + self.reach * half_width])

    @property
    def continued(self):
        """Whether the terms are themselves everywhere."""
        return self.reach == np.inf

    @property
    def work_init(self):
        """The work array with the box beyond which the terms go on otherwise
        (unbounded when they are continued)."""
        work = np.zeros(self.work_size)
        start = self._range_offset
        work[start : start + self._box.size] = self._box.ravel()
        return work


def _pointers(terms):
    """The terms' compiled functions, by address."""
    return (_kernels.function_pointer(terms.evaluate, _kernels.EVALUATE),
            _kernels.function_pointer(terms.state_jacobian, _kernels.STATE_JACOBIAN),
            _kernels.function_pointer(terms.parameter_jacobian,
                                      _kernels.PARAMETER_JACOBIAN))


class StateSpaceModel:
    """Linear part plus nonlinear terms, with the parameter layout.

    Parameters
    ----------
    n_states, n_inputs, n_outputs : int
        Dimensions.
    terms : Terms, default=None
        The nonlinear terms; ``None`` for a linear model.
    estimate_x0 : bool, default=False
        Whether the initial state and the output offset end the parameter
        vector (the offset only when the terms have no ``output_constant``,
        which holds it otherwise).
    n_sequences : int, default=1
        Number of sequences, each with its own estimated initial state: the
        block ``x0`` has shape (n_states,) for one, else (n_sequences,
        n_states).

    Attributes
    ----------
    offset_block : str or None
        The block holding the output offset: ``"y0"``, the terms'
        ``output_constant``, or None without ``estimate_x0``.
    """

    def __init__(self, n_states, n_inputs, n_outputs, terms=None, *, estimate_x0=False,
                 n_sequences=1):
        self.n_states, self.n_inputs, self.n_outputs = n_states, n_inputs, n_outputs
        self.terms = Terms() if terms is None else terms
        self.estimate_x0 = bool(estimate_x0)
        self.n_sequences = int(n_sequences)
        own_offset = self.terms.output_constant is None
        self.blocks = self.layout(n_states, n_inputs, n_outputs, self.terms.blocks,
                                  estimate_x0=self.estimate_x0, output_offset=own_offset,
                                  n_sequences=self.n_sequences)
        self.offset_block = (None if not self.estimate_x0 else "y0" if own_offset
                             else self.terms.output_constant)
        sizes = [int(np.prod(shape, dtype=np.int64)) for _, shape in self.blocks]
        self.offsets = dict(zip((name for name, _ in self.blocks), np.cumsum([0] + sizes)))
        self.n_params = int(sum(sizes))
        self.n_linear = parameter_count(self.blocks[:4])
        self.n_terms = self.terms.n_params

    @staticmethod
    def layout(n_states, n_inputs, n_outputs, terms_blocks=(), *, estimate_x0=False,
               output_offset=True, n_sequences=1):
        """The parameter blocks ``(name, shape)`` of the model, known before
        its terms are built: the linear part, the terms' blocks, then x0 with
        ``estimate_x0`` (one per sequence), and y0 too with ``output_offset``
        (False for terms with an ``output_constant``)."""
        n, n_u, n_y = n_states, n_inputs, n_outputs
        blocks = [("A", (n, n)), ("B", (n, n_u)), ("C", (n_y, n)), ("D", (n_y, n_u))]
        blocks += list(terms_blocks)
        if estimate_x0:
            blocks += [("x0", (n,) if n_sequences == 1 else (n_sequences, n))]
            blocks += [("y0", (n_y,))] if output_offset else []
        return blocks

    # ---------------------------------------------------------------- layout
    def columns(self, *names):
        """Indices in theta of the named blocks (absent names are skipped)."""
        index = []
        for name, shape in self.blocks:
            if name in names:
                begin = self.offsets[name]
                index.append(np.arange(begin, begin + int(np.prod(shape, dtype=np.int64))))
        return np.concatenate(index) if index else np.zeros(0, dtype=np.int64)

    @property
    def linear_columns(self):
        """Indices of A, B, C, D, x0 and the output offset."""
        return self.columns("A", "B", "C", "D", "x0", self.offset_block)

    def linear_values(self, theta):
        """A, B, C, D, x0 and the output offset ``y0`` of ``theta`` (whichever
        block holds it), keyed by block name, for a ``theta`` whose terms are
        otherwise off: the inverse of :meth:`pack_linear`."""
        values = self.unpack(theta)
        linear = {name: values[name] for name in ("A", "B", "C", "D", "x0") if name in values}
        if self.offset_block is not None:
            linear["y0"] = values[self.offset_block]
        return linear

    def pack_linear(self, linear):
        """The parameters with the linear part (and x0 and the output offset
        ``y0``) of ``linear`` (keyed by block name) and the terms switched off,
        but for the constant that holds the offset (see ``offset_block``)."""
        values = {name: np.zeros(shape) for name, shape in self.blocks}
        values.update((name, linear[name]) for name in ("A", "B", "C", "D", "x0")
                      if name in values)
        if self.offset_block is not None:
            values[self.offset_block] = linear["y0"]
        return self.pack(values)

    @property
    def terms_columns(self):
        """Indices of the terms' parameters."""
        return np.arange(self.n_linear, self.n_linear + self.n_terms)

    def pack(self, values):
        """Parameter vector from a dict of arrays keyed by block name."""
        return np.concatenate(
            [np.asarray(values[name], dtype=np.float64).reshape(-1) for name, _ in self.blocks]
        )

    def unpack(self, theta):
        """Dict of arrays (copies) keyed by block name."""
        return {
            name: np.array(theta[self.offsets[name] : self.offsets[name]
                                 + int(np.prod(shape, dtype=np.int64))]).reshape(shape)
            for name, shape in self.blocks
        }

    # ------------------------------------------------------------ simulation
    def initial_states(self, theta, n_sequences, x0=None):
        """Initial state of every sequence: ``x0`` if given, else the estimated
        one(s) in theta, else zero."""
        if x0 is None:
            if self.estimate_x0:
                begin = self.offsets["x0"]
                x0 = theta[begin : begin + self.n_sequences * self.n_states].reshape(
                    -1, self.n_states)
            else:
                x0 = np.zeros(self.n_states)
        x0 = np.asarray(x0, dtype=np.float64)
        return np.array(np.broadcast_to(x0, (n_sequences, self.n_states)), dtype=np.float64,
                        order="C")

    def simulate(self, theta, U, starts, x0=None):
        """Free-run simulation: outputs, states and the divergence flag.

        See :func:`sknlss._core._kernels.simulate`; ``x0`` defaults to
        :meth:`initial_states`.
        """
        terms = self.terms
        Y, X, diverged = _kernels.simulate(
            _array(theta), self.n_outputs, self.n_terms,
            _array(terms.spec, np.int64), terms.work_init, *_contiguous(U, starts),
            self.initial_states(theta, len(starts) - 1, x0), _pointers(terms)[0],
        )
        return self._with_output_offset(theta, Y), X, diverged

    def sensitivities(self, theta, U, starts, jacobian_rows, x0=None, *, with_local=False):
        """Outputs, states, the outputs' Jacobian on ``jacobian_rows``, the state
        map's local Jacobians there (with ``with_local``, else no rows) and the
        divergence flag (see :func:`sknlss._core._kernels.sensitivities`)."""
        terms = self.terms
        Y, X, J, local, diverged = _kernels.sensitivities(
            _array(theta), self.n_outputs, self.n_terms,
            terms.n_state_params, _array(terms.spec, np.int64), terms.work_init, *_contiguous(U, starts),
            self.initial_states(theta, len(starts) - 1, x0), self.estimate_x0,
            self.n_sequences > 1,
            _array(jacobian_rows, np.int64), with_local, *_pointers(terms),
        )
        if self.offset_block == "y0":
            # The kernels leave the columns of y0 at zero.
            outputs = np.arange(self.n_outputs)
            J[:, outputs, self.offsets["y0"] + outputs] = 1.0
        return self._with_output_offset(theta, Y), X, J, local, diverged

    def _with_output_offset(self, theta, Y):
        """The kernels' outputs ``Y`` plus the estimated output offset (in place)."""
        if self.offset_block == "y0":
            Y += theta[self.offsets["y0"] :]
        return Y

    def local_jacobians(self, theta, S):
        """``[A; C] + dh/dx`` at the points ``S = [x; u]``, shape
        (n_points, n_states + n_outputs, n_states)."""
        terms = self.terms
        return _kernels.local_jacobians(
            _array(theta), self.n_states, self.n_outputs,
            self.n_terms, _array(terms.spec, np.int64), terms.work_init,
            _array(S), *_pointers(terms)[:2],
        )

    def curvature_contraction(self, theta, S, G, step):
        """``sum_ij G[t, i, j] d^2 h_x,i / dx_j dtheta_k`` for the terms' parameters
        of h_x, at the points ``S`` (see
        :func:`sknlss._core._kernels.curvature_contraction`)."""
        terms = self.terms
        return _kernels.curvature_contraction(
            _array(theta), self.n_states, self.n_outputs,
            self.n_terms, terms.n_state_params, _array(terms.spec, np.int64), terms.work_init,
            _array(S),
            _array(G), float(step), *_pointers(terms),
        )

    def parameter_rms(self, theta, S):
        """RMS over the points ``S = [x; u]`` of the direct derivative of the terms
        with respect to each of their parameters, shape (n_terms,)."""
        terms = self.terms
        return _kernels.parameter_rms(
            _array(theta), self.n_states, self.n_outputs, self.n_terms,
            terms.n_state_params, _array(terms.spec, np.int64), terms.work_init, _array(S),
            *_pointers(terms),
        )
