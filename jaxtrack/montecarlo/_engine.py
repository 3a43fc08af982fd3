"""The one Monte Carlo primitive: blocks of runs, run ``i`` from ``fold_in(key, i)``, streaming
accumulation in block order, on one device or dealt out over a mesh, with a progress bar.

Everything that runs many independent runs goes through :func:`run_blocks`:
:func:`~jaxtrack.montecarlo.monte_carlo` and :func:`~jaxtrack.montecarlo.monte_carlo_sweep`
(fused simulate-filter-score blocks) and :func:`monte_carlo_map` (any per-run function, used by
the studies). A *block* is a fixed number of consecutive runs and the unit of compilation and of
device work; its contribution is a pure function of its start index and the key, and the
contributions are added to the running totals one block at a time in block order. Hence:

- results do not depend on ``chunk_size`` (progress granularity only) nor on the number of
  devices or hosts, to the last bit;
- run ``i`` can be replayed alone from ``jax.random.fold_in(key, i)``;
- memory is one block plus the totals, whatever the number of runs.
"""

from __future__ import annotations

import math
import time
from typing import Any, Callable, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, PartitionSpec as P
from jaxtyping import PRNGKeyArray, PyTree

from .._progress import tqdm
from .._validation import InputError, as_key, is_concrete
from ._sharding import RUN_AXIS, axis_size, local_value, place

# (common, value, key, start, valid) -> the block's contribution (a pytree)
BlockFn = Callable[[Any, Any, PRNGKeyArray, jax.Array, jax.Array], PyTree]
# (totals, contribution, start) -> new totals
Accumulate = Callable[[PyTree, PyTree, jax.Array], PyTree]


class MonteCarloInterrupted(KeyboardInterrupt):
    """Ctrl-C (SIGINT) during :func:`run_blocks`, carrying what had finished.

    It is a ``KeyboardInterrupt``, so a program that does not look at it stops as on any Ctrl-C
    (the CLI exits 130). ``totals``: the accumulated totals of the first ``num_runs_done`` runs
    (host arrays; whole blocks in block order, so exactly what a run of ``num_runs_done`` runs
    would have given), or None when no block had finished; a caller may attach a result built
    from them as ``partial`` (the multi-target Monte Carlo does).
    """

    def __init__(self, totals, num_runs_done: int):
        super().__init__(f"interrupted after {num_runs_done} runs")
        self.totals = totals
        self.num_runs_done = num_runs_done
        self.partial = None


def add_totals(totals, delta, start):
    """The default accumulation: running sums (``start`` unused).

    **Arguments:**

    - ``totals``: the running totals, a pytree of arrays; ``delta``: one block's contribution, the same
      structure and shapes; ``start``: the block's first run index (unused).

    **Returns:** ``totals + delta`` leaf by leaf, the same structure and shapes.
    """
    del start
    return jax.tree_util.tree_map(jnp.add, totals, delta)


def block_size_for(num_runs: int, largest: int) -> int:
    """Runs per block: ``largest``, or the next power of two above ``num_runs`` when fewer.

    **Arguments:**

    - ``num_runs``: the number of runs ``M ≥ 1``; ``largest``: the largest block size.

    **Returns:** the block size, a Python int.
    """
    return min(largest, 1 << max(0, (num_runs - 1).bit_length()))


def check_mesh(mesh, axes) -> None:
    """Raise unless ``mesh`` is a :class:`~jax.sharding.Mesh` with at least one of ``axes``.

    **Arguments:**

    - ``mesh``: the mesh to check.
    - ``axes``: axis names (``None`` entries are ignored).

    **Returns:** ``None``.

    **Raises:** ``InputError`` for a non-mesh or a mesh with none of ``axes``.
    """
    if not isinstance(mesh, Mesh):
        raise InputError(f"`mesh` must be a jax.sharding.Mesh (see jaxtrack.montecarlo.run_mesh); got {type(mesh).__name__}.")
    if not any(a in mesh.axis_names for a in axes if a is not None):
        raise InputError(f"`mesh` has axes {mesh.axis_names}; it needs at least one of {tuple(a for a in axes if a)}.")


@eqx.filter_jit
def _one_block(block_fn, accumulate, totals, common, value, key, start, num_runs, block):
    valid = start + jnp.arange(block) < num_runs
    return accumulate(totals, block_fn(common, value, key, start, valid), start)


