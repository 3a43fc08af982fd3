"""Export of the filter results (issue 23): FilterResult, SmootherResult, IMMResult and
MonteCarloResult through ``to_dict``, ``save``/``load`` (bit for bit), ``to_xarray`` and ``to_pandas``.

Oracle: the result itself. A loaded result must have every leaf with the saved bytes, shape and
dtype and the same pytree structure (None fields stay None, tuples stay tuples, nested results
stay nested); the labelled exports must hold the same numbers under the documented names.
"""

from __future__ import annotations

import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.filters import (
    ExtendedKalmanFilter,
    FilterResult,
    IMMResult,
    InteractingMultipleModel,
    KalmanFilter,
    SmootherResult,
    SquareRootKalmanFilter,
    rts_smoother,
    run_filter,
    run_imm,
)
from jaxtrack.models import (
    ConstantVelocity,
    NearlyConstantTurn,
    RangeBearing,
    TrackingModel,
    constant_velocity,
)
from jaxtrack.montecarlo import MonteCarloResult, monte_carlo, simulate

xr = pytest.importorskip("xarray")
pd = pytest.importorskip("pandas")

T = 12


@pytest.fixture(scope="module")
def cv():
    model = constant_velocity(1.0, dim=2, accel_psd=0.5, measurement_std=3.0,
                              initial_mean=np.array([0.0, 0.0, 5.0, -2.0]),
                              initial_cov=np.diag([50.0, 50.0, 4.0, 4.0]))
    sim = simulate(model, jax.random.key(7), T)
    mask = np.ones((T, 2), bool)
    mask[4] = False  # one missed detection: innovation 0, identity rows in S
    return model, sim.measurements, mask


def _assert_identical(a, b):
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    assert ta == tb, (ta, tb)
    for x, y in zip(la, lb):
        x, y = np.asarray(x), np.asarray(y)
        assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes()


def test_filter_result_roundtrip_bit_for_bit(cv, tmp_path):
    model, z, mask = cv
    res = run_filter(KalmanFilter(), model, z, mask=mask)
    loaded = FilterResult.load(res.save(tmp_path / "kf.npz"))
    _assert_identical(res, loaded)
    assert loaded.filtered_cov_factor is None and bool(loaded.ok)


def test_filter_result_final_only_and_square_root(cv, tmp_path):
    model, z, mask = cv
    final = run_filter(KalmanFilter(), model, z, mask=mask, save="final")
    assert final.filtered_mean is None
    _assert_identical(final, FilterResult.load(final.save(tmp_path / "final.npz")))
    sr = run_filter(SquareRootKalmanFilter(), model, z, mask=mask)
    assert sr.filtered_cov_factor is not None
    _assert_identical(sr, FilterResult.load(sr.save(tmp_path / "sr.npz")))


def test_smoother_result_nested_roundtrip(cv, tmp_path):
    model, z, mask = cv
    sm = rts_smoother(model, z, mask=mask)
    path = sm.save(tmp_path / "rts.npz")
    with np.load(path, allow_pickle=False) as npz:
        assert "filtered/filtered_mean" in npz.files and "smoothed_mean" in npz.files
        meta = json.loads(str(npz["meta"]))
    assert meta["kind"] == "jaxtrack.SmootherResult" and meta["nested"]["filtered"]["kind"] == "jaxtrack.FilterResult"
    _assert_identical(sm, SmootherResult.load(path))
    d = sm.to_dict()
    assert d["filtered"]["kind"] == "jaxtrack.FilterResult"
    np.testing.assert_array_equal(d["filtered"]["filtered_mean"], sm.filtered.filtered_mean)


@pytest.fixture(scope="module")
def imm_result():
    tau = 1.0
    x0, p0 = np.array([2000.0, 1000.0, -15.0, 10.0]), np.diag([400.0, 400.0, 25.0, 25.0])
    sensor = RangeBearing(np.array([10.0, 0.004]))
    truth = TrackingModel(ConstantVelocity(tau, noise_intensity=0.05), sensor, x0, p0)
    x5, p5 = np.append(x0, 0.0), np.diag(np.append(np.diag(p0), 0.01))
    members = [
        (ExtendedKalmanFilter(), truth),
        (ExtendedKalmanFilter(), TrackingModel(NearlyConstantTurn(tau, noise_intensity=0.05,
                                                                  turn_rate_intensity=1e-4), sensor, x5, p5)),
    ]
    imm = InteractingMultipleModel(members, np.array([[0.9, 0.1], [0.1, 0.9]]))
    z = simulate(truth, jax.random.key(1), T).measurements
    return run_imm(imm, z)


def test_imm_result_tuples_roundtrip_and_labels(imm_result, tmp_path):
    loaded = IMMResult.load(imm_result.save(tmp_path / "imm.npz"))
    _assert_identical(imm_result, loaded)
    assert isinstance(loaded.member_means, tuple) and loaded.member_means[1].shape == (T, 5)
    ds = imm_result.to_xarray()
    # members of different state size get their own dimension names
    assert ds["member_means.0"].dims == ("time", "state_0") and ds.sizes["state_0"] == 4
    assert ds["member_means.1"].dims == ("time", "state_1") and ds.sizes["state_1"] == 5
    assert ds["mode_probs"].dims == ("time", "mode") and ds["mode_probs"].attrs["units"] == "probability"


