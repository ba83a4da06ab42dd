"""Placeholder until the estimator lands."""


class NLSS2Regressor:
    pass
