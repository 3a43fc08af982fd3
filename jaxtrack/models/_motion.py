r"""Motion (transition) model components, and how to compose them per axis or per block.

Each class here is an :class:`~jaxtrack.models.AbstractTransitionModel`: a motion model
``x_k = f_k(x_{k-1}) + w_k``, ``w_k ~ N(0, Q_k)`` that :class:`~jaxtrack.models.TrackingModel`
joins with a sensor model and a prior. Every physical parameter (sample period τ, turn rate ω,
noise intensities) is an array leaf, so ``jax.grad`` with respect to it works through any filter,
and every class supplies its analytic Jacobian.

State layout
------------
As in :mod:`jaxtrack.models._kinematic`, positions come first: ``[x, y(, z), vx, vy(, vz)]``
(Stone Soup orders ``[x, vx, y, vy, …]``; a permutation maps one to the other).

Components
----------
- :class:`LinearTransition` — any ``F``, ``Q`` (constant or per step).
- :class:`ConstantVelocity`, :class:`ConstantAcceleration` — white-noise acceleration / jerk
  (the 1-D blocks of :func:`~jaxtrack.models.constant_velocity`), 1–3 axes.
- :class:`CoordinatedTurn` — known turn rate ω, 2-D ``[x, y, vx, vy]`` or 3-D
  ``[x, y, z, vx, vy, vz]`` (horizontal turn, nearly constant velocity in z).
- :class:`NearlyConstantTurn` — the turn rate is a state: ``[x, y, vx, vy, ω]``.

The turn models evaluate ``sin(ωτ)/ω`` and ``(1 − cos ωτ)/ω`` through a Taylor series for
``|ωτ| < 0.5`` and the closed form elsewhere, with the "double where" (the closed form is fed a
harmless argument on the series side), so that at ω = 0 their value, their gradient with respect
to ω and their ∂/∂ω Jacobian column are finite and equal to the constant-velocity limit.

Composition
-----------
:class:`BlockTransition` combines components acting on disjoint sub-vectors of the state into one
block-diagonal model: the mean and the Jacobian are computed block by block and ``Q`` is block
diagonal. Without ``order`` the blocks act on consecutive sub-vectors; ``order`` (a permutation of
``0 … n−1``) says which state components form the concatenated block vector
``u = x[order]``. Examples::

    # 3-D target: a horizontal turn on (x, y, vx, vy) and CV on (z, vz), state [x, y, z, vx, vy, vz]
    BlockTransition(
        [CoordinatedTurn(1.0, turn_rate=0.05, noise_intensity=0.1),
         ConstantVelocity(1.0, noise_intensity=0.01, dim=1)],
        order=(0, 1, 3, 4, 2, 5),
    )

    # per-axis CV blocks [p, v] with different intensities, state stored [x, y, vx, vy]
    BlockTransition.per_axis([ConstantVelocity(1.0, noise_intensity=0.5, dim=1),
                              ConstantVelocity(1.0, noise_intensity=2.0, dim=1)])
    # = BlockTransition([...], order=(0, 2, 1, 3))

References: Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and
Navigation* (2001), §6.2 (CWNA/Wiener models) and §11.7 (coordinated turn with the turn rate in
the state); Li & Jilkov, "Survey of maneuvering target tracking. Part I: dynamic models", IEEE
TAES 39(4), 2003, §V.A (coordinated-turn model, known and unknown turn rate).
"""

from __future__ import annotations

import abc
import math
import numbers
from collections.abc import Sequence
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jax.scipy.linalg import block_diag
from jaxtyping import Array, ArrayLike, Float, Int

from .._deprecation import keyword_args
from .._validation import InputError, check_covariance, check_finite, check_shape
from ._base import _num_steps_of, affine_in_state, at_step
from ._components import AbstractTransitionModel
from ._discretize import check_taus
from ._kinematic import _ca_blocks, _check_nonneg, _cv_blocks, _kron_diag
from ._layout import TURN_RATE, check_layout, kinematic_layout, num_axes, shift_axes

# helpers ------------------------------------------------------------------------------------


def _check_dim(dim, allowed=(1, 2, 3)) -> int:
    if isinstance(dim, bool) or not isinstance(dim, numbers.Integral) or int(dim) not in allowed:
        raise InputError(f"`dim` must be one of {allowed} (spatial dimensions); got {dim!r}.")
    return int(dim)


