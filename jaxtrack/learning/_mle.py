"""Maximum-likelihood fitting of any jaxtrack model and filter, with standard errors.

Given recorded measurements ``z_{r,1:T}`` of ``R`` independent runs and a parametrised model
``build(θ)``, :func:`fit` maximises the prediction-error-decomposition log-likelihood

.. math::

    ℓ(u) = Σ_r Σ_k \\log N(ν_{r,k}; 0, S_{r,k}),\\qquad θ = g(u),

(Schweppe 1965; Harvey 1989, *Forecasting, structural time series models and the Kalman
filter*, eq. 3.4.2; Durbin & Koopman 2012, *Time Series Analysis by State Space Methods*, 2nd ed.,
eq. 7.2), the :attr:`~jaxtrack.filters.FilterResult.log_likelihood` of
:func:`~jaxtrack.filters.run_filter` summed over the runs, over *unconstrained* leaves ``u``
mapped to valid parameters by the parametrisations of :mod:`~jaxtrack.learning._params`. For a
linear-Gaussian model and the Kalman filter ``ℓ`` is the exact likelihood; for the EKF/UKF it is
the usual quasi-likelihood of the filter's Gaussian predictive densities.

**Optimiser.** Quasi-Newton by default: :class:`~jaxtrack.learning.LBFGS`, L-BFGS with a line
search satisfying the strong Wolfe conditions (Nocedal & Wright 2006, *Numerical Optimization*,
2nd ed., Alg. 7.5 and Alg. 3.5–3.6), on ``−ℓ/(R·T)``, written so that each loop iteration
evaluates the objective once (the compiled fit holds one copy of it: ``_lbfgs``). The loop is one
jitted ``lax.while_loop`` that stops on convergence, at the iteration cap, or when the line
search finds no acceptable point; a non-finite trial point shrinks the step, and a non-finite
start stops with ``ok = False``. Any optax transformation may be passed instead; that loop stops
at the first non-finite evaluation (keeping the last finite iterate, as
:func:`~jaxtrack.learning.fit_imm` does).

**Standard errors** (Harvey 1989 §3.5; Durbin & Koopman 2012 §7.3.3). The observed information
at the optimum ``û`` is ``I(û) = −∇²ℓ(û)`` (autodiff Hessian with respect to the flattened
unconstrained leaves, :func:`jax.flatten_util.ravel_pytree`); the asymptotic covariance of ``û``
is ``I(û)⁻¹``. For the natural parameters the delta method gives ``J I(û)⁻¹ Jᵀ`` with
``J = ∂θ/∂u`` at ``û`` (Casella & Berger 2002, *Statistical Inference*, 2nd ed., Thm. 5.5.24).
At an exact optimum this equals the inverse of the observed information computed in ``θ``
directly (the gradient term of the chain rule vanishes), which is what statsmodels'
``MLEResults`` reports for ``cov_type="approx"`` (numerical Hessian of the log-likelihood in its
natural, "untransformed" parameters: variances, not its internal square-root transform); its
default ``cov_type="opg"`` (outer product of the per-step scores) and ``"oim"`` (Harvey 1989's
analytic information-matrix formula from first derivatives of the innovations and their
variances) are other estimators of the same asymptotic covariance and differ in finite samples.
The tests compare with ``cov_type="approx"``.

Two kinds of intervals (:meth:`MLEFit.confidence_intervals`): ``"transformed"`` — the symmetric
interval ``û ± z σ_u`` mapped through ``g`` (for entrywise increasing maps: it stays inside the
constraint, e.g. a positive lower bound for a variance); ``"delta"`` — the symmetric interval
``θ̂ ± z σ_θ`` in the natural parametrisation (may cross the constraint).
"""

from __future__ import annotations

from typing import Any, Callable, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax.flatten_util import ravel_pytree
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PyTree

from .._validation import InputError
from ..filters._base import AbstractFilter, FirstStep, check_run_arguments
from ..filters._run import run_filter
from ..filters._kalman import KalmanFilter
from ..models import AbstractStateSpaceModel
from ._lbfgs import LBFGS
from ._loop import OptaxStepper, grad_norm, optimise, progress_bar, tick
from ._params import AbstractParametrisation, natural
from ._runs import all_finite, any_observed, check_params, prepare_runs

# L-BFGS (memory 10) with a strong-Wolfe line search, one objective evaluation per loop
# iteration (_lbfgs: the compiled fit holds the objective once, not four times as with optax's).
_DEFAULT_OPTIMIZER = LBFGS()
_DEFAULT_FILTER = KalmanFilter()

