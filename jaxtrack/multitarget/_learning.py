r"""Fitting the detection probability and the clutter density of a tracker by maximum likelihood.

The objective is the tracker's own log-likelihood of the recorded scans, summed over scans and
runs (:meth:`~jaxtrack.multitarget.Tracker.step` derives each scan's term):

.. math::

    ℓ(P_D, λ) = \sum_r \sum_k \big(−λV + M_{r,k} \log λ − \log M_{r,k}! + \log Z_{r,k}(P_D, λ)\big),

with ``Z`` the association's partition function given the tracks predicted into scan ``k``. The
gradient flows through the soft association (the JPDA or belief-propagation marginals) into the
state updates and so into every later scan; the track-management decisions (hits, births,
confirmations, deletions, the χ² gate) are piecewise constant in the parameters and contribute
nothing to it, so ``ℓ`` is smooth between the parameter values at which one of them flips.

**Estimation** (:func:`fit_detection_and_clutter`). The parameters are fitted unconstrained,
``P_D = σ(u₁)`` (:class:`~jaxtrack.learning.Bounded`) and ``λ = exp(u₂)``
(:class:`~jaxtrack.learning.PositiveScalar`), by Newton's method with the exact Hessian
(forward over forward mode, ``jax.jacfwd`` twice; Nocedal & Wright 2006, *Numerical
Optimization*, 2nd ed., §3.3, §3.4 for the modified Hessian, Alg. 3.1 for the backtracking line
search). With two parameters the Hessian costs four tangents of the forward pass, the standard
errors need it at the optimum anyway, and Newton converges in a few steps where
:class:`~jaxtrack.learning.LBFGS` (the optimiser of :func:`~jaxtrack.learning.fit`) needs tens of
evaluations and a second compiled program for the Hessian. Value, gradient and Hessian come from
one program (its compilation, not its running, dominates a small fit: forward mode compiles in
about 40 % of the time of a reverse-mode gradient differentiated forward), evaluated once per
loop iteration in one jitted ``lax.while_loop``.

**Standard errors**, as :class:`~jaxtrack.learning.MLEFit` computes them (Harvey 1989 §3.5): the
observed information ``I(û) = −∇²ℓ(û)`` in the unconstrained parameters, the covariance
``I(û)⁻¹`` (through a Cholesky factor: NaN when ``I`` is not positive definite), and the delta
method ``J I(û)⁻¹ Jᵀ`` with ``J = ∂θ/∂u`` for the natural parameters (Casella & Berger 2002,
Thm. 5.5.24). They are the asymptotic standard errors of the maximiser of this approximate
likelihood; they do not include the approximation's own bias (targets counted as clutter in their
first scan, tracks born from clutter counted as targets: see :meth:`Tracker.step`).
"""

from __future__ import annotations

from typing import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._validation import InputError, is_concrete
from ..learning._params import Bounded, PositiveScalar
from ._tracker import Tracker, _run_tracker, check_measurement_dim

_NAMES = ("prob_detect", "clutter_density")


class DetectionClutterFit(eqx.Module):
    """Result of :func:`fit_detection_and_clutter`: the estimates, their standard errors, diagnostics.

    **Fields:**

    - ``prob_detect`` ``()``: ``P̂_D`` (dimensionless); ``clutter_density`` ``()``: ``λ̂``, clutter
      points per unit measurement-space volume per scan (a parameter held fixed keeps its value).
    - ``prob_detect_se``, ``clutter_density_se`` ``()``: their standard errors (delta method, same
      units; 0 for a parameter held fixed, NaN when the observed information is not positive
      definite).
    - ``covariance`` ``(2, 2)``: the asymptotic covariance of ``(P̂_D, λ̂)`` (rows and columns of a
      fixed parameter are 0).
    - ``observed_information`` ``(k, k)``: ``−∇²ℓ`` at the estimate with respect to the ``k``
      estimated unconstrained parameters, in the order ``(logit P_D, log λ)`` (nats per unit²).
    - ``log_likelihood`` ``()``: ``ℓ`` at the estimate (nats, summed over runs and scans);
      ``log_likelihood_history`` ``(num_iterations + 1,)``: ``ℓ`` at the accepted iterate after
      each loop iteration (entry 0: the start; entries after the stop repeat the final value).
    - ``num_iterations`` ``()`` int: the loop iterations (objective evaluations after the first).
    - ``converged`` ``()`` bool: stopped because the Newton decrement ``gᵀI⁻¹g/2 ≤ tol`` with ``I``
      positive definite (a maximum of the local quadratic model to within ``tol`` nats).
    - ``ok`` ``()`` bool: the log-likelihood, its gradient and Hessian were finite at the estimate,
      and the scans hold at least one valid measurement (with none, ``ℓ = −λVRT`` is maximised
      at ``λ = 0`` on the boundary and does not depend on ``P_D``: there is nothing to fit).
    - ``tracker``: the input tracker with the estimates (and ``clutter_volume``) set.
    """

    prob_detect: Float[Array, ""]
    clutter_density: Float[Array, ""]
    prob_detect_se: Float[Array, ""]
    clutter_density_se: Float[Array, ""]
    covariance: Float[Array, "2 2"]
    observed_information: Float[Array, "k k"]
    log_likelihood: Float[Array, ""]
    log_likelihood_history: Float[Array, " I"]
    num_iterations: Int[Array, ""]
    converged: Bool[Array, ""]
    ok: Bool[Array, ""]
    tracker: Tracker


