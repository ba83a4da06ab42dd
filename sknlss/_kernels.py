"""Compiled pieces shared by the simulation kernels of every model."""

from numba import njit


@njit(cache=True)
def out_of_bounds(x, bound):
    """Whether a state has left the region ``|x_i| <= bound`` (NaN counts as out)."""
    for i in range(x.shape[0]):
        if not abs(x[i]) <= bound:
            return True
    return False
