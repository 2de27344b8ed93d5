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

"""The figures and plots of a recorded run: ``vas report BAG`` (rosbags, numpy).

A run through ROS writes no summary.json and no PNG: its record is the bag
(``ros2 launch ... record:=true``, or ``ros2 bag record`` beside a real arm).
:func:`read_bag` reads a rosbag2 folder (MCAP or SQLite storage) or a single
``.mcap`` file (``vas run``'s run.mcap) and :func:`bag_figures` computes from it
what summary.json holds of the tracking, with the same definitions
(:mod:`.summary`), plus what only a bag shows: the joint states' and the camera
frames' largest gaps, the commands per joint state, and every
``/diagnostics`` status that was not OK.

What a bag cannot have is the true error: the camera's pixels carry their
noise, and the figures are of the error the controller published
(``/controller_node/tracking_error``, x - x_d), as summary.json's
``final_rms_error_px`` is.  ``final_depth_error`` needs the simulator's
``/sim_node/true_depth``.

Times are header stamps in seconds: as they are when they are simulated time
(under 10^6 s: a simulator's clock starts at 0), else from the first joint
state (a real arm's wall clock).  A Float64MultiArray has no header: it gets
the stamp of the message its node published with it (``~/observed`` for the
controller's, ``/joint_states`` for the simulator's): one for one when the two
topics hold as many messages, else matched by the time the recorder received
them (``lost_messages`` names an array topic with fewer messages than the one it is
always published with).  Those receive times (the recorder's clock) also give
each topic's largest gap as the recorder saw it: a simulator or controller
that stalls in real time keeps its stamps regular, not its arrivals.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import messages as m
from .recorder import CONTROLLER_NS, SIM_NS
from .summary import RMS_WINDOW_S, desired_at, error_figures

JOINT_STATES = "/joint_states"
FEATURES = "/camera/features"
COMMANDS = "/effort_controller/commands"
TRUE_DEPTH = f"{SIM_NS}/true_depth"
DESIRED = f"{CONTROLLER_NS}/desired"
OBSERVED = f"{CONTROLLER_NS}/observed"
TRACKING_ERROR = f"{CONTROLLER_NS}/tracking_error"
ESTIMATED_DEPTH = f"{CONTROLLER_NS}/estimated_depth"
PARAMETERS = f"{CONTROLLER_NS}/parameters"
EFFORT_COMMAND = f"{CONTROLLER_NS}/effort_command"
DIAGNOSTICS = "/diagnostics"
# the unstamped arrays and the stamped topic published with each (see the module docstring)
# (the first of them in the bag; a bag recorded without it: the next)
STAMPED_WITH = {ESTIMATED_DEPTH: (OBSERVED, TRACKING_ERROR, JOINT_STATES),
                PARAMETERS: (OBSERVED, TRACKING_ERROR, JOINT_STATES),
                TRUE_DEPTH: (JOINT_STATES,), COMMANDS: (EFFORT_COMMAND, JOINT_STATES)}
# of those, the ones always published one for one with their first partner (the same call):
# fewer of them in a bag means the recorder lost some
ONE_FOR_ONE = {ESTIMATED_DEPTH: OBSERVED, PARAMETERS: OBSERVED, COMMANDS: EFFORT_COMMAND}
SIMULATED_BELOW_NS = 10 ** 15    # stamps under 10^6 s are simulated time (they start at 0)
READ = (JOINT_STATES, FEATURES, COMMANDS, TRUE_DEPTH, DESIRED, OBSERVED, TRACKING_ERROR,
        ESTIMATED_DEPTH, PARAMETERS, EFFORT_COMMAND, DIAGNOSTICS)
# plots.plot_recording's names of the topics
PLOTTED = {"error": TRACKING_ERROR, "desired": DESIRED, "observed": OBSERVED,
           "features": FEATURES, "torque": EFFORT_COMMAND, "z_hat": ESTIMATED_DEPTH,
           "z": TRUE_DEPTH, "parameters": PARAMETERS, "joint_states": JOINT_STATES}
LEVELS = {level: name for name, level in m.DIAGNOSTIC_LEVELS.items()}


class BagError(ValueError):
    """A bag that cannot be read, or holds nothing to report."""


@dataclass
class Signal:
    """One topic's messages: stamps [s] (NaN: none), receive times [ns], values (N, w)."""

    t: np.ndarray
    received: np.ndarray
    values: np.ndarray
    labels: list = field(default_factory=list)


