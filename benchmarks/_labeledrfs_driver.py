"""Driver of the labeledRFS Python port (linh-gist/labeledRFS, MIT) for benchmarks/labelled_reference.py.

Runs under the reference's own interpreter (numpy < 2; imports numpy, scipy and the port's own
modules only, never jaxtrack) from the port's own checkout (``--labeledrfs DIR``): its δ-GLMB
(``jointglmb_gms_python``, the port of Vo & Vo's MATLAB ``jointglmb/gms``) and its LMB
(``jointlmb_gms_python``) on exactly the measurement sets of ``--input`` (an .npz written by
labelled_reference.py), with the scenario's model numbers written over the port's ``gen_model``
(converted from jaxtrack's state ``[x, y, vx, vy]`` to the port's ``[x, vx, y, vy]``). Nothing of
the port is copied here; its files are not edited. At run time the driver

- sets ``np.int = int``, ``np.float = float`` (the port uses the aliases numpy removed);
- stubs the modules ``cv2`` (display only), ``murty`` (a C++ package, not installable) and
  ``gibbs`` (the LMB folder's compiled Gibbs sampler) and points both filters' assignment
  generator at the port's own Python Gibbs sampler ``utils.gibbswrap_jointpredupdt_custom`` (the
  sampler of Vo's MATLAB ``jointglmb``/``jointlmb``): ``run_filter.murty`` (δ-GLMB) and
  ``run_filter.gibbs_jointpredupdt`` (LMB);
- sets ``filter.run_flag = 'silence'`` and seeds ``np.random`` with ``--seed + run`` before each
  run's filter (the sampler draws from ``np.random``); every other filter setting keeps the port's
  default;
- records each scan's estimate as the scan is processed (``online``: what an online tracker
  reports at that scan). The port's δ-GLMB estimator rewrites the estimates of earlier scans at
  every scan (the recursive estimator of Vo's ``extract_estimates_recursive``: a track's states are
  recomputed along its latest association history), so its ``est`` after the last scan
  (``final``) is also stored for the δ-GLMB.

The port's LMB creates its births *adaptively* from the previous scan's measurements (Reuter et al.
2014, eq. 75; ``apdative_birth``), not from the fixed four-label birth of Vo's MATLAB ``jointlmb``
and of jaxtrack's LMB. ``--lmb-birth fixed`` (the default) replaces that one method, in a subclass
written here, by the scenario's fixed LMB birth (four labels, ``r_B``, means and covariance of the
scenario) so both LMBs filter the same model; ``--lmb-birth adaptive`` runs the port unchanged.

Output (``--output``, rewritten after every run, so a killed job resumes where it stopped): per
filter ``f``: ``f_done (R,)`` bool, ``f_seconds (R,)`` wall time of the run, ``f_cpu_seconds`` its process CPU time,
``f_finished_at`` when it ended (epoch s), ``f_card (R, T)``,
``f_pos (R, T, K, 2)`` estimated positions (NaN where absent); for the δ-GLMB also
``glmb_final_card`` and ``glmb_final_pos``.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import time
import types

import numpy as np

MAX_EST = 64  # estimate rows stored per scan
MODULES = ("run_filter", "utils", "gen_model", "gen_truth", "gen_meas", "plot_results")
FOLDERS = {"glmb": "jointglmb_gms_python", "lmb": "jointlmb_gms_python"}
# jaxtrack's [x, y, vx, vy] -> the port's [x, vx, y, vy]
PERM = np.array([0, 2, 1, 3])


def _shim():
    np.int = int
    np.float = float
    sys.modules.setdefault("cv2", types.ModuleType("cv2"))
    murty = types.ModuleType("murty")
    murty.Murty = None
    sys.modules.setdefault("murty", murty)
    gibbs = types.ModuleType("gibbs")
    gibbs.gibbs_jointpredupdt = None
    sys.modules.setdefault("gibbs", gibbs)


def _load(root: str, name: str):
    """The port's modules of one folder (both folders use the same module names)."""
    folder = os.path.join(root, FOLDERS[name])
    for m in MODULES:
        sys.modules.pop(m, None)
    sys.path.insert(0, folder)
    try:
        mods = {m: importlib.import_module(m) for m in ("run_filter", "utils", "gen_model")}
    finally:
        sys.path.remove(folder)
        for m in MODULES:
            sys.modules.pop(m, None)
    if name == "glmb":
        mods["run_filter"].murty = mods["utils"].gibbswrap_jointpredupdt_custom
    else:
        mods["run_filter"].gibbs_jointpredupdt = mods["utils"].gibbswrap_jointpredupdt_custom
    return mods


