"""The GM-CPHD filter (Vo, Vo & Cantoni 2007): the cardinality pmf and the intensity weights
against a brute-force enumeration of every measurement-to-target assignment, the identity
"updated intensity mass = updated mean cardinality", the truncation flag, a non-finite update
flagged, gradients against central differences, and the input checks.

One shape only (T = 3 scans, M_max = 4, N_max = 3, capacity 48): every forward run shares one
compiled program, the gradient test adds one more."""

import itertools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.special import gammainc

from jaxtrack import InputError
from jaxtrack.filters import KalmanFilter
from jaxtrack.models import LinearGaussianModel
from _multitarget_cases import new_style
from jaxtrack.multitarget import GMCPHD, GMPHD, CapacityWarning, run_cphd, run_phd

DT = 1.0
F_CV = np.array([[1, DT, 0, 0], [0, 1, 0, 0], [0, 0, 1, DT], [0, 0, 0, 1.0]])
Q_CV = 0.1 * np.kron(np.eye(2), np.array([[DT**3 / 3, DT**2 / 2], [DT**2 / 2, DT]]))
H_CV = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
R_CV = np.diag([1.0, 1.5])
B_MEAN = np.array([1.0, 0.5, -2.0, 0.3])  # moving, so a predicted missed birth does not sit on the new birth
B_COV = np.diag([25.0, 4.0, 16.0, 4.0])
PS, PD, LAM, C = 0.9, 0.7, 1.5, 1.0 / 400.0
BIRTH_W = 0.4
BIRTH_CARD = [0.6, 0.4]  # Bernoulli births: at most one per scan, so at most 3 targets in 3 scans
N_MAX, CAPACITY = 3, 48
# Scans of 2, 4 and 1 measurements (M_max = 4): 3, 20 and 42 components with no pruning or merging.
SCANS = [[[2.0, -1.0], [-6.0, 4.0]], [[3.1, -0.8], [-6.9, 4.6], [8.0, 1.0], [0.5, -3.0]], [[4.0, -0.5]]]
T, M_MAX = 3, 4


def _cphd(**kwargs):
    model = LinearGaussianModel(F_CV, Q_CV, H_CV, R_CV, B_MEAN, B_COV)
    args = {"prob_survival": PS, "prob_detect": PD, "clutter_rate": LAM, "clutter_volume": 400.0,  # c = 1/V = C
            "birth_weights": [BIRTH_W], "birth_means": [B_MEAN], "birth_covs": [B_COV],
            "birth_cardinality": BIRTH_CARD, "capacity": CAPACITY, "max_cardinality": N_MAX,
            "prune_threshold": 0.0, "merge_threshold": 0.0}
    return GMCPHD(KalmanFilter(), model, **new_style({**args, **kwargs}))


def _scans(points=SCANS):
    z = np.full((T, M_MAX, 2), np.nan)
    valid = np.zeros((T, M_MAX), bool)
    for k, scan in enumerate(points):
        for j, p in enumerate(scan):
            z[k, j], valid[k, j] = p, True
    return z, valid


def _gauss(z, mean, S):
    y = z - mean
    return math.exp(-0.5 * y @ np.linalg.solve(S, y)) / math.sqrt(np.linalg.det(2 * np.pi * S))


