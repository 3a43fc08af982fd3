"""A brute-force δ-GLMB / LMB oracle for tests/test_glmb.py, written from the papers' equations
with Python lists and itertools (nothing of jaxtrack's own code), linear Gaussian models only.

δ-GLMB (Vo & Vo 2013, "Labeled random finite sets and multi-object conjugate priors", IEEE TSP
61(13); with the *separate* prediction and update of Vo, Vo & Phung 2014, "Labeled random finite
sets and the Bayes multi-target tracking filter", IEEE TSP 62(24), Sec. III):

- prediction: every prior hypothesis ``(w, I)`` and every subset ``J ⊆ I`` of survivors and every
  subset ``L`` of the birth labels gives ``(w Π_{J} P_S Π_{I∖J} (1 − P_S) Π_{L} r_B Π_{𝔹∖L}
  (1 − r_B), J ∪ L)``, survivors' Gaussians Kalman-predicted, births' as given;
- update: every predicted hypothesis and every map ``θ`` of its labels to ``{miss} ∪ {1..M}``,
  one-to-one on the measurements, gives weight ``w Π_{θ(ℓ)=miss} (1 − P_D)
  Π_{θ(ℓ)=j} P_D N(z_j; H m, H P Hᵀ + R) / κ``, the Gaussians Kalman-updated; weights normalised.
  Nothing is merged or pruned: two hypotheses that differ only in a dead track's history stay two.

LMB (Reuter, Vo, Vo & Dietmayer 2014, "The labeled multi-Bernoulli filter", IEEE TSP 62(12)):
prediction ``r ← P_S r`` plus the birth labels; the LMB written as a δ-GLMB over all subsets of
its labels (``w(I) = Π_{I} r Π_{∖I} (1 − r)``), the δ-GLMB update above, then the projection
``r_ℓ = Σ_h w_h 1[ℓ ∈ I_h]``, the label's mixture collapsed by moment matching.

Labels: birth component ``b`` of scan ``k`` is ``k·B + b`` (jaxtrack's documented convention).
A hypothesis is ``(weight, ((label, mean, cov), ...))`` with its tracks sorted by label.
"""

from __future__ import annotations

import itertools
import math

import numpy as np


class LinearCase:
    """``F, Q, H, R``, ``P_S``, ``P_D``, ``κ`` and the LMB birth ``[(r_B, mean, cov)]``."""

    def __init__(self, F, Q, H, R, ps, pd, kappa, birth):
        self.F, self.Q, self.H, self.R = (np.asarray(a, float) for a in (F, Q, H, R))
        self.ps, self.pd, self.kappa = float(ps), float(pd), float(kappa)
        self.birth = [(float(r), np.asarray(m, float), np.asarray(P, float)) for r, m, P in birth]

    def predict(self, m, P):
        return self.F @ m, self.F @ P @ self.F.T + self.Q

    def update(self, m, P, z):
        S = self.H @ P @ self.H.T + self.R
        y = z - self.H @ m
        K = P @ self.H.T @ np.linalg.inv(S)
        lik = math.exp(-0.5 * y @ np.linalg.solve(S, y)) / math.sqrt(np.linalg.det(2 * np.pi * S))
        return m + K @ y, (np.eye(len(m)) - K @ self.H) @ P, lik


def _births(case, k):
    B = len(case.birth)
    out = []
    for chosen in itertools.product([False, True], repeat=B):
        w, tracks = 1.0, []
        for b, (on, (r, m, P)) in enumerate(zip(chosen, case.birth)):
            w *= r if on else 1.0 - r
            if on:
                tracks.append((k * B + b, m, P))
        out.append((w, tracks))
    return out


def glmb_predict(case, hyps, k):
    """VVP14's δ-GLMB prediction: survivors' subsets times birth subsets."""
    out = []
    for w, tracks in hyps:
        for alive in itertools.product([False, True], repeat=len(tracks)):
            ws, surv = w, []
            for on, (l, m, P) in zip(alive, tracks):
                ws *= case.ps if on else 1.0 - case.ps
                if on:
                    surv.append((l,) + case.predict(m, P))
            for wb, born in _births(case, k):
                if ws * wb > 0.0:
                    out.append((ws * wb, surv + born))
    return out


def association_maps(num_tracks, num_measurements):
    """Every map of ``num_tracks`` tracks to ``None`` (missed) or a measurement index, one-to-one
    on the measurements."""
    for theta in itertools.product([None] + list(range(num_measurements)), repeat=num_tracks):
        used = [j for j in theta if j is not None]
        if len(used) == len(set(used)):
            yield theta


def glmb_update(case, hyps, zs):
    """VV13's δ-GLMB update: every association map, normalised. **Returns** the hypotheses."""
    out = []
    for w, tracks in hyps:
        for theta in association_maps(len(tracks), len(zs)):
            wu, new = w, []
            for (l, m, P), j in zip(tracks, theta):
                if j is None:
                    wu *= 1.0 - case.pd
                    new.append((l, m, P))
                else:
                    mu, Pu, lik = case.update(m, P, np.asarray(zs[j], float))
                    wu *= case.pd * lik / case.kappa
                    new.append((l, mu, Pu))
            if wu > 0.0:
                out.append((wu, tuple(sorted(new, key=lambda t: t[0]))))
    total = sum(w for w, _ in out)
    return [(w / total, t) for w, t in out]


