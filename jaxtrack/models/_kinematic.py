"""Standard kinematic models built from a sampling schedule, and Ho's segment schedules.

Every builder takes ``taus``, the sampling period(s) in seconds: a scalar gives constant ``F`` and
``Q`` of shape ``(n, n)``; a schedule of shape ``(T,)`` gives per-step stacks ``(T, n, n)`` where
``taus[k]`` is the interval that ENDS at measurement ``k`` (the model convention of
:mod:`jaxtrack.models._base`). All matrices are built with ``jnp`` from ``taus``, so ``jax.grad``
with respect to every τ_k (and to the noise levels) works.

State ordering is all positions, then all velocities (then all accelerations):
``x = [p_1..p_d, v_1..v_d, (a_1..a_d)]``, i.e. ``F = F_1d ⊗ I_d`` and ``Q = Q_1d ⊗ diag(q)``.
The measurement is the position, ``H = [I_d, 0, …]``, with ``R = diag(σ²)``.
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._validation import InputError, check_finite, check_shape, is_concrete, nan_where_traced
from ._base import LinearGaussianModel
from ._discretize import check_taus, discretize
from ._layout import kinematic_layout

# --------------------------------------------------------------------------------------------
# helpers


def _check_dim(dim) -> int:
    if isinstance(dim, bool) or not isinstance(dim, numbers.Integral) or int(dim) not in (1, 2, 3):
        raise InputError(f"`dim` must be 1, 2 or 3 (spatial dimensions); got {dim!r}.")
    return int(dim)


def _check_nonneg(name: str, x, shapes, *, strict: bool) -> Array:
    """Float array of an allowed shape whose concrete entries are finite and ≥ 0 (> 0 if strict)."""
    x = jnp.asarray(x)
    x = x.astype(jnp.result_type(x, float))
    check_shape(name, x, shapes)
    check_finite(name, x)
    if is_concrete(x):
        arr = np.atleast_1d(np.asarray(x))
        bad = arr <= 0 if strict else arr < 0
        if np.any(bad):
            first = int(np.argwhere(bad)[0][0])
            what = "strictly positive" if strict else "non-negative"
            raise InputError(
                f"`{name}` must be {what}; entry {first} is {arr[first]} "
                f"(a standard deviation or spectral density, not a signed quantity)."
            )
    return nan_where_traced(x, (lambda a: a <= 0) if strict else (lambda a: a < 0))


def _per_axis(name: str, x, dim: int, *, strict: bool) -> Array:
    """A scalar or per-axis ``(dim,)`` positive quantity, broadcast to shape ``(dim,)``."""
    x = _check_nonneg(name, x, [(), (dim,)], strict=strict)
    return jnp.broadcast_to(x, (dim,))


def _kron_diag(M: Array, v: Array) -> Array:
    """``M ⊗ diag(v)`` for ``M`` of shape ``(..., k, k)`` and ``v`` of shape ``(d,)``."""
    k, d = M.shape[-1], v.shape[0]
    out = jnp.einsum("...ij,ab->...iajb", M, jnp.diag(v))
    return out.reshape(M.shape[:-2] + (k * d, k * d))


def _map_taus(fn, taus: Array):
    """Apply a per-period builder to a scalar τ, or vmap it over a schedule."""
    return fn(taus) if taus.ndim == 0 else jax.vmap(fn)(taus)


def _position_model(F1, Q1, q, dim, order, measurement_std, initial_mean, initial_cov):
    """Assemble the ``LinearGaussianModel`` from 1-D blocks ``F1``, ``Q1`` of size ``order``."""
    dtype = jnp.result_type(F1, Q1, q)
    n = order * dim
    std = _per_axis("measurement_std", measurement_std, dim, strict=True).astype(dtype)
    F = _kron_diag(F1, jnp.ones((dim,), dtype))
    Q = _kron_diag(Q1, q.astype(dtype))
    H = jnp.eye(dim, n, dtype=dtype)
    R = jnp.diag(std**2)
    if initial_mean is None:
        initial_mean = jnp.zeros((n,), dtype)
    if initial_cov is None:
        raise InputError(f"`initial_cov` is required: the prior covariance, shape ({n}, {n}).")
    return LinearGaussianModel(F, Q, H, R, initial_mean, initial_cov, state_layout=kinematic_layout(dim, order))


# --------------------------------------------------------------------------------------------
# 1-D blocks (scalar τ)


def _cv_blocks(tau):
    one, zero = jnp.ones_like(tau), jnp.zeros_like(tau)
    F = jnp.stack([jnp.stack([one, tau]), jnp.stack([zero, one])])
    Q = jnp.stack(
        [
            jnp.stack([tau**3 / 3, tau**2 / 2]),
            jnp.stack([tau**2 / 2, tau]),
        ]
    )
    return F, Q


def _ca_blocks(tau):
    one, zero = jnp.ones_like(tau), jnp.zeros_like(tau)
    F = jnp.stack(
        [
            jnp.stack([one, tau, tau**2 / 2]),
            jnp.stack([zero, one, tau]),
            jnp.stack([zero, zero, one]),
        ]
    )
    Q = jnp.stack(
        [
            jnp.stack([tau**5 / 20, tau**4 / 8, tau**3 / 6]),
            jnp.stack([tau**4 / 8, tau**3 / 3, tau**2 / 2]),
            jnp.stack([tau**3 / 6, tau**2 / 2, tau]),
        ]
    )
    return F, Q


# --------------------------------------------------------------------------------------------
# public builders


def constant_velocity(
    taus: ArrayLike,
    *,
    dim: int = 2,
    accel_psd: ArrayLike,
    measurement_std: ArrayLike,
    initial_mean: ArrayLike | None = None,
    initial_cov: ArrayLike,
) -> LinearGaussianModel:
    r"""Constant-velocity model driven by continuous white-noise acceleration (CWNA).

    Per axis, ``p̈ = w(t)`` with ``E[w(t) w(s)] = q δ(t − s)``. Over a period τ the exact
    discretisation is (Bar-Shalom, Li & Kirubarajan 2001, §6.2.2)

    .. math::

        F_{1d}(τ) = \begin{bmatrix} 1 & τ \\ 0 & 1 \end{bmatrix}, \qquad
        Q_{1d}(τ) = q \begin{bmatrix} τ^3/3 & τ^2/2 \\ τ^2/2 & τ \end{bmatrix},

    and in ``dim`` axes ``F = F_{1d} ⊗ I_d``, ``Q = Q_{1d} ⊗ diag(q)`` (state
    ``[positions…, velocities…]``). Closed form, so differentiable in every τ_k and in ``q``.

    **Arguments:**

    - ``taus``: sampling period(s), seconds, shape ``()`` (constant ``F``, ``Q``) or ``(T,)``
      (per-step stacks; ``taus[k]`` ends at measurement ``k``). Finite, > 0.
    - ``dim``: number of spatial axes, 1, 2 or 3.
    - ``accel_psd``: acceleration noise power spectral density ``q``, m²/s³ (= (m/s²)²/Hz), shape
      ``()`` or per-axis ``(dim,)``, ≥ 0.
    - ``measurement_std``: position measurement noise σ, metres, shape ``()`` or ``(dim,)``, > 0.
    - ``initial_mean``: prior mean, shape ``(2·dim,)`` (m, m/s); zeros when ``None``.
    - ``initial_cov``: prior covariance, shape ``(2·dim, 2·dim)`` (m², m²/s², m²/s); required.

    **Returns:**

    A :class:`~jaxtrack.models.LinearGaussianModel` with ``n = 2·dim`` states and ``m = dim``
    position measurements, ``H = [I_d, 0]``, ``R = diag(σ²)``.

    **Raises:**

    :class:`~jaxtrack.InputError` naming the argument: ``dim`` not 1–3, a non-positive τ, a
    negative ``accel_psd``, a non-positive ``measurement_std``, or a bad prior.
    """
    dim = _check_dim(dim)
    taus = check_taus("taus", taus)
    q = _per_axis("accel_psd", accel_psd, dim, strict=False)
    F1, Q1 = _map_taus(_cv_blocks, taus)
    return _position_model(F1, Q1, q, dim, 2, measurement_std, initial_mean, initial_cov)


def constant_acceleration(
    taus: ArrayLike,
    *,
    dim: int = 2,
    jerk_psd: ArrayLike,
    measurement_std: ArrayLike,
    initial_mean: ArrayLike | None = None,
    initial_cov: ArrayLike,
) -> LinearGaussianModel:
    r"""Constant-acceleration model driven by continuous white-noise jerk (Wiener acceleration).

    Per axis, ``p⃛ = w(t)`` with ``E[w(t) w(s)] = q δ(t − s)``. Over a period τ
    (Bar-Shalom, Li & Kirubarajan 2001, §6.2.3)

    .. math::

        F_{1d}(τ) = \begin{bmatrix} 1 & τ & τ^2/2 \\ 0 & 1 & τ \\ 0 & 0 & 1 \end{bmatrix},
        \qquad
        Q_{1d}(τ) = q \begin{bmatrix} τ^5/20 & τ^4/8 & τ^3/6 \\ τ^4/8 & τ^3/3 & τ^2/2 \\
        τ^3/6 & τ^2/2 & τ \end{bmatrix},

    with ``F = F_{1d} ⊗ I_d`` and ``Q = Q_{1d} ⊗ diag(q)`` (state
    ``[positions…, velocities…, accelerations…]``). Closed form.

    **Arguments:**

    - ``taus``: sampling period(s), seconds, shape ``()`` or ``(T,)``, finite and > 0.
    - ``dim``: number of spatial axes, 1, 2 or 3.
    - ``jerk_psd``: jerk noise power spectral density ``q``, m²/s⁵, shape ``()`` or ``(dim,)``, ≥ 0.
    - ``measurement_std``: position measurement noise σ, metres, shape ``()`` or ``(dim,)``, > 0.
    - ``initial_mean``: prior mean, shape ``(3·dim,)``; zeros when ``None``.
    - ``initial_cov``: prior covariance, shape ``(3·dim, 3·dim)``; required.

    **Returns:**

    A :class:`~jaxtrack.models.LinearGaussianModel` with ``n = 3·dim`` states and ``m = dim``.

    **Raises:**

    :class:`~jaxtrack.InputError` naming the argument, as :func:`constant_velocity`.
    """
    dim = _check_dim(dim)
    taus = check_taus("taus", taus)
    q = _per_axis("jerk_psd", jerk_psd, dim, strict=False)
    F1, Q1 = _map_taus(_ca_blocks, taus)
    return _position_model(F1, Q1, q, dim, 3, measurement_std, initial_mean, initial_cov)


def singer(
    taus: ArrayLike,
    *,
    dim: int = 2,
    maneuver_time_constant: ArrayLike,
    accel_std: ArrayLike,
    measurement_std: ArrayLike,
    initial_mean: ArrayLike | None = None,
    initial_cov: ArrayLike,
) -> LinearGaussianModel:
    r"""Singer (1970) manoeuvring-target model: exponentially correlated acceleration.

    Per axis, with state ``[p, v, a]``,

    .. math::

        \dot p = v, \quad \dot v = a, \quad \dot a = -a/θ + w(t), \qquad
        E[w(t) w(s)] = \frac{2σ_a^2}{θ} δ(t - s),

    so the acceleration is a stationary Gauss–Markov process with variance ``σ_a²`` and
    correlation time θ. ``Φ(τ)`` and ``Q(τ)`` are computed by :func:`van_loan` from
    ``A = [[0,1,0],[0,0,1],[0,0,−1/θ]]`` and ``Q_c = diag(0, 0, 2σ_a²/θ)``; in closed form
    ``Φ = [[1, τ, θ²(−1 + τ/θ + e^{−τ/θ})], [0, 1, θ(1 − e^{−τ/θ})], [0, 0, e^{−τ/θ}]]``.
    Then ``F = Φ ⊗ I_d`` and ``Q = Q_{1d} ⊗ I_d`` (the same θ and σ_a on every axis).
    Differentiable in every τ_k, θ and σ_a.

    **Arguments:**

    - ``taus``: sampling period(s), seconds, shape ``()`` or ``(T,)``, finite and > 0.
    - ``dim``: number of spatial axes, 1, 2 or 3.
    - ``maneuver_time_constant``: θ, seconds, shape ``()``, > 0.
    - ``accel_std``: σ_a, standard deviation of the target acceleration, m/s², shape ``()``, ≥ 0.
    - ``measurement_std``: position measurement noise σ, metres, shape ``()`` or ``(dim,)``, > 0.
    - ``initial_mean``: prior mean, shape ``(3·dim,)``; zeros when ``None``.
    - ``initial_cov``: prior covariance, shape ``(3·dim, 3·dim)``; required.

    **Returns:**

    A :class:`~jaxtrack.models.LinearGaussianModel` with ``n = 3·dim`` states and ``m = dim``.

    **Raises:**

    :class:`~jaxtrack.InputError` naming the argument.

    ??? cite "Reference"

        ```bibtex
        @article{singer1970,
          author  = {Singer, Robert A.},
          title   = {Estimating Optimal Tracking Filter Performance for Manned Maneuvering Targets},
          journal = {IEEE Transactions on Aerospace and Electronic Systems},
          volume  = {AES-6},
          number  = {4},
          pages   = {473--483},
          year    = {1970},
        }
        ```
    """
    dim = _check_dim(dim)
    taus = check_taus("taus", taus)
    theta = _check_nonneg("maneuver_time_constant", maneuver_time_constant, [()], strict=True)
    sigma = _check_nonneg("accel_std", accel_std, [()], strict=False)
    dtype = jnp.result_type(taus, theta, sigma)
    theta, sigma = theta.astype(dtype), sigma.astype(dtype)
    zero, one = jnp.zeros((), dtype), jnp.ones((), dtype)
    A = jnp.stack(
        [
            jnp.stack([zero, one, zero]),
            jnp.stack([zero, zero, one]),
            jnp.stack([zero, zero, -1.0 / theta]),
        ]
    )
    Qc = jnp.diag(jnp.stack([zero, zero, 2.0 * sigma**2 / theta]))
    F1, Q1 = discretize(A, Qc, taus)
    return _position_model(
        F1, Q1, jnp.ones((dim,), dtype), dim, 3, measurement_std, initial_mean, initial_cov
    )


# Ho 1968, eq. (86): Q = diag(0.259 τ, 104 τ) ft², ft²/s² for a 1-g plant noise.
_HO_Q_RATE = (0.259, 104.0)


def ho_plant(
    taus: ArrayLike,
    *,
    g: ArrayLike = 1.0,
    measurement_var: ArrayLike = 1e4,
    initial_cov: ArrayLike | None = None,
    initial_mean: ArrayLike | None = None,
) -> LinearGaussianModel:
    r"""Ho's (1968) 1/s² plant of Sec. III-E, in feet, with the literal plant noise of eq. (86).

    State ``x = [p, ṗ]`` (ft, ft/s), position measurements (Ho 1968, eqs. 83–86)

    .. math::

        x_k = \begin{bmatrix} 1 & τ_k \\ 0 & 1 \end{bmatrix} x_{k-1} + w_k, \qquad
        Q_k = \mathrm{diag}(0.259\,τ_k,\ 104\,τ_k)\, g^2, \qquad
        z_k = [1\ 0]\, x_k + v_k, \qquad R_k = 10^4\ \mathrm{ft}^2,

    with prior ``P_{0/-1} = diag(10⁶, 10⁶)``.

    ``Q`` is eq. (86) taken LITERALLY, linear in τ, so ``∂Q/∂τ = diag(0.259, 104)·g²``: this is
    Convention 1 of ``specs/ho-sensitivity.md`` §4.1. The coefficients are Ho's
    constant-acceleration-over-τ model (88) evaluated at τ₀ = 0.1 s with σ_a = 32.2 ft/s² and
    then made proportional to τ; the exact eq. (88) or the continuous-white-noise
    ``q[[τ³/3, τ²/2],[τ²/2, τ]]`` do not reproduce the paper's numbers (e.g. 1331 instead of
    876 ft² terminal variance). For the paper's sample indexing use :func:`segment_schedule`
    (Convention 2): ``taus[0]`` is unused when the filter's prior sits at the first sample
    (``first_step="update"``).

    **Arguments:**

    - ``taus``: sampling period(s) τ_k, seconds, shape ``()`` or ``(T,)``, finite and > 0.
    - ``g``: plant-noise level in g (1 or 10 in the paper), shape ``()``, ≥ 0, dimensionless.
    - ``measurement_var``: ``R_k``, ft², shape ``()`` or per-step ``(T,)``, > 0. Example 2's
      smoothed measurements are ``measurement_var=1e3 / taus`` (Ho 1968, eq. 87).
    - ``initial_cov``: ``P_{0/-1}``, shape ``(2, 2)`` (ft², ft²/s²); ``diag(1e6, 1e6)`` when
      ``None``.
    - ``initial_mean``: prior mean, shape ``(2,)``; zeros when ``None``.

    **Returns:**

    A :class:`~jaxtrack.models.LinearGaussianModel` with ``n = 2``, ``m = 1``.

    **Raises:**

    :class:`~jaxtrack.InputError` naming the argument.

    >>> model = ho_plant(0.1)
    >>> model.Q.round(6).tolist()
    [[0.0259, 0.0], [0.0, 10.4]]
    """
    taus = check_taus("taus", taus)
    g = _check_nonneg("g", g, [()], strict=False)
    rvar = _check_nonneg("measurement_var", measurement_var, [(), (None,)], strict=True)
    if taus.ndim == 1 and rvar.ndim == 1 and rvar.shape[0] != taus.shape[0]:
        raise InputError(
            f"`measurement_var` has {rvar.shape[0]} steps but `taus` has {taus.shape[0]}."
        )
    dtype = jnp.result_type(taus, g, rvar)
    taus, g, rvar = taus.astype(dtype), g.astype(dtype), rvar.astype(dtype)
    rate = jnp.asarray(_HO_Q_RATE, dtype) * g**2

    def blocks(tau):
        F = jnp.stack([jnp.stack([jnp.ones_like(tau), tau]), jnp.eye(2, dtype=dtype)[1]])
        return F, jnp.diag(rate * tau)

    F, Q = _map_taus(blocks, taus)
    H = jnp.array([[1.0, 0.0]], dtype)
    R = rvar[..., None, None]
    if initial_cov is None:
        initial_cov = jnp.diag(jnp.array([1e6, 1e6], dtype))
    if initial_mean is None:
        initial_mean = jnp.zeros((2,), dtype)
    return LinearGaussianModel(F, Q, H, R, initial_mean, initial_cov)


def segment_schedule(
    counts: Sequence[int], segment_duration: ArrayLike = 1.0
) -> Float[Array, " N"]:
    r"""Ho's segment sampling schedule (Convention 2 of ``specs/ho-sensitivity.md`` §4.1).

    Segment ``i`` (``i = 1..S``) covers ``[(i−1)D, iD]`` and holds ``n_i`` equally spaced samples
    at ``t = (i−1)·D + j·D/n_i``, ``j = 1..n_i``. The result holds one period per sample,
    ``N = Σ n_i`` entries, where ``taus[k]`` is the interval that ENDS at sample ``k``: the
    first ``n_1`` entries are ``D/n_1``, the next ``n_2`` are ``D/n_2``, and so on. Thus the
    interval ending at a segment's first sample has that segment's τ, and ``taus[0] = D/n_1`` is
    the (unused) interval before the first sample when the prior sits at it
    (``first_step="update"``). :func:`sample_times` turns it into the sample times, the last one
    being ``S·D``.

    **Arguments:**

    - ``counts``: samples per segment ``(n_1, …, n_S)``, a Python sequence of positive ints.
    - ``segment_duration``: ``D``, seconds, shape ``()``, > 0 (differentiable).

    **Returns:**

    ``taus``, seconds, shape ``(N,)``.

    **Raises:**

    :class:`~jaxtrack.InputError` naming ``counts`` or ``segment_duration``.

    >>> segment_schedule((2, 4)).tolist()
    [0.5, 0.5, 0.25, 0.25, 0.25, 0.25]
    """
    if isinstance(counts, (str, bytes)) or not isinstance(counts, Sequence | np.ndarray):
        raise InputError(
            f"`counts` must be a sequence of positive ints (samples per segment); got {counts!r}."
        )
    counts = list(counts)
    if not counts:
        raise InputError("`counts` must hold at least one segment; got an empty sequence.")
    for i, c in enumerate(counts):
        if isinstance(c, bool) or not isinstance(c, numbers.Integral) or c <= 0:
            raise InputError(
                f"`counts` must hold positive ints (samples per segment); entry {i} is {c!r}."
            )
    counts = [int(c) for c in counts]
    D = _check_nonneg("segment_duration", segment_duration, [()], strict=True)
    per_segment = D / jnp.asarray(counts, D.dtype)
    return jnp.repeat(per_segment, np.asarray(counts), total_repeat_length=sum(counts))


def sample_times(taus: ArrayLike) -> Float[Array, " N"]:
    r"""Sample times ``t_k = Σ_{j≤k} τ_j`` of a schedule (seconds).

    Consistent with the convention that ``taus[k]`` ends at sample ``k``: the first sample is at
    ``t_0 = τ_0`` (e.g. ``D/n_1`` for :func:`segment_schedule`, whose last sample is then at
    ``S·D``). Subtract ``taus[0]`` for times relative to the first sample.

    **Arguments:**

    - ``taus``: sampling periods, seconds, shape ``(N,)``, finite and > 0.

    **Returns:**

    Sample times, seconds, shape ``(N,)``.
    """
    taus = check_taus("taus", taus)
    check_shape("taus", taus, [(None,)])
    return jnp.cumsum(taus)