@dataclass
class Recording:
    """What :func:`read_bag` read: signals by topic, /diagnostics statuses, message counts."""

    path: str
    signals: dict
    diagnostics: list            # (t [s], name, level name, message), in the bag's order
    counts: dict                 # every topic of the bag, read or not
    t0_ns: int                   # time 0: 0 for simulated time, else the first joint state


def _values(topic, msg, joint_names):
    """(stamp [ns] or None, values (w,), labels) of a message of ``topic``."""
    if topic in (JOINT_STATES, EFFORT_COMMAND):
        names = joint_names.setdefault(topic, list(msg.name))
        if list(msg.name) != names:
            raise BagError(f"{topic}: the joint names changed from {names} to {list(msg.name)}")
        parts = [np.asarray(msg.effort, float)] if topic == EFFORT_COMMAND else [
            np.asarray(getattr(msg, key), float) for key in ("position", "velocity", "effort")]
        if any(len(part) not in (0, len(names)) for part in parts):
            raise BagError(f"{topic}: {len(names)} names but position/velocity/effort of "
                           f"{[len(part) for part in parts]} values")
        parts = [part if len(part) else np.full(len(names), math.nan) for part in parts]
        return m.stamp_to_ns(msg.header.stamp), np.concatenate(parts), names
    if topic in (FEATURES, DESIRED, OBSERVED, TRACKING_ERROR):
        return m.stamp_to_ns(msg.header.stamp), m.features_from_msg(msg)[1], []
    values, labels = m.float_array_from_msg(msg)
    return None, values, labels or []


def _stack(topic, rows, t0_ns):
    """The Signal of a topic's rows, its stamps in seconds from ``t0_ns``."""
    widths = {len(values) for _, _, values, _ in rows}
    if len(widths) > 1:
        raise BagError(f"{topic}: messages of {sorted(widths)} values; one size expected")
    return Signal(t=np.array([math.nan if row[0] is None else (row[0] - t0_ns) * 1e-9
                              for row in rows], dtype=float),
                  received=np.array([row[1] for row in rows], dtype=np.int64),
                  values=np.array([row[2] for row in rows], dtype=float).reshape(len(rows), -1),
                  labels=rows[-1][3])


def _stamp_by_partner(signal, partner):
    """Stamps for an unstamped signal, from ``partner``'s messages published with it.

    As many messages as the partner: one for one, in order (a topic's messages reach
    the recorder in the order they were published).  Otherwise (a partner at another
    rate, or messages lost): the partner's message received nearest, which a recorder
    that received a backlog all at once can get wrong.
    """
    if len(signal.received) == len(partner.received):
        signal.t = partner.t.copy()
        return
    order = np.argsort(partner.received, kind="stable")
    received = partner.received[order]
    at = np.searchsorted(received, signal.received)
    lo, hi = np.clip(at - 1, 0, len(received) - 1), np.clip(at, 0, len(received) - 1)
    nearest = np.where(np.abs(received[lo] - signal.received)
                       <= np.abs(received[hi] - signal.received), lo, hi)
    signal.t = partner.t[order][nearest]


def _refuse_unfinished(path):
    """A folder without metadata.yaml: a recording not finished, or not a bag at all."""
    if not path.is_dir() or (path / "metadata.yaml").exists():
        return
    files = sorted(f.name for f in path.iterdir() if f.suffix in (".mcap", ".db3"))
    if files:
        raise BagError(f"{path}: no metadata.yaml beside {files}: the recording has not "
                       f"finished (ros2 bag record writes it when it stops), or was killed "
                       f"(ros2 bag reindex {path} writes it)")
    raise BagError(f"{path}: not a rosbag2 (no metadata.yaml, no .mcap or .db3 file in it)")


