"""The PMBM filter (García-Fernández, Williams, Granström & Svensson 2018) and the track-oriented
PMB filter (Williams 2015) against a brute-force enumeration of every global hypothesis.

The oracle below is written from the papers' equations with Python lists and itertools: every
prior global hypothesis and every injective map of its present tracks to the scan's measurements
(the rest missed; an unassigned measurement starts a new track), weights multiplied out and
normalised, nothing pruned. The PMB oracle is the same update followed by the track-by-track
projection (Williams 2015, Sec. IV). Tiny cases (scans of 2, 2, 2 measurements: 1, 7 and 87 global
hypotheses) and one compiled shape per filter.
"""

import itertools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.association import JPDA
from jaxtrack.filters import KalmanFilter
from jaxtrack.models import LinearGaussianModel
from _multitarget_cases import new_style
from jaxtrack.multitarget import PMB, PMBM, CapacityWarning, run_pmbm

F_CV = np.array([[1, 1.0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1.0], [0, 0, 0, 1.0]])
Q_CV = 0.1 * np.kron(np.eye(2), np.array([[1 / 3, 1 / 2], [1 / 2, 1.0]]))
H_CV = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
R_CV = np.diag([1.0, 1.5])
B_MEAN = np.array([1.0, 0.5, -2.0, 0.3])  # moving: a predicted Poisson component never sits on a new birth
B_COV = np.diag([25.0, 4.0, 16.0, 4.0])
PS, PD, KAPPA, BIRTH_W, INIT_W = 0.95, 0.8, 1.0 / 400.0, 0.3, 2.0
SCANS = [[[2.0, -1.0], [-6.0, 4.0]], [[3.1, -0.8], [-6.9, 4.6]], [[4.0, -0.5], [20.0, 9.0]]]
T, M_MAX, N_MAX, H_MAX = 3, 3, 8, 96  # 87 hypotheses after three scans: none pruned


def _model():
    return LinearGaussianModel(F_CV, Q_CV, H_CV, R_CV, B_MEAN, B_COV)


def _kwargs(**kw):
    args = {"prob_survival": PS, "prob_detect": PD, "clutter_density": KAPPA, "birth_weights": [BIRTH_W],
            "birth_means": [B_MEAN], "birth_covs": [B_COV], "initial_weights": [INIT_W], "initial_means": [B_MEAN],
            "initial_covs": [B_COV], "max_tracks": N_MAX, "existence_threshold": 0.0, "poisson_prune_threshold": 0.0,
            "poisson_merge_threshold": 0.0, "poisson_capacity": 8}
    return new_style({**args, **kw})


def _scans(points=SCANS):
    z = np.full((T, M_MAX, 2), np.nan)
    valid = np.zeros((T, M_MAX), bool)
    for k, scan in enumerate(points):
        for j, p in enumerate(scan):
            z[k, j], valid[k, j] = p, True
    return z, valid


# ---------------------------------------------------------------------------------------------- oracle
def _gauss(z, mean, S):
    y = z - mean
    return math.exp(-0.5 * y @ np.linalg.solve(S, y)) / math.sqrt(np.linalg.det(2 * np.pi * S))


def _kf_update(m, P, z):
    S = H_CV @ P @ H_CV.T + R_CV
    K = P @ H_CV.T @ np.linalg.inv(S)
    return m + K @ (z - H_CV @ m), (np.eye(4) - K @ H_CV) @ P, _gauss(z, H_CV @ m, S)


