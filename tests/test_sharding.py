"""Monte Carlo sharded over devices and processes gives the single-device statistics, bit for bit.

The number of CPU devices is fixed when JAX starts, so the sharded runs happen in fresh
interpreters (``_sharded_worker.py``) on a CPU split into 4 devices, or in two processes joined by
``jax.distributed.initialize`` on loopback; this process computes the single-device reference.
"""

import contextlib
import io
import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest
from jax.sharding import Mesh

from jaxtrack import InputError
from jaxtrack.cli import main
from jaxtrack.models import constant_velocity
from jaxtrack.montecarlo import monte_carlo, monte_carlo_sweep, run_mesh

from _sharded_cases import FIELDS, NUM_RUNS, NUM_STEPS, SWEEP_RUNS, SWEEP_VALUES, cases, cv, sweep_models

WORKER = Path(__file__).with_name("_sharded_worker.py")
KEY = jax.random.key(3)


def worker_env():
    """This process's environment for a sharded subprocess, without any device-count XLA flag (the
    worker sets its own device count) but with the rest (the suite's optimisation level: the
    statistics are compared bit for bit with this process's)."""
    env = dict(os.environ)
    flags = [f for f in env.pop("XLA_FLAGS", "").split() if "device_count" not in f]
    if flags:
        env["XLA_FLAGS"] = " ".join(flags)
    return env


def start_worker(*args, cases=None):
    env = worker_env()
    if cases is not None:
        env["JAXTRACK_SHARDED_CASES"] = ",".join(cases)
    return subprocess.Popen([sys.executable, str(WORKER), *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, cwd=WORKER.parent)


def result_of(proc, timeout=600):
    out, err = proc.communicate(timeout=timeout)
    assert proc.returncode == 0, err[-3000:]
    # Gloo prints connection messages on stdout; the result is the JSON line.
    return json.loads(next(line for line in out.splitlines() if line.startswith("{")))


def reference(names=None):
    return {name: monte_carlo(key=KEY, num_runs=NUM_RUNS, num_steps=NUM_STEPS, progress=False, **case)
            for name, case in cases().items() if names is None or name in names}


def assert_identical(stats, res, label):
    assert stats["num_runs"] == res.num_runs
    for field in FIELDS:
        np.testing.assert_array_equal(np.asarray(stats[field]), np.asarray(getattr(res, field)),
                                      err_msg=f"{label}: {field}")


# The cases the 4-device worker runs unless --runslow: the shared-covariance path and the per-run
# path with per-run masks and detections (rows sliced by run index, padding runs clamped); with the
# two-process test's "ekf_detect" every path but the plain EKF runs sharded by default.
# All four: 61 s of one worker; these two: about 35 s.
FOUR_DEVICE_SUBSET = ("kf", "kf_detect")


@pytest.fixture(scope="module")
def four_devices(request):
    subset = None if request.config.getoption("--runslow") else FOUR_DEVICE_SUBSET
    return result_of(start_worker(4, cases=subset)), subset


def test_one_and_four_devices_give_identical_statistics(four_devices):
    four_devices, subset = four_devices
    assert four_devices["device_count"] == 4
    ref = reference(subset)
    assert len(four_devices["runs"]) == 2 * len(ref)
    for label, stats in four_devices["runs"].items():
        assert_identical(stats, ref[label.split(" / ")[0]], label)
    # The comparison has teeth: a different key changes the statistics.
    other = monte_carlo(key=jax.random.key(4), num_runs=NUM_RUNS, num_steps=NUM_STEPS, progress=False,
                        **cases()["kf"])
    assert not np.array_equal(np.asarray(four_devices["runs"]["kf / all"]["mse"]), np.asarray(other.mse))


def test_sharded_sweep_matches_the_unsharded_sweep(four_devices):
    four_devices, _ = four_devices
    unsharded = monte_carlo_sweep(sweep_models, SWEEP_VALUES, KEY, SWEEP_RUNS, num_steps=NUM_STEPS, progress=False)
    assert len(four_devices["sweeps"]) == 3
    for mesh_name, per_value in four_devices["sweeps"].items():
        for q, stats, res in zip(SWEEP_VALUES, per_value, unsharded, strict=True):
            assert_identical(stats, res, f"{mesh_name}, q = {q}")
    # ... and each value of the sweep is the plain Monte Carlo of that value (common random numbers).
    for q, res in zip(SWEEP_VALUES, unsharded):
        truth, filter_model = sweep_models(q)
        single = monte_carlo(truth, KEY, SWEEP_RUNS, num_steps=NUM_STEPS, filter_model=filter_model, progress=False)
        for field in FIELDS:
            np.testing.assert_array_equal(getattr(res, field), getattr(single, field), err_msg=f"q = {q}: {field}")
    # The truth's plant noise drives the velocity error: its final MSE grows with q, each step by
    # far more than the ±4% (1σ, 1500 runs) Monte Carlo spread of an MSE.
    final = [float(r.mse[-1, 2]) for r in unsharded]
    assert final[0] < 0.8 * final[1] and final[1] < 0.8 * final[2], final


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_two_processes_give_the_single_process_statistics(request):
    """Two local processes with 2 CPU devices each, joined on loopback, form one 4-device mesh.

    One of the four cases unless --runslow (the per-run path with per-run detections; all four:
    65 worker-s, two: 31 s); the 4-device test runs the shared-covariance path, the block
    dealing and merging across processes is the same code for every case."""
    coordinator = f"127.0.0.1:{free_port()}"
    subset = None if request.config.getoption("--runslow") else ("ekf_detect",)
    procs = [start_worker(2, coordinator, 2, i, cases=subset) for i in range(2)]
    outs = [result_of(p) for p in procs]
    ref = reference(subset)
    for i, out in enumerate(outs):
        assert (out["process_count"], out["device_count"]) == (2, 4)
        assert len(out["runs"]) == 2 * (4 if subset is None else len(subset))
        for label, stats in out["runs"].items():
            assert_identical(stats, ref[label.split(" / ")[0]], f"process {i}: {label}")


def test_mesh_errors_name_the_problem():
    with pytest.raises(InputError, match="jax.sharding.Mesh"):
        monte_carlo(cv(), KEY, 10, num_steps=5, progress=False, mesh="cpu")
    with pytest.raises(InputError, match="needs at least one of"):
        monte_carlo(cv(), KEY, 10, num_steps=5, progress=False, mesh=run_mesh(axis_name="batch"))
    with pytest.raises(InputError, match="stack"):
        monte_carlo_sweep(lambda d: constant_velocity(1.0, dim=d, accel_psd=0.5, measurement_std=10.0, initial_cov=100.0 * np.eye(2 * d)), [2, 3],
                          KEY, 10, num_steps=5, progress=False)
    with pytest.raises(InputError, match="at least one"):
        monte_carlo_sweep(sweep_models, [], KEY, 10, num_steps=5, progress=False)


def test_single_device_mesh_is_the_plain_run():
    mesh = Mesh(np.asarray(jax.devices()[:1]), ("runs",))
    a = monte_carlo(key=KEY, num_runs=700, num_steps=NUM_STEPS, progress=False, mesh=mesh, **cases()["ekf"])
    b = monte_carlo(key=KEY, num_runs=700, num_steps=NUM_STEPS, progress=False, **cases()["ekf"])
    for field in FIELDS:
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))


