"""Simulation of truth and measurements from a state-space model and a PRNG key."""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, PRNGKeyArray

from .._validation import (
    InputError,
    as_key,
    check_covariance,
    check_finite,
    covariance_ok,
    is_concrete,
    throw_unless_ok,
)
from ..filters._base import FirstStep
from ..filters._linalg import matmul
from ._noise import key_words, step_normals
from ..models import AbstractStateSpaceModel, at_step


class Trajectory(NamedTuple):
    """One simulated run: ``states`` ``(T, n)``, ``measurements`` ``(T, m)``, ``detected`` ``(T,)``, ``ok`` ``()``.

    ``detected`` is True where the sensor detected the target at that step (the whole measurement
    vector is then observed); all True unless :func:`simulate` was given a
    ``detection_probability``. ``measurements`` holds the drawn values at every step, detected or
    not: pass ``mask=detected`` to :func:`~jaxtrack.filters.run_filter`. ``ok`` is False when a
    state or measurement is not finite (e.g. a turn rate or noise level built under ``jit`` as
    NaN, which no constructor could check); with ``simulate(..., throw=True)`` that is an error.
    """

    states: Float[Array, "T n"]
    measurements: Float[Array, "T m"]
    detected: Bool[Array, " T"]
    ok: Bool[Array, ""]


_SIMULATE_FAILED = (
    "jaxtrack.simulate produced a non-finite state or measurement. Likely cause: a model "
    "parameter built under jit/vmap/grad (a turn rate, sample period, noise level or sensor "
    "position) is NaN or infinite, or outside its range (a sample period <= 0, a negative noise "
    "level: the constructors reject such concrete values and turn traced ones into NaN); or a "
    "transition that overflows. Pass throw=False to get the Trajectory with ok=False instead."
)


@jax.custom_jvp
def psd_sqrt(cov: Array) -> Array:
    """A factor ``L`` with ``L Lᵀ = cov`` for a positive *semi*definite ``cov``.

    Plant noise is often singular (noise on the velocity only), where a Cholesky factor is NaN;
    the symmetric eigendecomposition handles it. Tiny negative eigenvalues from rounding clip to 0.

    **Arguments:**

    - ``cov``: a symmetric positive semidefinite matrix, ``(..., n, n)`` (leading axes batch).

    **Returns:** ``L``, shape ``(..., n, n)``, in the square root of ``cov``'s units.

    **Derivative** (a custom JVP): where the eigenvalues are distinct it is the exact derivative
    of ``L = V √Λ``. Where they repeat (``Q₁ ⊗ I`` of every kinematic model repeats each one), the
    eigenvectors are not unique and JAX's ``eigh`` derivative divides by ``λ_i − λ_j = 0`` (NaN);
    inside each repeated eigenspace the basis is then held fixed and the root differentiated
    (``S dS + dS S = dcov`` for ``S = cov^{1/2}``). With ``A = Vᵀ dcov V``: ``dL = V K`` with
    ``K_ij = A_ij √λ_j / (λ_j − λ_i)`` for distinct and ``K_ij = A_ij / (√λ_i + √λ_j)`` for equal
    eigenvalues (``i = j`` included: ``dλ_i / (2√λ_i)``), so that ``d(L Lᵀ) = dcov`` in both cases.
    Pairs of zero eigenvalues (a singular ``cov``, where the root is not differentiable) get 0.
    Why it is the right gradient for Monte Carlo: with repeated eigenvalues the factor, and so a
    simulated path for a fixed key, jumps when the computed basis rotates (finite differences with
    common random numbers are then meaningless), while ``S V ε`` with ``V`` held fixed has the
    law ``N(0, cov)`` for every ``cov``: this derivative is the pathwise (reparametrisation)
    gradient of the expectation. The value is computed as before, bit for bit: draws do not change.
    """
    eigvals, eigvecs = jnp.linalg.eigh(cov)
    return eigvecs * jnp.sqrt(jnp.clip(eigvals, 0.0))[..., None, :]


