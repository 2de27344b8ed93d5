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

"""The closed loop in one process: simulator + controller, recorded and plotted.

``run_scenario`` is what ``vas run`` calls.  It is deterministic for a given
configuration and seed, stops early (and says why) on divergence, and always
writes its outputs -- summary.json, timeseries.csv, the PNG plots and a closed
MCAP file -- also after Ctrl-C or an exception.
"""

from __future__ import annotations

import logging
import math
import os
import re
import sys
import time
from dataclasses import replace

import numpy as np

from sim_bridge.simulator import Simulator

from .control.controller import AdaptiveVisualTracker
from .recording import messages as m
from .recording.recorder import McapRecorder, write_csv, write_json
from .recording.summary import camera_figures, divergence_origin, summarize

log = logging.getLogger(__name__)


class Progress:
    """A one-line progress bar on a terminal (silent when not a TTY).

    ``Progress.live`` is the bar being drawn, if any: :class:`LogAboveProgress` clears its
    line before a log message and has it drawn again at its next update.
    """

    live = None

    def __init__(self, total, enabled=None, stream=sys.stderr, width=30):
        self.total, self.stream, self.width = total, stream, width
        self.enabled = stream.isatty() if enabled is None else enabled
        self.last = -1

    def update(self, done, note=""):
        if not self.enabled:
            return
        pct = int(100 * done / max(self.total, 1))
        if pct == self.last and done < self.total:
            return
        self.last = pct
        Progress.live = self
        filled = int(self.width * done / max(self.total, 1))
        self.stream.write(f"\r[{'#' * filled}{'.' * (self.width - filled)}] {pct:3d}% {note}")
        self.stream.flush()

    def close(self):
        if Progress.live is self:
            Progress.live = None
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()


class LogAboveProgress(logging.StreamHandler):
    """A log handler that writes its messages on lines of their own above a live bar."""

    def emit(self, record):
        bar = Progress.live
        if bar is not None and bar.stream is self.stream:
            self.stream.write("\r\x1b[K")      # the bar's line, cleared; drawn again next
            bar.last = -1
        super().emit(record)


class Series:
    """Preallocated time series of one run."""

    def __init__(self, steps, model):
        n, m2, m = model.n, 2 * model.m, model.m
        # x_stamp: the capture time of the frame in x (NaN where none)
        shapes = {"t": (), "x": (m2,), "x_stamp": (), "x_true": (m2,), "x_d": (m2,),
                  "x_obs": (m2,), "z": (m,), "z_hat": (m,),
                  "q": (n,), "qd": (n,), "tau": (n,), "a_z_perp": (model.p_perp,),
                  "a_z": (model.p_z,), "a_d": (model.p_d,), "sigma_min_J_star": (),
                  "damped": (), "motion_scale": (), "gamma": ()}
        self.data = {k: np.full((steps,) + s, np.nan) for k, s in shapes.items()}
        self.status = []
        self.count = 0

    def add(self, **values):
        k = self.count
        for key, value in values.items():
            self.data[key][k] = value
        self.count += 1

    def view(self):
        return {k: v[:self.count] for k, v in self.data.items()}


def start_report(ctl, scenario):
    """The controller's start-up report at the simulated start pose, as text lines.

    The controller fixes its damping and derives the gains it was not given there
    (``AdaptiveVisualTracker.start``; a ConfigError refuses the run before it
    starts); the simulator's ground truth adds the true J(q0, x0)'s sigma_min.
    Controllers without a start (the calibrated baseline) report nothing.
    """
    start = getattr(ctl, "start", None)
    if start is None:
        return []
    q0 = np.asarray(scenario.sim.initial_positions, dtype=float)
    lines = start(q0).lines()
    model = scenario.controller.model
    x0, _ = model.project(q0)
    sigma = np.linalg.svd(model.true_image_jacobian(q0, x0), compute_uv=False)[-1]
    floor = ctl.min_singular_value
    lines.append(f"true J(q0, x0): sigma_min {sigma:.4g} px m/rad"
                 + (f" -- below min_singular_value {floor:g}: near a singular pose"
                    if sigma < floor else ""))
    return lines


