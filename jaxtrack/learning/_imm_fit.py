"""Learning IMM parameters from measurements alone: gradient ascent on the measurement likelihood.

After Brandenburger, Hoffmann & Charlish (2023), "Learning IMM filter parameters from
measurements using gradient descent" (arXiv:2307.06618). The IMM (Blom & Bar-Shalom 1988; BLK
2001 §11.6.6) is differentiable end to end in jaxtrack, so its parameters ``θ`` (Markov
transition matrix, process-noise levels, turn rates, …) can be fitted to recorded measurements
``z_{r,1:T}`` of ``R`` tracks, with no ground truth, by maximising the IMM's measurement
log-likelihood

.. math::

    ℓ(θ) = Σ_r Σ_k \\log Σ_j Λ_{r,k,j}(θ)\\, \\bar c_{r,k,j}(θ),

the log of the Gaussian-mixture predictive density of each measurement (BLK eq. 11.6.6-13's
normaliser: member innovation likelihoods ``Λ_j = N(ν_j; 0, S_j)`` weighted by the predicted mode
probabilities ``c̄_j``), i.e. :attr:`~jaxtrack.filters.IMMResult.log_likelihood` summed over the
tracks. What we follow from the paper (its Fig. 1 and loss): the loss is the negative
measurement log-likelihood of the IMM itself, built from the per-step mixture likelihood
``Ψ_t = Σ_j c̄_j N(z_t; ẑ_j, S_j)`` (no ground truth, no smoother), its gradient comes from
automatic differentiation through the whole filter recursion, and the parameters are updated by
gradient steps ``θ ← θ − η ∇L(θ)`` (``optimizer=optax.sgd(η)`` is that update, on the loss
normalised per track-step below); like the paper, ``θ`` may hold mode-transition, process-noise
and measurement-noise parameters. What is
ours: any optax optimiser (default Adam); every iteration uses the full batch of the given
tracks (one deterministic objective, normalised per track-step, so the history is monotone up
to the optimiser's own overshoot); the whole loop is one jitted ``lax.while_loop``; the
parametrisation is the caller's ``build`` (rows kept stochastic by
:meth:`~jaxtrack.filters.InteractingMultipleModel.from_logits`, positive levels as ``exp`` of a
real); and any jaxtrack member filter (KF, EKF, UKF, iterated EKF) and member model can be
learned through, not only the paper's two motion modes.

This is the IMM instance of maximum-likelihood learning by gradient; :func:`imm_log_likelihood`
is the objective and :func:`fit_imm` the optimiser loop (the learning module's one loop, ``_loop``, shared with :func:`~jaxtrack.learning.fit`).
"""

from __future__ import annotations

from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PyTree

from .._validation import InputError
from ..filters._base import FirstStep
from ..filters._imm import InteractingMultipleModel, run_imm
from ._loop import OptaxStepper, optimise
from ._runs import all_finite as _all_finite, any_observed, check_params, prepare_runs

# Built once so that the default does not create new closures (and a recompilation) per call.
_DEFAULT_OPTIMIZER = optax.adam(1e-2)


class IMMFit(eqx.Module):
    """Result of :func:`fit_imm`.

    **Fields:**

    - ``params``: the fitted parameters (same pytree structure and dtypes as the starting
      ``params``): the last iterate whose log-likelihood and gradient were finite.
    - ``imm``: ``build(params)``, the learned :class:`~jaxtrack.filters.InteractingMultipleModel`.
    - ``log_likelihood_history`` ``(num_iterations + 1,)``: the **total** measurement
      log-likelihood ``ℓ = Σ_r Σ_k log Σ_j Λ_j c̄_j`` (nats, summed over all tracks and steps, not
      normalised) at iterate ``i`` (entry 0: the starting ``params``; entry ``i``: after ``i``
      optimiser steps). After a non-finite evaluation the iterate is frozen, so the entries from
      there on repeat the last finite value.
    - ``gradient_norm_history`` ``(num_iterations + 1,)``: the Euclidean norm of ``∂ℓ/∂θ`` over
      all leaves at each iterate (a convergence diagnostic), frozen like the history.
    - ``num_steps_taken`` ``()`` int: the number of optimiser steps that led to ``params``
      (``num_iterations`` unless the fit stopped).
    - ``ok`` ``()`` bool: False if a log-likelihood or gradient became non-finite (or the IMM
      reported a non-finite state); the fit then stopped there and ``params`` is the last finite
      iterate. False with ``num_steps_taken == 0`` means the starting point itself was not finite
      (the history is then NaN).
    """

    params: PyTree
    imm: InteractingMultipleModel
    log_likelihood_history: Float[Array, " I"]
    gradient_norm_history: Float[Array, " I"]
    num_steps_taken: Int[Array, ""]
    ok: Bool[Array, ""]

    @property
    def log_likelihood(self) -> Float[Array, ""]:
        """The total log-likelihood at the returned ``params`` (the history's last entry)."""
        return self.log_likelihood_history[-1]