def _run_log_likelihoods(build, params, filter, z, observed, first_step) -> tuple[Array, Array]:
    """Per-run ``log_likelihood`` ``(R,)`` and ``ok`` ``(R,)`` of ``build(params)``."""
    model = build(params)

    def one(zr, obs_r):
        res = run_filter(filter, model, zr, mask=obs_r, first_step=first_step, save="final", throw=False)
        return res.log_likelihood, res.ok

    # Runs are independent: vmap over the leading axis, one scan inside.
    return jax.vmap(one)(z, observed)


def _total(build, params, filter, z, observed, first_step, ll_dtype):
    ll, ok = _run_log_likelihoods(build, params, filter, z, observed, first_step)
    return jnp.sum(ll).astype(ll_dtype), jnp.all(ok)


@eqx.filter_jit
def _fit_loop(build, params, filter, z, observed, first_step, optimizer, num_iterations, tol, gradient_tol,
              ll_dtype, progress):
    R, T, _ = z.shape
    # Minimise −ℓ/(R·T): the optimum of −ℓ, with gradients (and gradient_tol) per run-step, so
    # the criteria do not depend on the amount of data.
    scale = 1.0 / (R * T)

    def objective(p):
        total, ok = _total(build, p, filter, z, observed, first_step, ll_dtype)
        return -total * scale, (total, ok)

    value_and_grad = jax.value_and_grad(objective, has_aux=True)

    def value_fn(p):  # for optax's line searches: the same objective, value only
        return objective(p)[0]

    def evaluate(p):
        (v, (ll, ok)), g = value_and_grad(p)
        return v, ll, g, ok & jnp.isfinite(v) & all_finite(g)

    def converged_fn(ll1, ll, g):
        # Small per-run-step gradient, or ℓ stopped changing relative to itself.
        return (grad_norm(g) <= gradient_tol) | (jnp.abs(ll1 - ll) <= tol * jnp.abs(ll1))

    if isinstance(optimizer, LBFGS):
        # L-BFGS works on the flattened unconstrained leaves.
        flat0, unravel = ravel_pytree(params)

        def evaluate_flat(u):
            v, ll, g, good = evaluate(unravel(u))
            return v, ll, ravel_pytree(g)[0], good

        out = optimise(evaluate_flat, flat0, optimizer, num_iterations, converged_fn, ll_dtype,
                       tick if progress else None)
        fitted = unravel(out.x)
    else:
        # The start before the loop, as this path always did (same numbers either way).
        stepper = OptaxStepper(optimizer, value_fn, start_outside=True)
        out = optimise(evaluate, params, stepper, num_iterations, converged_fn, ll_dtype, tick if progress else None)
        fitted = out.x
    # The loop's norms are of ∂(−ℓ/(R·T))/∂u; the history reports ‖∂ℓ/∂u‖.
    return fitted, out.aux_history, (out.grad_norm_history / scale).astype(ll_dtype), out.num_steps, \
        out.converged, out.ok


def _hessian_and_jacobian(build, params, filter, z, observed, first_step, ll_dtype):
    flat, unravel = ravel_pytree(params)

    def total(u):
        return _total(build, unravel(u), filter, z, observed, first_step, ll_dtype)[0]

    def nat(u):
        return ravel_pytree(natural(unravel(u)))[0]

    return jax.hessian(total)(flat), jax.jacfwd(nat)(flat)


_hessian_and_jacobian_jit = eqx.filter_jit(_hessian_and_jacobian)