def run_scenario(scenario, out_dir, duration=None, progress=None, record=True, plots=True,
                 faults=None, controller_factory=AdaptiveVisualTracker, announce=None):
    """Run the closed loop and write every output into ``out_dir``; return the summary.

    Parameters
    ----------
    scenario : config.Scenario
    out_dir : str or None
        Created if needed; None: nothing is written, the summary is only returned
        (campaign runs: no scratch folder to leave behind, no CSV to write).
    duration : float, optional
        Simulated seconds; default ``sim_node.duration`` (30 s if that is 0).
    progress : bool, optional
        Progress bar; default: when stderr is a terminal.
    record, plots : bool
        Write run.mcap / the PNGs (benchmarks switch them off).
    faults : callable, optional
        ``faults(step, measurement) -> measurement`` to inject bad input (tests).
    controller_factory : callable, optional
        ``controller_factory(scenario.controller)`` -> the controller, anything with
        ``step(t, q, qd, x)`` returning a :class:`~.control.controller.StepResult`; default the
        paper's :class:`~.control.controller.AdaptiveVisualTracker` (``vas compare`` passes
        the baselines).
    announce : callable, optional
        Called with the start-up report (text) before the run starts (``vas run``: print).
    """
    if out_dir is None:
        if record or plots:
            raise ValueError("run_scenario: out_dir None writes nothing: record and plots "
                             "must be False")
    else:
        os.makedirs(out_dir, exist_ok=True)
    duration = duration or scenario.sim.duration or 30.0
    period = scenario.sim.control_period
    steps = int(round(duration / period))
    model = scenario.controller.model
    ctl = controller_factory(scenario.controller)
    start = start_report(ctl, scenario)
    if announce is not None and start:
        announce("\n".join(["start-up report:"] + [f"  {line}" for line in start]))
    sim = Simulator(scenario.sim)
    series = Series(steps, model)
    counters = {"rejected": 0, "fallback": 0, "saturated": 0, "projection_active": 0,
                "damped": 0, "sim_refused_commands": 0}
    diverged, reason, interrupted, error = False, "", False, None
    rendered = scenario.sim.camera_mode == "rendered"
    recorder = (McapRecorder(os.path.join(out_dir, "run.mcap"), scenario.sim.joint_names, model,
                             camera=scenario.sim.camera if rendered else None)
                if record else None)
    detections = FrameDetections(scenario.detector)
    bar = Progress(steps, progress)
    limit = scenario.controller["divergence_torque"]
    diag_every = max(1, int(round(1.0 / period)))
    last_status = None
    wall0 = time.perf_counter()
    try:
        for k in range(steps):
            truth = sim.measure()
            meas = truth if faults is None else faults(k, truth)
            if meas.image is not None:
                if recorder is not None:
                    recorder.record_picture(meas)
                meas = detections.detect(meas)
            # what controller_node reads from the messages: times from their nanosecond
            # stamps, pixels as float32 (so this loop and the nodes compute the same)
            pixels = None if meas.pixels is None else m.received_pixels(meas.pixels)
            res = ctl.step(m.received_time(meas.t), meas.q, meas.qd, pixels,
                           None if meas.feature_stamp is None
                           else m.received_time(meas.feature_stamp))
            counters["rejected"] += res.status != "ok"
            counters["fallback"] += res.status == "fallback"
            counters["saturated"] += res.saturated
            counters["projection_active"] += res.projection_active
            counters["damped"] += res.damped
            x, x_stamp = ((pixels, meas.feature_stamp) if pixels is not None
                          else (np.nan, np.nan))
            series.add(t=meas.t, x=x, x_stamp=x_stamp, x_true=truth.true_pixels, x_d=res.x_d,
                       x_obs=res.x_obs, z=truth.true_depth, z_hat=res.z_hat, q=truth.true_q,
                       qd=truth.qd, tau=res.tau,
                       a_z_perp=res.state.a_z_perp, a_z=res.state.a_z, a_d=res.state.a_d,
                       sigma_min_J_star=res.sigma_min, damped=float(res.damped),
                       motion_scale=res.motion_scale, gamma=res.gamma)
            series.status.append(res.status)
            if recorder is not None:
                recorder.record(meas, res, k % diag_every == 0 or res.status != last_status)
            last_status = res.status
            unsat = res.tau_unsaturated if res.tau_unsaturated is not None else res.tau
            # divergence is judged on the plant itself, not on injected measurement faults;
            # checked on Python floats (np.all/np.max cost microseconds on 3 elements)
            qd_list = truth.qd.tolist()
            if not all(map(math.isfinite, truth.true_q.tolist() + qd_list)):
                diverged, reason = True, f"joint state not finite at t={meas.t:.3f}"
            elif max(map(abs, unsat.tolist())) > limit:
                # the law's command before the torque limit: what is applied stays within
                # it, so summary.json's max_abs_torque does not show this figure
                diverged, reason = True, (f"commanded |tau| = {np.max(np.abs(unsat)):.3g} N m "
                                          f"(before the torque limit) > divergence_torque "
                                          f"{limit:g} at t={meas.t:.3f}")
            elif max(map(abs, qd_list)) > 1e3:
                diverged, reason = True, f"joint speed above 1e3 rad/s at t={meas.t:.3f}"
            if diverged:
                log.error("diverged: %s", reason)
                break
            if sim.apply(res.tau) is not None:
                counters["sim_refused_commands"] += 1
            if bar.enabled:
                bar.update(k + 1, f"t={meas.t + period:6.2f} s")
        if recorder is not None:
            recorder.flush()  # here, so that a failure is reported as the run's error
    except KeyboardInterrupt:
        interrupted = True
        log.warning("interrupted: writing what was simulated so far")
    except Exception as exc:  # noqa: BLE001 -- outputs must still be written
        error = f"{type(exc).__name__}: {exc}"
        log.exception("run failed: writing what was simulated so far")
    finally:
        bar.close()
        wall = time.perf_counter() - wall0
        sim.close()
        if recorder is not None:
            recorder.close()
    data = series.view()
    # (t, text) of the first time the frames moved against the model's image motion, or None
    reversed_motion = getattr(ctl, "reversed_motion", None)
    if diverged:
        joints = list(scenario.sim.joint_names)
        origin = divergence_origin(data, {"tau": joints, "qd": joints,
                                          "a_z_perp": model.a_z_perp_labels,
                                          "a_z": model.a_z_labels, "a_d": model.a_d_labels})
        if origin is not None:
            reason += f"; grew first: {origin[0]} at t={origin[1]:.3f} s"
        if reversed_motion is not None:
            reason += (f"; the frames moved against the model's image motion from "
                       f"t={reversed_motion[0]:.3f} s: check initial_estimate.camera "
                       f"(pixel_axes, pixel_origin, its side of the arm)")
    counters.update(camera_figures(getattr(ctl, "frames", None), sim.feature_camera,
                                   getattr(ctl, "frame_noise", math.nan)))
    # times a joint went past its URDF position limit (the controller warned each time)
    counters["joint_limit_excursions"] = getattr(ctl, "limit_excursions", 0)
    counters["reversed_motion_t"] = math.nan if reversed_motion is None else reversed_motion[0]
    counters.update(detections.figures())
    # the last sample the law computed (the others were held or fell back): NaN if none
    tracked = [k for k, status in enumerate(series.status) if status == "ok"]
    counters["last_tracked_t"] = float(data["t"][tracked[-1]]) if tracked else math.nan
    summary = summarize(data, series.status, wall, diverged, reason, counters, period)
    summary.update(interrupted=interrupted, error=error, steps=series.count,
                   duration_requested_s=duration, control_period_s=period,
                   outputs=[] if out_dir is None else ["summary.json", "timeseries.csv"],
                   start_report=start)
    if out_dir is not None:
        write_outputs(out_dir, data, series.status, model, summary, record, plots)
    return summary


