"""Unbiased converted measurements: polar / spherical radar measurements to Cartesian position.

A converted-measurement Kalman filter turns each radar measurement into a Cartesian position and
runs the *linear* Kalman filter with ``H = [I 0]``. The plain conversion ``r_m [cos θ_m, sin θ_m]``
is biased: with a symmetric bearing error ``ṽ``, ``E[cos θ_m] = λ cos θ`` where ``λ = E[cos ṽ] < 1``,
so the converted point is pulled towards the sensor by ``(1 − λ) r`` — 50 m at r = 10 km and
σ_θ = 0.1 rad, many standard errors of a filtered track.

**Method (one, cited).** L. Mo (Longbin), X. Song, Y. Zhou, Z. K. Sun, Y. Bar-Shalom, "Unbiased
converted measurements for tracking", *IEEE Trans. Aerospace and Electronic Systems* 34(3),
1023–1027, 1998: the *multiplicative* unbiased conversion. In 2-D (§II)

- conversion, eqs. (4)–(5): ``x_u = λ_θ⁻¹ r_m cos θ_m``, ``y_u = λ_θ⁻¹ r_m sin θ_m`` with
  ``λ_θ = E[cos ṽ_θ] = exp(−σ_θ²/2)`` for Gaussian noise;
- covariance, eqs. (7a)–(7c), with ``λ'_θ = E[cos 2ṽ_θ] = exp(−2σ_θ²)``:
  ``R11 = (λ⁻² − 2) r_m² cos²θ_m + ½(r_m² + σ_r²)(1 + λ' cos 2θ_m)``,
  ``R22 = (λ⁻² − 2) r_m² sin²θ_m + ½(r_m² + σ_r²)(1 − λ' cos 2θ_m)``,
  ``R12 = (λ⁻² − 2) r_m² cos θ_m sin θ_m + ½(r_m² + σ_r²) λ' sin 2θ_m``;

and in 3-D (§III) the same with ``λ_α λ_ε`` on the horizontal components and ``λ_ε`` on the
vertical one. (Equation numbers as quoted in secondary implementations of the paper; not checked
against the printed page. The formulas themselves are derived below and verified by Monte Carlo
in ``tests/test_converted_measurements.py``.)

**What is conditioned on what.** Two different covariances appear in this literature:

- ``given="truth"``: the conversion error ``x_u − x`` for a *fixed true* position ``x``, averaged over
  the measurement noise. The conversion is exactly unbiased here, ``E[x_u | x] = x``, and
  ``Cov(x_u | x) = E[x_u x_uᵀ | x] − x xᵀ``. It needs the true (r, θ), so it is an analysis tool
  (what a Monte Carlo over measurement noise at one target measures).
- ``given="measurement"`` (default; what a filter can use): the mean squared error
  ``E[(x_u − x)(x_u − x)ᵀ | z_m]``, the truth treated as ``r = r_m − ṽ_r``, ``θ = θ_m − ṽ_θ``
  (the errors independent of the measured value). This is Longbin et al.'s practical covariance,
  eqs. (7a)–(7c): ``u uᵀ − u μᵀ − μ uᵀ + E[x xᵀ | z_m]`` with ``u = x_u`` and
  ``μ = E[x | z_m] = λ r_m [cos θ_m, sin θ_m]``. Note ``x_u`` is *not* the conditional mean
  ``μ`` given the measurement; the matrix includes that offset (it is an MSE, not a variance).

Both use the Gaussian moments ``E[cos ṽ] = λ``, ``E[sin ṽ] = 0``, ``E[cos 2ṽ] = λ⁴`` and
``E[r²] = r_·² + σ_r²``. Bordonaro, Willett & Bar-Shalom (IEEE TAES 50(2), 2014) show the
measurement-conditioned covariance is correlated with the measurement error (the "decorrelated"
variant); that refinement is not implemented here.
"""

from __future__ import annotations


import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._validation import InputError, check_shape, is_concrete

__all__ = ["ConvertedMeasurement", "unbiased_polar_to_cartesian", "unbiased_spherical_to_cartesian"]