def read_bag(path):
    """A :class:`Recording` of the package's topics in the rosbag2 at ``path``.

    ``path`` is a ``ros2 bag record`` folder or an ``.mcap`` file.  Raises
    FileNotFoundError for a path that does not exist and :class:`BagError`
    naming the problem for anything else it cannot read.
    """
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such bag (a ros2 bag record folder or an .mcap "
                                f"file)")
    rows = {topic: [] for topic in READ}
    diagnostics, joint_names = [], {}
    _refuse_unfinished(path)
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY))
        reader.open()
    except Exception as exc:  # noqa: BLE001 -- rosbags raises its own kinds, named here
        hint = (": the file was not closed (a recording still running, or one that was "
                "killed): stop ros2 bag record, or rebuild its index with ros2 bag reindex"
                if "magic" in str(exc).lower() else "")
        raise BagError(f"{path}: not a readable rosbag2 (a ros2 bag record folder or an "
                       f".mcap file){hint}: {type(exc).__name__}: {exc}") from exc
    try:
        counts = {}
        for connection in reader.connections:
            counts[connection.topic] = counts.get(connection.topic, 0) + connection.msgcount
        # (no connection at all would read every message)
        wanted = [c for c in reader.connections if c.topic in rows]
        for connection, received, raw in (reader.messages(connections=wanted) if wanted
                                          else ()):
            msg = reader.deserialize(raw, connection.msgtype)
            if connection.topic == DIAGNOSTICS:
                stamp = m.stamp_to_ns(msg.header.stamp)
                diagnostics += [(stamp, status.name, LEVELS.get(int(status.level), "UNKNOWN"),
                                 status.message) for status in msg.status]
                continue
            stamp, values, labels = _values(connection.topic, msg, joint_names)
            rows[connection.topic].append((stamp, received, values, labels))
    finally:
        reader.close()
    stamps = [row[0] for found in rows.values() for row in found if row[0] is not None]
    if stamps and min(stamps) < SIMULATED_BELOW_NS:
        t0_ns = 0
    elif rows[JOINT_STATES]:
        t0_ns = rows[JOINT_STATES][0][0]
    elif stamps:
        t0_ns = min(stamps)
    else:
        raise BagError(f"{path}: none of the package's topics is in the bag (it has "
                       f"{sorted(counts) or 'no topic'}); expected {JOINT_STATES}, "
                       f"{TRACKING_ERROR} and the others of servo.launch.py record:=true")
    signals = {topic: _stack(topic, found, t0_ns) for topic, found in rows.items() if found}
    for topic, partners in STAMPED_WITH.items():
        found = [signals[partner] for partner in partners if partner in signals]
        if topic in signals and found:
            _stamp_by_partner(signals[topic], found[0])
    return Recording(str(path), signals,
                     [((ns - t0_ns) * 1e-9, *rest) for ns, *rest in diagnostics], counts, t0_ns)


def timing_figures(key, signal):
    """A topic's count, rate and gaps, by its stamps and by the recorder's receive times.

    ``<key>_largest_gap_s`` and ``_at_s`` (where it ends) from the stamps in order;
    ``<key>_largest_received_gap_s`` and ``_at_s`` (the stamp of the message after it)
    from the receive times.
    """
    order = np.argsort(signal.t, kind="stable")
    t = signal.t[order]
    figures = {key: len(t), f"{key}_first_at_s": float(t[0]), f"{key}_last_at_s": float(t[-1])}
    if len(t) < 2:
        return figures
    steps = np.diff(t)
    k = int(np.argmax(steps))
    span = t[-1] - t[0]
    arrived = np.argsort(signal.received, kind="stable")
    waits = np.diff(signal.received[arrived]) * 1e-9
    j = int(np.argmax(waits))
    figures.update({
        f"{key}_rate_hz": (len(t) - 1) / span if span > 0 else math.inf,
        f"{key}_median_interval_s": float(np.median(steps)),
        f"{key}_largest_gap_s": float(steps[k]), f"{key}_largest_gap_at_s": float(t[k + 1]),
        f"{key}_largest_received_gap_s": float(waits[j]),
        f"{key}_largest_received_gap_at_s": float(signal.t[arrived][j + 1])})
    return figures


