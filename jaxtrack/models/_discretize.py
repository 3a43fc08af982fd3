"""Continuous-time linear dynamics to discrete transition and process-noise matrices.

For the linear SDE ``dx = A x dt + dβ`` with ``E[dβ dβᵀ] = Q_c dt`` (``Q_c`` already mapped into
state space, i.e. ``L Q_c Lᵀ`` for a noise gain ``L``), the exact discretisation over a period τ is

.. math::

    Φ(τ) = e^{Aτ}, \\qquad Q_d(τ) = \\int_0^τ e^{As} Q_c e^{Aᵀs}\\,ds.

:func:`van_loan` evaluates both with one matrix exponential (Van Loan 1978, Theorem 1), and
:func:`discretize` maps it over a sampling schedule ``taus`` so that the result can feed the
per-step ``F``/``Q`` of a :class:`~jaxtrack.models.LinearGaussianModel`, differentiably in each τ_k.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.linalg import expm
from jaxtyping import Array, ArrayLike, Float

from .._validation import InputError, check_covariance, check_finite, check_shape, is_concrete, nan_where_traced


def check_taus(name: str, taus, *, allow_vector: bool = True) -> Array:
    """Return ``taus`` as a float array after checking its shape and (when concrete) its values.

    Accepts a scalar ``()`` or, with ``allow_vector``, a schedule of shape ``(T,)`` with ``T ≥ 1``.
    Every entry must be finite and strictly positive (seconds).

    **Arguments:**

    - ``name``: the argument name for error messages.
    - ``taus``: the sampling period(s) (s), scalar ``()`` or ``(T,)``.
    - ``allow_vector``: accept a ``(T,)`` schedule (default True).

    **Returns:** ``taus`` as a floating array of the same shape, s.

    **Raises:** ``InputError`` for a wrong shape, an empty schedule, or non-finite or non-positive entries.
    """
    taus = jnp.asarray(taus)
    taus = taus.astype(jnp.result_type(taus, float))
    check_shape(name, taus, [(), (None,)] if allow_vector else [()])
    if taus.ndim == 1 and taus.shape[0] == 0:
        raise InputError(f"`{name}` must hold at least one sampling period; got an empty array.")
    check_finite(name, taus)
    if is_concrete(taus):
        arr = np.asarray(taus)
        if np.any(arr <= 0):
            bad = np.argwhere(np.atleast_1d(arr) <= 0)
            first = int(bad[0][0])
            raise InputError(
                f"`{name}` must be strictly positive (sampling periods in seconds); "
                f"{len(bad)} entries are not (first at index {first}: {np.atleast_1d(arr)[first]})."
            )
    return nan_where_traced(taus, lambda t: t <= 0)


def _check_dynamics(A, Qc, A_name: str, Qc_name: str) -> tuple[Array, Array]:
    A = jnp.asarray(A)
    Qc = jnp.asarray(Qc)
    dtype = jnp.result_type(A, Qc, float)
    A, Qc = A.astype(dtype), Qc.astype(dtype)
    check_shape(A_name, A, [(None, None)])
    n = A.shape[0]
    if A.shape[1] != n:
        raise InputError(f"`{A_name}` must be a square (n, n) matrix; got shape {A.shape}.")
    check_shape(Qc_name, Qc, [(n, n)])
    check_finite(A_name, A)
    check_covariance(Qc_name, Qc, definite=False)
    return A, Qc


def _van_loan(A: Array, Qc: Array, tau: Array) -> tuple[Array, Array]:
    n = A.shape[0]
    zeros = jnp.zeros_like(A)
    M = jnp.block([[-A, Qc], [zeros, A.T]]) * tau
    E = expm(M)
    # E = [[e^{-Aτ}, e^{-Aτ} Q_d], [0, e^{Aᵀτ}]] (Van Loan 1978, Theorem 1 with B = Q_c).
    Phi = E[n:, n:].T
    Qd = Phi @ E[:n, n:]
    # Q_d is symmetric in exact arithmetic; the product Φ·(e^{-Aτ}Q_d) is not, by rounding
    # (~eps·‖Q_d‖). Symmetrise so the filter's covariance stays symmetric.
    Qd = 0.5 * (Qd + Qd.T)
    return Phi, Qd


# Jitted once per shape and dtype, so eager calls with new values (or a new schedule of the same
# length) reuse one compilation; inside an outer jit/grad/vmap they are inlined as usual.
_van_loan_one = jax.jit(_van_loan)
_van_loan_stack = jax.jit(jax.vmap(_van_loan, in_axes=(None, None, 0)))


def van_loan(
    A: ArrayLike, L_Qc_Lt: ArrayLike, tau: ArrayLike
) -> tuple[Float[Array, "n n"], Float[Array, "n n"]]:
    r"""Discretise ``dx = A x dt + noise`` over one period τ by Van Loan's method.

    With the block matrix

    .. math::

        M = \begin{bmatrix} -A & Q_c \\ 0 & Aᵀ \end{bmatrix} τ, \qquad
        e^{M} = \begin{bmatrix} E_{11} & E_{12} \\ 0 & E_{22} \end{bmatrix},

    Van Loan (1978, Theorem 1) gives ``Φ = e^{Aτ} = E_{22}ᵀ`` and
    ``Q_d = ∫_0^τ e^{As} Q_c e^{Aᵀs} ds = Φ E_{12}``. ``Q_d`` is symmetrised after the product to
    remove rounding asymmetry.

    Differentiable in ``A``, ``L_Qc_Lt`` and ``tau`` (through ``jax.scipy.linalg.expm``), and usable
    under ``jax.vmap`` over ``tau``; see :func:`discretize` for a whole schedule.

    **Arguments:**

    - ``A``: continuous-time system matrix, shape ``(n, n)``, units 1/s.
    - ``L_Qc_Lt``: spectral density matrix of the white process noise, already mapped into state
      space (``L Q_c Lᵀ``), shape ``(n, n)``, symmetric positive semidefinite, units
      (state unit)²/s.
    - ``tau``: sampling period τ, shape ``()``, seconds, finite and > 0.

    **Returns:**

    ``(Phi, Qd)``: the transition matrix ``Φ(τ)`` and process-noise covariance ``Q_d(τ)``, each
    shape ``(n, n)``.

    **Raises:**

    :class:`~jaxtrack.InputError` if ``A`` is not square, ``L_Qc_Lt`` has the wrong shape or is not
    symmetric PSD, or ``tau`` is not a positive finite scalar (value checks only when concrete).

    ??? cite "Reference"

        ```bibtex
        @article{vanloan1978,
          author  = {Van Loan, Charles F.},
          title   = {Computing Integrals Involving the Matrix Exponential},
          journal = {IEEE Transactions on Automatic Control},
          volume  = {23},
          number  = {3},
          pages   = {395--404},
          year    = {1978},
        }
        ```

    Example (constant velocity in 1D: ``Q_d = q [[τ³/3, τ²/2], [τ²/2, τ]]``):

    >>> import jax.numpy as jnp
    >>> A = jnp.array([[0.0, 1.0], [0.0, 0.0]])
    >>> Phi, Qd = van_loan(A, jnp.diag(jnp.array([0.0, 3.0])), 2.0)
    >>> Phi.round(12).tolist(), Qd.round(12).tolist()
    ([[1.0, 2.0], [0.0, 1.0]], [[8.0, 6.0], [6.0, 6.0]])
    """
    A, Qc = _check_dynamics(A, L_Qc_Lt, "A", "L_Qc_Lt")
    tau = check_taus("tau", tau, allow_vector=False).astype(A.dtype)
    return _van_loan_one(A, Qc, tau)


def discretize(
    A: ArrayLike, Qc: ArrayLike, taus: ArrayLike
) -> tuple[Float[Array, "*T n n"], Float[Array, "*T n n"]]:
    r"""Van Loan discretisation (:func:`van_loan`) over a scalar period or a whole schedule.

    For a schedule ``taus`` of shape ``(T,)`` the result is the per-step stacks ``Φ[k] = e^{Aτ_k}``
    and ``Q_d[k] = ∫_0^{τ_k} e^{As} Q_c e^{Aᵀs} ds``, computed with one ``jax.vmap`` (one
    compilation regardless of ``T``). Following the model convention, ``taus[k]`` is the interval
    that ends at measurement ``k``, so the stacks can be passed straight to
    :class:`~jaxtrack.models.LinearGaussianModel`.

    **Arguments:**

    - ``A``: continuous-time system matrix, shape ``(n, n)``, units 1/s.
    - ``Qc``: state-space spectral density ``L Q_c Lᵀ``, shape ``(n, n)``, symmetric PSD,
      units (state unit)²/s.
    - ``taus``: sampling period(s) in seconds, shape ``()`` or ``(T,)``, each finite and > 0.

    **Returns:**

    ``(Phi, Qd)``, each of shape ``(n, n)`` for a scalar ``taus`` or ``(T, n, n)`` for a schedule.

    **Raises:**

    :class:`~jaxtrack.InputError` as :func:`van_loan`, naming ``A``, ``Qc`` or ``taus``.
    """
    A, Qc = _check_dynamics(A, Qc, "A", "Qc")
    taus = check_taus("taus", taus).astype(A.dtype)
    if taus.ndim == 0:
        return _van_loan_one(A, Qc, taus)
    return _van_loan_stack(A, Qc, taus)
