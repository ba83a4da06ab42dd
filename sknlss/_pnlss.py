"""Placeholder until the estimator lands."""


class PNLSSRegressor:
    pass
