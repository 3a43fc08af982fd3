"""Per-step standard normal draws for simulation: one fused counter-based hash per draw.

Why not ``jax.random.normal(jax.random.fold_in(key, k), ...)`` at every step? On XLA's CPU
backend every Threefry call is lowered as a small ``while`` loop (rolled rounds), so a step that
folds in the step index, splits and draws twice runs a few hundred tiny kernels; in a Monte Carlo
the random numbers then cost far more than the filter. Here step ``k`` of a run draws its ``d``
numbers from ONE Threefry-2x32 evaluation per number, with the counter ``(k, j)`` under the run's
key, with the 20 rounds unrolled so that XLA fuses the hash, the conversion to a uniform and the
inverse-error-function transform into one element-wise loop over all runs of a batch.

The hash is Threefry-2x32 with 20 rounds (Salmon et al. 2011), the generator behind
``jax.random``'s default keys; :func:`threefry2x32` reproduces ``jax.extend.random.threefry_2x32``
bit for bit (tested). The uniform and the transform are those of ``jax.random.normal``
(``√2 · erfinv(u)``, ``u`` uniform on ``(−1, 1)`` from the top mantissa bits), so the draws have
the statistical quality of ``jax.random.normal``; they are a different stream of numbers.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, PRNGKeyArray

_ROTATIONS = ((13, 15, 26, 6), (17, 29, 16, 24))


def _rotl(x: Array, r: int) -> Array:
    return (x << np.uint32(r)) | (x >> np.uint32(32 - r))


def threefry2x32(k0: Array, k1: Array, x0: Array, x1: Array) -> tuple[Array, Array]:
    """Threefry-2x32, 20 rounds, on ``uint32`` arrays (broadcasting); rounds unrolled.

    **Arguments:**

    - ``k0``, ``k1``: the key words; ``x0``, ``x1``: the counter words. ``uint32``, broadcastable ``(...)``.

    **Returns:** ``(y0, y1)``, two ``uint32`` arrays of the broadcast shape ``(...)``.
    """
    ks = (k0, k1, k0 ^ k1 ^ np.uint32(0x1BD11BDA))
    x0 = x0 + ks[0]
    x1 = x1 + ks[1]
    for i in range(5):
        for r in _ROTATIONS[i % 2]:
            x0 = x0 + x1
            x1 = _rotl(x1, r)
            x1 = x1 ^ x0
        x0 = x0 + ks[(i + 1) % 3]
        x1 = x1 + ks[(i + 2) % 3] + np.uint32(i + 1)
    return x0, x1


def key_words(key: PRNGKeyArray) -> Array:
    """The two ``uint32`` words of a Threefry key (typed ``jax.random.key`` or raw ``PRNGKey``).

    **Arguments:**

    - ``key``: a Threefry key or batch of keys, typed ``(*batch,)`` or raw ``(*batch, 2)``.

    **Returns:** the key words, ``uint32`` ``(*batch, 2)``.

    **Raises:** ``TypeError`` for a key that is not Threefry.
    """
    if jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        key = jax.random.key_data(key)
    if key.shape[-1:] != (2,) or key.dtype != jnp.uint32:
        raise TypeError(
            "jaxtrack's simulation needs Threefry keys (jax.random.key / jax.random.PRNGKey with "
            f"the default implementation); got key data of shape {key.shape} and dtype {key.dtype}."
        )
    return key


def step_normals(words: Array, k, num: int, dtype) -> Array:
    """``num`` standard normal draws of step ``k`` for each key in ``words``.

    ``words``: ``(*batch, 2)`` ``uint32`` key words (:func:`key_words`). Returns ``(num, *batch)``:
    the batch is the trailing axis, the layout the batched simulation uses. Draw ``j`` of a key
    uses the Threefry counter ``(k, j)``, so a step's numbers depend only on the key, the step and
    ``j`` (not on how many steps, numbers or runs are drawn together).

    **Arguments:**

    - ``words``: ``(*batch, 2)`` ``uint32`` key words; ``k``: the step index.
    - ``num``: draws per key; ``dtype``: the floating dtype.

    **Returns:** standard normal draws, ``(num, *batch)``, of ``dtype``.
    """
    batch = words.shape[:-1]
    shape = (num,) + batch
    counter = jax.lax.broadcasted_iota(jnp.uint32, shape, 0)
    step = jnp.full(shape, jnp.asarray(k).astype(jnp.uint32))
    # Key words broadcast over the draws explicitly (rank promotion may be set to raise).
    k0 = jnp.broadcast_to(words[..., 0], shape)
    k1 = jnp.broadcast_to(words[..., 1], shape)
    hi, lo = threefry2x32(k0, k1, step, counter)
    dtype = jnp.dtype(dtype)
    if dtype.itemsize == 8:
        bits = (hi.astype(jnp.uint64) << np.uint64(32)) | lo.astype(jnp.uint64)
        one = np.array(1.0, np.float64).view(np.uint64)
        floats = jax.lax.bitcast_convert_type((bits >> np.uint64(12)) | one, jnp.float64) - 1.0
    else:
        one = np.array(1.0, np.float32).view(np.uint32)
        floats = jax.lax.bitcast_convert_type((hi >> np.uint32(9)) | one, jnp.float32) - 1.0
        floats = floats.astype(dtype)
    lo_val = np.nextafter(np.array(-1.0, dtype), np.array(0.0, dtype))
    u = jnp.maximum(lo_val, floats * (1.0 - lo_val) + lo_val)
    # Barriers keep XLA from fusing the hash into the (branchy) inverse error function, and that
    # into every consumer of the draws, which would repeat the work several times per draw.
    u = jax.lax.optimization_barrier(u)
    return jax.lax.optimization_barrier(np.sqrt(2.0).astype(dtype) * jax.lax.erf_inv(u))
