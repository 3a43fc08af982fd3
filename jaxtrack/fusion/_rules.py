"""Fusion rules: two Gaussian estimates of one state, with unknown, partly known or known correlation.

Every rule is a plain function of arrays (``covariance_intersection``, ...) and a strategy object
(``CovarianceIntersection()``, ...) that calls it, so that the track-fusion run
(:func:`~jaxtrack.fusion.run_track_fusion`) and a user's own loop take the rule as an argument.
All act on ONE pair of estimates (no batch axis); batches come from ``jax.vmap``.

Why the optimal CI weight is found by bisection and differentiated by the implicit function
theorem: the criterion ``J(ω)`` (trace or log-determinant of the fused covariance) is convex in
``ω`` for CI and for split CI (see :func:`optimal_ci_weight`), so the sign of ``dJ/dω`` (by
autodiff) brackets the minimiser; a fixed number of halvings keeps the function jittable with a
static loop, and ``jax.lax.custom_root`` gives the exact derivative of the minimiser
``dω*/dθ = −(∂g/∂ω)⁻¹ ∂g/∂θ`` (``g = dJ/dω``) instead of differentiating through the loop.
"""

from __future__ import annotations

from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._validation import (
    InputError,
    check_covariance,
    check_finite,
    check_shape,
    is_concrete,
    nan_where_traced,
)
from ..filters._linalg import cholesky_and_inverse
from ..filters._updates import symmetrize

Criterion = Literal["trace", "det"]
CRITERIA = ("trace", "det")
# Halvings of [0, 1]: after 64 the bracket is 5e-20 wide, below float64 resolution at any ω.
DEFAULT_ITERATIONS = 64


class FusedEstimate(eqx.Module):
    """The result of every fusion rule (one fused estimate, no batch axis).

    **Fields** (``n`` states):

    - ``mean``: the fused mean, ``(n,)``, in the state's units.
    - ``cov``: the fused covariance, ``(n, n)`` (symmetric), in the state's units squared.
    - ``ok``: ``()`` bool; False when the mean or covariance is not finite (a covariance that is
      not positive definite, a traced weight outside ``[0, 1]``: see each rule). A rule never
      returns a non-finite answer with ``ok`` True.
    - ``weight``: ``ω``, ``()``, the weight of the first estimate (covariance intersection and
      split CI, given or optimal); None for the other rules.
    - ``independent_cov``: split CI only, ``(n, n)``: the independent part of ``cov`` (Li et al.
      2013); None for the other rules.
    - ``mutual_mean``, ``mutual_cov``: ellipsoidal intersection only, ``(n,)`` and ``(n, n)``:
      the mutual estimate ``γ``, ``Γ`` (Sijs & Lazar 2012); None for the other rules.
    """

    mean: Float[Array, " n"]
    cov: Float[Array, "n n"]
    ok: Bool[Array, ""]
    weight: Float[Array, ""] | None = None
    independent_cov: Float[Array, "n n"] | None = None
    mutual_mean: Float[Array, " n"] | None = None
    mutual_cov: Float[Array, "n n"] | None = None


# --------------------------------------------------------------------------------------------
# Input checks (concrete values; under jit/vmap/grad only the shapes, see _validation).


def _as_pair(mean1, cov1, mean2, cov2):
    x1, P1, x2, P2 = (jnp.asarray(a) for a in (mean1, cov1, mean2, cov2))
    dtype = jnp.result_type(x1, P1, x2, P2, float)
    x1, P1, x2, P2 = (a.astype(dtype) for a in (x1, P1, x2, P2))
    check_shape("mean1", x1, [(None,)])
    n = x1.shape[0]
    check_shape("cov1", P1, [(n, n)])
    check_shape("mean2", x2, [(n,)])
    check_shape("cov2", P2, [(n, n)])
    for name, x in (("mean1", x1), ("mean2", x2)):
        check_finite(name, x)
    for name, P in (("cov1", P1), ("cov2", P2)):
        check_covariance(name, P)
    return x1, P1, x2, P2


def _as_cov_like(name: str, value, n: int, dtype, *, definite: bool = False):
    a = jnp.asarray(value).astype(dtype)
    check_shape(name, a, [(n, n)])
    check_covariance(name, a, definite=definite)
    return a


