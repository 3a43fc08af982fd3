"""Gaussian-mixture reduction: pruning and merging into a fixed number of slots.

One place for the reduction every Gaussian-mixture multi-target filter applies to its intensity
(the GM-PHD and GM-CPHD filters, the Poisson part of the PMB/PMBM filters): Table II of Vo & Ma
(2006), "The Gaussian mixture probability hypothesis density filter", IEEE Trans. Signal Process.
54(11), 4091-4104 (:class:`~jaxtrack.multitarget.VoMaReduction`), or Stone Soup's
``GaussianMixtureReducer`` pairwise merging (:class:`~jaxtrack.multitarget.StoneSoupReduction`);
the strategy objects are in :mod:`._mixture`, the numerics here.

Each merging has two forms with the same values. The fixed loops (:func:`_merge_loops`: ``J_max``
passes, each over every candidate) are what reverse-mode differentiation needs; the forward pass
runs a ``while_loop`` over the merges actually made (:func:`_merge_vo_ma`,
:func:`_merge_stonesoup`), whose ``custom_jvp`` is the fixed loops' JVP, so ``jax.grad`` works
through either. Measured: Stone Soup's merging at ``J_max = 128``, ``M = 27`` (the scenario of
``benchmarks/rfs.py``) 175 ms a scan as fixed loops, 0.9 ms as the while loop; Table II's in the
Williams (2015) scenario (``J_max = 100``, up to 40 measurements a scan, one run, whole filter
step; ``benchmarks/pmbm.py``): GM-PHD 18.5 ms a scan with the fixed loops, 0.77 ms with the while
loop, GM-CPHD 19.0 and 1.26 ms (the same estimates: equal to rounding, see ``tests/test_gm_phd.py``).

Under ``jax.vmap`` (a Monte Carlo block: ``tracker_monte_carlo``, ``monte_carlo_map``) the while
loops would run side by side, each step of every member until the slowest member is done; on CPU
the batching rule runs the members in turn instead (:func:`_in_turn_on_cpu`), so a batched run
costs what a single run costs and gives its values bit for bit. Measured
(``benchmarks/phd_batch.py``, 16 runs, CPU time per run, batch over one run): the GM-PHD on
``crossing_targets()`` 1.88x side by side, 1.07x in turn (Stone Soup's merging 1.36x, 1.07x), in
the Williams scenario 1.86x, 1.07x.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from ..filters._linalg import cholesky_and_inverse


def reduce_mixture(stonesoup: bool, prune_threshold, merge_threshold, capacity: int, free_mean, free_cov,
                   weights, means, covs, active):
    """Prune and merge ``(weights (K,), means (K, n), covs (K, n, n), active (K,))`` into
    ``capacity`` slots: Table II (``stonesoup`` False) or Stone Soup's reducer (True); free slots
    hold ``(free_mean, free_cov)``. The strategy objects of :mod:`._mixture` call this.

    **Returns:** ``(weights, means, covs, active, num_dropped, dropped_weight, num_pruned)``."""
    dtype = weights.dtype
    T, U = prune_threshold.astype(dtype), merge_threshold.astype(dtype)
    ss = stonesoup
    keep = active & ((weights >= T) if ss else (weights > T))
    num_pruned = jnp.sum(active & ~keep).astype(jnp.int32)
    if ss:
        # Stone Soup spreads the pruned weight evenly over the kept components.
        pruned = jnp.sum(jnp.where(active & ~keep, weights, 0.0))
        n_keep = jnp.sum(keep)
        weights = weights + jnp.where(keep, pruned / jnp.maximum(n_keep, 1), 0.0)
    free = (free_mean.astype(dtype), free_cov.astype(dtype))  # what a free slot holds
    merge = _merge_stonesoup if ss else _merge_vo_ma
    out = merge(capacity, U, *free, weights, means, covs, keep)
    return *out, num_pruned


def _free_slots(J: int, free_mean, free_cov, dtype):
    """``J`` empty output slots ``(weights, means, covs, active)``: weight 0, inactive, holding the
    free component (finite moments)."""
    n = free_mean.shape[0]
    return (jnp.zeros((J,), dtype), jnp.broadcast_to(free_mean, (J, n)), jnp.broadcast_to(free_cov, (J, n, n)),
            jnp.zeros((J,), bool))


def _leftover(remaining, weights):
    """``(num_dropped, dropped_weight)``: the candidates no slot took (``remaining``, in the
    input's order), counted and summed so that an overflow is never silent."""
    return jnp.sum(remaining).astype(jnp.int32), jnp.sum(jnp.where(remaining, weights, 0.0))


def _merge_loops(J, ss, U, free_mean, free_cov, weights, means, covs, keep):
    """The merging into ``J`` slots as fixed loops (differentiable in both modes): a ``fori_loop``
    over the slots, each a vectorised Table II pass (``ss`` False) or, for Stone Soup's pairwise
    merging, a ``fori_loop`` over all ``K`` candidates. **Returns:** ``(weights, means, covs,
    active, num_dropped, dropped_weight)``."""
    dtype = weights.dtype
    # Each candidate's inverse covariance, once: the distance uses the candidate's P_i.
    _, chol_inv = jax.vmap(cholesky_and_inverse)(covs)
    prec = jnp.einsum("kji,kjl->kil", chol_inv, chol_inv)
    K, n = means.shape
    masked = jnp.where(keep, weights, -jnp.inf)
    # Stone Soup pops the last of a stable ascending sort: among equal weights the later one.
    order = jnp.argsort(masked, stable=True)  # ascending
    out = (jnp.zeros((J,), dtype), jnp.zeros((J, n), dtype), jnp.zeros((J, n, n), dtype), jnp.zeros((J,), bool))

    def pass_vo_ma(remaining):
        j = jnp.argmax(jnp.where(remaining, weights, -jnp.inf))
        d = means - means[j][None, :]
        dist = jnp.einsum("ki,kil,kl->k", d, prec, d)
        L = remaining & (dist <= U)
        wl = jnp.where(L, weights, 0.0)
        wsum = jnp.sum(wl)
        safe = jnp.where(wsum > 0.0, wsum, 1.0)
        mean = jnp.sum(wl[:, None] * means, axis=0) / safe
        dm = mean[None, :] - means
        cov = jnp.sum(wl[:, None, None] * (covs + dm[:, :, None] * dm[:, None, :]), axis=0) / safe
        return wsum, mean, cov, remaining & ~L

    def pass_stonesoup(remaining):
        last = jnp.max(jnp.where(remaining[order], jnp.arange(K), -1))
        j = order[jnp.maximum(last, 0)]
        remaining = remaining.at[j].set(False)

        def inner(p, carry):
            w_b, m_b, P_b, rem = carry
            c = order[p]
            d = m_b - means[c]
            hit = rem[c] & (d @ prec[c] @ d < U)
            w_new, m_new, P_new = _merge_pair(w_b, m_b, P_b, weights[c], means[c], covs[c], d)
            return (jnp.where(hit, w_new, w_b), jnp.where(hit, m_new, m_b),
                    jnp.where(hit, P_new, P_b), rem.at[c].set(rem[c] & ~hit))

        return jax.lax.fori_loop(0, K, inner, (weights[j], means[j], covs[j], remaining))

    def body(slot, carry):
        remaining, (w_o, m_o, P_o, a_o) = carry
        has = jnp.any(remaining)
        if ss:
            def skip(rem):
                return jnp.zeros((), dtype), means[0], covs[0], rem
            wsum, mean, cov, remaining = jax.lax.cond(has, pass_stonesoup, skip, remaining)
        else:
            wsum, mean, cov, remaining = pass_vo_ma(remaining)
        w_o = w_o.at[slot].set(jnp.where(has, wsum, 0.0))
        m_o = m_o.at[slot].set(jnp.where(has, mean, free_mean))
        P_o = P_o.at[slot].set(jnp.where(has, cov, free_cov))
        return remaining, (w_o, m_o, P_o, a_o.at[slot].set(has))

    remaining, (w_o, m_o, P_o, a_o) = jax.lax.fori_loop(0, J, body, (keep, out))
    return w_o, m_o, P_o, a_o, *_leftover(remaining, weights)


def _merge_pair(w_b, m_b, P_b, w_c, m_c, P_c, d):
    """Stone Soup's merge of candidate ``c`` into the running component ``b`` (``d = m_b − m_c``),
    the merged weight capped at 1."""
    ws = w_b + w_c
    ws_safe = jnp.where(ws > 0.0, ws, 1.0)  # a pruned (T = 0) pair: keep it finite
    a, b = w_b / ws_safe, w_c / ws_safe
    return jnp.minimum(ws, 1.0), m_b * a + m_c * b, P_b * a + P_c * b + jnp.outer(d, d) * a * b


_CHUNK = 128  # candidates per vectorised distance evaluation in the fast mergings

# How a vmapped batch runs the fast mergings: "platform" (members in turn on CPU, side by side
# elsewhere), "in-turn" or "side-by-side" everywhere (``benchmarks/phd_batch.py`` compares them).
_BATCHED = "platform"


def _in_turn_on_cpu(fun, *args):
    """``fun(*args)`` (arrays in, a tuple of arrays out), whose ``jax.vmap`` on CPU runs the
    batch's members one after another (``lax.map``), each its own ``while_loop`` to its own trip
    count, instead of side by side (elsewhere, where a batch's members run in parallel).

    A ``while_loop`` vmapped side by side runs until its slowest member is done, every member
    paying for every step (a finished one's steps are computed and discarded), and its
    ``dynamic_slice``/``.at[]`` at per-member positions become gathers and scatters: on CPU a
    batch of 16 crossing-targets GM-PHD runs cost 1.9x their single runs
    (``benchmarks/phd_batch.py``). In turn it costs what the single runs cost, with their values
    bit for bit. Elsewhere (``jax.lax.platform_dependent``'s ``default``, e.g. a GPU, which runs
    a batch's members in parallel) the batch runs side by side, as ``jax.vmap`` makes it.
    ``_BATCHED`` forces either form (benchmarks, tests). Differentiation is unaffected: the
    mergings' ``custom_jvp`` differentiates the fixed loops, never this function."""
    f = jax.custom_batching.custom_vmap(fun)

    @f.def_vmap
    def rule(axis_size, in_batched, *args):
        del axis_size

        def in_turn(*args):
            def one(members):
                it = iter(members)
                return f(*(next(it) if b else a for a, b in zip(args, in_batched)))

            return jax.lax.map(one, [a for a, b in zip(args, in_batched) if b])

        def side_by_side(*args):
            return jax.vmap(fun, in_axes=tuple(0 if b else None for b in in_batched))(*args)

        if _BATCHED == "platform":
            out = jax.lax.platform_dependent(*args, cpu=in_turn, default=side_by_side)
        else:
            out = (in_turn if _BATCHED == "in-turn" else side_by_side)(*args)
        return out, jax.tree.map(lambda _: True, out)

    return f(*args)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _merge_stonesoup(J, U, free_mean, free_cov, weights, means, covs, keep):
    """:func:`_fast_stonesoup`, members of a ``vmap`` in turn on CPU (:func:`_in_turn_on_cpu`)."""
    return _in_turn_on_cpu(functools.partial(_fast_stonesoup, J), U, free_mean, free_cov, weights, means, covs, keep)


def _fast_stonesoup(J, U, free_mean, free_cov, weights, means, covs, keep):
    """Stone Soup's pairwise merging, the same values as :func:`_merge_loops` (``ss`` True) at the
    cost of the work actually done. One ``while_loop`` whose every step either merges a candidate
    into the running component or, when none is left to merge, stores it and seeds the next slot
    with the heaviest remaining one; the running component changes only at a merge, so the next
    candidate merged is the first remaining one (in visiting order) within ``U`` of it, found with
    the distances of ``_CHUNK`` candidates at a time among the kept ones (the pruned ones sort
    first, and their precisions are never computed). Derivatives (its JVP, and so ``jax.grad``)
    are those of :func:`_merge_loops`, whose fixed loops reverse-mode differentiation needs."""
    dtype = weights.dtype
    K, n = means.shape
    ch = min(K, _CHUNK)
    order = jnp.argsort(jnp.where(keep, weights, -jnp.inf), stable=True)  # visiting order, ascending
    w_o, m_o, P_o = weights[order], means[order], covs[order]
    first_kept = (K - jnp.sum(keep)).astype(jnp.int32)

    def precisions(c):
        q, prec = c
        q = jnp.minimum(q, K - ch)
        _, chol_inv = jax.vmap(cholesky_and_inverse)(jax.lax.dynamic_slice_in_dim(P_o, q, ch))
        return q + ch, jax.lax.dynamic_update_slice_in_dim(prec, jnp.einsum("kji,kjl->kil", chol_inv, chol_inv), q, 0)

    _, prec_o = jax.lax.while_loop(lambda c: c[0] < K, precisions, (first_kept, jnp.zeros((K, n, n), dtype)))

    def step(c):
        s, p, is_open, (w_b, m_b, P_b), rem, n_rem, (w, m, P, a) = c
        # Search one chunk from p for the next candidate within U of the open slot's component.
        q = jnp.minimum(p, K - ch)
        d = m_b[None, :] - jax.lax.dynamic_slice_in_dim(m_o, q, ch)
        dist = jnp.einsum("ki,kil,kl->k", d, jax.lax.dynamic_slice_in_dim(prec_o, q, ch), d)
        hit = jax.lax.dynamic_slice_in_dim(rem, q, ch) & (dist < U) & (q + jnp.arange(ch) >= p)
        found = is_open & jnp.any(hit)
        h = q + jnp.argmax(hit).astype(jnp.int32)
        advance = is_open & ~found & (q + ch < K)
        done = is_open & ~found & ~advance  # nothing left to merge: store the slot
        w, m, P, a = (w.at[s].set(jnp.where(done, w_b, w[s])), m.at[s].set(jnp.where(done, m_b, m[s])),
                      P.at[s].set(jnp.where(done, P_b, P[s])), a.at[s].set(done | a[s]))
        s = s + done.astype(jnp.int32)
        seeding = (done | ~is_open) & (n_rem > 0) & (s < J)
        seed = K - 1 - jnp.argmax(rem[::-1]).astype(jnp.int32)  # the last remaining: the heaviest
        merged = _merge_pair(w_b, m_b, P_b, w_o[h], m_o[h], P_o[h], m_b - m_o[h])
        running = tuple(jnp.where(found, x, jnp.where(seeding, y, z)) for x, y, z in
                        zip(merged, (w_o[seed], m_o[seed], P_o[seed]), (w_b, m_b, P_b)))
        taken = jnp.where(found, h, seed)
        rem = rem.at[taken].set(rem[taken] & ~(found | seeding))
        n_rem = n_rem - (found | seeding).astype(jnp.int32)
        p = jnp.where(found, h + 1, jnp.where(advance, q + ch, first_kept))
        return s, p, found | advance | seeding, running, rem, n_rem, (w, m, P, a)

    out = _free_slots(J, free_mean, free_cov, dtype)
    running = (jnp.zeros((), dtype), jnp.zeros((n,), dtype), jnp.zeros((n, n), dtype))
    init = (jnp.zeros((), jnp.int32), first_kept, jnp.zeros((), bool), running, keep[order], K - first_kept, out)
    _, _, _, _, rem, _, (w, m, P, a) = jax.lax.while_loop(
        lambda c: c[2] | ((c[5] > 0) & (c[0] < J)), step, init)
    remaining = jnp.zeros((K,), bool).at[order].set(rem)  # back to the input's order, for the sum
    return w, m, P, a, *_leftover(remaining, weights)


@_merge_stonesoup.defjvp
def _merge_stonesoup_jvp(J, primals, tangents):
    return jax.jvp(functools.partial(_merge_loops, J, True), primals, tangents)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _merge_vo_ma(J, U, free_mean, free_cov, weights, means, covs, keep):
    """:func:`_fast_vo_ma`, members of a ``vmap`` in turn on CPU (:func:`_in_turn_on_cpu`)."""
    return _in_turn_on_cpu(functools.partial(_fast_vo_ma, J), U, free_mean, free_cov, weights, means, covs, keep)


def _fast_vo_ma(J, U, free_mean, free_cov, weights, means, covs, keep):
    """Table II's merging (Vo & Ma 2006), the values of :func:`_merge_loops` (``ss`` False, to
    rounding: sums are taken chunk by chunk) at the cost of the work actually done. The fixed
    loops run ``J`` passes over all ``K = (1 + M)·J`` candidates however few remain (18.5 ms a
    scan at ``J = 100`` in the Williams scenario); here one ``while_loop`` runs one pass per
    component made, each over ``_CHUNK``-row chunks of the kept candidates only (sorted heaviest
    first, so the pruned ones are never visited and a pass starts at the chunk of its seed, the
    heaviest remaining one). Derivatives (its JVP, and so ``jax.grad``) are those of
    :func:`_merge_loops`, whose fixed loops reverse-mode differentiation needs."""
    dtype = weights.dtype
    K, n = means.shape
    ch = min(K, _CHUNK)
    Kp = -(-K // ch) * ch  # padded to whole chunks: padding is never kept
    # Heaviest first, pruned last; ties in input order, as Table II's argmax takes the first.
    order = jnp.argsort(jnp.where(keep, -weights, jnp.inf), stable=True)
    pad = Kp - K
    w_o = jnp.pad(weights[order], (0, pad))
    m_o = jnp.pad(means[order], ((0, pad), (0, 0)))
    P_o = jnp.concatenate([covs[order], jnp.broadcast_to(jnp.eye(n, dtype=dtype), (pad, n, n))])
    num_kept = jnp.sum(keep).astype(jnp.int32)
    num_chunks = (num_kept + ch - 1) // ch

    def chunk(a, c):
        return jax.lax.dynamic_slice_in_dim(a, c * ch, ch)

    def precisions(c):
        i, prec = c
        _, chol_inv = jax.vmap(cholesky_and_inverse)(chunk(P_o, i))
        return i + 1, jax.lax.dynamic_update_slice_in_dim(prec, jnp.einsum("kji,kjl->kil", chol_inv, chol_inv),
                                                          i * ch, 0)

    _, prec_o = jax.lax.while_loop(lambda c: c[0] < num_chunks, precisions,
                                   (jnp.zeros((), jnp.int32), jnp.zeros((Kp, n, n), dtype)))

    def one_pass(c):
        s, rem, n_rem, (w_out, m_out, P_out, a_out) = c
        j = jnp.argmax(rem).astype(jnp.int32)  # the heaviest remaining; none before it remains
        m_j = m_o[j]

        def select(i, acc):
            # L = {i remaining : (m_i − m_j)ᵀ P_i⁻¹ (m_i − m_j) ≤ U}, and Σ w, Σ w m over it.
            sel, wsum, wm = acc
            d = chunk(m_o, i) - m_j[None, :]
            hit = chunk(rem, i) & (jnp.einsum("ki,kil,kl->k", d, chunk(prec_o, i), d) <= U)
            wl = jnp.where(hit, chunk(w_o, i), 0.0)
            return (jax.lax.dynamic_update_slice_in_dim(sel, hit, i * ch, 0), wsum + jnp.sum(wl),
                    wm + jnp.sum(wl[:, None] * chunk(m_o, i), axis=0))

        first = j // ch
        sel, wsum, wm = jax.lax.fori_loop(first, num_chunks, select,
                                          (jnp.zeros((Kp,), bool), jnp.zeros((), dtype), jnp.zeros((n,), dtype)))
        safe = jnp.where(wsum > 0.0, wsum, 1.0)
        mean = wm / safe

        def spread(i, acc):
            wl = jnp.where(chunk(sel, i), chunk(w_o, i), 0.0)
            dm = mean[None, :] - chunk(m_o, i)
            return acc + jnp.sum(wl[:, None, None] * (chunk(P_o, i) + dm[:, :, None] * dm[:, None, :]), axis=0)

        cov = jax.lax.fori_loop(first, num_chunks, spread, jnp.zeros((n, n), dtype)) / safe
        out = (w_out.at[s].set(wsum), m_out.at[s].set(mean), P_out.at[s].set(cov), a_out.at[s].set(True))
        return s + 1, rem & ~sel, n_rem - jnp.sum(sel).astype(jnp.int32), out

    out = _free_slots(J, free_mean, free_cov, dtype)
    kept_o = jnp.arange(Kp) < num_kept
    _, rem, _, (w, m, P, a) = jax.lax.while_loop(lambda c: (c[2] > 0) & (c[0] < J), one_pass,
                                                 (jnp.zeros((), jnp.int32), kept_o, num_kept, out))
    remaining = jnp.zeros((K,), bool).at[order].set(rem[:K])  # back to the input's order, for the sum
    return w, m, P, a, *_leftover(remaining, weights)


@_merge_vo_ma.defjvp
def _merge_vo_ma_jvp(J, primals, tangents):
    return jax.jvp(functools.partial(_merge_loops, J, False), primals, tangents)
