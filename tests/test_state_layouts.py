"""State layouts (jaxtrack.models._layout): declared by the motion models, checked for sensors,
and the IMM's embedding of members of different layouts derived from them (issue 37, cause 2).

Before layouts, a 3-D radar on a 2-D state read ``vx`` as height, and an IMM of a 2-D and a 3-D
constant-velocity member put the 2-D member's ``vx`` into the 3-D member's ``z`` (the prefix
rule, documented but never checked): both ran with ``ok=True``.
"""

from __future__ import annotations

import itertools

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxtrack import InputError
from jaxtrack.filters import ExtendedKalmanFilter, InteractingMultipleModel, imm_smoother, run_imm
from jaxtrack.models import (
    BlockTransition,
    ConstantAcceleration,
    ConstantVelocity,
    CoordinatedTurn,
    LinearTransition,
    NearlyConstantTurn,
    RangeAzimuthElevation,
    RangeBearing,
    TrackingModel,
    constant_acceleration,
    constant_velocity,
)
from jaxtrack.montecarlo import simulate

CV2 = ("x", "y", "vx", "vy")
CV3 = ("x", "y", "z", "vx", "vy", "vz")


@pytest.mark.parametrize(
    "model, layout",
    [
        (ConstantVelocity(1.0, noise_intensity=0.1), CV2),
        (ConstantVelocity(1.0, noise_intensity=0.1, dim=3), CV3),
        (ConstantVelocity(1.0, noise_intensity=0.1, dim=1), ("x", "vx")),
        (ConstantAcceleration(1.0, noise_intensity=0.1), ("x", "y", "vx", "vy", "ax", "ay")),
        (CoordinatedTurn(1.0, turn_rate=0.05, noise_intensity=0.1), CV2),
        (CoordinatedTurn(1.0, turn_rate=0.05, noise_intensity=0.1, dim=3), CV3),
        (NearlyConstantTurn(1.0, noise_intensity=0.1, turn_rate_intensity=1e-4), CV2 + ("omega",)),
        (LinearTransition(np.eye(3), np.eye(3)), None),
        (LinearTransition(np.eye(2), np.eye(2), state_layout=("r", "rdot")), ("r", "rdot")),
        # a 2-D turn then 1-D CV: the CV block's axis is the one after the turn's (z)
        (BlockTransition([CoordinatedTurn(1.0, turn_rate=0.05, noise_intensity=0.1), ConstantVelocity(1.0,
            noise_intensity=0.01, dim=1)],
                         order=(0, 1, 3, 4, 2, 5)), CV3),
        (BlockTransition.per_axis([ConstantVelocity(1.0, noise_intensity=0.5, dim=1), ConstantVelocity(1.0,
            noise_intensity=2.0, dim=1)]), CV2),
        (BlockTransition([ConstantVelocity(1.0, noise_intensity=0.5, dim=1), LinearTransition(np.eye(1), np.eye(1))]),
         None),
    ],
)
def test_motion_models_declare_their_layout(model, layout):
    assert model.state_layout == layout
    if layout is not None:
        assert len(layout) == model.state_dim


def test_kinematic_builders_declare_their_layout():
    P4, P6 = np.eye(4), np.eye(6)
    assert constant_velocity(1.0, accel_psd=1.0, measurement_std=1.0, initial_cov=P4).state_layout == CV2
    assert constant_velocity(1.0, dim=3, accel_psd=1.0, measurement_std=1.0, initial_cov=P6).state_layout == CV3
    ca = constant_acceleration(1.0, dim=2, jerk_psd=1.0, measurement_std=1.0, initial_cov=P6)
    assert ca.state_layout == ("x", "y", "vx", "vy", "ax", "ay")


def _f(x, k):
    return x


def _h(x, k):
    return x[:2]


def test_linear_and_nonlinear_models_take_a_declared_layout():
    lgm = constant_velocity(1.0, accel_psd=1.0, measurement_std=1.0, initial_cov=np.eye(4))
    from jaxtrack.models import LinearGaussianModel, NonlinearGaussianModel

    args = (np.eye(4), np.eye(2), np.zeros(4), np.eye(4))
    assert NonlinearGaussianModel(_f, _h, *args).state_layout is None
    assert NonlinearGaussianModel(_f, _h, *args, state_layout=CV2).state_layout == CV2
    assert LinearGaussianModel(lgm.F, lgm.Q, lgm.H, lgm.R, lgm.initial_mean, lgm.initial_cov).state_layout is None
    with pytest.raises(InputError, match="state_layout"):
        NonlinearGaussianModel(_f, _h, *args, state_layout=("x", "y"))


@pytest.mark.parametrize("bad", [("x", "y"), ("x", "x", "vx", "vy"), "xyvv", (0, 1, 2, 3)])
def test_declared_layout_is_validated(bad):
    with pytest.raises(InputError, match="state_layout"):
        LinearTransition(np.eye(4), np.eye(4), state_layout=bad)


