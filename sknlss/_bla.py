"""Placeholder until the estimator lands."""


class BLAEstimator:
    pass