def _set_model(model, d):
    """Write the scenario's numbers (jaxtrack layout in ``d``) over the port's model; returns the
    rows (name, port default, value set) of the parameter table."""
    P = np.eye(4)[PERM]
    rows = []

    def put(attr, value, shown=None):
        old = getattr(model, attr)
        setattr(model, attr, value)
        rows.append((attr, old, value if shown is None else shown))

    put("F", P @ d["F"] @ P.T)
    put("Q", P @ d["Q"] @ P.T)
    put("H", d["H"] @ P.T)
    put("R", np.array(d["R"], float))
    model.D = np.linalg.cholesky(model.R)
    put("P_S", float(d["prob_survival"]))
    model.Q_S = 1 - model.P_S
    put("P_D", float(d["prob_detect"]))
    model.Q_D = 1 - model.P_D
    put("lambda_c", float(d["clutter_rate"]))
    put("range_c", np.array(d["clutter_region"], float))
    put("pdf_c", 1.0 / np.prod(model.range_c[:, 1] - model.range_c[:, 0]))
    B = d["birth_means"].shape[0]
    assert B == model.T_birth, (B, model.T_birth)
    put("r_birth", np.array(d["birth_weights"], float).reshape(B, 1))
    put("m_birth", (d["birth_means"] @ P.T).reshape(B, 4, 1))
    put("P_birth", np.einsum("ij,bjk,lk->bil", P, d["birth_covs"], P))
    model.w_birth = np.ones((B, 1))
    model.B_birth = np.stack([np.linalg.cholesky(c) for c in model.P_birth])
    return rows


def _print_table(rows):
    print("parameter | port's gen_model default | set to (the scenario's, in the port's layout [x, vx, y, vy])")
    for name, old, new in rows:
        fmt = lambda a: np.array2string(np.squeeze(np.asarray(a, float)), precision=6, max_line_width=200,
                                        separator=",").replace("\n", "")
        print(f"{name} | {fmt(old)} | {fmt(new)}")


def _positions(X, n):
    out = np.full((MAX_EST, 2), np.nan)
    X = np.asarray(X, float).reshape(4, -1)[:, :n]
    k = min(X.shape[1], MAX_EST)
    out[:k, 0] = X[0, :k]
    out[:k, 1] = X[2, :k]
    return out


class _Meas:
    def __init__(self, z, valid):
        self.K = z.shape[0]
        self.Z = {k: np.ascontiguousarray(z[k][valid[k]].T) for k in range(self.K)}


def _fixed_birth_lmb(rf):
    class FixedBirthLMB(rf.LMB):
        """The port's LMB with the fixed LMB birth of the model in place of its adaptive birth."""

        def _births(self, model, k):
            out = []
            for b in range(model.T_birth):
                t = rf.target()
                t.r = float(model.r_birth[b, 0])
                t.w = np.array([1.0])
                t.m = np.array(model.m_birth[b], float).reshape(4, 1)
                t.P = np.array(model.P_birth[b], float).reshape(4, 4, 1)
                t.l = np.array([k, b])
                out.append(t)
            return out

        def run(self, model, filter, meas, est):
            self.assign_prob = np.zeros(0)  # not None: the port then keeps self.tt_birth
            self.tt_birth = self._births(model, 0)
            return super().run(model, filter, meas, est)

        def apdative_birth(self, assign_prob, meas, model, k):  # the port's name
            self.tt_birth = self._births(model, k + 1)

    return FixedBirthLMB


def _run_glmb(mods, model, meas, store, i):
    rf = mods["run_filter"]
    T = meas.K
    online_n = np.zeros(T)
    online_x = np.full((T, MAX_EST, 2), np.nan)

    class Recording(rf.GLMB):
        def extract_estimates_recursive(self, model, meas, est):
            est = super().extract_estimates_recursive(model, meas, est)
            k = self._k
            online_n[k] = est.N[k]
            online_x[k] = _positions(est.X[k], int(est.N[k]))
            self._k += 1
            return est

    filt = rf.filter(model)
    filt.run_flag = "silence"
    est = rf.est(meas)
    g = Recording()
    g._k = 0
    t, c = time.perf_counter(), time.process_time()
    g.run(model, filt, meas, est)
    secs, cpu = time.perf_counter() - t, time.process_time() - c
    store["glmb_card"][i] = online_n
    store["glmb_pos"][i] = online_x
    store["glmb_final_card"][i] = est.N
    store["glmb_final_pos"][i] = [_positions(est.X[k], int(est.N[k])) for k in range(T)]
    return secs, cpu, filt


