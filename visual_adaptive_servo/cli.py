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

"""``vas``: the command line tool.

``vas run`` runs the closed loop (PyBullet arm + camera + controller) in one
process, without ROS, and writes summary.json, timeseries.csv, PNG plots and a
rosbag2 MCAP file.  ``vas teach`` records a realisable desired trajectory,
``vas robustness`` and ``vas compare`` run the robustness matrix and the
comparison with the baselines, ``vas campaign`` a campaign spec, ``vas tune``
searches the gains for a configuration (Optuna, an optional extra).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys

from .campaigns.campaign import add_parser as add_campaign_parser
from .campaigns.compare import add_parser as add_compare_parser
from .campaigns.tune import add_parser as add_tune_parser
from .config.scenario import load_scenario
from .control.registry import CONTROLLER_NAMES, controller_factory
from .models.backend import NOTICE_LOGGER
from .schema import ConfigError
from .teach import add_parser as add_teach_parser


def _floats(text):
    try:
        return [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated numbers, got {text!r}") from None


def _positive(text):
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (value > 0.0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _run_overrides(args):
    """The parameter overrides of ``vas run``'s options; ``--set`` comes last, so it wins.

    ``--camera-rate`` and ``--camera-latency`` describe the camera, so both nodes get them:
    the simulator makes its frames so, and the controller derives its gains for them
    (``controller_node.camera_rate``, ``camera_latency``), as a user writes them into both
    sections of a file.  A controller told another camera is ``--set controller_node...``.
    """
    overrides = []
    if args.initial_positions is not None:
        overrides.append(f"sim_node.initial_positions={args.initial_positions}")
    if args.pixel_noise is not None:
        overrides.append(f"sim_node.pixel_noise_std={args.pixel_noise}")
    if args.seed is not None:
        overrides.append(f"sim_node.seed={args.seed}")
    for option, name in ((args.camera_rate, "camera_rate"),
                         (args.camera_latency, "camera_latency")):
        if option is not None:
            overrides += [f"sim_node.{name}={option}", f"controller_node.{name}={option}"]
    return overrides + list(args.set or [])


def cmd_run(args):
    from .runner import run_scenario

    scenario = load_scenario(args.config, _run_overrides(args))
    summary = run_scenario(scenario, args.out, duration=args.duration, progress=args.progress,
                           record=not args.no_bag,
                           controller_factory=controller_factory(args.controller),
                           announce=print)
    print(json.dumps({k: summary[k] for k in (
        "diverged", "final_rms_error_px", "max_error_px", "final_rms_true_error_px",
        "max_abs_torque", "final_depth_error", "sim_time_s", "wall_time_s", "realtime_factor")},
        indent=2))
    print(f"outputs in {args.out}: {', '.join(summary['outputs'])}")
    if summary["diverged"]:
        print(f"DIVERGED: {summary['divergence_reason']}", file=sys.stderr)
    untracked = _untracked(summary)
    if untracked:
        print(f"NOT TRACKING: {untracked}", file=sys.stderr)
    if summary.get("joint_limit_excursions"):
        print(f"JOINT LIMITS: a joint went past its URDF position limit "
              f"{summary['joint_limit_excursions']} time(s); `vas -v run ...` names them",
              file=sys.stderr)
    if summary.get("error"):
        print(f"FAILED: {summary['error']}", file=sys.stderr)
    if summary.get("interrupted"):
        return 130
    return 1 if summary["diverged"] or summary.get("error") or untracked else 0


#: a run that ends this long without the law computing a sample did not track [s]
UNTRACKED_END_S = 1.0


def _untracked(summary):
    """Why a run that did not diverge did not track either ('' when it did).

    Every sample rejected (held, then the fallback), or none since ``UNTRACKED_END_S``
    before the end: a camera whose points were never or no longer seen, joint states
    refused, ...; the warnings above it name each kind of rejection (``vas -v run``: the
    wait for a first frame too).
    """
    if summary["diverged"] or not summary.get("steps"):
        return ""
    last, end = summary.get("last_tracked_t", math.nan), summary["sim_time_s"]
    if math.isfinite(last) and end - last <= UNTRACKED_END_S:
        return ""
    frames = ""
    if "frames_applied" in summary:
        frames = (f"; camera frames: {summary['frames_published']} published, "
                  f"{summary['frames_applied']} applied")
    if summary.get("frames_without_features"):
        frames += (f", {summary['frames_without_features']} pictures without features "
                   f"{summary['frames_without_features_by_reason']}")
    when = ("every sample was rejected" if not math.isfinite(last)
            else f"no sample tracked after t={last:.3f} s of {end:.3f} s")
    return (f"{when} (held, then the fallback torque){frames}; the warnings above name each "
            f"kind of rejection (`vas -v run ...`: the wait for a first frame too)")


def cmd_robustness(args):
    import os

    from .campaigns.robustness import markdown_table, outside_bounds, run_matrix

    rows = run_matrix(args.out, args.workers, args.ray, args.duration, args.progress)
    table = markdown_table(rows)
    title = (f"{args.duration:g} s per case" if args.duration
             else "config/campaigns/robustness.yaml, 10 s per case")
    with open(os.path.join(args.out, "robustness.md"), "w", encoding="utf-8") as handle:
        handle.write(f"# Robustness matrix ({title})\n\n{table}\n")
    print(table)
    failed = outside_bounds(rows)
    if failed:
        print(f"outside their bounds: {failed}", file=sys.stderr)
    return 1 if failed else 0


def cmd_report(args):
    import os

    from .recording.bag_report import BagError, read_bag, report_lines, write_report

    bag = os.path.normpath(args.bag)
    stem, suffix = os.path.splitext(bag)
    out = args.out or f"{stem if suffix in ('.mcap', '.db3') else bag}_report"
    try:
        figures = write_report(read_bag(bag), out, args.window)
    except BagError as exc:
        print(f"vas: {exc}", file=sys.stderr)
        return 2
    print("\n".join(report_lines(figures)))
    print(f"outputs in {out}: {', '.join(figures['outputs'])}")
    return 0


def build_parser():
    parser = argparse.ArgumentParser(prog="vas", description=__doc__.split("\n\n")[0])
    parser.add_argument("-v", "--verbose", action="store_true",
                        help="log at INFO (vas run logs warnings without it, the other "
                        "commands errors only)")
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run the closed loop without ROS and record it")
    run.add_argument("--config", required=True, help="ROS parameter YAML (sim_node + "
                     "controller_node), e.g. config/paper_3dof.yaml")
    run.add_argument("--out", required=True, help="output folder (created)")
    run.add_argument("--duration", type=float,
                     help="simulated seconds (default: sim_node.duration)")
    run.add_argument("--initial-positions", type=_floats, metavar="A,B,C",
                     help="joint positions at start [rad]")
    run.add_argument("--pixel-noise", type=float, metavar="STD", help="pixel noise std [px]")
    run.add_argument("--camera-rate", type=float, metavar="HZ",
                     help="camera frames per second (0: one per control period), for the "
                          "simulator and the controller's derived gains (sim_node. and "
                          "controller_node.camera_rate)")
    run.add_argument("--camera-latency", type=float, metavar="S",
                     help="camera latency from capture to publication [s], for the simulator "
                          "and the controller's derived gains (both nodes' camera_latency)")
    run.add_argument("--seed", type=int, help="noise seed")
    run.add_argument("--set", action="append", metavar="NODE.PARAM=VALUE",
                     help="override a parameter, e.g. controller_node.alpha=12 (repeatable; "
                          "it wins over the options above)")
    run.add_argument("--controller", choices=CONTROLLER_NAMES, default=CONTROLLER_NAMES[0],
                     help="the paper's observer-based controller (default) or a baseline of "
                     "vas compare")
    run.add_argument("--no-bag", action="store_true", help="do not write run.mcap")
    run.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                     help="progress bar (default: on a terminal)")
    run.set_defaults(func=cmd_run)
    rob = sub.add_parser("robustness", help="run the robustness matrix (a campaign) and write "
                         "its table")
    rob.add_argument("--out", required=True, help="output folder (created; rerun to resume)")
    rob.add_argument("--duration", type=float,
                     help="simulated seconds per case (default: the spec's, 10 s)")
    rob.add_argument("--workers", type=int, help="worker processes (default: every core)")
    rob.add_argument("--ray", metavar="auto|ADDRESS", help="run on Ray (pip install '.[ray]')")
    rob.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                     help="progress bar (default: on a terminal)")
    rob.set_defaults(func=cmd_robustness)
    report = sub.add_parser(
        "report", help="the figures and plots of a recorded run: a ros2 bag record folder "
        "or vas run's run.mcap")
    report.add_argument("bag", help="rosbag2 folder (ros2 launch ... record:=true, ros2 bag "
                        "record) or .mcap file")
    report.add_argument("--out", help="output folder for report.json and the PNGs (default: "
                        "BAG_report beside the bag)")
    report.add_argument("--window", type=_positive, default=5.0, metavar="S",
                        help="the final RMS errors over the last S seconds (default 5, as "
                        "vas run's summary.json)")
    report.set_defaults(func=cmd_report)
    add_compare_parser(sub)
    add_teach_parser(sub, _floats)
    add_campaign_parser(sub)
    add_tune_parser(sub)
    return parser


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "run":
        # one run: its warnings (a start check, a joint past its limit, a stale camera, a
        # capped fallback) are printed, above the progress bar; many runs: errors only
        from .runner import LogAboveProgress
        level, handlers = logging.WARNING, [LogAboveProgress(sys.stderr)]
    else:
        level, handlers = logging.ERROR, None
    logging.basicConfig(level=logging.INFO if args.verbose else level, handlers=handlers,
                        format="%(levelname)s %(name)s: %(message)s")
    # a first start compiles for half a minute: say so, -v or not (models/backend.py)
    logging.getLogger(NOTICE_LOGGER).setLevel(logging.INFO)
    try:
        return args.func(args)
    except ConfigError as exc:
        print(f"vas: invalid configuration: {exc}", file=sys.stderr)
        return 2
    except FileNotFoundError as exc:
        print(f"vas: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