class ConvertedMeasurement(eqx.Module):
    """A radar measurement converted to Cartesian position, with its covariance.

    **Fields:**

    - ``position`` ``(..., d)``: the converted position (m), relative to the sensor, in the
      sensor frame's axes (x: azimuth 0 direction of the math convention, i.e. East unrotated).
    - ``cov`` ``(..., d, d)``: its error covariance (m²), conditioned as the producing function's
      ``given`` says.

    Use with the linear Kalman filter as the measurement ``z = position`` with ``H = [I_d 0]`` and
    ``R_k = cov``. To world axes: ``p_w = Cᵀ position + s``, ``R_w = Cᵀ cov C`` (``C`` the
    world-to-sensor rotation, ``s`` the sensor position).
    """

    position: Float[Array, "*batch d"]
    cov: Float[Array, "*batch d d"]


def _prepare(measurement, noise_std, d: int, azimuth: str, given: str):
    if azimuth not in ("math", "compass"):
        raise InputError(
            f"`azimuth` must be 'math' (counter-clockwise from +x/East) or 'compass' (clockwise "
            f"from +y/North); got {azimuth!r}."
        )
    if given not in ("measurement", "truth"):
        raise InputError(f"`given` must be 'measurement' or 'truth'; got {given!r}.")
    z, std = jnp.asarray(measurement), jnp.asarray(noise_std)
    dtype = jnp.result_type(z, std, float)
    z, std = z.astype(dtype), std.astype(dtype)
    if z.ndim < 1 or z.shape[-1] != d:
        raise InputError(f"`measurement` must have shape (..., {d}); got shape {z.shape}.")
    check_shape("noise_std", std, [(d,)])
    if is_concrete(std) and np.any(np.asarray(std) < 0):
        raise InputError(f"`noise_std` must be non-negative; got {np.asarray(std)}.")
    if azimuth == "compass":
        # Compass θ_c (clockwise from North) → mathematical ψ = π/2 − θ_c; same error σ.
        z = z.at[..., 1].set(0.5 * jnp.pi - z[..., 1])
    return z, std


def _trig_moments(angle: Array, sigma: Array):
    """First and second moments of (cos, sin) of ``angle ± ṽ``, ``ṽ ~ N(0, σ²)``.

    ``E[cos] = λ cos``, ``E[sin] = λ sin``, ``E[cos²] = ½(1 + λ' cos 2·)``,
    ``E[sin²] = ½(1 − λ' cos 2·)``, ``E[sin cos] = ½ λ' sin 2·`` with ``λ = e^{−σ²/2}``,
    ``λ' = e^{−2σ²}``. The same form holds conditioned on the measurement (angle = measured,
    truth random) or on the truth (angle = true, measurement random): the noise is symmetric.
    """
    lam, lam2 = jnp.exp(-0.5 * sigma**2), jnp.exp(-2.0 * sigma**2)
    c, s = jnp.cos(angle), jnp.sin(angle)
    c2, s2 = jnp.cos(2 * angle), jnp.sin(2 * angle)
    return lam, (c, s), (0.5 * (1 + lam2 * c2), 0.5 * (1 - lam2 * c2), 0.5 * lam2 * s2)


def _outer(a: Array, b: Array) -> Array:
    return a[..., :, None] * b[..., None, :]


def _assemble(r, sig_r, g, Ggg, D, given) -> ConvertedMeasurement:
    """Position and covariance from the angle vector ``g`` (``p = r g``) and its moments.

    ``D``: the debiasing factors (``E[g(angle ± ṽ)] = D ⊙ g(angle)``); ``Ggg``: ``E[g gᵀ]``.
    """
    D = jnp.broadcast_to(D, g.shape)  # explicit: jaxtrack's tests forbid rank promotion
    second = (r**2 + sig_r**2)[..., None, None] * Ggg
    if given == "measurement":
        u = r[..., None] * g / D  # x_u: eq. (5) (2-D) / §III (3-D)
        mu = r[..., None] * D * g  # E[x | z_m]
        cov = _outer(u, u) - _outer(u, mu) - _outer(mu, u) + second
        return ConvertedMeasurement(u, cov)
    # Given the truth: E[x_u | x] = x (unbiased), Cov = E[x_u x_uᵀ] − x xᵀ.
    p = r[..., None] * g
    cov = second / _outer(D, D) - _outer(p, p)
    return ConvertedMeasurement(p, cov)


