"""The estimators: the BLA, the shared nonlinear template and one module per model."""
