"""Scenarios and independent NumPy references for ``tests/test_nonlinear_filters.py`` (issue 19).

Three 200-step tracking scenarios, each simulated ONCE by :func:`jaxtrack.montecarlo.simulate`
(``first_step="predict"``: the prior is one transition before the first measurement, FilterPy's
``predict(); update(z)`` and Stone Soup's prior at ``t_0``, first measurement at ``t_0 + τ``):

- **A** — 2-D coordinated turn with known turn rate (:class:`CoordinatedTurn`) observed by
  :class:`RangeBearing` from a sensor at a non-origin position, turned by ``sensor_yaw``; the
  target's bearing from the sensor crosses ±π several times, so every angle residual and angle
  average meets the wrap.
- **B** — 3-D radar (:class:`RangeAzimuthElevation`) on a moving sensor (per-step position) with a
  per-step rotation (yaw varies, pitch and roll constant; all three non-zero); target on a 3-D
  coordinated turn (``CoordinatedTurn(dim=3)``).
- **C** — :class:`NearlyConstantTurn` (turn rate in the state, so the transition Jacobian depends
  on the state) observed by :class:`RangeBearing`.

For each scenario this module gives, besides the jaxtrack model and the data, the model written
out again in NumPy in jaxtrack's state order (``f``, ``F``, ``Q``, ``h``, ``H``, ``R``), without
calling jaxtrack: the transition of C and its Jacobian by complex-step differentiation of a NumPy
``f`` (exact to rounding, independent of jaxtrack's series/closed-form code), the sensor values and
Jacobians from ``atan2``/``hypot`` and hand-derived gradients, the rotation from elementary
rotation matrices. FilterPy is fed these; Stone Soup gets its own models
(``KnownTurnRate``, ``ConstantVelocity``, ``CartesianToBearingRange``,
``CartesianToElevationBearingRange``) with matching offsets, see ``stonesoup_*`` below.
"""

from __future__ import annotations

import dataclasses
import datetime
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from jaxtrack.models import (
    BlockTransition,
    CoordinatedTurn,
    NearlyConstantTurn,
    RangeAzimuthElevation,
    RangeBearing,
    TrackingModel,
    sensor_rotation,
)
from jaxtrack.montecarlo import simulate

T = 200
TAU = 1.0
START = datetime.datetime(2024, 1, 1)


def wrap(a):
    """Angle(s) to [−π, π) (NumPy; the half-open end differs from jaxtrack's only at ±π exactly)."""
    return np.remainder(np.asarray(a) + np.pi, 2 * np.pi) - np.pi


def timestamp(k: int) -> datetime.datetime:
    """Stone Soup time of measurement ``k`` (the prior sits at ``START``)."""
    return START + datetime.timedelta(seconds=TAU * (k + 1))


# ------------------------------------------------------------------------------------------------
# NumPy geometry (independent of jaxtrack)
# ------------------------------------------------------------------------------------------------


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def world_to_sensor(roll, pitch, yaw):
    """``C`` with ``d_sensor = C d_world`` for Stone Soup's ``rotation_offset = [roll, pitch, yaw]``:
    ``rotx(−roll) roty(pitch) rotz(−yaw)`` (``stonesoup.functions.build_rotation_matrix``)."""
    return _rx(-roll) @ _ry(pitch) @ _rz(-yaw)


def spherical_rows(d):
    """Range, azimuth (atan2(y, x)), elevation of the sensor-frame 3-vector ``d`` and their
    gradients with respect to ``d`` (rows of a 3×3 matrix)."""
    x, y, z = d
    rho2 = x * x + y * y
    rho = np.sqrt(rho2)
    r2 = rho2 + z * z
    r = np.sqrt(r2)
    values = np.array([r, np.arctan2(y, x), np.arctan2(z, rho)])
    grads = np.array(
        [
            [x / r, y / r, z / r],
            [-y / rho2, x / rho2, 0.0],
            [-x * z / (rho * r2), -y * z / (rho * r2), rho / r2],
        ]
    )
    return values, grads


def range_bearing_np(p, s, yaw):
    """``[r, φ]`` of target position ``p`` (2,) seen from ``s`` (2,), sensor turned by ``yaw``,
    and the 2×2 gradient with respect to ``p``."""
    C = world_to_sensor(0.0, 0.0, yaw)
    d3 = C @ np.array([p[0] - s[0], p[1] - s[1], 0.0])
    values, grads = spherical_rows(d3)
    return values[:2], grads[:2] @ C[:, :2]


def radar_np(p, s, C):
    """``[r, α, ε]`` of ``p`` (3,) seen from ``s`` with world-to-sensor ``C``; 3×3 gradient in ``p``."""
    values, grads = spherical_rows(C @ (p - s))
    return values, grads @ C


def cwna_q(tau, q):
    """Per-axis white-noise-acceleration ``Q`` on ``[p_1..p_d, v_1..v_d]`` (jaxtrack's layout)."""
    q = np.asarray(q, float)
    Q1 = np.array([[tau**3 / 3, tau**2 / 2], [tau**2 / 2, tau]])
    return np.kron(Q1, np.diag(q))