def _check_criterion(criterion) -> None:
    if not isinstance(criterion, str) or criterion not in CRITERIA:
        raise InputError(f"`criterion` must be 'trace' or 'det'; got {criterion!r}.")


def _check_iterations(iterations) -> None:
    if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1:
        raise InputError(f"`iterations` must be a positive int; got {iterations!r}.")


def _as_weight(omega, dtype=None):
    """``ω`` as a scalar array; a concrete one outside ``[0, 1]`` raises, a traced one becomes NaN."""
    w = jnp.asarray(omega)
    w = w.astype(jnp.result_type(w, float) if dtype is None else dtype)
    check_shape("omega", w, [()])
    if is_concrete(w):
        value = float(w)
        if not 0.0 <= value <= 1.0:  # NaN fails too
            raise InputError(f"`omega` must lie in [0, 1]; got {value!r}.")
        return w
    return nan_where_traced(w, lambda v: ~((v >= 0.0) & (v <= 1.0)))


def _estimate(mean, cov, **extra) -> FusedEstimate:
    ok = jnp.all(jnp.isfinite(mean)) & jnp.all(jnp.isfinite(cov))
    return FusedEstimate(mean, cov, ok, **extra)


# --------------------------------------------------------------------------------------------
# Linear algebra (any n; these run once per scan, not per run of a batched filter step).


def _spd_inverse(a: Array) -> Array:
    """``a⁻¹`` for a symmetric positive definite ``a``, as ``L⁻ᵀ L⁻¹``: exactly symmetric."""
    _, L_inv = cholesky_and_inverse(a)
    return L_inv.T @ L_inv


def _criterion_of_information(Y: Array, criterion: str) -> Array:
    """``tr(Y⁻¹)`` or ``log det(Y⁻¹)`` from one Cholesky factor of the information matrix ``Y``.

    The factor and its inverse are written out entry by entry up to ``n = 4``
    (``filters._linalg``), not LAPACK calls: XLA:CPU (jax 0.10.2) stopped with every thread idle
    on the optimal weight's 64-step bisection of ``tr(Y⁻¹)`` batched over 3,200 pairs (800 runs of
    a 4-slot fusion tracker) through ``potrf``/``trsm`` and their derivatives, while 3,000 took 0.2 s.
    """
    L, L_inv = cholesky_and_inverse(Y)
    if criterion == "det":
        return -2.0 * jnp.sum(jnp.log(jnp.diagonal(L)))
    return jnp.sum(L_inv * L_inv)


def _scalar_tangent_solve(linear, y):
    # g'(ω*)⁻¹ y. g' > 0 where J is strictly convex; a flat criterion (g' = 0: P1 = P2, any ω is
    # optimal) gives the zero tangent rather than 0/0.
    slope = linear(jnp.ones_like(y))
    return y / jnp.where(slope == 0, 1.0, slope)


def _optimal_weight(information, criterion: str, iterations: int, dtype) -> Array:
    """``argmin_{ω∈[0,1]} J(ω)``, ``J`` the criterion of ``information(ω)``; convex ``J`` assumed.

    Interior minimiser: bisection on the sign of ``g = dJ/dω`` (autodiff), differentiated by
    ``lax.custom_root``. Boundary minimiser (``g(0) ≥ 0`` or ``g(1) ≤ 0``): ``ω* = 0`` or ``1``
    exactly, with zero derivative (a minimiser held at a bound does not move with the inputs).
    """
    def criterion_at(w):
        return _criterion_of_information(information(w), criterion)

    g = jax.grad(criterion_at)
    zero, one = jnp.zeros((), dtype), jnp.ones((), dtype)

    def bisect(f, _guess):
        def halve(_, bracket):
            a, b = bracket
            mid = 0.5 * (a + b)
            right = f(mid) < 0  # J still decreasing at mid: the minimiser lies to its right
            return jnp.where(right, mid, a), jnp.where(right, b, mid)

        a, b = jax.lax.fori_loop(0, iterations, halve, (zero, one))
        return 0.5 * (a + b)

    interior = jax.lax.custom_root(g, 0.5 * one, bisect, _scalar_tangent_solve)
    at_lower = g(zero) >= 0
    at_upper = g(one) <= 0
    return jnp.where(at_lower, zero, jnp.where(at_upper, one, interior))


# --------------------------------------------------------------------------------------------
# Covariance intersection


def _ci_information(Y1, Y2, w):
    return w * Y1 + (1.0 - w) * Y2


