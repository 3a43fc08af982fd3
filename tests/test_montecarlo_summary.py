"""The Monte Carlo result names its estimator, and ``summary()`` says it in words (issue 37).

Without ``filter_model=`` the filter runs the truth's own model (a matched, best-case filter);
the result must record that (``filter_model_source == "truth"``) and the summary must say it.
Oracle: the arguments of each call (which filter, which model, whether ``filter_model`` was
passed), and the result's own arrays for the numbers the summary prints.
"""

from __future__ import annotations

import json

import jax
import numpy as np
import pytest

from jaxtrack.filters import ExtendedKalmanFilter, InteractingMultipleModel, KalmanFilter
from jaxtrack.models import constant_velocity
from jaxtrack.montecarlo import MonteCarloResult, differentiable_monte_carlo, monte_carlo, monte_carlo_sweep

RUNS, STEPS = 20, 10
ESTIMATOR_FIELDS = ("filter_name", "filter_model_name", "filter_model_source")
MATCHED_WORDS = "the truth's own model"


def _cv(accel_psd):
    """1-D constant velocity, τ = 1 s, σ = 2 m: 2 states, 1 measurement."""
    return constant_velocity(1.0, dim=1, accel_psd=accel_psd, measurement_std=2.0,
                             initial_mean=np.array([0.0, 1.0]), initial_cov=np.diag([25.0, 4.0]))


@pytest.fixture(scope="module")
def results():
    """One small study per way of choosing the filter's model, sharing the truth and the key."""
    truth = _cv(1.0)
    key = jax.random.key(7)
    run = lambda **kw: monte_carlo(truth, key, RUNS, num_steps=STEPS, progress=False, **kw)  # noqa: E731
    imm = InteractingMultipleModel([(KalmanFilter(), _cv(0.1)), (ExtendedKalmanFilter(), _cv(4.0))],
                                   np.array([[0.9, 0.1], [0.1, 0.9]]))
    return {
        "truth": run(),
        "given": run(filter_model=_cv(1e-3)),  # q 1000× too small: overconfident
        "imm": run(filter=imm),
    }


def test_default_filter_model_is_recorded_as_the_truth(results):
    res = results["truth"]
    assert (res.filter_name, res.filter_model_name, res.filter_model_source) == (
        "KalmanFilter", "LinearGaussianModel", "truth")
    text = res.summary()
    lines = text.splitlines()
    assert MATCHED_WORDS in lines[-1] and "best-case" in lines[-1] and "filter_model=" in lines[-1]
    assert lines[-1].startswith("Estimator: KalmanFilter on LinearGaussianModel")
    # the numbers printed are the result's own
    assert lines[0].startswith(f"Monte Carlo: {RUNS} runs (0 failed") and f"{STEPS} steps" in lines[0]
    lo, hi = (float(b) for b in res.anees_bounds)
    assert f"ANEES {float(res.anees):.4g}, 95% bounds [{lo:.4g}, {hi:.4g}]: inside" in text
    assert lo <= float(res.anees) <= hi  # the matched filter of this key is consistent
    assert f"RMSE over the 2 scored components: {float(res.rmse()[-1]):.4g}" in text
    assert 0.5 < float(res.rmse()[-1]) < 5.0  # σ = 2 m measurements, few metres of error
    assert "mode probabilities" not in text and "/" not in text  # no paths, no IMM line


def test_given_filter_model_is_recorded_as_given(results):
    res = results["given"]
    assert (res.filter_name, res.filter_model_name, res.filter_model_source) == (
        "KalmanFilter", "LinearGaussianModel", "given")
    text = res.summary()
    assert MATCHED_WORDS not in text and "best-case" not in text
    assert "Estimator: KalmanFilter on LinearGaussianModel, the filter_model given" in text
    # a process noise 1000× too small makes the filter overconfident: ANEES above its bound
    assert float(res.anees) > float(res.anees_bounds[1]) and "ABOVE the upper bound" in text


def test_imm_records_its_members(results):
    res = results["imm"]
    assert res.filter_model_source == "imm"
    assert res.filter_name == "InteractingMultipleModel(KalmanFilter, ExtendedKalmanFilter)"
    assert res.filter_model_name == "LinearGaussianModel, LinearGaussianModel"
    text = res.summary()
    assert MATCHED_WORDS not in text
    assert ("Estimator: InteractingMultipleModel(KalmanFilter, ExtendedKalmanFilter) on its members' own "
            "models: LinearGaussianModel, LinearGaussianModel.") in text
    probs = ", ".join(f"{p:.3f}" for p in np.asarray(res.mode_probs[-1]))
    assert f"Final mean mode probabilities: {probs}." in text
    np.testing.assert_allclose(np.asarray(res.mode_probs[-1]).sum(), 1.0, atol=1e-12)


def test_fields_round_trip_through_save_load_and_to_dict(results, tmp_path):
    for source, res in results.items():
        loaded = MonteCarloResult.load(res.save(tmp_path / f"{source}.npz"))
        for name in ESTIMATOR_FIELDS:
            assert getattr(loaded, name) == getattr(res, name) and isinstance(getattr(loaded, name), str), name
        assert loaded.filter_model_source == source and loaded.summary() == res.summary()
        assert json.loads(json.dumps(res.to_dict("list")))["filter_model_source"] == source