def bag_figures(rec, window=RMS_WINDOW_S):
    """The report's figures of a :class:`Recording` (the module docstring); a dict for JSON.

    ``window``: the final_rms_*_error_px figures are over the last ``window`` seconds,
    up to the last joint state (the last stamp of any kind without one); a BagError
    unless it is a positive number.
    """
    if not (window > 0.0 and math.isfinite(window)):
        raise BagError(f"window: expected a positive number of seconds, got {window}")
    sig = rec.signals
    times = {topic: s.t for topic, s in sig.items()}
    stamped = [t[np.isfinite(t)] for t in times.values() if np.isfinite(t).any()]
    start = float(times[JOINT_STATES][0]) if JOINT_STATES in sig else min(t.min() for t in stamped)
    end = float(times[JOINT_STATES][-1]) if JOINT_STATES in sig else max(t.max() for t in stamped)
    figures = {"bag": rec.path, "time_origin": "simulated time" if rec.t0_ns == 0
               else "the first joint state", "start_s": start, "end_s": end,
               "duration_s": end - start, "window_s": min(window, end - start),
               "messages": dict(sorted(rec.counts.items())),
               "missing": [topic for topic in READ if topic not in rec.counts]}
    command_topic = EFFORT_COMMAND if EFFORT_COMMAND in sig else COMMANDS
    for topic, key in ((JOINT_STATES, "joint_states"), (FEATURES, "camera_frames"),
                       (command_topic, "commands")):
        if topic in sig and np.isfinite(sig[topic].t).all():
            figures.update(timing_figures(key, sig[topic]))
    frames = frame_error_series(rec)
    if frames is not None:
        figures.update(_error_figures("frame", *frames, end, window))
    if TRACKING_ERROR in sig:
        figures.update(_error_figures("tracking", times[TRACKING_ERROR],
                                      sig[TRACKING_ERROR].values, end, window))
        if OBSERVED in sig:
            figures["samples_without_tracking_error"] = (len(times[OBSERVED])
                                                         - len(times[TRACKING_ERROR]))
    command = sig.get(EFFORT_COMMAND, sig.get(COMMANDS))
    if command is not None:
        tau = command.values
        figures["max_abs_torque"] = float(np.nanmax(np.abs(tau)))
        if command.labels and EFFORT_COMMAND in sig:
            figures["max_abs_torque_by_joint"] = dict(zip(
                command.labels, np.nanmax(np.abs(tau), axis=0).tolist()))
        if JOINT_STATES in sig:
            figures["commands_per_joint_state"] = len(tau) / len(times[JOINT_STATES])
        if JOINT_STATES in sig and command_topic == EFFORT_COMMAND:
            # each command is stamped with the joint state it answers
            figures["joint_states_without_command"] = int(np.count_nonzero(~np.isin(
                np.round(times[JOINT_STATES], 9), np.round(command.t, 9))))
    if ESTIMATED_DEPTH in sig:
        z_hat = sig[ESTIMATED_DEPTH].values
        figures["min_estimated_depth"] = float(np.nanmin(z_hat))
        if TRUE_DEPTH in sig:
            # at the estimate's last stamp (the two topics may end apart: other rates, or
            # a recorder that lost the last messages of one)
            last, true = times[ESTIMATED_DEPTH][-1], sig[TRUE_DEPTH]
            at = (int(np.nanargmin(np.abs(true.t - last)))
                  if np.isfinite(last) and np.isfinite(true.t).any() else -1)
            error = z_hat[-1] - true.values[at]
            figures["final_depth_error"] = (float(error[0]) if error.size == 1
                                            else error.tolist())
    lost = {topic: len(sig[partner].t) - len(sig[topic].t)
            for topic, partner in ONE_FOR_ONE.items()
            if topic in sig and partner in sig and len(sig[topic].t) < len(sig[partner].t)}
    if lost:
        figures["lost_messages"] = lost
    figures["diagnostics"] = diagnostics_figures(rec.diagnostics)
    return figures


