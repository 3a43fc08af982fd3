"""Learning model parameters from data: constrained parametrisations, maximum likelihood, EM.

- ``_imm_fit``: IMM parameters (transition matrix, noise levels, turn rates) from measurements
  alone, by gradient ascent on the IMM measurement log-likelihood with optax (Brandenburger,
  Hoffmann & Charlish 2023): :func:`fit_imm`, its objective :func:`imm_log_likelihood`.
"""

from ._imm_fit import (
    IMMFit as IMMFit,
    fit_imm as fit_imm,
    imm_log_likelihood as imm_log_likelihood,
)
