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

"""Configuration: one YAML for both nodes, validated whole, refused with the name and rule."""

import os

import numpy as np
import pytest
import yaml

from conftest import PAPER_CONFIG, ROOT
from visual_adaptive_servo.config.controller import CONTROLLER_PARAMS, ControllerConfig
from visual_adaptive_servo.config.files import read_param_file
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.config.sim import SIM_PARAMS, SimConfig
from visual_adaptive_servo.schema import ConfigError
from visual_adaptive_servo.control.controller import AdaptiveVisualTracker


def test_reference_file_holds_every_number_of_the_paper(scenario):
    c, s = scenario.controller, scenario.sim
    np.testing.assert_allclose(c.K, [0.001, 0.001])
    assert (c.alpha, c.gamma) == (10.0, 10.0)
    np.testing.assert_allclose(c.Gamma_d, [300.0] * 8)
    np.testing.assert_allclose(c.Gamma_z_perp, [600.0] * 2)
    np.testing.assert_allclose(c.Gamma_z, [0.2] * 3)
    np.testing.assert_allclose(c.a_z_perp_init, [0.1 * 700 * 3.0] * 2)
    np.testing.assert_allclose(c.a_z_init, [3.0, 3.0, 3.0])
    np.testing.assert_allclose(c.a_d_init, [0, 0, 0, 0, 0, 0, 15, 0])
    assert c.sample_time == s.control_period == 0.005
    assert s.physics_dt == 0.001
    np.testing.assert_allclose(s.initial_positions, [1.0807, 0.5756, -0.5])
    # the true parameters of the model are the paper's a_z_perp = f beta [l2, l3], a_z
    np.testing.assert_allclose(c.model.a_z_perp, [270.0, 270.0])
    np.testing.assert_allclose(c.model.a_z, [2.0, 2.0, 5.0])


def test_every_schema_entry_has_a_description():
    for spec in SIM_PARAMS + CONTROLLER_PARAMS:
        assert spec.description.strip(), spec.name


@pytest.mark.parametrize("override, message", [
    ("controller_node.alpha=3.0", r"controller_node\.alpha: Theorem 1 requires alpha > gamma/3"),
    ("controller_node.K=[0.001, 0.002, 0.003]", r"controller_node\.K: needs 2 values, got 3"),
    ("controller_node.K=[0.001, 0.0]",
     r"controller_node\.K: every entry must be > 0 .*got \[0\.001, 0\.0\]$"),
    ("controller_node.gamma=-1.0", r"controller_node\.gamma: must be >= 0.0"),
    ("controller_node.Gamma_d=[1, 1]", r"controller_node\.Gamma_d: needs 8 values, got 2"),
    ("controller_node.model=ur5", r"controller_node\.model: unknown model name 'ur5'"),
    ("controller_node.kp=3.0", r"controller_node: unknown parameter\(s\) \['kp'\]"),
    ("controller_node.alpha=fast", r"controller_node\.alpha: must be a number, got 'fast'"),
    ("controller_node.a_z_init=[3.0, .nan, 3.0]", r"controller_node\.a_z_init: must not contain"),
    ("controller_node.a_z_init=[30.0, 3.0, 3.0]",
     r"controller_node\.a_z_init: must lie within projection\.a_z_min/_max"),
    ("controller_node.safety.fallback=brake",
     r"controller_node\.safety\.fallback: must be one of"),
    ("sim_node.control_period=0.0055", r"sim_node\.control_period: must be a whole multiple"),
    ("sim_node.initial_positions=[0.0, 1.0]", r"sim_node\.initial_positions: needs 3 values"),
    ("sim_node.timing_mode=fast", r"sim_node\.timing_mode: must be one of"),
    ("sim_node.camera_latency=-0.01", r"sim_node\.camera_latency: must be >= 0.0"),
    ("sim_node.camera_rate=500.0", r"sim_node\.camera_rate: at most one frame per control"),
    ("sim_node.camera.pixel_axes=[1.0, 0.5]", r"sim_node\.camera\.pixel_axes: each must be 1 or"),
    ("sim_node.camera.look_at=[-5.0, 0.0, 0.0]", r"sim_node\.camera\.look_at: must differ"),
    ("sim_node.camera.orientation=euler", r"sim_node\.camera\.orientation: must be 'look_at'"),
    ("sim_node.camera.look_at=[]",
     r"sim_node\.camera\.look_at: needs 3 values with camera\.orientation look_at, got 0"),
    ("sim_node.camera.image_size=[640.5, 480]", r"sim_node\.camera\.image_size: two whole"),
    ("sim_node.camera.position=[-5.0, 0.5, 0.0]",
     r"sim_node\.camera: model paper_rrr assumes the paper's camera"),
    ("sim_node.urdf=nowhere.urdf", r"sim_node\.urdf: 'nowhere.urdf' not found"),
    ("sim_node.tip_link=link9", r"sim_node\.tip_link: no link 'link9'"),
    ("sim_node.base_link=link2", r"sim_node\.tip_link: 'tip' is not below base_link 'link2'|"
     r"sim_node\.base_link: 'link2' moves"),
    ("sim_node.feature_points=[0.0, 0.0]", r"sim_node\.feature_points: 3 numbers per point"),
    ("controller_node.image_bounds=[-320, 0, -240, 240]",
     r"sim_node\.initial_positions: feature point\(s\) \[1\] outside the image at the start"),
    ("controller_node.trajectory.type=spiral", r"controller_node\.trajectory\.type: must be one"),
    ("controller_node.trajectory.type=table", r"controller_node\.trajectory\.file: no file name"),
])
def test_invalid_values_are_refused_with_name_and_rule(override, message):
    with pytest.raises(ConfigError, match=message):
        load_scenario(PAPER_CONFIG, [override])


