"""Sec. 2: absolute spherical biases of two radars from their relative bias (eqs 3–41, spec §2).

Two radars see the same target; the relative bias ``B_R = B_2 − B_1`` (rectangular, ENU of
sensor 1, eq. 6) is measurable, the absolute spherical biases ``e_i = (Δr_i, Δψ_i, Δθ_i)`` are
not. The minimum-cost pair under the weighted quadratic cost (13) subject to
``A2 e2 − A1 e1 = B_R`` (16) is

    S_c = A1 D1⁻¹ A1' + A2 D2⁻¹ A2',  a = S_c⁻¹ B_R,  e1 = −D1⁻¹ A1' a,  e2 = D2⁻¹ A2' a,

with Lagrange multipliers ``a = ∂F*/∂B_R``. :func:`absolute_bias` solves it three ways
(``method="compact" | "paper" | "kkt"``; the KKT one is the library's
:func:`jaxtrack.estimation.equality_constrained_lsq`), and with a rotation
``R21 = T_ENU(2)2ENU(1)`` for real, non-parallel sensor sites (spec §2.6). Frames come from
:mod:`jaxtrack.geometry`. **Sign convention (§2):** bias = true − measured, i.e. the correction
added to a measurement, ``P_T = P_i + B_i``.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, ArrayLike, Float

from ... import geometry
from ..._validation import InputError, check_shape, check_finite, is_concrete
from ...estimation import equality_constrained_lsq


def _real(x) -> Array:
    """``x`` as a floating array, keeping its precision (Python scalars: the default float)."""
    x = jnp.asarray(x)
    return x.astype(jnp.result_type(x, float))


class SensorGeometry(eqx.Module):
    """Line of sight from a sensor to the target, in that sensor's ENU frame (eqs 11–12, A5, A7).

    - ``slant_range``: ``p_Ti``, sensor-to-target distance, m (from the *measured* position).
    - ``azimuth``: ψ_i, from East towards North, rad.
    - ``elevation``: θ_i, above the horizontal plane, rad.
    """

    slant_range: Float[Array, ""]
    azimuth: Float[Array, ""]
    elevation: Float[Array, ""]

    def __init__(self, slant_range: ArrayLike, azimuth: ArrayLike, elevation: ArrayLike):
        self.slant_range, self.azimuth, self.elevation = (jnp.asarray(v) for v in (slant_range, azimuth, elevation))


class Site(eqx.Module):
    """A sensor site on WGS-84: geodetic ``latitude`` and ``longitude`` (rad), ``height`` (m)."""

    latitude: Float[Array, ""]
    longitude: Float[Array, ""]
    height: Float[Array, ""]

    def __init__(self, latitude: ArrayLike, longitude: ArrayLike, height: ArrayLike = 0.0):
        self.latitude, self.longitude, self.height = (jnp.asarray(v) for v in (latitude, longitude, height))


class AbsoluteBias(eqx.Module):
    """Minimum-cost absolute biases consistent with a relative bias (Sec. 2).

    - ``e1``, ``e2``: ``(3,)`` spherical biases ``[Δr (m), Δψ (rad), Δθ (rad)]`` of sensors 1, 2.
      Δψ is a face cross-range angle (cross-range ``p Δψ``, no ``cos θ``; spec A6).
    - ``multipliers``: ``(3,)`` Lagrange multipliers ``a`` of the E, N, U constraints (28), m;
      equal to ``∂F*/∂B_R``.
    - ``cost``: ``F(e*)`` of eq. (13), m².
    - ``bias1_enu``: ``(3,)`` ``B_1 = A1 e1`` in ENU(1), m.
    - ``bias2_enu``: ``(3,)`` ``B_2 = A2 e2`` in ENU(2) (its own frame), m.
    """

    e1: Float[Array, "3"]
    e2: Float[Array, "3"]
    multipliers: Float[Array, "3"]
    cost: Float[Array, ""]
    bias1_enu: Float[Array, "3"]
    bias2_enu: Float[Array, "3"]


def _face_matrix(sensor: SensorGeometry) -> Array:
    return geometry.face_bias_matrix(sensor.slant_range, sensor.azimuth, sensor.elevation)


def _as_rotation(rotation_21, dtype) -> Array:
    return jnp.eye(3, dtype=dtype) if rotation_21 is None else jnp.asarray(rotation_21, dtype=dtype)


def constraint_jacobian(sensor1: SensorGeometry, sensor2: SensorGeometry, rotation_21=None) -> Array:
    """``J = [−A1, R21 A2]`` (3×6): the constraint (16)–(17) is ``J e = B_R``; rows are ∇G_E', ∇G_N', ∇G_U' (25)–(27).

    ``R21 = T_ENU(2)2ENU(1)`` (default identity: the paper's parallel frames, spec A4/§2.6).
    Columns are in m per (m, rad, rad), ordered ``(Δr1, Δψ1, Δθ1, Δr2, Δψ2, Δθ2)``.

    **Arguments:**

    - ``sensor1``, ``sensor2``: the :class:`SensorGeometry` of each radar (m, rad).
    - ``rotation_21``: optional ``R21``, ``(3, 3)`` (default: identity).

    **Returns:** ``J``, shape ``(3, 6)``: m per m in the range columns, m per rad in the angle columns.
    """
    a1 = _face_matrix(sensor1)
    a2 = _face_matrix(sensor2)
    return jnp.concatenate([-a1, _as_rotation(rotation_21, a2.dtype) @ a2], axis=1)


def bias_cost(e: ArrayLike, weights_sq: ArrayLike) -> Array:
    """The cost (13)/(33): ``F = ½ e' D e`` with ``D = diag(k²)``, m².

    ``e`` ``(6,)`` = ``(Δr1, Δψ1, Δθ1, Δr2, Δψ2, Δθ2)``; ``weights_sq`` ``(6,)`` =
    ``(k_r1², k_ψ1², k_θ1², k_r2², k_ψ2², k_θ2²)`` (the paper prints the squares, spec A11).

    **Arguments:**

    - ``e``: the biases, ``(6,)``, (m, rad, rad, m, rad, rad).
    - ``weights_sq``: the squared weights, ``(6,)`` (unitless for ranges, m²/rad² for angles).

    **Returns:** ``F``, a scalar, m².
    """
    e = jnp.asarray(e)
    return 0.5 * jnp.sum(jnp.asarray(weights_sq) * e * e)


def printed_cost(e: ArrayLike, weights_sq: ArrayLike) -> Array:
    """The paper's printed "Cost": ``Σ e_j² / k_j²`` (spec A8), *not* F of eq. (13).

    ``½ e' diag(2/k²) e`` is (14)'s quadratic form without the matrix inverse; the paper's
    optimiser minimises (13) (its e* prove it), but its tables print this number. Kept only to
    reproduce and expose that discrepancy.

    **Arguments:**

    - ``e``: the biases, ``(6,)``, (m, rad, rad, m, rad, rad).
    - ``weights_sq``: the squared weights ``k²``, ``(6,)``, as in :func:`bias_cost`.

    **Returns:** the printed cost, a scalar (mixed units, as printed by the paper).
    """
    e = jnp.asarray(e)
    return jnp.sum(e * e / jnp.asarray(weights_sq))


def _compact(b_r, a1, a2r, d1, d2):
    # S_c is SPD (spec §2.4); a = S_c⁻¹ B_R and e = D⁻¹ J' a is the minimum-D-norm solution.
    s_c = a1 @ (a1.T / d1[:, None]) + a2r @ (a2r.T / d2[:, None])
    a = jnp.linalg.solve(s_c, b_r)
    return -(a1.T @ a) / d1, (a2r.T @ a) / d2, a


def _paper(b_r, a1, a2r, d1, d2):
    # (36)–(41) with A2 → R21 A2: M1 = −A1', M2 = (R21 A2)'.
    m1 = -a1.T
    m2 = a2r.T
    d1m, d2inv = jnp.diag(d1), jnp.diag(1.0 / d2)
    coupling = d2inv @ m2 @ jnp.linalg.solve(m1, d1m)  # D2⁻¹ M2 M1⁻¹ D1, (38)
    a2inv_a1 = jnp.linalg.solve(a2r, a1)
    e1 = jnp.linalg.solve(coupling - a2inv_a1, jnp.linalg.solve(a2r, b_r))  # (41)
    e2 = coupling @ e1  # (38)
    a = jnp.linalg.solve(m1, d1m @ e1)  # (36)
    return e1, e2, a


def _kkt(b_r, a1, a2r, d1, d2):
    sol = equality_constrained_lsq(jnp.concatenate([d1, d2]), jnp.concatenate([-a1, a2r], axis=1), b_r)
    return sol.solution[:3], sol.solution[3:], sol.multipliers


_METHODS = {"compact": _compact, "paper": _paper, "kkt": _kkt}


def _check_bias_inputs(relative_bias, sensor1, sensor2, weights_sq, rotation_21, method):
    if method not in _METHODS:
        raise InputError(f"`method` must be one of {sorted(_METHODS)}; got {method!r}.")
    check_shape("relative_bias", relative_bias, [(3,)])
    check_shape("weights_sq", weights_sq, [(6,)])
    check_finite("relative_bias", relative_bias)
    if rotation_21 is not None:
        check_shape("rotation_21", rotation_21, [(3, 3)])
    for name, sensor in (("sensor1", sensor1), ("sensor2", sensor2)):
        if not isinstance(sensor, SensorGeometry):
            raise InputError(f"`{name}` must be a SensorGeometry(slant_range, azimuth, elevation); got {type(sensor).__name__}.")
        for field in ("slant_range", "azimuth", "elevation"):
            check_shape(f"{name}.{field}", getattr(sensor, field), [()])
        if is_concrete(sensor.slant_range) and not float(sensor.slant_range) > 0.0:
            raise InputError(
                f"`{name}.slant_range` must be positive (m); got {float(sensor.slant_range)}. "
                "A zero range makes A(p, ψ, θ) singular (det A = p²)."
            )
    if is_concrete(weights_sq) and not np.all(np.asarray(weights_sq) > 0.0):
        raise InputError(
            f"`weights_sq` (k_r1², k_ψ1², k_θ1², k_r2², k_ψ2², k_θ2²) must all be positive; got {np.asarray(weights_sq)}."
        )


def absolute_bias(
    relative_bias: ArrayLike,
    sensor1: SensorGeometry,
    sensor2: SensorGeometry,
    weights_sq: ArrayLike,
    *,
    rotation_21: ArrayLike | None = None,
    method: str = "compact",
) -> AbsoluteBias:
    """Minimum-cost absolute spherical biases of two sensors from their relative bias (Sec. 2, (13)–(41)).

    Minimises ``F = Σ ½ k_j² e_j²`` (13) subject to ``R21 A2 e2 − A1 e1 = B_R`` (16), where
    ``A_i = A(p_Ti, ψ_i, θ_i)`` (12), :func:`jaxtrack.geometry.face_bias_matrix`. Methods:

    - ``"compact"`` (spec §2.4, the recommended one): ``S_c = A1 D1⁻¹ A1' + R21 A2 D2⁻¹ A2' R21'``,
      ``a = S_c⁻¹ B_R``, ``e1 = −D1⁻¹ A1' a``, ``e2 = D2⁻¹ (R21 A2)' a``;
    - ``"paper"``: (41) then (38), multipliers from (36);
    - ``"kkt"``: the 9×9 KKT system (35) by :func:`equality_constrained_lsq`.

    **Arguments:**

    - ``relative_bias``: ``B_R = B_2 − B_1`` in ENU(1), ``(3,)``, m (eq. 6; :func:`relative_bias`).
    - ``sensor1``, ``sensor2``: :class:`SensorGeometry`, line of sight to the target in each
      sensor's own ENU frame.
    - ``weights_sq``: ``(6,)`` ``(k_r1², k_ψ1², k_θ1², k_r2², k_ψ2², k_θ2²)``; k_r unitless, k_ψ, k_θ
      in m. Larger means a more expensive bias.
    - ``rotation_21``: ``T_ENU(2)2ENU(1)`` ``(3, 3)``; ``None`` is the paper's parallel frames.

    **Returns:** an :class:`AbsoluteBias`. Sign convention: bias = true − measured.

    **Raises:** :class:`~jaxtrack.InputError` for wrong shapes, non-positive weights or ranges.
    """
    _check_bias_inputs(relative_bias, sensor1, sensor2, weights_sq, rotation_21, method)
    return _absolute_bias_jit(relative_bias, sensor1, sensor2, weights_sq, rotation_21, method)


@functools.partial(jax.jit, static_argnames="method")
def _absolute_bias_jit(relative_bias, sensor1, sensor2, weights_sq, rotation_21, method):
    b_r = _real(relative_bias)
    w = jnp.asarray(weights_sq, dtype=b_r.dtype)
    a1 = _face_matrix(sensor1)
    a2 = _face_matrix(sensor2)
    a2r = _as_rotation(rotation_21, a2.dtype) @ a2
    e1, e2, a = _METHODS[method](b_r, a1, a2r, w[:3], w[3:])
    return AbsoluteBias(e1, e2, a, bias_cost(jnp.concatenate([e1, e2]), w), a1 @ e1, a2 @ e2)


def bias_sensitivity(sensor1: SensorGeometry, sensor2: SensorGeometry, weights_sq: ArrayLike, rotation_21=None) -> Array:
    """Analytic ``∂e*/∂B_R = D⁻¹ J' S_c⁻¹`` ``(6, 3)`` (spec §2.4); e* is linear in B_R.

    **Arguments:**

    - ``sensor1``, ``sensor2``: the :class:`SensorGeometry` of each radar (m, rad).
    - ``weights_sq``: the squared weights, ``(6,)``, as in :func:`bias_cost`.
    - ``rotation_21``: optional ``R21``, ``(3, 3)`` (default: identity).

    **Returns:** ``∂e*/∂B_R``, shape ``(6, 3)``: unitless in the range rows, rad/m in the angle rows.
    """
    jac = constraint_jacobian(sensor1, sensor2, rotation_21)
    w = jnp.asarray(weights_sq, dtype=jac.dtype)
    jd = jac / w[None, :]
    return jd.T @ jnp.linalg.inv(jd @ jac.T)


class BiasDescent(eqx.Module):
    """Result of :func:`absolute_bias_by_descent`: ``e`` ``(6,)`` the final iterate
    ``(Δr1, Δψ1, Δθ1, Δr2, Δψ2, Δθ2)`` (m, rad); ``costs`` ``(num_steps,)`` F at every step, m²."""

    e: Float[Array, " 6"]
    costs: Float[Array, " S"]


def absolute_bias_by_descent(
    relative_bias: ArrayLike,
    sensor1: SensorGeometry,
    sensor2: SensorGeometry,
    weights_sq: ArrayLike,
    *,
    rotation_21: ArrayLike | None = None,
    num_steps: int = 100,
    learning_rate: float = 0.5,
) -> BiasDescent:
    """e* by gradient descent (optax) on the null-space parametrisation of the constraint (V14).

    Variables are scaled, ``u = D^{1/2} e``, so that ``F = ½|u|²`` is isotropic. A feasible start
    ``e_p`` is (20) with ``e1 = 0``; ``u = D^{1/2} e_p + N z`` with ``N`` an orthonormal basis of
    ``null(J D^{-1/2})`` keeps every iterate on the constraint, and ``jax.grad`` of F in ``z``
    drives the descent.

    **Arguments:** as :func:`absolute_bias`; ``num_steps`` SGD steps, ``learning_rate``.

    **Returns:** a :class:`BiasDescent`: the final ``(6,)`` iterate and F at every step, m².
    """
    _check_bias_inputs(relative_bias, sensor1, sensor2, weights_sq, rotation_21, "compact")
    return BiasDescent(*_descent_jit(relative_bias, sensor1, sensor2, weights_sq, rotation_21, num_steps, learning_rate))


@functools.partial(jax.jit, static_argnames="num_steps")
def _descent_jit(relative_bias, sensor1, sensor2, weights_sq, rotation_21, num_steps, learning_rate):
    b_r = _real(relative_bias)
    w = jnp.asarray(weights_sq, dtype=b_r.dtype)
    jac = constraint_jacobian(sensor1, sensor2, rotation_21)
    root = jnp.sqrt(w)
    e_p = jnp.concatenate([jnp.zeros(3, b_r.dtype), jnp.linalg.solve(jac[:, 3:], b_r)])  # (20), e1 = 0
    _, _, vt = jnp.linalg.svd(jac / root[None, :])
    basis = vt[3:].T  # (6, 3) orthonormal null space of J D^{-1/2}
    u_p = root * e_p

    def cost(z):
        return 0.5 * jnp.sum((u_p + basis @ z) ** 2)

    opt = optax.sgd(learning_rate)

    def step(carry, _):
        z, state = carry
        value, grad = jax.value_and_grad(cost)(z)
        updates, state = opt.update(grad, state, z)
        return (optax.apply_updates(z, updates), state), value

    z0 = jnp.zeros(3, b_r.dtype)
    (z, _), costs = jax.lax.scan(step, (z0, opt.init(z0)), None, length=num_steps)
    return (u_p + basis @ z) / root, costs


def relative_bias(p1_enu1: ArrayLike, p2_enu2: ArrayLike, site1: Site, site2: Site) -> Array:
    """Relative bias ``B_R = P_1 − P_1TO2 − P_2`` in ENU(1) from the two measured positions (eq. 6).

    ``P_1`` is sensor 1's measured target position in ENU(1); ``P_2`` sensor 2's in ENU(2), rotated
    into ENU(1) with ``T_ENU(2)2ENU(1)``; ``P_1TO2`` is the site-1-to-site-2 vector in ENU(1)
    (Appendix). Equals ``B_2 − B_1`` in ENU(1) with bias = true − measured.

    **Arguments:** positions ``(..., 3)`` (m), sites as :class:`Site`. **Returns:** ``(..., 3)``, m.
    """
    rot_21 = jnp.swapaxes(geometry.enu_to_enu_rotation(site1.latitude, site1.longitude, site2.latitude, site2.longitude), -1, -2)
    offset = geometry.enu_site_offset(site1.latitude, site1.longitude, site2.latitude, site2.longitude,
                                      site1.height, site2.height, frame=1)
    p2_in_1 = geometry.rotate(rot_21, p2_enu2)
    p1, off, p2 = jnp.broadcast_arrays(jnp.asarray(p1_enu1, dtype=p2_in_1.dtype), offset, p2_in_1)
    return p1 - off - p2


def absolute_bias_from_tracks(
    p1_enu1: ArrayLike,
    p2_enu2: ArrayLike,
    site1: Site,
    site2: Site,
    weights_sq: ArrayLike,
    *,
    method: str = "compact",
) -> AbsoluteBias:
    """The whole Sec. 2 chain for real sensor sites (spec §2.6): positions → B_R → absolute biases.

    ``B_R`` from :func:`relative_bias` (eq. 6); each sensor's line of sight from its *measured*
    position by :func:`jaxtrack.geometry.cartesian_to_spherical` (footnote 2, spec A5/A7);
    ``R21 = T_ENU(2)2ENU(1)`` from the Appendix, so the ENU frames need not be parallel.

    **Arguments:** ``p1_enu1``, ``p2_enu2`` ``(3,)`` measured target positions (m) in each sensor's
    ENU frame; the two :class:`Site`; ``weights_sq`` as in :func:`absolute_bias`.
    """
    check_shape("p1_enu1", p1_enu1, [(3,)])
    check_shape("p2_enu2", p2_enu2, [(3,)])
    b_r = relative_bias(p1_enu1, p2_enu2, site1, site2)
    s1 = SensorGeometry(*geometry.cartesian_to_spherical(_real(p1_enu1)))
    s2 = SensorGeometry(*geometry.cartesian_to_spherical(_real(p2_enu2)))
    rot_21 = geometry.enu_to_enu_rotation(site2.latitude, site2.longitude, site1.latitude, site1.longitude)
    return absolute_bias(b_r, s1, s2, weights_sq, rotation_21=rot_21, method=method)