def _oracle(points, *, project=False):
    """After each scan: (Poisson [(w, m, P)], hypotheses [(weight, [(r, m, P) of present tracks]])."""
    ppp = [(INIT_W, B_MEAN, B_COV)]
    tracks = []  # track -> list of local hypotheses (r, m, P)
    hyps = [(1.0, ())]  # (weight, local index per track or None)
    out = []
    for k, scan in enumerate(points):
        if k > 0:
            ppp = [(PS * w, F_CV @ m, F_CV @ P @ F_CV.T + Q_CV) for w, m, P in ppp] + [(BIRTH_W, B_MEAN, B_COV)]
            tracks = [[(PS * r, F_CV @ m, F_CV @ P @ F_CV.T + Q_CV) for r, m, P in t] for t in tracks]
        zs = [np.asarray(z) for z in scan]
        # New tracks (one per measurement): the Poisson components updated on z, collapsed.
        new = []
        for z in zs:
            parts = [(PD * w * lik, mu, Pu) for w, m, P in ppp for mu, Pu, lik in [_kf_update(m, P, z)]]
            e = sum(a for a, _, _ in parts)
            mean = sum(a * mu for a, mu, _ in parts) / e
            cov = sum(a * (Pu + np.outer(mu - mean, mu - mean)) for a, mu, Pu in parts) / e
            new.append((e / (e + KAPPA), mean, cov, e + KAPPA))
        post = []
        for w, loc in hyps:
            present = [t for t in range(len(tracks)) if loc[t] is not None]
            for choice in itertools.product([None] + list(range(len(zs))), repeat=len(present)):
                used = [c for c in choice if c is not None]
                if len(used) != len(set(used)):
                    continue
                weight, bern = w, []
                for t, c in zip(present, choice):
                    r, m, P = tracks[t][loc[t]]
                    if c is None:
                        weight *= 1 - r * PD
                        bern.append((r * (1 - PD) / (1 - r * PD), m, P))
                    else:
                        mu, Pu, lik = _kf_update(m, P, zs[c])
                        weight *= r * PD * lik
                        bern.append((1.0, mu, Pu))
                for j, (r, m, P, wj) in enumerate(new):
                    if j not in used:
                        weight *= wj
                        bern.append((r, m, P))
                post.append((weight, bern, present, choice, used))
        total = sum(p[0] for p in post)
        post = [(p[0] / total,) + p[1:] for p in post]
        ppp = [((1 - PD) * w, m, P) for w, m, P in ppp]
        out.append((list(ppp), [(w, b) for w, b, *_ in post]))
        # Rebuild the track-oriented form for the next scan: each old track's children, then new tracks.
        n_old = len(tracks)
        tracks2 = [[] for _ in range(n_old + len(zs))]
        hyps2 = []
        for w, bern, present, choice, used in post:
            loc = [None] * (n_old + len(zs))
            for i, t in enumerate(present):
                key_b = bern[i]
                idx = _find(tracks2[t], key_b)
                loc[t] = idx
            nb = len(present)
            for j in range(len(zs)):
                if j not in used:
                    idx = _find(tracks2[n_old + j], bern[nb])
                    loc[n_old + j] = idx
                    nb += 1
            hyps2.append((w, tuple(loc)))
        tracks, hyps = tracks2, hyps2
        if project:
            merged = []
            for t in range(len(tracks)):
                wr = [(w * tracks[t][loc[t]][0], tracks[t][loc[t]]) for w, loc in hyps if loc[t] is not None]
                r = sum(a for a, _ in wr)
                if r == 0:
                    merged.append([(0.0, B_MEAN, B_COV)])
                    continue
                mean = sum(a * b[1] for a, b in wr) / r
                cov = sum(a * (b[2] + np.outer(b[1] - mean, b[1] - mean)) for a, b in wr) / r
                merged.append([(r, mean, cov)])
            tracks = merged
            hyps = [(1.0, tuple(0 for _ in tracks))]
            out[-1] = (out[-1][0], [(1.0, [b[0] for b in tracks])])
    return out


def _find(lst, bern):
    """The index of an identical Bernoulli in ``lst`` (appended when new)."""
    for i, b in enumerate(lst):
        if b[0] == bern[0] and np.array_equal(b[1], bern[1]) and np.array_equal(b[2], bern[2]):
            return i
    lst.append(bern)
    return len(lst) - 1


def _hypotheses_of(state):
    """The state's global hypotheses as [(weight, [(r, m, P) of present tracks])], weight-sorted."""
    s = jax.tree_util.tree_map(np.asarray, state)
    out = []
    for h in np.flatnonzero(s.hypothesis_active):
        bern = [(s.existence[t, l], s.means[t, l], s.covs[t, l])
                for t, l in enumerate(s.hypotheses[h]) if l >= 0 and s.track_active[t]]
        out.append((math.exp(s.log_weights[h]), bern))
    return out


def _canonical(hyps):
    def key(b):
        return (round(b[0], 9), tuple(np.round(b[1], 6)))

    return sorted(((w, sorted(bern, key=key)) for w, bern in hyps), key=lambda x: -x[0])


def _assert_same_hypotheses(got, want, tol):
    got, want = _canonical(got), _canonical(want)
    assert len(got) == len(want)
    for (wg, bg), (ww, bw) in zip(got, want):
        assert abs(wg - ww) <= tol
        assert len(bg) == len(bw)
        for (rg, mg, Pg), (rw, mw, Pw) in zip(bg, bw):
            assert abs(rg - rw) <= tol
            np.testing.assert_allclose(mg, mw, rtol=0, atol=tol * 10)
            np.testing.assert_allclose(Pg, Pw, rtol=0, atol=tol * 10)


_STEP = eqx.filter_jit(lambda f, s, zk, vk: f.step(s, zk, vk))


@pytest.fixture(scope="module")
def pmbm_states():
    pmbm = PMBM(KalmanFilter(), _model(), max_hypotheses=H_MAX, assignment_rows=M_MAX, assignment_tracks=N_MAX,
                **_kwargs())
    z, valid = _scans()
    state = pmbm.init()
    states = []
    for k in range(T):
        state, info = _STEP(pmbm, state, z[k], valid[k])
        states.append((state, info))
    return pmbm, states


