"""Bearings-only TMA study (Lindgren & Gong 1977): report constants, observer paths, engagements, bearings.

The scenario of spec §4.4: an observer on legs with point maneuvers or a turn-rate limit, a
constant-velocity target, compass bearings ``atan2(r_x, r_y)`` (:func:`jaxtrack.geometry.bearing`),
white Gaussian noise, optional pre-averaging of 1-s samples (A3). The observer's true displacement
enters the prediction through the general input ``u(k)`` of spec §3.5 item 5.

Conventions: SI units (m, s) and radians; samples ``k = 0, …, K`` at ``t_k = k t_s``. Observer
velocity ``V_O(k)`` is the right limit at ``t_k`` (for a point maneuver at ``t_k`` it is already the
new velocity). State vectors are ``[r_x, r_y, V_x, V_y]``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..._validation import InputError, check_shape
from ...geometry import bearing, course
from ...models import constant_velocity_transition, wrap_angle

# --------------------------------------------------------------------------------------------
# Report constants (spec §4.1, V31)

SPEED = 5.626  # m/s, target and observer (≈ 10.94 kn)
LEG_DURATION = 240.0  # s, four legs of 240 s
NUM_LEGS = 4
SAMPLE_PERIOD = 20.0  # s: twenty 1-s bearings averaged per sample (A1)
NUM_AVERAGED = 20
RAW_BEARING_STD = math.radians(0.5)  # rad, σ of one raw 1-s bearing
AVERAGED_BEARING_STD = RAW_BEARING_STD / math.sqrt(NUM_AVERAGED)  # 0.1118° = 1.951e-3 rad
TURN_RATE = math.radians(3.0)  # rad/s, geometries 2 and 3
INITIAL_RANGE_GUESSES = (0.0, 5000.0, 10000.0, 20000.0)  # m (A6)
EKF_VELOCITY_STD = 10.0  # m/s, Appendix D P(0|0) velocity σ (A8 guess)

# Noise configurations of A2: (true σ of the averaged bearing, filter σ), rad.
NOISE_CONFIGS = {
    "A": (AVERAGED_BEARING_STD, AVERAGED_BEARING_STD),
    "B": (AVERAGED_BEARING_STD, RAW_BEARING_STD),
    "C": (RAW_BEARING_STD, RAW_BEARING_STD),
}


# --------------------------------------------------------------------------------------------
# Geometry: bearing convention, transition matrix, observer path


class ObserverPath(eqx.Module):
    """An observer that sails straight legs joined by point or constant-rate turns (A10).

    - ``courses``: course of each leg, rad clockwise from +y.
    - ``speed``: m/s, constant (also through turns).
    - ``leg_duration``: s; leg ``i`` starts at ``i·leg_duration`` and *includes* its turn.
    - ``turn_rate``: rad/s, or ``None`` for instantaneous (point) maneuvers at the leg starts.
      Turns go the short way round.
    - ``start``: position at ``t = 0``, m.

    Before ``t = 0`` and after the last leg the observer keeps its first / last course (needed
    only by pre-averaging windows that straddle the ends).
    """

    courses: tuple[float, ...] = eqx.field(static=True)
    speed: float = eqx.field(default=SPEED, static=True)
    leg_duration: float = eqx.field(default=LEG_DURATION, static=True)
    turn_rate: float | None = eqx.field(default=None, static=True)
    start: tuple[float, float] = eqx.field(default=(0.0, 0.0), static=True)

    def __check_init__(self):
        if len(self.courses) < 1:
            raise InputError("`courses` must hold at least one leg's course (rad).")
        if not self.speed > 0 or not self.leg_duration > 0:
            raise InputError(f"`speed` and `leg_duration` must be positive; got {self.speed}, {self.leg_duration}.")

    def _segments(self):
        """Host-side list of arcs ``(t0, x0, y0, course0, rate)``, straight (rate 0) or turning."""
        segs = []
        x, y = float(self.start[0]), float(self.start[1])
        psi = float(self.courses[0])
        for i, new in enumerate(self.courses):
            t = i * self.leg_duration
            if segs:
                x, y, psi = _advance(segs[-1], t, self.speed)
            turn = float(np.angle(np.exp(1j * (new - psi)))) if i else 0.0  # short way round
            if turn != 0.0 and self.turn_rate:
                segs.append((t, x, y, psi, math.copysign(self.turn_rate, turn)))
                t_end = t + abs(turn) / self.turn_rate
                if t_end > t + self.leg_duration:
                    raise InputError(
                        f"a {math.degrees(abs(turn)):.0f}° turn at {math.degrees(self.turn_rate):g}°/s "
                        f"does not fit in a {self.leg_duration:g}-s leg."
                    )
                x, y, _ = _advance(segs[-1], t_end, self.speed)
                t = t_end
            segs.append((t, x, y, float(new), 0.0))
        return segs

    @staticmethod
    def _arc_at(segs, t):
        """The arc that holds time ``t``; right-continuous, so a maneuver instant has the new arc."""
        starts = [seg[0] for seg in segs]
        return segs[int(np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(segs) - 1))]

    def state_at(self, times: ArrayLike) -> np.ndarray:
        """``[r_Ox, r_Oy, V_Ox, V_Oy]`` at ``times`` (s), shape ``(T, 4)``, float64, exact arcs.

        The velocity is the right limit: at a point maneuver it is already the new velocity.
        """
        times = np.atleast_1d(np.asarray(times, dtype=np.float64))
        segs = self._segments()
        out = np.empty((times.shape[0], 4))
        for j, t in enumerate(times):
            x, y, psi = _advance(self._arc_at(segs, t), t, self.speed)
            out[j] = (x, y, self.speed * math.sin(psi), self.speed * math.cos(psi))
        return out

    def dead_reckoning_residual(self, times: ArrayLike) -> np.ndarray:
        """``r_O(t_{k+1}) − r_O(t_k) − (t_{k+1} − t_k) V_O(t_k)`` for consecutive ``times``, ``(T−1, 2)`` m.

        The position part of the general input ``u(k)`` (spec §3.5 item 5), integrated arc by arc:
        straight arcs on the course held at ``t_k`` contribute exactly zero, so a point-maneuver
        path gives exactly the report's ``[0; ΔV_O]`` (no subtraction round-off).
        """
        times = np.asarray(times, dtype=np.float64)
        segs = self._segments()
        out = np.zeros((max(times.shape[0] - 1, 0), 2))
        for k, (t0, t1) in enumerate(zip(times[:-1], times[1:])):
            _, _, psi0 = _advance(self._arc_at(segs, t0), t0, self.speed)
            v0 = self.speed * np.array([math.sin(psi0), math.cos(psi0)])
            cuts = [t0, *[seg[0] for seg in segs if t0 < seg[0] < t1], t1]
            for a, b in zip(cuts[:-1], cuts[1:]):
                seg = self._arc_at(segs, a)
                if seg[4] == 0.0 and seg[3] == psi0:
                    continue
                xa, ya, _ = _advance(seg, a, self.speed)
                xb, yb, _ = _advance(seg, b, self.speed)
                out[k] += np.array([xb - xa, yb - ya]) - (b - a) * v0
        return out


def _advance(seg, t, speed):
    """Position and course at time ``t`` on an arc ``(t0, x0, y0, course0, rate)`` (exact)."""
    t0, x0, y0, psi0, rate = seg
    dt = t - t0
    if rate == 0.0:
        return x0 + speed * dt * math.sin(psi0), y0 + speed * dt * math.cos(psi0), psi0
    psi = psi0 + rate * dt
    # ∫ v (sin ψ, cos ψ) dt along ψ(t) = ψ0 + ω t.
    x = x0 + speed / rate * (math.cos(psi0) - math.cos(psi))
    y = y0 + speed / rate * (math.sin(psi) - math.sin(psi0))
    return x, y, psi


class Scenario(eqx.Module):
    """Truth of one engagement sampled at ``t_k = k t_s``, ``k = 0, …, K`` (spec §4.4).

    - ``times``: ``(K+1,)`` s.
    - ``observer``: ``(K+1, 4)`` ``x_O(k) = [r_Ox, r_Oy, V_Ox, V_Oy]`` (m, m/s); velocity is the
      right limit at ``t_k``.
    - ``target``: ``(K+1, 4)`` ``x_T(k)``, constant velocity (eq. 1).
    - ``window_bearings``: ``(K+1, M)`` true bearings (rad) at the ``M`` 1-s instants centred on
      ``t_k`` that pre-averaging combines into one sample (A3).
    - ``sample_period``: ``t_s`` (s), shape ``()``.
    - ``turn_displacement``: ``(K, 2)`` ``r_O(k+1) − r_O(k) − t_s V_O(k)`` (m): how far the
      observer's turns put it off its dead-reckoned position over each interval (exactly zero for
      straight intervals; :meth:`ObserverPath.dead_reckoning_residual`).
    """

    times: Float[Array, " K1"]
    observer: Float[Array, "K1 4"]
    target: Float[Array, "K1 4"]
    window_bearings: Float[Array, "K1 M"]
    sample_period: Float[Array, ""]
    turn_displacement: Float[Array, "K 2"]

    @property
    def relative(self) -> Array:
        """``x_R(k) = x_T(k) − x_O(k)`` (eq. 67b), ``(K+1, 4)``."""
        return self.target - self.observer

    @property
    def bearings(self) -> Array:
        """True bearings ``β(k)`` (eq. 5), rad, ``(K+1,)``."""
        return bearing(self.relative)

    @property
    def slant_range(self) -> Array:
        """True range ``r_s(k) = ‖r_R(k)‖`` (eq. 9), m, ``(K+1,)``."""
        r = self.relative
        return jnp.hypot(r[:, 0], r[:, 1])

    @property
    def target_course(self) -> Array:
        """True target course (rad, [0, 2π)), ``(K+1,)``."""
        return course(self.target[:, 2:])

    @property
    def target_speed(self) -> Array:
        """True target speed (m/s), ``(K+1,)``."""
        return jnp.hypot(self.target[:, 2], self.target[:, 3])

    @property
    def observer_input(self) -> Array:
        """General observer input ``u(k)`` (spec §3.5 item 5), ``(K, 4)``.

        ``u(k) = [r_O(k+1) − r_O(k) − t_s V_O(k);  V_O(k+1) − V_O(k)]`` so that
        ``x_R(k+1) = Φ x_R(k) − u(k)`` holds exactly for any observer path; for point maneuvers at
        sample instants the position part is exactly zero and this is eq. (67b)'s ``[0; I] ΔV_O(k)``.
        """
        dv = self.observer[1:, 2:] - self.observer[:-1, 2:]
        return jnp.concatenate([self.turn_displacement, dv], axis=1)

    @property
    def naive_observer_input(self) -> Array:
        """The report's input ``[0; ΔV_O(k)]`` (eqs. 3, 67b), exact only for point maneuvers."""
        dv = self.observer[1:, 2:] - self.observer[:-1, 2:]
        return jnp.concatenate([jnp.zeros_like(dv), dv], axis=1)


