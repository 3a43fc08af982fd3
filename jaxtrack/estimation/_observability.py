"""Observability of a sequence of linear measurements.

A linear measurement sequence ``z_k = H_k x + v_k`` (``x`` a constant parameter, or the state at a
reference time once each ``H_k`` is multiplied by its transition ``Φ(k, 0)``) determines ``x``
exactly when the stacked matrix ``A = [H_1; H_2; …]`` has full column rank, i.e. when the
observability Gramian ``M = Σ_k H_kᵀ H_k = AᵀA`` is positive definite. :func:`observability`
returns both views: the singular values of ``A`` (rank, Lindgren & Gong 1977, Appendix A,
eqs A-1…A-4) and the eigen-decomposition of the column-normalised Gramian ``S⁻¹ M S⁻¹``,
``S = diag(√M_jj)`` (scale-free when the states have different units; Liu et al., mobile radar
registration, eqs 21–27).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._validation import InputError, check_finite, check_shape

__all__ = ["Observability", "observability"]


class Observability(eqx.Module):
    """Observability analysis of stacked linear measurements (see :func:`observability`).

    - ``gramian`` ``(n, n)``: ``M = Σ_k H_kᵀ H_k = AᵀA`` in the states' physical units.
    - ``eigenvalues`` ``(n,)``: of the (column-normalised, if requested) Gramian, ascending.
    - ``eigenvectors`` ``(n, n)``: the matching unit eigenvectors, as columns.
    - ``column_norms`` ``(n,)``: ``S = √diag(M)``; ones when not normalised. A physical direction is
      ``eigenvector / column_norms``.
    - ``condition`` ``()``: ``λ_max / |λ_min|`` of the (normalised) Gramian.
    - ``singular_values`` ``(min(K·m, n),)``: of the stacked matrix ``A``, descending (un-normalised).
    """

    gramian: Float[Array, "n n"]
    eigenvalues: Float[Array, " n"]
    eigenvectors: Float[Array, "n n"]
    column_norms: Float[Array, " n"]
    condition: Float[Array, ""]
    singular_values: Float[Array, " s"]

    def rank(self, rtol: float = 1e-9) -> int:
        """Numerical rank of ``A``: singular values above ``rtol · σ_max`` (eq. A-1; not jit-able).

        The sequence is observable when the rank equals the state dimension ``n``.
        """
        s = np.asarray(self.singular_values)
        return int(np.sum(s > rtol * s[0])) if s.size else 0

    def num_null(self, rtol: float = 1e-10) -> int:
        """Gramian eigenvalues below ``rtol · λ_max``: the numerically unobservable directions."""
        ev = np.asarray(self.eigenvalues)
        return int(np.sum(ev < rtol * ev[-1]))

    def physical_direction(self, i: int = 0) -> np.ndarray:
        """Eigenvector ``i`` (0 = least observable) in the states' physical units, scaled to max-norm 1.

        **Returns:** ``(n,)`` NumPy array whose largest-magnitude entry is ``+1``.
        """
        v = np.asarray(self.eigenvectors[:, i]) / np.asarray(self.column_norms)
        return v / v[np.argmax(np.abs(v))]


@eqx.filter_jit
def _analyse(h: Array, normalize: bool) -> Observability:
    m = jnp.einsum("kin,kim->nm", h, h)
    if normalize:
        s = jnp.sqrt(jnp.diagonal(m))
        mn = m / (s[:, None] * s[None, :])
    else:
        s = jnp.ones(m.shape[0], m.dtype)
        mn = m
    ev, vec = jnp.linalg.eigh(0.5 * (mn + mn.T))
    sv = jnp.linalg.svd(jnp.reshape(h, (-1, h.shape[-1])), compute_uv=False)
    # Rounding can leave a null eigenvalue slightly negative; the condition uses its magnitude.
    return Observability(m, ev, vec, s, ev[-1] / jnp.abs(ev[0]), sv)


def observability(
    measurement_matrices: ArrayLike, *, transitions: ArrayLike | None = None, normalize: bool = True
) -> Observability:
    """Observability Gramian, its spectrum and the singular values of the stacked measurement matrix.

    ``M = Σ_k H̃_kᵀ H̃_k`` with ``H̃_k = H_k Φ_k`` (``Φ_k = I`` without ``transitions``): the
    observability matrix of Liu et al. eq. (23) and ``A'A`` of Lindgren & Gong eq. (51), whose
    stacked ``A(k)`` rows are ``H(i) Φ(i, k)`` (eq. 22). ``normalize=True`` analyses
    ``S⁻¹ M S⁻¹``, ``S = diag(√M_jj)``, so that states in different units (m, rad, gain) compare;
    its eigenvalues are scale-free (trace ``n``). The singular values (Appendix A, eqs A-1…A-4)
    are always those of the un-normalised stacked matrix.

    **Arguments:**

    - ``measurement_matrices``: ``(K, m, n)`` blocks ``H_k``, or one stacked ``(K·m, n)`` matrix ``A``.
    - ``transitions``: optional ``(K, n, n)`` transitions ``Φ_k`` that map the reference state to the
      state measured by block ``k``.
    - ``normalize``: whether the eigen-decomposition is of the column-normalised Gramian.

    **Returns:** :class:`Observability`; ``.rank(rtol)`` and ``.num_null(rtol)`` count the observable
    and unobservable directions. A zero column (a state no measurement touches) makes the normalised
    Gramian undefined (NaN); analyse it with ``normalize=False``.
    """
    h = jnp.asarray(measurement_matrices)
    h = h.astype(jnp.result_type(h, float))
    check_shape("measurement_matrices", h, [(None, None), (None, None, None)])
    check_finite("measurement_matrices", h)
    if h.ndim == 2:
        h = h[:, None, :]
    if h.shape[0] == 0 or h.shape[-1] == 0:
        raise InputError(f"`measurement_matrices` must hold at least one row and one column; got shape {h.shape}.")
    if transitions is not None:
        phi = jnp.asarray(transitions, h.dtype)
        n = h.shape[-1]
        check_shape("transitions", phi, [(h.shape[0], n, n)])
        check_finite("transitions", phi)
        h = h @ phi
    return _analyse(h, normalize)