def optimal_ci_weight(
    cov1: Float[ArrayLike, "n n"],
    cov2: Float[ArrayLike, "n n"],
    *,
    criterion: Criterion = "trace",
    iterations: int = DEFAULT_ITERATIONS,
) -> Float[Array, ""]:
    r"""The covariance-intersection weight that minimises the trace or determinant of the fused covariance.

    .. math::

        ω^* = \arg\min_{ω ∈ [0, 1]} J(ω),\qquad
        J(ω) = \operatorname{tr} P(ω)\ \text{or}\ \log\det P(ω),\qquad
        P(ω)^{-1} = ω P_1^{-1} + (1 − ω) P_2^{-1}

    (Julier & Uhlmann 1997 choose ``ω`` to minimise the trace or the determinant of ``P``).
    Both criteria are convex in ``ω`` (``P(ω)⁻¹`` is affine in ``ω``; ``Y ↦ tr Y⁻¹`` and
    ``Y ↦ −log det Y`` are convex), so the sign of ``dJ/dω`` brackets ``ω*``: ``iterations``
    halvings of ``[0, 1]`` (static, jittable), ``dJ/dω`` by autodiff. A minimiser on the
    boundary (``dJ/dω ≥ 0`` at 0 or ``≤ 0`` at 1) is returned as exactly 0 or 1.

    **Derivative:** exact. In the interior by the implicit function theorem on ``dJ/dω = 0``
    (``jax.lax.custom_root``), not through the loop; on the boundary ``ω*`` does not move, its
    derivative is 0. Where ``P_1 = P_2`` every ``ω`` is optimal (0 is returned, derivative 0).

    **Arguments:**

    - ``cov1``, ``cov2``: ``P_1``, ``P_2``, ``(n, n)``, symmetric positive definite, in the
      state's units squared.
    - ``criterion``: ``"trace"`` (default) or ``"det"`` (static).
    - ``iterations``: the number of halvings (static; default 64: the bracket is then narrower
      than float64 resolution).

    **Returns:** ``ω*``, ``()``, dimensionless, the weight of the first estimate.

    **Raises:** ``InputError`` naming the argument for a shape that is not ``(n, n)``, a concrete
    covariance that is not symmetric positive definite, an unknown ``criterion`` or a bad
    ``iterations``.

    References: S. J. Julier and J. K. Uhlmann, "A non-divergent estimation algorithm in the
    presence of unknown correlations", Proc. American Control Conference, 1997.
    """
    _check_criterion(criterion)
    _check_iterations(iterations)
    P1 = jnp.asarray(cov1)
    n = P1.shape[0] if P1.ndim else 0
    _, P1, _, P2 = _as_pair(jnp.zeros((n,), jnp.result_type(P1, float)), P1, jnp.zeros((n,)), cov2)
    Y1, Y2 = _spd_inverse(P1), _spd_inverse(P2)
    return _optimal_weight(lambda w: _ci_information(Y1, Y2, w), criterion, iterations, P1.dtype)