def observer_input(observer_states: ArrayLike, sample_period: ArrayLike) -> Array:
    """``u(k) = x_O(k+1) − Φ(t_s) x_O(k)`` for ``k = 0..K−1`` (spec §3.5 item 5), ``(K, 4)``.

    For an observer track given only as sampled states (e.g. navigation data). Built scenarios
    use :attr:`Scenario.observer_input`, which integrates the path and so has no round-off on
    straight intervals.

    **Arguments:**

    - ``observer_states``: the sampled observer states ``[x, y, ẋ, ẏ]``, shape ``(K+1, 4)``, m and m/s.
    - ``sample_period``: ``t_s`` (s), scalar.

    **Returns:** ``u``, shape ``(K, 4)``, m and m/s.
    """
    xo = jnp.asarray(observer_states)
    phi = constant_velocity_transition(sample_period, dtype=xo.dtype)
    return xo[1:] - xo[:-1] @ phi.T


def make_scenario(
    path: ObserverPath,
    target_position: Sequence[float],
    target_course: float,
    target_speed: float = SPEED,
    *,
    sample_period: float = SAMPLE_PERIOD,
    num_samples: int | None = None,
    num_averaged: int = NUM_AVERAGED,
) -> Scenario:
    """Sample an engagement (host-side, float64): observer ``path`` and a constant-velocity target.

    **Arguments:**

    - ``path``: the :class:`ObserverPath`.
    - ``target_position``: ``(r_Tx, r_Ty)`` at ``t = 0``, m; ``target_course`` rad; ``target_speed`` m/s.
    - ``num_samples``: ``K + 1``; default covers every leg, ``t = 0 … legs·leg_duration``.
    - ``num_averaged``: raw 1-s bearings per sample for pre-averaging (A3); the raw instants are
      spaced ``t_s / num_averaged`` and centred on ``t_k``.
    - ``sample_period``: ``t_s`` (s).

    **Returns:** a :class:`Scenario` with ``K + 1`` samples (observer and target states ``(K+1, 4)``,
    m and m/s; raw bearings ``(K+1, num_averaged)``, rad).

    **Raises:** ``InputError`` for a non-positive ``sample_period``, ``num_averaged < 1``,
    ``num_samples < 2`` or a ``target_position`` not of shape ``(2,)``.
    """
    if sample_period <= 0:
        raise InputError(f"`sample_period` must be positive (s); got {sample_period}.")
    if num_averaged < 1:
        raise InputError(f"`num_averaged` must be at least 1; got {num_averaged}.")
    if num_samples is None:
        num_samples = int(round(len(path.courses) * path.leg_duration / sample_period)) + 1
    if num_samples < 2:
        raise InputError(f"`num_samples` must be at least 2; got {num_samples}.")
    times = np.arange(num_samples) * float(sample_period)
    vt = target_speed * np.array([math.sin(target_course), math.cos(target_course)])
    r0 = np.asarray(target_position, dtype=np.float64)
    check_shape("target_position", r0, [(2,)])

    def target_at(t):
        return np.concatenate([r0[None, :] + t[:, None] * vt[None, :], np.broadcast_to(vt, (t.shape[0], 2))], axis=1)

    offsets = (np.arange(num_averaged) - (num_averaged - 1) / 2) * (sample_period / num_averaged)
    window_times = (times[:, None] + offsets[None, :]).ravel()
    rel_window = target_at(window_times) - path.state_at(window_times)
    window = np.arctan2(rel_window[:, 0], rel_window[:, 1]).reshape(num_samples, num_averaged)
    return Scenario(
        times=jnp.asarray(times),
        observer=jnp.asarray(path.state_at(times)),
        target=jnp.asarray(target_at(times)),
        window_bearings=jnp.asarray(window),
        sample_period=jnp.asarray(float(sample_period)),
        turn_displacement=jnp.asarray(path.dead_reckoning_residual(times)),
    )