def _brute_force(points, *, ps=PS, pd=PD, lam=LAM, c=C):
    """The CPHD recursion by enumeration, no elementary symmetric functions: per scan, every
    cardinality n <= N_max and every assignment θ of a subset S of the measurements to distinct
    targets (itertools.combinations for S, permutations for the targets), the rest clutter.
    With the predicted targets i.i.d. with density v/N, θ has weight
    p(n) (1 − P_D)^{n−|S|} Π_{z∈S} P_D ℓ(z)/N Π_{z∉S} λ c,  ℓ(z) = Σ_i w_i q_i(z);
    the posterior intensity puts (n − |S|) w_i / N on each missed component and w_i q_i(z) / ℓ(z)
    on component i updated on z ∈ S, averaged over the hypotheses' posterior probabilities.
    Returns the pmf and the sorted component weights after each scan."""
    comps, pmf = [], np.eye(N_MAX + 1)[0]
    history = []
    for scan in points:
        zs = [np.asarray(z) for z in scan]
        M = len(zs)
        pred = [(ps * w, F_CV @ m, F_CV @ P @ F_CV.T + Q_CV) for w, m, P in comps]
        pred.append((BIRTH_W, B_MEAN, B_COV))
        surv = [sum(math.comb(l, j) * ps**j * (1 - ps) ** (l - j) * pmf[l] for l in range(j, N_MAX + 1))
                for j in range(N_MAX + 1)]
        birth = BIRTH_CARD + [0.0] * (N_MAX + 1 - len(BIRTH_CARD))
        ppred = [sum(birth[n - j] * surv[j] for j in range(n + 1)) for n in range(N_MAX + 1)]
        N = sum(w for w, _, _ in pred)
        q = np.array([[_gauss(z, H_CV @ m, H_CV @ P @ H_CV.T + R_CV) for z in zs] for _, m, P in pred]).reshape(len(pred), M)
        ell = np.array([sum(pred[i][0] * q[i, j] for i in range(len(pred))) for j in range(M)])
        post_n = np.zeros(N_MAX + 1)
        missed_count = 0.0  # Σ_θ weight·(n − |S|)
        detected = np.zeros(M)  # Σ_θ weight·[z ∈ S]
        for n in range(N_MAX + 1):
            for j in range(min(n, M) + 1):
                for S in itertools.combinations(range(M), j):
                    for _targets in itertools.permutations(range(n), j):
                        wt = ppred[n] * (1 - pd) ** (n - j) * (lam * c) ** (M - j)
                        for z in S:
                            wt *= pd * ell[z] / N
                        post_n[n] += wt
                        missed_count += wt * (n - j)
                        for z in S:
                            detected[z] += wt
        total = post_n.sum()
        pmf = post_n / total
        new = [(w * missed_count / total / N, m, P) for w, m, P in pred]
        for j, z in enumerate(zs):
            for i, (w, m, P) in enumerate(pred):
                S_ = H_CV @ P @ H_CV.T + R_CV
                K = P @ H_CV.T @ np.linalg.inv(S_)
                new.append((w * q[i, j] / ell[j] * detected[j] / total, m + K @ (z - H_CV @ m), (np.eye(4) - K @ H_CV) @ P))
        comps = [cmp for cmp in new if cmp[0] > 0.0]
        history.append((pmf.copy(), np.sort([w for w, _, _ in comps])[::-1]))
    return history


def test_cardinality_and_weights_equal_brute_force_enumeration():
    """Three scans (2, 4, 1 measurements; at most 3 targets), no pruning or merging: the pmf and
    every component weight equal the enumeration of all assignment hypotheses to 1e-10."""
    z, valid = _scans()
    result = run_cphd(_cphd(), z, valid)
    assert bool(np.all(result.ok)) and not bool(result.overflow) and not bool(result.truncated)
    np.testing.assert_array_equal(np.asarray(result.truncated_mass), 0.0)
    worst_pmf = worst_w = 0.0
    for k, (pmf, weights) in enumerate(_brute_force(SCANS)):
        act = np.asarray(result.active[k])
        got = np.sort(np.asarray(result.weights[k])[act])[::-1]
        assert got.shape == weights.shape, (k, got.shape, weights.shape)
        worst_pmf = max(worst_pmf, np.max(np.abs(np.asarray(result.cardinality_pmf[k]) - pmf)))
        worst_w = max(worst_w, np.max(np.abs(got - weights)))
    print(f"largest differences: pmf {worst_pmf:.2e}, weights {worst_w:.2e}")
    assert worst_pmf <= 1e-10 and worst_w <= 1e-10
    assert int(np.asarray(result.active[-1]).sum()) == 42


def test_intensity_mass_equals_mean_cardinality():
    """The updated intensity's mass equals the updated cardinality's mean (and the pmf sums to 1),
    every scan; extraction takes the MAP number of the heaviest components."""
    z, valid = _scans()
    result = run_cphd(_cphd(), z, valid)
    pmf = np.asarray(result.cardinality_pmf)
    np.testing.assert_allclose(pmf.sum(axis=1), 1.0, rtol=0, atol=1e-12)
    mean = pmf @ np.arange(N_MAX + 1)
    np.testing.assert_allclose(np.asarray(result.mean_cardinality), mean, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(result.updated_intensity_mass), mean, rtol=0, atol=1e-10)
    np.testing.assert_array_equal(np.asarray(result.map_cardinality), pmf.argmax(axis=1))
    for k in range(T):
        n_hat = int(result.map_cardinality[k])
        assert int(np.asarray(result.estimate_mask[k]).sum()) == n_hat == int(result.num_estimates[k])
        w, act = np.asarray(result.weights[k]), np.asarray(result.active[k])
        heaviest = np.asarray(result.means[k])[np.argsort(-np.where(act, w, -np.inf), kind="stable")[:n_hat]]
        np.testing.assert_allclose(np.asarray(result.estimates[k])[:n_hat], heaviest, rtol=0, atol=0)


