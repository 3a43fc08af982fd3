"""Constrained parametrisations: unconstrained leaves that map to valid model parameters.

A maximum-likelihood fit (:func:`~jaxtrack.learning.fit`) moves *unconstrained* real numbers
``u``; the model needs *natural* parameters ``θ = g(u)`` that satisfy a constraint (a variance
is positive, a probability lies in (0, 1), a covariance is symmetric positive definite, a
transition-matrix row sums to one). Each class here is a small equinox Module whose only array
leaf is ``u`` and whose :attr:`~AbstractParametrisation.value` (or call) is ``θ = g(u)``; the
classmethod ``from_value(θ)`` is the exact inverse ``u = g⁻¹(θ)``. Bounds and sizes are static
fields, so ``jax.grad``, ``jax.hessian`` and ``jax.flatten_util.ravel_pytree`` see only ``u``.

The maps are one-to-one, which the standard errors need: the observed information with respect to
``u`` (:meth:`~jaxtrack.learning.MLEFit.standard_errors`) must be non-singular, so no map here has a
redundant direction (the Cholesky parametrisation stores only the ``n(n+1)/2`` lower entries, the
softmax pins one logit per row).

**The symmetric-gradient rule.** Differentiating a loss ``L(S)`` with respect to a symmetric
matrix ``S`` *directly* (e.g. ``jax.grad`` of a filter's log-likelihood with respect to ``Q``)
treats the ``n²`` entries as independent, and the raw gradient ``G = ∂L/∂S`` is in general not
symmetric (the filter reads ``Q[i, j]`` and ``Q[j, i]`` in different places). On the space of
symmetric matrices, where ``S`` actually lives, the derivative is its symmetric part
``sym(G) = (G + Gᵀ)/2``: for a symmetric direction ``E``, ``dL = ⟨G, E⟩ = ⟨sym(G), E⟩`` because
the antisymmetric part of ``G`` is orthogonal to every symmetric ``E`` (Magnus & Neudecker 2019,
*Matrix Differential Calculus*, 3rd ed., ch. 18 §18.11 on symmetric matrices; Petersen &
Pedersen, *The Matrix Cookbook*, 2012, eq. 138). A plain gradient step ``S + η G`` leaves the
symmetric matrices (and :class:`~jaxtrack.models.LinearGaussianModel` rejects the result); use
:func:`symmetric_grad`, or better, parametrise with :class:`SPDMatrix` so that every step stays
symmetric positive definite.
"""

from __future__ import annotations

import abc
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PyTree

from .._validation import InputError, check_covariance, check_finite, check_shape


def symmetric_grad(g: ArrayLike) -> Float[Array, "*B n n"]:
    """The derivative on symmetric matrices from a raw gradient: ``sym(G) = (G + Gᵀ)/2``.

    For a loss ``L`` of a symmetric matrix ``S``, ``jax.grad`` returns ``G = ∂L/∂S`` treating all
    ``n²`` entries as free; for every symmetric direction ``E``,
    ``d/dε L(S + εE)|₀ = ⟨G, E⟩ = ⟨sym(G), E⟩`` (module docstring; Magnus & Neudecker 2019,
    §18.11), so ``sym(G)`` is the gradient on the symmetric matrices and ``S − η sym(G)`` stays
    symmetric.

    **Arguments:**

    - ``g``: the raw gradient, shape ``(..., n, n)`` (a batch of square matrices), in the loss's
      units per unit of ``S``.

    **Returns:** ``(G + Gᵀ)/2`` over the last two axes, same shape and dtype.

    **Raises:** ``InputError`` if ``g`` is not a (batch of) square matrix.
    """
    g = jnp.asarray(g)
    if g.ndim < 2 or g.shape[-1] != g.shape[-2]:
        raise InputError(f"`g` must be a (batch of) square matrix (..., n, n); got shape {g.shape}.")
    return 0.5 * (g + jnp.swapaxes(g, -1, -2))


class AbstractParametrisation(eqx.Module):
    """A natural parameter ``θ = g(u)`` held through its unconstrained leaf ``u``.

    Subclasses hold one float array leaf (the unconstrained ``u``) and static metadata; they
    implement :attr:`value` and the classmethod ``from_value``. ``elementwise`` is True when ``g``
    acts entry by entry and is increasing, so that an interval for ``u_i`` maps to an interval for
    ``θ_i`` (used by :meth:`~jaxtrack.learning.MLEFit.confidence_intervals`).
    """

    elementwise: ClassVar[bool] = False

    @property
    @abc.abstractmethod
    def value(self) -> Array:
        """The natural parameter ``θ = g(u)``."""

    def __call__(self) -> Array:
        """``self.value``: the natural parameter."""
        return self.value