def _per_axis(name: str, x, dim: int) -> Array:
    """A non-negative intensity, scalar or per axis ``(dim,)``, broadcast to ``(dim,)``."""
    return jnp.broadcast_to(_check_nonneg(name, x, [(), (dim,)], strict=False), (dim,))


def _steps(**arrays) -> int | None:
    """Common ``T`` of the per-step ``(T,)`` parameters (``InputError`` naming them if they differ)."""
    return _num_steps_of(**{name: (a, 0) for name, a in arrays.items()})


# Series of the four turn functions in θ = ωτ, used for |θ| < _SERIES_CUT. Nine terms: at |θ| = 0.5
# the first omitted term is below 1e-22 relative, and on the closed-form side (|θ| ≥ 0.5) the
# cancellation in cos θ − sin θ/θ costs at most a factor ~10 of the unit round-off.
_SERIES_CUT = 0.5
_NUM_TERMS = 9
_F = math.factorial
# Coefficients in powers of θ² (lowest first); "odd" series carry one extra factor θ.
_S1 = [(-1) ** j / _F(2 * j + 1) for j in range(_NUM_TERMS)]  # sin θ / θ
_C1 = [(-1) ** j / _F(2 * j + 2) for j in range(_NUM_TERMS)]  # (1 − cos θ)/θ  (odd)
_DS1 = [(-1) ** (j + 1) * (2 * j + 2) / _F(2 * j + 3) for j in range(_NUM_TERMS)]  # d/dθ sinθ/θ (odd)
_DC1 = [(-1) ** j * (2 * j + 1) / _F(2 * j + 2) for j in range(_NUM_TERMS)]  # d/dθ (1−cosθ)/θ


def _series_or_closed(theta, coeffs, odd, closed):
    """``closed(θ)`` for ``|θ| ≥ 0.5``, the Taylor polynomial otherwise (double-where).

    The closed form is evaluated at θ = 1 on the series side so that neither it nor its
    derivative (which ``jnp.where`` still differentiates) produces 0/0 at θ = 0.
    """
    small = jnp.abs(theta) < _SERIES_CUT
    safe = jnp.where(small, jnp.ones_like(theta), theta)
    t2 = theta * theta
    poly = jnp.zeros_like(theta)
    for c in reversed(coeffs):  # Horner in θ²
        poly = poly * t2 + c
    if odd:
        poly = poly * theta
    return jnp.where(small, poly, closed(safe))


def _sinc(theta):
    """``sin θ / θ`` (→ 1 at 0)."""
    return _series_or_closed(theta, _S1, False, lambda t: jnp.sin(t) / t)


def _cosc(theta):
    """``(1 − cos θ)/θ`` (→ 0 at 0); closed form ``2 sin²(θ/2)/θ`` avoids the cancellation."""
    return _series_or_closed(theta, _C1, True, lambda t: 2 * jnp.sin(t / 2) ** 2 / t)


def _dsinc(theta):
    """``d/dθ (sin θ/θ) = (cos θ − sin θ/θ)/θ`` (→ −θ/3 at 0)."""
    return _series_or_closed(theta, _DS1, True, lambda t: (jnp.cos(t) - jnp.sin(t) / t) / t)


def _dcosc(theta):
    """``d/dθ ((1 − cos θ)/θ) = (sin θ − (1 − cos θ)/θ)/θ`` (→ 1/2 at 0)."""
    return _series_or_closed(
        theta, _DC1, False, lambda t: (jnp.sin(t) - 2 * jnp.sin(t / 2) ** 2 / t) / t
    )


def _turn_block(omega, tau):
    r"""The 4×4 coordinated-turn matrix on ``[x, y, vx, vy]`` (Li & Jilkov 2003, §V.A).

    .. math::

        F = \begin{bmatrix} I_2 & A \\ 0 & R(ωτ) \end{bmatrix},\quad
        A = \begin{bmatrix} \sin ωτ/ω & -(1-\cos ωτ)/ω \\ (1-\cos ωτ)/ω & \sin ωτ/ω \end{bmatrix},

    ``R(θ)`` the active rotation by +θ (``geometry.rotation_z``'s convention): ω > 0 turns the
    velocity counter-clockwise. ``A = ∫_0^τ R(ωs) ds``; at ω = 0 it is ``τ I`` (constant velocity).
    """
    theta = omega * tau
    a = tau * _sinc(theta)
    b = tau * _cosc(theta)
    c, s = jnp.cos(theta), jnp.sin(theta)
    one, zero = jnp.ones_like(theta), jnp.zeros_like(theta)
    return jnp.stack(
        [
            jnp.stack([one, zero, a, -b]),
            jnp.stack([zero, one, b, a]),
            jnp.stack([zero, zero, c, -s]),
            jnp.stack([zero, zero, s, c]),
        ]
    )


