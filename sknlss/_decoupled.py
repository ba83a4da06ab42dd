"""Placeholder until the estimator lands."""


class DecoupledPNLSS:
    pass