class GeometrySpec(eqx.Module):
    """An engagement before sampling: observer ``path``, ``target_position`` at t = 0 (m) and ``target_course`` (rad)."""

    path: ObserverPath
    target_position: tuple[float, float] = eqx.field(static=True)
    target_course: float = eqx.field(static=True)


def geometry_spec(name: str) -> GeometrySpec:
    """The spec's reconstructed geometries (§4.4) as paths: ``"R1"``, ``"R2"`` or ``"R3"``.

    - R1 (report geometry 1): observer courses 90°, 0°, 90°, 0° with point maneuvers at 240, 480,
      720 s; target from (10 000, 0) m heading 0°; legs 2 and 4 run parallel (zero bearing rate).
    - R2 (geometry 2 stand-in): R1 with 3°/s turns.
    - R3 (geometry 3 stand-in): observer 0°, 90°, 0°, 90° with 3°/s turns; target from
      (−5000, 8660.25) m (bearing 330°, 10 km) heading 120° — leg 1 runs down the line of sight.

    Both vehicles sail at 5.626 m/s.

    **Arguments:**

    - ``name``: ``"R1"``, ``"R2"`` or ``"R3"``.

    **Returns:** a :class:`GeometrySpec`.

    **Raises:** ``InputError`` for any other ``name``.
    """
    zigzag = tuple(math.radians(c) for c in (90, 0, 90, 0))
    if name == "R1":
        return GeometrySpec(ObserverPath(zigzag), (10_000.0, 0.0), 0.0)
    if name == "R2":
        return GeometrySpec(ObserverPath(zigzag, turn_rate=TURN_RATE), (10_000.0, 0.0), 0.0)
    if name == "R3":
        path = ObserverPath(tuple(math.radians(c) for c in (0, 90, 0, 90)), turn_rate=TURN_RATE)
        return GeometrySpec(path, (-5000.0, 8660.25), math.radians(120.0))
    raise InputError(f"`name` must be 'R1', 'R2' or 'R3'; got {name!r}.")


