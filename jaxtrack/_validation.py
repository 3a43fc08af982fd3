"""Input checks for the public entry points.

Every check names the offending argument and says what was expected. Shape checks always run
(shapes are static under ``jit``). Value checks (finite, symmetric, positive definite) run only
when the value is concrete; under ``jit``/``vmap``/``grad`` tracing they are skipped, because a
traced value cannot be inspected without a host round-trip. Entry points that run under tracing
rely on the filter's own run-time status instead (``FilterResult.ok`` and ``throw=True``).
"""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np


class InputError(ValueError):
    """Raised when an argument to a jaxtrack entry point has the wrong shape or value."""


class CapacityWarning(UserWarning):
    """A static capacity (e.g. ``max_measurements``) was exceeded; the excess was counted, not stored.

    Defined here, below every subpackage, so that :mod:`jaxtrack.association` (JPDA's cluster
    caps) and :mod:`jaxtrack.multitarget` (scan, track-table and mixture capacities) warn with
    the same class; it is exported as ``jaxtrack.multitarget.CapacityWarning``.
    """


# Its public home: warnings print it as jaxtrack.multitarget.CapacityWarning, where the docs and
# the multi-target layer's __all__ place it (as before it moved down here).
CapacityWarning.__module__ = "jaxtrack.multitarget"


def is_concrete(x) -> bool:
    """True when ``x`` holds a value that can be inspected now (not a tracer).

    **Arguments:**

    - ``x``: any value (array, tracer or Python object).

    **Returns:** a Python bool.
    """
    return not isinstance(x, jax.core.Tracer)


def throw_unless_ok(result, ok, message: str):
    """``result``, or a run-time error with ``message`` when ``ok`` is not all True.

    The ``throw=True`` of the entry points. Called on the result of a jitted function, OUTSIDE
    it: when ``ok`` is concrete (an eager call) it is read here and
    ``equinox.EquinoxRuntimeError(message)`` raised (the error type the users of ``throw`` have
    always met); when it is traced (the entry point runs inside the caller's
    ``jit``/``vmap``/``grad``) an ``equinox.error_if`` is attached in the caller's trace. Either
    way the jitted function itself holds no host callback, so JAX's persistent compilation cache
    can store it (JAX refuses to write a program with a host callback: the CLI's second run and
    every test process would compile it again).

    **Arguments:** ``result``: any pytree; ``ok``: a boolean array (all True = no error);
    ``message``: the error's text. **Returns:** ``result``.
    """
    if is_concrete(ok):
        if not bool(np.all(np.asarray(ok))):
            raise eqx.EquinoxRuntimeError(message)
        return result
    return eqx.error_if(result, ~jnp.all(ok), message)


def nan_where_traced(x, bad):
    """The traced twin of a value check: ``x`` with NaN where ``bad``, when ``x`` is traced.

    A constructor checks concrete values and raises ``InputError``; under ``jit``/``vmap``/``grad``
    it cannot see them. Rather than a second error mechanism (an ``equinox.error_if`` would raise
    even where the caller asked for ``throw=False`` and reads ``ok`` per run), a rejected traced
    value becomes NaN: every entry point's ``ok`` flag and its ``throw=True`` error already report
    a non-finite result, so a value the concrete path rejects is never a silent answer. Values
    that pass are returned unchanged (bit for bit, with their gradient).

    **Arguments:** ``x``: a float array; ``bad``: a boolean array broadcastable to ``x`` (or a
    function of ``x`` returning it). **Returns:** ``x`` (concrete) or ``where(bad, nan, x)``.
    """
    if is_concrete(x):
        return x
    bad = bad(x) if callable(bad) else bad
    return jnp.where(bad, jnp.asarray(jnp.nan, x.dtype), x)


def as_key(key, name: str = "key"):
    """A PRNG key from ``key``: a typed key (``jax.random.key``), a legacy ``uint32`` key
    (``jax.random.PRNGKey``), or an integer seed (Python or NumPy int, read as
    ``jax.random.key(seed)``).

    **Arguments:** ``key``: the value given; ``name``: the argument's name, for the error.

    **Returns:** the key (a typed key for an int seed; a key as given otherwise).

    **Raises:** :class:`InputError` naming the argument for anything else (a float, a bool, an
    array that is not a key).
    """
    if isinstance(key, (bool, np.bool_)):
        raise InputError(f"`{name}` must be a PRNG key (jax.random.key(seed)) or an int seed; got {key!r}.")
    if isinstance(key, (int, np.integer)):
        return jax.random.key(int(key))
    dtype = getattr(key, "dtype", None)
    if dtype is not None and (jax.dtypes.issubdtype(dtype, jax.dtypes.prng_key)
                              or (dtype == jnp.uint32 and getattr(key, "shape", None) == (2,))):
        return key
    what = type(key).__name__ if dtype is None else f"an array of dtype {dtype}, shape {getattr(key, 'shape', None)}"
    raise InputError(f"`{name}` must be a PRNG key (jax.random.key(seed)) or an int seed; got {what}.")