def test_imm_old_result_names_work_for_one_release(imm_result, tmp_path):
    """`IMMResult.mean`/`.cov` were renamed `filtered_mean`/`filtered_cov` (one naming of results):
    the old names still read, with a DeprecationWarning saying what to write, and a file saved
    with the old names loads under the new ones."""
    for old, new in (("mean", "filtered_mean"), ("cov", "filtered_cov")):
        with pytest.warns(DeprecationWarning, match=rf"`IMMResult\.{old}` is deprecated: use `\.{new}`"):
            value = getattr(imm_result, old)
        np.testing.assert_array_equal(value, getattr(imm_result, new))
    one = TrackingModel(ConstantVelocity(1.0, noise_intensity=0.05), RangeBearing(np.array([10.0, 0.004])),
                        np.ones(4), np.eye(4))
    imm = InteractingMultipleModel([(ExtendedKalmanFilter(), one)], np.eye(1))
    state, out = imm.step(imm.init(), jnp.array([100.0, 0.3]))
    with pytest.warns(DeprecationWarning, match="IMMStepOutput.mean"):
        np.testing.assert_array_equal(out.mean, out.filtered_mean)
    # a file written before the rename: the same arrays under `mean` and `cov`
    path = imm_result.save(tmp_path / "new.npz")
    with np.load(path) as npz:
        entries = {("mean" if k == "filtered_mean" else "cov" if k == "filtered_cov" else k): npz[k] for k in npz.files}
    np.savez(tmp_path / "old.npz", **entries)
    _assert_identical(imm_result, IMMResult.load(tmp_path / "old.npz"))


def test_wrong_kind_is_refused_naming_path(cv, tmp_path):
    model, z, mask = cv
    path = run_filter(KalmanFilter(), model, z).save(tmp_path / "kf.npz")
    with pytest.raises(InputError, match=r"`path` .*kf.npz.* not a saved SmootherResult.*jaxtrack.FilterResult"):
        SmootherResult.load(path)
    with pytest.raises(InputError, match="not a saved MonteCarloResult"):
        MonteCarloResult.load(path)


def test_filter_result_to_xarray_and_pandas(cv):
    model, z, mask = cv
    res = run_filter(KalmanFilter(), model, z, mask=mask)
    ds = res.to_xarray()
    assert ds["filtered_cov"].dims == ("time", "state", "state_col")
    assert ds.sizes == {"time": T, "state": 4, "state_col": 4, "measurement": 2, "measurement_col": 2}
    np.testing.assert_array_equal(ds["filtered_mean"].values, np.asarray(res.filtered_mean))
    assert ds["innovation_cov"].attrs["units"] == "measurement units squared"
    assert ds.attrs["kind"] == "jaxtrack.FilterResult"
    df = res.to_pandas()
    assert df.shape[0] == T and df.index.name == "time"
    np.testing.assert_array_equal(df["filtered_mean[2]"].to_numpy(), np.asarray(res.filtered_mean)[:, 2])
    np.testing.assert_array_equal(df["filtered_cov[0,1]"].to_numpy(), np.asarray(res.filtered_cov)[:, 0, 1])
    assert df["num_observed"].to_numpy()[4] == 0 and df["num_observed"].to_numpy()[3] == 2
    # quantities without a time axis go to attrs
    assert df.attrs["log_likelihood"] == pytest.approx(float(res.log_likelihood), rel=0, abs=0)
    assert df.attrs["units"]["filtered_mean[0]"] == "state units"


def test_batch_of_results(cv):
    model, z, _ = cv
    batch = jax.vmap(lambda zz: run_filter(KalmanFilter(), model, zz, throw=False))(jnp.stack([z, z + 1.0, z - 1.0]))
    ds = batch.to_xarray()
    assert ds["filtered_mean"].dims == ("batch_0", "time", "state") and ds.sizes["batch_0"] == 3
    with pytest.raises(InputError, match="batch axes"):
        batch.to_pandas()
    one = jax.tree_util.tree_map(lambda a: a[1], batch)
    assert one.to_pandas().shape[0] == T


def test_monte_carlo_result_labelled_exports(cv):
    model, _, _ = cv
    res = monte_carlo(model, jax.random.key(5), 40, num_steps=T, progress=False)
    ds = res.to_xarray()
    assert ds["mse"].dims == ("time", "component") and ds["nees_bounds"].dims == ("time", "bound")
    assert ds.attrs["num_runs"] == 40 and ds.attrs["key_impl"] == "threefry2x32"
    np.testing.assert_array_equal(ds["key"].values, np.asarray(jax.random.key_data(jax.random.key(5))))
    df = res.to_pandas()
    assert list(df.index) == list(range(T))
    np.testing.assert_array_equal(df["nees"].to_numpy(), np.asarray(res.nees))
    np.testing.assert_array_equal(df["nees_bounds[1]"].to_numpy(), np.asarray(res.nees_bounds)[:, 1])
    assert df.attrs["anees"] == float(res.anees) and df.attrs["confidence"] == 0.95
    # the JSON form carries the same numbers
    d = json.loads(json.dumps(res.to_dict("list")))
    assert d["nees"] == np.asarray(res.nees).tolist() and d["key_impl"] == "threefry2x32"


def test_raw_uint32_key_is_recorded(cv):
    model, _, _ = cv
    res = monte_carlo(model, jax.random.PRNGKey(9), 10, num_steps=4, progress=False)
    np.testing.assert_array_equal(np.asarray(res.key), np.asarray(jax.random.PRNGKey(9)))
    assert res.key.dtype == jnp.uint32


def test_eqx_module_still_a_pytree(cv):
    """The mixin adds methods only: no extra leaves, and results still pass through jit."""
    model, z, _ = cv
    res = eqx.filter_jit(lambda zz: run_filter(KalmanFilter(), model, zz))(z)
    assert len(jax.tree_util.tree_leaves(res)) == 11