def _float(x) -> Array:
    a = jnp.asarray(x)
    if not jnp.issubdtype(a.dtype, jnp.floating):
        a = a.astype(jnp.result_type(float))
    return a


class PositiveScalar(AbstractParametrisation):
    """A positive parameter (a variance, a noise level, a rate) as ``θ = exp(u)``.

    **Fields:** ``log_value``: ``u = log θ``, any shape (entrywise), unconstrained real.

    Construct from the natural value with :meth:`from_value` (``PositiveScalar.from_value(2.0)``)
    or from the log directly (``PositiveScalar(jnp.log(2.0))``).
    """

    log_value: Float[Array, "*s"]
    elementwise: ClassVar[bool] = True

    def __init__(self, log_value: ArrayLike):
        self.log_value = _float(log_value)

    @property
    def value(self) -> Float[Array, "*s"]:
        """``θ = exp(u)`` (same units as the natural parameter), same shape as ``log_value``."""
        return jnp.exp(self.log_value)

    @classmethod
    def from_value(cls, value: ArrayLike) -> "PositiveScalar":
        """The exact inverse: ``u = log θ``.

        **Arguments:** ``value``: ``θ > 0``, any shape. **Returns:** a :class:`PositiveScalar`.
        **Raises:** ``InputError`` if a concrete ``value`` is not finite and positive.
        """
        v = _float(value)
        check_finite("value", v)
        if isinstance(v, jax.core.Tracer) is False and not bool(np.all(np.asarray(v) > 0)):
            raise InputError(f"`value` must be positive for PositiveScalar; got {np.asarray(v)}.")
        return cls(jnp.log(v))


class Bounded(AbstractParametrisation):
    """A parameter in an open interval ``(lo, hi)`` as ``θ = lo + (hi − lo)·σ(u)`` (logit link).

    **Fields:** ``logit``: ``u = log((θ − lo)/(hi − θ))``, any shape, unconstrained;
    ``lo``, ``hi``: the bounds, Python floats (static: not fitted, no gradient).
    """

    logit: Float[Array, "*s"]
    lo: float = eqx.field(static=True)
    hi: float = eqx.field(static=True)
    elementwise: ClassVar[bool] = True

    def __init__(self, logit: ArrayLike, lo: float = 0.0, hi: float = 1.0):
        lo, hi = float(lo), float(hi)
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise InputError(f"`lo` and `hi` must be finite with lo < hi; got lo={lo}, hi={hi}.")
        self.logit = _float(logit)
        self.lo = lo
        self.hi = hi

    @property
    def value(self) -> Float[Array, "*s"]:
        """``θ = lo + (hi − lo)·σ(u)``, strictly inside ``(lo, hi)``."""
        return self.lo + (self.hi - self.lo) * jax.nn.sigmoid(self.logit)

    @classmethod
    def from_value(cls, value: ArrayLike, lo: float = 0.0, hi: float = 1.0) -> "Bounded":
        """The exact inverse ``u = log((θ − lo)/(hi − θ))``.

        **Arguments:** ``value``: ``θ`` strictly inside ``(lo, hi)``; ``lo``, ``hi``: the bounds.
        **Returns:** a :class:`Bounded`. **Raises:** ``InputError`` if a concrete ``value`` is
        outside the open interval.
        """
        v = _float(value)
        check_finite("value", v)
        if not isinstance(v, jax.core.Tracer):
            a = np.asarray(v)
            if not np.all((a > lo) & (a < hi)):
                raise InputError(f"`value` must lie strictly inside ({lo}, {hi}); got {a}.")
        return cls(jnp.log(v - lo) - jnp.log(hi - v), lo, hi)