class MLEFit(eqx.Module):
    """Result of :func:`fit`: the estimate, convergence diagnostics, and its standard errors.

    **Fields:**

    - ``params``: the fitted parameters, same pytree (of parametrisation Modules and arrays) as
      the starting ``params``: the last iterate whose log-likelihood and gradient were finite.
    - ``model``: ``build(params)``, the fitted model.
    - ``log_likelihood_history`` ``(num_iterations + 1,)``: the total log-likelihood ``ℓ``
      (nats, summed over runs and steps) at iterate ``i`` (entry 0: the start); entries after the
      fit stopped repeat the final value.
    - ``gradient_norm_history`` ``(num_iterations + 1,)``: ``‖∂ℓ/∂u‖₂`` at each iterate (nats per
      unit of ``u``), frozen like the history.
    - ``num_iterations`` ``()`` int: the optimiser iterations that led to ``params``.
    - ``converged`` ``()`` bool: the fit stopped because ``‖∂ℓ/∂u‖/(R·T) ≤ gradient_tol`` or
      ``|Δℓ| ≤ tol·|ℓ|`` (not at the iteration cap, not at a failure).
    - ``ok`` ``()`` bool: False if a log-likelihood or gradient became non-finite (or the filter
      reported a non-finite state); ``params`` is then the last finite iterate.
    - ``filter``, ``measurements`` ``(R, T, m)``, ``observed`` ``(R, T, m)``, ``build``,
      ``first_step``: what was fitted, kept for the standard errors.
    """

    params: PyTree
    model: AbstractStateSpaceModel
    log_likelihood_history: Float[Array, " I"]
    gradient_norm_history: Float[Array, " I"]
    num_iterations: Int[Array, ""]
    converged: Bool[Array, ""]
    ok: Bool[Array, ""]
    filter: AbstractFilter
    measurements: Float[Array, "R T m"]
    observed: Bool[Array, "R T m"]
    build: Callable
    first_step: str = eqx.field(static=True)

    @property
    def log_likelihood(self) -> Float[Array, ""]:
        """The total log-likelihood at ``params`` (nats)."""
        return self.log_likelihood_history[-1]

    @property
    def natural_params(self) -> PyTree:
        """The fitted natural parameters: ``params`` with each parametrisation replaced by its value."""
        return natural(self.params)

    def _dtype(self):
        return jnp.result_type(self.model.initial_cov, self.measurements)

    def _hess_jac(self):
        args = (self.build, self.params, self.filter, self.measurements, self.observed, self.first_step,
                self._dtype())
        # Inside an outer trace (e.g. vmap over data sets) call the plain function: a nested
        # filter_jit would work too, but this keeps one compilation of the caller's function.
        if isinstance(self.measurements, jax.core.Tracer):
            return _hessian_and_jacobian(*args)
        return _hessian_and_jacobian_jit(*args)

    def observed_information(self) -> Float[Array, "k k"]:
        """``I(û) = −∇²ℓ(û)``, the observed information w.r.t. the flattened unconstrained leaves.

        **Returns:** ``(k, k)`` (``k`` unconstrained scalars, in ``ravel_pytree(params)`` order),
        nats per unit² of ``u``.
        """
        H, _ = self._hess_jac()
        return -H

    def covariance(self, space: Literal["unconstrained", "natural"] = "unconstrained") -> Array:
        """The asymptotic covariance of the estimate (Harvey 1989 §3.5, delta method for ``natural``).

        **Arguments:** ``space``: ``"unconstrained"`` — ``I(û)⁻¹`` ``(k, k)`` over
        ``ravel_pytree(params)``; ``"natural"`` — ``J I(û)⁻¹ Jᵀ`` ``(p, p)`` over
        ``ravel_pytree(natural_params)`` (``J = ∂θ/∂u``).

        **Returns:** the covariance; NaN if the observed information is not positive definite
        (not a maximum, or a parameter not identified).
        """
        if space not in ("unconstrained", "natural"):
            raise InputError(f"`space` must be 'unconstrained' or 'natural'; got {space!r}.")
        H, J = self._hess_jac()
        info = -H
        # Cholesky: NaN (not a silently wrong inverse) when −∇²ℓ is not positive definite.
        L = jnp.linalg.cholesky(0.5 * (info + info.T))
        eye = jnp.eye(info.shape[0], dtype=info.dtype)
        Linv = jax.scipy.linalg.solve_triangular(L, eye, lower=True)
        cov_u = Linv.T @ Linv
        if space == "unconstrained":
            return cov_u
        return J @ cov_u @ J.T

    def standard_errors(self, space: Literal["natural", "unconstrained"] = "natural") -> PyTree:
        """Standard errors of the estimate, as a pytree shaped like the parameters.

        **Arguments:** ``space``: ``"natural"`` (default) — delta-method SEs of ``θ̂``, shaped like
        :attr:`natural_params` (units of each parameter); ``"unconstrained"`` — SEs of ``û``,
        shaped like ``params`` (a pytree of parametrisation Modules whose leaves hold the SEs).

        **Returns:** the pytree of standard errors (square roots of the covariance diagonal).
        """
        cov = self.covariance("natural" if space == "natural" else "unconstrained")
        se = jnp.sqrt(jnp.diag(cov))
        tree = self.natural_params if space == "natural" else self.params
        return ravel_pytree(tree)[1](se)

    def confidence_intervals(
        self, level: float = 0.95, method: Literal["transformed", "delta"] = "transformed"
    ) -> tuple[PyTree, PyTree]:
        """Wald confidence intervals for the natural parameters.

        **Arguments:**

        - ``level``: the coverage probability, in (0, 1).
        - ``method``: ``"transformed"`` — ``g(û ± z σ_u)`` (the unconstrained interval mapped
          through: respects positivity and bounds; needs entrywise increasing parametrisations:
          :class:`PositiveScalar`, :class:`Bounded`, plain arrays); ``"delta"`` — ``θ̂ ± z σ_θ``
          (symmetric, delta-method SEs; any parametrisation). ``z = Φ⁻¹((1 + level)/2)``.

        **Returns:** ``(lower, upper)``, each shaped like :attr:`natural_params`.

        **Raises:** ``InputError`` for ``level`` outside (0, 1), an unknown ``method``, or
        ``"transformed"`` with a parametrisation that is not entrywise (e.g. :class:`SPDMatrix`).
        """
        if not (0.0 < float(level) < 1.0):
            raise InputError(f"`level` must be in (0, 1); got {level}.")
        z = jax.scipy.special.ndtri(0.5 + 0.5 * float(level))
        if method == "delta":
            se = self.standard_errors("natural")
            theta = self.natural_params
            lower = jax.tree_util.tree_map(lambda t, s: t - z * s, theta, se)
            upper = jax.tree_util.tree_map(lambda t, s: t + z * s, theta, se)
            return lower, upper
        if method != "transformed":
            raise InputError(f"`method` must be 'transformed' or 'delta'; got {method!r}.")
        nodes = jax.tree_util.tree_leaves(self.params, is_leaf=lambda x: isinstance(x, AbstractParametrisation))
        bad = [type(n).__name__ for n in nodes if isinstance(n, AbstractParametrisation) and not n.elementwise]
        if bad:
            raise InputError(
                f"`method='transformed'` needs entrywise parametrisations; `params` holds {bad}. "
                f"Use method='delta' for those."
            )
        flat, unravel = ravel_pytree(self.params)
        se_u = jnp.sqrt(jnp.diag(self.covariance("unconstrained")))
        return natural(unravel(flat - z * se_u)), natural(unravel(flat + z * se_u))