def _describe_shape(shape: Sequence[int | None]) -> str:
    return "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"


def check_shape(name: str, x, shapes: Sequence[Sequence[int | None]]) -> None:
    """Raise unless ``x.shape`` matches one of ``shapes`` (``None`` matches any size).

    **Arguments:**

    - ``name``: the argument's name, for the message; ``x``: the array (anything with a shape).
    - ``shapes``: the allowed shapes, each a sequence of sizes or ``None``.

    **Returns:** ``None``.

    **Raises:** ``InputError`` if no shape matches.
    """
    actual = tuple(jnp.shape(x))
    for shape in shapes:
        if len(shape) == len(actual) and all(s is None or s == a for s, a in zip(shape, actual)):
            return
    expected = " or ".join(_describe_shape(s) for s in shapes)
    raise InputError(f"`{name}` must have shape {expected}; got shape {actual}.")


def check_finite(name: str, x) -> None:
    """Raise if a concrete ``x`` has a NaN or infinite entry.

    **Arguments:**

    - ``name``: the argument's name, for the message; ``x``: the array, any shape (tracers are skipped).

    **Returns:** ``None``.

    **Raises:** ``InputError`` naming the count and the first non-finite entry.
    """
    if not is_concrete(x):
        return
    arr = np.asarray(x)
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))
        first = tuple(int(i) for i in bad[0])
        raise InputError(
            f"`{name}` must be finite; it has {len(bad)} non-finite entries "
            f"(first at index {first}: {arr[first]})."
        )


def _last_two(x):
    arr = np.asarray(x)
    return arr.reshape((-1,) + arr.shape[-2:])


def _matrix_label(x, i) -> str:
    return "" if np.ndim(x) == 2 else f" (matrix {i} of the stack)"


def check_symmetric(name: str, x, rtol: float = 1e-8) -> None:
    """Raise if a concrete matrix (or stack of matrices) is not symmetric to ``rtol``.

    **Arguments:**

    - ``name``: the argument's name, for the message.
    - ``x``: a matrix ``(d, d)`` or stack ``(..., d, d)`` (tracers are skipped).
    - ``rtol``: the tolerance on ``max|A − Aᵀ|`` relative to ``max|A|``.

    **Returns:** ``None``.

    **Raises:** ``InputError`` naming the first asymmetric matrix.
    """
    if not is_concrete(x):
        return
    stack = _last_two(x)
    scale = np.maximum(np.max(np.abs(stack), axis=(-1, -2)), np.finfo(stack.dtype).tiny)
    asym = np.max(np.abs(stack - np.swapaxes(stack, -1, -2)), axis=(-1, -2))
    bad = np.flatnonzero(asym > rtol * scale)
    if bad.size:
        i = int(bad[0])
        raise InputError(
            f"`{name}` must be a symmetric covariance matrix{_matrix_label(x, i)}; "
            f"max |A - A^T| = {asym[i]:.3g} against max |A| = {scale[i]:.3g}."
        )