@psd_sqrt.defjvp
def _psd_sqrt_jvp(primals, tangents):
    (cov,), (dcov,) = primals, tangents
    eigvals, eigvecs = jnp.linalg.eigh(cov)
    lam = jnp.clip(eigvals, 0.0)
    root = jnp.sqrt(lam)
    factor = eigvecs * root[..., None, :]
    # eigh reads one triangle: the tangent of a symmetric input is its symmetric part.
    dsym = 0.5 * (dcov + jnp.swapaxes(dcov, -1, -2))
    a = jnp.swapaxes(eigvecs, -1, -2) @ dsym @ eigvecs
    gap = lam[..., None, :] - lam[..., :, None]  # λ_j − λ_i
    scale = jnp.max(lam, axis=-1, keepdims=True)[..., None]
    # "equal" up to rounding of the eigensolver (relative to the largest eigenvalue)
    equal = jnp.abs(gap) <= 1e3 * jnp.finfo(lam.dtype).eps * scale
    den_equal = root[..., :, None] + root[..., None, :]
    k_equal = jnp.where(den_equal > 0, a / jnp.where(den_equal > 0, den_equal, 1.0), 0.0)
    k_distinct = a * root[..., None, :] / jnp.where(equal, 1.0, gap)
    return factor, eigvecs @ jnp.where(equal, k_equal, k_distinct)


class NoiseFactors(NamedTuple):
    """Square-root noise factors, constant ``(n, n)`` or per step ``(T, n, n)``, and the prior's."""

    process: Array
    measurement: Array
    prior: Array


def noise_factors(model: AbstractStateSpaceModel, num_steps: int) -> NoiseFactors:
    """Factor Q, R and the prior covariance once, outside the per-run scan.

    **Arguments:**

    - ``model``: the state-space model.
    - ``num_steps``: ``T``, used when the model's covariances vary per step.

    **Returns:** :class:`NoiseFactors`: ``L_Q`` ``(n, n)`` or ``(T, n, n)``, ``L_R`` ``(m, m)`` or
    ``(T, m, m)``, and the prior's factor ``(n, n)``, in the square root of the covariances' units.
    """
    if model.num_steps is None:
        Lq = psd_sqrt(model.process_noise_cov(0))
        Lr = psd_sqrt(model.measurement_noise_cov(0))
    else:
        ks = jnp.arange(num_steps)
        Lq = jax.vmap(lambda k: psd_sqrt(model.process_noise_cov(k)))(ks)
        Lr = jax.vmap(lambda k: psd_sqrt(model.measurement_noise_cov(k)))(ks)
    return NoiseFactors(Lq, Lr, psd_sqrt(model.initial_cov))


# The detection draws of a run come from ``fold_in(run_key, _DETECTION_STREAM)``: a stream of its
# own, so that adding detections leaves the run's prior and per-step draws (``split(run_key)``,
# see step_keys) unchanged. The constant is arbitrary (ASCII "dete").
_DETECTION_STREAM = 0x64657465


def check_detection_probability(detection_probability, num_steps: int) -> np.ndarray:
    """Validate a detection probability: a float in ``(0, 1]`` or one per step ``(T,)``.

    It is a fixed design value, not a traced parameter: the detections are Bernoulli draws, not a
    differentiable function of it.

    **Arguments:**

    - ``detection_probability``: ``P_D``, a scalar or ``(T,)`` array-like of probabilities.
    - ``num_steps``: ``T``.

    **Returns:** ``P_D`` per step, a float64 NumPy array ``(T,)``.

    **Raises:** ``InputError`` for a traced value, a wrong shape, or a value outside ``(0, 1]``.
    """
    try:
        p = np.asarray(detection_probability, dtype=np.float64)
    except (TypeError, jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError) as err:
        raise InputError(
            "`detection_probability` must be a concrete float or array of floats (a fixed design value, "
            f"not a traced one); got {type(detection_probability).__name__}."
        ) from err
    if p.ndim == 0:
        p = np.full((num_steps,), float(p))
    if p.shape != (num_steps,):
        raise InputError(
            f"`detection_probability` must be a scalar or have shape ({num_steps},) (one per step); got shape {p.shape}."
        )
    if not np.all((p > 0.0) & (p <= 1.0)):
        raise InputError(f"`detection_probability` must lie in (0, 1] at every step; got values in [{p.min()}, {p.max()}].")
    return p