def glmb_run(case, scans, prior=None, first_step=0):
    """The exact δ-GLMB after each scan (a list of hypothesis lists). ``prior``: hypotheses
    ``[(w, [(label, m, P)])]`` (default: the empty set, weight 1); scan ``i`` has index
    ``first_step + i`` (the birth labels)."""
    hyps = [(1.0, [])] if prior is None else [(w, list(t)) for w, t in prior]
    out = []
    for i, zs in enumerate(scans):
        hyps = glmb_update(case, glmb_predict(case, hyps, first_step + i), zs)
        out.append(hyps)
        hyps = [(w, list(t)) for w, t in hyps]
    return out


def existence(hyps):
    """``{label: Σ_h w_h 1[label ∈ I_h]}``."""
    r = {}
    for w, tracks in hyps:
        for l, _, _ in tracks:
            r[l] = r.get(l, 0.0) + w
    return r


def project(hyps):
    """R14's projection: ``{label: (r, mean, cov)}``."""
    out = {}
    for l, r in existence(hyps).items():
        parts = [(w, m, P) for w, tracks in hyps for (ll, m, P) in tracks if ll == l]
        mean = sum(w * m for w, m, _ in parts) / r
        cov = sum(w * (P + np.outer(m - mean, m - mean)) for w, m, P in parts) / r
        out[l] = (r, mean, cov)
    return out


def lmb_run(case, scans, first_step=0):
    """The LMB filter without truncation: ``{label: (r, m, P)}`` after each scan."""
    lmb = {}
    out = []
    for i, zs in enumerate(scans):
        k = first_step + i
        pred = {l: (case.ps * r,) + case.predict(m, P) for l, (r, m, P) in lmb.items()}
        B = len(case.birth)
        for b, (r, m, P) in enumerate(case.birth):
            pred[k * B + b] = (r, m, P)
        labels = [l for l in sorted(pred) if pred[l][0] > 0.0]
        hyps = []
        for chosen in itertools.product([False, True], repeat=len(labels)):
            w, tracks = 1.0, []
            for on, l in zip(chosen, labels):
                r, m, P = pred[l]
                w *= r if on else 1.0 - r
                if on:
                    tracks.append((l, m, P))
            if w > 0.0:
                hyps.append((w, tracks))
        lmb = project(glmb_update(case, hyps, zs))
        out.append(lmb)
    return out


def gm_lmb_run(case, scans, first_step=0):
    """The LMB filter whose labels keep their whole Gaussian mixture (R14's GM implementation
    without pruning, merging or a cap): ``{label: (r, [(w, m, P)])}`` after each scan, the
    component weights of a label summing to 1. The δ-GLMB update of a mixture track on ``z``:
    likelihood ``Σ_c w_c N(z; H m_c, H P_c Hᵀ + R)``, components Kalman-updated with weights
    ``∝ w_c N(z; ...)``; missed: the mixture as predicted."""
    lmb = {}
    out = []
    for i, zs in enumerate(scans):
        k = first_step + i
        pred = {l: (case.ps * r, [(w,) + case.predict(m, P) for w, m, P in comps]) for l, (r, comps) in lmb.items()}
        B = len(case.birth)
        for b, (r, m, P) in enumerate(case.birth):
            pred[k * B + b] = (r, [(1.0, m, P)])
        labels = [l for l in sorted(pred) if pred[l][0] > 0.0]
        post = {}  # label -> list of (weight, comps) over hypotheses and associations
        total = 0.0
        for chosen in itertools.product([False, True], repeat=len(labels)):
            w0 = 1.0
            on = [l for c, l in zip(chosen, labels) if c]
            for c, l in zip(chosen, labels):
                w0 *= pred[l][0] if c else 1.0 - pred[l][0]
            if w0 == 0.0:
                continue
            for theta in association_maps(len(on), len(zs)):
                wu, tracks = w0, []
                for l, j in zip(on, theta):
                    comps = pred[l][1]
                    if j is None:
                        wu *= 1.0 - case.pd
                        tracks.append((l, comps))
                    else:
                        upd = [case.update(m, P, np.asarray(zs[j], float)) for _, m, P in comps]
                        lik = sum(w * u[2] for (w, _, _), u in zip(comps, upd))
                        wu *= case.pd * lik / case.kappa
                        tracks.append((l, [(w * u[2] / lik, u[0], u[1]) for (w, _, _), u in zip(comps, upd)]))
                total += wu
                for l, comps in tracks:
                    post.setdefault(l, []).append((wu, comps))
        lmb = {}
        for l, parts in post.items():
            r = sum(w for w, _ in parts) / total
            lmb[l] = (r, [(w * wc / total / r, m, P) for w, comps in parts for wc, m, P in comps])
        out.append(lmb)
    return out
