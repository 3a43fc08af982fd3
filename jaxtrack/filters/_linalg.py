"""Small dense linear algebra that batches well: Cholesky factors and their inverses.

Why this module exists: under ``jax.vmap`` on a CPU, ``jnp.linalg.cholesky`` and
``solve_triangular`` become one LAPACK call per batch element, and each call costs far more
than the arithmetic of a 2×2 or 3×3 factorisation. For the measurement sizes trackers use
(``m ≤ 4``) the factorisation is written out entry by entry, so that a batch of runs is a few
fused element-wise loops. For larger sizes LAPACK is used, as before.

A second rule keeps batched filters cheap whatever the size: the factor ``L`` and its inverse
depend only on the covariance, and everything that touches data (whitening an innovation, the
gain) is a matrix product with ``L⁻¹``. When the covariance is shared by every run of a batch
(a linear model with one measurement schedule), ``jax.vmap`` then leaves the factorisation
unbatched and only the products are batched.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import jax.scipy.linalg as jsl
from jaxtyping import Array, Float

# Largest size factorised entry by entry. The unrolled code has O(d³) operations in the trace,
# so it stays small; beyond this LAPACK is at least as fast.
UNROLL_MAX = 4


# Largest contraction length of a product written out as a sum of broadcast products; longer
# ones use `@`. Measured on 2 cores, per-run masks, 10k runs × 200 steps: at 9 states `@` is
# 20–30% faster than the written-out sums (1.10–1.22× dynamax instead of 0.95×), at 4 and 6
# states the written-out sums are faster. 7 rather than 8 so that the OBEM study's 8- and
# 14-state updates (V14's XLA FLOP counts) are both counted as `dot`s.
MATMUL_UNROLL_MAX = 7


def matmul(a: Array, b: Array) -> Array:
    """``a @ b`` for matrices and vectors (ndim ≤ 2), written as ``Σ_k a[:, k] b[k, :]``.

    Under ``jax.vmap`` a product of two small batched matrices is a batched ``dot_general``,
    which XLA's CPU backend runs as one tiny kernel call per batch element; the sum of
    broadcast products is instead an element-wise loop over the whole batch that fuses with
    its neighbours. Long contractions (``k > MATMUL_UNROLL_MAX``) use ``@``.

    **Arguments:**

    - ``a``: ``(p, k)`` or ``(k,)``; ``b``: ``(k, q)`` or ``(k,)`` (higher ranks fall back to ``@``).

    **Returns:** ``a @ b``: ``(p, q)``, ``(p,)``, ``(q,)`` or a scalar.
    """
    k = a.shape[-1]
    if a.ndim > 2 or b.ndim > 2 or k > MATMUL_UNROLL_MAX or b.shape[0] != k:
        return a @ b
    if a.ndim == 1:
        col = lambda i: a[i]  # noqa: E731
    else:
        col = lambda i: a[:, i] if b.ndim == 1 else a[:, i, None]  # noqa: E731
    row = lambda i: b[i] if a.ndim == 1 or b.ndim == 1 else b[None, i]  # noqa: E731
    out = col(0) * row(0)
    for i in range(1, k):
        out = out + col(i) * row(i)
    return out


def congruence(a: Array, p: Array) -> Array:
    """``a p aᵀ`` for a symmetric ``p``, exactly symmetric: the lower triangle, mirrored.

    Under ``vmap`` XLA fuses the inner product ``a p`` into every element of the outer one, so
    each of the ``n²`` outputs recomputes ``n`` entries of ``a p`` (``n⁴`` multiply-adds, the
    largest cost of the README radar's UKF prediction); computing the ``n(n+1)/2`` distinct
    entries only nearly halves that.

    **Arguments:** ``a`` ``(q, n)``; ``p`` ``(n, n)``, symmetric.

    **Returns:** ``a p aᵀ``, ``(q, q)``, symmetric.
    """
    q, n = a.shape
    if n > MATMUL_UNROLL_MAX:
        out = matmul(matmul(a, p), a.T)
        return 0.5 * (out + out.T)
    ap = matmul(a, p)
    lower = {(i, j): matmul(ap[i], a[j]) for i in range(q) for j in range(i + 1)}
    return jnp.stack([jnp.stack([lower[max(i, j), min(i, j)] for j in range(q)]) for i in range(q)])


def cholesky(a: Float[Array, "d d"], unroll_max: int = UNROLL_MAX) -> Float[Array, "d d"]:
    """Lower Cholesky factor ``L`` (``L Lᵀ = a``) of a symmetric positive definite ``a``.

    Reads the lower triangle only. Not positive definite → NaN entries (as LAPACK's ``potrf``
    through ``jnp.linalg.cholesky``), which the filters turn into ``ok = False``.

    **Arguments:**

    - ``a``: the matrix, ``(..., d, d)``.
    - ``unroll_max``: the largest ``d`` written out entry by entry (default :data:`UNROLL_MAX`);
      a caller that factorises once per run and step may write out larger ones.

    **Returns:** ``L``, lower triangular, ``(..., d, d)``, in the square root of ``a``'s units.
    """
    d = a.shape[-1]
    if d > unroll_max:
        return jnp.linalg.cholesky(a)
    # Cholesky–Banachiewicz, row by row; the same operations and rounding as LAPACK's
    # unblocked algorithm up to the order of the sums.
    L = [[None] * d for _ in range(d)]
    for i in range(d):
        for j in range(i + 1):
            s = a[..., i, j]
            for k in range(j):
                s = s - L[i][k] * L[j][k]
            L[i][j] = jnp.sqrt(s) if i == j else s / L[j][j]
    zero = jnp.zeros_like(a[..., 0, 0])
    return jnp.stack(
        [jnp.stack([L[i][j] if j <= i else zero for j in range(d)], axis=-1) for i in range(d)],
        axis=-2,
    )


def tril_inverse(L: Float[Array, "d d"]) -> Float[Array, "d d"]:
    """``L⁻¹`` of a lower-triangular ``L`` with non-zero diagonal (forward substitution).

    **Arguments:**

    - ``L``: the lower-triangular matrix, ``(d, d)``.

    **Returns:** ``L⁻¹``, lower triangular, ``(d, d)``.
    """
    d = L.shape[-1]
    if d > UNROLL_MAX:
        return jsl.solve_triangular(L, jnp.eye(d, dtype=L.dtype), lower=True)
    X = [[None] * d for _ in range(d)]
    for i in range(d):
        inv_diag = 1.0 / L[..., i, i]
        X[i][i] = inv_diag
        for j in range(i):
            s = L[..., i, j] * X[j][j]
            for k in range(j + 1, i):
                s = s + L[..., i, k] * X[k][j]
            X[i][j] = -s * inv_diag
    zero = jnp.zeros_like(L[..., 0, 0])
    return jnp.stack(
        [jnp.stack([X[i][j] if j <= i else zero for j in range(d)], axis=-1) for i in range(d)],
        axis=-2,
    )


def marginal_cov(cov: Array, components) -> Array:
    """``cov[..., c, c]``: the covariance of the sub-state ``components`` (leading axes batch).

    **Arguments:** ``cov`` ``(..., n, n)``; ``components``: None (all) or a sequence of ``d``
    distinct indices. **Returns:** ``(..., d, d)`` (``cov`` itself for None).
    """
    if components is None:
        return cov
    run = _contiguous(components)
    if run is not None:  # a slice, not a gather: fuses, and its derivative is a pad, not a scatter
        return cov[..., run, run]
    idx = np.asarray(components)
    return cov[..., idx[:, None], idx[None, :]]


def _contiguous(components) -> slice | None:
    """``slice(a, b)`` when ``components`` is ``a, a+1, …, b−1``, else None."""
    c = [int(i) for i in components]
    return slice(c[0], c[0] + len(c)) if c and c == list(range(c[0], c[0] + len(c))) else None


def take_components(x: Array, components) -> Array:
    """``x[components]`` along the leading axis (all of ``x`` for None): a slice when contiguous.

    **Arguments:** ``x`` ``(n, ...)``; ``components``: None or ``d`` distinct indices.
    **Returns:** ``(d, ...)``.
    """
    if components is None:
        return x
    run = _contiguous(components)
    return x[run] if run is not None else x[np.asarray(components)]


def cholesky_and_inverse(a: Float[Array, "d d"]) -> tuple[Float[Array, "d d"], Float[Array, "d d"]]:
    """``(L, L⁻¹)`` for a symmetric positive definite ``a``.

    **Arguments:**

    - ``a``: the matrix, ``(d, d)``.

    **Returns:** ``(L, L⁻¹)``, each lower triangular ``(d, d)`` (see :func:`cholesky`, :func:`tril_inverse`).
    """
    L = cholesky(a)
    return L, tril_inverse(L)


def normalized_squared_error(error: Array, cov: Array) -> Array:
    """``eᵀ P⁻¹ e`` for one error ``(d,)`` and covariance ``(d, d)``: NEES or NIS.

    The formula behind :func:`jaxtrack.montecarlo.normalized_squared_error` (documented there)
    and :meth:`jaxtrack.filters.AbstractFilter.consistency`; here, below both, so that the
    filters do not import the Monte Carlo layer. ``e`` is whitened by a product with ``L⁻¹``
    (``L`` the Cholesky factor of ``P``), not a triangular solve: under ``jax.vmap`` with a
    covariance shared by the batch only the product is batched.
    """
    _, chol_inv = cholesky_and_inverse(cov)
    whitened = matmul(chol_inv, error)
    return whitened @ whitened


def sum_rows(a: Array) -> Array:
    """``a.sum(axis=0)`` over a few rows, as adds: on CPU a reduction over a short leading axis
    is a separate, slow kernel, while adds fuse with the rest of the step.

    **Arguments:**

    - ``a``: the array, ``(r, ...)`` with a short leading axis.

    **Returns:** the sum over the leading axis, ``(...)``.
    """
    out = a[0]
    for i in range(1, a.shape[0]):
        out = out + a[i]
    return out


def all_rows(a: Array) -> Array:
    """``a.all(axis=0)`` over a few rows, as ``&`` (see :func:`sum_rows`).

    **Arguments:**

    - ``a``: a boolean array, ``(r, ...)`` with a short leading axis.

    **Returns:** the logical and over the leading axis, boolean ``(...)``.
    """
    out = a[0]
    for i in range(1, a.shape[0]):
        out = out & a[i]
    return out
