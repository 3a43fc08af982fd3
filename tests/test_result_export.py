"""Export of MonteCarloResult (issue 23): ``to_dict``, and ``save`` then ``load`` bit for bit.

Oracle: the result itself. Every array leaf of the loaded result must have the saved bytes,
shape and dtype (``tobytes`` also tells -0.0 from 0.0 and NaN payloads apart), every static
field must be equal, and the methods must give identical values.
"""

from __future__ import annotations

import dataclasses
import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.filters import ExtendedKalmanFilter, InteractingMultipleModel
from jaxtrack.models import (
    ConstantVelocity,
    CoordinatedTurn,
    LinearGaussianModel,
    NearlyConstantTurn,
    RangeBearing,
    TrackingModel,
    constant_velocity,
)
from jaxtrack.montecarlo import MonteCarloResult, monte_carlo

ARRAY_FIELDS = ("mse", "mean_error", "nees", "nees_std", "nees_bounds", "nis", "nis_dof", "nis_bounds",
                "anees", "anees_bounds", "mode_probs", "key")
STATIC_FIELDS = ("num_runs", "num_failed", "confidence", "shared_covariance", "precision_warning", "components",
                 "key_impl", "filter_name", "filter_model_name", "filter_model_source")


@pytest.fixture(scope="module")
def cv_result():
    """2-D constant velocity, 100 runs × 20 steps, τ = 1 s, q = 1 m²/s³, σ = 5 m."""
    model = constant_velocity(1.0, dim=2, accel_psd=1.0, measurement_std=5.0,
                              initial_mean=np.array([0.0, 0.0, 10.0, -5.0]),
                              initial_cov=np.diag([100.0, 100.0, 10.0, 10.0]))
    return monte_carlo(model, jax.random.key(0), 100, num_steps=20, chunk_size=50, progress=False)


@pytest.fixture(scope="module")
def imm_result():
    """An IMM (CV + nearly-constant-turn EKFs) on a turning target, scored on 4 of 5 states:
    mode_probs (T, 2) and components (0, 1, 2, 3) are set."""
    T, tau = 30, 1.0
    x0, p0 = np.array([2000.0, 1000.0, -15.0, 10.0]), np.diag([400.0, 400.0, 25.0, 25.0])
    sensor = RangeBearing(np.array([10.0, 0.004]))
    omega = np.where((np.arange(T) >= 10) & (np.arange(T) < 20), 0.06, 0.0)
    truth = TrackingModel(CoordinatedTurn(tau, turn_rate=omega, noise_intensity=0.05), sensor, x0, p0)
    x5, p5 = np.append(x0, 0.0), np.diag(np.append(np.diag(p0), 0.01))
    members = [
        (ExtendedKalmanFilter(), TrackingModel(ConstantVelocity(tau, noise_intensity=0.05), sensor, x0, p0)),
        (ExtendedKalmanFilter(), TrackingModel(NearlyConstantTurn(tau, noise_intensity=0.05,
                                                                  turn_rate_intensity=1e-4), sensor, x5, p5)),
    ]
    imm = InteractingMultipleModel(members, np.array([[0.9, 0.1], [0.1, 0.9]]))
    return monte_carlo(truth, jax.random.key(3), 8, filter=imm, filter_components=(0, 1, 2, 3), progress=False)


@pytest.fixture(scope="module")
def f32_result():
    """A float32 result (the statistics accumulated in float32): 1-D CV, 64 runs × 25 steps."""
    f32 = lambda a: jnp.asarray(a, jnp.float32)  # noqa: E731
    model = LinearGaussianModel(f32([[1.0, 1.0], [0.0, 1.0]]), f32([[1 / 3, 1 / 2], [1 / 2, 1.0]]),
                                f32([[1.0, 0.0]]), f32([[4.0]]), f32([0.0, 1.0]), f32(np.diag([10.0, 1.0])))
    return monte_carlo(model, jax.random.key(2), 64, num_steps=25, progress=False)


def _assert_identical(a: MonteCarloResult, b: MonteCarloResult):
    """Every leaf equal bit for bit (bytes, shape, dtype), static fields equal, methods equal."""
    assert type(b) is MonteCarloResult
    for f in dataclasses.fields(MonteCarloResult):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if f.metadata.get("static", False):
            assert x == y and type(x) is type(y), (f.name, x, y)
        elif x is None:
            assert y is None, f.name
        else:
            assert isinstance(y, jax.Array), f.name  # jnp arrays out, as the fields were
            x, y = np.asarray(x), np.asarray(y)
            assert x.dtype == y.dtype and x.shape == y.shape, f.name
            assert np.array_equal(x, y, equal_nan=True) and x.tobytes() == y.tobytes(), f.name
    if not any(np.isnan(np.asarray(x)).any() for x in jax.tree_util.tree_leaves(a)):  # NaN != NaN
        assert bool(eqx.tree_equal(a, b))
    assert np.asarray(a.rmse()).tobytes() == np.asarray(b.rmse()).tobytes()
    assert np.asarray(a.rmse((0, 1))).tobytes() == np.asarray(b.rmse((0, 1))).tobytes()
    assert float(a.fraction_nees_inside()) == float(b.fraction_nees_inside())


