"""The corrected closed-form single-look targeting solution (Sec. 5, E30–E55; spec §1.7) and its
round-trip check over random look geometries (V-5)."""

from __future__ import annotations

from typing import Literal

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..._validation import InputError, check_shape, is_concrete
from ...geometry import body_to_ned_rotation, heading_to_ned_rotation, path_to_heading_rotation
from ...montecarlo import monte_carlo_map
from .geometry import LookGeometry, boresight_angles, los_from_monopulse, radar_measurements
from .states import _choice, _safe_sqrt, _vec3

def single_look_target(
    measurements: ArrayLike,
    aircraft_position: ArrayLike,
    velocity: ArrayLike,
    body_to_nav_dcm: ArrayLike,
    antenna_to_body_dcm: ArrayLike,
    *,
    doppler_cone: Literal["general", "literal"] = "general",
) -> Float[Array, "3"]:
    r"""Closed-form target position from one look (Sec. 5, E30–E55, spec §1.7), m, NED.

    The target is the intersection of the range sphere, the Doppler cone about the velocity and
    the plane ``h_t`` below the aircraft, with ``h_t = r u_pzⁿ`` from the monopulse LOS (E55):

    .. math::

        p^p = \bigl[r\cos β,\ s\sqrt{r^2 − p_x^2 − p_z^2},\ \tan η_y\, p_x + h_t/\cos η_y\bigr],
        \qquad \cos β = −ṙ/|v_a|

    (E31, E40, E47–E48 corrected), with η_z, η_y the heading and climb angle of the velocity
    (E49–E50, FIX-11) and ``s`` the side of the monopulse LOS in the path frame (FIX-8). The
    solution is ``r_tⁿ = r_aⁿ + C_h^n C_p^h p^p``; for ECEF, ``r_t^e = r_a^e + C_n^e (r_tⁿ − r_aⁿ)``.

    **Arguments:**

    - ``measurements``: ``[r, ṙ, A, E]`` (m, m/s, rad, rad), shape ``(4,)``.
    - ``aircraft_position``: INS ``r_aⁿ``, m, shape ``(3,)``.
    - ``velocity``: INS ``v_aⁿ``, m/s, shape ``(3,)`` (not vertical).
    - ``body_to_nav_dcm``: INS ``C_b^n``, shape ``(3, 3)``.
    - ``antenna_to_body_dcm``: ``C_a^b`` from the gimbal/ESA angles, shape ``(3, 3)``.
    - ``doppler_cone``: ``"general"`` (FIX-7) or ``"literal"``, the printed ``cos β = |ṙ|/|v|``,
      which mirrors receding targets across the cross-track plane (V-5b).

    **Returns:** ``r_tⁿ``, shape ``(3,)``.

    **Raises:** :class:`~jaxtrack.InputError` for wrong shapes, or (when concrete) angles that put
    the target behind the array face (``cos²A + cos²E > 1``).
    """
    _choice("doppler_cone", doppler_cone, ("general", "literal"))
    m = jnp.asarray(measurements)
    check_shape("measurements", m, [(4,)])
    r_a = _vec3("aircraft_position", aircraft_position)
    v = _vec3("velocity", velocity)
    C_bn, C_ab = jnp.asarray(body_to_nav_dcm), jnp.asarray(antenna_to_body_dcm)
    check_shape("body_to_nav_dcm", C_bn, [(3, 3)])
    check_shape("antenna_to_body_dcm", C_ab, [(3, 3)])
    r, rdot, A, E = m[0], m[1], m[2], m[3]
    if is_concrete(m):
        front = 1.0 - np.cos(float(A)) ** 2 - np.cos(float(E)) ** 2
        if front < -1e-12:
            raise InputError(
                f"`measurements` angles A, E give cos²A + cos²E = {1 - front:.6g} > 1: the target "
                f"would be behind the array face (E51 needs u_px^a ≥ 0)."
            )
    u_n = C_bn @ C_ab @ los_from_monopulse(A, E)  # E54
    h_t = r * u_n[2]  # E55
    speed = jnp.linalg.norm(v)
    heading = jnp.arctan2(v[1], v[0])
    C_hn = heading_to_ned_rotation(heading)
    v_h = C_hn.T @ v
    climb = jnp.arctan2(-v_h[2], v_h[0])  # E49/E50 (FIX-11)
    C_ph = path_to_heading_rotation(climb)
    # FIX-7: cos β = −ṙ/|v| holds on both sides of broadside; |ṙ|/|v| only for β ≤ π/2.
    cos_cone = jnp.abs(rdot) / speed if doppler_cone == "literal" else -rdot / speed
    p_x = r * cos_cone  # E31, E33
    p_z = jnp.tan(climb) * p_x + h_t / jnp.cos(climb)  # E47 (FIX-9)
    side = jnp.sign((C_hn @ C_ph).T @ u_n)[1]  # resolves the ± of E40 (FIX-8)
    p_y = side * _safe_sqrt(r * r - p_x * p_x - p_z * p_z)  # E40 (FIX-8, FIX-10)
    return r_a + C_hn @ C_ph @ jnp.stack([p_x, p_y, p_z])