def _natural(u):
    """``(P_D, λ)`` from the unconstrained ``u = (logit P_D, log λ)``."""
    return jnp.stack([Bounded(u[0]).value, PositiveScalar(u[1]).value])


def _with(tracker, theta):
    return eqx.tree_at(lambda t: (t.prob_detect, t.clutter_density), tracker, (theta[0], theta[1]))


def _total_log_likelihood(u, tracker, z, valid):
    fitted = _with(tracker, _natural(u))
    per_run = jax.vmap(lambda zr, vr: _run_tracker(fitted, zr, vr, False).log_likelihood)(z, valid)
    return jnp.sum(per_run)


def _value_grad_hessian(u, tracker, z, valid, free):
    """``ℓ``, ``∇ℓ`` and ``∇²ℓ`` at ``u`` in one program, forward over forward mode (two
    parameters: two tangents, then two more; it compiles faster than reverse mode under a
    forward Hessian, and runs as fast). Held parameters get zero gradient and a unit
    curvature, so the Newton step leaves them where they are."""

    def value_twice(v):
        value = _total_log_likelihood(v, tracker, z, valid)
        return value, value

    def grad_and_value(v):
        grad, value = jax.jacfwd(value_twice, has_aux=True)(v)
        return grad, (grad, value)

    H, (grad, value) = jax.jacfwd(grad_and_value, has_aux=True)(u)
    H = 0.5 * (H + H.T)  # symmetric to rounding; the Cholesky and eigh below read one triangle
    grad = jnp.where(free, grad, 0.0)
    H = jnp.where(free[:, None] & free[None, :], H, -jnp.eye(2, dtype=H.dtype))
    return value, grad, H


@eqx.filter_jit
def _fit_loop(u0, tracker, z, valid, free, num_iterations, tol):
    dtype = u0.dtype
    eye = jnp.eye(2, dtype=dtype)

    def evaluate(u):
        value, grad, H = _value_grad_hessian(u, tracker, z, valid, free)
        good = jnp.isfinite(value) & jnp.all(jnp.isfinite(grad)) & jnp.all(jnp.isfinite(H))
        return value, grad, H, good

    def newton(grad, H):
        """The ascent direction ``(I + μ1)⁻¹ g`` with ``I = −H`` shifted to be positive definite
        (Nocedal & Wright 2006 §3.4), and the Newton decrement ``gᵀI⁻¹g`` (NaN unless ``I > 0``)."""
        info = -H
        smallest = jnp.linalg.eigvalsh(info)[0]
        scale = jnp.max(jnp.abs(jnp.diag(info))) + 1.0
        mu = jnp.where(smallest > 1e-10 * scale, 0.0, 1e-3 * scale - smallest)
        d = jnp.linalg.solve(info + mu * eye, grad)
        decrement = jnp.where(mu == 0.0, grad @ d, jnp.nan)
        return d, decrement

    v0, g0, H0, good0 = evaluate(u0)
    d0, dec0 = newton(g0, H0)
    hist0 = jnp.full((num_iterations + 1,), jnp.nan, dtype).at[0].set(v0)
    conv0 = good0 & (0.5 * dec0 <= tol)
    init = (jnp.zeros((), jnp.int32), u0, v0, g0, H0, d0, jnp.ones((), dtype), hist0, good0 & ~conv0, conv0)

    def cond(c):
        i, *_, running, _ = c
        return running & (i < num_iterations)

    def body(c):
        i, u, v, g, H, d, alpha, hist, _, _ = c
        u_try = u + alpha * d
        v1, g1, H1, good = evaluate(u_try)
        # Armijo's sufficient increase (Nocedal & Wright 2006, eq. 3.4, for a maximum); a trial
        # that fails it or is not finite halves the step from the same iterate.
        accept = good & (v1 >= v + 1e-4 * alpha * (g @ d))
        d1, dec1 = newton(g1, H1)
        u, v, g, H = (jnp.where(accept, a, b) for a, b in ((u_try, u), (v1, v), (g1, g), (H1, H)))
        d = jnp.where(accept, d1, d)
        alpha = jnp.where(accept, 1.0, 0.5 * alpha)
        converged = accept & (0.5 * dec1 <= tol)
        stalled = alpha < 1e-12
        i1 = i + 1
        return (i1, u, v, g, H, d, alpha, hist.at[i1].set(v), ~converged & ~stalled, converged)

    i, u, v, g, H, _, _, hist, _, converged = jax.lax.while_loop(cond, body, init)
    hist = jnp.where(jnp.arange(num_iterations + 1) > i, v, hist)
    # Scans that are all padding carry no information on P_D or λ (traced `valid`; a concrete
    # one raised already): finite numbers, but no estimate.
    ok = jnp.isfinite(v) & jnp.all(jnp.isfinite(g)) & jnp.all(jnp.isfinite(H)) & jnp.any(valid)
    return u, v, H, hist, i, converged, ok