def ct_matrix_np(omega, tau):
    """Known-turn-rate ``F`` on ``[x, y, vx, vy]`` (closed form; ω ≠ 0)."""
    th = omega * tau
    a, b = np.sin(th) / omega, 2 * np.sin(th / 2) ** 2 / omega
    c, s = np.cos(th), np.sin(th)
    return np.array([[1, 0, a, -b], [0, 1, b, a], [0, 0, c, -s], [0, 0, s, c]], float)


def nct_f_np(x, tau):
    """Nearly-constant-turn transition on ``[x, y, vx, vy, ω]`` (NumPy; complex inputs allowed)."""
    px, py, vx, vy, w = x
    th = w * tau
    a, b = np.sin(th) / w, 2 * np.sin(th / 2) ** 2 / w
    c, s = np.cos(th), np.sin(th)
    return np.array([px + a * vx - b * vy, py + b * vx + a * vy, c * vx - s * vy, s * vx + c * vy, w])


def complex_step_jacobian(f, x, h=1e-30):
    """``∂f/∂x`` by the complex step ``Im f(x + i h e_j)/h``: exact to rounding for analytic ``f``."""
    x = np.asarray(x, float)
    cols = []
    for j in range(x.size):
        xc = x.astype(complex)
        xc[j] += 1j * h
        cols.append(np.imag(f(xc)) / h)
    return np.stack(cols, axis=1)


# ------------------------------------------------------------------------------------------------
# Scenarios
# ------------------------------------------------------------------------------------------------


@dataclasses.dataclass
class Scenario:
    """One scenario: the jaxtrack model and data, and the NumPy model in jaxtrack's state order."""

    name: str
    model: TrackingModel
    zs: np.ndarray  # (T, m) measurements, jaxtrack component order
    states: np.ndarray  # (T, n) simulated truth
    m0: np.ndarray
    P0: np.ndarray
    f: Callable  # f(x, k) -> (n,)
    F: Callable  # F(x, k) -> (n, n), the transition Jacobian at x
    Q: np.ndarray
    h: Callable  # h(x, k) -> (m,)
    H: Callable  # H(x, k) -> (m, n)
    R: np.ndarray
    angles: tuple[int, ...]  # angle components of z (jaxtrack order)
    extra: dict = dataclasses.field(default_factory=dict)
    # The same model with the state in Stone Soup's order [x, vx, y, vy(, z, vz)] (see
    # ``in_stonesoup_order``); None for C.
    model_ss: TrackingModel | None = None

    def residual(self, a, b):
        """``a − b`` with the angle components wrapped (FilterPy's ``residual_z``)."""
        y = np.asarray(a, float) - np.asarray(b, float)
        idx = list(self.angles)
        y[idx] = wrap(y[idx])
        return y

    def z_mean(self, sigmas, weights):
        """jaxtrack's measurement mean: deviations about the central point, through the residual.

        ``ẑ = z_0 + Σ_i w_i residual(z_i, z_0)`` (``jaxtrack/filters/_unscented.py``); FilterPy's
        ``z_mean_fn(sigmas, Wm)``. Equal to ``Σ w_i z_i`` when no angle wraps, and the circular
        average done right when one does.
        """
        z0 = np.asarray(sigmas[0], float)
        dev = np.stack([self.residual(s, z0) for s in sigmas])
        return z0 + np.asarray(weights) @ dev


# jaxtrack index -> Stone Soup index: jaxtrack x = stonesoup x[PERM[n]].
PERM = {4: np.array([0, 2, 1, 3]), 6: np.array([0, 2, 4, 1, 3, 5])}


def in_stonesoup_order(transition, measurement, sensor_kwargs, m0, P0):
    """The scenario's model on the state ``x_ss`` in Stone Soup's order, composed with jaxtrack's
    documented tools: ``BlockTransition([transition], order=PERM)`` (the block acts on
    ``x_ss[PERM]``, i.e. jaxtrack's layout) and the sensor's ``position_indices``."""
    n = m0.size
    perm = PERM[n]
    m_ss = np.zeros(n)
    m_ss[perm] = m0
    P_ss = np.zeros((n, n))
    P_ss[np.ix_(perm, perm)] = P0
    d = n // 2
    sensor = measurement(**sensor_kwargs, position_indices=tuple(int(i) for i in perm[:d]),
                         velocity_indices=tuple(int(i) for i in perm[d:]))
    return TrackingModel(BlockTransition([transition], order=tuple(int(i) for i in perm)), sensor, m_ss, P_ss)


def _simulate(model, seed):
    traj = simulate(model, jax.random.key(seed), T, first_step="predict")
    return np.asarray(traj.measurements), np.asarray(traj.states)