def test_3d_radar_on_a_2d_state_is_refused():
    """Cause 2: RangeAzimuthElevation's default position_indices (0, 1, 2) read vx as height."""
    with pytest.raises(InputError, match=r"position_indices.*\('x', 'y', 'vx'\).*\('x', 'y', 'z'\)"):
        TrackingModel(ConstantVelocity(1.0, noise_intensity=0.1), RangeAzimuthElevation(noise_std=(1.0, 0.01, 0.01)),
                      np.zeros(4), np.eye(4))
    # on a 3-D state it is right, and a 2-D radar reads the horizontal plane of a 3-D state
    TrackingModel(ConstantVelocity(1.0, noise_intensity=0.1, dim=3), RangeAzimuthElevation(noise_std=(1.0, 0.01, 0.01)),
                  np.ones(6), np.eye(6))
    TrackingModel(ConstantVelocity(1.0, noise_intensity=0.1, dim=3), RangeBearing(noise_std=(1.0, 0.01)), np.ones(6),
                  np.eye(6))


def test_range_rate_must_read_velocities():
    nct = NearlyConstantTurn(1.0, noise_intensity=0.1, turn_rate_intensity=1e-4)
    bad = RangeBearing(noise_std=(1.0, 0.01, 0.1), range_rate=True, velocity_indices=(2, 4))
    with pytest.raises(InputError, match=r"velocity_indices.*pass velocity_indices=\(2, 3\)"):
        TrackingModel(nct, bad, np.ones(5), np.eye(5))
    TrackingModel(nct, RangeBearing(noise_std=(1.0, 0.01, 0.1), range_rate=True), np.ones(5), np.eye(5))


def test_a_layout_that_names_no_position_is_not_checked():
    tr = LinearTransition(np.eye(4), np.eye(4), state_layout=("a", "b", "c", "d"))
    TrackingModel(tr, RangeAzimuthElevation(noise_std=(1.0, 0.01, 0.01)), np.ones(4), np.eye(4))


@settings(max_examples=60, deadline=None)
@given(perm=st.permutations(range(4)), pos=st.tuples(st.integers(0, 3), st.integers(0, 3)))
def test_sensor_is_accepted_exactly_when_it_reads_the_positions(perm, pos):
    """Property: for any ordering of a 2-D CV state, a sensor is accepted iff it reads (x, y)."""
    layout = tuple(CV2[i] for i in perm)
    tr = LinearTransition(np.eye(4), np.eye(4), state_layout=layout)
    if len(set(pos)) < 2:
        return
    sensor = RangeBearing(noise_std=(1.0, 0.01), position_indices=pos)
    reads = tuple(layout[i] for i in pos)
    if reads == ("x", "y"):
        TrackingModel(tr, sensor, np.ones(4), np.eye(4))
    else:
        with pytest.raises(InputError, match="position_indices"):
            TrackingModel(tr, sensor, np.ones(4), np.eye(4))


# ---------------------------------------------------------------------------------------------
# IMM embedding

RB = (5.0, 0.002)
SENSOR3 = (-2000.0, 500.0, 0.0)


def _cv3_permuted(order):
    """The 3-D CV model with its state stored in ``order`` (a permutation of CV3), layout declared."""
    cv = ConstantVelocity(1.0, noise_intensity=0.2, dim=3)
    F, Q = np.asarray(cv.transition_matrix(0)), np.asarray(cv.noise_cov(0))
    p = [CV3.index(c) for c in order]
    tr = LinearTransition(F[np.ix_(p, p)], Q[np.ix_(p, p)], state_layout=order)
    return tr, p


def _members(order):
    x2, P2 = np.array([0.0, 0.0, 10.0, 5.0]), np.diag([400.0, 400.0, 25.0, 25.0])
    x3, P3 = np.array([0.0, 0.0, 0.0, 10.0, 5.0, 0.0]), np.diag([400.0, 400.0, 100.0, 25.0, 25.0, 4.0])
    tr3, p = _cv3_permuted(order)
    sensor3 = RangeBearing(noise_std=RB, sensor_position=SENSOR3[:2], position_indices=(order.index("x"),
        order.index("y")))
    return [
        (ExtendedKalmanFilter(), TrackingModel(ConstantVelocity(1.0, noise_intensity=2.0), RangeBearing(noise_std=RB,
            sensor_position=SENSOR3[:2]), x2, P2)),
        (ExtendedKalmanFilter(), TrackingModel(tr3, sensor3, x3[p], P3[np.ix_(p, p)])),
    ]


@pytest.fixture(scope="module")
def cv2_cv3_runs():
    """The same IMM of a 2-D and a 3-D CV member, the 3-D state stored in two orders."""
    truth = TrackingModel(ConstantVelocity(1.0, noise_intensity=0.5), RangeBearing(noise_std=RB,
        sensor_position=SENSOR3[:2]),
                          np.array([0.0, 0.0, 10.0, 5.0]), np.eye(4))
    z = simulate(truth, 3, 12).measurements
    ptrans = np.array([[0.9, 0.1], [0.2, 0.8]])
    out = {}
    for name, order in (("native", CV3), ("prefix", ("x", "y", "vx", "vy", "z", "vz"))):
        imm = InteractingMultipleModel(_members(order), ptrans, augment_var=np.full(6, 9.0))
        out[name] = (imm, run_imm(imm, z), imm_smoother(imm, z))
    return out


