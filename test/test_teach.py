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

"""``vas teach``: the taught table against the chain's own kinematics, and the joint limits."""

import math
import os

import numpy as np
import pytest

from visual_adaptive_servo.cli import main
from visual_adaptive_servo.config.files import apply_overrides, read_param_file
from visual_adaptive_servo.config.sim import SimConfig
from visual_adaptive_servo.control.trajectory import TabulatedTrajectory
from visual_adaptive_servo.teach import joint_path, teach

BOOM = os.path.join(os.path.dirname(__file__), "..", "docs", "examples", "boom", "boom.yaml")


def boom_sim(*overrides):
    sections = apply_overrides(read_param_file(BOOM), list(overrides))
    return SimConfig.from_params(sections["sim_node"],
                                 search_dirs=(os.path.dirname(os.path.abspath(BOOM)),))


def test_table_is_the_chain_seen_by_the_camera():
    """Pixels recorded through PyBullet equal the URDF chain's own kinematics projected."""
    sim = boom_sim()
    amplitudes = [0.2, -0.3, 0.2, 0.5]
    t, pixels = teach(sim, duration=4.0, amplitudes=amplitudes, cycles=[1, 2, 1, 2], rate=10.0)
    assert t.shape == (41,) and pixels.shape == (41, 2)
    path = joint_path(sim.initial_positions, amplitudes, [1, 2, 1, 2], 4.0)
    for k in (0, 7, 13, 20, 33):
        expected, _ = sim.camera.project(sim.arm.chain.points(path(t[k]), sim.arm.offsets))
        np.testing.assert_allclose(pixels[k], expected, atol=1e-6)
    np.testing.assert_array_equal(pixels[-1], pixels[0])        # one period, closed
    # joint 2 (amplitude -0.3) goes below its start: the sign gives the direction
    q = np.array([path(tk) for tk in np.linspace(0.0, 4.0, 401)])
    assert q[:, 1].min() == pytest.approx(sim.initial_positions[1] - 0.3, abs=1e-4)
    assert q[:, 1].max() == pytest.approx(sim.initial_positions[1])


def test_path_past_a_joint_limit_is_refused_with_amplitudes_that_fit():
    sim = boom_sim()                    # 'extend' starts at 0.05 m, limits [-0.3, 0.3] m
    with pytest.raises(ValueError) as excinfo:
        teach(sim, duration=2.0, amplitudes=0.3, rate=10.0)
    message = str(excinfo.value)
    assert "joint 'extend' from 0.05 to 0.35 m, past its URDF upper limit 0.3 m" in message
    assert "'swing'" not in message and "'lift'" not in message
    suggested = [float(a) for a in message.split("--amplitude ")[1].split(",")]
    assert suggested == [0.3, 0.3, -0.3, 0.3]     # the same size, the way with room
    t, pixels = teach(sim, duration=2.0, amplitudes=suggested, rate=10.0)
    assert np.all(np.isfinite(pixels))
    # no room either way for the size asked: 90 % of the larger room, named per joint
    with pytest.raises(ValueError, match=r"joint 'lift' from 0.4 to 2.9 rad.*joint 'extend'"
                       r".*--amplitude 0.3,-2.16,-0.315,0.3$"):
        teach(sim, duration=2.0, amplitudes=[0.3, 2.5, -0.4, 0.3], rate=10.0)


def test_start_outside_the_joint_limits_is_refused():
    sim = boom_sim("sim_node.initial_positions=[0.3, 0.4, 0.35, 0.5]")
    with pytest.raises(ValueError, match=r"joint 'extend' starts at 0.35 m, outside its URDF "
                       r"limits \[-0.3, 0.3\] m \(sim_node.initial_positions\)"):
        teach(sim, duration=2.0, amplitudes=-0.1, rate=10.0)


def test_cli_writes_a_table_the_controller_reads(tmp_path, capsys):
    out = tmp_path / "taught.csv"
    assert main(["teach", "--config", BOOM, "--out", str(out), "--duration", "3",
                 "--amplitude", "0.1", "--rate", "20"]) == 0
    assert (tmp_path / "taught.png").stat().st_size > 0
    assert "taught 61 samples over 3 s for 1 point(s)" in capsys.readouterr().out
    trajectory = TabulatedTrajectory.from_csv(out, 1)
    assert trajectory.periodic
    x0 = trajectory(0.0)[0]
    sim = boom_sim()
    start, _ = sim.camera.project(sim.arm.chain.points(sim.initial_positions, sim.arm.offsets))
    np.testing.assert_allclose(x0, start, atol=1e-6)           # starts where the arm is
    np.testing.assert_allclose(trajectory(3.0)[0], x0, atol=1e-9)
    assert math.isclose(trajectory.t_end, 3.0)


def test_cli_names_the_joint_past_its_limit(tmp_path, capsys):
    assert main(["teach", "--config", BOOM, "--out", str(tmp_path / "x.csv"), "--duration", "2",
                 "--amplitude", "0.3", "--rate", "10"]) == 2
    assert ("vas: invalid configuration: vas teach: the taught path moves joint 'extend'"
            in capsys.readouterr().err)
    assert list(tmp_path.iterdir()) == []                       # nothing written


def test_a_path_that_reaches_a_joint_limit_is_refused_too():
    # from a new user's trial: a prismatic joint taught from 0.1 m by 0.15 m reached its
    # 0.25 m limit exactly, and the tracking then pushed it into the end stop for seconds
    sim = boom_sim()                    # 'extend' starts at 0.05 m, limits [-0.3, 0.3] m
    with pytest.raises(ValueError, match=r"joint 'extend' from 0.05 to 0.3 m, within 5% of the "
                       r"room to its URDF upper limit 0.3 m"):
        teach(sim, duration=2.0, amplitudes=[0.0, 0.0, 0.25, 0.0], rate=10.0)
    t, pixels = teach(sim, duration=2.0, amplitudes=[0.0, 0.0, 0.23, 0.0], rate=10.0)
    assert np.all(np.isfinite(pixels))           # 0.28 m: 8 % of the room left
