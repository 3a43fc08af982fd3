"""Shared pieces of the learning loops: batches of recorded runs, finiteness, selection.

Used by :func:`~jaxtrack.learning.fit_imm` and :func:`~jaxtrack.learning.fit` (one place each).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike

from .._validation import InputError, check_finite, check_shape, is_concrete


def prepare_runs(meas_dim: int, dtype, measurements: ArrayLike, mask: ArrayLike | None,
                 require_observed: bool = True) -> tuple[Array, Array]:
    """Validate a batch of recorded runs and its mask.

    **Arguments:** ``meas_dim``: ``m``; ``dtype``: the float dtype for integer measurements;
    ``measurements``: ``(R, T, m)`` (``R`` runs of ``T`` steps) or ``(T, m)`` (one run);
    ``mask``: optional boolean ``(R, T)``/``(R, T, m)`` (``(T,)``/``(T, m)`` for one run), True = observed;
    ``require_observed``: refuse a mask with no observed entry (a fit; a log-likelihood of no data is 0).

    **Returns:** ``(z, observed)``: floats ``(R, T, m)`` with missing entries 0, booleans ``(R, T, m)``.

    **Raises:** ``InputError`` naming ``measurements`` or ``mask`` (wrong shapes, non-boolean mask,
    observed non-finite entries, or no entry observed at all, when concrete).
    """
    m = meas_dim
    z = jnp.asarray(measurements)
    if not jnp.issubdtype(z.dtype, jnp.floating):
        z = z.astype(dtype)
    check_shape("measurements", z, [(None, m), (None, None, m)])
    single = z.ndim == 2
    if single:
        z = z[None]
    R, T, _ = z.shape
    if R == 0 or T == 0:
        raise InputError(
            f"`measurements` must hold at least one track of at least one step; got shape {z.shape}."
        )
    if mask is None:
        observed = jnp.ones(z.shape, bool)
    else:
        mk = jnp.asarray(mask)
        if single:
            check_shape("mask", mk, [(T,), (T, m)])
            mk = mk[None]
        else:
            check_shape("mask", mk, [(R, T), (R, T, m)])
        if mk.dtype != bool:
            raise InputError(f"`mask` must be boolean (True = observed); got dtype {mk.dtype}.")
        observed = jnp.broadcast_to(mk[..., None] if mk.ndim == 2 else mk, z.shape)
    if require_observed and is_concrete(observed) and not bool(np.any(np.asarray(observed))):
        # Nothing to fit: every iterate would have the same (zero) likelihood and the fit would
        # return its start as a success. A traced mask gets the same answer through the fits'
        # `ok` (any_observed below).
        raise InputError(
            f"`mask` marks no measurement as observed (all {int(np.asarray(observed).size)} entries False): "
            "there is no data to fit."
        )
    if is_concrete(z) and is_concrete(observed):
        bad = np.asarray(observed) & ~np.isfinite(np.asarray(z))
        if bad.any():
            first = tuple(int(i) for i in np.argwhere(bad)[0])
            raise InputError(
                f"`measurements` has {int(bad.sum())} non-finite entries marked observed (first at "
                f"(track, step, component) {first}); mark them missing with `mask`."
            )
    # Missing entries may hold anything: never let them into the arithmetic.
    return jnp.where(observed, z, 0.0), observed


def any_observed(observed: Array) -> Array:
    """The traced twin of :func:`prepare_runs`' "no measurement observed" error: a scalar bool
    that the fits fold into their ``ok`` (a mask built inside ``jit``/``vmap`` is not checked)."""
    return jnp.any(observed)


def all_finite(tree) -> Array:
    """True when every entry of every leaf of ``tree`` is finite (a scalar bool array)."""
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in jax.tree_util.tree_leaves(tree)]))


def select(pred, a, b):
    """``a`` where the scalar ``pred`` is True, else ``b``, leaf by leaf (same structures)."""
    return jax.tree_util.tree_map(lambda x, y: jnp.where(pred, x, y), a, b)


def check_params(params, examples: str = ""):
    """``params`` with every leaf a finite float array (the unconstrained reals a fit moves).

    **Arguments:** ``params``: a pytree; ``examples``: words appended to the error's description
    of the leaves (e.g. ``": logits, log noise levels, …"``).

    **Returns:** the pytree with ``jnp`` array leaves. **Raises:** :class:`~jaxtrack.InputError`
    naming ``params`` for no leaves, a non-float leaf or a non-finite one.
    """
    leaves, treedef = jax.tree_util.tree_flatten(params)
    if not leaves:
        raise InputError("`params` must be a pytree with at least one float array leaf; got no leaves.")
    out = []
    for i, leaf in enumerate(leaves):
        a = jnp.asarray(leaf)
        if not jnp.issubdtype(a.dtype, jnp.floating):
            raise InputError(
                f"`params` leaves must be float arrays (unconstrained reals{examples}); leaf {i} has dtype {a.dtype}."
            )
        check_finite("params", a)
        out.append(a)
    return jax.tree_util.tree_unflatten(treedef, out)
