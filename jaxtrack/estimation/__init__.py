"""Batch linear estimation: weighted least squares with and without a prior, equality-constrained
least squares, minimum-norm solutions, and the observability of linear measurement sequences."""