def frame_errors(t_frames, frames, t_desired, desired):
    """(capture times, x - x_d(capture time)) of the camera frames within x_d's span.

    x_d between the controller's samples is interpolated linearly
    (:func:`.summary.desired_at`, as summary.json judges the frames); a frame with
    a NaN pixel (a fault) is left out.
    """
    if frames.shape[1] != desired.shape[1]:
        raise BagError(f"{FEATURES} has {frames.shape[1] // 2} points and {DESIRED} "
                       f"{desired.shape[1] // 2}")
    err = frames - desired_at(t_desired, desired, t_frames)
    kept = np.isfinite(err).all(axis=1)
    return t_frames[kept], err[kept]


def frame_error_series(rec):
    """:func:`frame_errors` of a Recording's frames and x_d; None without both topics."""
    sig = rec.signals
    if FEATURES not in sig or DESIRED not in sig:
        return None
    return frame_errors(sig[FEATURES].t, sig[FEATURES].values, sig[DESIRED].t,
                        sig[DESIRED].values)


def _error_figures(kind, t, err, end, window):
    """final_rms_<kind>_error_px (the last ``window`` s up to ``end``), its largest, by point."""
    if not len(t):
        return {f"{kind}_errors": 0}
    last = t >= end - window + 1e-9
    rms, peak = error_figures(err, np.zeros_like(err), last)
    points = np.linalg.norm(err.reshape(len(t), -1, 2), axis=2)
    return {f"final_rms_{kind}_error_px": rms, f"max_{kind}_error_px": peak,
            f"max_{kind}_error_at_s": float(t[np.argmax(points.max(axis=1))]),
            f"final_rms_{kind}_error_px_by_point": [
                float(np.sqrt(np.mean(points[last, i] ** 2))) if last.any() else math.nan
                for i in range(points.shape[1])],
            f"{kind}_errors": len(t)}


def diagnostics_figures(statuses):
    """Per status name: its messages by level, and its problems.

    A problem runs from a message that is not OK to the next OK one (``end`` None: it
    lasted to the end of the bag); it has its worst level and that level's first message.
    """
    out = {}
    for t, name, level, message in sorted(statuses, key=lambda status: status[0]):
        entry = out.setdefault(name, {"count": {}, "problems": []})
        entry["count"][level] = entry["count"].get(level, 0) + 1
        problems = entry["problems"]
        open_ = problems[-1] if problems and problems[-1]["end"] is None else None
        if level == "OK":
            if open_ is not None:
                open_["end"] = t
        elif open_ is None:
            problems.append({"start": t, "end": None, "level": level, "message": message})
        elif (m.DIAGNOSTIC_LEVELS.get(level, 3)
              > m.DIAGNOSTIC_LEVELS.get(open_["level"], 3)):
            open_.update(level=level, message=message)
    return out


SHOWN_PROBLEMS = 3    # per status, in the printed report (report.json has them all)


def _ms(seconds):
    return f"{1e3 * seconds:.1f} ms"