def test_fields_are_the_ones_exported():
    """The field lists above are MonteCarloResult's: a new field makes this test list it."""
    fields = dataclasses.fields(MonteCarloResult)
    assert {f.name for f in fields if not f.metadata.get("static", False)} == set(ARRAY_FIELDS)
    assert {f.name for f in fields if f.metadata.get("static", False)} == set(STATIC_FIELDS)


def test_save_load_cv_bit_for_bit(cv_result, tmp_path):
    res = cv_result
    assert res.mse.shape == (20, 4) and res.nees.dtype == jnp.float64 and res.mode_probs is None
    assert res.num_runs == 100 and res.components is None and res.shared_covariance  # KF: shared path
    path = tmp_path / "cv_result.npz"
    assert res.save(path) == path
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cv_result.npz"]  # no temporary left behind
    loaded = MonteCarloResult.load(path)
    _assert_identical(res, loaded)
    # the position RMSE at the last step is a real number of metres (σ = 5 m measurements)
    assert 1.0 < float(loaded.rmse((0, 1))[-1]) < 10.0


def test_save_load_imm_bit_for_bit(imm_result, tmp_path):
    res = imm_result
    assert res.mode_probs.shape == (30, 2) and res.components == (0, 1, 2, 3) and not res.shared_covariance
    path = tmp_path / "imm"  # no suffix: written exactly there, nothing appended
    res.save(str(path))
    assert path.exists() and not (tmp_path / "imm.npz").exists()
    loaded = MonteCarloResult.load(str(path))
    _assert_identical(res, loaded)
    assert loaded.components == (0, 1, 2, 3) and isinstance(loaded.components, tuple)
    np.testing.assert_allclose(np.asarray(loaded.mode_probs).sum(axis=1), 1.0, atol=1e-12)


def test_save_load_float32_bit_for_bit(f32_result, tmp_path):
    res = f32_result
    assert res.nees.dtype == jnp.float32 and res.mse.dtype == jnp.float32
    res.save(tmp_path / "f32.npz")
    loaded = MonteCarloResult.load(tmp_path / "f32.npz")
    _assert_identical(res, loaded)
    assert loaded.nees.dtype == jnp.float32  # not widened to float64 on the way back


def test_flags_and_odd_values_round_trip(cv_result, tmp_path):
    """Flags set both ways, a non-default confidence, -0.0, NaN and inf in leaves survive."""
    mse = np.asarray(cv_result.mse).copy()
    mse[0, 0], mse[1, 1], mse[2, 2] = -0.0, np.nan, np.inf
    odd = dataclasses.replace(cv_result, mse=jnp.asarray(mse), shared_covariance=False, precision_warning=True,
                              confidence=0.99, num_failed=3, components=(1, 0))
    odd.save(tmp_path / "odd.npz")
    loaded = MonteCarloResult.load(tmp_path / "odd.npz")
    _assert_identical(odd, loaded)
    assert np.signbit(np.asarray(loaded.mse)[0, 0]) and loaded.precision_warning and loaded.confidence == 0.99


def test_file_is_plain_npz_with_json_meta(imm_result, tmp_path):
    """Readable without jaxtrack and without pickle: arrays by field name, meta a JSON string."""
    imm_result.save(tmp_path / "r.npz")
    with np.load(tmp_path / "r.npz", allow_pickle=False) as npz:
        assert set(npz.files) == set(ARRAY_FIELDS) | {"meta"}
        meta = json.loads(str(npz["meta"]))
        np.testing.assert_array_equal(npz["mode_probs"], imm_result.mode_probs)
    assert meta == {"format_version": 1, "kind": "jaxtrack.MonteCarloResult", "num_runs": 8, "num_failed": 0,
                    "confidence": 0.95, "shared_covariance": False, "precision_warning": False,
                    "components": [0, 1, 2, 3], "key_impl": "threefry2x32",
                    "filter_name": "InteractingMultipleModel(ExtendedKalmanFilter, ExtendedKalmanFilter)",
                    "filter_model_name": "TrackingModel(ConstantVelocity, RangeBearing), "
                                         "TrackingModel(NearlyConstantTurn, RangeBearing)",
                    "filter_model_source": "imm"}
    # the study's key travels with the result: wrap it back and it is the key the fixture used
    key = jax.random.wrap_key_data(npz_key := np.load(tmp_path / "r.npz")["key"], impl=meta["key_impl"])
    assert npz_key.dtype == np.uint32
    np.testing.assert_array_equal(jax.random.key_data(key), jax.random.key_data(jax.random.key(3)))


