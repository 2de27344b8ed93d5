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

"""Arms the package has never seen: a random serial arm, a guessed camera, a taught path.

What a new user brings, drawn at random from a seed, so that the defaults are measured
on arms nobody tuned them for (benchmarks/unseen_arms.py runs many):

* a chain of 3-6 joints on a tilted mount: the first about z, the others about a random
  axis of their frame with random fixed rotations between them, one of them prismatic
  in three arms of ten; links 0.08-0.4 m long, box-shaped masses halving outward;
  the URDF's effort limits fall from 150 N m at the base;
* 1-3 feature points on the last link, 3-10 cm from its frame (2m <= n);
* a camera 1.2-2.5 m from the arm, looking at its workspace;
* the controller's guess of the camera: moved by 0.15 m (each axis, normal) and aimed
  0.1 m off, focal length x0.8-1.25, each pixel scale x0.9-1.1; lengths x0.8-1.25 and
  inertial parameters x0.5-2 (``initial_estimate``); ``guess_scale`` g multiplies each
  of these kinematic errors (the moves, and each factor's distance from 1: g = 2 gives
  0.3 m, focal length x0.6-1.5, lengths x0.6-1.5), the same draws otherwise;
* the desired trajectory taught on the simulated arm (:func:`..teach.teach`: each joint
  0.15 rad around the start over 20 s), so that the points can follow it.

No gain is written: what runs is the defaults.  A draw is kept when the whole taught
path stays in the picture, the scenario passes every start check of
:func:`..config.scenario.load_scenario`, and the true J(q0, x0) has a condition number
below :data:`MAX_CONDITION`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import yaml

from ..config.files import flatten
from ..config.scenario import load_scenario
from ..config.sim import SimConfig
from ..schema import ConfigError, CONTROLLER_SECTION, SIM_SECTION
from ..teach import teach, write_table

#: a draw whose true J(q0, x0) is worse conditioned than this is drawn again
MAX_CONDITION = 300.0
#: taught joint amplitude [rad] (prismatic joints: this x 0.3 m/rad) and period [s]
TAUGHT_AMPLITUDE = 0.15
TAUGHT_PERIOD = 20.0


@dataclass(frozen=True)
class UnseenArm:
    """One drawn arm: its scenario file and what it is."""

    path: str                   # the scenario YAML (the URDF and trajectory beside it)
    seed: int
    n: int
    m: int
    prismatic: bool
    condition: float            # of the true J(q0, x0)


def _vec(values):
    return " ".join(f"{v:.4f}" for v in values)


def _box_inertia(mass, size):
    a, b, c = size
    return (mass * (b * b + c * c) / 12.0, mass * (a * a + c * c) / 12.0,
            mass * (a * a + b * b) / 12.0)


def _urdf(rng, name, n):
    """URDF text, tip link, rough reach [m], which joints slide."""
    rows = ['<link name="world"/>',
            f'<joint name="mount" type="fixed"><parent link="world"/><child link="base"/>'
            f'<origin xyz="0 0 {rng.uniform(0.0, 0.3):.3f}" '
            f'rpy="{_vec(rng.uniform(-0.4, 0.4, 3))}"/></joint>',
            '<link name="base"><inertial><origin xyz="0 0 0"/><mass value="4.0"/>'
            '<inertia ixx="0.03" iyy="0.03" izz="0.03" ixy="0" ixz="0" iyz="0"/>'
            "</inertial></link>"]
    slides = rng.integers(0, n) if rng.random() < 0.3 else -1
    parent, reach, prismatic = "base", 0.0, []
    for j in range(n):
        child = f"link{j + 1}"
        if j == 0:
            axis, offset = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, rng.uniform(0.05, 0.15)])
        else:
            axis = np.eye(3)[rng.integers(0, 3)]
            length = rng.uniform(0.08, 0.4) * (1.0 if j < n - 2 else 0.6)
            offset = (np.array([length, 0.0, 0.0]) if rng.random() < 0.7
                      else np.array([0.0, 0.0, length]))
        reach += float(np.linalg.norm(offset))
        rpy = rng.uniform(-0.5, 0.5, 3) if rng.random() < 0.5 else np.zeros(3)
        mass = rng.uniform(0.3, 4.0) * 0.6 ** j
        size = (rng.uniform(0.08, 0.3), rng.uniform(0.03, 0.08), rng.uniform(0.03, 0.08))
        ixx, iyy, izz = _box_inertia(mass, size)
        if j == slides:
            kind, limits, effort = "prismatic", 'lower="-0.3" upper="0.3"', 200.0
        else:
            kind, limits, effort = ("revolute", 'lower="-2.8" upper="2.8"',
                                    float(round(max(5.0, 150.0 * 0.55 ** j))))
        prismatic.append(kind == "prismatic")
        rows.append(f'<joint name="j{j + 1}" type="{kind}"><parent link="{parent}"/>'
                    f'<child link="{child}"/><origin xyz="{_vec(offset)}" rpy="{_vec(rpy)}"/>'
                    f'<axis xyz="{_vec(axis)}"/><limit {limits} effort="{effort:g}" '
                    'velocity="3"/></joint>')
        rows.append(f'<link name="{child}"><inertial><origin xyz="{size[0] / 2:.3f} 0 0"/>'
                    f'<mass value="{mass:.4f}"/><inertia ixx="{ixx:.6g}" iyy="{iyy:.6g}" '
                    f'izz="{izz:.6g}" ixy="0" ixz="0" iyz="0"/></inertial></link>')
        parent = child
    text = (f'<?xml version="1.0"?>\n<robot name="{name}">\n  ' + "\n  ".join(rows)
            + "\n</robot>\n")
    return text, parent, reach, prismatic


def _camera(position, target, focal_length, pixel_scale):
    return {"position": [float(v) for v in position], "orientation": "look_at",
            "look_at": [float(v) for v in target], "up": [0.0, 0.0, 1.0],
            "focal_length": float(focal_length), "pixel_scale": [float(s) for s in pixel_scale],
            "principal_point": [320.0, 240.0], "image_size": [640.0, 480.0],
            "pixel_origin": [0.0, 0.0], "pixel_axes": [1.0, 1.0]}


def _draw(rng, name, guess_scale=1.0):
    """One candidate: (urdf text, sim section, controller section) without a trajectory."""
    g = float(guess_scale)

    def off(factor):
        """A guess's factor with its distance from 1 times g (the same draw at g = 1)."""
        return 1.0 + g * (factor - 1.0)

    n = int(rng.integers(3, 7))
    m = int(min(3, rng.integers(1, n // 2 + 1)))
    urdf, tip, reach, prismatic = _urdf(rng, name, n)
    points = []
    for _ in range(m):
        offset = rng.normal(size=3)
        points += (offset / np.linalg.norm(offset) * rng.uniform(0.03, 0.1)).tolist()
    q0 = rng.uniform(-0.8, 0.8, n)
    q0[np.array(prismatic)] *= 0.3 / 0.8 * 0.5        # a slide starts within +-0.15 m
    target = np.array([0.4 * reach, 0.0, 0.3 + 0.3 * reach]) + rng.normal(0.0, 0.05, 3)
    distance, azimuth, elevation = (rng.uniform(1.2, 2.5), rng.uniform(-np.pi, np.pi),
                                    rng.uniform(0.1, 0.7))
    position = target + distance * np.array([np.cos(elevation) * np.cos(azimuth),
                                             np.cos(elevation) * np.sin(azimuth),
                                             np.sin(elevation)])
    focal, scale = rng.uniform(0.006, 0.012), 1e5
    camera = _camera(position, target, focal, (scale, scale))
    guess = _camera(position + g * rng.normal(0.0, 0.15, 3),
                    target + g * rng.normal(0.0, 0.1, 3),
                    focal * off(rng.uniform(0.8, 1.25)), scale * off(rng.uniform(0.9, 1.1, 2)))
    urdf_file = f"{name}.urdf"
    sim = {"urdf": urdf_file, "base_link": "world", "tip_link": tip,
           "feature_points": points, "physics_dt": 0.001, "control_period": 0.001,
           "duration": 30.0, "initial_positions": q0.tolist(), "camera": camera}
    controller = {"model": "urdf", "urdf": urdf_file, "base_link": "world", "tip_link": tip,
                  "feature_points": points, "unknown_lengths": ["all"], "sample_time": 0.001,
                  "camera_rate": 0.0, "camera_latency": 0.0,
                  "initial_estimate": {"camera": guess,
                                       "length_scale": float(off(rng.uniform(0.8, 1.25))),
                                       "inertia_scale": float(rng.uniform(0.5, 2.0))},
                  "image_bounds": [0.0, 640.0, 0.0, 480.0]}
    return urdf, sim, controller, n, m, any(prismatic)


def random_arm(seed, folder, attempts=200, guess_scale=1.0):
    """Draw the arm of ``seed`` into ``folder``; return its :class:`UnseenArm`.

    Writes ``arm<seed>.urdf``, ``arm<seed>.yaml`` and ``arm<seed>_trajectory.csv``.  The
    same seed gives the same arm.  ``guess_scale`` multiplies the initial estimate's
    kinematic errors (module docstring).  Raises RuntimeError when no draw passes in
    ``attempts``.
    """
    os.makedirs(folder, exist_ok=True)
    rng = np.random.default_rng(seed)
    name = f"arm{seed}"
    path = os.path.join(folder, f"{name}.yaml")
    for _ in range(attempts):
        urdf, sim, controller, n, m, prismatic = _draw(rng, name, guess_scale)
        with open(os.path.join(folder, f"{name}.urdf"), "w", encoding="utf-8") as handle:
            handle.write(urdf)
        try:
            sim_config = SimConfig.from_params(flatten(sim), search_dirs=(folder,))
            # (no headroom: the draws the benchmark was measured on; with vas teach's, the
            # held-out arm 105 is another arm)
            t, pixels = teach(sim_config, TAUGHT_PERIOD, TAUGHT_AMPLITUDE, headroom=0.0)
        except (ConfigError, ValueError):
            continue
        table = f"{name}_trajectory.csv"
        write_table(os.path.join(folder, table), t, pixels)
        controller["trajectory"] = {"type": "table", "file": table}
        with open(path, "w", encoding="utf-8") as handle:
            yaml.safe_dump({SIM_SECTION: {"ros__parameters": sim},
                            CONTROLLER_SECTION: {"ros__parameters": controller}}, handle,
                           sort_keys=False)
        try:
            scenario = load_scenario(path)
        except (ConfigError, ValueError):
            continue
        model = scenario.controller.model
        q0 = np.asarray(sim["initial_positions"])
        x0, _ = model.project(q0)
        sigma = np.linalg.svd(model.true_image_jacobian(q0, x0), compute_uv=False)
        condition = float(sigma[0] / sigma[-1]) if sigma[-1] > 0.0 else np.inf
        if condition <= MAX_CONDITION:
            return UnseenArm(path, int(seed), n, m, prismatic, condition)
    raise RuntimeError(f"unseen arm {seed}: no draw passed the start checks in {attempts} "
                       "attempts")
