"""Make the independent reference for the particle filter's likelihood: the bootstrap filter of
the ``particles`` library (Chopin & Papaspiliopoulos 2020) on a fixed linear-Gaussian record.

``particles`` cannot be an oracle installed beside jaxtrack: its release 0.4 requires
``numpy < 2`` and jaxtrack's lock pins numpy 2.x (JAX needs it). So its output is made once,
in a virtual environment of its own, and stored: ``tests/data/particles_bootstrap_loglik.npz``
holds the model's matrices, the measurements, and ``RUNS`` log-likelihood estimates of
``particles``' bootstrap filter (``N`` particles, systematic resampling when ESS < N/2: the
defaults of ``particles.SMC``, and of :class:`jaxtrack.filters.ParticleFilter`).
``tests/test_particle_filter.py`` compares jaxtrack's estimates on the same record with these
(two-sample Kolmogorov–Smirnov). The versions used are stored in the file.

Usage (in a fresh virtual environment, not jaxtrack's)::

    python -m venv /path/to/pvenv && /path/to/pvenv/bin/pip install "particles==0.4" "numpy<2"
    /path/to/pvenv/bin/python tools/make_particles_reference.py

The model: a 2-D constant-velocity target, state ``(x, y, vx, vy)`` in m and m/s, period 1 s,
white-acceleration intensity 0.5 m²/s³, position measurements with σ = 10 m, prior
``N(0, diag(20², 20², 2², 2²))`` on the state at the first measurement (jaxtrack's
``first_step="update"``; ``particles``' ``X_0 ~ N(mu0, cov0)``, ``Y_0 = G X_0 + V``).
"""

from __future__ import annotations

import sys
from importlib import metadata
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent.parent / "tests" / "data" / "particles_bootstrap_loglik.npz"
STEPS = 25
PARTICLES = 100
RUNS = 2000
SEED = 20261205


def model():
    dt, q, sigma = 1.0, 0.5, 10.0
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    block = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    Q = np.zeros((4, 4))
    for i in range(2):  # axis i: position i, velocity i + 2
        idx = np.ix_([i, i + 2], [i, i + 2])
        Q[idx] = block
    H = np.zeros((2, 4))
    H[0, 0] = H[1, 1] = 1.0
    R = sigma**2 * np.eye(2)
    m0 = np.zeros(4)
    P0 = np.diag([20.0, 20.0, 2.0, 2.0]) ** 2
    return F, Q, H, R, m0, P0


def simulate(F, Q, H, R, m0, P0, rng):
    x = rng.multivariate_normal(m0, P0)
    zs = []
    for k in range(STEPS):
        if k:
            x = F @ x + rng.multivariate_normal(np.zeros(4), Q)
        zs.append(H @ x + rng.multivariate_normal(np.zeros(2), R))
    return np.array(zs)


def main():
    import particles
    from particles import kalman
    from particles import state_space_models as ssm

    F, Q, H, R, m0, P0 = model()
    rng = np.random.default_rng(SEED)
    z = simulate(F, Q, H, R, m0, P0, rng)
    lg = kalman.MVLinearGauss(F=F, G=H, covX=Q, covY=R, mu0=m0, cov0=P0)
    fk = ssm.Bootstrap(ssm=lg, data=[zk for zk in z])
    np.random.seed(SEED)  # particles draws from NumPy's global generator
    loglik = np.empty(RUNS)
    for i in range(RUNS):
        pf = particles.SMC(fk=fk, N=PARTICLES, resampling="systematic", ESSrmin=0.5)
        pf.run()
        loglik[i] = pf.logLt
    # The exact log-likelihood from particles' own Kalman filter (a check of the model's setup).
    kf = kalman.Kalman(ssm=lg, data=[zk for zk in z])
    kf.filter()
    exact = float(np.sum(kf.logpyt))
    versions = f"particles {metadata.version('particles')}, numpy {np.__version__}, python {sys.version.split()[0]}"
    np.savez(OUT, F=F, Q=Q, H=H, R=R, m0=m0, P0=P0, z=z, loglik=loglik, exact=exact, particles=PARTICLES,
             versions=versions)
    print(f"wrote {OUT}: {RUNS} runs, N = {PARTICLES}, T = {STEPS}; mean exp(l - l_KF) = "
          f"{np.mean(np.exp(loglik - exact)):.4f}; {versions}")


if __name__ == "__main__":
    main()
