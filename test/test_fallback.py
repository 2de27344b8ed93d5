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

"""The safety fallback's damping on a light wrist: bounded by the sampled-data step.

The arm here is one the package does not ship (a 3R arm on a tilted mount with a
0.5 kg hand, written for this test, no gain in its file).  Behind a camera 33 ms
late the fallback holds it until the first frame; with a fixed 5 N m s/rad the
wrist's torque flips sign every 1 ms sample and the run diverges at 0.046 s.
"""

import logging

import numpy as np
import pytest

from conftest import logged_warnings
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.control import controller
from visual_adaptive_servo.control.controller import fallback_bound, FALLBACK_STEP
from visual_adaptive_servo.runner import run_scenario

URDF = """<?xml version="1.0"?>
<robot name="tilted_3r">
  <link name="world"/>
  <joint name="mount" type="fixed">
    <parent link="world"/><child link="base"/>
    <origin xyz="0.1 -0.05 0.2" rpy="0.2 -0.15 0.6"/>
  </joint>
  <link name="base">
    <inertial><origin xyz="0 0 0.05"/><mass value="3.0"/>
      <inertia ixx="0.02" iyy="0.02" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <joint name="yaw" type="revolute">
    <parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.12"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="80" velocity="3"/>
  </joint>
  <link name="upper">
    <inertial><origin xyz="0.18 0 0"/><mass value="2.2"/>
      <inertia ixx="0.004" iyy="0.03" izz="0.03" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <joint name="pitch" type="revolute">
    <parent link="upper"/><child link="fore"/>
    <origin xyz="0.35 0 0.02"/><axis xyz="0 1 0"/>
    <limit lower="-2.5" upper="2.5" effort="60" velocity="3"/>
  </joint>
  <link name="fore">
    <inertial><origin xyz="0.13 0 0"/><mass value="1.1"/>
      <inertia ixx="0.002" iyy="0.012" izz="0.012" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <joint name="roll" type="revolute">
    <parent link="fore"/><child link="hand"/>
    <origin xyz="0.27 0 0" rpy="0 0.4 0"/><axis xyz="1 0 0"/>
    <limit lower="-3" upper="3" effort="30" velocity="4"/>
  </joint>
  <link name="hand">
    <inertial><origin xyz="0.04 0.02 0"/><mass value="0.5"/>
      <inertia ixx="0.0008" iyy="0.001" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
</robot>
"""

CAMERA = """      orientation: look_at
      up: [0.0, 0.0, 1.0]
      principal_point: [320.0, 240.0]
      image_size: [640.0, 480.0]
      pixel_origin: [0.0, 0.0]
      pixel_axes: [1.0, 1.0]
"""

SCENARIO = """sim_node:
  ros__parameters:
    urdf: arm.urdf
    base_link: world
    tip_link: hand
    feature_points: [0.06, 0.08, 0.0]
    physics_dt: 0.001
    control_period: 0.001
    initial_positions: [0.4, 0.5, 0.3]
    camera_rate: 30.0
    camera_latency: 0.033
    camera:
      position: [0.3, -1.8, 1.4]
      look_at: [0.35, 0.3, 0.3]
      focal_length: 0.008
      pixel_scale: [90000.0, 90000.0]
{camera}controller_node:
  ros__parameters:
    model: urdf
    urdf: arm.urdf
    base_link: world
    tip_link: hand
    feature_points: [0.06, 0.08, 0.0]
    sample_time: 0.001
    camera_rate: 30.0
    camera_latency: 0.033
    initial_estimate:
      camera:
        position: [0.5, -1.5, 1.2]
        look_at: [0.3, 0.35, 0.35]
        focal_length: 0.01
        pixel_scale: [80000.0, 100000.0]
{estimated_camera}      length_scale: 0.8
      inertia_scale: 1.5
    trajectory:
      offset: [305.17546384, 204.2986397]
      a_cos: [20.0, 0.0]
      a_sin: [0.0, 20.0]
      omega: 0.5
    image_bounds: [0.0, 640.0, 0.0, 480.0]
    min_singular_value: 5.0
{torque_limit}"""

#: no saturation: the fallback's own torque is what these tests measure
NO_LIMIT = "    torque_limit: [.inf, .inf, .inf]\n"