def draw_detections(run_key: PRNGKeyArray, detection_probability: Array, dtype) -> Array:
    """The detections of one run: step ``k`` is detected with probability ``P_D[k]``, independently.

    The draws depend only on the run's key (one uniform per step from
    ``fold_in(run_key, _DETECTION_STREAM)``), so :func:`simulate` and the Monte Carlo harness make
    the same ones for the same run key, in any batch, block or device.

    **Arguments:**

    - ``run_key``: the run's PRNG key (run ``i`` of a Monte Carlo: ``fold_in(key, i)``).
    - ``detection_probability``: ``P_D`` per step, ``(T,)``; ``dtype``: the floating type of the uniforms.

    **Returns:** ``detected``, boolean ``(T,)``.
    """
    p = jnp.asarray(detection_probability, dtype)
    u = jax.random.uniform(jax.random.fold_in(run_key, _DETECTION_STREAM), p.shape, dtype)
    # u ∈ [0, 1): P(u < p) = p, and p = 1 always detects.
    return u < p


def step_keys(key: PRNGKeyArray) -> tuple[PRNGKeyArray, PRNGKeyArray]:
    """Split a run's key into the prior-draw key and the base key of the per-step draws.

    **Arguments:**

    - ``key``: the run's PRNG key.

    **Returns:** ``(prior_key, steps_key)``, two PRNG keys.
    """
    prior_key, steps_key = jax.random.split(key)
    return prior_key, steps_key


def draw_initial_state(model, factors: NoiseFactors, prior_key) -> Array:
    """Draw ``x_0 = m_0 + L_0 ε`` from the model's prior ``N(m_0, P_0)``.

    **Arguments:**

    - ``model``: the state-space model; ``factors``: its :class:`NoiseFactors`.
    - ``prior_key``: the run's prior-draw key (:func:`step_keys`).

    **Returns:** ``x_0``, shape ``(n,)``, in the model's state units.
    """
    n = model.state_dim
    eps = jax.random.normal(prior_key, (n,), model.initial_mean.dtype)
    return model.initial_mean + matmul(factors.prior, eps)


def simulate_step(model, factors: NoiseFactors, first_step: FirstStep, x_prev, steps_key, k):
    """Draw ``x_k`` from ``x_{k-1}`` and then ``z_k``.

    Step ``k``'s ``n + m`` standard normal numbers come from the run's ``steps_key`` and the
    step index alone (see :func:`step_noise`): the plant noise uses the first ``n``, the
    measurement noise the last ``m``.

    **Arguments:**

    - ``model``: the state-space model; ``factors``: its :class:`NoiseFactors`.
    - ``first_step``: ``"update"`` (no transition into step 0) or ``"predict"``.
    - ``x_prev``: ``x_{k-1}``, ``(n,)`` (at ``k = 0`` under ``"update"``: the drawn ``x_0``).
    - ``steps_key``: the run's per-step key (:func:`step_keys`); ``k``: the step index.

    **Returns:** ``(x_k, z_k)``, shapes ``(n,)`` and ``(m,)``, in the model's units.
    """
    eps = step_noise(steps_key, k, model.state_dim + model.meas_dim, model.initial_mean.dtype)
    return advance(model, factors, first_step, x_prev, eps, k)


def step_noise(steps_key: PRNGKeyArray, k, num: int, dtype) -> Array:
    """Step ``k``'s ``num`` standard normal numbers for a run with per-step key ``steps_key``.

    One Threefry-2x32 evaluation per number, counter ``(k, j)`` (see :mod:`._noise`): the same
    numbers whether a run is simulated alone or in a batch of any size.

    **Arguments:**

    - ``steps_key``: the run's per-step PRNG key; ``k``: the step index.
    - ``num``: how many numbers; ``dtype``: their floating dtype.

    **Returns:** ``(num,)`` standard normal numbers.
    """
    return step_normals(key_words(steps_key), k, num, dtype)