@eqx.filter_jit
def _mesh_round(block_fn, accumulate, totals, common, value, key, start, num_runs, block, mesh, run_axis,
                sweep_axis):
    """One round on a mesh: device ``d`` along ``run_axis`` runs block ``start/block + d``; with
    ``sweep_axis``, every array leaf of ``value`` and ``totals`` has a leading axis over parameter
    values (sharded along ``sweep_axis`` when the mesh has it) and each device ``lax.map``s over
    its values. The blocks' contributions are accumulated one at a time in block order."""
    common_dyn, common_static = eqx.partition((common, key), eqx.is_array)
    value_dyn, value_static = eqx.partition(value, eqx.is_array)
    has_run_axis = run_axis in mesh.axis_names
    num_dev = axis_size(mesh, run_axis)

    def per_device(start, num_runs, common_dyn, value_dyn):
        common, key = eqx.combine(common_dyn, common_static)
        block_start = start + (jax.lax.axis_index(run_axis) * block if has_run_axis else 0)
        valid = block_start + jnp.arange(block) < num_runs

        def one(v):
            return block_fn(common, eqx.combine(v, value_static), key, block_start, valid)

        delta = one(value_dyn) if sweep_axis is None else jax.lax.map(one, value_dyn)
        return jax.tree_util.tree_map(lambda a: a[None], delta)

    value_spec = P(sweep_axis) if sweep_axis is not None and sweep_axis in mesh.axis_names else P()
    out_spec = P(run_axis if has_run_axis else None, *((sweep_axis,) if value_spec != P() else ()))
    # check_vma=False: the block code is shared with the single-device path and has no
    # device-varying annotations (its scans would need pcast); the outputs are declared above.
    deltas = jax.shard_map(
        per_device, mesh=mesh, in_specs=(P(), P(), P(), value_spec), out_specs=out_spec, check_vma=False
    )(start, num_runs, common_dyn, value_dyn)
    for d in range(num_dev):
        delta = jax.tree_util.tree_map(lambda a: a[d], deltas)
        if sweep_axis is None:
            totals = accumulate(totals, delta, start + d * block)
        else:
            totals = jax.vmap(accumulate, in_axes=(0, 0, None))(totals, delta, start + d * block)
    return totals


def refuse_traced(entry: str, *trees) -> None:
    """Raise :class:`~jaxtrack.InputError` if any leaf of ``trees`` is a tracer.

    The host-loop entry points (``monte_carlo``, ``monte_carlo_sweep``, ``monte_carlo_map``) run
    their blocks from Python (progress bar, streaming sums, devices); traced by ``jax.grad``,
    ``jax.jit`` or ``jax.vmap`` they would fail deep inside JAX (a ``ConcretizationTypeError``
    about ``is_fully_addressable``). This says what to use instead.
    """
    if not all(is_concrete(leaf) for leaf in jax.tree_util.tree_leaves(trees)):
        raise InputError(
            f"jaxtrack.montecarlo.{entry} runs its blocks from the host (progress bar, streaming sums) "
            "and cannot be traced by jax.grad, jax.jit or jax.vmap: an argument is a tracer. For the "
            "gradient of Monte Carlo statistics use jaxtrack.montecarlo.differentiable_monte_carlo "
            "(the same statistics as one differentiable scan); otherwise call it outside the transformation."
        )


