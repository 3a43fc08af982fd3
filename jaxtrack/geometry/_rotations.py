"""Rotations: elementary rotations, skew matrices, rotation vectors, 3-2-1 Euler angles.

**One convention, used throughout jaxtrack.** Every rotation matrix here is *active* and
right-handed: ``rotation_z(a) @ v`` turns the vector ``v`` by ``+a`` about z (counter-clockwise
seen from +z). Equivalently, ``rotation_z(a)`` maps the components of a vector in a frame B, whose
axes are those of frame A turned by ``+a`` about z, into its components in A:
``v_A = rotation_z(a) @ v_B``. The passive matrix (A components to B components) is the
transpose, ``rotation_z(a).T == rotation_z(−a)``. Frame transformations in
:mod:`jaxtrack.geometry` are named ``a_to_b_rotation`` and satisfy ``v_b = T @ v_a``.

All functions are pure, differentiable and vectorised over leading axes: an angle of shape
``(...)`` gives a ``(..., 3, 3)`` matrix. Angles in radians.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float


def _stack_matrix(rows) -> Array:
    """A ``(..., 3, 3)`` array from a 3×3 nested list of same-shaped arrays."""
    return jnp.stack([jnp.stack(row, axis=-1) for row in rows], axis=-2)


def _angle(angle: ArrayLike) -> Array:
    return jnp.asarray(angle, dtype=jnp.result_type(angle, float))


def rotation_x(angle: ArrayLike) -> Float[Array, "... 3 3"]:
    """Active rotation by ``angle`` (rad) about x: ``[[1,0,0],[0,c,−s],[0,s,c]]``; ``(...)`` → ``(..., 3, 3)``.

    **Arguments:**

    - ``angle``: the rotation angle (rad), shape ``(...)``.

    **Returns:** the rotation matrix, shape ``(..., 3, 3)``.
    """
    a = _angle(angle)
    c, s, o, i = jnp.cos(a), jnp.sin(a), jnp.zeros_like(a), jnp.ones_like(a)
    return _stack_matrix([[i, o, o], [o, c, -s], [o, s, c]])


def rotation_y(angle: ArrayLike) -> Float[Array, "... 3 3"]:
    """Active rotation by ``angle`` (rad) about y: ``[[c,0,s],[0,1,0],[−s,0,c]]``; ``(...)`` → ``(..., 3, 3)``.

    **Arguments:**

    - ``angle``: the rotation angle (rad), shape ``(...)``.

    **Returns:** the rotation matrix, shape ``(..., 3, 3)``.
    """
    a = _angle(angle)
    c, s, o, i = jnp.cos(a), jnp.sin(a), jnp.zeros_like(a), jnp.ones_like(a)
    return _stack_matrix([[c, o, s], [o, i, o], [-s, o, c]])


def rotation_z(angle: ArrayLike) -> Float[Array, "... 3 3"]:
    """Active rotation by ``angle`` (rad) about z: ``[[c,−s,0],[s,c,0],[0,0,1]]``; ``(...)`` → ``(..., 3, 3)``.

    **Arguments:**

    - ``angle``: the rotation angle (rad), shape ``(...)``.

    **Returns:** the rotation matrix, shape ``(..., 3, 3)``.
    """
    a = _angle(angle)
    c, s, o, i = jnp.cos(a), jnp.sin(a), jnp.zeros_like(a), jnp.ones_like(a)
    return _stack_matrix([[c, -s, o], [s, c, o], [o, o, i]])


def skew(a: ArrayLike) -> Float[Array, "... 3 3"]:
    """The cross-product matrix ``[a×]`` with ``[a×] b = a × b``; ``a`` shape ``(..., 3)``.

    **Arguments:**

    - ``a``: the vector, shape ``(..., 3)``, any units.

    **Returns:** ``[a×]``, shape ``(..., 3, 3)``, in the units of ``a``.
    """
    a = jnp.asarray(a)
    zero = jnp.zeros_like(a[..., 0])
    return _stack_matrix([[zero, -a[..., 2], a[..., 1]], [a[..., 2], zero, -a[..., 0]], [-a[..., 1], a[..., 0], zero]])


def vee(S: ArrayLike) -> Float[Array, "... 3"]:
    """Inverse of :func:`skew`: the axial vector of the skew-symmetric part of ``S`` ``(..., 3, 3)``.

    **Arguments:**

    - ``S``: the matrix, shape ``(..., 3, 3)``.

    **Returns:** the axial vector, shape ``(..., 3)``, in the units of ``S``.
    """
    S = jnp.asarray(S)
    A = 0.5 * (S - jnp.swapaxes(S, -1, -2))
    return jnp.stack([A[..., 2, 1], A[..., 0, 2], A[..., 1, 0]], axis=-1)


def rotation_vector_to_dcm(rotation: ArrayLike) -> Float[Array, "3 3"]:
    """Active rotation by the rotation vector ``a`` (rad): ``exp([a×])`` (Rodrigues' formula).

    ``exp([a×]) = I + (sin θ/θ)[a×] + ((1 − cos θ)/θ²)[a×]²`` with ``θ = ‖a‖``. Series
    coefficients are used for ``θ² < 1e-8``, so the value and its derivatives stay exact and
    finite at ``a = 0`` (where error-state Jacobians are taken). ``a`` shape ``(3,)``.

    **Arguments:**

    - ``rotation``: the rotation vector ``a`` (rad), shape ``(3,)``.

    **Returns:** the rotation matrix, shape ``(3, 3)``.
    """
    a = jnp.asarray(rotation)
    theta2 = a @ a
    small = theta2 < 1e-8
    theta = jnp.sqrt(jnp.where(small, 1.0, theta2))
    f1 = jnp.where(small, 1.0 - theta2 / 6.0, jnp.sin(theta) / theta)
    f2 = jnp.where(small, 0.5 - theta2 / 24.0, (1.0 - jnp.cos(theta)) / jnp.where(small, 1.0, theta2))
    K = skew(a)
    return jnp.eye(3, dtype=K.dtype) + f1 * K + f2 * (K @ K)


def euler_321_to_dcm(angles: ArrayLike) -> Float[Array, "... 3 3"]:
    """``R_z(a_z) R_y(a_y) R_x(a_x)`` from ``angles = [roll a_x, pitch a_y, yaw a_z]`` (rad), ``(..., 3)``.

    The aerospace 3-2-1 (yaw, pitch, roll) sequence: the matrix maps body components to the
    reference frame (e.g. ``C_b^n`` of Layne & Blasch 1997, E12), written out element by element.
    It equals ``rotation_z(a_z) @ rotation_y(a_y) @ rotation_x(a_x)`` (tested).

    **Arguments:**

    - ``angles``: ``[roll a_x, pitch a_y, yaw a_z]`` (rad), shape ``(..., 3)``.

    **Returns:** the direction cosine matrix, shape ``(..., 3, 3)``.
    """
    a = jnp.asarray(angles)
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    sx, cx, sy, cy, sz, cz = jnp.sin(ax), jnp.cos(ax), jnp.sin(ay), jnp.cos(ay), jnp.sin(az), jnp.cos(az)
    return _stack_matrix([
        [cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx],
        [sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx],
        [-sy, cy * sx, cy * cx],
    ])


def orthonormalize(dcm: ArrayLike) -> Float[Array, "... 3 3"]:
    """The nearest rotation matrix to ``dcm``: ``C (CᵀC)^{−1/2}`` (Britting; Layne & Blasch 1997, E107).

    The optimal (Frobenius-nearest) orthogonalisation of a direction-cosine matrix that has drifted
    from orthonormality, by the eigen-decomposition of ``CᵀC``.

    **Arguments:** ``dcm``: shape ``(..., 3, 3)``, non-singular.

    **Returns:** the orthonormal matrix, shape ``(..., 3, 3)``.
    """
    from .._validation import check_shape

    C = jnp.asarray(dcm)
    check_shape("dcm", C, [(3, 3), (None, 3, 3), (None, None, 3, 3)])
    w, V = jnp.linalg.eigh(jnp.swapaxes(C, -1, -2) @ C)
    return C @ (V * (1.0 / jnp.sqrt(w))[..., None, :]) @ jnp.swapaxes(V, -1, -2)


def orthonormalize_first_order(dcm: ArrayLike, perturbation: ArrayLike) -> Float[Array, "... 3 3"]:
    """First-order :func:`orthonormalize` of ``C + δC``: ``(I + ½[δC Cᵀ − C δCᵀ]) C`` (Layne & Blasch 1997, E108).

    Exact to first order in ``δC`` when ``C`` is orthonormal (the residual is ``O(‖δC‖²)``).

    **Arguments:** ``dcm`` ``C`` (orthonormal) and ``perturbation`` ``δC``, shape ``(..., 3, 3)``.

    **Returns:** shape ``(..., 3, 3)``.
    """
    C, dC = jnp.asarray(dcm), jnp.asarray(perturbation)
    Ct, dCt = jnp.swapaxes(C, -1, -2), jnp.swapaxes(dC, -1, -2)
    X = 0.5 * (dC @ Ct - C @ dCt)
    return (jnp.broadcast_to(jnp.eye(3, dtype=X.dtype), X.shape) + X) @ C