def _check_turn_rate(name, omega) -> Array:
    omega = jnp.asarray(omega)
    omega = omega.astype(jnp.result_type(omega, float))
    check_shape(name, omega, [(), (None,)])
    check_finite(name, omega)
    return omega


def _cast(x, *params):
    """``x`` and ``params`` in their common floating dtype (follow the inputs, never force f64)."""
    dtype = jnp.result_type(x, *params, float)
    return jnp.asarray(x, dtype), [jnp.asarray(p, dtype) for p in params]


# linear components --------------------------------------------------------------------------


class LinearTransition(AbstractTransitionModel):
    """A linear motion model ``x_k = F_k x_{k-1} + w_k``, ``w_k ~ N(0, Q_k)``.

    **Arguments:**

    - ``transition_matrix``: ``F``, shape ``(n, n)`` or per step ``(T, n, n)`` (``F[k]`` ends at
      step ``k``).
    - ``process_noise_cov``: ``Q``, shape ``(n, n)`` or ``(T, n, n)``, symmetric positive
      semidefinite, in the state's units squared.
    - ``state_layout``: optional names of the ``n`` state components (keyword), e.g.
      ``("x", "y", "vx", "vy")`` (:mod:`jaxtrack.models._layout`); sensors and IMM members are
      checked against it. None: not declared, nothing checked.

    **Raises:** ``InputError`` naming the argument on a wrong shape, non-finite ``F`` or a ``Q``
    that is not a covariance, a disagreeing number of steps, or a ``state_layout`` that does not
    name ``n`` distinct components.
    """

    F: Float[Array, "*T n n"]
    Q: Float[Array, "*T n n"]
    _layout: tuple[str, ...] | None = eqx.field(static=True, default=None)

    def __init__(self, transition_matrix: ArrayLike, process_noise_cov: ArrayLike, *,
                 state_layout: Sequence | None = None):
        F, Q = jnp.asarray(transition_matrix), jnp.asarray(process_noise_cov)
        dtype = jnp.result_type(F, Q, float)
        F, Q = F.astype(dtype), Q.astype(dtype)
        check_shape("transition_matrix", F, [(None, None), (None, None, None)])
        n = F.shape[-1]
        check_shape("transition_matrix", F, [(n, n), (None, n, n)])
        check_shape("process_noise_cov", Q, [(n, n), (None, n, n)])
        check_finite("transition_matrix", F)
        check_covariance("process_noise_cov", Q, definite=False)
        _num_steps_of(transition_matrix=(F, 2), process_noise_cov=(Q, 2))
        self.F, self.Q = F, Q
        self._layout = check_layout("state_layout", state_layout, n)

    @property
    def state_dim(self) -> int:
        return self.F.shape[-1]

    @property
    def state_layout(self) -> tuple[str, ...] | None:
        return self._layout

    @property
    def num_steps(self) -> int | None:
        return _num_steps_of(transition_matrix=(self.F, 2), process_noise_cov=(self.Q, 2))

    def transition_matrix(self, k: Int[ArrayLike, ""]) -> Float[Array, "n n"]:
        """``F_k``."""
        return at_step(self.F, k, 2)

    @affine_in_state
    def mean(self, x, k):
        return self.transition_matrix(k) @ x

    def jacobian(self, x, k):
        return self.transition_matrix(k)

    def noise_cov(self, k):
        return at_step(self.Q, k, 2)