def reason_kind(reason):
    """A detector's reason without its details: the text before a ': ' outside parentheses.

    ``marker 1 missing: no pixel of its colour`` -> ``marker 1 missing``; ``tag 0
    missing (ids found: none)`` stays whole.
    """
    return re.split(r": (?![^()]*\))", reason)[0]


class FrameDetections:
    """The feature detector between the rendered camera and the controller (rendered mode).

    ``detect`` replaces a measurement's picture by the detected pixels (None, with the
    frame's stamp dropped, when a marker is missing or ambiguous -- as the
    feature_detector node publishes nothing then) and keeps the detection error
    against the true projection at the frame's capture.
    """

    def __init__(self, config):
        self.config = config
        self.detector = None if config is None else config.detector()
        self.errors = []
        self.without_features = 0
        self.reasons = {}

    def detect(self, meas):
        found = self.detector.detect(meas.image)
        if found.pixels is None:
            self.without_features += 1
            kind = reason_kind(found.reason)
            self.reasons[kind] = self.reasons.get(kind, 0) + 1
            return replace(meas, pixels=None, feature_stamp=None)
        err = (found.pixels - meas.frame_true_pixels).reshape(-1, 2)
        self.errors.append(np.linalg.norm(err, axis=1).max())
        return replace(meas, pixels=found.pixels)

    def figures(self):
        if self.config is None:
            return {}
        errors = np.array(self.errors)
        return {"detection_rms_px": float(np.sqrt(np.mean(errors ** 2))) if len(errors)
                else math.nan,
                "detection_max_px": float(errors.max()) if len(errors) else math.nan,
                "frames_without_features": self.without_features,
                "frames_without_features_by_reason": self.reasons}


