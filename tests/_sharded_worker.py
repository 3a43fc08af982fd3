"""Runs Monte Carlo studies on a split CPU (and, with a coordinator, in one of several processes)
and prints their statistics as one JSON line. Started by ``tests/test_sharding.py`` in a fresh
interpreter, because the number of CPU devices is fixed when JAX starts.

Usage: ``python _sharded_worker.py DEVICES [COORDINATOR NUM_PROCESSES PROCESS_ID]``
"""

import json
import os
import sys

import jax

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_num_cpu_devices", int(sys.argv[1]))
if len(sys.argv) > 2:
    coordinator, num_processes, process_id = sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    jax.distributed.initialize(coordinator_address=coordinator, num_processes=num_processes, process_id=process_id)

import numpy as np  # noqa: E402

from jaxtrack.montecarlo import monte_carlo, monte_carlo_sweep, run_mesh, sweep_mesh  # noqa: E402

from _sharded_cases import FIELDS, NUM_RUNS, NUM_STEPS, SWEEP_RUNS, SWEEP_VALUES, cases, sweep_models  # noqa: E402


def stats(res):
    return {name: np.asarray(getattr(res, name)).tolist() for name in FIELDS} | {"num_runs": res.num_runs}


out = {"process_count": jax.process_count(), "device_count": jax.device_count(), "runs": {}, "sweeps": {}}
key = jax.random.key(3)
# "two": a mesh on part of the devices (in two processes, the first device of each).
two = jax.devices()[:2] if jax.process_count() == 1 else [jax.devices()[0], jax.devices()[-1]]
meshes = {"all": run_mesh(), "two": run_mesh(two)}
# JAXTRACK_SHARDED_CASES=kf,ekf_detect runs a subset of the cases (comma-separated names).
only = os.environ.get("JAXTRACK_SHARDED_CASES")
selected = {k: v for k, v in cases().items() if only is None or k in only.split(",")}
for name, case in selected.items():
    for mesh_name, mesh in meshes.items():
        res = monte_carlo(key=key, num_runs=NUM_RUNS, num_steps=NUM_STEPS, progress=False, mesh=mesh, **case)
        out["runs"][f"{name} / {mesh_name}"] = stats(res)
if jax.process_count() == 1:
    sweep_meshes = {"values only": run_mesh(axis_name="sweep"), "values x runs": sweep_mesh(2), "runs only": run_mesh()}
    for mesh_name, mesh in sweep_meshes.items():
        res = monte_carlo_sweep(sweep_models, SWEEP_VALUES, key, SWEEP_RUNS, num_steps=NUM_STEPS, progress=False,
                                mesh=mesh)
        out["sweeps"][mesh_name] = [stats(r) for r in res]
print(json.dumps(out))