class SPDMatrix(AbstractParametrisation):
    """A symmetric positive-definite matrix (a covariance) as ``S = L Lᵀ``, ``L`` lower with ``exp`` diagonal.

    ``u`` holds the ``n(n+1)/2`` lower-triangular entries of ``L`` row by row
    (``jnp.tril_indices(n)`` order), the diagonal ones as logs: ``L_ii = exp(u)``, ``L_ij = u``
    (``i > j``). The map is one-to-one onto the SPD matrices (the Cholesky factor with a positive
    diagonal is unique; Pinheiro & Bates 1996, "Unconstrained parametrizations for
    variance-covariance matrices", *Statistics and Computing* 6, §2.2, the "log-Cholesky"
    parametrisation), so ``from_value`` is its exact inverse and every gradient step on ``u``
    gives a valid covariance.

    **Fields:** ``tril``: ``(n(n+1)/2,)`` unconstrained reals; ``n``: the size (static).
    """

    tril: Float[Array, " k"]
    n: int = eqx.field(static=True)

    def __init__(self, tril: ArrayLike, n: int):
        n = int(n)
        t = _float(tril)
        check_shape("tril", t, [(n * (n + 1) // 2,)])
        self.tril = t
        self.n = n

    @property
    def cholesky(self) -> Float[Array, "n n"]:
        """The lower factor ``L`` (positive diagonal)."""
        rows, cols = np.tril_indices(self.n)
        diag = np.flatnonzero(rows == cols)
        # exp only on the diagonal entries (a where() over all entries could overflow exp on a
        # large off-diagonal entry and poison its gradient with inf·0).
        vals = self.tril.at[diag].set(jnp.exp(self.tril[diag]))
        return jnp.zeros((self.n, self.n), self.tril.dtype).at[rows, cols].set(vals)

    @property
    def value(self) -> Float[Array, "n n"]:
        """``S = L Lᵀ``, exactly symmetric, positive definite."""
        L = self.cholesky
        return L @ L.T

    @classmethod
    def from_value(cls, value: ArrayLike) -> "SPDMatrix":
        """The exact inverse: ``L = chol(S)``, diagonal logged.

        **Arguments:** ``value``: ``S`` ``(n, n)``, symmetric positive definite (units²).
        **Returns:** an :class:`SPDMatrix`. **Raises:** ``InputError`` if ``S`` is not square or (when
        concrete) not a symmetric positive-definite matrix.
        """
        S = _float(value)
        check_shape("value", S, [(None, None)])
        if S.shape[0] != S.shape[1]:
            raise InputError(f"`value` must be square (n, n); got shape {S.shape}.")
        check_covariance("value", S)
        n = S.shape[0]
        L = jnp.linalg.cholesky(S)
        rows, cols = np.tril_indices(n)
        diag = np.flatnonzero(rows == cols)
        entries = L[rows, cols]
        return cls(entries.at[diag].set(jnp.log(entries[diag])), n)


class StochasticRows(AbstractParametrisation):
    """A row-stochastic matrix (e.g. a Markov transition matrix) as a row-wise softmax of logits.

    The IMM's convention (:meth:`~jaxtrack.filters.InteractingMultipleModel.from_logits`):
    ``p_ij = softmax_j(ℓ_ij)``, with the last logit of each row pinned at 0 so that the map is
    one-to-one (softmax is invariant to adding a constant to a row; pinning removes that
    direction, which would otherwise make the observed information singular). The free logits
    are the log-odds against the last column, ``u_ij = log(p_ij / p_{i,M−1})``.

    **Fields:** ``logits``: ``(K, M − 1)`` unconstrained reals (``K`` rows over ``M`` columns).
    """

    logits: Float[Array, "K Mm1"]

    def __init__(self, logits: ArrayLike):
        lg = _float(logits)
        check_shape("logits", lg, [(None, None)])
        self.logits = lg

    @property
    def value(self) -> Float[Array, "K M"]:
        """``P = softmax([u, 0])`` row by row: ``(K, M)``, positive rows summing to 1."""
        full = jnp.concatenate([self.logits, jnp.zeros(self.logits.shape[:-1] + (1,), self.logits.dtype)], -1)
        return jax.nn.softmax(full, axis=-1)

    @classmethod
    def from_value(cls, value: ArrayLike) -> "StochasticRows":
        """The exact inverse ``u_ij = log p_ij − log p_{i,M−1}``.

        **Arguments:** ``value``: ``(K, M)``, ``M ≥ 2``, positive entries, rows summing to 1.
        **Returns:** a :class:`StochasticRows`. **Raises:** ``InputError`` for a wrong shape or
        (when concrete) entries not positive or rows not summing to 1.
        """
        P = _float(value)
        check_shape("value", P, [(None, None)])
        if P.shape[1] < 2:
            raise InputError(f"`value` must have at least 2 columns; got shape {P.shape}.")
        if not isinstance(P, jax.core.Tracer):
            a = np.asarray(P)
            if not (np.all(a > 0) and np.allclose(a.sum(-1), 1.0, atol=1e-8)):
                raise InputError("`value` must have positive entries and rows summing to 1.")
        logP = jnp.log(P)
        return cls(logP[:, :-1] - logP[:, -1:])


def _is_param(x) -> bool:
    return isinstance(x, AbstractParametrisation)


def natural(params: PyTree) -> PyTree:
    """Map a pytree of parametrisations to their natural values.

    **Arguments:** ``params``: any pytree whose nodes are :class:`AbstractParametrisation`
    Modules or plain float arrays (a plain array is its own natural value: an unconstrained
    parameter such as a bias).

    **Returns:** the same structure with each parametrisation replaced by its ``value``.
    """
    return jax.tree_util.tree_map(lambda p: p.value if _is_param(p) else p, params, is_leaf=_is_param)
