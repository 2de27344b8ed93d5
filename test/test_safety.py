# Copyright 2026 visual_adaptive_servo contributors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Safe start, projection, saturation, the J* guard and bad input in the sampled controller."""


import logging
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import logged_warnings, PAPER_CONFIG
from visual_adaptive_servo.config.controller import ControllerConfig
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.control.controller import (
    AdaptiveVisualTracker,
    EstimatorState,
    Projection,
    control_law,
    health,
)
from visual_adaptive_servo.control.trajectory import (
    BlendedStart,
    SinusoidTrajectory,
    quintic_blend,
)

Q0 = np.array([1.0807, 0.5756, -0.5000])
T = 0.005


def controller(**changes):
    params = dict(load_scenario(PAPER_CONFIG).controller.params)
    params.update(changes)
    return AdaptiveVisualTracker(ControllerConfig.from_params(params))


def measure(ctl, q=Q0):
    return ctl.model.project(q)[0]


# -- safe start -------------------------------------------------------------------------------
def test_quintic_blend_is_c2_with_zero_end_derivatives():
    taus = np.linspace(-0.1, 1.1, 2401)
    vals = np.array([quintic_blend(t) for t in taus])
    h = taus[1] - taus[0]
    np.testing.assert_allclose(np.gradient(vals[:, 0], h)[2:-2], vals[2:-2, 1], atol=2e-3)
    np.testing.assert_allclose(np.gradient(vals[:, 1], h)[2:-2], vals[2:-2, 2], atol=2e-2)
    for tau in (0.0, 1.0):
        _, d1, d2 = quintic_blend(tau)
        assert d1 == 0.0 and d2 == 0.0


