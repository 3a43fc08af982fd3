"""Learning model parameters from data: constrained parametrisations, maximum likelihood, EM.

- ``_imm_fit``: IMM parameters (transition matrix, noise levels, turn rates) from measurements
  alone, by gradient ascent on the IMM measurement log-likelihood with optax (Brandenburger,
  Hoffmann & Charlish 2023): :func:`fit_imm`, its objective :func:`imm_log_likelihood`.
- ``_params``: constrained parametrisations (:class:`PositiveScalar`, :class:`Bounded`,
  :class:`SPDMatrix`, :class:`StochasticRows`) and the symmetric-gradient rule
  (:func:`symmetric_grad`).
- ``_lbfgs``: :class:`LBFGS`, the default optimiser of :func:`fit` (one objective evaluation per
  loop iteration).
- ``_mle``: :func:`fit`, maximum likelihood for any model and filter over many recorded runs, with
  standard errors and confidence intervals from the observed information (:class:`MLEFit`).
- ``_em``: :func:`fit_em`, expectation–maximisation (Shumway & Stoffer 1982) for
  ``LinearGaussianModel`` (F, H, Q, R, prior; each optionally fixed; masks; many runs): :class:`EMFit`.
- ``_loop``: the one optimisation loop under :func:`fit`, :func:`fit_imm` and :func:`fit_em`
  (iterations, stopping rule, histories, progress bar); L-BFGS, an optax transformation and the
  EM M-step are its steppers.
"""

from ._em import EMFit as EMFit, fit_em as fit_em
from ._imm_fit import (
    IMMFit as IMMFit,
    fit_imm as fit_imm,
    imm_log_likelihood as imm_log_likelihood,
)
from ._lbfgs import LBFGS as LBFGS
from ._mle import MLEFit as MLEFit, fit as fit
from ._params import (
    AbstractParametrisation as AbstractParametrisation,
    Bounded as Bounded,
    PositiveScalar as PositiveScalar,
    SPDMatrix as SPDMatrix,
    StochasticRows as StochasticRows,
    natural as natural,
    symmetric_grad as symmetric_grad,
)

__all__ = [
    "EMFit",
    "fit_em",
    "IMMFit",
    "fit_imm",
    "imm_log_likelihood",
    "AbstractParametrisation",
    "Bounded",
    "LBFGS",
    "MLEFit",
    "PositiveScalar",
    "SPDMatrix",
    "StochasticRows",
    "fit",
    "natural",
    "symmetric_grad",
]