def test_the_bound_keeps_every_joint_within_the_step_and_leaves_unknown_inertia_alone():
    M_hat = np.array([[2.0, 0.3, 0.0], [0.3, 0.05, 0.0], [0.0, 0.0, 0.0]])
    D = np.diag([4.0, 1.0, 0.5])
    T = 0.001
    bound = fallback_bound(M_hat, D, T)
    # T (D_jj + d_j) / M_jj is the step where the bound binds, and never more
    np.testing.assert_allclose(T * (np.diag(D)[:2] + bound[:2]) / np.diag(M_hat)[:2],
                               FALLBACK_STEP, rtol=1e-12)
    assert bound[2] == np.inf                         # nothing known about joint 3
    # a damping D already past the step leaves no room, not a negative damping
    assert fallback_bound(M_hat, np.diag([2000.0, 1.0, 0.0]), T)[0] == 0.0


def test_where_joints_move_one_another_the_bound_holds_for_the_whole_matrix():
    # a planar chain: each joint carries the links after it, so M_hat is far from diagonal
    # and its lightest mode (3.1e-4) is lighter than any diagonal entry (1e-3 or more)
    M_hat = 1e-3 * np.array([[3.0, 2.0, 1.0], [2.0, 2.0, 1.0], [1.0, 1.0, 1.0]])
    T = 0.001
    D = 0.2 / T * M_hat

    def largest_step(d):
        return np.max(np.linalg.eigvals(T * np.linalg.solve(M_hat, D + np.diag(d))).real)

    per_joint = FALLBACK_STEP * np.diag(M_hat) / T - np.diag(D)
    # the oracle: each joint within its own step, the loop together past 2 -- its velocity
    # error flips sign every sample and grows
    assert largest_step(per_joint) > 2.0
    bound = fallback_bound(M_hat, D, T)
    assert largest_step(bound) == pytest.approx(FALLBACK_STEP, rel=1e-6)
    np.testing.assert_allclose(bound / per_joint, bound[0] / per_joint[0], rtol=1e-12)
    # a requested damping the whole matrix allows is applied as requested
    np.testing.assert_array_equal(fallback_bound(M_hat, D, T, 0.05), [0.05] * 3)
    largest = largest_step(fallback_bound(M_hat, D, T, 0.5))
    assert largest == pytest.approx(FALLBACK_STEP, rel=1e-6)
    # any damping below the bound, joint by joint, stays within
    for d in (np.minimum(bound, 0.2), 0.5 * bound, bound * [1.0, 0.0, 1.0]):
        assert largest_step(d) <= FALLBACK_STEP + 1e-12
        iterate = np.eye(3) - T * np.linalg.solve(M_hat, D + np.diag(d))
        assert np.max(np.abs(np.linalg.eigvals(iterate))) < 1.0


def test_an_unseen_planar_arm_held_by_the_fallback_before_its_first_frame(tmp_path,
                                                                          monkeypatch):
    # benchmarks/unseen_arms.py's arm 7: three parallel axes, a real camera's first frame
    # 33 ms late; the per-joint bounds alone threw its joints to their velocity limits
    from visual_adaptive_servo.campaigns.unseen_arms import random_arm
    arm = random_arm(7, str(tmp_path / "arm"))
    scenario = load_scenario(arm.path, (
        "sim_node.camera_rate=30", "sim_node.camera_latency=0.033",
        "sim_node.pixel_noise_std=0.5", "sim_node.seed=1", "controller_node.camera_rate=30",
        "controller_node.camera_latency=0.033"))
    summary = run_scenario(scenario, str(tmp_path / "held"), 1.0, progress=False,
                           record=False, plots=False)
    assert not summary["diverged"], summary.get("divergence_reason")
    assert summary["max_true_error_px"] < 10.0
    per_joint = controller.fallback_bound

    def diagonal_only(M_hat, D, sample_time, requested):
        M_hat = np.diag(np.diag(M_hat))         # the bound as it was: joint by joint
        return per_joint(M_hat, np.diag(np.diag(D)), sample_time, requested)

    monkeypatch.setattr(controller, "fallback_bound", diagonal_only)
    thrown = run_scenario(scenario, str(tmp_path / "thrown"), 1.0, progress=False,
                          record=False, plots=False)
    assert thrown["diverged"]


