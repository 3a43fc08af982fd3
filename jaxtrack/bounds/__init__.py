"""Performance bounds: the posterior Cramér–Rao bound (Tichavský, Muravchik & Nehorai 1998) by
autodiff, with expectations over true trajectories by Monte Carlo (:mod:`._pcrlb`), and the
efficiency of an estimator against it."""

from ._pcrlb import (
    PosteriorCRB as PosteriorCRB,
    efficiency as efficiency,
    pcrlb as pcrlb,
    pcrlb_along as pcrlb_along,
)

__all__ = ["PosteriorCRB", "efficiency", "pcrlb", "pcrlb_along"]