class _AbstractKinematic(AbstractTransitionModel):
    """Shared body of the polynomial (CV/CA) components: ``F = F_1d(τ) ⊗ I_d``, ``Q = Q_1d(τ) ⊗ diag(q)``."""

    # The fields and constructor are shared: the subclasses differ only in their 1-D blocks.
    sample_period: Float[Array, "*T"]
    noise_intensity: Float[Array, " d"]
    dim: int = eqx.field(static=True)
    _order: ClassVar[int]  # states per axis: 2 (p, v) or 3 (p, v, a)

    def __init__(self, sample_period: ArrayLike, *args, noise_intensity: ArrayLike | None = None, dim: int = 2):
        a = keyword_args(type(self).__name__, sample_period, args, ("sample_period", "noise_intensity"),
                          {"noise_intensity": noise_intensity})
        self.dim = _check_dim(dim)
        self.sample_period = check_taus("sample_period", a["sample_period"])
        self.noise_intensity = _per_axis("noise_intensity", a["noise_intensity"], self.dim)

    @abc.abstractmethod
    def _blocks(self, tau):
        """The 1-D ``(F_1d, Q_1d / q)`` of period ``tau``."""

    @property
    def num_steps(self) -> int | None:
        return _steps(sample_period=self.sample_period)

    @property
    def state_dim(self) -> int:
        return self._order * self.dim

    @property
    def state_layout(self) -> tuple[str, ...]:
        """``[positions…, velocities…(, accelerations…)]``, e.g. ``("x", "y", "vx", "vy")``."""
        return kinematic_layout(self.dim, self._order)

    def transition_matrix(self, k: Int[ArrayLike, ""]) -> Float[Array, "n n"]:
        """``F_k = F_1d(τ_k) ⊗ I_d``."""
        F1, _ = self._blocks(at_step(self.sample_period, k, 0))
        return _kron_diag(F1, jnp.ones((self.dim,), F1.dtype))

    @affine_in_state
    def mean(self, x, k):
        return self.transition_matrix(k) @ x

    def jacobian(self, x, k):
        return self.transition_matrix(k)

    def noise_cov(self, k):
        _, Q1 = self._blocks(at_step(self.sample_period, k, 0))
        return _kron_diag(Q1, self.noise_intensity.astype(Q1.dtype))


class ConstantVelocity(_AbstractKinematic):
    r"""Constant velocity driven by continuous white-noise acceleration (CWNA), ``dim`` axes.

    Per axis ``p̈ = w(t)``, ``E[w(t)w(s)] = q δ(t−s)``; exactly discretised over τ
    (Bar-Shalom, Li & Kirubarajan 2001, §6.2.2):
    ``F_1d = [[1, τ], [0, 1]]``, ``Q_1d = q [[τ³/3, τ²/2], [τ²/2, τ]]``; in ``dim`` axes
    ``F = F_1d ⊗ I_d``, ``Q = Q_1d ⊗ diag(q)``, state ``[positions…, velocities…]`` — the blocks of
    :func:`~jaxtrack.models.constant_velocity`. With ``dim=1`` it is the ``[p, v]`` block used for
    per-axis composition (:meth:`BlockTransition.per_axis`).

    **Arguments:**

    - ``sample_period``: τ, seconds, shape ``()`` or per step ``(T,)``, > 0.
    - ``noise_intensity`` (keyword): ``q``, m²/s³, shape ``()`` or per axis ``(dim,)``, ≥ 0.
    - ``dim``: number of axes, 1, 2 or 3 (keyword).

    **Raises:** ``InputError`` naming ``sample_period``, ``noise_intensity`` or ``dim``.
    """

    _order: ClassVar[int] = 2

    def _blocks(self, tau):
        return _cv_blocks(tau)


class ConstantAcceleration(_AbstractKinematic):
    r"""Constant acceleration driven by continuous white-noise jerk (Wiener acceleration).

    Per axis ``p⃛ = w(t)`` with intensity ``q`` (Bar-Shalom, Li & Kirubarajan 2001, §6.2.3):
    ``F_1d = [[1, τ, τ²/2], [0, 1, τ], [0, 0, 1]]``,
    ``Q_1d = q [[τ⁵/20, τ⁴/8, τ³/6], [τ⁴/8, τ³/3, τ²/2], [τ³/6, τ²/2, τ]]``; state
    ``[positions…, velocities…, accelerations…]`` (the blocks of
    :func:`~jaxtrack.models.constant_acceleration`).

    **Arguments:**

    - ``sample_period``: τ, seconds, shape ``()`` or ``(T,)``, > 0.
    - ``noise_intensity`` (keyword): ``q``, m²/s⁵, shape ``()`` or ``(dim,)``, ≥ 0.
    - ``dim``: number of axes, 1, 2 or 3 (keyword).

    **Raises:** ``InputError`` naming ``sample_period``, ``noise_intensity`` or ``dim``.
    """

    _order: ClassVar[int] = 3

    def _blocks(self, tau):
        return _ca_blocks(tau)