def _check_params(params) -> PyTree:
    return check_params(params)


def fit(
    build: Callable[[Any], AbstractStateSpaceModel],
    params: PyTree,
    measurements: ArrayLike,
    *,
    filter: AbstractFilter = _DEFAULT_FILTER,
    mask: ArrayLike | None = None,
    optimizer: LBFGS | optax.GradientTransformation | None = None,
    num_iterations: int = 200,
    tol: float = 1e-13,
    gradient_tol: float = 1e-9,
    first_step: FirstStep = "update",
    progress: bool = False,
) -> MLEFit:
    """Fit model parameters to recorded measurements by maximum likelihood.

    Maximises ``ℓ(u) = Σ_r run_filter(filter, build(params(u)), z_r, mask=mask_r).log_likelihood``
    (module docstring: the prediction-error decomposition, Harvey 1989 eq. 3.4.2) over the
    unconstrained leaves ``u`` of ``params``, with L-BFGS and a zoom line search by default
    (Nocedal & Wright 2006, Alg. 7.5; :class:`LBFGS`). One jitted ``lax.while_loop``; ``build``, ``optimizer``
    and ``filter`` settings are static (pass the same objects to reuse the compilation). Works
    under ``jax.vmap`` over ``measurements`` (one compilation for many data sets).

    **Arguments:**

    - ``build``: ``params -> AbstractStateSpaceModel`` (e.g. a
      :class:`~jaxtrack.models.LinearGaussianModel`); traceable (``jnp`` only). It receives the
      pytree as given: call each parametrisation (``p["q"]()`` or ``p["q"].value``) for its
      natural value.
    - ``params``: the starting point, a pytree of parametrisations (:class:`PositiveScalar`,
      :class:`Bounded`, :class:`SPDMatrix`, :class:`StochasticRows`) and plain float arrays
      (unconstrained parameters, e.g. biases), in the units ``build`` gives them.
    - ``measurements``: ``(R, T, m)`` (``R`` recorded runs of ``T`` steps) or ``(T, m)`` (one
      run; ``(T,)`` when ``m = 1``), in the model's units.
    - ``filter``: any jaxtrack filter (``KalmanFilter()`` default; ``ExtendedKalmanFilter()``,
      ``UnscentedKalmanFilter()``, … for nonlinear models: then ``ℓ`` is the filter's
      quasi-likelihood).
    - ``mask``: optional boolean ``(R, T)``/``(R, T, m)`` (``(T,)``/``(T, m)`` for one run), True =
      observed; missing components leave the likelihood.
    - ``optimizer``: :class:`LBFGS` (default ``LBFGS()``: L-BFGS with a strong-Wolfe line search,
      one objective evaluation per loop iteration, so the objective is compiled once) or any
      optax ``GradientTransformation`` (``optax.lbfgs()`` works too: its zoom line search
      receives the objective through ``value_fn``; other transformations ignore it).
    - ``num_iterations``: the iteration cap, a Python int ≥ 1.
    - ``tol``: stop when ``|ℓ_i − ℓ_{i−1}| ≤ tol·|ℓ_i|`` (relative change, dimensionless).
    - ``gradient_tol``: stop when ``‖∂ℓ/∂u‖₂/(R·T) ≤ gradient_tol`` (nats per run-step per unit of
      ``u``).
    - ``first_step``: ``"update"`` (the prior is on the state at the first measurement) or
      ``"predict"``, as in :func:`~jaxtrack.filters.run_filter`.
    - ``progress``: show a tqdm bar of the iterations (from inside the jitted loop).

    **Returns:** an :class:`MLEFit` (estimate, ``log_likelihood_history``, ``num_iterations``,
    ``converged``, ``ok``; :meth:`MLEFit.standard_errors`, :meth:`MLEFit.confidence_intervals`).

    **Raises:** ``InputError`` naming the argument: ``build`` not callable or not returning a
    state-space model, ``params`` empty/not float/not finite, ``measurements`` or ``mask`` of the
    wrong shape, observed non-finite measurements, ``num_iterations`` not an int ≥ 1, negative
    tolerances, ``optimizer`` not an optax transformation, a wrong ``filter`` or ``first_step``.

    Example::

        build = lambda p: LinearGaussianModel(F, p["q"]() * Q1, H, p["r"]() * jnp.eye(1), m0, P0)
        res = fit(build, {"q": PositiveScalar.from_value(1.0), "r": PositiveScalar.from_value(1.0)}, zs)
        lower, upper = res.confidence_intervals(0.95)
    """
    if isinstance(num_iterations, bool) or not isinstance(num_iterations, (int, np.integer)):
        raise InputError(f"`num_iterations` must be a Python int ≥ 1; got {num_iterations!r}.")
    if num_iterations < 1:
        raise InputError(f"`num_iterations` must be ≥ 1; got {num_iterations}.")
    if not (float(tol) >= 0.0 and float(gradient_tol) >= 0.0):
        raise InputError(f"`tol` and `gradient_tol` must be ≥ 0; got {tol}, {gradient_tol}.")
    optimizer = _DEFAULT_OPTIMIZER if optimizer is None else optimizer
    if not isinstance(optimizer, LBFGS):
        if not (callable(getattr(optimizer, "init", None)) and callable(getattr(optimizer, "update", None))):
            raise InputError(
                f"`optimizer` must be jaxtrack.learning.LBFGS or an optax GradientTransformation (with init "
                f"and update); got {type(optimizer).__name__}."
            )
        # Plain transformations do not take the line search's extra arguments: wrap them.
        optimizer = optax.with_extra_args_support(optimizer)
    if not callable(build):
        raise InputError(f"`build` must be a callable params -> model; got {type(build).__name__}.")
    params = _check_params(params)
    model = build(params)
    if not isinstance(model, AbstractStateSpaceModel):
        raise InputError(f"`build` must return a jaxtrack state-space model; it returned {type(model).__name__}.")
    check_run_arguments(filter, model, first_step, "final")
    z = jnp.asarray(measurements)
    if z.ndim == 1 and model.meas_dim == 1:
        z = z[:, None]
    z, observed = prepare_runs(model.meas_dim, model.initial_mean.dtype, z, mask)
    ll_dtype = jnp.result_type(model.initial_cov, z)
    with progress_bar(bool(progress), int(num_iterations), "fit") as finish:
        fitted, hist, ghist, steps, converged, ok = _fit_loop(
            build, params, filter, z, observed, first_step, optimizer, int(num_iterations), float(tol),
            float(gradient_tol), ll_dtype, bool(progress),
        )
        finish(steps)
    # Built outside the loop so that the model's concrete checks run on the result.
    ok = ok & any_observed(observed)
    return MLEFit(fitted, build(fitted), hist, ghist, steps, converged, ok, filter, z, observed, build, first_step)
