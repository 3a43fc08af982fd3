"""Memory of jax.grad through differentiable_monte_carlo: bounded by one block plus the totals
(checkpointed blocks), not by the number of runs. Peak RSS (``ru_maxrss``) of a fresh subprocess
per size, so each measures one configuration (JAX runtime and compilation included)."""

import json
import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent("""
    import json, resource, sys
    import jax, jax.numpy as jnp
    jax.config.update("jax_enable_x64", True)
    from jaxtrack.models import constant_velocity
    from jaxtrack.montecarlo import differentiable_monte_carlo
    runs, steps, block = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
    P0 = jnp.diag(jnp.array([100.0, 100.0, 25.0, 25.0]))
    truth = constant_velocity(1.0, accel_psd=1.0, measurement_std=10.0, initial_cov=P0)

    def loss(log_q):
        fm = constant_velocity(1.0, accel_psd=jnp.exp(log_q), measurement_std=15.0, initial_cov=P0)
        res = differentiable_monte_carlo(truth, jax.random.key(0), runs, num_steps=steps, filter_model=fm,
                                         block_size=block)
        return jnp.mean(jnp.sum(res.mse[:, :2], axis=-1))

    g = float(jax.jit(jax.grad(loss))(0.0))
    print(json.dumps({"grad": g, "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
""")


def _start(runs, steps, block):
    return subprocess.Popen([sys.executable, "-c", SCRIPT, str(runs), str(steps), str(block)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _result(proc):
    out, err = proc.communicate(timeout=900)
    assert proc.returncode == 0, err[-3000:]
    return json.loads(out.strip().splitlines()[-1])


@pytest.mark.slow
@pytest.mark.skipif(sys.platform != "linux", reason="ru_maxrss in KiB (Linux)")
def test_gradient_peak_memory_does_not_grow_with_runs():
    """10⁴ vs 10³ runs × 200 steps (blocks of 512: 20 vs 2 blocks), both processes at once.

    Behind --runslow: a memory target, which ``benchmarks/mc_gradient.py`` reports (peak RSS) in
    the default workflow; here it took 21 s of one worker with two more processes on 2 cores.

    Without checkpointing the reverse pass keeps every block's per-step residuals, O(M·T): ~15 MB
    per block of 512 × 200 here, +300 MB at 10⁴ runs. With it only the totals at each block
    boundary (O(B·T·n), < 1 MB) grow. Measured: ≈ the same peak (a few MB apart).
    """
    small, large = _start(1000, 200, 512), _start(10_000, 200, 512)
    a, b = _result(small), _result(large)
    assert b["peak_mb"] / a["peak_mb"] < 2  # the acceptance ratio
    assert b["peak_mb"] - a["peak_mb"] < 100, (a, b)  # far below the ~300 MB a non-checkpointed pass adds


@pytest.mark.slow
@pytest.mark.skipif(sys.platform != "linux", reason="ru_maxrss in KiB (Linux)")
def test_gradient_1e5_runs_200_steps_under_2gb():
    """The acceptance size: the gradient for 10⁵ runs × 200 steps under 2 GB peak RSS (default blocks)."""
    r = _result(_start(100_000, 200, 2048))
    assert r["peak_mb"] < 2048, r