def test_file_saved_without_the_fields_still_loads(results, tmp_path):
    """A result saved before the estimator was recorded: its meta has no such keys."""
    path = results["truth"].save(tmp_path / "new.npz")
    with np.load(path) as npz:
        entries = {k: npz[k] for k in npz.files}
    meta = json.loads(str(entries["meta"]))
    entries["meta"] = np.asarray(json.dumps({k: v for k, v in meta.items() if k not in ESTIMATOR_FIELDS}))
    old = tmp_path / "old.npz"
    with open(old, "wb") as fh:
        np.savez(fh, **entries)
    loaded = MonteCarloResult.load(old)
    assert all(getattr(loaded, name) is None for name in ESTIMATOR_FIELDS)
    np.testing.assert_array_equal(np.asarray(loaded.mse), np.asarray(results["truth"].mse))
    text = loaded.summary()
    assert text.splitlines()[-1].startswith("Estimator: not recorded") and MATCHED_WORDS not in text


def test_sweep_and_differentiable_paths_record_the_estimator():
    """monte_carlo_sweep per value, and differentiable_monte_carlo under jit (static strings)."""
    fm = _cv(0.5)
    swept = monte_carlo_sweep(lambda q: (_cv(q), fm) if q > 1.0 else _cv(q), [2.0], jax.random.key(1), 8,
                              num_steps=4, progress=False)
    assert [r.filter_model_source for r in swept] == ["given"]
    truth_only = monte_carlo_sweep(_cv, [1.0], jax.random.key(1), 8, num_steps=4, progress=False)
    assert truth_only[0].filter_model_source == "truth" and MATCHED_WORDS in truth_only[0].summary()

    @jax.jit
    def study(q):
        return differentiable_monte_carlo(_cv(1.0), jax.random.key(1), 8, num_steps=4, filter_model=_cv(q))

    res = study(0.5)
    assert (res.filter_name, res.filter_model_name, res.filter_model_source) == (
        "KalmanFilter", "LinearGaussianModel", "given")


def _per_run(filter, model, truth, key):
    """Each run's error, NEES, NIS, its degrees of freedom and mode probabilities, by run_filter /
    run_imm on simulate's runs (run i from fold_in(key, i)), kept whole by monte_carlo_map."""
    from jaxtrack.filters import run_filter, run_imm
    from jaxtrack.montecarlo import monte_carlo_map, normalized_squared_error, simulate

    def one(k, _):
        run = simulate(truth, k, STEPS)
        if model is None:
            res = run_imm(filter, run.measurements)
            zero = jax.numpy.zeros(STEPS)
            nis, dof, modes = zero, zero, res.mode_probs
        else:
            res = run_filter(filter, model, run.measurements)
            nis = jax.vmap(normalized_squared_error)(res.innovation, res.innovation_cov)
            dof, modes = res.num_observed.astype(nis.dtype), jax.numpy.zeros((STEPS, 0))
        error = run.states - res.filtered_mean
        return error, jax.vmap(normalized_squared_error)(error, res.filtered_cov), nis, dof, modes

    return monte_carlo_map(one, key, RUNS, reduce="stack")


@pytest.mark.parametrize("case", ["given", "imm"])
def test_summarize_runs_equals_the_streamed_monte_carlo(results, case):
    """summarize_runs of per-run statistics (one pass of monte_carlo_map, as the maneuvering study
    uses it) = monte_carlo's streamed result on the same runs: every field to 1e-12."""
    from jaxtrack.montecarlo import summarize_runs

    truth, key = _cv(1.0), jax.random.key(7)
    imm = InteractingMultipleModel([(KalmanFilter(), _cv(0.1)), (ExtendedKalmanFilter(), _cv(4.0))],
                                   np.array([[0.9, 0.1], [0.1, 0.9]]))
    flt, model = (KalmanFilter(), _cv(1e-3)) if case == "given" else (imm, None)
    error, nees, nis, dof, modes = _per_run(flt, model, truth, key)
    got = summarize_runs(error, nees, nis=nis, nis_dof=dof, mode_probs=modes if case == "imm" else None, key=key,
                         filter=flt, filter_model=model)
    ref = results[case]
    for f in ("mse", "mean_error", "nees", "nees_std", "nees_bounds", "nis", "nis_dof", "nis_bounds", "anees",
              "anees_bounds", "key"):
        np.testing.assert_allclose(np.asarray(getattr(got, f)), np.asarray(getattr(ref, f)), rtol=1e-12, atol=1e-12,
                                   err_msg=f)
    if case == "imm":
        np.testing.assert_allclose(got.mode_probs, ref.mode_probs, rtol=1e-12)
    assert (got.num_runs, got.num_failed) == (ref.num_runs, 0)
    assert [getattr(got, f) for f in ESTIMATOR_FIELDS] == [getattr(ref, f) for f in ESTIMATOR_FIELDS]
    # A non-finite run is left out and counted, with monte_carlo's warning.
    bad_error = np.array(error)
    bad_error[3, 4, 0] = np.nan
    with pytest.warns(RuntimeWarning, match="1 of 20 runs"):
        bad = summarize_runs(bad_error, nees, nis=nis, nis_dof=dof)
    assert (bad.num_runs, bad.num_failed) == (RUNS - 1, 1)
    with pytest.raises(Exception, match="`nees`"):
        summarize_runs(error, nees[:, :-1])