@pytest.mark.parametrize("fixture", ["cv_result", "imm_result", "f32_result"])
def test_to_dict_numpy_and_json(fixture, request):
    res = request.getfixturevalue(fixture)
    d = res.to_dict()
    assert set(d) == set(ARRAY_FIELDS) | set(STATIC_FIELDS) | {"format_version", "kind"}
    assert d["format_version"] == 1 and d["num_runs"] == res.num_runs and d["confidence"] == res.confidence
    for name in ARRAY_FIELDS:
        value = getattr(res, name)
        if value is None:
            assert d[name] is None
        else:
            assert isinstance(d[name], np.ndarray) and d[name].dtype == value.dtype
            assert d[name].tobytes() == np.asarray(value).tobytes()
    # "list": JSON-serialisable; the numbers come back exactly (shortest repr round-trips).
    text = json.dumps(res.to_dict(arrays="list"))
    back = json.loads(text)
    for name in ARRAY_FIELDS:
        value = getattr(res, name)
        if value is None:
            assert back[name] is None
        else:
            arr = np.asarray(back[name], dtype=value.dtype)
            assert arr.shape == value.shape and arr.tobytes() == np.asarray(value).tobytes(), name
    assert back["components"] == (None if res.components is None else list(res.components))


def test_to_dict_bad_arrays_names_the_argument(cv_result):
    with pytest.raises(InputError, match="`arrays`"):
        cv_result.to_dict(arrays="pandas")


def _rewrite(src, dst, *, meta=None, drop=(), add=None):
    """Copy a saved file with its meta replaced / entries dropped or added."""
    with np.load(src) as npz:
        entries = {k: npz[k] for k in npz.files if k not in drop}
    if meta is not None:
        entries["meta"] = np.asarray(json.dumps(meta))
    entries.update(add or {})
    with open(dst, "wb") as fh:
        np.savez(fh, **entries)
    return dst


def test_load_refuses_wrong_files_naming_path(cv_result, tmp_path):
    good = cv_result.save(tmp_path / "good.npz")
    with np.load(good) as npz:
        meta = json.loads(str(npz["meta"]))
    text = tmp_path / "notes.txt"
    text.write_text("not an archive\n")
    npy = tmp_path / "a.npy"
    np.save(npy, np.zeros(3))
    zipped_garbage = tmp_path / "broken.npz"
    zipped_garbage.write_bytes(b"PK\x03\x04" + b"\x00" * 40)
    cases = {
        text: "cannot be read",
        npy: "one array",
        zipped_garbage: "cannot be read|entry",
        _rewrite(good, tmp_path / "nometa.npz", drop=("meta",)): "no `meta`",
        _rewrite(good, tmp_path / "v2.npz", meta={**meta, "format_version": 2}): "format_version 2",
        _rewrite(good, tmp_path / "v0.npz", meta={k: v for k, v in meta.items() if k != "format_version"}):
            "format_version None",
        _rewrite(good, tmp_path / "kind.npz", meta={**meta, "kind": "jaxtrack.FilterResult"}): "kind",
        _rewrite(good, tmp_path / "nomse.npz", drop=("mse",)): "`mse` is missing",
        _rewrite(good, tmp_path / "extra.npz", add={"rmse": np.zeros(20)}): "unknown fields",
        _rewrite(good, tmp_path / "noruns.npz", meta={k: v for k, v in meta.items() if k != "num_runs"}):
            "num_runs` is missing",
    }
    for path, why in cases.items():
        with pytest.raises(InputError, match=why) as info:
            MonteCarloResult.load(path)
        assert "`path`" in str(info.value) and str(path) in str(info.value), str(info.value)
    bad_json = _rewrite(good, tmp_path / "badjson.npz", add={"meta": np.asarray("{not json")})
    with pytest.raises(InputError, match="not JSON"):
        MonteCarloResult.load(bad_json)
    with pytest.raises(FileNotFoundError):
        MonteCarloResult.load(tmp_path / "missing.npz")


def test_load_refuses_arrays_of_different_lengths(cv_result, imm_result, tmp_path):
    """Issue 37, cause 5: a file whose per-step arrays disagree in length loaded without a word."""
    good = cv_result.save(tmp_path / "good.npz")
    with np.load(good) as npz:
        mse, nis = npz["mse"], npz["nis"]
    cases = {
        _rewrite(good, tmp_path / "short.npz", add={"mse": mse[:-1]}): "axis `time`: `mse` has 19, `mean_error` has 20",
        _rewrite(good, tmp_path / "long.npz", add={"nis": np.append(nis, 1.0)}): "length of axis `time`",
        _rewrite(good, tmp_path / "state.npz", add={"mse": mse[:, :3]}): "length of axis `component`: `mse` has 3, `mean_error` has 4",
    }
    for path, why in cases.items():
        with pytest.raises(InputError, match=why) as info:
            MonteCarloResult.load(path)
        assert "`path`" in str(info.value), str(info.value)
    # A consistent file of another shape (the IMM's, with mode probabilities) still loads.
    _assert_identical(imm_result, MonteCarloResult.load(imm_result.save(tmp_path / "imm.npz")))
