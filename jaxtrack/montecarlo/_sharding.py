"""Monte Carlo over many devices and hosts: blocks of runs dealt out along a mesh axis.

The single-device harness (:mod:`._run`) is a sequence of *blocks* of runs: block ``b`` holds
runs ``b·B … b·B+B−1``, run ``i`` draws everything from ``jax.random.fold_in(key, i)``, and the
block's sums are a pure function of its start index. Sharding therefore changes nothing but
*where* blocks run:

- a round of ``D`` blocks is one ``jax.shard_map`` over the mesh's run axis (device ``d`` runs
  block ``r·D + d``, its start index computed from ``jax.lax.axis_index``), so no key is ever
  split per device and the per-run streams are the single-device streams;
- the ``D`` blocks' sums are gathered and added to the running totals *one block at a time, in
  block order*, exactly the additions the single-device loop makes. The totals, and every
  statistic derived from them, are then identical to the last bit on 1, 4 or 64 devices, on
  one host or many (tested);
- only the per-step sums (sums, sums of squares, counts: ``O(T·n)``) cross devices; memory per
  device is one block, whatever the number of runs.

The rounds themselves live beside the single-device loop in :mod:`._run`
(``_sharded_round``, ``_sweep_round``); this module holds the mesh helpers. Parameter sweeps
(:func:`~jaxtrack.montecarlo.monte_carlo_sweep`) add a second mesh axis: each device takes a share
of the parameter values (looping over them with ``lax.map``, so each value runs the very block
program of :func:`monte_carlo`) and, if the mesh also has a run axis, a share of the blocks.

Multi-host: call ``jax.distributed.initialize`` in every process first (one process per host,
see the README); ``jax.devices()`` then lists every process's devices, :func:`run_mesh` spans
them, and the same call runs everywhere. Inputs are placed on the mesh from each process's own
(identical) host values, and the replicated totals are read back on every process.
"""

from __future__ import annotations

from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P

RUN_AXIS = "runs"
SWEEP_AXIS = "sweep"


def run_mesh(devices: Sequence[jax.Device] | None = None, axis_name: str = RUN_AXIS) -> Mesh:
    """A one-axis mesh over ``devices`` (default: every device of every process) for
    ``monte_carlo(..., mesh=...)``.

    On one CPU host, split the CPU into ``N`` devices before JAX starts with
    ``jax.config.update("jax_num_cpu_devices", N)`` (or
    ``XLA_FLAGS=--xla_force_host_platform_device_count=N``); across hosts, call
    ``jax.distributed.initialize`` first.

    **Arguments:**

    - ``devices``: the devices (default: ``jax.devices()``).
    - ``axis_name``: the mesh axis name (default ``RUN_AXIS``).

    **Returns:** a :class:`jax.sharding.Mesh` of shape ``(len(devices),)``.
    """
    devices = jax.devices() if devices is None else list(devices)
    return Mesh(np.asarray(devices), (axis_name,))


def sweep_mesh(num_sweep: int, devices: Sequence[jax.Device] | None = None) -> Mesh:
    """A ``(sweep, runs)`` mesh: ``num_sweep`` groups of devices share the parameter values,
    the devices of a group share the runs. ``num_sweep`` must divide the device count.

    **Arguments:**

    - ``num_sweep``: the number of device groups (the ``SWEEP_AXIS`` size).
    - ``devices``: the devices (default: ``jax.devices()``).

    **Returns:** a :class:`jax.sharding.Mesh` of shape ``(num_sweep, len(devices) // num_sweep)``, axes
    ``(SWEEP_AXIS, RUN_AXIS)``.

    **Raises:** ``ValueError`` if ``num_sweep`` is not a positive divisor of the device count.
    """
    devices = jax.devices() if devices is None else list(devices)
    if num_sweep < 1 or len(devices) % num_sweep:
        raise ValueError(f"`num_sweep` = {num_sweep} must divide the number of devices ({len(devices)}).")
    return Mesh(np.asarray(devices).reshape(num_sweep, -1), (SWEEP_AXIS, RUN_AXIS))


def axis_size(mesh: Mesh, name: str) -> int:
    """Devices along ``name`` (1 if the mesh has no such axis).

    **Arguments:**

    - ``mesh``: the mesh; ``name``: an axis name.

    **Returns:** the axis size, a Python int.
    """
    return int(dict(mesh.shape).get(name, 1))


def place(tree, mesh: Mesh, spec: P = P()):
    """Every array leaf of ``tree`` as a global array on ``mesh`` with sharding ``spec``.

    Built from this process's host value of each leaf (which every process holds identically),
    so it works the same on one host and across hosts, where a plain host array could not be
    passed to a computation spanning other processes' devices.

    **Arguments:**

    - ``tree``: a pytree; array leaves (NumPy or JAX, PRNG keys included) are placed, others kept.
    - ``mesh``: the mesh; ``spec``: the :class:`~jax.sharding.PartitionSpec` (default: replicated).

    **Returns:** the pytree with each array leaf a global ``jax.Array`` of the same shape and dtype.
    """
    sharding = NamedSharding(mesh, spec)

    def one(a):
        if not isinstance(a, (jax.Array, np.ndarray)):
            return a
        if isinstance(a, jax.Array) and jnp.issubdtype(a.dtype, jax.dtypes.prng_key):
            impl = jax.random.key_impl(a)
            return jax.random.wrap_key_data(one(jax.random.key_data(a)), impl=impl)
        host = np.asarray(a)
        return jax.make_array_from_callback(host.shape, sharding, lambda idx: host[idx], dtype=host.dtype)

    return jax.tree_util.tree_map(one, tree)


def local_value(tree):
    """Host copies of the replicated result arrays (readable on every process).

    **Arguments:**

    - ``tree``: a pytree of result arrays (other leaves are kept).

    **Returns:** the pytree with each ``jax.Array`` leaf as a NumPy array of the same shape.
    """

    def one(a):
        if isinstance(a, jax.Array) and not a.is_fully_addressable:
            return np.asarray(a.addressable_data(0))
        return np.asarray(a) if isinstance(a, jax.Array) else a

    return jax.tree_util.tree_map(one, tree)