# turn models --------------------------------------------------------------------------------


class CoordinatedTurn(AbstractTransitionModel):
    r"""Coordinated turn with a KNOWN turn rate ω (2-D, or 3-D with a horizontal turn).

    The velocity rotates at the constant rate ω in the x–y plane
    (``ẋ = vx, ẏ = vy, v̇x = −ω vy, v̇y = ω vx``); the exact discretisation over τ is
    (Li & Jilkov 2003, §V.A; Bar-Shalom, Li & Kirubarajan 2001, §11.7)

    .. math::

        \begin{bmatrix} x \\ y \\ v_x \\ v_y \end{bmatrix}_k =
        \begin{bmatrix}
        1 & 0 & \frac{\sin ωτ}{ω} & -\frac{1-\cos ωτ}{ω} \\
        0 & 1 & \frac{1-\cos ωτ}{ω} & \frac{\sin ωτ}{ω} \\
        0 & 0 & \cos ωτ & -\sin ωτ \\
        0 & 0 & \sin ωτ & \cos ωτ
        \end{bmatrix}
        \begin{bmatrix} x \\ y \\ v_x \\ v_y \end{bmatrix}_{k-1} + w_k,

    ω > 0 counter-clockwise (the active rotation of ``geometry.rotation_z``), ω in rad/s. At
    ω = 0 this is constant velocity; value and ∂/∂ω there are the series limits (module docstring).

    The plant noise is white acceleration of intensity ``q_i`` on each axis with the turn
    neglected in the noise: ``Q = Q_1d(τ) ⊗ diag(q)``, ``Q_1d = [[τ³/3, τ²/2], [τ²/2, τ]]``. This is
    the ``Q`` of Stone Soup's ``KnownTurnRate`` (there in ``[x, vx, y, vy]`` order) and of the
    per-axis CWNA model; it is exact for ω = 0.

    With ``dim=3`` the state is ``[x, y, z, vx, vy, vz]`` and z moves with nearly constant
    velocity (``q_z`` its intensity) — the same as :class:`BlockTransition` of a 2-D
    ``CoordinatedTurn`` and ``ConstantVelocity(dim=1)`` with ``order=(0, 1, 3, 4, 2, 5)``.

    **Arguments:**

    - ``sample_period``: τ, seconds, shape ``()`` or ``(T,)``, > 0 (the one positional argument).
    - ``turn_rate`` (keyword): ω, rad/s, shape ``()`` or per step ``(T,)``, finite, any sign.
    - ``noise_intensity`` (keyword): ``q``, m²/s³, shape ``()`` or per axis ``(dim,)``, ≥ 0.
    - ``dim``: 2 or 3 (keyword).

    **Raises:** ``InputError`` naming the argument (negative τ or ``q``, wrong shapes, ``dim``,
    or ``turn_rate`` and ``sample_period`` of different lengths).
    """

    turn_rate: Float[Array, "*T"]
    sample_period: Float[Array, "*T"]
    noise_intensity: Float[Array, " d"]
    dim: int = eqx.field(static=True)

    def __init__(
        self, sample_period: ArrayLike, *args, turn_rate: ArrayLike | None = None,
        noise_intensity: ArrayLike | None = None, dim: int = 2,
    ):
        # Deprecated positional form: the old order put the turn rate first.
        a = keyword_args("CoordinatedTurn", sample_period, args, ("turn_rate", "sample_period", "noise_intensity"),
                          {"turn_rate": turn_rate, "noise_intensity": noise_intensity})
        self.dim = _check_dim(dim, (2, 3))
        self.turn_rate = _check_turn_rate("turn_rate", a["turn_rate"])
        self.sample_period = check_taus("sample_period", a["sample_period"])
        self.noise_intensity = _per_axis("noise_intensity", a["noise_intensity"], self.dim)
        _steps(turn_rate=self.turn_rate, sample_period=self.sample_period)

    @property
    def state_dim(self) -> int:
        return 2 * self.dim

    @property
    def state_layout(self) -> tuple[str, ...]:
        """``("x", "y", "vx", "vy")`` or ``("x", "y", "z", "vx", "vy", "vz")``."""
        return kinematic_layout(self.dim, 2)

    @property
    def num_steps(self) -> int | None:
        return _steps(turn_rate=self.turn_rate, sample_period=self.sample_period)

    def transition_matrix(self, k: Int[ArrayLike, ""]) -> Float[Array, "n n"]:
        """``F_k = F(ω_k, τ_k)``, shape ``(2·dim, 2·dim)``."""
        omega = at_step(self.turn_rate, k, 0)
        tau = at_step(self.sample_period, k, 0)
        dtype = jnp.result_type(omega, tau)
        omega, tau = omega.astype(dtype), tau.astype(dtype)
        F4 = _turn_block(omega, tau)
        if self.dim == 2:
            return F4
        # 3-D: horizontal turn on (x, y, vx, vy) = indices (0, 1, 3, 4), CV on (z, vz) = (2, 5).
        F1, _ = _cv_blocks(tau)
        F = jnp.zeros((6, 6), F4.dtype)
        h, v = np.array([0, 1, 3, 4]), np.array([2, 5])
        F = F.at[np.ix_(h, h)].set(F4)
        return F.at[np.ix_(v, v)].set(F1)

    @affine_in_state
    def mean(self, x, k):
        return self.transition_matrix(k) @ x

    def jacobian(self, x, k):
        return self.transition_matrix(k)

    def noise_cov(self, k):
        _, Q1 = _cv_blocks(at_step(self.sample_period, k, 0))
        return _kron_diag(Q1, self.noise_intensity.astype(Q1.dtype))