def targeting_round_trip_error(looks: LookGeometry, *, doppler_cone: Literal["general", "literal"] = "general") -> Array:
    """‖closed-form target − true target‖ (m) from the looks' own noise-free measurements (V-5).

    ``looks`` is a batch (leading axis) of :class:`LookGeometry`; returns shape ``(B,)``.

    **Arguments:** ``looks``: a batched :class:`LookGeometry` (leading axis B); ``doppler_cone``:
    as :func:`single_look_target`.

    **Returns:** the position errors (m), shape ``(B,)``.
    """

    def one(look):
        est = single_look_target(radar_measurements(look), look.aircraft_position, look.velocity,
                                 look.body_to_nav(), look.antenna_to_body(), doppler_cone=doppler_cone)
        return jnp.linalg.norm(est - look.target_position)

    return jax.jit(jax.vmap(one))(looks)


def _random_look(key: Array, args) -> LookGeometry:
    """One random look of :func:`random_targeting_geometries` (a Monte Carlo run)."""
    del args
    k = jax.random.split(key, 10)
    u = lambda i, lo, hi: jax.random.uniform(k[i], (), minval=lo, maxval=hi)  # noqa: E731
    rng = u(0, 5e3, 6e4)
    height = jnp.minimum(u(1, 1e3, 1.2e4), 0.95 * rng)
    speed = u(2, 100.0, 300.0)
    heading = u(3, -jnp.pi, jnp.pi)
    climb = u(4, -0.3, 0.3)
    squint = u(5, jnp.deg2rad(10.0), jnp.deg2rad(160.0)) * jnp.where(jax.random.bernoulli(k[6], 0.5), 1.0, -1.0)
    ground = jnp.sqrt(rng * rng - height * height)
    bearing = heading + squint
    zero = jnp.zeros_like(rng)
    r_a = jnp.stack([zero, zero, -height])
    r_t = jnp.stack([ground * jnp.cos(bearing), ground * jnp.sin(bearing), zero])
    v = speed * jnp.stack([jnp.cos(climb) * jnp.cos(heading), jnp.cos(climb) * jnp.sin(heading), -jnp.sin(climb)])
    offsets = jax.random.uniform(k[7], (3,), minval=-1.0, maxval=1.0) * jnp.array([0.3, 0.1, 0.1])
    attitude = jnp.stack([zero, climb, heading]) + offsets
    los_b = body_to_ned_rotation(attitude).T @ (r_t - r_a)
    antenna = boresight_angles(los_b) + jax.random.uniform(k[8], (3,), minval=-1.0, maxval=1.0) * jnp.array([0.5, 0.3, 0.3])
    return LookGeometry(r_a, r_t, v, attitude, antenna, u(9, -1.2, 1.2), zero)


def random_targeting_geometries(key: Array, num: int) -> LookGeometry:
    """Random looks for the round-trip test V-5: a batch of ``num`` :class:`LookGeometry`.

    Slant range 5–60 km, aircraft 1–12 km above the target plane (and below 0.95 r), speed
    100–300 m/s, any heading, flight-path angle ±0.3 rad, squint 10°–160° off the ground track
    on either side, roll ±0.3 rad, pitch and yaw within 0.1 rad of the velocity, an antenna
    pointed within 0.3 rad (yaw, pitch) and 0.5 rad (roll) of the target, latitude ±1.2 rad.

    Look ``i`` is drawn from ``jax.random.fold_in(key, i)`` by
    :func:`jaxtrack.montecarlo.monte_carlo_map` (``reduce="stack"``).

    **Arguments:** ``key``: a PRNG key; ``num``: the number of looks, a positive int.

    **Returns:** a :class:`LookGeometry` whose fields have a leading axis ``num``.
    """
    if not isinstance(num, (int, np.integer)) or num < 1:
        raise InputError(f"`num` must be a positive int; got {num!r}.")
    looks = monte_carlo_map(_random_look, key, int(num), reduce="stack")
    return jax.tree.map(jnp.asarray, looks)