def geometry(name: str, *, sample_period: float = SAMPLE_PERIOD) -> Scenario:
    """Geometry ``name`` of :func:`geometry_spec` sampled every ``sample_period`` s (49 samples at 20 s, A1).

    **Arguments:**

    - ``name``: ``"R1"``, ``"R2"`` or ``"R3"`` (see :func:`geometry_spec`).
    - ``sample_period``: ``t_s`` (s), default ``SAMPLE_PERIOD``.

    **Returns:** a :class:`Scenario`, as from :func:`make_scenario` with every leg covered.
    """
    spec = geometry_spec(name)
    return make_scenario(spec.path, spec.target_position, spec.target_course, sample_period=sample_period)


def first_maneuver_index(scenario: Scenario) -> int:
    """``k_m``: the first sample with ``V_O(k_m) ≠ V_O(k_m − 1)`` (spec §3.5 item 2).

    **Arguments:**

    - ``scenario``: a :class:`Scenario`.

    **Returns:** ``k_m`` as a Python int; ``K + 1`` (the number of samples) if the observer never maneuvers.
    """
    dv = np.abs(np.diff(np.asarray(scenario.observer[:, 2:]), axis=0)).max(axis=1)
    changed = np.flatnonzero(dv > 1e-9)
    return int(changed[0]) + 1 if changed.size else int(scenario.times.shape[0])