class NearlyConstantTurn(AbstractTransitionModel):
    r"""Nearly-constant turn with the turn rate in the state: ``x = [x, y, vx, vy, ω]``.

    The coordinated-turn motion of :class:`CoordinatedTurn` with ω augmented to the state and
    driven by a random walk (Bar-Shalom, Li & Kirubarajan 2001, §11.7; Li & Jilkov 2003, §V.A, the
    CT model with unknown turn rate). With ``θ = ωτ``, ``a = sin θ/ω``, ``b = (1 − cos θ)/ω``:

    .. math::

        f(x) = [\,x + a v_x - b v_y,\; y + b v_x + a v_y,\;
                 v_x\cos θ - v_y \sin θ,\; v_x \sin θ + v_y \cos θ,\; ω\,].

    The Jacobian is ``[[F_CT(ω), ∂f/∂ω], [0, 1]]`` with
    ``∂a/∂ω = τ² s'(θ)``, ``∂b/∂ω = τ² c'(θ)`` (``s(θ) = sin θ/θ``, ``c(θ) = (1 − cos θ)/θ``):

    .. math::

        \frac{∂f}{∂ω} = [\,τ^2(s' v_x - c' v_y),\; τ^2(c' v_x + s' v_y),\;
        -τ(v_x \sin θ + v_y \cos θ),\; τ(v_x\cos θ - v_y \sin θ),\; 1\,],

    whose ω → 0 limit (``s' → 0``, ``c' → 1/2``) is ``[−τ² v_y/2, τ² v_x/2, −τ v_y, τ v_x, 1]``;
    all four turn functions go through the series/double-where evaluation, so the Jacobian and its
    derivatives are finite at ω = 0.

    Plant noise: white acceleration of intensity ``q_x, q_y`` per axis (the turn neglected in the
    noise, as :class:`CoordinatedTurn`) and a Wiener turn rate of intensity ``q_ω``:
    ``Q = blockdiag(Q_1d(τ) ⊗ diag(q_x, q_y), q_ω τ)`` — the ``Q`` of Stone Soup's nonlinear
    ``ConstantTurn`` (there ordered ``[x, vx, y, vy, ω]``).

    **Arguments:**

    - ``sample_period``: τ, seconds, shape ``()`` or per step ``(T,)``, > 0.
    - ``noise_intensity`` (keyword): ``q``, m²/s³, shape ``()`` or per axis ``(2,)``, ≥ 0.
    - ``turn_rate_intensity`` (keyword): ``q_ω``, rad²/s³, shape ``()``, ≥ 0.

    **Raises:** ``InputError`` naming the argument.
    """

    sample_period: Float[Array, "*T"]
    noise_intensity: Float[Array, " 2"]
    turn_rate_intensity: Float[Array, ""]

    def __init__(self, sample_period: ArrayLike, *args, noise_intensity: ArrayLike | None = None,
                 turn_rate_intensity: ArrayLike | None = None):
        a = keyword_args("NearlyConstantTurn", sample_period, args,
                          ("sample_period", "noise_intensity", "turn_rate_intensity"),
                          {"noise_intensity": noise_intensity, "turn_rate_intensity": turn_rate_intensity})
        self.sample_period = check_taus("sample_period", a["sample_period"])
        self.noise_intensity = _per_axis("noise_intensity", a["noise_intensity"], 2)
        self.turn_rate_intensity = _check_nonneg("turn_rate_intensity", a["turn_rate_intensity"], [()], strict=False)

    @property
    def state_dim(self) -> int:
        return 5

    @property
    def state_layout(self) -> tuple[str, ...]:
        """``("x", "y", "vx", "vy", "omega")``."""
        return kinematic_layout(2, 2) + (TURN_RATE,)

    @property
    def num_steps(self) -> int | None:
        return _steps(sample_period=self.sample_period)

    def mean(self, x, k):
        x, (tau,) = _cast(x, at_step(self.sample_period, k, 0))
        omega = x[4]
        F4 = _turn_block(omega, tau)
        return jnp.concatenate([F4 @ x[:4], x[4:]])

    def jacobian(self, x, k):
        x, (tau,) = _cast(x, at_step(self.sample_period, k, 0))
        px, py, vx, vy, omega = x[0], x[1], x[2], x[3], x[4]
        del px, py
        theta = omega * tau
        ds, dc = _dsinc(theta), _dcosc(theta)
        c, s = jnp.cos(theta), jnp.sin(theta)
        d_omega = jnp.stack(
            [
                tau**2 * (ds * vx - dc * vy),
                tau**2 * (dc * vx + ds * vy),
                -tau * (vx * s + vy * c),
                tau * (vx * c - vy * s),
                jnp.ones_like(theta),
            ]
        )
        J = jnp.zeros((5, 5), x.dtype)
        J = J.at[:4, :4].set(_turn_block(omega, tau))
        return J.at[:, 4].set(d_omega)

    def noise_cov(self, k):
        tau = at_step(self.sample_period, k, 0)
        _, Q1 = _cv_blocks(tau)
        dtype = jnp.result_type(Q1, self.noise_intensity, self.turn_rate_intensity)
        Q = jnp.zeros((5, 5), dtype)
        Q = Q.at[:4, :4].set(_kron_diag(Q1, self.noise_intensity.astype(dtype)))
        return Q.at[4, 4].set(self.turn_rate_intensity * tau)