def covariance_intersection(
    mean1: Float[ArrayLike, " n"],
    cov1: Float[ArrayLike, "n n"],
    mean2: Float[ArrayLike, " n"],
    cov2: Float[ArrayLike, "n n"],
    omega: Float[ArrayLike, ""] | None = None,
    *,
    criterion: Criterion = "trace",
    iterations: int = DEFAULT_ITERATIONS,
) -> FusedEstimate:
    r"""Covariance intersection of two estimates with unknown correlation (Julier & Uhlmann 1997).

    .. math::

        P^{-1} = ω P_1^{-1} + (1 − ω) P_2^{-1},\qquad
        P^{-1} x̂ = ω P_1^{-1} x̂_1 + (1 − ω) P_2^{-1} x̂_2

    (Julier & Uhlmann 1997). For every ``ω ∈ [0, 1]`` and every cross-covariance
    of the two errors that makes the joint covariance valid, ``P`` bounds the actual error
    covariance of ``x̂`` (it is consistent). ``ω`` is given, or (``omega=None``) the minimiser of
    the trace or log-determinant of ``P`` (:func:`optimal_ci_weight`).

    **Arguments:**

    - ``mean1``, ``mean2``: ``x̂_1``, ``x̂_2``, ``(n,)``, in the state's units.
    - ``cov1``, ``cov2``: ``P_1``, ``P_2``, ``(n, n)``, symmetric positive definite, in the
      state's units squared.
    - ``omega``: ``ω``, the weight of the first estimate, a scalar in ``[0, 1]`` (an array leaf:
      ``jax.grad`` with respect to it works), or None (default) for the optimal weight.
    - ``criterion``: ``"trace"`` (default) or ``"det"``, for ``omega=None`` (static).
    - ``iterations``: bisection halvings for ``omega=None`` (static; default 64).

    **Returns:** a :class:`FusedEstimate` with ``weight`` ``ω``. A traced ``ω`` outside
    ``[0, 1]`` (under ``jit``/``vmap``/``grad``, where it cannot be checked) gives NaN and
    ``ok`` False; so does a traced covariance that is not positive definite.

    **Raises:** ``InputError`` naming the argument for mismatched or non-square shapes, concrete
    non-finite means or covariances that are not symmetric positive definite, a concrete
    ``omega`` outside ``[0, 1]``, an unknown ``criterion`` or a bad ``iterations``.

    Differentiable in every input and in ``ω``; through the optimal ``ω`` exactly (see
    :func:`optimal_ci_weight`).

    References: S. J. Julier and J. K. Uhlmann, "A non-divergent estimation algorithm in the
    presence of unknown correlations", Proc. American Control Conference, 1997.
    """
    _check_criterion(criterion)
    _check_iterations(iterations)
    x1, P1, x2, P2 = _as_pair(mean1, cov1, mean2, cov2)
    # The weight first: a bad concrete ω raises before any arithmetic.
    w = None if omega is None else _as_weight(omega, P1.dtype)
    Y1, Y2 = _spd_inverse(P1), _spd_inverse(P2)
    if w is None:
        w = _optimal_weight(lambda v: _ci_information(Y1, Y2, v), criterion, iterations, P1.dtype)
    a1, a2 = w * Y1, (1.0 - w) * Y2
    P = _spd_inverse(a1 + a2)
    return _estimate(P @ (a1 @ x1 + a2 @ x2), P, weight=w)


# --------------------------------------------------------------------------------------------
# Split covariance intersection


def _sci_inflated_information(P, Pi, w):
    """``(P_d/ω + P_i)⁻¹ = ω (P_d + ω P_i)⁻¹`` with ``P_d = P − P_i``: finite at ``ω = 0`` for PD ``P_d``."""
    return w * _spd_inverse(P - (1.0 - w) * Pi)


def _sci_information(P1, P1i, P2, P2i, w):
    return _sci_inflated_information(P1, P1i, w) + _sci_inflated_information(P2, P2i, 1.0 - w)


def _as_split(mean1, cov1, independent_cov1, mean2, cov2, independent_cov2):
    x1, P1, x2, P2 = _as_pair(mean1, cov1, mean2, cov2)
    n, dtype = x1.shape[0], x1.dtype
    parts = []
    for i, (P, Pi) in enumerate(((P1, independent_cov1), (P2, independent_cov2)), start=1):
        Pi = jnp.zeros((n, n), dtype) if Pi is None else _as_cov_like(f"independent_cov{i}", Pi, n, dtype)
        # The dependent part P − P_i must itself be a covariance (positive semidefinite).
        if is_concrete(P) and is_concrete(Pi):
            try:
                check_covariance(f"cov{i} - independent_cov{i}", P - Pi, definite=False)
            except InputError as err:
                raise InputError(f"`independent_cov{i}` must not exceed `cov{i}`: {err}") from None
        parts.append(Pi)
    return x1, P1, parts[0], x2, P2, parts[1]