def _scenario(tmp_path, torque_limit=NO_LIMIT):
    (tmp_path / "arm.urdf").write_text(URDF)
    path = tmp_path / "arm.yaml"
    path.write_text(SCENARIO.format(camera=CAMERA, estimated_camera="".join(
        "  " + line + "\n" for line in CAMERA.splitlines()), torque_limit=torque_limit))
    return load_scenario(str(path))


def test_a_light_wrist_held_by_the_fallback_until_a_late_first_frame_stays_bounded(
        tmp_path, monkeypatch):
    scenario = _scenario(tmp_path)
    with logged_warnings(level=logging.INFO) as records:   # (the default's cap: INFO)
        summary = run_scenario(scenario, str(tmp_path / "bounded"), 0.3, progress=False,
                               record=False, plots=False)
    assert not summary["diverged"], summary.get("divergence_reason")
    assert summary["max_abs_torque"] < 30.0               # the roll joint's URDF effort
    assert any("the fallback uses" in r.getMessage() and "roll 0." in r.getMessage()
               for r in records)
    # the oracle: the same run with the fixed 5 N m s/rad on every joint diverges in the
    # 33 ms before the first frame (the fallback's sign-flipping wrist torque)
    monkeypatch.setattr(controller, "fallback_bound",
                        lambda M_hat, D, sample_time, requested: np.full(len(D), requested))
    fixed = run_scenario(scenario, str(tmp_path / "fixed"), 0.3, progress=False,
                         record=False, plots=False)
    assert fixed["diverged"]
    assert pytest.approx(0.046, abs=0.01) == float(
        fixed["divergence_reason"].split("at t=")[1].split(";")[0])


def test_without_a_torque_limit_the_urdf_effort_limits_saturate_the_command(
        tmp_path, monkeypatch):
    scenario = _scenario(tmp_path, torque_limit="")
    np.testing.assert_array_equal(scenario.controller.torque_limit, [80.0, 60.0, 30.0])
    given = _scenario(tmp_path, torque_limit="    torque_limit: 500.0\n")
    np.testing.assert_array_equal(given.controller.torque_limit, [500.0] * 3)
    tracker = controller.AdaptiveVisualTracker(scenario.controller)
    lines = tracker.start(scenario.sim.initial_positions).lines()
    assert ("torque limit: yaw 80 N m, pitch 60 N m, roll 30 N m (the URDF's <limit effort>, "
            "as torque_limit is not given)") in lines
    # the oracle of the test above: the fixed fallback damping's sign-flipping wrist torque
    # diverges without a limit; with the URDF's limits every command stays within them
    monkeypatch.setattr(controller, "fallback_bound",
                        lambda M_hat, D, sample_time, requested: np.full(len(D), requested))
    summary = run_scenario(scenario, str(tmp_path / "limited"), 0.1, progress=False,
                           record=False, plots=False)
    unlimited = run_scenario(_scenario(tmp_path), str(tmp_path / "unlimited"), 0.1,
                             progress=False, record=False, plots=False)
    assert unlimited["diverged"]
    assert not summary["diverged"], summary.get("divergence_reason")
    assert summary["max_abs_torque"] <= 80.0


@pytest.mark.parametrize("given", [False, True])
def test_the_fallback_damping_capped_on_light_joints_is_warned_of_only_when_given(
        tmp_path, given):
    # benchmarks/unseen_arms.py's arm 7: its wrist is light, so the default 5 N m s/rad is
    # capped there; a user who did not write it needs no warning at every start
    from visual_adaptive_servo.campaigns.unseen_arms import random_arm
    arm = random_arm(7, str(tmp_path / "arm"))
    scenario = load_scenario(arm.path, ("controller_node.safety.fallback_damping=5.0",)
                             if given else ())
    with logged_warnings(level=logging.INFO) as records:
        run_scenario(scenario, str(tmp_path / "run"), 0.01, progress=False, record=False,
                     plots=False)
    capped = [r for r in records if "safety.fallback_damping" in r.getMessage()]
    # capped either way (the INFO line says where), a warning only when the file gave it
    assert len(capped) == 1, [r.getMessage() for r in records]
    assert capped[0].levelno == (logging.WARNING if given else logging.INFO)