# --------------------------------------------------------------------------------------------
# Measurements


def noisy_bearings(scenario: Scenario, key, bearing_std: ArrayLike, *, preaverage: bool = False) -> Array:
    """Measured bearings ``β_m(k) = β(k) + ν(k)`` (eq. 7), rad, ``(K+1,)``.

    **Arguments:**

    - ``scenario``: a :class:`Scenario`; ``key``: a PRNG key.
    - ``bearing_std``: σ of ``ν`` (rad). With ``preaverage=False`` (default, A3) it is the σ of the
      averaged sample (the report's 0.5°/√20 = 0.1118°) and the bearing is simulated directly at
      ``t_k``. With ``preaverage=True`` it is the σ of one *raw* 1-s bearing (0.5°): ``M`` raw
      bearings at the 1-s instants centred on ``t_k`` are averaged into one sample (the report's
      "averaging twenty 1-second samples"), which also smears a moving bearing slightly.

    **Returns:** the measured bearings, shape ``(K+1,)``, rad.
    """
    std = jnp.asarray(bearing_std, dtype=scenario.window_bearings.dtype)
    if preaverage:
        window = scenario.window_bearings
        centre = window[:, :1]
        raw = window + std * jax.random.normal(key, window.shape, window.dtype)
        # Average the wrapped offsets from the window's first bearing, so that a window straddling
        # ±π does not average to the opposite direction.
        return wrap_angle(centre[:, 0] + jnp.mean(wrap_angle(raw - centre), axis=1))
    beta = scenario.bearings
    return beta + std * jax.random.normal(key, beta.shape, beta.dtype)


def golden_bearing_noise(num_samples: int, bearing_std: float) -> Array:
    """Deterministic pseudo-noise of V23: ``ν(k) = σ √2 sin(2.3 k + 0.7)``, rad, ``(K+1,)``.

    **Arguments:**

    - ``num_samples``: ``K + 1``.
    - ``bearing_std``: ``σ`` (rad).

    **Returns:** ``ν``, shape ``(K+1,)``, rad.
    """
    k = jnp.arange(num_samples) * 1.0
    return bearing_std * math.sqrt(2.0) * jnp.sin(2.3 * k + 0.7)


def cross_range_noise(slant_range: ArrayLike, bearing_noise: ArrayLike) -> Array:
    """``η = r_s sin ν`` (eq. 15): the pseudo-measurement noise of eq. (13), m.

    **Arguments:**

    - ``slant_range``: ``r_s`` (m); ``bearing_noise``: ``ν`` (rad). Broadcastable arrays ``(...)``.

    **Returns:** ``η``, the broadcast shape ``(...)``, m.
    """
    return jnp.asarray(slant_range) * jnp.sin(jnp.asarray(bearing_noise))


def cross_range_noise_variance(slant_range: ArrayLike, bearing_std: ArrayLike) -> Array:
    """``σ_η² = ½ r_s² (1 − exp(−2σ_ν²))`` (eq. 16b, exact for Gaussian ν), m².

    **Arguments:**

    - ``slant_range``: ``r_s`` (m); ``bearing_std``: ``σ_ν`` (rad). Broadcastable arrays ``(...)``.

    **Returns:** ``σ_η²``, the broadcast shape ``(...)``, m².
    """
    r = jnp.asarray(slant_range)
    s = jnp.asarray(bearing_std)
    return 0.5 * r**2 * (1.0 - jnp.exp(-2.0 * s**2))

