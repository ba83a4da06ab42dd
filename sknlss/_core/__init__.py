"""The shared simulation-error core: kernel contract, model layouts, the least-squares
problem, the optimiser and the multi-start search."""