def test_blended_start_begins_at_the_measurement_and_ends_on_the_trajectory():
    traj = SinusoidTrajectory(np.array([45.0, 65.0]), np.array([20.0, 0.0]),
                              np.array([0.0, 20.0]), np.pi / 3)
    x0 = np.array([10.0, -30.0])
    blend = BlendedStart(traj, x0, 1.0, 2.0)
    x, xd, xdd = blend(1.0)
    np.testing.assert_allclose(x, x0)
    # x_d starts at rest, as the arm does: zero velocity and acceleration
    np.testing.assert_allclose(xd, 0.0, atol=1e-12)
    np.testing.assert_allclose(xdd, 0.0, atol=1e-12)
    for t in (3.0, 4.5):
        for a, b in zip(blend(t), traj(t)):
            np.testing.assert_allclose(a, b)
    # derivatives are consistent (finite differences) inside the blend
    h = 1e-5
    for t in (1.3, 2.0, 2.9):
        np.testing.assert_allclose((blend(t + h)[0] - blend(t - h)[0]) / (2 * h), blend(t)[1],
                                   rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose((blend(t + h)[1] - blend(t - h)[1]) / (2 * h), blend(t)[2],
                                   rtol=1e-5, atol=1e-5)


def test_a_start_on_the_trajectory_is_not_blended():
    traj = SinusoidTrajectory(np.array([45.0, 65.0]), np.array([20.0, 0.0]),
                              np.array([0.0, 20.0]), np.pi / 3)
    on = traj(0.7)[0] + np.array([0.004, -0.003])
    assert BlendedStart.from_measurement(traj, on, 0.7, 2.0, tolerance=0.01) is traj
    off = traj(0.7)[0] + np.array([0.02, 0.0])
    blend = BlendedStart.from_measurement(traj, off, 0.7, 2.0, tolerance=0.01)
    np.testing.assert_allclose(blend(0.7)[0], off)
    assert BlendedStart.from_measurement(traj, off, 0.7, 0.0, tolerance=0.01) is traj


@pytest.mark.parametrize("speed, lengthened", [(10.0, True), (200.0, False), (0.0, False)])
def test_a_far_start_is_blended_no_faster_than_the_speed_limit(speed, lengthened):
    # a trajectory at rest: the blend's velocity is the offset's part alone, and its peak
    # is measured by finite differences of x_d (not from the blend's own derivative)
    traj = SinusoidTrajectory(np.array([45.0, 65.0]), np.zeros(2), np.zeros(2), 0.0)
    off = traj(0.0)[0] + np.array([48.0, -64.0])          # 80 px off
    blend = BlendedStart.from_measurement(traj, off, 0.5, 2.0, tolerance=0.01, speed=speed)
    # 2 s at least; past that, as long as a peak of `speed` needs: 1.875 x 80 / speed
    assert blend.duration == pytest.approx(1.875 * 80.0 / speed if lengthened else 2.0)
    ts = np.linspace(0.5, 0.5 + blend.duration + 0.5, 20001)
    xs = np.array([blend(t)[0] for t in ts])
    peak = np.max(np.linalg.norm(np.diff(xs, axis=0), axis=1) / np.diff(ts))
    assert peak == pytest.approx(speed if lengthened else 1.875 * 80.0 / 2.0, rel=1e-3)
    np.testing.assert_allclose(blend(0.5 + blend.duration)[0], traj(0.0)[0])


def test_the_blend_speed_follows_the_trajectory_s_rms_image_speed():
    # the paper's circle, 20 px at pi/3 rad/s: RMS |x_d_dot| = 20 pi/3 px/s
    ctl = controller(start_blend_speed=1.5)
    assert ctl.blend_speed == pytest.approx(1.5 * 20.0 * np.pi / 3.0, rel=1e-3)
    assert controller(start_blend_speed=0.0).blend_speed == 0.0
    # a start 100 px off the paper's x_d(0) is blended in over 1.875 x 100 / (20 pi / 3) s
    ctl = controller()
    x = ctl.trajectory(0.0)[0] + np.array([60.0, 80.0])
    ctl.step(0.0, Q0, np.zeros(3), x)
    assert isinstance(ctl.desired, BlendedStart)
    assert ctl.desired.duration == pytest.approx(1.875 * 100.0 / (20.0 * np.pi / 3.0),
                                                 rel=1e-3)


def test_first_sample_has_zero_tracking_error_with_a_blend():
    ctl = controller(start_blend_time=2.0)
    q = Q0 + np.array([0.05, -0.03, 0.02])
    x = measure(ctl, q)
    res = ctl.step(0.0, q, np.zeros(3), x)
    np.testing.assert_allclose(res.error, 0.0)
    np.testing.assert_allclose(res.x_obs, x)


def test_zero_blend_time_is_the_paper_start():
    ctl = controller()
    res = ctl.step(0.0, Q0, np.zeros(3), measure(ctl))
    np.testing.assert_allclose(res.x_d, [65.0, 65.0])


# -- projection (Remark 6) --------------------------------------------------------------------
def make_projection(model, **bounds):
    kw = {"a_z_perp_min": np.full(2, 100.0), "a_z_perp_max": np.full(2, 1000.0),
          "a_z_min": np.array([0.5, 0.5, 1.0]), "a_z_max": np.array([10.0, 10.0, 20.0]),
          "a_d_min": np.full(8, -np.inf), "a_d_max": np.full(8, np.inf), "min_depth": 2.0}
    kw.update(bounds)
    return Projection(**kw)


def test_projection_leaves_rates_unchanged_inside_the_set(scenario, rng):
    model = scenario.controller.model
    proj = make_projection(model)
    H = model.kinematic_tensors(Q0, np.zeros(3))[0]
    state = EstimatorState(np.zeros(2), np.array([200.0, 300.0]), np.array([3.0, 3.0, 5.0]),
                           np.zeros(8))
    for _ in range(10):
        a_perp_dot, a_z_dot = rng.normal(size=2) * 10, rng.normal(size=3)
        p, z, active = proj.kinematic_rates(state, a_perp_dot, a_z_dot, H, np.full(3, 0.2))
        np.testing.assert_array_equal(p, a_perp_dot)
        np.testing.assert_array_equal(z, a_z_dot)
        assert not active


def test_projection_stops_rates_that_leave_the_set(scenario):
    model = scenario.controller.model
    proj = make_projection(model)
    H = model.kinematic_tensors(Q0, np.zeros(3))[0]
    # on the lower box face of a_z_perp[0], and exactly on the depth half-space
    a_z = np.array([1.0, 1.0, 0.0])
    a_z[2] = 2.0 - H[0, :2] @ a_z[:2]
    state = EstimatorState(np.zeros(2), np.array([100.0, 300.0]), a_z, np.zeros(8))
    p, z, active = proj.kinematic_rates(state, np.array([-5.0, 1.0]), -np.ones(3), H,
                                        np.full(3, 0.2))
    assert active
    assert p[0] == 0.0 and p[1] == 1.0
    assert H[0] @ z >= -1e-12  # the estimated depth no longer decreases


def test_clamp_puts_a_finite_step_back_into_the_set(scenario):
    model = scenario.controller.model
    proj = make_projection(model)
    H = model.kinematic_tensors(Q0, np.zeros(3))[0]
    state = EstimatorState(np.zeros(2), np.array([50.0, 5000.0]), np.array([0.6, 0.6, 1.0]),
                           np.zeros(8))
    out = proj.clamp(state, H)
    np.testing.assert_array_equal(out.a_z_perp, [100.0, 1000.0])
    assert H[0] @ out.a_z >= 2.0 - 1e-12


def test_estimates_never_leave_the_bounds_in_closed_loop(tmp_path):
    from visual_adaptive_servo.runner import run_scenario

    # tight bounds around the wrong initial estimates force the projection to act
    scenario = load_scenario(PAPER_CONFIG, [
        "controller_node.projection.a_z_perp_min=[205.0, 205.0]",
        "controller_node.projection.a_z_perp_max=[215.0, 215.0]",
        "controller_node.projection.a_z_min=[2.9, 2.9, 2.9]",
        "controller_node.projection.a_z_max=[3.1, 3.1, 3.1]"])
    summary = run_scenario(scenario, str(tmp_path), duration=3.0, progress=False, record=False,
                           plots=False)
    assert summary["projection_active"] > 0
    data = np.genfromtxt(tmp_path / "timeseries.csv", delimiter=",", names=True)
    for name in ("f_beta_l2", "f_beta_l3"):
        assert np.all((data[f"a_z_perp{name}"] >= 205.0) & (data[f"a_z_perp{name}"] <= 215.0))
    for name in ("l2", "l3", "d_C"):
        assert np.all((data[f"a_z{name}"] >= 2.9) & (data[f"a_z{name}"] <= 3.1))


# -- torque limit and the J* guard --------------------------------------------------------------
def test_torque_saturates_at_the_limit_and_is_reported():
    ctl = controller(torque_limit=[5.0, 5.0, 5.0])
    res = ctl.step(0.0, Q0, np.zeros(3), measure(ctl))
    assert res.saturated
    assert np.max(np.abs(res.tau)) <= 5.0
    assert np.max(np.abs(res.tau_unsaturated)) > 5.0
    assert health(res)[0] == "WARN" and "saturated" in health(res)[1]


def test_singular_j_star_is_damped_not_a_crash(scenario):
    model = scenario.controller.model
    c = scenario.controller
    gains = AdaptiveVisualTracker(c).gains
    q = Q0
    x = model.project(q)[0]
    # with a_z_perp_hat = 0, J* = -U J_z_hat has rank one: exactly what projection prevents
    state = EstimatorState(x, np.zeros(2), np.array(c.a_z_init), np.zeros(8))
    xd = (x, np.zeros(2), np.zeros(2))
    with pytest.raises(np.linalg.LinAlgError):
        control_law(model, gains, state, q, np.zeros(3), x, *xd)
    out = control_law(model, gains, state, q, np.zeros(3), x, *xd, min_singular_value=50.0)
    assert out.sigma_min < 1e-6
    assert out.damped
    assert np.all(np.isfinite(out.tau)) and np.all(np.isfinite(out.qr_ddot))


# -- bad input ----------------------------------------------------------------------------------
BAD_JOINTS = [
    ("q", np.array([np.nan, 0.5, -0.5]), "joint positions q: contains NaN"),
    ("q", np.array([1.0, 0.5]), "joint positions q: expected 3 values"),
    ("qd", np.array([0.0, np.inf, 0.0]), "joint velocities qd: contains NaN or inf"),
]
BAD_FRAMES = [
    (np.array([np.nan, 65.0]), "feature x: contains NaN"),
    (np.array([65.0, 65.0, 1.0]), "feature x: expected 2 values"),
    (np.array([900.0, 65.0]), "outside the image bounds"),
]


@pytest.mark.parametrize("compensation", [True, False])
@pytest.mark.parametrize("which, value, message", BAD_JOINTS)
def test_bad_joint_sample_is_rejected_without_touching_the_state(which, value, message,
                                                                 compensation):
    ctl = controller(latency_compensation=compensation)
    good = ctl.step(0.0, Q0, np.zeros(3), measure(ctl))
    state_before, rates_before = ctl.state, ctl.rates
    args = {"q": Q0, "qd": np.zeros(3)}
    args[which] = value
    res = ctl.step(T, args["q"], args["qd"], measure(ctl))
    assert res.status == "hold"
    assert any(message in p for p in res.problems), res.problems
    np.testing.assert_array_equal(res.tau, good.tau)
    assert ctl.state is state_before and ctl.rates is rates_before
    assert health(res)[0] == "WARN"


@pytest.mark.parametrize("value, message", BAD_FRAMES + [(None, "feature x: missing")])
def test_without_compensation_a_bad_frame_rejects_the_sample(value, message):
    ctl = controller(latency_compensation=False)
    good = ctl.step(0.0, Q0, np.zeros(3), measure(ctl))
    state_before, rates_before = ctl.state, ctl.rates
    res = ctl.step(T, Q0, np.zeros(3), value)
    assert res.status == "hold"
    assert any(message in p for p in res.problems), res.problems
    np.testing.assert_array_equal(res.tau, good.tau)
    assert ctl.state is state_before and ctl.rates is rates_before


@pytest.mark.parametrize("value, message", BAD_FRAMES)
def test_with_compensation_a_bad_frame_is_refused_and_the_sample_runs_on_the_prediction(
        value, message):
    ctl = controller()
    ctl.step(0.0, Q0, np.zeros(3), measure(ctl))
    predicted = ctl.predictor.predict(T)
    res = ctl.step(T, Q0, np.zeros(3), value)
    assert res.status == "ok" and any(message in p for p in res.problems), res.problems
    assert ctl.frames["rejected"] == 1 and ctl.frames["applied"] == 1
    np.testing.assert_array_equal(ctl.predictor.x_hat, predicted)
    np.testing.assert_allclose(res.error, predicted - res.x_d)


def test_degenerate_estimates_without_guards_reject_the_sample_not_crash():
    # a_hat = 0: J* = 0 and z_hat = 0, what projection and damping exist to prevent
    ctl = controller(**{"projection.enabled": False, "a_z_perp_init": [0.0, 0.0],
                        "a_z_init": [0.0, 0.0, 0.0], "min_singular_value": 0.0})
    with np.errstate(all="ignore"):
        res = ctl.step(0.0, Q0, np.zeros(3), measure(ctl))
    assert res.status == "fallback"
    # refused at the start: under a_z_hat = 0 every point has estimated depth 0
    assert "behind it or nearer than projection.min_depth" in res.problems[0]
    assert ctl.t_last is None


def test_time_going_backwards_is_rejected():
    ctl = controller()
    ctl.step(1.0, Q0, np.zeros(3), measure(ctl))
    res = ctl.step(0.5, Q0, np.zeros(3), measure(ctl))
    assert res.status == "hold" and "not after the last sample" in res.problems[0]


def test_hold_then_gravity_compensation_then_recovery_with_a_new_blend():
    ctl = controller(**{"safety.hold_time": 0.02, "safety.camera_timeout": 0.05,
                        "safety.fallback_damping": 2.0, "latency_compensation": False})
    t = 0.0
    ok = ctl.step(t, Q0, np.zeros(3), measure(ctl))
    statuses = []
    qd = np.array([0.1, -0.2, 0.05])
    for k in range(1, 20):               # 95 ms without a camera
        statuses.append(ctl.step(k * T, Q0, qd, None))
    assert [s.status for s in statuses[:4]] == ["hold"] * 4
    np.testing.assert_array_equal(statuses[0].tau, ok.tau)
    fallback = statuses[-1]
    assert fallback.status == "fallback" and health(fallback)[0] == "ERROR"
    zero = np.zeros(3)
    g_hat = ctl.model.dynamic_regressor(Q0, zero, zero, zero) @ ctl.state.a_d
    np.testing.assert_allclose(fallback.tau, g_hat - 2.0 * qd)
    assert ctl.stale
    # the camera comes back somewhere else: restart at the measurement, no jump in x_d
    q_new = Q0 + np.array([0.02, 0.01, -0.01])
    back = ctl.step(20 * T, q_new, np.zeros(3), measure(ctl, q_new))
    assert back.status == "ok" and not ctl.stale
    np.testing.assert_allclose(back.error, 0.0, atol=1e-12)


def test_with_compensation_a_stopped_camera_is_predicted_then_held_then_gravity_compensated():
    ctl = controller(**{"safety.hold_time": 0.02, "safety.camera_timeout": 0.05,
                        "safety.fallback_damping": 2.0})
    ctl.step(0.0, Q0, np.zeros(3), measure(ctl))
    qd = np.array([0.1, -0.2, 0.05])
    statuses = [ctl.step(k * T, Q0, qd, None).status for k in range(1, 20)]
    # predicted up to camera_timeout (10 samples), then held for hold_time, then the fallback
    assert statuses[:9] == ["ok"] * 9
    assert statuses[9:12] == ["hold"] * 3 and statuses[-1] == "fallback"
    assert ctl.stale
    q_new = Q0 + np.array([0.02, 0.01, -0.01])
    back = ctl.step(20 * T, q_new, np.zeros(3), measure(ctl, q_new))
    assert back.status == "ok" and not ctl.stale
    np.testing.assert_allclose(back.error, 0.0, atol=1e-12)


def test_zero_torque_fallback_and_invalid_joint_state_give_zero():
    ctl = controller(**{"safety.fallback": "zero_torque", "safety.hold_time": 0.0})
    ctl.step(0.0, Q0, np.zeros(3), measure(ctl))
    res = ctl.step(0.1, Q0, np.zeros(3), None)
    assert res.status == "fallback"
    np.testing.assert_array_equal(res.tau, np.zeros(3))
    ctl = controller(**{"safety.hold_time": 0.0})
    ctl.step(0.0, Q0, np.zeros(3), measure(ctl))
    res = ctl.step(0.1, np.full(3, np.nan), np.zeros(3), measure(ctl))
    np.testing.assert_array_equal(res.tau, np.zeros(3))


def test_non_finite_update_is_not_committed():
    ctl = controller()
    ctl.step(0.0, Q0, np.zeros(3), measure(ctl))
    before = ctl.state
    # a huge but finite velocity overflows the update: rejected, state kept
    with np.errstate(all="ignore"):
        res = ctl.step(T, Q0, np.full(3, 1e300), measure(ctl))
    assert res.status == "hold" and "not finite" in res.problems[0]
    assert ctl.state is before


def test_simulator_refuses_bad_commands_and_applies_zero(scenario):
    from sim_bridge.simulator import Simulator

    sim = Simulator(scenario.sim)
    try:
        assert "expected 3 torques" in sim.apply([1.0, 2.0])
        np.testing.assert_array_equal(sim.tau, np.zeros(3))
        assert "NaN or inf" in sim.apply([1.0, np.nan, 0.0])
        assert sim.apply([1.0, 0.0, 0.0]) is None
    finally:
        sim.close()


def test_joint_damping_is_the_estimated_inertia_at_the_start_and_damps_the_fallback():
    half = [0.5 * v for v in load_scenario(PAPER_CONFIG).controller.model.a_d]
    ctl = controller(**{"joint_damping.inertia_rate": 20.0, "safety.hold_time": 0.0,
                        "safety.fallback_damping": 1.0, "a_d_init": half})
    plain = controller(**{"safety.hold_time": 0.0, "a_d_init": half})
    q1 = Q0 + np.array([0.1, -0.05, 0.02])
    qd = np.array([0.3, -0.2, 0.1])
    res = ctl.step(0.0, q1, qd, measure(ctl, q1))
    ref = plain.step(0.0, q1, qd, measure(plain, q1))
    D = ctl.gains.D
    np.testing.assert_allclose(D, 20.0 * ctl.model.estimated_mass_matrix(q1, ctl.state.a_d),
                               rtol=1e-9)
    # the law: the paper's torque minus D s, with s = q_dot - q_dot_r of eq (20)
    xd, xd_dot, xd_ddot = ctl.desired(0.0)
    out = control_law(ctl.model, plain.gains, ctl.state, q1, qd, measure(ctl, q1), xd, xd_dot,
                      xd_ddot, None, ctl.config["min_singular_value"])
    np.testing.assert_allclose(res.tau, ref.tau - D @ out.s, rtol=1e-9, atol=1e-9)
    fallback = ctl.step(0.2, q1, qd, None)
    assert fallback.status == "fallback"
    zero = np.zeros(3)
    g_hat = ctl.model.dynamic_regressor(q1, zero, zero, zero) @ ctl.state.a_d
    np.testing.assert_allclose(fallback.tau, g_hat - 1.0 * qd - D @ qd, rtol=1e-12)


def test_joint_damping_is_off_when_the_inertia_estimate_is_zero():
    with logged_warnings() as records:
        ctl = controller(**{"joint_damping.inertia_rate": 20.0})   # the paper's a_d: no inertia
        ctl.step(0.0, Q0, np.zeros(3), measure(ctl))
    assert ctl.gains.D is None
    assert any("not positive definite" in r.getMessage() for r in records)


def test_estimated_mass_matrix_from_the_regressor_is_the_models(scenario):
    model = scenario.controller.model
    for q in (Q0, Q0 + 0.3):
        np.testing.assert_allclose(model.estimated_mass_matrix(q, model.a_d),
                                   model.mass_matrix(q), rtol=1e-12, atol=1e-12)


# -- joint position limits ----------------------------------------------------------------------
BOOM = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "docs",
                    "examples", "boom", "boom.yaml")