def run_blocks(
    block_fn: BlockFn,
    totals: PyTree,
    *,
    common: Any,
    key: PRNGKeyArray,
    num_runs: int,
    block: int,
    value: Any = None,
    accumulate: Accumulate = add_totals,
    mesh: Mesh | None = None,
    run_axis: str = RUN_AXIS,
    sweep_axis: str | None = None,
    chunk_size: int = 1000,
    progress: bool = True,
    desc: str = "Monte Carlo",
) -> PyTree:
    """Run ``num_runs`` runs as blocks of ``block`` runs and accumulate their contributions.

    ``block_fn(common, value, key, start, valid)`` returns the contribution of runs
    ``start … start+block−1``; ``valid`` ``(block,)`` marks those below ``num_runs`` (the last
    block is padded; padded runs must contribute nothing). It must be a pure function of its
    arguments (``block_fn`` and ``accumulate`` are compiled once per function object: pass
    module-level functions, not fresh lambdas, to reuse compilations). ``accumulate(totals,
    delta, start)`` folds one block into the totals, always in block order.

    Without ``mesh`` the blocks run one after the other on the default device. With ``mesh``,
    each round deals one block to each device along ``run_axis``; with ``sweep_axis`` (a sweep
    over parameter values), ``value`` and ``totals`` carry a leading axis over the values,
    shared out along ``sweep_axis``. Results are identical on any mesh. ``chunk_size`` sets how
    many runs pass between progress-bar updates (the host waits only then).

    **Arguments:**

    - ``block_fn``: ``(common, value, key, start, valid) -> delta``, as above; ``totals``: the initial
      totals, a pytree (with a leading axis over the values under ``sweep_axis``).
    - ``common``: a pytree passed to every block; ``key``: the base PRNG key.
    - ``num_runs``: ``M``; ``block``: runs per block.
    - ``value``: the swept value(s) (``None`` without a sweep); ``accumulate``: the fold, default
      :func:`add_totals`.
    - ``mesh``, ``run_axis``, ``sweep_axis``: the device mesh and its axis names, as above.
    - ``chunk_size``, ``progress``, ``desc``: the progress bar.

    **Returns:** the accumulated totals, as host arrays.
    """
    total = jnp.asarray(num_runs)
    if mesh is None and sweep_axis is None:
        def step(totals, start):
            return _one_block(block_fn, accumulate, totals, common, value, key, jnp.asarray(start), total, block)

        per_round = 1
    else:
        if mesh is None:
            mesh = Mesh(np.asarray(jax.devices()[:1]), (run_axis,))
        check_mesh(mesh, (sweep_axis, run_axis))
        per_round = axis_size(mesh, run_axis)
        value_spec = P(sweep_axis) if sweep_axis is not None and sweep_axis in mesh.axis_names else P()
        totals, value = place((totals, value), mesh, value_spec)
        total, key, common = place((total, key, common), mesh)

        def step(totals, start):
            return _mesh_round(block_fn, accumulate, totals, common, value, key, place(jnp.asarray(start), mesh),
                               total, block, mesh, run_axis, sweep_axis)

    runs_per_round = per_round * block
    rounds_per_chunk = max(1, round(chunk_size / runs_per_round))
    num_rounds = math.ceil(num_runs / runs_per_round)
    # Rounds are dispatched asynchronously. Left alone, the host would queue every round of a
    # chunk (possibly hours of work) and then block in C++, where Ctrl-C is not seen. So the host
    # also waits whenever about _WAIT_SECONDS of work is queued (the rate is measured at each
    # wait), and waits by polling, so a KeyboardInterrupt is raised within one poll interval
    # even while a round runs. Waiting never changes the results.
    seen = _Dispatched()
    try:
        return _rounds(step, totals, num_runs, num_rounds, runs_per_round, rounds_per_chunk, progress, desc, seen)
    except KeyboardInterrupt:
        pass
    # What the rounds dispatched before the interrupt give (a dispatched round is waited for: its
    # totals are whole). A second Ctrl-C while waiting gives up the partial totals.
    partial, runs = None, 0
    if seen.totals is not None:
        try:
            partial, runs = local_value(_wait(seen.totals)), seen.runs
        except KeyboardInterrupt:
            partial, runs = None, 0
    raise MonteCarloInterrupted(partial, runs) from None


class _Dispatched:
    """The latest dispatched totals and the runs they hold (updated as rounds are dispatched)."""

    totals = None
    runs = 0


def _rounds(step, totals, num_runs, num_rounds, runs_per_round, rounds_per_chunk, progress, desc, seen):
    """:func:`run_blocks`' loop over rounds (``seen`` tracks what was dispatched)."""
    rounds_per_wait = 1
    with tqdm(total=num_runs, desc=desc, unit="run", disable=not progress) as bar:
        done = 0
        last_round, last_time = 0, time.perf_counter()
        for r in range(num_rounds):
            totals = step(totals, r * runs_per_round)
            seen.totals, seen.runs = totals, min((r + 1) * runs_per_round, num_runs)
            report = (r + 1) % rounds_per_chunk == 0 or r + 1 == num_rounds
            if report or r + 1 - last_round >= rounds_per_wait:
                totals = _wait(totals)
                now = time.perf_counter()
                if last_round > 0:  # the first round includes the compilation
                    per_round = (now - last_time) / (r + 1 - last_round)
                    rounds_per_wait = max(1, int(_WAIT_SECONDS / max(per_round, 1e-9)))
                last_round, last_time = r + 1, now
            if report:
                finished = min((r + 1) * runs_per_round, num_runs)
                bar.update(finished - done)
                done = finished
    return local_value(totals)