def write_outputs(out_dir, data, status, model, summary, record, plots):
    columns, blocks = ["t"], [data["t"][:, None]]
    for key, names in (("x", None), ("x_true", None), ("x_d", None), ("x_obs", None), ("z", None),
                       ("z_hat", None), ("q", None), ("qd", None), ("tau", None),
                       ("a_z_perp", model.a_z_perp_labels), ("a_z", model.a_z_labels),
                       ("a_d", model.a_d_labels)):
        arr = data[key]
        names = names or [str(i) for i in range(arr.shape[1])]
        columns += [f"{key}.{name}" for name in names]
        blocks.append(arr)
    # sigma_min of J* and whether its pseudo-inverse was damped (NaN, 0 when not computed),
    # the image-motion scale s (docs/robust_adaptation.md; 1 when off), and gamma in effect
    # (it follows the measured pixel noise: docs/gain_design.md)
    columns += ["sigma_min_J_star", "damped", "motion_scale", "gamma"]
    blocks += [data["sigma_min_J_star"][:, None], data["damped"][:, None],
               data["motion_scale"][:, None], data["gamma"][:, None]]
    write_csv(os.path.join(out_dir, "timeseries.csv"), columns + ["status"], np.hstack(blocks),
              status)
    if plots and len(data["t"]) > 1:
        # matplotlib costs ~0.5 s to import: only runs that plot pay it (campaign workers
        # and benchmarks run headless)
        from .recording.plots import plot_run

        labels = {"a_z_perp": model.a_z_perp_labels, "a_z": model.a_z_labels,
                  "a_d": model.a_d_labels}
        summary["outputs"] += [os.path.basename(p) for p in plot_run(data, out_dir, labels)]
    if record:
        summary["outputs"].append("run.mcap")
    write_json(os.path.join(out_dir, "summary.json"), summary)
