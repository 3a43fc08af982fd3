"""Shared cases for the learning tests: three linear-Gaussian models with variance parameters.

``_case(name)`` gives ``(F, H, [Q_i], R1, m0, P0, θ_true)`` with ``Q = Σ θ_i Q_i``, ``R = θ_last R1``;
``_simulate`` draws ``T = 200`` measurements; ``_builder_for(name)`` is the cached ``build`` for
:func:`jaxtrack.learning.fit` (one object per model: the fit loop compiles once per model).
"""

import functools

import jax.numpy as jnp
import numpy as np

from jaxtrack.models import LinearGaussianModel

T = 200


def _case(name):
    """(F, H, Qs, R1, a0, P0, true θ) for the three models."""
    if name == "local_level":
        F, H = np.eye(1), np.eye(1)
        Qs = [np.eye(1)]
        theta = [0.5, 1.0]
        a0, P0 = np.zeros(1), 10.0 * np.eye(1)
    elif name == "local_linear_trend":
        F, H = np.array([[1.0, 1.0], [0.0, 1.0]]), np.array([[1.0, 0.0]])
        Qs = [np.diag([1.0, 0.0]), np.diag([0.0, 1.0])]
        theta = [1.0, 0.1, 2.0]
        a0, P0 = np.zeros(2), np.diag([10.0, 1.0])
    else:  # constant velocity: position measured, white-noise acceleration of PSD q (dt = 1 s)
        dt = 1.0
        F, H = np.array([[1.0, dt], [0.0, 1.0]]), np.array([[1.0, 0.0]])
        Qs = [np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])]
        theta = [0.3, 4.0]
        a0, P0 = np.zeros(2), np.diag([25.0, 4.0])
    return F, H, Qs, np.eye(1), a0, P0, np.array(theta)


def _simulate(F, H, Qs, R1, a0, P0, theta, seed):
    rng = np.random.default_rng(seed)
    Q = sum(t * Qi for t, Qi in zip(theta[:-1], Qs))
    n = F.shape[0]
    x = rng.multivariate_normal(a0, P0)
    ys = []
    for _ in range(T):
        ys.append(H @ x + rng.multivariate_normal(np.zeros(1), theta[-1] * R1))
        x = F @ x + rng.multivariate_normal(np.zeros(n), Q, method="eigh")
    return np.array(ys)


@functools.lru_cache(maxsize=None)
def _builder_for(name):
    # One build function per model, reused across tests: fit's loop compiles once per build.
    return _builder(*_case(name)[:6])


def _builder(F, H, Qs, R1, a0, P0):
    F, H, R1, a0, P0 = (jnp.asarray(a) for a in (F, H, R1, a0, P0))
    Qs = jnp.asarray(np.stack(Qs))

    def build(p):
        theta = p["theta"]()
        return LinearGaussianModel(F, jnp.tensordot(theta[:-1], Qs, 1), H, theta[-1] * R1, a0, P0)

    return build
