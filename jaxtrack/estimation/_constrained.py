r"""Equality-constrained weighted least squares (minimum weighted norm under linear constraints).

.. math::

    \min_e\ ½\, e^T D e \quad\text{s.t.}\quad J e = b

with ``D`` symmetric positive definite (or a positive diagonal) and ``J`` of full row rank. The
Lagrange (Kuhn–Tucker) conditions ``D e = Jᵀ a``, ``J e = b`` form one linear system,

.. math::

    \begin{bmatrix} D & −J^T \\ J & 0 \end{bmatrix}
    \begin{bmatrix} e \\ a \end{bmatrix} = \begin{bmatrix} 0 \\ b \end{bmatrix},

whose solution is ``e* = D⁻¹Jᵀ (J D⁻¹ Jᵀ)⁻¹ b`` with multipliers ``a = (J D⁻¹ Jᵀ)⁻¹ b``, equal to
``∂F*/∂b`` of the optimal cost ``F* = ½ aᵀ b``. The radar-bias study (Serakos, Gray, Youssef,
"Topics in mitigating radar bias", eqs. (24)–(41)) is the case of six spherical biases under the
three relative-bias constraints; the KKT form is its eq. (35). See e.g. S. Boyd and
L. Vandenberghe, *Convex Optimization*, 2004, §10.1.1 (equality-constrained quadratic programs).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._validation import InputError, check_finite, check_shape, is_concrete

__all__ = ["ConstrainedSolution", "equality_constrained_lsq"]


class ConstrainedSolution(eqx.Module):
    """Solution of :func:`equality_constrained_lsq`.

    - ``solution`` ``(k,)``: the minimiser ``e*``.
    - ``multipliers`` ``(c,)``: the Lagrange multipliers ``a`` (``D e* = Jᵀ a``), the gradient
      of the optimal cost with respect to ``b``.
    - ``cost`` ``()``: ``F* = ½ e*ᵀ D e*``.
    """

    solution: Float[Array, " k"]
    multipliers: Float[Array, " c"]
    cost: Float[Array, ""]


def equality_constrained_lsq(weights: ArrayLike, jacobian: ArrayLike, rhs: ArrayLike) -> ConstrainedSolution:
    r"""``min ½ eᵀ D e`` subject to ``J e = b``, by one solve of the KKT system.

    **Arguments:**

    - ``weights``: ``D``, either its positive diagonal ``(k,)`` or a symmetric positive definite
      matrix ``(k, k)``; units of cost per unit of ``e`` squared.
    - ``jacobian``: ``J`` ``(c, k)``, full row rank (``c ≤ k``).
    - ``rhs``: ``b`` ``(c,)``.

    **Returns:** a :class:`ConstrainedSolution`. The dtype follows the inputs (float64 under x64).
    Jittable and differentiable (``jax.grad`` of ``cost`` in ``rhs`` is ``multipliers``).

    **Raises:** :class:`~jaxtrack.InputError` for wrong shapes, non-finite values, or (for
    concrete inputs) non-positive diagonal weights.

    Example::

        sol = equality_constrained_lsq(jnp.array([1.0, 4.0]), jnp.array([[1.0, 1.0]]), jnp.array([5.0]))
        sol.solution   # [4., 1.]: the cheaper component takes more of the constraint
    """
    w, jac, b = (jnp.asarray(a) for a in (weights, jacobian, rhs))
    dtype = jnp.result_type(w, jac, b, float)
    w, jac, b = (a.astype(dtype) for a in (w, jac, b))
    check_shape("jacobian", jac, [(None, None)])
    c, k = jac.shape
    check_shape("weights", w, [(k,), (k, k)])
    check_shape("rhs", b, [(c,)])
    for name, a in (("weights", w), ("jacobian", jac), ("rhs", b)):
        check_finite(name, a)
    if c > k:
        raise InputError(f"`jacobian` has {c} constraints for {k} unknowns; at most {k} are allowed.")
    if w.ndim == 1 and is_concrete(w) and not bool(jnp.all(w > 0)):
        raise InputError(f"`weights` (the diagonal of D) must all be positive; got {w}.")
    d = jnp.diag(w) if w.ndim == 1 else w
    kkt = jnp.block([[d, -jac.T], [jac, jnp.zeros((c, c), dtype)]])
    sol = jnp.linalg.solve(kkt, jnp.concatenate([jnp.zeros((k,), dtype), b]))
    e, a = sol[:k], sol[k:]
    return ConstrainedSolution(e, a, 0.5 * e @ (d @ e))