def test_poisson_prediction_reduces_to_the_phd_update():
    """With a Poisson predicted cardinality (the first scan: Poisson births onto no targets) and
    Poisson clutter, the CPHD's intensity update is the PHD's with ``κ = λ c``. The Poisson is
    truncated at N_max = 3, which shows as a relative difference scaling as μ³ (2.1e-9 at birth mass
    μ = 1e-3, 2.1e-12 at 1e-4); a Bernoulli birth of the same mean differs by 2.4e-4 at 1e-4."""
    mu = 1e-4
    z, valid = _scans([SCANS[1]])
    cphd = run_cphd(_cphd(birth_weights=[mu], birth_cardinality=None), z, valid, warn=False)
    model = LinearGaussianModel(F_CV, Q_CV, H_CV, R_CV, B_MEAN, B_COV)
    phd = run_phd(GMPHD(KalmanFilter(), model, **new_style(dict(
        prob_survival=PS, prob_detect=PD, clutter_density=LAM * C, birth_weights=[mu], birth_means=[B_MEAN],
        birth_covs=[B_COV], capacity=CAPACITY, prune_threshold=0.0, merge_threshold=0.0))), z, valid)
    act = np.asarray(phd.active[0])
    assert act.sum() == 5
    np.testing.assert_array_equal(np.asarray(cphd.active[0]), act)
    np.testing.assert_allclose(np.asarray(cphd.weights[0])[act], np.asarray(phd.weights[0])[act], rtol=1e-10, atol=0)
    np.testing.assert_allclose(np.asarray(cphd.means[0])[act], np.asarray(phd.means[0])[act], rtol=1e-12, atol=1e-12)
    # and not for a Bernoulli birth of the same mean
    bern = run_cphd(_cphd(birth_weights=[mu], birth_cardinality=[1 - mu, mu]), z, valid, warn=False)
    assert np.max(np.abs(np.asarray(bern.weights[0])[act] / np.asarray(phd.weights[0])[act] - 1.0)) > 1e-5


def test_initial_intensity_is_a_poisson_start():
    """``initial_*``: a Poisson RFS at time 0. The CPHD's pmf is Poisson(Σ w_0) (SciPy's, cut at
    N_max = 3 and renormalised, the tail counted as truncated), and with Poisson births its first
    update from a tiny initial mass equals the PHD's from the same initial intensity (the
    truncation shows as μ³: total mass 2e-4, 1e-10 relative)."""
    from scipy.stats import poisson

    m0, P0 = B_MEAN + np.array([-7.0, 0.0, 6.0, 0.0]), B_COV / 4.0
    big = _cphd(initial_weights=[1.5, 1.0], initial_means=[m0, B_MEAN], initial_covs=[P0, B_COV]).init()
    want = poisson.pmf(np.arange(N_MAX + 1), 2.5)
    np.testing.assert_allclose(np.asarray(big.cardinality_pmf), want / want.sum(), rtol=1e-13)
    np.testing.assert_allclose(float(big.truncated_mass), poisson.sf(N_MAX, 2.5), rtol=1e-12)
    assert int(np.asarray(big.mixture.active).sum()) == 2 and float(big.mixture.cardinality) == 2.5

    mu = 1e-4
    start = dict(initial_weights=[mu], initial_means=[m0], initial_covs=[P0])
    z, valid = _scans([SCANS[0]])
    cphd = run_cphd(_cphd(birth_weights=[mu], birth_cardinality=None, **start), z, valid, warn=False)
    model = LinearGaussianModel(F_CV, Q_CV, H_CV, R_CV, B_MEAN, B_COV)
    phd = run_phd(GMPHD(KalmanFilter(), model, **new_style(dict(
        prob_survival=PS, prob_detect=PD, clutter_density=LAM * C, birth_weights=[mu], birth_means=[B_MEAN],
        birth_covs=[B_COV], capacity=CAPACITY, prune_threshold=0.0, merge_threshold=0.0, **start))), z, valid)
    act = np.asarray(phd.active[0])
    assert act.sum() == 2 * (1 + len(SCANS[0]))  # the initial and the birth component, missed and per z
    np.testing.assert_array_equal(np.asarray(cphd.active[0]), act)
    np.testing.assert_allclose(np.asarray(cphd.weights[0])[act], np.asarray(phd.weights[0])[act], rtol=1e-10, atol=0)
    np.testing.assert_allclose(np.asarray(cphd.means[0])[act], np.asarray(phd.means[0])[act], rtol=1e-12, atol=1e-12)