def check_covariance(name: str, x, *, definite: bool = True) -> None:
    """Raise unless ``x`` is a finite symmetric positive (semi)definite matrix or stack of them.

    Definiteness does not depend on units, so a matrix passes if either its own eigenvalues or
    those of its correlation-scaled form ``D^{-1/2} A D^{-1/2}`` (``D = diag(A)``) pass: a
    covariance whose variances span many orders of magnitude (a 33-state navigation prior, 1e-16
    rad² to 1e3 m²) is judged as fairly as a well-scaled one, while rounding noise in the tiny
    entries of a discretised plant noise (which the scaling would magnify) is still tolerated.
    ``definite=False`` accepts singular covariances (e.g. a plant noise acting on one state only)
    but rejects eigenvalues below ``-1e-10`` (correlation form) or ``-1e-10·max|A|``. Stacks are
    checked in batched eigendecompositions, so a per-step model of many steps validates quickly.

    **Arguments:**

    - ``name``: the argument's name, for the message.
    - ``x``: a matrix ``(d, d)`` or stack ``(..., d, d)``, in any units (tracers skip the value checks).
    - ``definite``: require positive definite (default) or only positive semidefinite.

    **Returns:** ``None``.

    **Raises:** ``InputError`` for a non-finite, asymmetric or not positive (semi)definite matrix.
    """
    check_finite(name, x)
    check_symmetric(name, x)
    if not is_concrete(x):
        return
    stack = _last_two(x).astype(np.float64)
    stack = 0.5 * (stack + np.swapaxes(stack, -1, -2))
    diag = np.diagonal(stack, axis1=-2, axis2=-1)
    negative = np.flatnonzero(np.any(diag < 0, axis=-1) | (definite & np.any(diag <= 0, axis=-1)))
    if negative.size:
        i = int(negative[0])
        raise InputError(
            f"`{name}` must be positive {'definite' if definite else 'semidefinite'}{_matrix_label(x, i)}; "
            f"its diagonal holds {np.min(diag[i]):.3g}. Check units (e.g. variances in m², rad²) and "
            f"that no standard deviation is zero."
        )
    inv_sd = np.where(diag > 0, 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0)), 1.0)
    corr = stack * inv_sd[..., :, None] * inv_sd[..., None, :]
    smallest = np.linalg.eigvalsh(corr)[:, 0]
    raw = np.linalg.eigvalsh(stack)[:, 0]
    scale = np.maximum(np.max(np.abs(stack), axis=(-1, -2)), np.finfo(np.float64).tiny)
    if definite:
        bad = np.flatnonzero((smallest <= 0.0) & (raw <= 0.0))
        if bad.size:
            i = int(bad[0])
            raise InputError(
                f"`{name}` must be positive definite{_matrix_label(x, i)}; the smallest eigenvalue of "
                f"its correlation matrix is {smallest[i]:.3g}. Check units (e.g. variances in m², "
                f"rad²) and that no standard deviation is zero."
            )
    else:
        bad = np.flatnonzero((smallest < -1e-10) & (raw < -1e-10 * scale))
        if bad.size:
            i = int(bad[0])
            raise InputError(
                f"`{name}` must be positive semidefinite{_matrix_label(x, i)}; the smallest "
                f"eigenvalue of its correlation matrix is {smallest[i]:.3g}."
            )


def covariance_ok(x, *, definite: bool = True):
    """Traceable twin of :func:`check_covariance`: a JAX bool, True when ``x`` passes.

    For use under ``jit``/``vmap``/``grad``, where :func:`check_covariance` cannot look at the
    value: the result feeds a status flag (``ok``) or an ``equinox.error_if``. The criteria are
    those of :func:`check_covariance` (finite, symmetric to 1e-8 relative, diagonal positive (or
    non-negative with ``definite=False``), smallest eigenvalue of the matrix or of its
    correlation-scaled form positive, or above ``-1e-10`` for semidefinite). One batched
    ``eigvalsh`` per call, so call it once per run, never inside a per-step loop.

    **Arguments:**

    - ``x``: a matrix ``(d, d)`` or stack ``(..., d, d)``, in any units.
    - ``definite``: require positive definite (default) or only positive semidefinite.

    **Returns:** a JAX bool scalar (no gradient flows through it).
    """
    a = jax.lax.stop_gradient(jnp.asarray(x))
    stack = a.reshape((-1,) + a.shape[-2:])
    finite = jnp.all(jnp.isfinite(stack))
    # Replace non-finite entries so eigvalsh sees a valid matrix; `finite` already says False.
    stack = jnp.where(jnp.isfinite(stack), stack, 0.0)
    scale = jnp.maximum(jnp.max(jnp.abs(stack), axis=(-1, -2)), jnp.finfo(stack.dtype).tiny)
    asym = jnp.max(jnp.abs(stack - jnp.swapaxes(stack, -1, -2)), axis=(-1, -2))
    symmetric = jnp.all(asym <= 1e-8 * scale)
    stack = 0.5 * (stack + jnp.swapaxes(stack, -1, -2))
    diag = jnp.diagonal(stack, axis1=-2, axis2=-1)
    diag_ok = jnp.all(diag > 0) if definite else jnp.all(diag >= 0)
    inv_sd = jnp.where(diag > 0, 1.0 / jnp.sqrt(jnp.where(diag > 0, diag, 1.0)), 1.0)
    corr = stack * inv_sd[..., :, None] * inv_sd[..., None, :]
    smallest = jnp.linalg.eigvalsh(corr)[:, 0]
    raw = jnp.linalg.eigvalsh(stack)[:, 0]
    if definite:
        eig_ok = jnp.all((smallest > 0.0) | (raw > 0.0))
    else:
        eig_ok = jnp.all((smallest >= -1e-10) | (raw >= -1e-10 * scale))
    return finite & symmetric & diag_ok & eig_ok
