r"""Designs by gradient on a Monte Carlo objective, next to the same design on a covariance objective.

A covariance recursion gives a filter's error exactly only for linear models; for a nonlinear
filter (an EKF on range-bearing data) the error must be measured by Monte Carlo. With common random
numbers (a fixed key) the Monte Carlo objective ``J_M(θ)`` is a smooth function of the design
parameters θ, and :func:`~jaxtrack.montecarlo.differentiable_monte_carlo` gives its exact gradient,
so the same optax loop (L-BFGS by default) that designs on a covariance objective designs on a\nMonte Carlo one.

- :func:`design_by_monte_carlo` — minimise ``J_M(θ) = (1/T) Σ_k Σ_i w_i MSE_k,i(θ)`` (or the
  terminal step, or any function of the :class:`~jaxtrack.montecarlo.MonteCarloResult`) over θ.
- :func:`design_by_covariance` — the same objective from the **actual** error covariance of the
  (possibly mismatched) linear filter, :func:`jaxtrack.covariance.actual_covariance` (Ho 1968,
  Sec. II-G(1): the Joseph recursion with the truth's noise and the filter's gains), which is the
  expectation of the Monte Carlo objective: on a linear problem both designs agree within Monte
  Carlo error.

Stochastic approximation with common random numbers (sample-average approximation): the
minimiser of ``J_M`` converges to that of ``E[J]`` at rate ``M^{-1/2}`` with
``θ_M − θ* ≈ −∇J_M(θ*) / ∇²J(θ*)`` (Shapiro, Dentcheva & Ruszczyński 2009, *Lectures on
Stochastic Programming*, Thm 5.8), which is how the tests bound their difference.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Literal, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, ArrayLike, PRNGKeyArray

from .._validation import InputError
from ..covariance import actual_covariance
from ..filters import AbstractFilter
from ..filters._base import FirstStep
from ..models import AbstractStateSpaceModel, LinearGaussianModel
from ..montecarlo import MonteCarloResult, differentiable_monte_carlo

__all__ = ["GradientDesign", "design_by_monte_carlo", "design_by_covariance"]

ModelsFn = Callable[[Any], AbstractStateSpaceModel | tuple[AbstractStateSpaceModel, AbstractStateSpaceModel]]
DesignObjective = Literal["running", "terminal"]


class GradientDesign(NamedTuple):
    """Result of :func:`design_by_monte_carlo` / :func:`design_by_covariance`.

    - ``params``: the designed parameters (same shape as ``params0``), NumPy.
    - ``cost``: the objective at ``params`` (float); ``gradient``: its gradient there.
    - ``history`` ``(iterations,)``: the objective at each optimiser iteration (before its update).
    """

    params: np.ndarray
    cost: float
    gradient: np.ndarray
    history: np.ndarray


def _split(built):
    return built if isinstance(built, tuple) else (built, None)


def _check_common(params0, steps, gtol):
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise InputError(f"`steps` must be a positive int; got {steps!r}.")
    if not (np.isfinite(gtol) and gtol >= 0):
        raise InputError(f"`gtol` must be a non-negative float; got {gtol!r}.")
    p = jnp.asarray(params0, dtype=jnp.result_type(float))
    if not bool(jnp.all(jnp.isfinite(p))):
        raise InputError("`params0` must be finite.")
    return p


def _weights(weight, n) -> Array:
    w = jnp.asarray(weight, dtype=jnp.result_type(float))
    if w.shape != (n,):
        raise InputError(f"`weight` must have shape ({n},) (one weight per scored state component); got {w.shape}.")
    return w


def _reduce(per_step: Array, objective: DesignObjective) -> Array:
    """``(T,)`` weighted error per step → the scalar objective (time average or terminal step)."""
    return jnp.mean(per_step) if objective == "running" else per_step[-1]


def _optimise(fn, params0, steps, optimizer, gtol):
    """Minimise the deterministic smooth ``fn`` (common random numbers make the Monte Carlo objective one).

    Default: L-BFGS with a backtracking Armijo line search (``optax.lbfgs``; Nocedal & Wright 2006,
    Alg. 7.5 and 3.1): a smooth objective of a few parameters converges in tens of iterations to the
    precision needed to compare designs, where Adam would oscillate by its step size. Any other
    optax ``optimizer`` (e.g. ``optax.adam(1e-2)``) runs with plain updates. Stops after
    ``steps`` iterations or when ``‖∇J‖ ≤ gtol·max(1, |J|)``.
    """
    if optimizer is None:
        # Backtracking (Armijo) instead of the default zoom search: it evaluates only J at trial
        # points, so one compiled step holds one gradient of the objective, not two.
        opt = optax.lbfgs(linesearch=optax.scale_by_backtracking_linesearch(max_backtracking_steps=30))
        vg = jax.value_and_grad(fn)

        @jax.jit
        def step(params, state):
            J, g = vg(params)
            updates, state = opt.update(g, state, params, value=J, grad=g, value_fn=fn)
            return optax.apply_updates(params, updates), state, J, g
    else:
        opt = optimizer
        vg = jax.value_and_grad(fn)

        @jax.jit
        def step(params, state):
            J, g = vg(params)
            updates, state = opt.update(g, state, params)
            return optax.apply_updates(params, updates), state, J, g

    state = opt.init(params0)
    params = params0
    hist = []
    for _ in range(steps + 1):
        new, state, J, g = step(params, state)
        if float(jnp.linalg.norm(g)) <= gtol * max(1.0, abs(float(J))) or len(hist) == steps:
            break  # J, g are those at params (the last update is discarded)
        hist.append(float(J))
        params = new
    return GradientDesign(np.asarray(params), float(J), np.asarray(g), np.asarray(hist))


def design_by_monte_carlo(
    models: ModelsFn,
    params0: ArrayLike,
    key: PRNGKeyArray,
    num_runs: int,
    *,
    weight: ArrayLike | None = None,
    objective: DesignObjective | Callable[[MonteCarloResult], Array] = "running",
    num_steps: int | None = None,
    filter: AbstractFilter | None = None,
    first_step: FirstStep = "update",
    steps: int = 50,
    optimizer: optax.GradientTransformation | None = None,
    gtol: float = 1e-9,
    block_size: int | None = None,
) -> GradientDesign:
    r"""Minimise a Monte Carlo objective over design parameters with optax (common random numbers).

    ``models(θ)`` builds the truth, or ``(truth, filter_model)``: the parameters may enter the
    filter's model (its process-noise intensity, a sampling period it assumes), the truth (a
    sampling schedule changes both) or both. The objective is evaluated by
    :func:`~jaxtrack.montecarlo.differentiable_monte_carlo` with the same ``key`` at every step,
    so ``J_M(θ)`` is one deterministic smooth function and its exact gradient drives Adam:

    .. math:: J_M(θ) = \frac1T \sum_{k} \sum_i w_i\,\widehat{\mathrm{MSE}}_{k,i}(θ)
              \quad(\text{``running''}),\qquad \sum_i w_i\,\widehat{\mathrm{MSE}}_{T,i}(θ)\quad(\text{``terminal''}),

    or ``objective(result)`` for any differentiable function of the
    :class:`~jaxtrack.montecarlo.MonteCarloResult` (e.g. the NEES deviation ``(ANEES − 1)²``).
    Its minimiser differs from that of the expected objective by Monte Carlo error
    ``O(M^{-1/2})`` (sample-average approximation; Shapiro et al. 2009, Thm 5.8).

    **Arguments:**

    - ``models``: ``θ -> truth`` or ``θ -> (truth, filter_model)``; ``params0``: the initial θ
      (any shape; e.g. ``log q``, so that q stays positive).
    - ``key``, ``num_runs``: the common random numbers and the Monte Carlo size ``M``.
    - ``weight``: ``(n,)`` weights ``w_i`` of the scored state components (e.g. 1 on positions, 0 on
      velocities); default all ones. Ignored with a callable ``objective``.
    - ``objective``: ``"running"`` (time average), ``"terminal"`` (last step) or a callable.
    - ``num_steps``, ``filter``, ``first_step``, ``block_size``: as in
      :func:`~jaxtrack.montecarlo.differentiable_monte_carlo`.
    - ``steps``: the most optimiser iterations; ``optimizer``: an optax transformation (default
      ``optax.lbfgs`` with a backtracking line search: the objective is deterministic and smooth);
      ``gtol``: stop when ``‖∇J‖ ≤ gtol·max(1, |J|)``.

    **Returns:** a :class:`GradientDesign` (``cost`` in the units of the weighted MSE, e.g. m²).
    """
    p0 = _check_common(params0, steps, gtol)
    if not (callable(objective) or objective in ("running", "terminal")):
        raise InputError(f"`objective` must be 'running', 'terminal' or a callable; got {objective!r}.")
    truth0, fm0 = _split(models(p0))
    n = (truth0 if fm0 is None else fm0).state_dim
    w = None if callable(objective) else (jnp.ones(n) if weight is None else _weights(weight, n))

    def cost(params, key):
        truth, fm = _split(models(params))
        res = differentiable_monte_carlo(truth, key, num_runs, num_steps=num_steps, filter=filter, filter_model=fm,
                                         first_step=first_step, block_size=block_size)
        if callable(objective):
            return objective(res)
        return _reduce(res.mse @ w, objective)

    return _optimise(lambda p: cost(p, key), p0, int(steps), optimizer, float(gtol))


def design_by_covariance(
    models: ModelsFn,
    params0: ArrayLike,
    *,
    weight: ArrayLike | None = None,
    objective: DesignObjective = "running",
    num_steps: int | None = None,
    first_step: FirstStep = "update",
    steps: int = 50,
    optimizer: optax.GradientTransformation | None = None,
    gtol: float = 1e-9,
) -> GradientDesign:
    r"""The design of :func:`design_by_monte_carlo` on the exact covariance of a linear filter.

    ``models(θ)`` returns a :class:`~jaxtrack.models.LinearGaussianModel` truth (a matched Kalman
    filter) or ``(truth, filter_model)`` sharing ``F`` and ``H`` (a filter with wrong noise
    statistics). The objective replaces the Monte Carlo MSE by the diagonal of the actual error
    covariance ``P_{k/k}`` (Ho 1968, eq. (3) with the filter's gains ``W*``, Sec. II-G(1);
    :func:`jaxtrack.covariance.actual_covariance`), its expectation:

    .. math:: J(θ) = \frac1T \sum_k \sum_i w_i\,[P_{k/k}(θ)]_{ii}\quad(\text{``running''}),\qquad
              \sum_i w_i\,[P_{T/T}(θ)]_{ii}\quad(\text{``terminal''}).

    Same optimiser as :func:`design_by_monte_carlo`, so the two designs differ only by the Monte
    Carlo error of the latter.

    **Arguments:** ``models``, ``params0``, ``weight`` ``(n,)``, ``objective``, ``num_steps``,
    ``first_step``, ``steps``, ``optimizer``, ``gtol`` as in :func:`design_by_monte_carlo`.

    **Returns:** a :class:`GradientDesign`.
    """
    p0 = _check_common(params0, steps, gtol)
    if objective not in ("running", "terminal"):
        raise InputError(f"`objective` must be 'running' or 'terminal'; got {objective!r}.")
    truth0, fm0 = _split(models(p0))
    for name, m in (("truth", truth0), ("filter_model", fm0)):
        if m is not None and not isinstance(m, LinearGaussianModel):
            raise InputError(f"`models` must return LinearGaussianModel(s) for a covariance design; its {name} is "
                             f"a {type(m).__name__} (use design_by_monte_carlo).")
    n = truth0.state_dim
    w = jnp.ones(n) if weight is None else _weights(weight, n)

    def cost(params):
        truth, fm = _split(models(params))
        _, actual = actual_covariance(truth, truth if fm is None else fm, num_steps, first_step=first_step)
        per_step = jnp.einsum("kii,i->k", actual.filtered_cov, w)
        return _reduce(per_step, objective)

    return _optimise(cost, p0, int(steps), optimizer, float(gtol))