def _check_build_and_params(build, params) -> tuple[PyTree, InteractingMultipleModel]:
    if not callable(build):
        raise InputError(
            f"`build` must be a callable params -> InteractingMultipleModel; got {type(build).__name__}."
        )
    params = check_params(params, ": logits, log noise levels, …")
    imm = build(params)
    if not isinstance(imm, InteractingMultipleModel):
        raise InputError(
            f"`build` must return an InteractingMultipleModel; it returned {type(imm).__name__}."
        )
    return params, imm


def _prepare_tracks(imm, measurements, mask, require_observed=True) -> tuple[Array, Array]:
    """``measurements`` → ``(R, T, m)`` floats with missing entries 0, ``mask`` → ``(R, T, m)`` bools."""
    return prepare_runs(imm.models[0].meas_dim, imm.transition_probs.dtype, measurements, mask, require_observed)


def _check_first_step(first_step):
    if first_step not in ("update", "predict"):
        raise InputError(f"`first_step` must be 'update' or 'predict'; got {first_step!r}.")


def _track_log_likelihoods(build, params, z, observed, first_step) -> tuple[Array, Array]:
    """Per-track ``log_likelihood`` ``(R,)`` and per-track ``ok`` ``(R,)`` of ``build(params)``."""
    imm = build(params)

    def one(zr, obs_r):
        res = run_imm(imm, zr, mask=obs_r, first_step=first_step, throw=False)
        return res.log_likelihood, res.ok

    # Tracks are independent runs of the same IMM: vmap over the leading axis, one scan inside.
    return jax.vmap(one)(z, observed)


@eqx.filter_jit
def _total_log_likelihood(build, params, z, observed, first_step):
    ll, _ = _track_log_likelihoods(build, params, z, observed, first_step)
    return jnp.sum(ll)


def imm_log_likelihood(
    build: Callable[[Any], InteractingMultipleModel],
    params: PyTree,
    measurements: ArrayLike,
    *,
    mask: ArrayLike | None = None,
    first_step: FirstStep = "update",
) -> Float[Array, ""]:
    """The total IMM measurement log-likelihood of a batch of tracks: :func:`fit_imm`'s objective.

    ``ℓ(θ) = Σ_r run_imm(build(θ), z_r, mask=mask_r).log_likelihood`` (module docstring), jitted and
    differentiable in ``params`` (``jax.grad(imm_log_likelihood, argnums=1)``).

    **Arguments:** as for :func:`fit_imm` (``build``, ``params``, ``measurements`` ``(R, T, m)`` or
    ``(T, m)``, ``mask``, ``first_step``).

    **Returns:** ``ℓ``, a scalar in nats (summed over tracks and steps); ``-inf``/NaN if the IMM
    fails at these ``params``.

    **Raises:** ``InputError`` naming the argument, as :func:`fit_imm`.
    """
    _check_first_step(first_step)
    params, imm = _check_build_and_params(build, params)
    z, observed = _prepare_tracks(imm, measurements, mask, require_observed=False)  # ℓ of no data: 0
    return _total_log_likelihood(build, params, z, observed, first_step)


@eqx.filter_jit
def _fit(build, params, z, observed, optimizer, num_iterations, first_step, ll_dtype):
    R, T, _ = z.shape
    # The optimiser minimises the per-track-step negative log-likelihood −ℓ/(R·T): the same
    # optimum as −ℓ, but gradient magnitudes (and so SGD learning rates) do not grow with the
    # amount of data. The history reports the unnormalised ℓ.
    scale = 1.0 / (R * T)

    def objective(p):
        ll, ok = _track_log_likelihoods(build, p, z, observed, first_step)
        # A fixed dtype for the loop carry (the models' dtype, whatever the params' dtype).
        total = jnp.sum(ll).astype(ll_dtype)
        return -total * scale, (total, jnp.all(ok))

    value_and_grad = jax.value_and_grad(objective, has_aux=True)

    def evaluate(p):
        (v, (ll, imm_ok)), g = value_and_grad(p)
        return v, ll, g, jnp.isfinite(ll) & imm_ok & _all_finite(g)

    # The shared loop (_loop): iterates 0 … num_iterations, each with a checked (finite)
    # log-likelihood; no stopping rule (every step is taken unless an evaluation fails, which
    # stops the fit at the last finite iterate).
    out = optimise(evaluate, params, OptaxStepper(optimizer), num_iterations, None, ll_dtype)
    # A non-finite start has no finite log-likelihood to report: NaN histories.
    history = jnp.where(out.start_ok, out.aux_history, jnp.nan)
    grad_norms = jnp.where(out.start_ok, out.grad_norm_history / scale, jnp.nan).astype(ll_dtype)
    return out.x, history, grad_norms, out.num_steps, out.ok


