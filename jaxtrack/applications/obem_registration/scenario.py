"""The Monte Carlo scenario of Sec. 3 (spec §4.1–4.3): two ships, one target, and the per-scan
registration inputs Z, H, R (eqs 17–18, spec §2.2 [R])."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from ... import geometry
from ..._validation import InputError, check_finite, check_shape, is_concrete
from ...models import wrap_angle
from .frames import DEG, attitude_matrix, pseudo_measurement_noise_cov, registration_terms

__all__ = [
    "Scenario",
    "paper_scenario",
    "unequal_tilt_scenario",
    "bias_free",
    "Scans",
    "simulate_scans",
    "RegistrationInputs",
    "registration_inputs",
]


class Scenario(eqx.Module):
    """The Monte Carlo scenario of Sec. 3 (spec §4.1); every number is an array leaf.

    - ``ship_sites`` ``(2, 3)``: initial ``[L, λ, h]`` of ships 1, 2 (rad, rad, m).
    - ``ship_states`` ``(2, 6)``: initial ``[x, ẋ, y, ẏ, z, ż]`` in each ship's own initial ENU (m, m/s).
    - ``ship_accel_std`` ``(3,)``: DWNA process-noise std per axis, m/s².
    - ``target_state`` ``(6,)``: initial target state in the fusion-centre ENU (ship 1's initial ENU).
    - ``target_accel_std`` ``(3,)``: m/s².
    - ``offset_bias`` ``(2, 4)``: ``[Δr (m), k_r, Δθ (rad), Δε (rad)]`` per radar.
    - ``attitude_bias`` ``(2, 3)``: ``[Δφ, Δη, Δψ]`` per platform, rad.
    - ``noise_std`` ``(2, 3)``: ``[σ_r (m), σ_θ (rad), σ_ε (rad)]`` per radar.
    - ``period`` T (s); ``num_scans`` K (static).
    """

    ship_sites: Float[Array, "2 3"]
    ship_states: Float[Array, "2 6"]
    ship_accel_std: Float[Array, "3"]
    target_state: Float[Array, "6"]
    target_accel_std: Float[Array, "3"]
    offset_bias: Float[Array, "2 4"]
    attitude_bias: Float[Array, "2 3"]
    noise_std: Float[Array, "2 3"]
    period: Float[Array, ""]
    num_scans: int = eqx.field(static=True)

    def __check_init__(self):
        for name, shape in (("ship_sites", (2, 3)), ("ship_states", (2, 6)), ("ship_accel_std", (3,)),
                            ("target_state", (6,)), ("target_accel_std", (3,)), ("offset_bias", (2, 4)),
                            ("attitude_bias", (2, 3)), ("noise_std", (2, 3)), ("period", ())):
            check_shape(name, getattr(self, name), [shape])
            check_finite(name, getattr(self, name))
        for name in ("noise_std", "period"):
            if not is_concrete(getattr(self, name)):
                continue
            value = np.asarray(getattr(self, name))
            if not np.all(value > 0):
                raise InputError(f"`{name}` must be positive (a zero σ makes R singular); got {value}.")
        if not isinstance(self.num_scans, int) or self.num_scans < 2:
            raise InputError(f"`num_scans` must be an int ≥ 2; got {self.num_scans!r}.")


def paper_scenario(num_scans: int = 200, *, dtype=None) -> Scenario:
    """The paper's scenario (Sec. 3, spec §4.1): two ships heading NE at 14.1 m/s, one CV target,
    Δr = 300 m, k_r = 0.01, Δθ = Δε = 2°, (Δφ, Δη, Δψ) = (2°, 1°, 1°) on both platforms,
    σ = (50 m, 0.5°, 0.5°), T = 5 s.

    **Arguments:** ``num_scans`` K (default 200); ``dtype`` of the arrays (default JAX's default
    float; use float64, spec §5).

    **Returns:** a :class:`Scenario`.
    """
    dtype = jnp.result_type(float) if dtype is None else dtype

    def f(x):
        return jnp.asarray(x, dtype)

    return Scenario(
        ship_sites=f([[40.0 * DEG, 116.0 * DEG, 10.0], [40.75 * DEG, 115.34 * DEG, 10.0]]),
        ship_states=f([[0.0, 10.0, 0.0, 10.0, 0.0, 0.0]] * 2),
        ship_accel_std=f([0.1, 0.1, 0.0]),
        target_state=f([60e3, -170.0, 30e3, 30.0, 5e3, 1.0]),
        target_accel_std=f([1.0, 1.0, 0.1]),
        offset_bias=f([[300.0, 0.01, 2 * DEG, 2 * DEG]] * 2),
        attitude_bias=f([[2 * DEG, 1 * DEG, 1 * DEG]] * 2),
        noise_std=f([[50.0, 0.5 * DEG, 0.5 * DEG]] * 2),
        period=f(5.0),
        num_scans=num_scans,
    )


def unequal_tilt_scenario(pitch2: float = -1.0 * DEG, roll2: float = -1.0 * DEG, num_scans: int = 200) -> Scenario:
    """The spec's caveat scenario (§4.6 [X]): as the paper's, but platform 2 has pitch ``pitch2``
    and roll ``roll2`` (rad; default −1°, −1°) instead of +1°, +1°.

    **Arguments:**

    - ``pitch2``, ``roll2``: platform 2's pitch and roll biases (rad).
    - ``num_scans``: ``K``, the number of scans (default 200).

    **Returns:** a :class:`Scenario`.
    """
    s = paper_scenario(num_scans)
    return eqx.tree_at(lambda sc: sc.attitude_bias, s, s.attitude_bias.at[1, 1].set(pitch2).at[1, 2].set(roll2))


def bias_free(scenario: Scenario) -> Scenario:
    """``scenario`` with all offset and attitude biases set to zero.

    **Arguments:** ``scenario``. **Returns:** a :class:`Scenario`.
    """
    return eqx.tree_at(lambda s: (s.offset_bias, s.attitude_bias), scenario,
                       (jnp.zeros_like(scenario.offset_bias), jnp.zeros_like(scenario.attitude_bias)))


class Scans(eqx.Module):
    """One simulated run (spec §4.2–4.3), radar index first, scans ``k = 1…K`` in rows ``0…K−1``.

    - ``raw`` ``(2, K, 3)``: raw measurements ``[r, θ, ε]`` (m, rad, rad), compass θ in (−π, π].
    - ``sites`` ``(2, K, 3)``: radar sites ``[L, λ, h]`` at each scan (rad, rad, m).
    - ``target_enu`` ``(2, K, 3)``: the true target in each radar's current ENU frame, m.
    """

    raw: Float[Array, "2 K 3"]
    sites: Float[Array, "2 K 3"]
    target_enu: Float[Array, "2 K 3"]


def _cv_positions(state, accel_std, period, num_scans, key):
    """Positions ``(K, 3)`` of a CV model with discrete white-noise acceleration (spec §4.2 [R])."""
    pos0, vel0 = state[0::2], state[1::2]
    accel = jnp.broadcast_to(accel_std, (num_scans - 1, 3)) * jax.random.normal(key, (num_scans - 1, 3), state.dtype)

    def step(carry, a):
        p, v = carry
        p = p + period * v + 0.5 * period**2 * a
        return (p, v + period * a), p

    _, ps = jax.lax.scan(step, (pos0, vel0), accel)
    return jnp.concatenate([pos0[None, :], ps])


def simulate_run(scenario: Scenario, key: PRNGKeyArray, measurement_noise: bool = True,
                 process_noise: bool = True) -> Scans:
    """:func:`simulate_scans` without the input checks and the jit (for use inside jitted runs).

    **Arguments:**

    - ``scenario``: the :class:`Scenario`; ``key``: a PRNG key.
    - ``measurement_noise``, ``process_noise``: switch the two noise sources on (default) or off.

    **Returns:** :class:`Scans` (``(2, K, 3)`` arrays: m, rad, rad for ``raw``; rad, rad, m for ``sites``;
    m for ``target_enu``).
    """
    k_ships, k_target, k_noise = jax.random.split(key, 3)
    dtype = scenario.ship_sites.dtype
    proc = 1.0 if process_noise else 0.0
    n = scenario.num_scans
    fc = scenario.ship_sites[0]
    # Target in the fusion-centre ENU (ship 1's initial frame), then ECEF.
    target = _cv_positions(scenario.target_state, proc * scenario.target_accel_std, scenario.period, n, k_target)
    target_ecef = geometry.enu_to_ecef(target, fc[0], fc[1], fc[2])
    raws, sites, enus = [], [], []
    noise = jax.random.normal(k_noise, (2, n, 3), dtype) * jnp.broadcast_to(scenario.noise_std[:, None, :], (2, n, 3))
    noise = noise * (1.0 if measurement_noise else 0.0)
    for i, k_ship in enumerate(jax.random.split(k_ships, 2)):
        s0 = scenario.ship_sites[i]
        # Each ship moves in its own initial ENU; its geodetic site is re-derived every scan
        # (spec §6 item 16), which gives T_i(k) and X_is(k).
        ship = _cv_positions(scenario.ship_states[i], proc * scenario.ship_accel_std, scenario.period, n, k_ship)
        lat, lon, h = geometry.ecef_to_geodetic(geometry.enu_to_ecef(ship, s0[0], s0[1], s0[2]))
        x_enu = geometry.ecef_to_enu(target_ecef, lat, lon, h)
        x_p = geometry.rotate(jnp.swapaxes(attitude_matrix(scenario.attitude_bias[i]), -1, -2), x_enu)  # eq. (6)
        true = geometry.cartesian_to_compass_spherical(x_p)
        ob = scenario.offset_bias[i]
        w = noise[i]
        raw = jnp.stack(
            [
                (1.0 + ob[1]) * true[:, 0] + ob[0] + w[:, 0],
                wrap_angle(true[:, 1] + ob[2] + w[:, 1]),
                true[:, 2] + ob[3] + w[:, 2],
            ],
            axis=-1,
        )
        raws.append(raw)
        sites.append(jnp.stack([lat, lon, h], axis=-1))
        enus.append(x_enu)
    return Scans(jnp.stack(raws), jnp.stack(sites), jnp.stack(enus))


_simulate_jit = eqx.filter_jit(simulate_run)


def simulate_scans(scenario: Scenario, key: PRNGKeyArray, *, measurement_noise: bool = True,
                   process_noise: bool = True) -> Scans:
    """Simulate one run of ``scenario``: ship and target tracks, raw biased noisy measurements (§4.2–4.3).

    Truth → raw (spec §1.6 [R]): ``X_ENU,i = T_iᵀ(X_tgt − X_is)``, ``X_p,i = T_ENU2p(α_i) X_ENU,i``,
    ``(r_t, θ_t, ε_t) = cart2radar(X_p,i)``, ``r = (1 + k_r) r_t + Δr + δ_r``, ``θ = θ_t + Δθ + δ_θ``
    (wrapped), ``ε = ε_t + Δε + δ_ε``. Scan k is at ``t = (k−1)T``.

    **Arguments:** ``scenario``; ``key``; ``measurement_noise=False`` / ``process_noise=False``
    switch the two noise sources off (the deterministic track of V8, V11, V13); use
    :func:`bias_free` for a bias-free run.

    **Returns:** :class:`Scans`.
    """
    if not isinstance(scenario, Scenario):
        raise InputError(f"`scenario` must be a Scenario; got {type(scenario).__name__}.")
    return _simulate_jit(scenario, key, bool(measurement_noise), bool(process_noise))


class RegistrationInputs(eqx.Module):
    """Per-scan inputs of the registration filters (eqs 17–18).

    - ``Z`` ``(K, 3)``: pseudo-measurements, m.
    - ``H`` ``(K, 3, 14)``: H_AAM (OBEM uses :func:`obem_columns` of it).
    - ``R`` ``(K, 3, 3)``: pseudo-measurement noise covariance, m².
    """

    Z: Float[Array, "K 3"]
    H: Float[Array, "K 3 14"]
    R: Float[Array, "K 3 3"]


def _registration_inputs(scans: Scans, noise_std: Array) -> RegistrationInputs:
    terms = jax.vmap(registration_terms)(scans.raw[0], scans.sites[0], scans.raw[1], scans.sites[1])
    return RegistrationInputs(terms.pseudo_measurement, terms.measurement_matrix,
                              pseudo_measurement_noise_cov(terms.noise_matrix, noise_std))


_registration_inputs_jit = jax.jit(_registration_inputs)


def registration_inputs(scans: Scans, noise_std: ArrayLike) -> RegistrationInputs:
    """Z, H_AAM and R (eqs 17–18, spec §2.2 [R]) at every scan of ``scans``.

    **Arguments:** ``scans`` (:func:`simulate_scans`); ``noise_std`` ``(2, 3)`` per radar
    ``[σ_r (m), σ_θ (rad), σ_ε (rad)]``.

    **Returns:** :class:`RegistrationInputs`.
    """
    if not isinstance(scans, Scans):
        raise InputError(f"`scans` must be Scans (from simulate_scans); got {type(scans).__name__}.")
    check_shape("noise_std", noise_std, [(2, 3)])
    return _registration_inputs_jit(scans, noise_std)