def advance(model, factors: NoiseFactors, first_step: FirstStep, x_prev, eps, k):
    """``x_k = f_k(x_{k-1}) + L_Q ε_w``, ``z_k = h_k(x_k) + L_R ε_v`` given ``eps = (ε_w, ε_v)``.

    ``x_prev`` ``(n, *B)`` and ``eps`` ``(n + m, *B)`` may carry a trailing batch axis (the
    model's functions are then mapped over it). The noise products use ``matmul``, which sums in
    the same order with or without the batch axis, so a run replayed alone by :func:`simulate`
    reproduces the Monte Carlo harness's run exactly.

    **Arguments:**

    - ``model``: the state-space model; ``factors``: its :class:`NoiseFactors`.
    - ``first_step``: ``"update"`` (``x_0`` is ``x_prev`` at ``k = 0``) or ``"predict"``.
    - ``x_prev``: ``x_{k-1}``, ``(n,)`` or ``(n, B)``; ``eps``: ``(n + m,)`` or ``(n + m, B)`` standard
      normals.
    - ``k``: the step index.

    **Returns:** ``(x_k, z_k)``, shapes ``(n,)`` and ``(m,)`` (``(n, B)`` and ``(m, B)`` batched), in the
    model's units.
    """
    n = model.state_dim
    transition, measurement = model.transition, model.measurement
    if x_prev.ndim == 2:
        transition = jax.vmap(transition, in_axes=(1, None), out_axes=1)
        measurement = jax.vmap(measurement, in_axes=(1, None), out_axes=1)
    x = transition(x_prev, k) + matmul(at_step(factors.process, k, 2), eps[:n])
    if first_step == "update":
        # The prior is on x_0 itself: no transition into step 0.
        x = jnp.where(k == 0, x_prev, x)
    return x, measurement(x, k) + matmul(at_step(factors.measurement, k, 2), eps[n:])


@eqx.filter_jit
def _simulate_jit(model, key, num_steps, first_step, detection_probability):
    # No host callback in this program (the checks are attached by the caller, outside it: see
    # `simulate`), so JAX's persistent compilation cache can keep it.
    factors = noise_factors(model, num_steps)
    prior_key, steps_key = step_keys(key)
    x0 = draw_initial_state(model, factors, prior_key)

    num = model.state_dim + model.meas_dim
    dtype = model.initial_mean.dtype

    def step(carry, k):
        # Step k's draws were made in step k−1 (see montecarlo._run._simulated_block): the
        # carried value is computed once instead of inside every consumer. Same numbers as
        # simulate_step.
        x_prev, eps = carry
        x, z = advance(model, factors, first_step, x_prev, eps, k)
        return (x, step_noise(steps_key, k + 1, num, dtype)), (x, z)

    init = (x0, step_noise(steps_key, 0, num, dtype))
    _, (xs, zs) = jax.lax.scan(step, init, jnp.arange(num_steps))
    if detection_probability is None:
        detected = jnp.ones((num_steps,), bool)
    else:
        detected = draw_detections(key, detection_probability, dtype)
    ok = jnp.all(jnp.isfinite(xs)) & jnp.all(jnp.isfinite(zs))
    return Trajectory(xs, zs, detected, ok)


def _check_model_values(model: AbstractStateSpaceModel) -> None:
    """Eager checks of the values :func:`simulate` draws from (prior, noise covariances).

    The constructors check these, but a model edited with ``eqx.tree_at`` (or a custom
    subclass) bypasses them, and a NaN prior would otherwise give NaN states without a word.
    Only concrete values are checked here; traced ones by :func:`_guard_traced_model`.
    """
    check_finite("initial_mean", model.initial_mean)
    check_covariance("initial_cov", model.initial_cov, definite=False)
    for name in ("Q", "R"):
        value = getattr(model, name, None)
        if value is not None:
            label = "process_noise_cov" if name == "Q" else "measurement_noise_cov"
            check_finite(label, value)


def _guard_traced_model(model: AbstractStateSpaceModel, out):
    """Attach ``equinox.error_if`` checks of a traced prior (and noise covariances) to ``out``.

    Under ``jit``/``vmap``/``grad`` the eager checks cannot see the values; a NaN or indefinite
    prior would give NaN (or meaningless) states silently. One ``(n, n)`` eigvalsh, outside the
    scan. Called outside the jitted simulation, where ``model`` is what the caller passed: a
    concrete (eagerly checked) model adds nothing.
    """
    if is_concrete(model.initial_mean) and is_concrete(model.initial_cov):
        checks = []
    else:
        checks = [
            ("initial_mean", jnp.all(jnp.isfinite(model.initial_mean)), "finite"),
            ("initial_cov", covariance_ok(model.initial_cov, definite=False),
             "a finite, symmetric, positive semidefinite covariance"),
        ]
    for name in ("Q", "R"):
        value = getattr(model, name, None)
        if value is not None and not is_concrete(value):
            label = "process_noise_cov" if name == "Q" else "measurement_noise_cov"
            checks.append((label, jnp.all(jnp.isfinite(value)), "finite"))
    for label, ok, what in checks:
        out = eqx.error_if(out, ~ok, f"jaxtrack.simulate: the model's `{label}` must be {what}.")
    return out


