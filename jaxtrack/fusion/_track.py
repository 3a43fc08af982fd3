"""Two-sensor track-to-track fusion of one target: two local Kalman filters and a fusion centre.

The local filters are the library's own (:class:`~jaxtrack.filters.KalmanFilter` stepped by
:meth:`~jaxtrack.filters.AbstractFilter.step`); the fusion centre applies a rule
(:class:`~jaxtrack.fusion.AbstractFusionRule`) to the two local tracks at every scan, without
feedback to the local filters. Beside the filters the scan carries the cross-covariance of the two
local errors (Bar-Shalom 1981) and the split of each local covariance into the part driven by
the common prior and process noise and the part driven by the sensor's own measurement noise,
so every rule gets what it needs from one recursion.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._validation import InputError, check_finite, check_shape, is_concrete
from ..filters._base import FirstStep
from ..filters._kalman import KalmanFilter
from ..filters._updates import symmetrize
from ..models import LinearGaussianModel
from ._strategies import AbstractFusionRule


def cross_covariance_step(
    cross_cov: Float[ArrayLike, "n n"],
    transition_matrix: Float[ArrayLike, "n n"],
    process_noise_cov: Float[ArrayLike, "n n"],
    gain1: Float[ArrayLike, "n m1"],
    measurement_matrix1: Float[ArrayLike, "m1 n"],
    gain2: Float[ArrayLike, "n m2"],
    measurement_matrix2: Float[ArrayLike, "m2 n"],
) -> Float[Array, "n n"]:
    r"""One step of the cross-covariance of two Kalman filters' errors on the same target.

    .. math::

        P_{12,k|k} = (I − K_1 H_1)\,(F P_{12,k-1|k-1} Fᵀ + Q)\,(I − K_2 H_2)ᵀ

    (Bar-Shalom 1981): the two filters share the process noise (hence ``+ Q``) and see
    independent measurement noises (hence no ``K R Kᵀ`` term). ``P_{12} = E[e_1 e_2ᵀ]``,
    ``e_i = x − x̂_i``; it holds for any gains ``K_i`` (optimal or not), as the Joseph form does.
    With ``K_1 = K_2`` and ``H_1 = H_2`` it is the recursion of the part of a filter's own
    covariance driven by its prior and the process noise.

    **Arguments:**

    - ``cross_cov``: ``P_{12,k-1|k-1}``, ``(n, n)`` (at the start: the prior covariance when
      both filters start from the same prior), state units squared.
    - ``transition_matrix``: ``F``, ``(n, n)``; ``process_noise_cov``: ``Q``, ``(n, n)`` (pass
      ``I`` and 0 for a step without prediction).
    - ``gain1``: ``K_1``, ``(n, m_1)``; ``measurement_matrix1``: ``H_1``, ``(m_1, n)``;
      ``gain2``, ``measurement_matrix2``: the second filter's, ``(n, m_2)`` and ``(m_2, n)``.

    **Returns:** ``P_{12,k|k}``, ``(n, n)`` (not symmetric in general).

    **Raises:** ``InputError`` naming the argument for mismatched shapes.

    References: Y. Bar-Shalom, "On the track-to-track correlation problem", IEEE Trans.
    Automatic Control 26(2), 571–572, 1981.
    """
    P12 = jnp.asarray(cross_cov)
    dtype = jnp.result_type(P12, float)
    F, Q, K1, H1, K2, H2 = (jnp.asarray(a).astype(dtype) for a in (
        transition_matrix, process_noise_cov, gain1, measurement_matrix1, gain2, measurement_matrix2))
    P12 = P12.astype(dtype)
    check_shape("cross_cov", P12, [(None, None)])
    n = P12.shape[0]
    check_shape("cross_cov", P12, [(n, n)])
    check_shape("transition_matrix", F, [(n, n)])
    check_shape("process_noise_cov", Q, [(n, n)])
    check_shape("gain1", K1, [(n, None)])
    check_shape("measurement_matrix1", H1, [(K1.shape[1], n)])
    check_shape("gain2", K2, [(n, None)])
    check_shape("measurement_matrix2", H2, [(K2.shape[1], n)])
    eye = jnp.eye(n, dtype=dtype)
    return (eye - K1 @ H1) @ (F @ P12 @ F.T + Q) @ (eye - K2 @ H2).T


class TrackFusionResult(eqx.Module):
    """Output of :func:`run_track_fusion` for one run of ``T`` scans.

    **Fields** (``n`` states; every array has a leading ``T``, one entry per scan):

    - ``mean1``, ``cov1``, ``mean2``, ``cov2``: the local tracks ``x̂_{i,k|k}`` ``(T, n)``,
      ``P_{i,k|k}`` ``(T, n, n)``.
    - ``cross_cov``: ``P_{12,k|k} = E[e_1 e_2ᵀ]``, ``(T, n, n)`` (:func:`cross_covariance_step`).
    - ``independent_cov1``, ``independent_cov2``: ``(T, n, n)``, the part of ``P_{i,k|k}`` driven
      by sensor ``i``'s own measurement noise, independent between the two tracks; the rest,
      ``P_i − P_{i,ind}``, comes from the common prior and process noise (what split CI reads).
    - ``fused_mean`` ``(T, n)``, ``fused_cov`` ``(T, n, n)``: the fusion centre's estimate.
    - ``fused_weight``: ``(T,)``, the rule's ``ω`` per scan (CI, split CI); None for the others.
    - ``ok``: ``()`` bool; False when a local filter or a fused estimate became non-finite.
    """

    mean1: Float[Array, "T n"]
    cov1: Float[Array, "T n n"]
    mean2: Float[Array, "T n"]
    cov2: Float[Array, "T n n"]
    cross_cov: Float[Array, "T n n"]
    independent_cov1: Float[Array, "T n n"]
    independent_cov2: Float[Array, "T n n"]
    fused_mean: Float[Array, "T n"]
    fused_cov: Float[Array, "T n n"]
    fused_weight: Float[Array, " T"] | None
    ok: Bool[Array, ""]


def _independent_step(Pi, F, K, H, R):
    """``A F P_i Fᵀ Aᵀ + K R Kᵀ`` with ``A = I − K H``: the part driven by the sensor's own noise."""
    A = jnp.eye(F.shape[0], dtype=F.dtype) - K @ H
    return symmetrize(A @ F @ Pi @ F.T @ A.T + K @ R @ K.T)