def optimal_sci_weight(
    cov1: Float[ArrayLike, "n n"],
    independent_cov1: Float[ArrayLike, "n n"],
    cov2: Float[ArrayLike, "n n"],
    independent_cov2: Float[ArrayLike, "n n"],
    *,
    criterion: Criterion = "trace",
    iterations: int = DEFAULT_ITERATIONS,
) -> Float[Array, ""]:
    r"""The split-CI weight that minimises the trace or log-determinant of the fused covariance.

    As :func:`optimal_ci_weight`, with the fused information of split CI
    (:func:`split_covariance_intersection`),
    ``P(ω)⁻¹ = ω (P_{1d} + ω P_{1i})⁻¹ + (1 − ω)(P_{2d} + (1 − ω) P_{2i})⁻¹``. Each term is the
    parallel sum of ``ω P_{1d}⁻¹`` (affine in ``ω``) and ``P_{1i}⁻¹``, which is operator concave,
    so the criterion is again convex in ``ω`` and bisection on ``dJ/dω`` finds its minimiser;
    the derivative is exact (implicit function theorem; 0 on the boundary).

    **Arguments:** ``cov1``, ``cov2``: the total covariances ``P_1 = P_{1d} + P_{1i}``, ``(n,
    n)``; ``independent_cov1``, ``independent_cov2``: their independent parts ``P_{1i}``,
    ``P_{2i}``, ``(n, n)``, positive semidefinite and not exceeding ``P_1``, ``P_2`` (state
    units squared); ``criterion``, ``iterations`` as in :func:`optimal_ci_weight`.

    **Returns:** ``ω*``, ``()``. A dependent part that is singular makes the criterion at the
    bound it belongs to undefined; the minimiser is then found inside ``(0, 1)``.

    **Raises:** ``InputError`` naming the argument, as :func:`split_covariance_intersection`.
    """
    _check_criterion(criterion)
    _check_iterations(iterations)
    P1 = jnp.asarray(cov1)
    n = P1.shape[0] if P1.ndim else 0
    zero = jnp.zeros((n,), jnp.result_type(P1, float))
    _, P1, P1i, _, P2, P2i = _as_split(zero, P1, independent_cov1, zero, cov2, independent_cov2)
    return _optimal_weight(lambda w: _sci_information(P1, P1i, P2, P2i, w), criterion, iterations, P1.dtype)


def split_covariance_intersection(
    mean1: Float[ArrayLike, " n"],
    cov1: Float[ArrayLike, "n n"],
    independent_cov1: Float[ArrayLike, "n n"] | None,
    mean2: Float[ArrayLike, " n"],
    cov2: Float[ArrayLike, "n n"],
    independent_cov2: Float[ArrayLike, "n n"] | None,
    omega: Float[ArrayLike, ""] | None = None,
    *,
    criterion: Criterion = "trace",
    iterations: int = DEFAULT_ITERATIONS,
) -> FusedEstimate:
    r"""Split covariance intersection: CI on the dependent parts, independent parts fused as such.

    Each covariance is split as ``P_1 = P_{1d} + P_{1i}``: the errors' independent parts are
    uncorrelated between the two estimates, their dependent parts have an unknown correlation.
    With ``ω ∈ [0, 1]`` (Julier & Uhlmann 2001; Li, Nashashibi & Yang 2013, the SCI fusion step):

    .. math::

        P_{1ω} = P_{1d}/ω + P_{1i},\qquad P_{2ω} = P_{2d}/(1 − ω) + P_{2i}

        P = (P_{1ω}^{-1} + P_{2ω}^{-1})^{-1},\qquad
        x̂ = P (P_{1ω}^{-1} x̂_1 + P_{2ω}^{-1} x̂_2)

        P_i = P (P_{1ω}^{-1} P_{1i} P_{1ω}^{-1} + P_{2ω}^{-1} P_{2i} P_{2ω}^{-1}) P,\qquad P_d = P − P_i

    ``P_{1ω}⁻¹`` is formed as ``ω (P_{1d} + ω P_{1i})⁻¹``, which is finite at ``ω = 0`` when
    ``P_{1d}`` is positive definite (and likewise for the second estimate at ``ω = 1``). With
    zero independent parts this is :func:`covariance_intersection`; with zero dependent parts,
    the independent (information-form) fusion. ``ω`` is given, or (``omega=None``) the minimiser
    of the trace or log-determinant of ``P`` (:func:`optimal_sci_weight`).

    **Arguments:**

    - ``mean1``, ``mean2``: ``(n,)``; ``cov1``, ``cov2``: the total covariances ``(n, n)``,
      symmetric positive definite (state units, squared).
    - ``independent_cov1``, ``independent_cov2``: ``P_{1i}``, ``P_{2i}``, ``(n, n)``, positive
      semidefinite and not exceeding the totals (``P − P_i ⪰ 0``); None means 0.
    - ``omega``, ``criterion``, ``iterations``: as in :func:`covariance_intersection`.

    **Returns:** a :class:`FusedEstimate` with ``weight`` ``ω`` and ``independent_cov`` ``P_i``.
    ``ω`` exactly 0 (1) with a singular ``P_{1d}`` (``P_{2d}``) has no finite answer: NaN, ``ok``
    False. A traced ``ω`` outside ``[0, 1]`` gives NaN and ``ok`` False.

    **Raises:** ``InputError`` naming the argument for bad shapes, concrete covariances that are
    not symmetric positive (semi)definite, an independent part exceeding its total, a concrete
    ``omega`` outside ``[0, 1]``, an unknown ``criterion`` or a bad ``iterations``.

    References: S. J. Julier and J. K. Uhlmann, "General decentralized data fusion with
    covariance intersection", in Handbook of Multisensor Data Fusion, CRC Press, 2001; H. Li, F.
    Nashashibi and M. Yang, "Split covariance intersection filter: theory and its application
    to vehicle localization", IEEE Trans. Intelligent Transportation Systems 14(4), 2013.
    """
    _check_criterion(criterion)
    _check_iterations(iterations)
    x1, P1, P1i, x2, P2, P2i = _as_split(mean1, cov1, independent_cov1, mean2, cov2, independent_cov2)
    if omega is None:
        w = _optimal_weight(lambda v: _sci_information(P1, P1i, P2, P2i, v), criterion, iterations, P1.dtype)
    else:
        w = _as_weight(omega, P1.dtype)
    Y1 = _sci_inflated_information(P1, P1i, w)
    Y2 = _sci_inflated_information(P2, P2i, 1.0 - w)
    P = _spd_inverse(Y1 + Y2)
    # P Y P is symmetric in exact arithmetic; the products round asymmetrically.
    Pi = symmetrize(P @ (Y1 @ P1i @ Y1 + Y2 @ P2i @ Y2) @ P)
    return _estimate(P @ (Y1 @ x1 + Y2 @ x2), P, weight=w, independent_cov=Pi)


