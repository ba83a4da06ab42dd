"""Compiled pieces shared by the simulation kernels of every model."""

from numba import njit


@njit(cache=True)
def out_of_bounds(x, bound):
    """Whether a state has left the region ``|x_i| <= bound`` (NaN counts as out)."""
    for i in range(x.shape[0]):
        if not abs(x[i]) <= bound:
            return True
    return False


@njit(cache=True)
def matvec(M, v, out):
    """``out = M v`` without allocating."""
    for i in range(M.shape[0]):
        acc = 0.0
        for j in range(v.shape[0]):
            acc += M[i, j] * v[j]
        out[i] = acc


@njit(cache=True)
def matmat(M, N, out):
    """``out = M N`` without allocating."""
    for i in range(M.shape[0]):
        for p in range(N.shape[1]):
            acc = 0.0
            for j in range(N.shape[0]):
                acc += M[i, j] * N[j, p]
            out[i, p] = acc


@njit(cache=True)
def state_space_step(A, B, C, D, x, u, state_term, output_term, x_next, y):
    """One step of a state-space model with its nonlinear terms already evaluated.

    ``y = C x + D u + output_term`` and ``x_next = A x + B u + state_term``,
    written in place.
    """
    for i in range(C.shape[0]):
        acc = output_term[i]
        for j in range(x.shape[0]):
            acc += C[i, j] * x[j]
        for j in range(u.shape[0]):
            acc += D[i, j] * u[j]
        y[i] = acc
    for i in range(A.shape[0]):
        acc = state_term[i]
        for j in range(x.shape[0]):
            acc += A[i, j] * x[j]
        for j in range(u.shape[0]):
            acc += B[i, j] * u[j]
        x_next[i] = acc