def test_cli_demo_across_two_processes_matches_one(tmp_path):
    """``jaxtrack demo`` started once per "host" (two local processes, one device each) prints
    the single-process table; process 1 prints nothing and writes nothing."""
    args = ["demo", "--runs", "300", "--steps", "20", "--json", "--no-progress"]
    coordinator = f"127.0.0.1:{free_port()}"
    env = worker_env()
    procs = [
        subprocess.Popen([sys.executable, "-m", "jaxtrack.cli", *args, "--out", str(tmp_path / f"p{i}"),
                          "--devices", "1", "--coordinator", coordinator, "--num-processes", "2",
                          "--process-id", str(i)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        for i in range(2)
    ]
    outs = [p.communicate(timeout=600) for p in procs]
    for p, (_, err) in zip(procs, outs):
        assert p.returncode == 0, err[-3000:]
    # Gloo prints connection messages on stdout; the rest is the JSON table.
    printed = ["\n".join(line for line in out.splitlines() if not line.startswith("[Gloo]")) for out, _ in outs]
    rows = json.loads(printed[0])["rows"]
    assert printed[1].strip() == "" and not (tmp_path / "p1").exists()
    assert (tmp_path / "p0" / "demo.png").exists()
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main([*args, "--out", str(tmp_path / "single")]) == 0
    single = json.loads(buf.getvalue())["rows"]
    for a, b in zip(rows, single, strict=True):
        a.pop("seconds"), b.pop("seconds")
        assert a == b