@pytest.mark.parametrize("section", ["sim_node.camera", "controller_node.initial_estimate.camera"])
def test_the_camera_s_orientation_says_which_of_look_at_and_rpy_is_read(section):
    # orientation rpy once read look_at all the same (its default, [0, 0, 0]): a camera
    # given by rpy was silently aimed at the origin
    from sim_bridge.camera import PinholeCamera
    from visual_adaptive_servo.models.urdf_chain import rpy_matrix

    iiwa = os.path.join(ROOT, "config", "iiwa_3points.yaml")

    def camera(overrides):
        scenario = load_scenario(iiwa, [f"{section}.{o}" for o in overrides])
        if section.startswith("sim_node"):
            return scenario.sim.camera.rotation
        # the guessed camera is read into the initial estimates only
        return scenario.controller.a_z_perp_init, scenario.controller.a_z_init

    if section.startswith("sim_node"):
        rot = load_scenario(iiwa).sim.camera.rotation
    else:
        guess = read_param_file(iiwa)["controller_node"]
        rot = PinholeCamera.look_at(*(guess[f"initial_estimate.camera.{k}"]
                                      for k in ("position", "look_at", "up")),
                                    1.0, 1.0, 0.0, 0.0, 640, 480).rotation
    W = rot.T                                   # rpy_matrix(rpy) = rotation^T
    rpy = [float(np.arctan2(W[2, 1], W[2, 2])), float(-np.arcsin(W[2, 0])),
           float(np.arctan2(W[1, 0], W[0, 0]))]
    np.testing.assert_allclose(rpy_matrix(rpy), W, atol=1e-12)
    turned = [rpy[0] + 0.05, rpy[1], rpy[2] - 0.03]
    look_at = camera([])
    # rpy is read with orientation rpy, whatever look_at holds
    by_rpy = camera(["orientation=rpy", f"rpy={turned}"])
    elsewhere = camera(["orientation=rpy", f"rpy={turned}", "look_at=[5.0, 5.0, 5.0]"])
    np.testing.assert_array_equal(np.hstack(elsewhere), np.hstack(by_rpy))
    # and not read with orientation look_at
    same = camera([f"rpy={turned}"])
    if section.startswith("sim_node"):
        np.testing.assert_allclose(by_rpy, rpy_matrix(turned).T, atol=1e-12)
        np.testing.assert_allclose(camera(["orientation=rpy", f"rpy={rpy}"]), rot, atol=1e-9)
        np.testing.assert_array_equal(same, look_at)
    else:
        assert not np.allclose(by_rpy[0], look_at[0])
        np.testing.assert_allclose(camera(["orientation=rpy", f"rpy={rpy}"])[0], look_at[0],
                                   rtol=1e-9, atol=1e-9)
        np.testing.assert_array_equal(same[0], look_at[0])
    with pytest.raises(ConfigError, match=rf"{section}\.orientation: must be 'look_at'"):
        camera(["orientation=euler"])


def test_joint_names_are_the_urdf_chain_s_in_its_order():
    # a name the chain lacks ran a ROS launch for 15 s with every sample refused
    iiwa = os.path.join(ROOT, "config", "iiwa_3points.yaml")
    names = [f"lbr_iiwa_joint_{i}" for i in range(1, 8)]
    with pytest.raises(ConfigError, match=r"controller_node\.joint_names: \['wrist_twist'\] "
                       r"not among the URDF chain's joints"):
        load_scenario(iiwa, [f"controller_node.joint_names={names[:6] + ['wrist_twist']}"])
    with pytest.raises(ConfigError, match=r"controller_node\.joint_names: not in the URDF "
                       r"chain's order"):
        load_scenario(iiwa, [f"controller_node.joint_names={names[::-1]}"])