def test_a_joint_past_its_urdf_limit_is_reported_once_per_excursion(tmp_path):
    scenario = load_scenario(BOOM)
    # the URDF's limits, read from the file: extend (prismatic) -0.3..0.3 m
    np.testing.assert_array_equal(scenario.controller.model.position_limits,
                                  [(-3.0, 3.0), (-2.0, 2.0), (-0.3, 0.3), (-3.0, 3.0)])
    tracker = AdaptiveVisualTracker(scenario.controller)
    q = np.array(scenario.sim.initial_positions, dtype=float)
    x = scenario.controller.model.project(q)[0]
    path = [0.05, 0.2, 0.31, 0.35, 0.32, 0.2, 0.32, 0.1]      # extend [m], every 10 ms
    with logged_warnings() as records:
        for k, extend in enumerate(path):
            q[2] = extend
            tracker.step(0.01 * k, q.copy(), np.zeros(4), x)
    past = [r.getMessage() for r in records if "URDF" in r.getMessage()]
    # out at 0.31 (reported), still out at 0.35 and 0.32 (not again), back in, out again
    assert len(past) == 2 and tracker.limit_excursions == 2
    assert past[0].startswith("joint extend at 0.31 m is past its URDF upper limit 0.3 m "
                              "(t=0.020)")
    assert tracker.outside_limits == set()          # back inside at the end
    # a limit the URDF does not set (lower >= upper, or a continuous joint) is none
    text = open(scenario.controller.model.chain.urdf).read().replace(
        'lower="-0.3" upper="0.3"', 'lower="0" upper="0"')
    (tmp_path / "boom.urdf").write_text(text)
    from visual_adaptive_servo.models.urdf_chain import load_chain
    chain = load_chain(str(tmp_path / "boom.urdf"), "world", "tool", "controller_node")
    assert chain.position_limits[2] == (-np.inf, np.inf)