# The most device work (s) queued between two host waits in run_blocks: bounds the delay before
# Ctrl-C is seen, at the cost of one host round trip per wait (tens of µs).
_WAIT_SECONDS = 0.25


def _wait(tree):
    """``jax.block_until_ready`` that stays interruptible: poll ``is_ready()`` with short sleeps
    (a signal interrupts ``time.sleep``, not a blocking wait inside the runtime)."""
    leaves = [x for x in jax.tree_util.tree_leaves(tree) if hasattr(x, "is_ready")]
    pause = 1e-4
    while not all(x.is_ready() for x in leaves):
        time.sleep(pause)
        pause = min(2 * pause, 0.002)  # overshoot ≤ 2 ms per wait (< 1% at one wait per 0.25 s)
    return jax.block_until_ready(tree)


# --------------------------------------------------------------------------------------------
# monte_carlo_map: any per-run function


def _run_keys(key, start, block):
    return jax.vmap(lambda i: jax.random.fold_in(key, i))(start + jnp.arange(block))


def _map_block_sum(common, value, key, start, valid):
    fn, args = common
    out = jax.vmap(fn, in_axes=(0, None))(_run_keys(key, start, valid.shape[0]), args)
    return masked_run_sums(out, valid)


def masked_run_sums(out: PyTree, valid: jax.Array) -> PyTree:
    """The sums over a block's runs (leading axis) of every leaf of ``out``, padded runs
    (``valid`` False) left out; booleans and integers summed as int32 counts."""

    def masked_sum(a):
        a = jnp.asarray(a)
        if a.dtype == bool or jnp.issubdtype(a.dtype, jnp.integer):
            a = a.astype(jnp.int32 if jnp.issubdtype(a.dtype, jnp.integer) or a.dtype == bool else a.dtype)
        mask = valid.reshape(valid.shape + (1,) * (a.ndim - 1))
        # Padded runs may hold anything (NaN included): zero them, don't weight them.
        return jnp.sum(jnp.where(mask, a, jnp.zeros((), a.dtype)), axis=0)

    return jax.tree_util.tree_map(masked_sum, out)


def _map_block_stack(common, value, key, start, valid):
    fn, args = common
    return jax.vmap(fn, in_axes=(0, None))(_run_keys(key, start, valid.shape[0]), args)


def _write_block(buffer, delta, start):
    return jax.tree_util.tree_map(
        lambda b, d: jax.lax.dynamic_update_slice_in_dim(b, d.astype(b.dtype), start, axis=0), buffer, delta)