# composition --------------------------------------------------------------------------------


class BlockTransition(AbstractTransitionModel):
    r"""Block-diagonal composition of motion models on disjoint sub-vectors of the state.

    With ``u = x[order]`` split into consecutive pieces ``u_1, …, u_B`` of the blocks' sizes,

    .. math::

        f(x)[\text{order}] = [f_1(u_1); …; f_B(u_B)],\qquad
        J[\text{order}][:, \text{order}] = \mathrm{blockdiag}(J_1, …, J_B),\qquad
        Q[\text{order}][:, \text{order}] = \mathrm{blockdiag}(Q_1, …, Q_B),

    i.e. the blocks are independent motions with independent plant noise. See the module
    docstring for examples (3-D coordinated turn, per-axis CV with different intensities).

    **Arguments:**

    - ``blocks``: a non-empty sequence of :class:`~jaxtrack.models.AbstractTransitionModel`.
    - ``order``: optional permutation of ``0 … n−1`` (``n`` the sum of the blocks' state sizes):
      ``order[i]`` is the index in the full state of component ``i`` of the concatenated block
      vector. ``None``: the blocks act on consecutive sub-vectors in the given order.

    **Raises:** ``InputError`` naming ``blocks`` (not transition models, empty, or disagreeing
    numbers of steps) or ``order`` (not a permutation of ``0 … n−1``).
    """

    blocks: tuple[AbstractTransitionModel, ...]
    order: tuple[int, ...] | None = eqx.field(static=True)

    def __init__(self, blocks: Sequence, order: Sequence | None = None):
        blocks = tuple(blocks) if isinstance(blocks, (list, tuple)) else None
        if not blocks:
            raise InputError("`blocks` must be a non-empty list or tuple of transition models.")
        for i, b in enumerate(blocks):
            if not isinstance(b, AbstractTransitionModel):
                raise InputError(
                    f"`blocks` entry {i} must be a jaxtrack transition model (AbstractTransitionModel); "
                    f"got {type(b).__name__}."
                )
        n = sum(b.state_dim for b in blocks)
        if order is not None:
            try:
                idx = [int(i) for i in order]
                integral = all(isinstance(i, numbers.Integral) and not isinstance(i, bool) for i in order)
            except (TypeError, ValueError):
                idx, integral = None, False
            if not integral or sorted(idx) != list(range(n)):
                raise InputError(
                    f"`order` must be a permutation of 0 … {n - 1} (one index per state component of "
                    f"the {len(blocks)} blocks, which have {n} states in all); got {order!r}."
                )
            order = None if idx == list(range(n)) else tuple(idx)
        self.blocks = blocks
        self.order = order
        _ = self.num_steps  # raises on disagreeing per-step lengths

    @classmethod
    def per_axis(cls, blocks: Sequence[AbstractTransitionModel]) -> BlockTransition:
        """One block per axis, the state stored derivative-major ``[p_1..p_d, v_1..v_d, …]``.

        Every block has the same size ``k`` (e.g. ``ConstantVelocity(dim=1)``: ``[p, v]``); block
        ``i`` acts on axis ``i``, so its component ``j`` is state index ``j·d + i``.

        **Arguments:** ``blocks``: ``d`` transition models of equal state size ``k``.

        **Returns:** a :class:`BlockTransition` with ``n = d·k`` states.

        **Raises:** ``InputError`` naming ``blocks`` if the sizes differ.
        """
        blocks = tuple(blocks) if isinstance(blocks, (list, tuple)) else ()
        if blocks and all(isinstance(b, AbstractTransitionModel) for b in blocks):
            sizes = {b.state_dim for b in blocks}
            if len(sizes) != 1:
                raise InputError(f"`blocks` must all have the same state size for per-axis use; got {sorted(sizes)}.")
            d, k = len(blocks), sizes.pop()
            return cls(blocks, order=tuple(j * d + i for i in range(d) for j in range(k)))
        return cls(blocks)

    @property
    def state_dim(self) -> int:
        return sum(b.state_dim for b in self.blocks)

    @property
    def state_layout(self) -> tuple[str, ...] | None:
        """The blocks' layouts, each block's axes after the previous blocks' (None if one is unknown):
        a 2-D turn then ``ConstantVelocity(dim=1)`` gives the latter's ``x``, ``vx`` as ``z``, ``vz``;
        ``order`` places the concatenated components."""
        u, offset = [], 0
        for b in self.blocks:
            lay = b.state_layout
            lay = None if lay is None else shift_axes(lay, offset)
            if lay is None:
                return None
            u.extend(lay)
            offset += num_axes(b.state_layout)
        if len(set(u)) != len(u):
            return None  # two blocks name the same component: not a layout we can interpret
        if self.order is None:
            return tuple(u)
        out = [""] * len(u)
        for i, j in enumerate(self.order):  # u[i] = x[order[i]]
            out[j] = u[i]
        return tuple(out)

    @property
    def num_steps(self) -> int | None:
        steps = {b.num_steps for b in self.blocks if b.num_steps is not None}
        if len(steps) > 1:
            raise InputError(f"`blocks` disagree on the number of steps: {sorted(steps)}.")
        return next(iter(steps), None)

    def _split(self, x):
        u = x if self.order is None else x[np.asarray(self.order)]
        out, start = [], 0
        for b in self.blocks:
            out.append(u[start : start + b.state_dim])
            start += b.state_dim
        return out

    def _inverse(self):
        return np.argsort(np.asarray(self.order))

    def _unpermute_vector(self, u):
        return u if self.order is None else u[self._inverse()]

    def _unpermute_matrix(self, M):
        if self.order is None:
            return M
        inv = self._inverse()
        return M[np.ix_(inv, inv)]

    def mean(self, x, k):
        parts = [b.mean(u, k) for b, u in zip(self.blocks, self._split(x))]
        return self._unpermute_vector(jnp.concatenate(parts))

    def jacobian(self, x, k):
        parts = [b.jacobian(u, k) for b, u in zip(self.blocks, self._split(x))]
        return self._unpermute_matrix(block_diag(*parts))

    def noise_cov(self, k):
        return self._unpermute_matrix(block_diag(*[b.noise_cov(k) for b in self.blocks]))
