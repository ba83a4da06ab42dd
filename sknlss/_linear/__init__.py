"""Linear systems: nonparametric FRFs, state-space realization and state estimation."""
