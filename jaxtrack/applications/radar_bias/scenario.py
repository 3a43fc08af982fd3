"""The study's scenarios: the paper's Sec. 2 examples a–d and the Sec. 3 bias models.

- :data:`EXAMPLES`, :func:`example_inputs`, :func:`solve_example`, :func:`cost_discrepancy_table`:
  the four absolute-bias examples of §2.3 (spec §2.5);
- :func:`reduced_state_model`: the Sec. 3 plant with a random constant measurement bias as a
  :class:`~jaxtrack.models.LinearGaussianModel` of ``[x; λ]`` for the library's
  :class:`~jaxtrack.filters.ConsiderKalmanFilter` (the bias is considered, not estimated);
- :func:`alpha_beta_bias_model` (eqs 70–76) and :func:`general_scenario` (spec §4, V23–V26).

Sign convention (§3): measured = true + bias, ``z = H x + n + W u(x, λ)``.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..._validation import InputError, check_covariance, check_finite, check_shape
from ...filters import consider_model
from ...models import LinearGaussianModel
from .absolute import AbsoluteBias, SensorGeometry, absolute_bias, printed_cost

# -- The paper's examples (§2.3.1–2.3.4; spec §2.5) ------------------------------------------

_P1, _P2 = 25000.0, 50000.0
_EXAMPLE_WEIGHTS = (2.0, 2 * _P1**2, 2 * _P1**2, 2.0, 2 * _P2**2, 2 * _P2**2)  # spec A11: squares


class PaperExample(eqx.Module):
    """One of the paper's §2.3 examples: inputs and printed outputs.

    ``relative_bias`` B_R (m, ENU); ``azimuth2``, ``elevation2`` sensor 2's line of sight (rad);
    ``printed_e`` the six printed biases ``(Δr1, Δψ1, Δθ1, Δr2, Δψ2, Δθ2)``; ``printed_cost``.
    """

    relative_bias: tuple[float, float, float]
    azimuth2: float
    elevation2: float
    printed_e: tuple[float, ...]
    printed_cost: float


EXAMPLES: dict[str, PaperExample] = {
    "a": PaperExample((200.0, 500.0, 300.0), 0.0, 3 * np.pi / 4,
                      (-1.7678e2, -1.0000e-2, -1.4142e-3, 3.5355e1, 5.0000e-3, -3.5355e-3), 1.6250e4),
    "b": PaperExample((200.0, 0.0, 500.0), 0.0, 3 * np.pi / 4,
                      (-2.4749e2, 0.0, -4.2426e-3, 1.0607e2, 0.0, -4.9497e-3), 3.6250e4),
    "c": PaperExample((200.0, 500.0, 300.0), np.pi, np.pi / 4,
                      (-1.7678e2, -1.0000e-2, -1.4142e-3, 3.5355e1, -5.0000e-3, 3.5355e-3), 1.6250e4),
    "d": PaperExample((200.0, 500.0, 300.0), np.pi / 2, np.pi / 4,
                      (-1.7678e2, -1.0000e-2, -1.4142e-3, 2.8284e2, -2.0000e-3, -1.4142e-3), 5.5625e4),
}
"""Paper §2.3 examples a–d: inputs (exact π/4, 3π/4; spec A9) and printed outputs."""

E_NAMES = ("Δr1 [m]", "Δψ1 [rad]", "Δθ1 [rad]", "Δr2 [m]", "Δψ2 [rad]", "Δθ2 [rad]")


class ExampleInputs(eqx.Module):
    """Inputs of :func:`~.absolute.absolute_bias` for one paper example.

    ``relative_bias`` ``(3,)`` m; ``sensor1``, ``sensor2`` :class:`SensorGeometry`;
    ``weights_sq`` ``(6,)`` ``(k_r1², k_ψ1², k_θ1², k_r2², k_ψ2², k_θ2²)``.
    """

    relative_bias: Float[Array, " 3"]
    sensor1: SensorGeometry
    sensor2: SensorGeometry
    weights_sq: Float[Array, " 6"]


def example_inputs(name: str) -> ExampleInputs:
    """The inputs of paper example ``name`` ∈ {a, b, c, d} (parallel ENU frames, as in the paper).

    **Arguments:**

    - ``name``: ``"a"``, ``"b"``, ``"c"`` or ``"d"``.

    **Returns:** an :class:`ExampleInputs`. **Raises:** :class:`~jaxtrack.InputError` for an unknown name.
    """
    if name not in EXAMPLES:
        raise InputError(f"`name` must be one of {sorted(EXAMPLES)}; got {name!r}.")
    ex = EXAMPLES[name]
    sensor1 = SensorGeometry(jnp.asarray(_P1), jnp.asarray(0.0), jnp.asarray(np.pi / 4))
    sensor2 = SensorGeometry(jnp.asarray(_P2), jnp.asarray(ex.azimuth2), jnp.asarray(ex.elevation2))
    return ExampleInputs(jnp.asarray(ex.relative_bias), sensor1, sensor2, jnp.asarray(_EXAMPLE_WEIGHTS))


def solve_example(name: str, method: str = "compact") -> AbsoluteBias:
    """Solve paper example ``name`` with :func:`~.absolute.absolute_bias` (``method`` as there).

    **Arguments:**

    - ``name``: ``"a"``, ``"b"``, ``"c"`` or ``"d"``.
    - ``method``: ``"compact"`` (default), ``"paper"`` or ``"kkt"``.

    **Returns:** an :class:`~.absolute.AbsoluteBias`.
    """
    ex = example_inputs(name)
    return absolute_bias(ex.relative_bias, ex.sensor1, ex.sensor2, ex.weights_sq, method=method)


def cost_discrepancy_table() -> list[dict]:
    """Sec. 2 examples: the minimised F(e*) of (13) against the paper's printed "Cost" (spec A8).

    One dict per example with ``F_star`` (m²), ``printed_cost``, ``sum_e2_over_k2`` (Σ e*²/k², which
    reproduces the print) and ``half_B_R_sq`` (|B_R|²/2, the closed form of F* for the examples'
    weights w1 = w2 = 2).
    """
    rows = []
    weights = jnp.asarray(_EXAMPLE_WEIGHTS)
    for name, ex in EXAMPLES.items():
        sol = solve_example(name)
        e = jnp.concatenate([sol.e1, sol.e2])
        rows.append(dict(example=name, F_star=float(sol.cost), printed_cost=ex.printed_cost,
                         sum_e2_over_k2=float(printed_cost(e, weights)),
                         half_B_R_sq=0.5 * float(np.sum(np.square(ex.relative_bias)))))
    return rows


# -- Sec. 3 models -----------------------------------------------------------------------------


def reduced_state_model(
    transition_matrix: ArrayLike,
    process_noise_cov: ArrayLike,
    measurement_matrix: ArrayLike,
    measurement_noise_cov: ArrayLike,
    bias_matrix: ArrayLike,
    bias_mean: ArrayLike,
    bias_cov: ArrayLike,
    initial_mean: ArrayLike,
    initial_cov: ArrayLike,
    *,
    bias_state_matrix: ArrayLike | None = None,
    bias_param_matrix: ArrayLike | None = None,
) -> LinearGaussianModel:
    r"""Linear plant with a random measurement bias that the filter does not estimate (eqs 42–45).

    .. math::

        x(k+1) = Φ x(k) + m(k),\qquad z(k) = H x(k) + n(k) + W u(x(k), λ)

    with ``m ~ N(0, Q)``, ``n ~ N(0, N)`` white and ``λ ~ N(λ̄, Λ)`` drawn **once** per realisation
    (spec A23). The bias function is affine, ``u(x, λ) = U_x x + U_λ λ``, so its Jacobians (50)
    are exact. Returned as the augmented model of ``[x; λ]`` (:func:`jaxtrack.filters.consider_model`):
    ``z = H̃ x + G λ + n`` with ``H̃ = H + W U_x`` (65) and ``G = W U_λ``; run
    :class:`~jaxtrack.filters.ConsiderKalmanFilter` with ``num_estimated = n`` on it. Its
    predicted cross-covariance is ``Φ D Λ`` and its filtered one ``D Λ`` (D the error sensitivity
    (60)); the prior is ``M(0|0) = P0``, ``D(0|0) = 0``.

    **Arguments** (``n`` states, ``q`` measurement components, ``m`` bias outputs, ``p`` bias
    parameters):

    - ``transition_matrix`` Φ ``(n, n)``; ``process_noise_cov`` Q ``(n, n)`` PSD;
    - ``measurement_matrix`` H ``(q, n)``; ``measurement_noise_cov`` N ``(q, q)`` PD;
    - ``bias_matrix`` W ``(q, m)``; ``bias_mean`` λ̄ ``(p,)``; ``bias_cov`` Λ ``(p, p)`` PSD;
    - ``initial_mean`` x̂(0|0) ``(n,)`` and ``initial_cov`` M(0|0) = P0 ``(n, n)`` PD;
    - ``bias_state_matrix`` U_x = ∂u/∂x ``(m, n)`` (default 0); ``bias_param_matrix``
      U_λ = ∂u/∂λ ``(m, p)`` (default identity, ``m = p``).

    **Returns:** a :class:`~jaxtrack.models.LinearGaussianModel` of dimension ``n + p``.

    **Raises:** :class:`~jaxtrack.InputError` naming the argument with a wrong shape or value.
    """
    arrays = [jnp.asarray(a) for a in (transition_matrix, process_noise_cov, measurement_matrix,
                                          measurement_noise_cov, bias_matrix, bias_mean, bias_cov,
                                          initial_mean, initial_cov)]
    dtype = jnp.result_type(float, *arrays)
    Phi, Q, H, N, W, lam, Lam, x0, P0 = (a.astype(dtype) for a in arrays)
    check_shape("initial_mean", x0, [(None,)])
    n = x0.shape[0]
    check_shape("transition_matrix", Phi, [(n, n)])
    check_shape("process_noise_cov", Q, [(n, n)])
    check_shape("initial_cov", P0, [(n, n)])
    check_shape("measurement_matrix", H, [(None, n)])
    q = H.shape[0]
    check_shape("measurement_noise_cov", N, [(q, q)])
    check_shape("bias_matrix", W, [(q, None)])
    m = W.shape[1]
    check_shape("bias_mean", lam, [(None,)])
    p = lam.shape[0]
    check_shape("bias_cov", Lam, [(p, p)])
    U_x = jnp.zeros((m, n), dtype) if bias_state_matrix is None else jnp.asarray(bias_state_matrix, dtype)
    if bias_param_matrix is None:
        if m != p:
            raise InputError(f"`bias_param_matrix` is required when the bias output size m = {m} differs from p = {p}.")
        U_l = jnp.eye(p, dtype=dtype)
    else:
        U_l = jnp.asarray(bias_param_matrix, dtype)
    check_shape("bias_state_matrix", U_x, [(m, n)])
    check_shape("bias_param_matrix", U_l, [(m, p)])
    for name, a in (("transition_matrix", Phi), ("measurement_matrix", H), ("bias_matrix", W),
                    ("bias_mean", lam), ("initial_mean", x0), ("bias_state_matrix", U_x),
                    ("bias_param_matrix", U_l)):
        check_finite(name, a)
    check_covariance("process_noise_cov", Q, definite=False)
    check_covariance("measurement_noise_cov", N)
    check_covariance("bias_cov", Lam, definite=False)
    check_covariance("initial_cov", P0)
    return consider_model(Phi, Q, H + W @ U_x, N, x0, P0, consider_matrix=W @ U_l, consider_mean=lam,
                          consider_cov=Lam)


def alpha_beta_bias_model(
    period: float,
    velocity_noise_var: float,
    measurement_noise_var: float,
    bias_var: float,
    *,
    bias_mean: float = 0.0,
    initial_mean: ArrayLike = (0.0, 0.0),
    initial_cov: ArrayLike = ((1.0, 0.0), (0.0, 1.0)),
) -> LinearGaussianModel:
    """The Sec. 3 position/velocity tracker with a constant position-measurement bias (eqs 70–76).

    ``Φ = [[1, T], [0, 1]]``, ``H = [1, 0]``, ``W = 1``, ``Q = diag(0, q22)``, ``u(x, λ) = λ``.

    **Arguments:** ``period`` T (s), ``velocity_noise_var`` q22 ((m/s)² per step),
    ``measurement_noise_var`` N (m²), ``bias_var`` Λ (m²), ``bias_mean`` λ̄ (m), and the prior
    ``initial_mean`` ``(2,)`` (m, m/s) and ``initial_cov`` ``(2, 2)``.

    **Returns:** the :func:`reduced_state_model` of state ``[p, v, λ]`` (``num_estimated = 2``).
    """
    t = jnp.asarray(period)
    t = t.astype(jnp.result_type(t, float))
    dtype = t.dtype
    phi = jnp.array([[1.0, 0.0], [0.0, 1.0]], dtype) + t * jnp.array([[0.0, 1.0], [0.0, 0.0]], dtype)
    q = jnp.asarray(velocity_noise_var, dtype) * jnp.array([[0.0, 0.0], [0.0, 1.0]], dtype)
    return reduced_state_model(
        phi, q, jnp.array([[1.0, 0.0]], dtype), jnp.reshape(jnp.asarray(measurement_noise_var, dtype), (1, 1)),
        jnp.ones((1, 1), dtype), jnp.reshape(jnp.asarray(bias_mean, dtype), (1,)),
        jnp.reshape(jnp.asarray(bias_var, dtype), (1, 1)), initial_mean, initial_cov,
    )


GENERAL_SCENARIO = dict(period=1.0, velocity_noise_var=2.0, measurement_noise_var=1.0,
                        bias_mean=3.0, initial_mean=(0.0, 10.0), initial_cov=((100.0, 0.0), (0.0, 10.0)))
"""Spec §4 general-case scenario (T = 1 s, q22 = 2, N = 1, λ̄ = 3, P0 = diag(100, 10)); Λ = 25 or 0."""

NUM_ESTIMATED = 2
"""Estimated states of the α-β bias models: ``[p, v]`` (the bias λ is the third, considered, state)."""


def general_scenario(bias_var: float = 25.0) -> LinearGaussianModel:
    """The spec's general-case scenario (V23–V26) with bias variance Λ (m²); state ``[p, v, λ]``.

    **Arguments:**

    - ``bias_var``: the bias variance ``Λ`` (m²), default 25.

    **Returns:** a :class:`~jaxtrack.models.LinearGaussianModel` with state ``[p, v, λ]`` (m, m/s, m) and
    a scalar position measurement (m); ``T = 1`` s.
    """
    return alpha_beta_bias_model(bias_var=bias_var, **GENERAL_SCENARIO)