def test_imm_embeds_a_2d_member_in_a_3d_state_by_name(cv2_cv3_runs):
    """Cause 2: the 2-D member's [x, y, vx, vy] are common components (0, 1, 3, 4), not (0, 1, 2, 3).

    The oracle is the same IMM with the 3-D state stored ``[x, y, vx, vy, z, vz]``, where the
    2-D member is a prefix (the only case the old rule got right): filtered and smoothed
    estimates agree to 1e-9 after the permutation. Under the old prefix rule the native order
    mixed the 2-D ``vx`` into ``z`` and differed by metres.
    """
    imm, res, sm = cv2_cv3_runs["native"]
    imm_p, res_p, sm_p = cv2_cv3_runs["prefix"]
    assert imm.state_layout == CV3 and imm.member_indices == ((0, 1, 3, 4), (0, 1, 2, 3, 4, 5))
    assert imm_p.member_indices == ((0, 1, 2, 3), (0, 1, 2, 3, 4, 5))
    assert bool(res.ok) and bool(sm.ok)
    p = [imm_p.state_layout.index(c) for c in CV3]  # prefix order → native order
    np.testing.assert_allclose(res.filtered_mean, res_p.filtered_mean[:, p], rtol=0, atol=1e-9)
    np.testing.assert_allclose(res.filtered_cov, res_p.filtered_cov[:, p][:, :, p], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(res.mode_probs, res_p.mode_probs, rtol=0, atol=1e-12)
    np.testing.assert_allclose(res.member_means[0], res_p.member_means[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(sm.smoothed_mean, sm_p.smoothed_mean[:, p], rtol=0, atol=1e-9)
    np.testing.assert_allclose(sm.smoothed_cov, sm_p.smoothed_cov[:, p][:, :, p], rtol=1e-9, atol=1e-9)
    # the combined height mixes the 3-D member's z with the augment value 0 only: it never sees vx
    z3 = np.asarray(res.member_means[1][:, 2])
    np.testing.assert_allclose(res.filtered_mean[:, 2], res.mode_probs[:, 1] * z3, rtol=0, atol=1e-9)


def test_declared_state_indices_match_the_derived_embedding():
    members = _members(CV3)
    derived = InteractingMultipleModel(members, np.eye(2))
    declared = InteractingMultipleModel(members, np.eye(2), state_indices=[(0, 1, 3, 4), range(6)])
    assert declared.member_indices == derived.member_indices and declared.state_dim == 6
    with pytest.raises(InputError, match=r"state_indices\[0\]"):
        InteractingMultipleModel(members, np.eye(2), state_indices=[(0, 1, 3), range(6)])
    with pytest.raises(InputError, match="leave common components"):
        InteractingMultipleModel(members, np.eye(2), state_indices=[(0, 1, 3, 4), (0, 1, 2, 3, 4, 7)])


def test_prefix_rule_is_checked_against_declared_layouts():
    """A member without a layout makes the IMM fall back to the prefix rule, which is then checked."""
    members = _members(CV3)
    undeclared = members[0][1]
    cv = ConstantVelocity(1.0, noise_intensity=2.0)
    bare = TrackingModel(LinearTransition(cv.transition_matrix(0), cv.noise_cov(0)), undeclared.measurement_model,
                         undeclared.initial_mean, undeclared.initial_cov)
    assert bare.state_layout is None
    with pytest.raises(InputError, match=r"not a prefix of \('x', 'y', 'z'"):
        InteractingMultipleModel(members + [(ExtendedKalmanFilter(), bare)], np.eye(3))
    # consistent with the prefix rule (a CV and a turn-rate state): accepted, embedding unchanged
    nct = TrackingModel(NearlyConstantTurn(1.0, noise_intensity=0.1, turn_rate_intensity=1e-4),
                        undeclared.measurement_model,
                        jnp.append(undeclared.initial_mean, 0.0), np.eye(5))
    imm = InteractingMultipleModel([(ExtendedKalmanFilter(), bare), (ExtendedKalmanFilter(), nct)], np.eye(2))
    assert imm.member_indices == ((0, 1, 2, 3), (0, 1, 2, 3, 4)) and imm.state_layout is None


@pytest.mark.parametrize("order", list(itertools.islice(itertools.permutations(CV2), 1, 4)))
def test_common_layout_is_the_longest_then_what_others_add(order):
    from jaxtrack.models._layout import common_layout

    common, idx = common_layout([order, CV2 + ("omega",)])
    assert common == CV2 + ("omega",)
    assert tuple(common[i] for i in idx[0]) == order