def simulate(
    model: AbstractStateSpaceModel,
    key: PRNGKeyArray | int,
    num_steps: int | None = None,
    *,
    first_step: FirstStep = "update",
    detection_probability: float | ArrayLike | None = None,
    throw: bool = True,
) -> Trajectory:
    """Simulate one run of truth and measurements.

    The initial state is drawn from the model's prior ``N(initial_mean, initial_cov)``; with
    ``first_step="update"`` that draw *is* ``x_0``, with ``"predict"`` it is ``x_{-1}`` and
    ``x_0 = f_0(x_{-1}) + w_0`` (the same conventions as :func:`jaxtrack.filters.run_filter`).

    The run's key is split once into a prior key and a per-step key; step ``k``'s noise is a
    function of the per-step key and ``k`` only (one Threefry-2x32 hash per number, with
    ``jax.random.normal``'s transform; see :func:`step_noise`), so a trajectory does not depend on
    how many steps are simulated after it, and the Monte Carlo harness reproduces it exactly for
    the same run key. Keys must use JAX's default Threefry implementation.

    **Missed detections.** With ``detection_probability`` ``P_D``, step ``k`` is detected with
    probability ``P_D`` (or ``P_D[k]``), independently of the other steps; a detection is the
    whole measurement vector (all components are missing together). The draws come from their
    own stream, ``fold_in(key, ·)``, so the states and measurements are those drawn without it, and
    run ``i`` of ``monte_carlo(..., detection_probability=P_D)`` has the detections
    ``simulate(truth, fold_in(key, i), T, detection_probability=P_D).detected``.

    **Arguments:** ``model``; ``key``, a PRNG key or an int seed; ``num_steps`` ``T`` (defaults to the model's
    per-step length); ``first_step`` as in ``run_filter``; ``detection_probability``: None (every
    step detected) or a float in ``(0, 1]``, or one per step ``(T,)`` (a fixed value, not traced);
    ``throw``: True (default) raises when a state or measurement is not finite (inside ``jit``
    too, as ``run_filter`` does); False returns the trajectory with ``ok=False`` (use it under
    ``vmap`` and read ``ok`` per run).

    **Returns:** a :class:`Trajectory` with ``states`` ``(T, n)``, ``measurements`` ``(T, m)``
    (drawn at every step), ``detected`` ``(T,)`` (True = detected; all True without
    ``detection_probability``) and ``ok`` ``()``. Use ``jax.vmap`` over keys for a batch.

    **Raises:** ``InputError`` for a bad ``num_steps``, ``first_step`` or ``detection_probability``, a model function
    returning the wrong shape, or (concrete values) a non-finite prior mean, a prior covariance
    that is not positive semidefinite, or non-finite noise covariances; under tracing the value
    checks become ``equinox`` runtime errors naming the same arguments.
    """
    key = as_key(key)
    if not isinstance(model, AbstractStateSpaceModel):
        raise InputError(f"`model` must be a jaxtrack state-space model; got {type(model).__name__}.")
    num_steps = _resolve_num_steps(model, num_steps)
    if first_step not in ("update", "predict"):
        raise InputError(f"`first_step` must be 'update' or 'predict'; got {first_step!r}.")
    model.check_functions()
    _check_model_values(model)
    if detection_probability is not None:
        detection_probability = check_detection_probability(detection_probability, num_steps)
        detection_probability = jnp.asarray(detection_probability, model.initial_mean.dtype)
    out = _simulate_jit(model, key, num_steps, first_step, detection_probability)
    # The model's own checks first: a NaN prior is reported by name, not as "non-finite states"
    # (chained error_if's fire in order).
    out = _guard_traced_model(model, out)
    return throw_unless_ok(out, out.ok, _SIMULATE_FAILED) if throw else out


def _resolve_num_steps(model, num_steps) -> int:
    model_steps = model.num_steps
    if num_steps is None:
        if model_steps is None:
            raise InputError("`num_steps` is required for a time-invariant model.")
        return model_steps
    if not isinstance(num_steps, int) or num_steps < 1:
        raise InputError(f"`num_steps` must be a positive int; got {num_steps!r}.")
    if model_steps is not None and model_steps != num_steps:
        raise InputError(
            f"`num_steps` is {num_steps} but the model's per-step arrays have {model_steps} steps."
        )
    return num_steps