def fit_imm(
    build: Callable[[Any], InteractingMultipleModel],
    params: PyTree,
    measurements: ArrayLike,
    *,
    optimizer: optax.GradientTransformation | None = None,
    num_iterations: int = 200,
    mask: ArrayLike | None = None,
    first_step: FirstStep = "update",
) -> IMMFit:
    """Fit IMM parameters to recorded measurements by maximising the measurement log-likelihood.

    The method of Brandenburger, Hoffmann & Charlish (2023) (module docstring: what is followed
    and what differs): gradient steps of an optax optimiser on ``−ℓ(θ)/(R·T)``, with
    ``ℓ(θ) = Σ_r run_imm(build(θ), z_r, mask=mask_r).log_likelihood`` the total log-likelihood of
    the ``R`` tracks (:func:`imm_log_likelihood`). The whole optimisation is one jitted
    ``lax.while_loop`` over the iterations (the loop shared with :func:`~jaxtrack.learning.fit`); ``build`` and ``optimizer`` are static (hashed by
    identity: pass the same objects to reuse the compilation).

    **Arguments:**

    - ``build``: ``params -> InteractingMultipleModel``; the parametrisation. Build the transition
      matrix with :meth:`~jaxtrack.filters.InteractingMultipleModel.from_logits` (rows stay
      stochastic for any logits) and positive quantities from logs (``q = exp(log_q)``) so that
      ``params`` are unconstrained. Must be traceable (``jnp`` operations only).
    - ``params``: the starting point, any pytree of finite float arrays (e.g.
      ``{"logits": (M, M), "log_q": (M,), "log_omega": ()}``), in the units ``build`` gives them
      (logs of m²/s³, rad/s, …).
    - ``measurements``: ``(R, T, m)`` (``R`` tracks of ``T`` steps) or ``(T, m)`` (one track), in
      the members' measurement units.
    - ``optimizer``: any ``optax.GradientTransformation``; default ``optax.adam(1e-2)`` (a step of
      about 0.01 per iteration in each unconstrained parameter).
    - ``num_iterations``: optimiser steps, a Python int ≥ 1 (static: a new value recompiles).
    - ``mask``: optional boolean, ``(R, T)`` or ``(R, T, m)`` (``(T,)`` or ``(T, m)`` for one
      track), True = observed, as in :func:`~jaxtrack.filters.run_imm`.
    - ``first_step``: ``"update"`` or ``"predict"``, as in :func:`~jaxtrack.filters.run_imm`.

    **Returns:** an :class:`IMMFit`: ``params``, ``imm``, the total log-likelihood history
    ``(num_iterations + 1,)`` (nats, summed over tracks and steps), the gradient-norm history,
    ``num_steps_taken`` and ``ok`` (False if the fit stopped at a non-finite log-likelihood or
    gradient; ``params`` is then the last finite iterate).

    **Raises:** ``InputError`` naming the argument: ``build`` not callable or not returning an
    :class:`~jaxtrack.filters.InteractingMultipleModel`, ``params`` empty, not float or not
    finite, ``measurements`` or ``mask`` of the wrong shape (``mask`` not boolean), observed
    non-finite measurements, ``num_iterations`` not an int ≥ 1, ``optimizer`` not an optax
    gradient transformation, a wrong ``first_step``.
    """
    if isinstance(num_iterations, bool) or not isinstance(num_iterations, (int, np.integer)):
        raise InputError(f"`num_iterations` must be a Python int ≥ 1; got {num_iterations!r}.")
    if num_iterations < 1:
        raise InputError(f"`num_iterations` must be ≥ 1; got {num_iterations}.")
    optimizer = _DEFAULT_OPTIMIZER if optimizer is None else optimizer
    if not (callable(getattr(optimizer, "init", None)) and callable(getattr(optimizer, "update", None))):
        raise InputError(
            f"`optimizer` must be an optax GradientTransformation (with init and update); got "
            f"{type(optimizer).__name__}."
        )
    _check_first_step(first_step)
    params, imm = _check_build_and_params(build, params)
    z, observed = _prepare_tracks(imm, measurements, mask)
    ll_dtype = jnp.result_type(imm.transition_probs, *(m.initial_cov for m in imm.models), z)
    fitted, history, grad_norms, accepted, ok = _fit(
        build, params, z, observed, optimizer, int(num_iterations), first_step, ll_dtype
    )
    # Built outside the trace so the IMM's concrete checks (stochastic rows, …) run on the result.
    return IMMFit(fitted, build(fitted), history, grad_norms, accepted, ok & any_observed(observed))