def _run_lmb(mods, model, meas, store, i, birth):
    rf = mods["run_filter"]
    cls = _fixed_birth_lmb(rf) if birth == "fixed" else rf.LMB
    filt = rf.filter(model)
    filt.run_flag = "silence"
    est = rf.est(meas)
    t, c = time.perf_counter(), time.process_time()
    cls().run(model, filt, meas, est)
    secs, cpu = time.perf_counter() - t, time.process_time() - c
    store["lmb_card"][i] = est.N
    store["lmb_pos"][i] = [_positions(est.X[k], int(est.N[k])) for k in range(meas.K)]
    return secs, cpu, filt


def _settings(filt):
    keys = ("H_upd", "H_max", "hyp_threshold", "T_max", "track_threshold", "L_max", "elim_threshold",
            "merge_threshold", "P_G", "gamma", "gate_flag")
    return ", ".join(f"{k}={getattr(filt, k)!r}" for k in keys if hasattr(filt, k))


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--labeledrfs", required=True, help="the labeledRFS checkout")
    p.add_argument("--input", required=True)
    p.add_argument("--output", required=True)
    p.add_argument("--runs", type=int, default=None, help="the first RUNS runs of the input (default all)")
    p.add_argument("--filters", default="glmb,lmb")
    p.add_argument("--lmb-birth", choices=("fixed", "adaptive"), default="fixed")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    _shim()
    d = dict(np.load(args.input))
    z, valid = d["z"], d["valid"]
    R_all, T = valid.shape[:2]
    runs = R_all if args.runs is None else min(args.runs, R_all)
    filters = [f for f in args.filters.split(",") if f]
    store = {}
    for f in filters:
        store[f"{f}_done"] = np.zeros(R_all, bool)
        store[f"{f}_seconds"] = np.full(R_all, np.nan)
        store[f"{f}_finished_at"] = np.full(R_all, np.nan)  # epoch seconds, to spot runs timed under load
        store[f"{f}_cpu_seconds"] = np.full(R_all, np.nan)  # process CPU time: robust to a loaded machine
        store[f"{f}_card"] = np.full((R_all, T), np.nan)
        store[f"{f}_pos"] = np.full((R_all, T, MAX_EST, 2), np.nan)
    if "glmb" in filters:
        store["glmb_final_card"] = np.full((R_all, T), np.nan)
        store["glmb_final_pos"] = np.full((R_all, T, MAX_EST, 2), np.nan)
    if os.path.exists(args.output):
        old = np.load(args.output)
        for k, v in store.items():
            if k in old.files and old[k].shape == v.shape:
                store[k] = old[k].copy()
    mods = {f: _load(args.labeledrfs, f) for f in filters}
    models = {}
    for f in filters:
        models[f] = mods[f]["gen_model"].model()
        rows = _set_model(models[f], d)
        print(f"[{f}] model", flush=True)
        _print_table(rows)
    print(f"numpy {np.__version__}, python {sys.version.split()[0]}; lmb birth: {args.lmb_birth}", flush=True)
    shown = set()
    for i in range(runs):
        meas = _Meas(z[i], valid[i])
        for f in filters:
            if store[f"{f}_done"][i]:
                continue
            np.random.seed(args.seed + i)
            if f == "glmb":
                secs, cpu, filt = _run_glmb(mods[f], models[f], meas, store, i)
            else:
                secs, cpu, filt = _run_lmb(mods[f], models[f], meas, store, i, args.lmb_birth)
            if f not in shown:
                print(f"[{f}] filter settings (the port's defaults): {_settings(filt)}", flush=True)
                shown.add(f)
            store[f"{f}_seconds"][i] = secs
            store[f"{f}_cpu_seconds"][i] = cpu
            store[f"{f}_done"][i] = True
            store[f"{f}_finished_at"][i] = time.time()
            tmp = args.output + ".tmp.npz"
            np.savez(tmp, **store)
            os.replace(tmp, args.output)
            print(f"run {i} {f}: {secs:.1f} s (CPU {cpu:.1f} s), mean cardinality {np.mean(store[f'{f}_card'][i]):.2f}", flush=True)
    for f in filters:
        done = store[f"{f}_done"]
        print(f"[{f}] runs done {int(done.sum())}/{R_all}, mean seconds a run {np.nanmean(store[f'{f}_seconds']):.2f}")


if __name__ == "__main__":
    main()