def unbiased_polar_to_cartesian(
    measurement: ArrayLike,
    noise_std: ArrayLike | tuple[float, ...],
    *,
    azimuth: str = "math",
    given: str = "measurement",
) -> ConvertedMeasurement:
    """Unbiased conversion of a 2-D radar measurement ``[r, θ]`` to ``[x, y]`` (Longbin et al. 1998).

    ``x_u = λ⁻¹ r_m [cos θ_m, sin θ_m]``, ``λ = exp(−σ_θ²/2)`` (eqs. (4)–(5)); covariance
    eqs. (7a)–(7c). See the module docstring for the conditioning.

    **Arguments:**

    - ``measurement``: ``(..., 2)``: range (m) and bearing θ (rad) — the measured values
      (``given="measurement"``) or the true ones (``given="truth"``).
    - ``noise_std``: ``(2,)``: ``[σ_r (m), σ_θ (rad)]`` of independent Gaussian errors.
    - ``azimuth`` (static): ``"math"`` (θ counter-clockwise from +x/East) or ``"compass"``
      (clockwise from +y/North; converted with ψ = π/2 − θ).
    - ``given`` (static): ``"measurement"`` (default; the MSE given the measured value, for a filter)
      or ``"truth"`` (the covariance of the conversion error given the true position).

    **Returns:** :class:`ConvertedMeasurement` with ``position`` ``(..., 2)`` (m; with
    ``given="truth"`` the true position, the mean of ``x_u``) and ``cov`` ``(..., 2, 2)`` (m²).
    Pure ``jnp``: ``vmap``, ``jit`` and ``grad`` apply.

    **Raises:** ``InputError`` on wrong shapes, negative ``noise_std``, unknown ``azimuth`` or ``given``.
    """
    z, std = _prepare(measurement, noise_std, 2, azimuth, given)
    r, theta = z[..., 0], z[..., 1]
    lam, (c, s), (cc, ss, cs) = _trig_moments(theta, std[1])
    g = jnp.stack([c, s], axis=-1)
    Ggg = jnp.stack([jnp.stack([cc, cs], -1), jnp.stack([cs, ss], -1)], -2)
    D = jnp.stack([lam, lam])
    return _assemble(r, std[0], g, Ggg, D, given)


def unbiased_spherical_to_cartesian(
    measurement: ArrayLike,
    noise_std: ArrayLike | tuple[float, ...],
    *,
    azimuth: str = "math",
    given: str = "measurement",
) -> ConvertedMeasurement:
    """Unbiased conversion of a 3-D radar measurement ``[r, α, ε]`` to ``[x, y, z]`` (Longbin et al. 1998, §III).

    ``x_u = r_m [cos ε cos α/(λ_α λ_ε), cos ε sin α/(λ_α λ_ε), sin ε/λ_ε]`` (measured angles),
    ``λ_· = exp(−σ_·²/2)``; the covariance from the independent Gaussian moments of the range,
    azimuth and elevation errors (module docstring). With ``σ_ε = 0`` and ``ε = 0`` it reduces to
    :func:`unbiased_polar_to_cartesian` in the horizontal plane.

    **Arguments:**

    - ``measurement``: ``(..., 3)``: range (m), azimuth α (rad), elevation ε (rad, up from the
      horizontal) — measured (``given="measurement"``) or true (``given="truth"``).
    - ``noise_std``: ``(3,)``: ``[σ_r (m), σ_α (rad), σ_ε (rad)]``, independent Gaussian errors.
    - ``azimuth``, ``given`` (static): as :func:`unbiased_polar_to_cartesian`.

    **Returns:** :class:`ConvertedMeasurement` with ``position`` ``(..., 3)`` (m) and ``cov``
    ``(..., 3, 3)`` (m²).

    **Raises:** ``InputError`` on wrong shapes, negative ``noise_std``, unknown ``azimuth`` or ``given``.
    """
    z, std = _prepare(measurement, noise_std, 3, azimuth, given)
    r, alpha, eps = z[..., 0], z[..., 1], z[..., 2]
    la, (ca, sa), (caca, sasa, casa) = _trig_moments(alpha, std[1])
    le, (ce, se), (cece, sese, cese) = _trig_moments(eps, std[2])
    g = jnp.stack([ce * ca, ce * sa, se], axis=-1)
    # E[g gᵀ]: products of independent azimuth and elevation moments.
    g11, g22, g12 = cece * caca, cece * sasa, cece * casa
    g13, g23, g33 = cese * la * ca, cese * la * sa, sese
    Ggg = jnp.stack([
        jnp.stack([g11, g12, g13], -1),
        jnp.stack([g12, g22, g23], -1),
        jnp.stack([g13, g23, g33], -1),
    ], -2)
    D = jnp.stack([la * le, la * le, le])
    return _assemble(r, std[0], g, Ggg, D, given)