def monte_carlo_map(
    fn: Callable[[PRNGKeyArray, Any], PyTree],
    key: PRNGKeyArray | int,
    num_runs: int,
    *,
    args: Any = (),
    reduce: Literal["sum", "stack"] = "sum",
    block_size: int = 512,
    mesh: Mesh | None = None,
    mesh_axis: str = RUN_AXIS,
    chunk_size: int = 1000,
    progress: bool = False,
    desc: str = "Monte Carlo",
) -> PyTree:
    """Evaluate ``fn(key_i, args)`` for runs ``i = 0 … num_runs−1`` with ``key_i = fold_in(key, i)``.

    The general entry to the Monte Carlo engine: ``fn`` is one run (simulate, estimate, score)
    returning a pytree of arrays; it is ``vmap``-ed over blocks of ``block_size`` runs and
    compiled once. ``args`` (a pytree, e.g. a scenario Module) is passed to every run unchanged
    and traced, so new values reuse the compilation; ``fn`` itself should be a module-level
    function (it is part of the compilation cache key).

    **Arguments:**

    - ``fn``: ``(key, args) -> pytree``; ``key``: a PRNG key or an int seed; ``num_runs``: ``M ≥ 1``.
    - ``reduce``: ``"sum"`` returns the sum over runs of every leaf (booleans and integers as
      int32 counts), accumulated in block order (bit-identical for any ``chunk_size`` and mesh);
      ``"stack"`` returns every run's output with a leading axis ``M`` (memory ``O(M)``).
    - ``block_size``: runs per compiled block (rounded down to a power of two for few runs).
    - ``mesh``, ``mesh_axis``: deal blocks out over devices (see :func:`monte_carlo`).
    - ``chunk_size``, ``progress``, ``desc``: the progress bar.

    **Returns:** the pytree of sums (``"sum"``) or of stacked per-run outputs (``"stack"``), as
    NumPy arrays.

    Example — the mean squared error of an estimator over 2,000 runs::

        def one_run(key, scenario):
            z = simulate_measurements(scenario, key)
            return jnp.sum((estimate(scenario, z) - scenario.truth) ** 2, axis=-1)   # (T,)

        mse = monte_carlo_map(one_run, jax.random.key(0), 2000, args=scenario) / 2000
    """
    key = as_key(key)
    refuse_traced("monte_carlo_map", key, args)
    if not callable(fn):
        raise InputError(f"`fn` must be callable (key, args) -> pytree; got {type(fn).__name__}.")
    if not isinstance(num_runs, int) or isinstance(num_runs, bool) or num_runs < 1:
        raise InputError(f"`num_runs` must be a positive int; got {num_runs!r}.")
    if not isinstance(block_size, int) or block_size < 1:
        raise InputError(f"`block_size` must be a positive int; got {block_size!r}.")
    if not isinstance(chunk_size, int) or chunk_size < 1:
        raise InputError(f"`chunk_size` must be a positive int; got {chunk_size!r}.")
    if reduce not in ("sum", "stack"):
        raise InputError(f"`reduce` must be 'sum' or 'stack'; got {reduce!r}.")
    block = block_size_for(num_runs, block_size)
    shape = jax.eval_shape(lambda k, a: fn(k, a), jax.random.fold_in(key, 0), args)
    if reduce == "sum":
        def zero(s):
            dtype = jnp.int32 if (s.dtype == bool or jnp.issubdtype(s.dtype, jnp.integer)) else s.dtype
            return jnp.zeros(s.shape, dtype)

        totals = jax.tree_util.tree_map(zero, shape)
        block_fn, accumulate = _map_block_sum, add_totals
    else:
        per_round = block * (1 if mesh is None else axis_size(mesh, mesh_axis))
        padded = -(-num_runs // per_round) * per_round
        totals = jax.tree_util.tree_map(lambda s: jnp.zeros((padded,) + s.shape, s.dtype), shape)
        block_fn, accumulate = _map_block_stack, _write_block
    out = run_blocks(block_fn, totals, common=(fn, args), key=key, num_runs=num_runs, block=block,
                     accumulate=accumulate, mesh=mesh, run_axis=mesh_axis, chunk_size=chunk_size,
                     progress=progress, desc=desc)
    if reduce == "stack":
        out = jax.tree_util.tree_map(lambda a: a[:num_runs], out)
    return out


def run_excluding_failures(run, valid):
    """``run(valid)``; if a valid run failed, ``run(valid & ok)`` again (same draws) without it.

    Returns ``(per-step sums, ok per run of the first pass)``. The two passes are one
    ``lax.scan`` of length 2 over a ``lax.cond`` whose other branch passes the first pass's
    sums on, not a ``cond`` between the first pass and a second copy of it: the block's program
    (its filter step, and under ``grad`` its transpose) is in the compiled program once, not
    twice, which halves its compile time. In the usual case (nothing failed) the second
    iteration takes the cheap branch, so the run time is that of one pass, as before.
    """
    run = jax.jit(run)  # traced once: eval_shape's trace is reused by the cond below
    shapes = jax.eval_shape(run, valid)
    zeros = jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), shapes)

    def body(carry, first):
        sums, ok = carry
        need = first | ~jnp.all(ok | ~valid)
        use = jnp.where(first, valid, valid & ok)
        new_sums, new_ok = jax.lax.cond(need, run, lambda u: (sums, ok), use)
        return (new_sums, jnp.where(first, new_ok, ok)), None

    (sums, ok), _ = jax.lax.scan(body, zeros, jnp.array([True, False]))
    return sums, ok