def test_cardinality_truncation_is_flagged():
    """A Poisson birth cardinality (mean 0.4) with N_max = 3: the mass above 3 is reported per
    scan, at least the Poisson tail P(N_birth > 3), and warned about."""
    z, valid = _scans()
    with pytest.warns(CapacityWarning, match="max_cardinality"):
        result = run_cphd(_cphd(birth_cardinality=None), z, valid)
    assert bool(result.truncated)
    mass = np.asarray(result.truncated_mass)
    np.testing.assert_allclose(mass[0], gammainc(N_MAX + 1, BIRTH_W), rtol=1e-12)
    assert np.all(mass[1:] > mass[0])
    np.testing.assert_allclose(float(result.final.truncated_mass), mass.sum(), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(result.cardinality_pmf).sum(axis=1), 1.0, atol=1e-12)


def test_infeasible_update_is_flagged_not_silent():
    """No clutter (λ = 0): two measurements in the first scan and at most one (Bernoulli) birth, so
    no hypothesis explains it; ``ok`` is False from there on and a RuntimeWarning names the scans."""
    z, valid = _scans()
    with pytest.warns(RuntimeWarning, match=r"scans \[0, 1, 2\]"):
        result = run_cphd(_cphd(clutter_rate=0.0), z, valid)
    assert np.asarray(result.ok).tolist() == [False, False, False]
    # One measurement and room for it: the same λ = 0 filter is fine.
    z1, valid1 = _scans([[[2.0, -1.0]]])
    assert bool(np.all(run_cphd(_cphd(clutter_rate=0.0), z1, valid1).ok))


def test_gradient_matches_central_differences():
    """d(final mean cardinality)/d(P_D, λ) by jax.grad and by central differences (no pruning or
    merging, so nothing discrete can flip)."""
    z, valid = _scans()

    def mean_card(pd, lam):
        return run_cphd(_cphd(prob_detect=pd, clutter_rate=lam), z, valid, warn=False).mean_cardinality[-1]

    x0 = (PD, LAM)
    grads = jax.grad(mean_card, argnums=(0, 1))(*map(jnp.asarray, x0))
    for i, g in enumerate(grads):
        h = 1e-6 * x0[i]
        plus = float(mean_card(*[x + (h if j == i else 0.0) for j, x in enumerate(x0)]))
        minus = float(mean_card(*[x - (h if j == i else 0.0) for j, x in enumerate(x0)]))
        fd = (plus - minus) / (2 * h)
        assert abs(fd) > 1e-3
        assert abs(float(g) - fd) <= 1e-6 * abs(fd), (i, float(g), fd)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"prob_detect": 0.0}, "prob_detect"),
        ({"clutter_rate": -1.0}, "clutter_rate"),
        ({"clutter_volume": 0.0}, "clutter_volume"),
        ({"clutter_density": 1e-3}, "clutter_volume"),  # both given
        ({"clutter_spatial_density": 1e-3}, "clutter_spatial_density"),  # meant c = 1/V up to 0.1.0: refused
        ({"max_cardinality": 0}, "max_cardinality"),
        ({"birth_cardinality": [0.5, 0.4]}, "birth_cardinality"),  # not a pmf
        ({"birth_cardinality": [0.5, 0.5]}, "birth_cardinality"),  # mean 0.5, birth mass 0.4
        ({"birth_cardinality": np.full(5, 0.2)}, "birth_cardinality"),  # longer than N_max + 1
        ({"birth_means": [[0.0, 0.0]], "birth_covs": [np.eye(2)]}, "birth"),
        ({"capacity": 0}, "capacity"),
    ],
)
def test_bad_arguments_raise_input_error(kwargs, name):
    with pytest.raises(InputError, match=f"`{name}`"):
        _cphd(**kwargs)


def test_bad_scans_raise_input_error():
    cphd = _cphd()
    z, valid = _scans()
    with pytest.raises(InputError, match="`measurements`"):
        run_cphd(cphd, np.zeros((T, M_MAX, 3)), valid)
    with pytest.raises(InputError, match="`valid`"):
        run_cphd(cphd, z, valid[:, :2])
    with pytest.raises(InputError, match="`cphd`"):
        run_cphd(object(), z, valid)
