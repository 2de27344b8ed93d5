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

"""``vas teach``: teach by showing -- a desired image trajectory the arm can realise.

With m > 1 feature points an arbitrary image curve is not realisable (three
points fix a pose).  A user with a real arm moves it along a smooth path and
records what the camera sees; this does the same with the simulated arm and
camera of a parameter file.  The joint path starts at rest at
``sim_node.initial_positions`` and is periodic with period ``duration``::

    q_j(t) = q0_j + a_j sin^2(pi k_j t / T)

(amplitudes a_j, whole numbers of cycles k_j), so the recorded table is a
periodic, C2 trajectory that starts exactly where the arm starts.  Joint j
sweeps [q0_j, q0_j + a_j] (a negative amplitude moves it the other way), which
must lie within the URDF's ``<limit lower upper>``: a path past a limit is
refused, naming the joint, with amplitudes that fit (a real arm stops at its end
stop, and PyBullet stops the simulated one there too).  The output is
the CSV read by ``trajectory.type: table`` (t, u1, v1, ..., um, vm) and a PNG of
the taught image paths.
"""

from __future__ import annotations

import math
import os

import numpy as np

from .config.files import apply_overrides, read_param_file
from .config.sim import SimConfig
from .schema import ConfigError, SIM_SECTION


def joint_path(q0, amplitudes, cycles, period):
    """q(t) of the taught path (a function of t returning (n,))."""
    q0, a, k = (np.asarray(v, dtype=float) for v in (q0, amplitudes, cycles))

    def q(t):
        return q0 + a * np.sin(math.pi * k * t / period) ** 2
    return q


#: the share of the room between the start and a joint limit a taught path leaves free
HEADROOM = 0.05


def check_joint_limits(chain, q0, amplitudes, headroom=HEADROOM):
    """Raise ValueError when the taught path takes a joint past its URDF position limits.

    Or to within ``headroom`` of the room to one: a path that reaches a limit puts the
    arm on its end stop as soon as the tracking overshoots it.

    Joint j sweeps [q0_j, q0_j + a_j] (the sin^2 reaches 1 in every cycle).  The message
    names each joint that leaves its range and ends with an ``--amplitude`` list that
    fits: the same size in the direction that has room, else 90 % of the larger room.
    """
    q0 = np.asarray(q0, dtype=float)
    problems, fitting = [], []
    for joint, start, a in zip(chain.joints, q0.tolist(), np.asarray(amplitudes).tolist()):
        unit = "m" if joint.prismatic else "rad"
        if not joint.lower <= start <= joint.upper:
            raise ValueError(f"joint {joint.name!r} starts at {start:g} {unit}, outside its URDF "
                             f"limits [{joint.lower:g}, {joint.upper:g}] {unit} "
                             f"(sim_node.initial_positions)")
        end = start + a
        room_up, room_down = joint.upper - start, start - joint.lower
        # the tracking overshoots the path: it keeps headroom of the room to a limit
        if -(1.0 - headroom) * room_down <= a <= (1.0 - headroom) * room_up:
            fitting.append(a)
            continue
        side, limit = ("upper", joint.upper) if a > 0.0 else ("lower", joint.lower)
        where = ("past" if not joint.lower <= end <= joint.upper
                 else f"within {headroom:.0%} of the room to")
        problems.append(f"joint {joint.name!r} from {start:g} to {end:g} {unit}, {where} its "
                        f"URDF {side} limit {limit:g} {unit} (room: {room_up:.4g} {unit} up, "
                        f"{room_down:.4g} {unit} down)")
        if a > 0.0:
            fitting.append(-a if (1.0 - headroom) * room_down >= a else
                           0.9 * (room_up if room_up >= room_down else -room_down))
        else:
            fitting.append(-a if (1.0 - headroom) * room_up >= -a else
                           0.9 * (-room_down if room_down >= room_up else room_up))
    if problems:
        raise ValueError("the taught path moves " + "; ".join(problems) + ". Amplitudes that "
                         "fit: --amplitude " + ",".join(f"{a:.4g}" for a in fitting))