def test_the_run_summary_counts_the_limit_excursions(tmp_path, capsys):
    from visual_adaptive_servo.runner import run_scenario
    # the boom started 5 cm past its extension's upper limit, which the URDF narrows to 0
    text = open(os.path.join(os.path.dirname(BOOM), "boom.urdf")).read().replace(
        'lower="-0.3" upper="0.3"', 'lower="-0.3" upper="0.0"')
    (tmp_path / "boom.urdf").write_text(text)
    (tmp_path / "boom.yaml").write_text(open(BOOM).read())
    summary = run_scenario(load_scenario(str(tmp_path / "boom.yaml")), str(tmp_path / "run"),
                           duration=0.2, progress=False, record=False, plots=False)
    assert summary["joint_limit_excursions"] == 1
    # vas run says so at the end (and its log warns at each excursion)
    from visual_adaptive_servo import cli
    code = cli.main(["run", "--config", str(tmp_path / "boom.yaml"), "--out",
                     str(tmp_path / "cli"), "--duration", "0.1", "--no-bag", "--no-progress"])
    assert code == 0
    assert ("JOINT LIMITS: a joint went past its URDF position limit 1 time(s)"
            in capsys.readouterr().err)
    # ... and its log warns as it happens, without -v: a process of its own, as a user runs it
    # (pytest's handlers on the root logger would make vas's logging setup a no-op here)
    done = subprocess.run(
        [sys.executable, "-m", "visual_adaptive_servo.cli", "run", "--config",
         str(tmp_path / "boom.yaml"), "--out", str(tmp_path / "proc"), "--duration", "0.1",
         "--no-bag", "--no-progress"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    warned = [line for line in done.stderr.splitlines() if line.startswith("WARNING")]
    assert len(warned) == 1 and "is past its URDF upper limit" in warned[0], done.stderr


def test_a_camera_that_never_starts_is_warned_of_once_after_the_camera_timeout():
    ctl = controller()
    timeout = ctl.config["safety.camera_timeout"]
    steps = int(round(3 * timeout / T))
    with logged_warnings() as records:
        for k in range(steps):
            ctl.step(k * T, Q0, np.zeros(3))                    # no frame, ever
    lines = [r.getMessage() for r in records]
    assert len(lines) == 1 and "no camera frame yet" in lines[0], lines
    # at the first sample past the timeout, not before
    assert f"t={int(np.ceil(timeout / T - 1e-9)) * T:.4f}" in lines[0], lines
    # a frame, then the camera gone: the stale camera's warnings, not this one
    ctl = controller()
    with logged_warnings() as records:
        ctl.step(0.0, Q0, np.zeros(3), measure(ctl))
        for k in range(1, steps):
            ctl.step(k * T, Q0, np.zeros(3))
    assert not any("no camera frame yet" in r.getMessage() for r in records)
    assert any("camera stale" in r.getMessage() for r in records)


def test_a_second_problem_of_the_same_input_is_logged_and_a_growing_age_is_not():
    # a rendered camera whose detector sends one point for a two-point controller: the log
    # once showed only 'waiting for the first camera frame' (both problems are of feature x)
    ctl = controller()
    with logged_warnings(level=logging.INFO) as records:
        ctl.step(0.0, Q0, np.zeros(3))                          # no frame yet
        for k in range(1, 4):
            ctl.step(k * T, Q0, np.zeros(3), np.zeros(1))       # the wrong size, 3 samples
    lines = [r for r in records if "rejected" in r.getMessage()]
    assert len(lines) == 2, [r.getMessage() for r in lines]
    # a camera's start is no warning (every camera-driven run has one); the wrong size is
    assert "waiting for the first camera frame" in lines[0].getMessage()
    assert lines[0].levelno == logging.INFO
    assert "feature x" in lines[1].getMessage() and "waiting" not in lines[1].getMessage()
    assert lines[1].levelno == logging.WARNING
    # a stale camera's age grows at every sample: one line for the whole outage
    ctl = controller()
    ctl.step(0.0, Q0, np.zeros(3), measure(ctl))
    with logged_warnings() as records:
        for k in range(1, 200):
            ctl.step(k * T, Q0, np.zeros(3))
    stale = [r.getMessage() for r in records
             if "rejected" in r.getMessage() and "camera stale" in r.getMessage()]
    assert len(stale) == 1, stale