# --------------------------------------------------------------------------------------------
# Ellipsoidal intersection


def ellipsoidal_intersection(
    mean1: Float[ArrayLike, " n"],
    cov1: Float[ArrayLike, "n n"],
    mean2: Float[ArrayLike, " n"],
    cov2: Float[ArrayLike, "n n"],
    *,
    zeta: float | None = None,
) -> FusedEstimate:
    r"""Ellipsoidal intersection (Sijs & Lazar 2012): remove the mutual estimate once.

    The fused estimate is the independent fusion of the two with their *mutual* estimate
    ``(γ, Γ)`` (the information they share) subtracted once (Sijs & Lazar 2012, eq. (8)):

    .. math::

        P = (P_1^{-1} + P_2^{-1} − Γ^{-1})^{-1},\qquad
        x̂ = P (P_1^{-1} x̂_1 + P_2^{-1} x̂_2 − Γ^{-1} γ)

    ``Γ`` and ``γ`` come from a joint diagonalisation: ``P_1 = S_1 D_1 S_1ᵀ`` and
    ``D_1^{-1/2} S_1ᵀ P_2 S_1 D_1^{-1/2} = S_2 D_2 S_2ᵀ`` (eq. (12a)), ``T = S_1 D_1^{1/2} S_2``
    (eq. (12b)), so that ``T⁻¹ P_1 T⁻ᵀ = I`` and ``T⁻¹ P_2 T⁻ᵀ = D_2`` (eq. (10));
    ``D_Γ = max(I, D_2)`` entry by entry (eq. (11)), ``Γ = T D_Γ Tᵀ`` (Theorem 6); with
    ``μ_i = T⁻¹ x̂_i`` (eq. (13)), ``γ = T μ_γ`` and

    .. math::

        μ_γ = (W_1 + W_2)^{-1}(W_1 μ_1 + W_2 μ_2),\quad
        W_1 = D_2^{-1} − D_Γ^{-1} + ηI,\quad W_2 = I − D_Γ^{-1} + ηI

    (eqs. (16a)–(16b)), ``η = ζ`` if some ``|[D_2]_{jj} − 1| < 10ζ`` and 0 otherwise (eq. (16c):
    the regulariser that keeps ``W_1 + W_2`` invertible when the two variances along an axis are
    equal). Eq. (8) is evaluated in the coordinates of eq. (10), where every matrix is diagonal:
    ``T⁻¹ P T⁻ᵀ = (I + D_2^{-1} − D_Γ^{-1})^{-1} = min(I, D_2)``, so along each joint principal
    axis the fused estimate takes the more precise of the two (the same numbers as eq. (8),
    without its three inverses).

    EI is not conservative in general (unlike CI): it assumes the correlation is the one that
    the mutual estimate stands for.

    **Arguments:**

    - ``mean1``, ``mean2``: ``(n,)``; ``cov1``, ``cov2``: ``(n, n)``, symmetric positive
      definite (state units, squared).
    - ``zeta``: ``ζ`` of eq. (16c), a small positive float, dimensionless (default: ``√ε`` of the
      dtype, 1.5e-8 in float64).

    **Returns:** a :class:`FusedEstimate` with ``mutual_mean`` ``γ`` and ``mutual_cov`` ``Γ``.

    **Raises:** ``InputError`` naming the argument for bad shapes, concrete non-finite means or
    covariances that are not symmetric positive definite, or a ``zeta`` that is not a positive
    float.

    Differentiable where the eigenvalues of eqs. (12a) are distinct and none of ``D_2`` equals 1
    (``eigh`` and ``max`` are not differentiable there).

    References: J. Sijs and M. Lazar, "State fusion with unknown correlation: Ellipsoidal
    intersection", Automatica 48(8), 1874–1878, 2012 (first presented with P. Bosch at the
    American Control Conference 2010).
    """
    x1, P1, x2, P2 = _as_pair(mean1, cov1, mean2, cov2)
    dtype = P1.dtype
    if zeta is None:
        zeta = float(np.sqrt(np.finfo(dtype).eps))
    if isinstance(zeta, bool) or not isinstance(zeta, (int, float)) or not zeta > 0:
        raise InputError(f"`zeta` must be a positive float; got {zeta!r}.")
    d1, S1 = jnp.linalg.eigh(P1)  # eq. (12a)
    r1 = jnp.sqrt(d1)
    A = S1 / r1[None, :]  # S_1 D_1^{-1/2}
    d2, S2 = jnp.linalg.eigh(symmetrize(A.T @ P2 @ A))  # eq. (12a)
    T = (S1 * r1[None, :]) @ S2  # eq. (12b)
    T_inv = S2.T @ A.T  # D_1^{-1/2} S_1ᵀ is A.T; S_2 is orthogonal
    dG = jnp.maximum(d2, 1.0)  # eq. (11)
    Gamma = symmetrize((T * dG[None, :]) @ T.T)  # Theorem 6
    eta = jnp.where(jnp.any(jnp.abs(d2 - 1.0) < 10.0 * zeta), zeta, 0.0)  # eq. (16c)
    W1 = 1.0 / d2 - 1.0 / dG + eta  # eq. (16b)
    W2 = 1.0 - 1.0 / dG + eta
    mu1, mu2 = T_inv @ x1, T_inv @ x2  # eq. (13)
    mu_g = (W1 * mu1 + W2 * mu2) / (W1 + W2)  # eq. (16a)
    gamma = T @ mu_g
    # Eq. (8) in the coordinates of eq. (10): P̂_1 = I, P̂_2 = D_2, Γ̂ = D_Γ are diagonal.
    s = 1.0 / (1.0 + 1.0 / d2 - 1.0 / dG)
    P = symmetrize((T * s[None, :]) @ T.T)
    mean = T @ (s * (mu1 + mu2 / d2 - mu_g / dG))
    return _estimate(mean, P, mutual_mean=gamma, mutual_cov=Gamma)