def teach(sim_config, duration=20.0, amplitudes=0.25, cycles=None, rate=100.0,
          headroom=HEADROOM):
    """Move the simulated arm along the taught path; return (t (N,), pixels (N, 2m)).

    Raises ValueError when a joint would pass its URDF position limits or come within
    ``headroom`` (default :data:`HEADROOM`) of the room to one (:func:`check_joint_limits`),
    or a point leaves the picture or goes behind the camera.
    """
    from sim_bridge.plant import ArmPlant
    from .models import GRAVITY

    arm = sim_config.arm
    n = arm.n
    amplitudes = np.broadcast_to(np.asarray(amplitudes, dtype=float), (n,))
    cycles = (np.array([1 + (j % 2) for j in range(n)]) if cycles is None
              else np.broadcast_to(np.asarray(cycles, dtype=float), (n,)))
    if np.any(cycles != np.round(cycles)) or np.any(cycles < 1):
        raise ValueError(f"cycles: whole numbers >= 1 per joint, got {list(cycles)}")
    if not duration > 0.0 or not rate > 0.0:
        raise ValueError(f"duration and rate must be > 0, got {duration} and {rate}")
    check_joint_limits(arm.chain, sim_config.initial_positions, amplitudes, headroom)
    path = joint_path(sim_config.initial_positions, amplitudes, cycles, duration)
    times = np.linspace(0.0, duration, int(round(duration * rate)) + 1)
    camera = sim_config.camera
    u0, u1, v0, v1 = camera.image_bounds
    rows = []
    with ArmPlant(arm.chain.urdf, sim_config.physics_dt, GRAVITY, arm.chain.tip_link,
                  arm.chain.joint_names, arm.offsets) as plant:
        for t in times:
            plant.reset(path(t))
            pixels, depth = camera.project(plant.feature_positions())
            uv = pixels.reshape(-1, 2)
            if min(depth.tolist()) <= 0.0:
                raise ValueError(f"the taught path puts a feature point behind the camera at "
                                 f"t={t:.2f} s; reduce the amplitudes")
            if np.any((uv[:, 0] < u0) | (uv[:, 0] > u1) | (uv[:, 1] < v0) | (uv[:, 1] > v1)):
                raise ValueError(f"the taught path leaves the picture at t={t:.2f} s (pixels "
                                 f"{np.round(pixels, 1).tolist()}, bounds "
                                 f"{camera.image_bounds.tolist()}); reduce the amplitudes")
            rows.append(pixels)
    pixels = np.array(rows)
    pixels[-1] = pixels[0]      # q(T) = q(0): close the period exactly
    return times, pixels


def write_table(path, t, pixels):
    """The CSV of ``trajectory.type: table``: header t,u1,v1,... then one row per sample."""
    m = pixels.shape[1] // 2
    header = ["t"] + [f"{axis}{i + 1}" for i in range(m) for axis in "uv"]
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(",".join(header) + "\n")
        for ti, row in zip(t, pixels):
            handle.write(",".join([f"{ti:.6f}"] + [f"{v:.9f}" for v in row]) + "\n")


def plot_table(path, t, pixels, bounds):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 5))
    for i in range(pixels.shape[1] // 2):
        ax.plot(pixels[:, 2 * i], pixels[:, 2 * i + 1], lw=1, label=f"point {i + 1}")
        ax.plot(pixels[0, 2 * i], pixels[0, 2 * i + 1], "go")
    u0, u1, v0, v1 = bounds
    ax.plot([u0, u1, u1, u0, u0], [v0, v0, v1, v1, v0], "k:", lw=0.8, label="picture")
    ax.set(xlabel="u [px]", ylabel="v [px]",
           title=f"taught image trajectory, {t[-1]:g} s (green: start)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def cmd_teach(args):
    """``vas teach``: write the taught table and its plot."""
    sections = apply_overrides(read_param_file(args.config), args.set or [])
    search_dirs = (os.path.dirname(os.path.abspath(args.config)),)
    sim = SimConfig.from_params(sections[SIM_SECTION], search_dirs=search_dirs)
    try:
        t, pixels = teach(sim, args.duration, args.amplitude, args.cycles, args.rate)
    except ValueError as exc:
        raise ConfigError(f"vas teach: {exc}") from None
    folder = os.path.dirname(os.path.abspath(args.out))
    os.makedirs(folder, exist_ok=True)
    write_table(args.out, t, pixels)
    png = plot_table(os.path.splitext(args.out)[0] + ".png", t, pixels, sim.image_bounds)
    print(f"taught {len(t)} samples over {t[-1]:g} s for {pixels.shape[1] // 2} point(s): "
          f"{args.out}, {png}")
    return 0


def add_parser(subparsers, floats):
    """Register ``vas teach`` (called by :func:`visual_adaptive_servo.cli.build_parser`)."""
    p = subparsers.add_parser("teach", help="record a realisable image trajectory by moving the "
                              "simulated arm (teach by showing)")
    p.add_argument("--config", required=True, help="parameter YAML (its sim_node section: arm, "
                   "feature points, camera, initial_positions)")
    p.add_argument("--out", required=True, help="CSV to write (a PNG of it is written beside)")
    p.add_argument("--duration", type=float, default=20.0,
                   help="period of the taught path [s] (the table repeats with it)")
    p.add_argument("--amplitude", type=floats, default=[0.25], metavar="A[,A...]",
                   help="joint amplitudes [rad or m]: one for all joints or one per joint; "
                   "joint j moves from its initial position to that plus its amplitude (a "
                   "negative one moves it the other way), within its URDF limits")
    p.add_argument("--cycles", type=floats, default=None, metavar="K[,K...]",
                   help="whole cycles per period, per joint (default 1, 2, 1, 2, ...)")
    p.add_argument("--rate", type=float, default=100.0, help="samples per second in the table")
    p.add_argument("--set", action="append", metavar="sim_node.PARAM=VALUE",
                   help="override a parameter (repeatable)")
    p.set_defaults(func=cmd_teach)
    return p
