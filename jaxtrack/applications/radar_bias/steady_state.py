"""Sec. 3 steady state: the α-β tracker with a constant measurement bias, closed forms (70)–(105).

These are the paper's analytic results (spec §3.5–3.9), kept as analysis: the transition F̄ (81),
its eigenvalues (82), the steady-state covariances M̄_N (88), M̄_Q (92)–(93), Ṁ (96), the bias
sensitivity D̄ and total covariances (97)–(98), the paper's α-β relation (104)/(105), and the
jointly optimal gain the spec derives (it is the ordinary bias-free steady-state Kalman gain: Λ
cancels). The time-varying recursion these are the limit of is :func:`~.reduced_state.reduced_state_covariance`
(the library's consider filter).
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, Float

from ..._validation import InputError


def _real(x) -> Array:
    """``x`` as a floating array, keeping its precision (Python scalars: the default float)."""
    x = jnp.asarray(x)
    return x.astype(jnp.result_type(x, float))


def alpha_beta_gain(alpha, beta, period) -> Array:
    """``K̄ = [α, β/T]'`` (79), shape ``(2, 1)``; α unitless, β/T in 1/s.

    **Arguments:**

    - ``alpha``, ``beta``: the α-β gains (unitless), scalars.
    - ``period``: the sampling period ``T`` (s), scalar.

    **Returns:** ``K̄``, shape ``(2, 1)``: ``[α, β/T]'`` (unitless, 1/s).
    """
    return jnp.stack([_real(alpha), beta / period])[:, None]


def steady_state_transition(alpha, beta, period) -> Array:
    """``F̄ = (I − K̄H) Φ = [[1−α, (1−α)T], [−β/T, 1−β]]`` (81); ``tr = 2−α−β``, ``det = 1−α``.

    **Arguments:**

    - ``alpha``, ``beta``: the α-β gains (unitless); ``period``: the sampling period ``T`` (s).
      Scalars, or broadcastable arrays ``(...)``.

    **Returns:** ``F̄``, shape ``(2, 2)`` (``(2, 2, ...)`` for broadcast inputs ``(...)``).
    """
    a, b, t = jnp.broadcast_arrays(*(_real(v) for v in (alpha, beta, period)))
    return jnp.stack([jnp.stack([1 - a, (1 - a) * t]), jnp.stack([-b / t, 1 - b])])


def steady_state_eigenvalues(alpha, beta) -> Array:
    """``λ_{1,2} = 1 − (α+β)/2 ± ½ sqrt(α² + 2αβ + β² − 4β)`` (82), complex ``(2,)``.

    **Arguments:**

    - ``alpha``, ``beta``: the α-β gains (unitless), scalars.

    **Returns:** the two eigenvalues of ``F̄``, complex, shape ``(2,)`` (``+`` root first).
    """
    a = _real(alpha)
    b = _real(beta)
    root = jnp.sqrt((a * a + 2 * a * b + b * b - 4 * b).astype(jnp.result_type(a, b, 1j)))
    centre = 1 - (a + b) / 2
    return jnp.stack([centre + root / 2, centre - root / 2])


def noise_covariance_from_measurement(alpha, beta, period, meas_var) -> Array:
    """``M̄_N`` (88), the measurement-noise part of the steady-state filtered covariance, ``(2, 2)``.

    ``N/(α(4−2α−β)) · [[2α² + 2β − 3αβ, β(2α−β)/T], [β(2α−β)/T, 2β²/T²]]``; solves (86).

    **Arguments:**

    - ``alpha``, ``beta``: the α-β gains (unitless), scalars.
    - ``period``: the sampling period ``T`` (s); ``meas_var``: the measurement-noise variance ``N`` (m²).

    **Returns:** ``M̄_N``, shape ``(2, 2)``, in m², m²/s, (m/s)² (position/velocity blocks).
    """
    a, b, t = alpha, beta, period
    c = meas_var / (a * (4 - 2 * a - b))
    off = b * (2 * a - b) / t
    return c * jnp.stack([jnp.stack([2 * a**2 + 2 * b - 3 * a * b, off]), jnp.stack([off, 2 * b**2 / t**2])])


def noise_covariance_from_plant(alpha, beta, period, q22) -> Array:
    """``M̄_Q`` (92)–(93), the plant-noise part of the steady-state filtered covariance, ``(2, 2)``.

    ``q22/(αβ(4−2α−β)) · [[T²(1−α)²(2−α), T(1−α)(2α−α²−β)], [·, 2β(1−α) + α²(2−α)]]``; solves (87).

    **Arguments:**

    - ``alpha``, ``beta``: the α-β gains (unitless), scalars.
    - ``period``: the sampling period ``T`` (s); ``q22``: the plant-noise variance on velocity ((m/s)²).

    **Returns:** ``M̄_Q``, shape ``(2, 2)``, in m², m²/s, (m/s)² (position/velocity blocks).
    """
    a, b, t = alpha, beta, period
    c = q22 / (a * b * (4 - 2 * a - b))
    off = t * (1 - a) * (2 * a - a**2 - b)
    return c * jnp.stack([jnp.stack([t**2 * (1 - a) ** 2 * (2 - a), off]),
                          jnp.stack([off, 2 * b * (1 - a) + a**2 * (2 - a)])])


def lyapunov_system(alpha, beta, period) -> Array:
    """The 3×3 matrix of (89)–(91) acting on ``(m̄11Q, m̄12Q, m̄22Q)``; its determinant is ``αβ(4−2α−β)``.

    **Arguments:**

    - ``alpha``, ``beta``: the α-β gains (unitless), scalars.
    - ``period``: the sampling period ``T`` (s).

    **Returns:** the system matrix, shape ``(3, 3)``.
    """
    a, b, t = alpha, beta, period
    g = (1 - a) ** 2
    return jnp.stack([
        jnp.stack([1 - g, -2 * g * t, -g * t**2]),
        jnp.stack([(1 - a) * b / t, 1 - (1 - a) * (1 - 2 * b), -(1 - a) * (1 - b) * t]),
        jnp.stack([-b**2 / t**2, -2 * b * (b - 1) / t, 1 - (1 - 2 * b + b**2)]),
    ])


def predicted_noise_covariance_terms(alpha, beta, period, meas_var, q22) -> tuple[Array, Array]:
    """Closed forms of ``Φ M̄_N Φ'`` and ``Φ M̄_Q Φ'`` in (96), each ``(2, 2)``.

    **Arguments:**

    - ``alpha``, ``beta``: the α-β gains (unitless), scalars.
    - ``period``: the sampling period ``T`` (s); ``meas_var``: ``N`` (m²); ``q22``: the plant-noise
      variance on velocity ((m/s)²).

    **Returns:** ``(Φ M̄_N Φ', Φ M̄_Q Φ')``, each shape ``(2, 2)``, in m², m²/s, (m/s)².
    """
    a, b, t = alpha, beta, period
    cn = meas_var / (a * (4 - 2 * a - b))
    off_n = b * (2 * a + b) / t
    pmn = cn * jnp.stack([jnp.stack([2 * a**2 + 2 * b + a * b, off_n]), jnp.stack([off_n, 2 * b**2 / t**2])])
    den = -4 * a * b + a * b**2 + 2 * a**2 * b
    off_q = t * (-2 * a - b + a * b + a**2)
    pmq = (q22 / den) * jnp.stack([jnp.stack([t**2 * (-2 + a), off_q]),
                                    jnp.stack([off_q, -2 * b + 2 * a * b - 2 * a**2 + a**3])])
    return pmn, pmq


class SteadyState(eqx.Module):
    """Steady-state α-β quantities (Sec. 3.5–3.7). Bar = filtered (k|k) limit, dot = predicted (k+1|k).

    - ``gain`` ``(2, 1)`` K̄ (79); ``transition`` ``(2, 2)`` F̄ (81).
    - ``noise_cov_measurement`` M̄_N (88); ``noise_cov_plant`` M̄_Q (93); ``filtered_noise_cov`` M̄ (94).
    - ``predicted_noise_cov`` Ṁ (96).
    - ``filtered_sensitivity`` D̄ ``(2, 1)`` = −(F̄−I)⁻¹C̄ (= [−1, 0]'); ``predicted_sensitivity`` Ḋ = F̄ D̄.
    - ``filtered_total_cov`` S̄ = M̄ + D̄ΛD̄'; ``predicted_total_cov`` Ṡ = Ṁ + Φ D̄ Λ D̄' Φ' (97)–(98).
    """

    gain: Float[Array, "2 1"]
    transition: Float[Array, "2 2"]
    noise_cov_measurement: Float[Array, "2 2"]
    noise_cov_plant: Float[Array, "2 2"]
    filtered_noise_cov: Float[Array, "2 2"]
    predicted_noise_cov: Float[Array, "2 2"]
    filtered_sensitivity: Float[Array, "2 1"]
    predicted_sensitivity: Float[Array, "2 1"]
    filtered_total_cov: Float[Array, "2 2"]
    predicted_total_cov: Float[Array, "2 2"]


@jax.jit
def steady_state(alpha, beta, period, meas_var, q22, bias_var=0.0) -> SteadyState:
    """All steady-state closed forms (80)–(98) for gains (α, β), period T (s), N (m²), q22 ((m/s)²), Λ (m²).

    Valid inside the stability triangle ``0 < α < 2``, ``β > 0``, ``4 − 2α − β > 0`` (spec §3.5).

    **Arguments:**

    - ``alpha``, ``beta``: the α-β gains (unitless), scalars.
    - ``period``: the sampling period ``T`` (s); ``meas_var``: the measurement-noise variance ``N`` (m²).
    - ``q22``: the plant-noise variance on velocity ((m/s)²).
    - ``bias_var``: the variance ``Λ`` of the constant measurement bias (m²), default 0.

    **Returns:** a :class:`SteadyState` (``(2, 2)`` covariances, ``(2, 1)`` gain and sensitivities).
    """
    a, b, t, n, q, lam = (_real(v) for v in (alpha, beta, period, meas_var, q22, bias_var))
    gain = alpha_beta_gain(a, b, t)
    f_bar = steady_state_transition(a, b, t)
    phi = jnp.stack([jnp.stack([jnp.ones_like(t), t]), jnp.stack([jnp.zeros_like(t), jnp.ones_like(t)])])
    m_n = noise_covariance_from_measurement(a, b, t, n)
    m_q = noise_covariance_from_plant(a, b, t, q)
    m_bar = m_n + m_q
    pmn, pmq = predicted_noise_covariance_terms(a, b, t, n, q)
    q_mat = jnp.stack([jnp.stack([jnp.zeros_like(q), jnp.zeros_like(q)]), jnp.stack([jnp.zeros_like(q), q])])
    m_dot = pmn + pmq + q_mat  # (96)
    c_bar = -gain  # (83), W = ∂u/∂λ = 1
    d_bar = -jnp.linalg.solve(f_bar - jnp.eye(2, dtype=f_bar.dtype), c_bar)
    d_dot = f_bar @ d_bar
    lam_m = jnp.reshape(lam, (1, 1))
    s_bar = m_bar + d_bar @ lam_m @ d_bar.T
    s_dot = m_dot + (phi @ d_bar) @ lam_m @ (phi @ d_bar).T
    return SteadyState(gain, f_bar, m_n, m_q, m_bar, m_dot, d_bar, d_dot, s_bar, s_dot)


@jax.jit
def gain_condition_residuals(alpha, beta, period, meas_var, q22, bias_var=0.0) -> Array:
    """Residuals of the two steady-state optimality conditions (68) with D̄, ``(2,)``, m².

    ``(G1) α(Ṡ11 + N − Λ) − (Ṡ11 − Λ)`` and ``(G2) β(Ṡ11 + N − Λ) − T Ṡ12`` (spec §3.8, with the
    A20 correction), which equal ``α(Ṁ11+N) − Ṁ11`` and ``β(Ṁ11+N) − TṀ12``: Λ cancels. Both are
    zero only at the jointly optimal gain; the paper's relation (104) only zeroes their ratio.

    **Arguments:**

    - ``alpha``, ``beta``: the α-β gains (unitless), scalars.
    - ``period``: ``T`` (s); ``meas_var``: ``N`` (m²); ``q22``: plant-noise variance on velocity ((m/s)²).
    - ``bias_var``: the bias variance ``Λ`` (m²), default 0.

    **Returns:** ``[G1, G2]``, shape ``(2,)``, m².
    """
    ss = steady_state(alpha, beta, period, meas_var, q22, bias_var)
    s_dot = ss.predicted_total_cov
    lam = bias_var
    g1 = alpha * (s_dot[0, 0] + meas_var - lam) - (s_dot[0, 0] - lam)
    g2 = beta * (s_dot[0, 0] + meas_var - lam) - period * s_dot[0, 1]
    return jnp.stack([g1, g2])


def noise_ratio(period, meas_var, q22) -> Array:
    """``ρ = q22 T² / N`` (unitless), the only parameter of the steady-state gain.

    **Arguments:**

    - ``period``: ``T`` (s); ``meas_var``: ``N`` (m²); ``q22``: plant-noise variance on velocity
      ((m/s)²). Scalars or broadcastable arrays ``(...)``.

    **Returns:** ``ρ``, unitless, the broadcast shape ``(...)``.
    """
    return q22 * period**2 / meas_var


def paper_quartic(beta, alpha, rho) -> Array:
    """The paper's α-β relation (104), a quartic in β:

    ``2β⁴ + (4α−8)β³ + ρ((α²−2α+2)β² + (3α³−10α²+12α−8)β + (2α⁴−8α³+8α²))``.

    It is the *ratio* of the two gain conditions (G1)/(G2), necessary but not sufficient for
    optimality (spec A26, §3.9).

    **Arguments:**

    - ``beta``, ``alpha``: the gains (unitless); ``rho``: the noise ratio ``ρ`` (unitless).
      Scalars or broadcastable arrays ``(...)``.

    **Returns:** the value of (104), the broadcast shape ``(...)``.
    """
    a, b = alpha, beta
    return (2 * b**4 + (4 * a - 8) * b**3
            + rho * ((a**2 - 2 * a + 2) * b**2 + (3 * a**3 - 10 * a**2 + 12 * a - 8) * b + (2 * a**4 - 8 * a**3 + 8 * a**2)))


def paper_quartic_factored(beta, alpha, rho) -> Array:
    """(105): ``(β + 2α − 4)(2β³ + ρ((α²−2α+2)β + α²(α−2)))``, equal to (104).

    **Arguments:**

    - ``beta``, ``alpha``: the gains (unitless); ``rho``: the noise ratio ``ρ`` (unitless).
      Scalars or broadcastable arrays ``(...)``.

    **Returns:** the value of (105), the broadcast shape ``(...)``.
    """
    a, b = alpha, beta
    return (b + 2 * a - 4) * (2 * b**3 + rho * ((a**2 - 2 * a + 2) * b + a**2 * (a - 2)))


@jax.jit
def paper_beta(alpha, rho) -> Array:
    """The ρ-dependent real root of (104): the unique real root of ``2β³ + ρ(aβ + b0) = 0``.

    With ``a = α²−2α+2 > 0`` and ``b0 = α²(α−2) < 0`` for ``0 < α < 2`` the cubic is strictly
    increasing, so Cardano's formula for the depressed cubic ``β³ + pβ + q = 0`` (``p = ρa/2 > 0``)
    gives the single real root; two Newton steps polish it to machine precision. Differentiable.

    **Arguments:**

    - ``alpha``: the position gain, ``0 < α < 2`` (unitless); ``rho``: the noise ratio ``ρ > 0``.
      Scalars or broadcastable arrays ``(...)``.

    **Returns:** ``β`` (unitless), the broadcast shape ``(...)``.
    """
    a_ = _real(alpha)
    r = _real(rho)
    a = a_**2 - 2 * a_ + 2
    b0 = a_**2 * (a_ - 2)
    p, q = r * a / 2, r * b0 / 2
    disc = jnp.sqrt(q**2 / 4 + p**3 / 27)
    beta = jnp.cbrt(-q / 2 + disc) + jnp.cbrt(-q / 2 - disc)
    for _ in range(2):
        beta = beta - (beta**3 + p * beta + q) / (3 * beta**2 + p)
    return beta


def paper_quartic_real_roots(alpha: float, rho: float) -> np.ndarray:
    """The real roots of (104) in β, ascending (host-side ``numpy.roots``; for tables and tests).

    **Arguments:**

    - ``alpha``: the position gain (unitless); ``rho``: the noise ratio ``ρ`` (unitless). Python floats.

    **Returns:** a NumPy array ``(r,)``, ``r ≤ 4``, of the real roots β, ascending.
    """
    a = alpha
    coeffs = [2.0, 4 * a - 8, rho * (a**2 - 2 * a + 2), rho * (3 * a**3 - 10 * a**2 + 12 * a - 8),
              rho * (2 * a**4 - 8 * a**3 + 8 * a**2)]
    roots = np.roots(coeffs)
    return np.sort(roots[np.abs(roots.imag) < 1e-9 * np.maximum(1.0, np.abs(roots))].real)


PAPER_BETA_TABLE: tuple[tuple[float, float, float, float], ...] = (
    # (ρ, α, β printed (ρ-dependent root), second printed root 4 − 2α)
    (2, 0.2, 0.04385, 3.6),
    (4, 0.2, 0.04386, 3.6),  # spec A22: the root is 0.0438767 → 0.04388; a rounding slip
    (6, 0.2, 0.04389, 3.6),
    (6, 0.4, 0.1866, 3.2),
    (8, 0.2, 0.04389, 3.6),
    (8, 0.4, 0.1870, 3.2),
    (10, 0.2, 0.04389, 3.6),
    (10, 0.4, 0.1873, 3.2),
    (10, 0.5, 0.2959, 3.0),
)
"""The paper's table of solutions of (104) (both printed real roots)."""


@jax.jit
def optimal_alpha_beta(rho) -> tuple[Array, Array]:
    """The jointly optimal steady-state gain (spec §3.9 [derived]): ``β = α²/(2−α)``, ``ρ = β²/(1−α)``.

    Closed form: with ``y = sqrt(1−α)`` the two conditions give the palindromic quartic
    ``y⁴ − √ρ y³ − 2y² − √ρ y + 1 = 0``; ``w = y + 1/y`` solves ``w² − √ρ w − 4 = 0``, so
    ``w = (√ρ + sqrt(ρ+16))/2``, ``y = (w − sqrt(w²−4))/2``, ``α = 1 − y²``. This is the
    standard (bias-free) steady-state Kalman gain for ``Q = diag(0, q22)``: Λ does not enter.

    **Arguments:** ``rho`` = q22 T²/N. **Returns:** ``(α*, β*)``.
    """
    r = jnp.sqrt(_real(rho))
    w = (r + jnp.sqrt(r * r + 16.0)) / 2
    # y = (w − sqrt(w² − 4))/2 written as 2/(w + sqrt(w² − 4)) to avoid cancellation at large ρ.
    y = 2.0 / (w + jnp.sqrt(w * w - 4.0))
    alpha = 1.0 - y * y
    return alpha, alpha**2 / (2.0 - alpha)


_OBJECTIVES = ("trace", "position", "velocity")


def steady_state_objective(alpha, beta, period, meas_var, q22, objective: str = "trace") -> Array:
    """``tr M̄``, ``M̄11`` or ``M̄22`` (94) at gains (α, β): the quantities the gain design minimises.

    ``objective`` is ``"trace"``, ``"position"`` (M̄11, m²) or ``"velocity"`` (M̄22, (m/s)²).

    **Arguments:**

    - ``alpha``, ``beta``: the α-β gains (unitless), scalars.
    - ``period``: ``T`` (s); ``meas_var``: ``N`` (m²); ``q22``: plant-noise variance on velocity ((m/s)²).
    - ``objective``: ``"trace"`` (default), ``"position"`` or ``"velocity"``.

    **Returns:** the objective, a scalar (m², (m/s)², or their sum for ``"trace"``).

    **Raises:** ``InputError`` for an unknown ``objective``.
    """
    if objective not in _OBJECTIVES:
        raise InputError(f"`objective` must be one of {_OBJECTIVES}; got {objective!r}.")
    return _objective_by_index(alpha, beta, period, meas_var, q22, _OBJECTIVES.index(objective))


def _objective_by_index(alpha, beta, period, meas_var, q22, index):
    # The objective is an array index, not a static argument, so one compilation serves all three.
    m = steady_state(alpha, beta, period, meas_var, q22).filtered_noise_cov
    return jnp.stack([m[0, 0] + m[1, 1], m[0, 0], m[1, 1]])[index]


def _to_triangle(params):
    # Unconstrained → inside the stability triangle 0 < α < 2, 0 < β < 4 − 2α, so every iterate
    # is a stable filter and the closed forms (88), (93) stay valid.
    alpha = 2.0 * jax.nn.sigmoid(params[0])
    return alpha, (4.0 - 2.0 * alpha) * jax.nn.sigmoid(params[1])


def _from_triangle(alpha, beta):
    a = _real(alpha)
    return jnp.stack([jax.scipy.special.logit(a / 2.0), jax.scipy.special.logit(beta / (4.0 - 2.0 * a))])


class AlphaBetaDescent(eqx.Module):
    """Result of :func:`optimise_alpha_beta`: ``gains`` ``(2,)`` the final (α, β); ``path``
    ``(num_steps + 1, 2)`` the iterates, starting with the initial point."""

    gains: Float[Array, " 2"]
    path: Float[Array, "S 2"]


def optimise_alpha_beta(period, meas_var, q22, *, objective: str = "trace", init=(0.5, 0.3),
                        num_steps: int = 60) -> AlphaBetaDescent:
    """Minimise a steady-state covariance (94) over (α, β) with optax L-BFGS (V22).

    The objective is ``log`` of :func:`steady_state_objective` (scale-free) in unconstrained
    coordinates mapped into the stability triangle. It lands on :func:`optimal_alpha_beta` of
    ``ρ = q22T²/N``, not on the paper's table points.

    **Arguments:** ``period`` T (s), ``meas_var`` N (m²), ``q22`` ((m/s)² per step),
    ``objective`` as in :func:`steady_state_objective`, ``init`` the start (α, β) inside the
    stability triangle, ``num_steps`` the L-BFGS iterations.

    **Returns:** an :class:`AlphaBetaDescent` (final gains and the path).

    **Raises:** :class:`~jaxtrack.InputError` for an unknown objective or an unstable start.
    """
    if objective not in _OBJECTIVES:
        raise InputError(f"`objective` must be one of {_OBJECTIVES}; got {objective!r}.")
    a0, b0 = float(init[0]), float(init[1])
    if not (0 < a0 < 2 and 0 < b0 < 4 - 2 * a0):
        raise InputError(f"`init` = {init} is outside the stability triangle 0 < α < 2, 0 < β < 4 − 2α.")
    period, meas_var, q22 = (_real(v) for v in (period, meas_var, q22))
    dtype = jnp.result_type(period, meas_var, q22)
    gains, path = _optimise_jit(period, meas_var, q22, jnp.asarray(_OBJECTIVES.index(objective)),
                                jnp.asarray([a0, b0], dtype), num_steps)
    return AlphaBetaDescent(gains, path)


@functools.partial(jax.jit, static_argnames="num_steps")
def _optimise_jit(period, meas_var, q22, objective_index, init, num_steps):
    def loss(params):
        return jnp.log(_objective_by_index(*_to_triangle(params), period, meas_var, q22, objective_index))

    opt = optax.lbfgs()
    value_and_grad = optax.value_and_grad_from_state(loss)
    params0 = _from_triangle(init[0], init[1])

    def step(carry, _):
        params, state = carry
        value, grad = value_and_grad(params, state=state)
        updates, state = opt.update(grad, state, params, value=value, grad=grad, value_fn=loss)
        params = optax.apply_updates(params, updates)
        return (params, state), jnp.stack(_to_triangle(params))

    (params, _), path = jax.lax.scan(step, (params0, opt.init(params0)), None, length=num_steps)
    return jnp.stack(_to_triangle(params)), jnp.concatenate([init[None, :], path])




def nonoptimality_table(period: float = 1.0, meas_var: float = 1.0) -> list[dict]:
    """The paper's (ρ, α, β) table points against the jointly optimal gain (spec §3.9).

    For each row: the computed β of (104), the residuals ``G1``, ``G2`` of the two optimality
    conditions (both 0 only at the optimum), (104) itself (0 at the paper's point: it is only their
    ratio), the steady-state position variance M̄11 at the paper's point and at the optimum
    (α*, β*) of the same ρ, in m² for the given T (s) and N (m²), and their ratio.

    **Arguments:**

    - ``period``: the sampling period ``T`` (s), default 1.
    - ``meas_var``: the measurement-noise variance ``N`` (m²), default 1.

    **Returns:** a list of dicts, one per row of ``PAPER_BETA_TABLE``, with keys ``rho``, ``alpha``,
    ``beta_printed``, ``beta``, ``G1``, ``G2``, ``paper_relation_104``, ``alpha_opt``, ``beta_opt``,
    ``position_var_paper``, ``position_var_opt``, ``position_var_ratio`` (Python floats).
    """
    rows = []
    for rho, alpha, beta_printed, _ in PAPER_BETA_TABLE:
        q22 = rho * meas_var / period**2
        beta = float(paper_beta(alpha, rho))
        g1, g2 = (float(v) for v in gain_condition_residuals(alpha, beta, period, meas_var, q22))
        a_s, b_s = (float(v) for v in optimal_alpha_beta(rho))
        m_paper = float(steady_state_objective(alpha, beta, period, meas_var, q22, "position"))
        m_opt = float(steady_state_objective(a_s, b_s, period, meas_var, q22, "position"))
        rows.append(dict(rho=rho, alpha=alpha, beta_printed=beta_printed, beta=beta, G1=g1, G2=g2,
                         paper_relation_104=float(paper_quartic(beta, alpha, rho)),
                         alpha_opt=a_s, beta_opt=b_s, position_var_paper=m_paper,
                         position_var_opt=m_opt, position_var_ratio=m_paper / m_opt))
    return rows