# --------------------------------------------------------------------------------------------
# Known cross-covariance: Bar-Shalom–Campo; and the independent (naive) fusion


def bar_shalom_campo(
    mean1: Float[ArrayLike, " n"],
    cov1: Float[ArrayLike, "n n"],
    mean2: Float[ArrayLike, " n"],
    cov2: Float[ArrayLike, "n n"],
    cross_cov: Float[ArrayLike, "n n"],
) -> FusedEstimate:
    r"""Bar-Shalom–Campo fusion of two track estimates with known cross-covariance ``P_{12}``.

    .. math::

        x̂ = x̂_1 + (P_1 − P_{12})(P_1 + P_2 − P_{12} − P_{12}ᵀ)^{-1}(x̂_2 − x̂_1)

        P = P_1 − (P_1 − P_{12})(P_1 + P_2 − P_{12} − P_{12}ᵀ)^{-1}(P_1 − P_{12})ᵀ

    (Bar-Shalom & Campo 1986): the linear minimum-variance combination of the two
    estimates given ``P_{12} = E[e_1 e_2ᵀ]``, ``e_i = x − x̂_i`` (Bar-Shalom 1981 gives its
    recursion for two Kalman filters: :func:`cross_covariance_step`). With ``P_{12} = 0`` it is
    the independent fusion :func:`independent_fusion`.

    **Arguments:** ``mean1``, ``mean2``: ``(n,)``; ``cov1``, ``cov2``: ``(n, n)``, symmetric
    positive definite; ``cross_cov``: ``P_{12}``, ``(n, n)`` (not symmetric in general), such
    that the joint covariance ``[[P_1, P_{12}], [P_{12}ᵀ, P_2]]`` is positive semidefinite.

    **Returns:** a :class:`FusedEstimate`. ``S = P_1 + P_2 − P_{12} − P_{12}ᵀ`` (the covariance
    of ``x̂_2 − x̂_1``) may be singular, as it is on a state component that neither sensor has
    observed yet (both tracks then hold the common prior there): its Moore–Penrose inverse is
    used (singular values below ``10·n·ε`` of the largest are taken as 0), which gives the same
    fused estimate as any generalised inverse for a valid joint covariance.

    **Raises:** ``InputError`` naming the argument for bad shapes or concrete values (non-finite
    ``cross_cov``, covariances that are not symmetric positive definite).

    References: Y. Bar-Shalom, "On the track-to-track correlation problem", IEEE Trans.
    Automatic Control 26(2), 1981; Y. Bar-Shalom and L. Campo, "The effect of the common process
    noise on the two-sensor fused-track covariance", IEEE Trans. Aerospace and Electronic
    Systems 22(6), 1986.
    """
    x1, P1, x2, P2 = _as_pair(mean1, cov1, mean2, cov2)
    n = x1.shape[0]
    P12 = jnp.asarray(cross_cov).astype(P1.dtype)
    check_shape("cross_cov", P12, [(n, n)])
    check_finite("cross_cov", P12)
    U = P1 - P12
    # The covariance of x̂_2 − x̂_1: symmetric by definition; keep it so for the decomposition.
    S = symmetrize(P1 + P2 - P12 - P12.T)
    # S may be singular: on a component neither sensor has observed yet, both tracks still hold
    # the common prior, so x̂_2 − x̂_1 is exactly 0 there and U annihilates that direction. Every
    # generalised inverse then gives the same gain; the Moore–Penrose one is used (JAX's cutoff:
    # singular values below 10·n·ε times the largest count as 0). Its derivative is the
    # Golub–Pereyra formula, defined for repeated singular values too.
    gain = U @ jnp.linalg.pinv(S, hermitian=True)  # U S⁺
    P = symmetrize(P1 - gain @ U.T)
    return _estimate(x1 + gain @ (x2 - x1), P)