def test_pmbm_equals_brute_force_enumeration(pmbm_states):
    pmbm, states = pmbm_states
    want = _oracle(SCANS)
    for k, (state, info) in enumerate(states):
        assert int(info.num_hypotheses) == len(want[k][1])
        _assert_same_hypotheses(_hypotheses_of(state), want[k][1], 1e-10)
        w = np.asarray(state.poisson_weights)[np.asarray(state.poisson_active)]
        np.testing.assert_allclose(np.sort(w), np.sort([p[0] for p in want[k][0]]), rtol=1e-12)
    assert [len(w[1]) for w in want] == [1, 7, 87]  # 21 + 4·13 + 2·7 after the third scan


def test_pmb_equals_projected_brute_force(pmbm_states):
    pmb = PMB(KalmanFilter(), _model(), associator=JPDA(), **_kwargs())
    z, valid = _scans()
    state = pmb.init()
    want = _oracle(SCANS, project=True)
    for k in range(T):
        state, info = _STEP(pmb, state, z[k], valid[k])
        assert bool(info.association_ok)
        _assert_same_hypotheses(_hypotheses_of(state), want[k][1], 1e-10)


def test_run_pmbm_estimates_and_capacity_warning():
    pmbm = PMBM(KalmanFilter(), _model(), max_hypotheses=16, **_kwargs(max_tracks=2))
    z, valid = _scans()
    with pytest.warns(CapacityWarning, match="max_tracks=2"):
        result = run_pmbm(pmbm, z, valid)
    assert bool(result.overflow) and int(np.sum(result.num_dropped_tracks)) > 0


def test_input_errors():
    with pytest.raises(InputError, match="prob_detect"):
        PMBM(KalmanFilter(), _model(), max_hypotheses=4, **_kwargs(prob_detect=1.0))
    with pytest.raises(InputError, match="max_hypotheses"):
        PMBM(KalmanFilter(), _model(), max_hypotheses=0, **_kwargs())
    with pytest.raises(InputError, match="clutter_density"):
        PMB(KalmanFilter(), _model(), **_kwargs(clutter_density=0.0))
    with pytest.raises(InputError, match="associator"):
        PMB(KalmanFilter(), _model(), associator="jpda", **_kwargs())
    with pytest.raises(InputError, match="mb"):
        run_pmbm("pmbm", *_scans())


def test_pmb_gradient_through_soft_marginals_matches_central_differences():
    """d(expected number of targets after 3 scans)/d(P_D, κ, birth weight) and d(Σ_k GOSPA_k)/d(·)
    of the PMB with loopy BP marginals, by jax.grad and by central differences. Both are smooth
    here: nothing is pruned (threshold 0) and the estimates' existence stays away from 0.4 (the
    same estimate masks at ±h, checked); the estimates are β-weighted means, so GOSPA moves."""
    from jaxtrack.association import LoopyBP
    from jaxtrack.montecarlo import gospa

    z, valid = _scans()
    truth = jnp.asarray([[[2.0, -1.0], [-6.0, 4.0]], [[3.0, -0.8], [-7.0, 4.5]], [[4.0, -0.5], [-7.8, 5.0]]])

    def objectives(pd, kappa, bw):
        pmb = PMB(KalmanFilter(), _model(), associator=LoopyBP(num_iters=30),
                  **_kwargs(prob_detect=pd, clutter_density=kappa, birth_weights=jnp.reshape(bw, (1,))))
        r = run_pmbm(pmb, z, valid, warn=False)
        g = jax.vmap(lambda x, y, m: gospa(x, jnp.ones(2, bool), y, m, cutoff=10.0).distance)(
            truth, r.estimates[..., jnp.array([0, 2])], r.estimate_mask)
        return jnp.stack([r.expected_cardinality[-1], jnp.sum(g)]), r.estimate_mask

    x0 = (PD, KAPPA, BIRTH_W)
    f = jax.jit(jax.jacobian(objectives, argnums=(0, 1, 2), has_aux=True))  # one program: d(both)/d(each)
    value = jax.jit(objectives)
    grads, mask0 = f(*map(jnp.asarray, x0))
    assert int(np.sum(np.asarray(mask0))) >= 4  # GOSPA scores real estimates (2, 2 and 1 per scan)
    for i, g in enumerate(grads):
        h = 1e-5 * x0[i]
        plus, mp = value(*[jnp.asarray(x + (h if j == i else 0.0)) for j, x in enumerate(x0)])
        minus, mm = value(*[jnp.asarray(x - (h if j == i else 0.0)) for j, x in enumerate(x0)])
        assert np.array_equal(np.asarray(mp), np.asarray(mm))
        fd = (np.asarray(plus) - np.asarray(minus)) / (2 * h)
        assert abs(fd[0]) > 1e-6 and abs(fd[1]) > 1e-6, (i, fd)
        np.testing.assert_allclose(np.asarray(g), fd, rtol=1e-6, err_msg=str(i))