def scenario_a() -> Scenario:
    omega, q = 0.03, np.array([0.05, 0.08])
    sensor, yaw = np.array([1600.0, 60.0]), 0.2
    R = np.diag([5.0**2, 0.01**2])
    m0 = np.array([0.0, -500.0, 15.0, 0.0])  # circle of radius 500 m about the origin
    P0 = np.diag([30.0**2, 30.0**2, 2.0**2, 2.0**2])
    transition = CoordinatedTurn(TAU, turn_rate=omega, noise_intensity=jnp.asarray(q))
    sensor_kwargs = dict(noise_std=np.sqrt(np.diag(R)), sensor_position=sensor, sensor_yaw=yaw)
    model = TrackingModel(transition, RangeBearing(**sensor_kwargs), m0, P0)
    model_ss = in_stonesoup_order(transition, RangeBearing, sensor_kwargs, m0, P0)
    zs, states = _simulate(model, 190)
    F = ct_matrix_np(omega, TAU)

    def h(x, k):
        return range_bearing_np(x[:2], sensor, yaw)[0]

    def H(x, k):
        J = np.zeros((2, 4))
        J[:, :2] = range_bearing_np(x[:2], sensor, yaw)[1]
        return J

    return Scenario(
        "A", model, zs, states, m0, P0, lambda x, k: F @ x, lambda x, k: F, cwna_q(TAU, q), h, H, R, (1,),
        extra=dict(omega=omega, q=q, sensor=sensor, yaw=yaw), model_ss=model_ss,
    )


def scenario_b() -> Scenario:
    omega, q = -0.015, np.array([0.02, 0.03, 0.005])
    k = np.arange(T)
    # Sensor on a straight climbing track; yaw slewing slowly, pitch and roll fixed.
    sensors = np.stack([-3000.0 + 12.0 * k, -4000.0 + 3.0 * k, 50.0 + 0.4 * k], axis=1)
    yaws, pitch, roll = 0.7 + 0.002 * k, -0.25, 0.1
    R = np.diag([10.0**2, 2e-3**2, 2e-3**2])
    m0 = np.array([1500.0, -800.0, 900.0, -10.0, 12.0, 0.5])
    P0 = np.diag([40.0**2] * 3 + [2.0**2] * 3)
    transition = CoordinatedTurn(TAU, turn_rate=omega, noise_intensity=jnp.asarray(q), dim=3)
    sensor_kwargs = dict(
        noise_std=np.sqrt(np.diag(R)),
        sensor_position=sensors,
        world_to_sensor_rotation=sensor_rotation(yaw=jnp.asarray(yaws), pitch=pitch, roll=roll),
    )
    model = TrackingModel(transition, RangeAzimuthElevation(**sensor_kwargs), m0, P0)
    model_ss = in_stonesoup_order(transition, RangeAzimuthElevation, sensor_kwargs, m0, P0)
    zs, states = _simulate(model, 191)
    F = np.zeros((6, 6))
    h4, v2 = np.array([0, 1, 3, 4]), np.array([2, 5])
    F[np.ix_(h4, h4)] = ct_matrix_np(omega, TAU)
    F[np.ix_(v2, v2)] = [[1.0, TAU], [0.0, 1.0]]
    Cs = [world_to_sensor(roll, pitch, y) for y in yaws]

    def h(x, k):
        return radar_np(x[:3], sensors[k], Cs[k])[0]

    def H(x, k):
        J = np.zeros((3, 6))
        J[:, :3] = radar_np(x[:3], sensors[k], Cs[k])[1]
        return J

    return Scenario(
        "B", model, zs, states, m0, P0, lambda x, k: F @ x, lambda x, k: F, cwna_q(TAU, q), h, H, R, (1, 2),
        extra=dict(omega=omega, q=q, sensors=sensors, yaws=yaws, pitch=pitch, roll=roll), model_ss=model_ss,
    )


def scenario_c() -> Scenario:
    q, q_omega = np.array([0.05, 0.05]), 1e-7
    sensor = np.array([-2500.0, 700.0])
    R = np.diag([5.0**2, 0.005**2])
    m0 = np.array([0.0, -600.0, 18.0, 0.0, 0.03])
    P0 = np.diag([30.0**2, 30.0**2, 2.0**2, 2.0**2, 0.01**2])
    model = TrackingModel(
        NearlyConstantTurn(TAU, noise_intensity=jnp.asarray(q), turn_rate_intensity=q_omega),
        RangeBearing(np.sqrt(np.diag(R)), sensor_position=sensor),
        m0,
        P0,
    )
    zs, states = _simulate(model, 192)
    Q = np.zeros((5, 5))
    Q[:4, :4] = cwna_q(TAU, q)
    Q[4, 4] = q_omega * TAU

    def f(x, k):
        return nct_f_np(x, TAU)

    def F(x, k):
        return complex_step_jacobian(lambda v: nct_f_np(v, TAU), x)

    def h(x, k):
        return range_bearing_np(x[:2], sensor, 0.0)[0]

    def H(x, k):
        J = np.zeros((2, 5))
        J[:, :2] = range_bearing_np(x[:2], sensor, 0.0)[1]
        return J

    return Scenario("C", model, zs, states, m0, P0, f, F, Q, h, H, R, (1,), extra=dict(sensor=sensor))