def independent_fusion(
    mean1: Float[ArrayLike, " n"],
    cov1: Float[ArrayLike, "n n"],
    mean2: Float[ArrayLike, " n"],
    cov2: Float[ArrayLike, "n n"],
) -> FusedEstimate:
    r"""Fusion of two estimates taken as independent (the information filter's sum; the naive rule).

    .. math::

        P^{-1} = P_1^{-1} + P_2^{-1},\qquad P^{-1} x̂ = P_1^{-1} x̂_1 + P_2^{-1} x̂_2

    Optimal when the two errors are uncorrelated; overconfident when they are positively
    correlated (common process noise, a common prior): the rule that CI, EI and Bar-Shalom–Campo
    are measured against.

    **Arguments:** ``mean1``, ``mean2``: ``(n,)``; ``cov1``, ``cov2``: ``(n, n)``, symmetric
    positive definite.

    **Returns:** a :class:`FusedEstimate`.

    **Raises:** ``InputError`` naming the argument for bad shapes or concrete values.
    """
    x1, P1, x2, P2 = _as_pair(mean1, cov1, mean2, cov2)
    Y1, Y2 = _spd_inverse(P1), _spd_inverse(P2)
    P = _spd_inverse(Y1 + Y2)
    return _estimate(P @ (Y1 @ x1 + Y2 @ x2), P)