def fit_detection_and_clutter(
    tracker: Tracker,
    measurements: ArrayLike,
    valid: ArrayLike,
    *,
    clutter_volume: ArrayLike | None = None,
    init: tuple[ArrayLike, ArrayLike] | None = None,
    estimate: Sequence[str] = _NAMES,
    num_iterations: int = 50,
    tol: float = 1e-14,
) -> DetectionClutterFit:
    r"""Fit a tracker's ``P_D`` and clutter density ``λ`` to recorded scans by maximum likelihood.

    Maximises the summed scan log-likelihood of the tracker's runs over the recorded scans
    (module docstring; :meth:`Tracker.step` derives each scan's term)

    .. math::

        ℓ(P_D, λ) = \sum_r \sum_k \big(−λV + M_{r,k} \log λ − \log M_{r,k}! + \log Z_{r,k}\big)

    over ``u = (logit P_D, log λ)`` by Newton's method with the exact Hessian and backtracking
    (one jitted ``lax.while_loop``), and returns the estimates with standard errors from the
    observed information ``−∇²ℓ`` (delta method into ``(P_D, λ)``). Every other part of the
    tracker (filter, model, association, management, existence) is held as given; the estimate is
    that of the tracker's own approximate likelihood (exact per scan for ``JPDA()`` without a gate,
    given the tracks' Gaussian predictions). For unbiased estimates the tracks born from clutter
    should carry little weight: with ``existence=IntegratedExistence(...)`` and a small
    ``OnePointInitiator(existence=...)`` (JIPDA), or few clutter points against many target
    detections; the plain JPDA tracker counts every clutter-born tentative track as a target
    missed in the scans it lives, which biases ``P̂_D`` down.

    **Arguments:**

    - ``tracker``: the :class:`Tracker` (its ``prob_detect`` and ``clutter_density`` are the start
      unless ``init`` is given).
    - ``measurements``: ``(T, M, m)`` (one run) or ``(R, T, M, m)`` (``R`` independent runs)
      padded scans in the sensor's units (padding may be NaN); ``valid``: boolean ``(T, M)`` or
      ``(R, T, M)``, False for padding.
    - ``clutter_volume``: ``V``, the volume of the measurement region the clutter falls in (the
      product of the region's widths for a box), > 0; default: the tracker's ``clutter_volume``.
      Required: without the count term ``−λV`` the likelihood grows without bound in ``λ``.
    - ``init``: ``(P_D, λ)``, the starting point (``0 < P_D < 1``, ``λ > 0``); default the tracker's.
    - ``estimate``: the parameters to fit, a subset of ``("prob_detect", "clutter_density")``
      (default both); the others are held at their starting values.
    - ``num_iterations``: the cap on loop iterations (objective evaluations after the first), a
      Python int ≥ 1.
    - ``tol``: stop when the Newton decrement ``gᵀ(−∇²ℓ)⁻¹g/2 ≤ tol`` (nats).

    **Returns:** a :class:`DetectionClutterFit`.

    **Raises:** :class:`~jaxtrack.InputError` naming the argument: ``tracker`` not a
    :class:`Tracker`, wrong shapes, a concrete ``valid`` with no True entry (every scan padding:
    no measurement to fit to), no clutter volume, ``init`` out of range, an unknown name in
    ``estimate``, ``num_iterations`` not an int ≥ 1, a negative ``tol``. A traced ``valid`` with
    no True entry gives ``ok`` False instead.

    Example::

        fitted = fit_detection_and_clutter(tracker, scans.measurements, scans.valid,
                                           clutter_volume=200.0 * 200.0, init=(0.6, 1e-4))
        fitted.prob_detect, fitted.prob_detect_se, fitted.clutter_density, fitted.clutter_density_se
    """
    if not isinstance(tracker, Tracker):
        raise InputError(f"`tracker` must be a jaxtrack.multitarget.Tracker; got {type(tracker).__name__}.")
    z = jnp.asarray(measurements)
    if not jnp.issubdtype(z.dtype, jnp.floating):
        z = z.astype(tracker.initiator.prior_cov.dtype)
    v = jnp.asarray(valid)
    if z.ndim == 3:
        z, v = z[None], v[None]
    if z.ndim != 4 or v.shape != z.shape[:3] or v.dtype != bool:
        raise InputError(
            "`measurements` must be (T, M, m) or (R, T, M, m) and `valid` boolean (T, M) or (R, T, M); "
            f"got {jnp.shape(measurements)} and {jnp.shape(valid)} ({jnp.asarray(valid).dtype})."
        )
    check_measurement_dim(tracker, z)
    if is_concrete(v) and not bool(np.any(np.asarray(v))):
        raise InputError(
            "`valid` has no True entry: every scan is padding, so there is no measurement to fit "
            "P_D and the clutter density to (the likelihood −λV·(runs·scans) is maximised at λ = 0)."
        )
    if clutter_volume is None:
        if tracker.clutter_volume is None:
            raise InputError(
                "`clutter_volume` is needed (here or as the tracker's `clutter_volume`): without the Poisson "
                "count term −λV the log-likelihood grows without bound in the clutter density."
            )
        clutter_volume = tracker.clutter_volume
    tracker = eqx.tree_at(lambda t: t.clutter_volume, tracker, jnp.asarray(clutter_volume, float),
                          is_leaf=lambda x: x is None)
    if is_concrete(tracker.clutter_volume) and not (
        tracker.clutter_volume.shape == () and 0.0 < float(tracker.clutter_volume) < np.inf
    ):
        raise InputError(f"`clutter_volume` must be a finite positive scalar; got {np.asarray(clutter_volume)!r}.")
    estimate = tuple(estimate) if not isinstance(estimate, str) else (estimate,)
    unknown = [e for e in estimate if e not in _NAMES]
    if unknown or not estimate or len(set(estimate)) != len(estimate):
        raise InputError(f"`estimate` must be a non-empty subset of {_NAMES}; got {estimate!r}.")
    # A mask, not a static choice: every subset runs the same compiled program.
    free_np = np.array([name in estimate for name in _NAMES])
    free = jnp.asarray(free_np)
    if isinstance(num_iterations, bool) or not isinstance(num_iterations, (int, np.integer)) or num_iterations < 1:
        raise InputError(f"`num_iterations` must be a Python int ≥ 1; got {num_iterations!r}.")
    if not float(tol) >= 0.0:
        raise InputError(f"`tol` must be ≥ 0; got {tol}.")
    dtype = jnp.result_type(tracker.initiator.prior_cov.dtype, z.dtype)
    pd0, lam0 = (tracker.prob_detect, tracker.clutter_density) if init is None else init
    pd0, lam0 = jnp.asarray(pd0, dtype), jnp.asarray(lam0, dtype)
    if is_concrete(pd0) and is_concrete(lam0):
        if pd0.shape != () or lam0.shape != () or not (0.0 < float(pd0) < 1.0 and 0.0 < float(lam0) < np.inf):
            raise InputError(
                f"`init` must be (P_D, λ) with 0 < P_D < 1 and λ > 0 (scalars); got ({np.asarray(pd0)}, "
                f"{np.asarray(lam0)})."
            )
    u0 = jnp.stack([Bounded.from_value(pd0).logit, PositiveScalar.from_value(lam0).log_value]).astype(dtype)

    u, ll, H, hist, steps, converged, ok = _fit_loop(u0, tracker, z, v, free, int(num_iterations), float(tol))
    theta = _natural(u)
    # Covariance: I⁻¹ through a Cholesky factor (NaN, not a wrong inverse, when I is not positive
    # definite), as MLEFit.covariance; then the delta method with J = ∂θ/∂u (diagonal here), with
    # the rows of held parameters zeroed.
    info = -H
    chol = jnp.linalg.cholesky(info)
    chol_inv = jax.scipy.linalg.solve_triangular(chol, jnp.eye(2, dtype=info.dtype), lower=True)
    J = jnp.where(free[:, None], jax.jacfwd(_natural)(u), 0.0)
    cov = J @ (chol_inv.T @ chol_inv) @ J.T
    info = info[np.ix_(free_np, free_np)]
    se = jnp.sqrt(jnp.diag(cov))
    return DetectionClutterFit(
        prob_detect=theta[0],
        clutter_density=theta[1],
        prob_detect_se=se[0],
        clutter_density_se=se[1],
        covariance=cov,
        observed_information=info,
        log_likelihood=ll,
        log_likelihood_history=hist,
        num_iterations=steps,
        converged=converged,
        ok=ok,
        tracker=_with(tracker, theta),
    )