@eqx.filter_jit
def _run_track_fusion(rule, model1, model2, z1, z2, filter1, filter2, first_step):
    n = model1.state_dim
    dtype = model1.initial_cov.dtype
    eye = jnp.eye(n, dtype=dtype)
    zeros = jnp.zeros((n, n), dtype)

    def step(carry, zs):
        state1, state2, P12, Pi1, Pi2 = carry
        k = state1.step
        state1, out1 = filter1.step(model1, state1, zs[0], first_step=first_step)
        state2, out2 = filter2.step(model2, state2, zs[1], first_step=first_step)
        F, Q = model1.transition_matrix(k), model1.process_noise_cov(k)
        if first_step == "update":
            # The prior sits at the first scan: no transition into scan 0 (as the filters do).
            F = jnp.where(k == 0, eye, F)
            Q = jnp.where(k == 0, zeros, Q)
        K1, K2 = out1.conditioned.gain, out2.conditioned.gain
        H1, H2 = model1.measurement_matrix(k), model2.measurement_matrix(k)
        P12 = cross_covariance_step(P12, F, Q, K1, H1, K2, H2)
        Pi1 = _independent_step(Pi1, F, K1, H1, model1.measurement_noise_cov(k))
        Pi2 = _independent_step(Pi2, F, K2, H2, model2.measurement_noise_cov(k))
        fused = rule.fuse(state1.mean, state1.cov, state2.mean, state2.cov, cross_cov=P12,
                          independent_cov1=Pi1, independent_cov2=Pi2)
        out = (state1.mean, state1.cov, state2.mean, state2.cov, P12, Pi1, Pi2, fused.mean, fused.cov,
               fused.weight, fused.ok)
        return (state1, state2, P12, Pi1, Pi2), out

    # Both filters start from the same prior: their initial errors are the same vector, so their
    # cross-covariance is the prior covariance and none of it is independent.
    init = (filter1.init(model1), filter2.init(model2), model1.initial_cov, zeros, zeros)
    (state1, state2, *_), hist = jax.lax.scan(step, init, (z1, z2))
    *fields, fused_ok = hist
    ok = state1.ok & state2.ok & jnp.all(fused_ok)
    return TrackFusionResult(*fields, ok)