def report_lines(figures):
    """The report as a few lines of text, for the terminal."""
    lines = [f"{figures['bag']}: {figures['duration_s']:.3f} s, t={figures['start_s']:.3f} "
             f"to {figures['end_s']:.3f} s ({figures['time_origin']})"]
    for key, what in (("joint_states", "joint states"), ("camera_frames", "camera frames"),
                      ("commands", "commands")):
        if f"{key}_rate_hz" not in figures:
            continue
        gap, median = figures[f"{key}_largest_gap_s"], figures[f"{key}_median_interval_s"]
        stamps = (f"largest gap {_ms(gap)} (ending at t={figures[f'{key}_largest_gap_at_s']:.3f}"
                  f" s), median {_ms(median)}" if gap > 1.5 * median
                  else f"intervals regular (largest {_ms(gap)})")
        received = figures[f"{key}_largest_received_gap_s"]
        lines.append(f"{what}: {figures[key]} at {figures[f'{key}_rate_hz']:.1f} Hz, {stamps}; "
                     f"as received, largest gap {_ms(received)} (before "
                     f"t={figures[f'{key}_largest_received_gap_at_s']:.3f} s)")
    for topic, count in figures.get("lost_messages", {}).items():
        lines.append(f"{topic}: {count} message(s) fewer than {ONE_FOR_ONE[topic]}, published "
                     f"with it one for one: the recorder lost them (stamps matched by receive "
                     f"time)")
    if "joint_states_without_command" in figures:
        lines.append(f"joint states without a command answering them: "
                     f"{figures['joint_states_without_command']} of {figures['joint_states']}")
    span = (f"the last {figures['window_s']:g} s"
            if figures["window_s"] < figures["duration_s"] - 1e-9
            else f"the whole run ({figures['window_s']:.3f} s)")
    for kind, what in (("frame", "camera frames - x_d at their capture (noise included)"),
                       ("tracking", "~/tracking_error, the law's x - x_d")):
        if f"final_rms_{kind}_error_px" in figures:
            lines.append(f"{what}: largest point error RMS "
                         f"{figures[f'final_rms_{kind}_error_px']:.4g} px over {span}, at most "
                         f"{figures[f'max_{kind}_error_px']:.4g} px (t="
                         f"{figures[f'max_{kind}_error_at_s']:.3f} s)")
    if "max_abs_torque" in figures:
        lines.append(f"largest commanded torque: {figures['max_abs_torque']:.4g} N m")
    if "final_depth_error" in figures:
        error = np.atleast_1d(figures["final_depth_error"])
        lines.append("depth estimate - true depth at the end: "
                     + ", ".join(f"{e:+.4f}" for e in error) + " m")
    for name, entry in figures["diagnostics"].items():
        problems = entry["problems"]
        if not problems:
            continue
        counts = ", ".join(f"{n} {level}" for level, n in entry["count"].items())
        shown = "; ".join(
            f"{p['level']} t={p['start']:.3f}-"
            f"{'end' if p['end'] is None else format(p['end'], '.3f')} s: {p['message']}"
            for p in problems[:SHOWN_PROBLEMS])
        more = (f" (and {len(problems) - SHOWN_PROBLEMS} more in report.json)"
                if len(problems) > SHOWN_PROBLEMS else "")
        lines.append(f"diagnostics {name!r} ({counts}): {len(problems)} "
                     f"problem{'s' if len(problems) > 1 else ''}: {shown}{more}")
    if figures["missing"]:
        lines.append(f"not in the bag: {', '.join(figures['missing'])}")
    return lines


def write_report(rec, out_dir, window=RMS_WINDOW_S):
    """report.json and the PNGs of a Recording in ``out_dir`` (created); returns the figures."""
    from .plots import plot_recording
    from .recorder import write_json

    figures = bag_figures(rec, window)
    os.makedirs(out_dir, exist_ok=True)
    series = {key: (rec.signals[topic].t, rec.signals[topic].values,
                    rec.signals[topic].labels)
              for key, topic in PLOTTED.items() if topic in rec.signals}
    if "observed" in series and "desired" in series:
        # x_o before the controller's first x_d (before a late camera's first frame) is 0
        t, values, labels = series["observed"]
        kept = t >= series["desired"][0][0] - 1e-9
        series["observed"] = (t[kept], values[kept], labels)
    frames = frame_error_series(rec)
    if frames is not None:
        series["frame_error"] = frames
    if "torque" not in series and COMMANDS in rec.signals:
        series["torque"] = (rec.signals[COMMANDS].t, rec.signals[COMMANDS].values, [])
    figures["outputs"] = ["report.json"] + [
        os.path.basename(p) for p in plot_recording(series, rec.diagnostics, out_dir)]
    write_json(os.path.join(out_dir, "report.json"), figures)
    return figures
