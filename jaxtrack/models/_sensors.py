"""Sensor measurement models: range–bearing, bearings-only and 3-D radar, with optional range rate.

Each model is an :class:`~jaxtrack.models.AbstractMeasurementModel` for a sensor with a position,
a velocity and an orientation, so it composes with any transition model in a
:class:`~jaxtrack.models.TrackingModel`::

    radar = RangeAzimuthElevation(noise_std=(10.0, 1e-3, 1e-3), sensor_position=(0.0, 0.0, 5.0),
                                  world_to_sensor_rotation=sensor_rotation(yaw=0.3, pitch=0.05))

Geometry (one convention, that of :mod:`jaxtrack.geometry`). With ``p`` the target position and
``v`` its velocity (read from the state at ``position_indices`` / ``velocity_indices``), ``s`` and
``ṡ`` the sensor's position and velocity, and ``C`` the world-to-sensor rotation
(``d_sensor = C d_world``, the ``a_to_b_rotation`` convention of :mod:`jaxtrack.geometry`):

- relative position ``d = p − s`` (world), in the sensor frame ``[x_s, y_s(, z_s)] = C d``;
- range ``r = ‖d‖`` and range rate ``ṙ = dᵀ(v − ṡ)/r`` (both frame-independent);
- azimuth, measured in the sensor frame's horizontal (x_s, y_s) plane:

  * ``azimuth="math"`` (default): ``atan2(y_s, x_s)``, counter-clockwise from the sensor's +x axis
    (from East with the identity orientation) — the convention of Stone Soup, ``atan2`` and
    :func:`jaxtrack.geometry.cartesian_to_spherical`;
  * ``azimuth="compass"``: ``atan2(x_s, y_s)``, clockwise from the sensor's +y axis (from North
    with the identity orientation), as radars report it and as
    :func:`jaxtrack.geometry.cartesian_to_compass_spherical`; it equals ``π/2 − math`` wrapped;

- elevation ``atan2(z_s, √(x_s² + y_s²))``, up from the sensor's horizontal plane.

Angles are wrapped to (−π, π] and listed in ``angle_components``, so filter residuals wrap.

Every parameter (noise, sensor pose, bias) is an array leaf: ``jax.grad`` with respect to it works
through any filter. Sensor pose and noise may be constant or per step (a leading axis ``T``,
indexed by the step ``k`` as :func:`jaxtrack.models.at_step`), so a moving sensor works;
``num_steps`` reports ``T``. Jacobians are analytic (the derivatives are written out in
:func:`_azimuth_row` etc.).

**Degenerate geometry.** At range 0 (target on the sensor) the values are finite: range and
range rate 0, angles 0 (elevation ±π/2 straight above or below the sensor, azimuth 0 there), and
so are their ``jax.grad`` (0). The Jacobian is undefined there — and for
:class:`RangeAzimuthElevation` on the sensor's vertical axis, where the azimuth is — so
:meth:`~_AbstractSensor.jacobian` returns NaN at such a point: an extended (or iterated) Kalman
filter linearised there fails loudly (``ok=False``, or the filter's error naming this cause)
instead of running with a zero row that silently ignores every measurement. The usual way in is
an "uninformed" prior mean on the sensor (e.g. mean 0 with the radar at the origin): give the
prior mean anywhere else (e.g. a first measurement converted to position), or use an unscented
filter, which needs no Jacobian. A measurement component marked missing never fails the update.
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from .._validation import InputError, check_covariance, check_finite, check_shape, is_concrete, nan_where_traced
from ..geometry import rotation_x, rotation_y, rotation_z
from ._atan2 import atan2
from ._base import _num_steps_of, at_step, wrap_angle
from ._components import AbstractMeasurementModel
from ._layout import AXES, indices_of
from ._layout import position_indices as position_indices_of

__all__ = ["RangeBearing", "Bearing", "RangeAzimuthElevation", "sensor_rotation"]

_AZIMUTH_CONVENTIONS = ("math", "compass")


# ----------------------------------------------------------------------------------------------
# Geometry with safe derivatives
# ----------------------------------------------------------------------------------------------


def _rotate(C: Array, d: Array) -> Array:
    """``C @ d`` for a small matrix, as a sum of scaled columns.

    Under ``vmap`` with ``C`` shared by the batch, ``@`` is a separate matrix-product kernel;
    the sum is element-wise and fuses with the trigonometry around it.
    """
    out = C[:, 0] * d[0]
    for j in range(1, d.shape[0]):
        out = out + C[:, j] * d[j]
    return out


def _dot(a: Array, b: Array) -> Array:
    """``a · b`` of two short vectors as adds (a batched ``@`` is a separate kernel under ``vmap``)."""
    out = a[0] * b[0]
    for j in range(1, a.shape[0]):
        out = out + a[j] * b[j]
    return out


def _take(x: Array, indices: tuple[int, ...]) -> Array:
    """``x[indices]`` for a static index tuple, as static slices."""
    return jnp.stack([x[i] for i in indices])


def _safe_norm(d: Array) -> tuple[Array, Array]:
    """``(‖d‖, 1/‖d‖)`` with ``1/‖d‖ := 0`` and a zero (not NaN) gradient at ``d = 0``."""
    r2 = _dot(d, d)
    pos = r2 > 0
    r = jnp.where(pos, jnp.sqrt(jnp.where(pos, r2, 1.0)), 0.0)
    inv_r = jnp.where(pos, 1.0 / jnp.where(pos, r, 1.0), 0.0)
    return r, inv_r


def _safe_atan2(y: Array, x: Array) -> Array:
    """``atan2(y, x)``, 0 with a zero gradient at the undefined point ``y = x = 0``."""
    zero = (y == 0) & (x == 0)
    # The polynomial atan2 (models/_atan2.py): XLA's costs 6x more, and a radar's angles at every
    # sigma point were the largest cost of a UKF step.
    return jnp.where(zero, 0.0, atan2(jnp.where(zero, 0.0, y), jnp.where(zero, 1.0, x)))


def _azimuth_row(ds: Array, convention: str) -> tuple[Array, Array]:
    """Azimuth of the sensor-frame vector ``ds`` and its gradient with respect to ``ds``.

    ``∂atan2(y, x)/∂(x, y) = (−y, x)/ρ²``, ``ρ² = x² + y²``; the compass azimuth
    ``atan2(x, y) = π/2 − atan2(y, x)`` (mod 2π) has the opposite gradient. Undefined at ρ = 0
    (returned as 0 there).
    """
    x, y = ds[0], ds[1]
    rho2 = x * x + y * y
    pos = rho2 > 0
    inv_rho2 = jnp.where(pos, 1.0 / jnp.where(pos, rho2, 1.0), 0.0)
    grad = jnp.zeros_like(ds).at[0].set(-y * inv_rho2).at[1].set(x * inv_rho2)
    if convention == "math":
        return _safe_atan2(y, x), grad
    return _safe_atan2(x, y), -grad


def _elevation_row(ds: Array) -> tuple[Array, Array]:
    """Elevation ``atan2(z, ρ)`` of the sensor-frame 3-vector ``ds`` and its gradient.

    ``∂ε/∂(x, y, z) = (−x z/(ρ r²), −y z/(ρ r²), ρ/r²)``; the horizontal derivatives are
    undefined on the vertical axis ρ = 0 (returned as 0 there).
    """
    x, y, z = ds[0], ds[1], ds[2]
    rho, inv_rho = _safe_norm(ds[:2])
    _, inv_r = _safe_norm(ds)
    inv_r2 = inv_r * inv_r
    el = _safe_atan2(z, rho)
    grad = jnp.stack([-x * z * inv_rho * inv_r2, -y * z * inv_rho * inv_r2, rho * inv_r2])
    return el, grad


# ----------------------------------------------------------------------------------------------
# Orientation helper
# ----------------------------------------------------------------------------------------------


def sensor_rotation(yaw: ArrayLike = 0.0, pitch: ArrayLike = 0.0, roll: ArrayLike = 0.0) -> Float[Array, "*T 3 3"]:
    """The world-to-sensor rotation ``C`` of a sensor turned by yaw, then pitch, then roll.

    The sensor frame is the world frame turned, in this order, by ``yaw`` about the world +z axis
    (counter-clockwise seen from above, the mathematical sense), by ``pitch`` about the new y
    axis with positive pitch raising the boresight (+x) towards +z, and by ``roll`` about the
    new x axis (right-handed). In the active convention of :mod:`jaxtrack.geometry`,

    ``sensor_to_world = rotation_z(yaw) @ rotation_y(−pitch) @ rotation_x(roll)`` and
    ``C = sensor_to_world.T = rotation_x(−roll) @ rotation_y(pitch) @ rotation_z(−yaw)``.

    This is the matrix Stone Soup builds from ``rotation_offset = [roll, pitch, yaw]``
    (``stonesoup.functions.build_rotation_matrix``), so a Stone Soup sensor maps one-to-one.

    **Arguments:** ``yaw``, ``pitch``, ``roll`` (rad), broadcast-compatible shapes ``()`` or
    ``(T,)`` for a sensor whose attitude changes per step.

    **Returns:** ``C``, shape ``(3, 3)`` or ``(T, 3, 3)``, with ``d_sensor = C @ d_world``.
    """
    yaw, pitch, roll = (jnp.asarray(a) for a in (yaw, pitch, roll))
    dtype = jnp.result_type(yaw, pitch, roll, float)
    yaw, pitch, roll = jnp.broadcast_arrays(yaw.astype(dtype), pitch.astype(dtype), roll.astype(dtype))
    return rotation_x(-roll) @ rotation_y(pitch) @ rotation_z(-yaw)


# ----------------------------------------------------------------------------------------------
# Construction helpers
# ----------------------------------------------------------------------------------------------


def _check_convention(azimuth: str) -> str:
    if azimuth not in _AZIMUTH_CONVENTIONS:
        raise InputError(
            f"`azimuth` must be one of {_AZIMUTH_CONVENTIONS} ('math': counter-clockwise from +x/East; "
            f"'compass': clockwise from +y/North); got {azimuth!r}."
        )
    return azimuth


def _check_indices(name: str, indices, d: int) -> tuple[int, ...]:
    try:
        idx = tuple(int(i) for i in indices)
    except TypeError as error:
        raise InputError(f"`{name}` must be a tuple of {d} state indices; got {indices!r}.") from error
    if len(idx) != d or len(set(idx)) != d or min(idx) < 0:
        raise InputError(f"`{name}` must be {d} distinct non-negative state indices; got {idx}.")
    return idx


def _noise_arrays(noise_std, noise_cov, m: int, dtype):
    """Validated ``(noise_std, noise_cov)``, exactly one of them not ``None``."""
    if (noise_std is None) == (noise_cov is None):
        raise InputError("give exactly one of `noise_std` (per component) and `noise_cov` (full matrix).")
    if noise_std is not None:
        std = jnp.asarray(noise_std).astype(dtype)
        check_shape("noise_std", std, [(m,), (None, m)])
        check_finite("noise_std", std)
        if is_concrete(std) and np.any(np.asarray(std) < 0):
            raise InputError(f"`noise_std` must be non-negative; got {np.asarray(std)}.")
        return nan_where_traced(std, lambda a: a < 0), None
    cov = jnp.asarray(noise_cov).astype(dtype)
    check_shape("noise_cov", cov, [(m, m), (None, m, m)])
    check_covariance("noise_cov", cov)
    return None, cov


def _vector(name: str, value, d: int, dtype, default_shape=None):
    """A ``(d,)`` or ``(T, d)`` float array (zeros when ``value`` is None)."""
    if value is None:
        return jnp.zeros(default_shape or (d,), dtype)
    a = jnp.asarray(value).astype(dtype)
    check_shape(name, a, [(d,), (None, d)])
    check_finite(name, a)
    return a


def _dtype(*values) -> jnp.dtype:
    return jnp.result_type(*[jnp.asarray(v) for v in values if v is not None], float)


# ----------------------------------------------------------------------------------------------
# Shared machinery
# ----------------------------------------------------------------------------------------------


class _AbstractSensor(AbstractMeasurementModel):
    """Shared noise, pose and bias handling of the sensor models (not public)."""

    noise_std: eqx.AbstractVar[Float[Array, "*T m"] | None]
    R: eqx.AbstractVar[Float[Array, "*T m m"] | None]
    sensor_position: eqx.AbstractVar[Float[Array, "*T d"]]
    sensor_velocity: eqx.AbstractVar[Float[Array, "*T d"]]
    bias: eqx.AbstractVar[Float[Array, "*T m"]]
    position_indices: eqx.AbstractVar[tuple[int, ...]]
    velocity_indices: eqx.AbstractVar[tuple[int, ...]]
    range_rate: eqx.AbstractVar[bool]
    azimuth: eqx.AbstractVar[str]

    def noise_cov(self, k: Int[ArrayLike, ""]) -> Float[Array, "m m"]:
        """``R_k``: ``diag(noise_std_k²)`` or the full ``noise_cov`` at step ``k``."""
        if self.noise_std is not None:
            return jnp.diag(jnp.square(at_step(self.noise_std, k, 1)))
        return at_step(self.R, k, 2)

    @property
    def meas_dim(self) -> int:
        return self.bias.shape[-1]

    @abc.abstractmethod
    def _orientation_arrays(self) -> dict:
        """``name=(array, rank of one step)`` of the orientation leaves, for ``num_steps``."""

    @property
    def num_steps(self) -> int | None:
        return _num_steps_of(
            noise_std=(self.noise_std, 1),
            noise_cov=(self.R, 2),
            sensor_position=(self.sensor_position, 1),
            sensor_velocity=(self.sensor_velocity, 1),
            bias=(self.bias, 1),
            **self._orientation_arrays(),
        )

    def check_state_layout(self, layout: tuple[str, ...]) -> None:
        """``InputError`` unless ``position_indices`` read the positions ``x, y(, z)`` of ``layout``
        (and, with ``range_rate``, ``velocity_indices`` the velocities ``vx, vy(, vz)``).

        A layout that names no position (a state of other quantities) is not checked.
        """
        d = len(self.position_indices)
        checks = [("position_indices", self.position_indices, AXES[:d])]
        if self.range_rate:
            checks.append(("velocity_indices", self.velocity_indices, tuple("v" + a for a in AXES[:d])))
        for name, idx, want in checks:
            if not any(c in layout for c in want):
                continue
            if max(idx) >= len(layout):
                raise InputError(f"`{name}` {idx} do not fit the state of {len(layout)} components {layout}.")
            got = tuple(layout[i] for i in idx)
            if got != want:
                where = indices_of(layout, want)
                fix = (f"pass {name}={where}" if where is not None else
                       f"the state has no {want}: use a {d}-axis motion model or a sensor of "
                       f"{len(position_indices_of(layout))} axes")
                raise InputError(
                    f"{type(self).__name__}'s `{name}` {idx} read {got} of the state {layout}; a "
                    f"{d}-axis sensor needs {want} ({fix})."
                )

    def _check_state(self, x: Array) -> None:
        # Static: an out-of-range index would be clamped silently by jnp indexing.
        n = x.shape[-1]
        used = self.position_indices + (self.velocity_indices if self.range_rate else ())
        if max(used) >= n:
            raise InputError(
                f"`position_indices`/`velocity_indices` {used} do not fit a state of dimension {n}."
            )

    def _relative(self, x: Array, k) -> tuple[Array, Array | None]:
        """``d = p − s`` and (with range rate) ``u = v − ṡ``, world frame."""
        self._check_state(x)
        # Static indices read one by one: a gather with an index array is a per-element kernel
        # under `vmap` on CPU, static slices fuse with the arithmetic around them.
        d = _take(x, self.position_indices) - at_step(self.sensor_position, k, 1)
        u = None
        if self.range_rate:
            u = _take(x, self.velocity_indices) - at_step(self.sensor_velocity, k, 1)
        return d, u

    @abc.abstractmethod
    def _rows(self, x: Array, k) -> list[tuple[Array, Array, Array | None]]:
        """``(value, ∂/∂p, ∂/∂v or None)`` for each measurement component (world frame)."""

    def _range_rate_row(self, d: Array, u: Array) -> tuple[Array, Array, Array]:
        # ṙ = dᵀu/r;  ∂ṙ/∂p = (u − ṙ d/r)/r;  ∂ṙ/∂v = d/r.
        _, inv_r = _safe_norm(d)
        rdot = _dot(d, u) * inv_r
        return rdot, (u - rdot * d * inv_r) * inv_r, d * inv_r

    def mean(self, x: Float[Array, " n"], k: Int[ArrayLike, ""]) -> Float[Array, " m"]:
        """``h_k(x)`` + bias, angle components wrapped to (−π, π]."""
        rows = self._rows(x, k)
        is_angle = np.isin(np.arange(len(rows)), self.angle_components)
        bias = at_step(self.bias, k, 1)
        # The angles from atan2 lie in (−π, π]; with the bias wrapped first (it is shared by the
        # runs of a batch, so this costs nothing per run) their sum lies in (−2π, 2π], and one
        # shift by 2π wraps it: cheaper than a general remainder per sigma point and run.
        z = jnp.stack([row[0] for row in rows]) + jnp.where(is_angle, wrap_angle(bias), bias)
        two_pi = 2 * jnp.pi
        shift = jnp.where(z > jnp.pi, -two_pi, jnp.where(z <= -jnp.pi, two_pi, 0.0))
        return jnp.where(is_angle, z + shift, z)

    def _undefined(self, x: Array, k) -> Array:
        """Whether the Jacobian at ``x`` is undefined: the target on the sensor (range 0)."""
        d, _ = self._relative(x, k)
        return jnp.all(d == 0)

    def jacobian(self, x: Float[Array, " n"], k: Int[ArrayLike, ""]) -> Float[Array, "m n"]:
        """The analytic ``∂h_k/∂x``; all NaN where it is undefined (see *Degenerate geometry* in
        the module docstring: a linearisation there must fail, not ignore the measurement)."""
        H = self._jacobian(x, k)
        return jnp.where(self._undefined(x, k), jnp.nan, H)

    def _jacobian(self, x: Array, k) -> Array:
        rows = self._rows(x, k)
        Hp = jnp.stack([row[1] for row in rows])
        # Columns placed by static index (no scatter): position columns, then velocity columns.
        zero = jnp.zeros((len(rows),), Hp.dtype)
        columns = [zero] * x.shape[-1]
        for j, i in enumerate(self.position_indices):
            columns[i] = Hp[:, j]
        if self.range_rate:
            Hv = jnp.stack([jnp.zeros_like(rows[0][1]) if row[2] is None else row[2] for row in rows])
            for j, i in enumerate(self.velocity_indices):
                columns[i] = columns[i] + Hv[:, j]
        return jnp.stack(columns, axis=1)


def _init_common(self, d, m, noise_std, noise_cov, sensor_position, sensor_velocity, bias,
                 position_indices, velocity_indices, range_rate, azimuth, dtype):
    self.noise_std, self.R = _noise_arrays(noise_std, noise_cov, m, dtype)
    self.sensor_position = _vector("sensor_position", sensor_position, d, dtype)
    self.sensor_velocity = _vector("sensor_velocity", sensor_velocity, d, dtype)
    self.bias = _vector("bias", bias, m, dtype)
    self.range_rate = bool(range_rate)
    self.azimuth = _check_convention(azimuth)
    self.position_indices = _check_indices(
        "position_indices", tuple(range(d)) if position_indices is None else position_indices, d)
    if velocity_indices is None:
        velocity_indices = tuple(range(d, 2 * d))
    self.velocity_indices = _check_indices("velocity_indices", velocity_indices, d)


def _rotation_2d(yaw: Array) -> Array:
    """World-to-sensor rotation in the plane for a sensor turned by ``yaw`` (counter-clockwise)."""
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    return jnp.stack([jnp.stack([c, s]), jnp.stack([-s, c])])


_COMMON_ARGS_DOC = """    - ``noise_std``: per-component noise standard deviations ``(m,)`` or ``(T, m)`` (metres,
      radians, m/s; non-negative), or
    - ``noise_cov``: the full covariance ``(m, m)`` or ``(T, m, m)`` (give exactly one).
    - ``sensor_position`` ``(d,)`` or ``(T, d)`` (m, world frame; default 0).
    - ``sensor_velocity`` ``(d,)`` or ``(T, d)`` (m/s; used by the range rate; default 0).
    - ``bias``: additive measurement bias ``(m,)`` or ``(T, m)`` (default 0): ``z = h(x) + b + v``.
    - ``range_rate`` (static): append the range rate ``ṙ = dᵀ(v − ṡ)/r`` (m/s) as the last component.
    - ``azimuth`` (static): ``"math"`` (default; counter-clockwise from the sensor's +x, i.e. from
      East unrotated) or ``"compass"`` (clockwise from the sensor's +y, i.e. from North unrotated).
    - ``position_indices`` / ``velocity_indices`` (static): where the target's position and velocity
      sit in the state; default jaxtrack's kinematic layout ``[x, y(, z), vx, vy(, vz)]``
      (positions ``0..d-1``, velocities ``d..2d-1``). Any layout works, e.g. a nearly-constant-turn
      state ``[x, y, speed, heading, ω]`` with ``position_indices=(0, 1)`` (range rate then needs
      the velocity components in the state).
"""


def _document(cls):
    """Fill the shared argument list into a sensor class docstring (one text for all three)."""
    cls.__doc__ = cls.__doc__.replace("{common_args}", _COMMON_ARGS_DOC.strip("\n").lstrip())
    return cls


@_document
class RangeBearing(_AbstractSensor):
    r"""2-D range–bearing sensor: ``z = [r, φ(, ṙ)] + b + v``, ``v ~ N(0, R)``.

    ``r = ‖p − s‖``; ``φ`` the azimuth of ``C (p − s)`` with ``C`` the planar world-to-sensor
    rotation of a sensor turned counter-clockwise by ``sensor_yaw``; ``ṙ`` the range rate. See the
    module docstring for the conventions; it is Stone Soup's ``CartesianToBearingRange`` (and
    ``CartesianToBearingRangeRate2D``) with the components reordered ``[r, φ]`` and
    ``rotation_offset = [0, 0, sensor_yaw]``.

    **Arguments** (``d = 2``, ``m = 2`` or ``3`` with range rate):

    {common_args}
    - ``sensor_yaw``: the sensor frame's rotation from the world frame, counter-clockwise (rad),
      shape ``()`` or ``(T,)`` (default 0; independent of the azimuth convention).

    ``angle_components = (1,)``.

    **Raises:** ``InputError`` naming the argument on wrong shapes, negative ``noise_std``, a
    non-covariance ``noise_cov``, an unknown ``azimuth`` or bad indices.
    """

    noise_std: Float[Array, "*T m"] | None
    R: Float[Array, "*T m m"] | None
    sensor_position: Float[Array, "*T 2"]
    sensor_velocity: Float[Array, "*T 2"]
    sensor_yaw: Float[Array, "*T"]
    bias: Float[Array, "*T m"]
    position_indices: tuple[int, ...] = eqx.field(static=True)
    velocity_indices: tuple[int, ...] = eqx.field(static=True)
    range_rate: bool = eqx.field(static=True)
    azimuth: str = eqx.field(static=True)
    angle_components: tuple[int, ...] = eqx.field(static=True)

    def __init__(self, noise_std=None, *, noise_cov=None, sensor_position=None, sensor_velocity=None,
                 sensor_yaw=0.0, bias=None, range_rate: bool = False, azimuth: str = "math",
                 position_indices=None, velocity_indices=None):
        m = 3 if range_rate else 2
        dtype = _dtype(noise_std, noise_cov, sensor_position, sensor_velocity, sensor_yaw, bias)
        _init_common(self, 2, m, noise_std, noise_cov, sensor_position, sensor_velocity, bias,
                     position_indices, velocity_indices, range_rate, azimuth, dtype)
        yaw = jnp.asarray(sensor_yaw).astype(dtype)
        check_shape("sensor_yaw", yaw, [(), (None,)])
        check_finite("sensor_yaw", yaw)
        self.sensor_yaw = yaw
        self.angle_components = (1,)

    def _orientation_arrays(self) -> dict:
        return {"sensor_yaw": (self.sensor_yaw, 0)}

    def _rows(self, x, k):
        d, u = self._relative(x, k)
        C = _rotation_2d(at_step(self.sensor_yaw, k, 0))
        r, inv_r = _safe_norm(d)
        az, g_az = _azimuth_row(_rotate(C, d), self.azimuth)
        rows = [(r, d * inv_r, None), (az, _rotate(C.T, g_az), None)]
        if self.range_rate:
            rows.append(self._range_rate_row(d, u))
        return rows


@_document
class Bearing(_AbstractSensor):
    r"""2-D bearings-only sensor: ``z = [φ(, ṙ)] + b + v``.

    The bearing of :class:`RangeBearing` without the range (Stone Soup's ``Cartesian2DToBearing``);
    with ``range_rate=True`` a bearing–Doppler sensor ``[φ, ṙ]``.

    **Arguments** (``d = 2``, ``m = 1`` or ``2`` with range rate):

    {common_args}
    - ``sensor_yaw``: the sensor frame's rotation from the world frame, counter-clockwise (rad),
      shape ``()`` or ``(T,)`` (default 0).

    ``angle_components = (0,)``.

    **Raises:** as :class:`RangeBearing`.
    """

    noise_std: Float[Array, "*T m"] | None
    R: Float[Array, "*T m m"] | None
    sensor_position: Float[Array, "*T 2"]
    sensor_velocity: Float[Array, "*T 2"]
    sensor_yaw: Float[Array, "*T"]
    bias: Float[Array, "*T m"]
    position_indices: tuple[int, ...] = eqx.field(static=True)
    velocity_indices: tuple[int, ...] = eqx.field(static=True)
    range_rate: bool = eqx.field(static=True)
    azimuth: str = eqx.field(static=True)
    angle_components: tuple[int, ...] = eqx.field(static=True)

    def __init__(self, noise_std=None, *, noise_cov=None, sensor_position=None, sensor_velocity=None,
                 sensor_yaw=0.0, bias=None, range_rate: bool = False, azimuth: str = "math",
                 position_indices=None, velocity_indices=None):
        m = 2 if range_rate else 1
        dtype = _dtype(noise_std, noise_cov, sensor_position, sensor_velocity, sensor_yaw, bias)
        _init_common(self, 2, m, noise_std, noise_cov, sensor_position, sensor_velocity, bias,
                     position_indices, velocity_indices, range_rate, azimuth, dtype)
        yaw = jnp.asarray(sensor_yaw).astype(dtype)
        check_shape("sensor_yaw", yaw, [(), (None,)])
        check_finite("sensor_yaw", yaw)
        self.sensor_yaw = yaw
        self.angle_components = (0,)

    def _orientation_arrays(self) -> dict:
        return {"sensor_yaw": (self.sensor_yaw, 0)}

    def _rows(self, x, k):
        d, u = self._relative(x, k)
        C = _rotation_2d(at_step(self.sensor_yaw, k, 0))
        az, g_az = _azimuth_row(_rotate(C, d), self.azimuth)
        rows = [(az, _rotate(C.T, g_az), None)]
        if self.range_rate:
            rows.append(self._range_rate_row(d, u))
        return rows


@_document
class RangeAzimuthElevation(_AbstractSensor):
    r"""3-D radar: ``z = [r, α, ε(, ṙ)] + b + v``.

    ``r = ‖p − s‖``; azimuth ``α`` and elevation ``ε`` of ``C (p − s)`` in the sensor frame (module
    docstring); ``ṙ`` the range rate. Stone Soup's ``CartesianToElevationBearingRange`` (and
    ``…RangeRate``) with the components reordered ``[r, α, ε]`` and ``C`` from
    :func:`sensor_rotation` (its ``rotation_offset = [roll, pitch, yaw]``).

    **Arguments** (``d = 3``, ``m = 3`` or ``4`` with range rate):

    {common_args}
    - ``world_to_sensor_rotation``: ``C``, ``(3, 3)`` or ``(T, 3, 3)`` (default identity), with
      ``d_sensor = C d_world``; build it from yaw/pitch/roll with :func:`sensor_rotation`. It should
      be a rotation matrix (not checked, so that a traced value is accepted).

    ``angle_components = (1, 2)``.

    **Raises:** as :class:`RangeBearing`.
    """

    noise_std: Float[Array, "*T m"] | None
    R: Float[Array, "*T m m"] | None
    sensor_position: Float[Array, "*T 3"]
    sensor_velocity: Float[Array, "*T 3"]
    world_to_sensor_rotation: Float[Array, "*T 3 3"]
    bias: Float[Array, "*T m"]
    position_indices: tuple[int, ...] = eqx.field(static=True)
    velocity_indices: tuple[int, ...] = eqx.field(static=True)
    range_rate: bool = eqx.field(static=True)
    azimuth: str = eqx.field(static=True)
    angle_components: tuple[int, ...] = eqx.field(static=True)

    def __init__(self, noise_std=None, *, noise_cov=None, sensor_position=None, sensor_velocity=None,
                 world_to_sensor_rotation=None, bias=None, range_rate: bool = False,
                 azimuth: str = "math", position_indices=None, velocity_indices=None):
        m = 4 if range_rate else 3
        dtype = _dtype(noise_std, noise_cov, sensor_position, sensor_velocity, world_to_sensor_rotation, bias)
        _init_common(self, 3, m, noise_std, noise_cov, sensor_position, sensor_velocity, bias,
                     position_indices, velocity_indices, range_rate, azimuth, dtype)
        if world_to_sensor_rotation is None:
            C = jnp.eye(3, dtype=dtype)
        else:
            C = jnp.asarray(world_to_sensor_rotation).astype(dtype)
            check_shape("world_to_sensor_rotation", C, [(3, 3), (None, 3, 3)])
            check_finite("world_to_sensor_rotation", C)
        self.world_to_sensor_rotation = C
        self.angle_components = (1, 2)

    def _orientation_arrays(self) -> dict:
        return {"world_to_sensor_rotation": (self.world_to_sensor_rotation, 2)}

    def _undefined(self, x, k):
        # The azimuth is undefined on the sensor's vertical axis (horizontal sensor-frame
        # components both 0), the target's position on the sensor included.
        d, _ = self._relative(x, k)
        ds = _rotate(at_step(self.world_to_sensor_rotation, k, 2), d)
        return (ds[0] == 0) & (ds[1] == 0)

    def _rows(self, x, k):
        d, u = self._relative(x, k)
        C = at_step(self.world_to_sensor_rotation, k, 2)
        ds = _rotate(C, d)
        r, inv_r = _safe_norm(d)
        az, g_az = _azimuth_row(ds, self.azimuth)
        el, g_el = _elevation_row(ds)
        rows = [(r, d * inv_r, None), (az, _rotate(C.T, g_az), None), (el, _rotate(C.T, g_el), None)]
        if self.range_rate:
            rows.append(self._range_rate_row(d, u))
        return rows