def _same(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    if not (is_concrete(a) and is_concrete(b)):
        return True  # traced: cannot be compared here (documented)
    return np.shape(a) == np.shape(b) and bool(np.array_equal(np.asarray(a), np.asarray(b)))


def _checked_measurements(name: str, z, model, dtype):
    z = jnp.asarray(z)
    z = z.astype(jnp.result_type(z, dtype))
    m = model.meas_dim
    if z.ndim == 1 and m == 1:
        z = z[:, None]
    check_shape(name, z, [(None, m)])
    if z.shape[0] == 0:
        raise InputError(f"`{name}` must have at least one scan; got shape {z.shape}.")
    check_finite(name, z)
    return z


def run_track_fusion(
    rule: AbstractFusionRule,
    model1: LinearGaussianModel,
    model2: LinearGaussianModel,
    measurements1: Float[ArrayLike, "T m1"],
    measurements2: Float[ArrayLike, "T m2"],
    *,
    filter1: KalmanFilter = KalmanFilter(),
    filter2: KalmanFilter = KalmanFilter(),
    first_step: FirstStep = "update",
) -> TrackFusionResult:
    r"""Two-sensor track-to-track fusion of ONE target: two local Kalman filters, fused every scan.

    Sensor ``i`` has its own measurement model (``H_i``, ``R_i`` of ``model_i``) and its own
    :class:`~jaxtrack.filters.KalmanFilter`; both filters share the target's motion model
    (``F``, ``Q``, ``b``) and prior. At every scan each filter takes its sensor's measurement
    (one :meth:`~jaxtrack.filters.AbstractFilter.step`), and the fusion centre fuses the two
    local tracks with ``rule`` (no feedback to the local filters). The same scan carries

    .. math::

        P_{12,k|k} = (I − K_1 H_1)(F P_{12,k-1|k-1} Fᵀ + Q)(I − K_2 H_2)ᵀ,\qquad P_{12,0} = P_0

    (Bar-Shalom 1981, :func:`cross_covariance_step`; exact for the models' ``F``, ``Q``, ``R``
    and any gains), handed to the rule as ``cross_cov`` (what
    :class:`~jaxtrack.fusion.BarShalomCampo` needs), and the part of each local covariance
    driven by that sensor's own measurement noise,
    ``P_{i,ind} ← (I − K_i H_i) F P_{i,ind} Fᵀ (I − K_i H_i)ᵀ + K_i R_i K_iᵀ`` from 0, handed as
    ``independent_cov1``/``independent_cov2`` (what
    :class:`~jaxtrack.fusion.SplitCovarianceIntersection` needs).

    Single target, one measurement per sensor per scan, every scan observed by both sensors: no
    association, clutter or missed detections here. One ``lax.scan``, jitted; ``jax.vmap`` it
    over runs for a Monte Carlo (simulate run ``i`` from ``jax.random.fold_in(key, i)`` with
    :func:`jaxtrack.montecarlo.simulate` on :func:`stacked_sensor_model`, whose measurement
    splits into the two sensors' columns). Differentiable in the rule's fields (a fixed ``ω``)
    and in the models' arrays (``Q``, ``R_i``, ...); through the optimal ``ω`` exactly.

    **Arguments:**

    - ``rule``: the fusion rule, an :class:`~jaxtrack.fusion.AbstractFusionRule`.
    - ``model1``, ``model2``: :class:`~jaxtrack.models.LinearGaussianModel` s with the same
      ``F``, ``Q``, ``b`` and prior (``initial_mean``, ``initial_cov``) and each its own ``H_i``,
      ``R_i``; constant or per scan.
    - ``measurements1``: ``(T, m_1)``, ``measurements2``: ``(T, m_2)``, in each sensor's units
      (the same ``T``).
    - ``filter1``, ``filter2``: the local filters (default ``KalmanFilter()``; a fixed-gain
      Kalman filter is allowed, the recursions hold for any gain).
    - ``first_step``: where the prior sits, as in :func:`~jaxtrack.filters.run_filter`.

    **Returns:** a :class:`TrackFusionResult`.

    **Raises:** ``InputError`` naming the argument for a rule, model or filter of the wrong
    kind, models that do not share (concrete) ``F``, ``Q``, ``b`` and prior, measurements of the
    wrong shape or different lengths, concrete non-finite measurements, or a bad ``first_step``.
    Traced models cannot be compared: keeping them equal is then the caller's part.
    """
    if not isinstance(rule, AbstractFusionRule):
        raise InputError(f"`rule` must be a jaxtrack fusion rule (AbstractFusionRule); got {type(rule).__name__}.")
    for name, model in (("model1", model1), ("model2", model2)):
        if not isinstance(model, LinearGaussianModel):
            raise InputError(f"`{name}` must be a LinearGaussianModel; got {type(model).__name__}.")
    for name, filt, model in (("filter1", filter1, model1), ("filter2", filter2, model2)):
        if not isinstance(filt, KalmanFilter):
            raise InputError(f"`{name}` must be a KalmanFilter; got {type(filt).__name__}.")
        filt.check_model(model)
    if first_step not in ("update", "predict"):
        raise InputError(f"`first_step` must be 'update' or 'predict'; got {first_step!r}.")
    if model2.state_dim != model1.state_dim:
        raise InputError(f"`model2` has {model2.state_dim} states but `model1` has {model1.state_dim}; "
                         f"both sensors track the same state.")
    for field in ("F", "Q", "b", "initial_mean", "initial_cov"):
        if not _same(getattr(model1, field), getattr(model2, field)):
            raise InputError(
                f"`model2` must share `model1`'s motion model and prior; their `{field}` differ. The "
                f"cross-covariance recursion holds for one target motion and one common prior.")
    dtype = model1.initial_cov.dtype
    z1 = _checked_measurements("measurements1", measurements1, model1, dtype)
    z2 = _checked_measurements("measurements2", measurements2, model2, dtype)
    if z2.shape[0] != z1.shape[0]:
        raise InputError(f"`measurements2` has {z2.shape[0]} scans but `measurements1` has {z1.shape[0]}; "
                         f"the sensors report at the same scans.")
    for name, model in (("model1", model1), ("model2", model2)):
        if model.num_steps is not None and model.num_steps != z1.shape[0]:
            raise InputError(f"`{name}` has per-step arrays of {model.num_steps} steps but the measurements "
                             f"have {z1.shape[0]} scans.")
    return _run_track_fusion(rule, model1, model2, z1, z2, filter1, filter2, first_step)


def _stack_rows(a, b, steps):
    """``[a; b]`` along the rows of each step's matrix; a constant side broadcast to per-step."""
    if a.ndim != b.ndim:
        a = a if a.ndim == 3 else jnp.broadcast_to(a, (steps,) + a.shape)
        b = b if b.ndim == 3 else jnp.broadcast_to(b, (steps,) + b.shape)
    return jnp.concatenate([a, b], axis=-2)


def _block_diag(a, b, steps):
    if a.ndim != b.ndim:
        a = a if a.ndim == 3 else jnp.broadcast_to(a, (steps,) + a.shape)
        b = b if b.ndim == 3 else jnp.broadcast_to(b, (steps,) + b.shape)
    m1, m2 = a.shape[-1], b.shape[-1]
    upper = jnp.concatenate([a, jnp.zeros(a.shape[:-1] + (m2,), a.dtype)], axis=-1)
    lower = jnp.concatenate([jnp.zeros(b.shape[:-1] + (m1,), b.dtype), b], axis=-1)
    return jnp.concatenate([upper, lower], axis=-2)


def stacked_sensor_model(model1: LinearGaussianModel, model2: LinearGaussianModel) -> LinearGaussianModel:
    r"""The two sensors as one: ``H = [H_1; H_2]``, ``R = diag(R_1, R_2)``, the shared motion and prior.

    What the target and both sensors do together, for simulating a two-sensor run with
    :func:`jaxtrack.montecarlo.simulate` (its measurement ``(T, m_1 + m_2)`` splits into
    ``[:, :m_1]`` for sensor 1 and ``[:, m_1:]`` for sensor 2) and for the centralised Kalman
    filter that track fusion is compared with.

    **Arguments:** ``model1``, ``model2``: as for :func:`run_track_fusion` (same ``F``, ``Q``,
    ``b`` and prior; the motion model and prior are taken from ``model1``).

    **Returns:** a :class:`~jaxtrack.models.LinearGaussianModel` with ``m_1 + m_2`` measurement
    components (``model2``'s angle components shifted by ``m_1``).

    **Raises:** ``InputError`` naming the argument, as :func:`run_track_fusion`.
    """
    for name, model in (("model1", model1), ("model2", model2)):
        if not isinstance(model, LinearGaussianModel):
            raise InputError(f"`{name}` must be a LinearGaussianModel; got {type(model).__name__}.")
    if model2.state_dim != model1.state_dim:
        raise InputError(f"`model2` has {model2.state_dim} states but `model1` has {model1.state_dim}.")
    for field in ("F", "Q", "b", "initial_mean", "initial_cov"):
        if not _same(getattr(model1, field), getattr(model2, field)):
            raise InputError(f"`model2` must share `model1`'s motion model and prior; their `{field}` differ.")
    steps = model1.num_steps or model2.num_steps
    m1 = model1.meas_dim
    return LinearGaussianModel(
        model1.F, model1.Q, _stack_rows(model1.H, model2.H, steps), _block_diag(model1.R, model2.R, steps),
        model1.initial_mean, model1.initial_cov, transition_offset=model1.b,
        angle_components=model1.angle_components + tuple(m1 + i for i in model2.angle_components),
        state_layout=model1.state_layout,
    )
