"""Scenarios: the reference scenario RS-1 [EXT: spec §3.5; not from the report], the generic look
geometries of V-5b and V-10, and RS-1 flown over time for the covariance analysis."""

from __future__ import annotations

import math
from typing import Literal

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike

from ..._validation import InputError
from ...geometry import ned_to_ecef_rotation
from ...models import EARTH_RADIUS
from .budgets import NavigationPrior
from .geometry import LookGeometry, boresight_angles

RS1_LATITUDE = math.radians(40.0)
RS1_HEIGHT = 7620.0  # m above the target plane
RS1_SPEED = 200.0  # m/s, level, due north
RS1_TARGET = (20000.0, 20000.0, 0.0)  # r_tⁿ, m, local NED at the aircraft
RS1_ANTENNA = (0.0, math.radians(-15.077939), math.radians(45.0))  # ζ: boresight on the target


def rs1_look() -> LookGeometry:
    """RS-1 at the first look: r_aⁿ = [0, 0, −7620], v = [200, 0, 0], α = 0, target
    [20000, 20000, 0] m, antenna ζ = [0, −15.077939°, 45°], latitude 40°, longitude 0.

    **Returns:** one :class:`LookGeometry` (float64 under x64).
    """
    return LookGeometry([0.0, 0.0, -RS1_HEIGHT], list(RS1_TARGET), [RS1_SPEED, 0.0, 0.0], [0.0, 0.0, 0.0],
                        list(RS1_ANTENNA), RS1_LATITUDE, 0.0)


def v5b_look() -> LookGeometry:
    """V-5b: v = [200, 0, 0], r_a = [0, 0, −8000], r_t = [−10000, 15000, 0] (a receding target),
    level attitude, boresight on the target.

    **Returns:** one :class:`LookGeometry` (float64 under x64).
    """
    r_a, r_t = jnp.array([0.0, 0.0, -8000.0]), jnp.array([-10000.0, 15000.0, 0.0])
    return LookGeometry(r_a, r_t, [200.0, 0.0, 0.0], [0.0, 0.0, 0.0], boresight_angles(r_t - r_a), 0.7, 0.0)


def v10_look() -> LookGeometry:
    """The generic geometry of V-10: r_a = [100, −50, −7620], r_t = [20000, 15000, 0],
    v = [180, 40, −5], α = [0.05, 0.03, 0.25], ζ = [0.02, −0.2, 0.6], φ = 0.7, λ = −1.4.

    **Returns:** one :class:`LookGeometry` (float64 under x64).
    """
    return LookGeometry([100.0, -50.0, -7620.0], [20000.0, 15000.0, 0.0], [180.0, 40.0, -5.0],
                        [0.05, 0.03, 0.25], [0.02, -0.2, 0.6], 0.7, -1.4)


Case = Literal["radar", "sar_only", "radar_gps"]
CASES: dict[str, str] = {
    "radar": "SAR + monopulse, no GPS (the report's filter)",
    "sar_only": "SAR range/range-rate only, no GPS",
    "radar_gps": "SAR + monopulse + GPS position [EXT]",
}


class CovarianceScenario(eqx.Module):
    """RS-1 flown over time for the covariance analysis [EXT: no scenario in the report, FIX-42].

    The aircraft flies level, due north at 200 m/s and 7620 m over a spherical Earth from 40° N;
    the target is the RS-1 target (fixed in ECEF). The ESA boresight is steered onto the target
    at every look. Steps are ``step`` seconds apart; the closed-form first look at ``t = 0``
    initialises the target (:func:`first_look_prior`), then a look every ``look_every`` steps
    and, where the case has GPS, a position fix every ``gps_every`` steps.

    - ``num_steps``, ``look_every``, ``gps_every`` (static ints); ``step`` (s). Default: 49 steps
      of 5 s (0–240 s), a look and a GPS fix at every step.
    - ``gps_std``: GPS position σ per axis, m [EXT].
    - ``nav``: :class:`NavigationPrior`.
    - ``flat_earth`` (static): fixed tangent frame (C_e^n, latitude held), as V-21 asks.
    """

    num_steps: int = eqx.field(static=True, default=49)
    look_every: int = eqx.field(static=True, default=1)
    gps_every: int = eqx.field(static=True, default=1)
    step: float = 5.0
    gps_std: float = 5.0
    nav: NavigationPrior = NavigationPrior()
    flat_earth: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        for name in ("num_steps", "look_every", "gps_every"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise InputError(f"`{name}` must be a positive int; got {value!r}.")

    @property
    def times(self) -> Array:
        """The step times ``step·k``, ``k = 0 … num_steps − 1`` (s), shape ``(num_steps,)``."""
        return self.step * jnp.arange(self.num_steps, dtype=jnp.result_type(self.step, float))


def rs1_trajectory(times: ArrayLike, *, flat_earth: bool = False) -> LookGeometry:
    """The RS-1 looks at ``times`` (s), a batched :class:`LookGeometry` (one per time).

    Curved (default): the aircraft's latitude advances at ``v/(R + h)`` and the LOS is expressed
    in the current NED frame; flat: the aircraft moves in the fixed RS-1 tangent frame.

    **Arguments:** ``times`` ``(T,)`` s; ``flat_earth``: bool.

    **Returns:** a :class:`LookGeometry` with leading axis T.
    """
    t = jnp.asarray(times)
    t = t.astype(jnp.result_type(t, float))
    rh = EARTH_RADIUS + RS1_HEIGHT
    r0 = jnp.array([0.0, 0.0, -RS1_HEIGHT])
    target0 = jnp.asarray(RS1_TARGET)
    if flat_earth:
        lat = jnp.full_like(t, RS1_LATITUDE)
        los = target0[None, :] - (r0[None, :] + RS1_SPEED * t[:, None] * jnp.array([1.0, 0.0, 0.0])[None, :])
    else:
        lat = RS1_LATITUDE + RS1_SPEED * t / rh
        radial = lambda la: jnp.stack([jnp.cos(la), jnp.zeros_like(la), jnp.sin(la)], axis=-1)  # noqa: E731
        target_e = rh * radial(jnp.asarray(RS1_LATITUDE)) + ned_to_ecef_rotation(RS1_LATITUDE, 0.0) @ (target0 - r0)
        los = jnp.einsum("tji,tj->ti", ned_to_ecef_rotation(lat, jnp.zeros_like(lat)), target_e[None, :] - rh * radial(lat))
    zeros = jnp.zeros_like(t)
    n = t.shape[0]
    aircraft = jnp.broadcast_to(r0, (n, 3))
    return LookGeometry(aircraft, aircraft + los, jnp.broadcast_to(jnp.array([RS1_SPEED, 0.0, 0.0]), (n, 3)),
                        jnp.zeros((n, 3)), boresight_angles(los), lat, zeros)