def test_a_long_list_is_named_by_its_first_failing_entry():
    # a 7-joint arm with three points has 66 a_z_perp gains: the message names the entry
    # (counted from 0) and how many more fail, in plain numbers rather than 66 numpy reprs
    for override, message in [
            ("controller_node.Gamma_z_perp=0", r"controller_node\.Gamma_z_perp: every entry "
             r"must be > 0 .*, entry 0 \(counted from 0\) is 0\.0, and 65 more of the 66 "
             r"entries$"),
            ("controller_node.Gamma_z=[" + ", ".join(["1.0"] * 20 + ["0.0"] + ["1.0"] * 13)
             + "]", r"controller_node\.Gamma_z: .*, entry 20 \(counted from 0\) is 0\.0$")]:
        with pytest.raises(ConfigError, match=message) as err:
            load_scenario(os.path.join(ROOT, "config", "iiwa_3points.yaml"), [override])
        assert "np.float64" not in str(err.value)


def test_broken_files_are_refused(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("sim_node: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        read_param_file(bad)
    bad.write_text(yaml.safe_dump({"sim_node": {"ros__parameters": {}}}))
    with pytest.raises(ConfigError, match="needs a 'controller_node: ros__parameters:'"):
        read_param_file(bad)


def test_scientific_notation_reads_as_a_number_like_ros():
    scenario = load_scenario(PAPER_CONFIG, ["controller_node.torque_limit=[1e3, 1e3, 1e3]"])
    np.testing.assert_allclose(scenario.controller.torque_limit, [1000.0] * 3)


def test_invalid_runtime_change_applies_nothing(scenario):
    ctl = AdaptiveVisualTracker(scenario.controller)
    before = ctl.gains
    with pytest.raises(ConfigError, match=r"controller_node\.Gamma_d: must be >= 0.0, got -1.0"):
        ctl.update_gains(K=[0.01, 0.01], Gamma_d=[-1.0] * 8)
    assert ctl.gains is before
    ctl.update_gains(K=[0.01, 0.01])
    np.testing.assert_allclose(ctl.gains.K, [0.01, 0.01])


def test_configs_are_immutable(scenario):
    with pytest.raises(ValueError):
        scenario.controller.K[0] = 5.0
    assert isinstance(scenario.sim, SimConfig)
    assert isinstance(scenario.controller, ControllerConfig)


def test_package_paths_resolve_without_a_sourced_ros(monkeypatch):
    from visual_adaptive_servo.models.resources import resolve_path

    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    path = resolve_path("package://visual_adaptive_servo/urdf/paper_rrr.urdf")
    assert path.endswith("sim_bridge/urdf/paper_rrr.urdf")
    with pytest.raises(FileNotFoundError,
                       match=r"sim_node\.urdf: 'package://nope/x.urdf' not found"):
        resolve_path("package://nope/x.urdf", what="sim_node.urdf")


def test_an_install_finds_its_shared_files_where_it_installed_them(tmp_path):
    # colcon build and pip install . put config/ and urdf/ under <prefix>/share/<package>
    # (setup.py's data_files), not beside the package: a campaign's `base: paper_3dof.yaml`,
    # vas compare, vas robustness and vas tune's default space must find them there
    from visual_adaptive_servo.models.resources import own_share, PACKAGE

    def install(prefix):
        site = prefix / "lib" / "python3.11" / "site-packages"
        site.mkdir(parents=True)
        share = prefix / "share" / PACKAGE
        (share / "config").mkdir(parents=True)
        (share / "urdf").mkdir()
        return site, share

    site, share = install(tmp_path / "install" / PACKAGE)
    assert own_share(str(site), environ={}, prefixes=[]) == {
        "urdf": str(share / "urdf"), "config": str(share / "config")}
    # a package found elsewhere (a --target folder): the ament index, as ROS resolves it
    other = tmp_path / "target"
    other.mkdir()
    prefix = tmp_path / "ros"
    _, ros_share = install(prefix)
    marker = prefix / "share" / "ament_index" / "resource_index" / "packages"
    marker.mkdir(parents=True)
    (marker / PACKAGE).write_text("")
    assert own_share(str(other), environ={"AMENT_PREFIX_PATH": str(prefix)},
                     prefixes=[])["config"] == str(ros_share / "config")
    # or pip's prefixes (sys.prefix, the user base)
    assert own_share(str(other), environ={}, prefixes=[str(prefix)])["config"] == str(
        ros_share / "config")
    # a checkout keeps its own folders, whatever is installed
    checkout = tmp_path / "checkout"
    (checkout / "config").mkdir(parents=True)
    assert own_share(str(checkout), environ={"AMENT_PREFIX_PATH": str(prefix)},
                     prefixes=[str(prefix)]) == {
        "urdf": str(checkout / "sim_bridge" / "urdf"), "config": str(checkout / "config")}
    # nothing anywhere: the checkout's places, which the error messages name
    assert own_share(str(other), environ={}, prefixes=[])["config"] == str(other / "config")


def test_vas_run_s_camera_options_tell_both_nodes_and_set_still_wins():
    # --camera-rate/--camera-latency once reached the simulator only: the controller kept
    # gains designed for a frame at every sample and a new arm diverged behind a 30 Hz camera
    from visual_adaptive_servo import cli

    iiwa = os.path.join(ROOT, "config", "iiwa_3points.yaml")

    def scenario(*options):
        args = cli.build_parser().parse_args(["run", "--config", iiwa, "--out", "unused",
                                              *options])
        return load_scenario(iiwa, cli._run_overrides(args))

    told = scenario("--camera-rate", "30", "--camera-latency", "0.033")
    assert told.sim.camera_rate == told.controller["camera_rate"] == 30.0
    assert told.sim.camera_latency == told.controller["camera_latency"] == 0.033
    # the derived gamma follows the camera's delay (gain_design.delay_bandwidth / tau)
    tau = told.controller["sample_time"] + 0.033 + 0.5 / 30.0
    assert told.controller["gamma"] == pytest.approx(0.15 / tau)
    assert scenario().controller["gamma"] == 20.0
    # a controller told another camera than the simulator's, on purpose
    other = scenario("--camera-rate", "30", "--set", "controller_node.camera_rate=60")
    assert other.sim.camera_rate == 30.0 and other.controller["camera_rate"] == 60.0


def test_image_bounds_left_out_are_the_guessed_camera_s_picture_in_its_pixels():
    # a file with top-left pixels (pixel_origin [0, 0]) once got centred bounds by default
    # and its start was refused as outside the image
    iiwa = os.path.join(ROOT, "config", "iiwa_3points.yaml")

    def without_bounds(params):
        del params["controller_node"]["image_bounds"]

    left_out = load_scenario(iiwa, edit=without_bounds).controller
    np.testing.assert_array_equal(left_out.image_bounds, [0.0, 640.0, 0.0, 480.0])
    turned = load_scenario(iiwa, ["controller_node.initial_estimate.camera.pixel_axes=[-1, 1]",
                                  "controller_node.initial_estimate.camera.image_size=[800, 600]",
                                  "controller_node.initial_estimate.camera.pixel_origin=[400, 0]"],
                           edit=without_bounds).controller
    np.testing.assert_array_equal(turned.image_bounds, [-400.0, 400.0, 0.0, 600.0])
    # the paper's camera (centred, both axes turned): the bounds the paper's files write
    paper = load_scenario(PAPER_CONFIG, edit=lambda p: p["controller_node"].pop(
        "image_bounds")).controller
    np.testing.assert_array_equal(paper.image_bounds, [-320.0, 320.0, -240.0, 240.0])
    # bounds written in another convention than the camera's: the message says which
    with pytest.raises(ConfigError, match=r"controller_node\.image_bounds \[-320\.0, 320\.0, "
                       r"-240\.0, 240\.0\]\); the simulated camera's picture is \[0\.0, 640\.0, "
                       r"0\.0, 480\.0\] in the controller's pixels"):
        load_scenario(iiwa, ["controller_node.image_bounds=[-320, 320, -240, 240]"])
    # left out, and the guess's pixel axis turned: the message names the guessed camera (it
    # said to leave out image_bounds, which was left out)
    with pytest.raises(ConfigError, match=r"image_bounds is initial_estimate\.camera's picture "
                       r"\(its image_size, pixel_origin, pixel_axes\), and the camera's pixels "
                       r"lie in \[0\.0, 640\.0, 0\.0, 480\.0\]: give the guessed camera "
                       r"your camera's pixel_origin and pixel_axes"):
        load_scenario(iiwa, ["controller_node.initial_estimate.camera.pixel_axes=[1, -1]"],
                      edit=without_bounds)
