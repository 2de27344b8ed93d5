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

"""The figures of a run, as summary.json holds them (numpy only).

:func:`summarize` is what ``vas run`` writes; campaigns read the same figures
back (``campaigns.engine.FIGURES``), and ``vas compare`` judges controllers by
:func:`run_figures`, over the window after the transient (t >= 5 s):

* RMS and max of the true image error, max_i |x_true,i - x_d,i| [px], from the
  noiseless pixels: the tracking itself, not the measurement noise;
* torque RMS, sqrt(mean |tau|^2) [N m];
* torque-rate RMS, sqrt(mean |(tau_k - tau_k-1) / T|^2) [N m/s]: the chatter.
"""

from __future__ import annotations

import math

import numpy as np

RMS_WINDOW_S = 5.0      # final_rms_*: over the last 5 s of the run
TRANSIENT_S = 5.0       # transient_* and torque figures: over t >= 5 s


def camera_figures(frames, feature_camera, noise=math.nan):
    """Frame counts and ages for summary.json: what the camera sent, what the controller used.

    ``frames_dropped`` counts published frames the controller did not apply (refused:
    invalid, out of order, too old); ``frame_age`` is the time from capture to use;
    ``frame_noise_px`` the pixel noise the controller measured in them (NaN: none).
    """
    figures = {"frames_captured": feature_camera.captured,
               "frames_published": feature_camera.published}
    if frames is not None:
        applied = frames["applied"]
        figures.update(frames_applied=applied, frames_late=frames["late"],
                       frames_dropped=frames["received"] - applied,
                       frame_age_mean_s=frames["age_sum"] / applied if applied else math.nan,
                       frame_age_max_s=frames["age_max"] if applied else math.nan,
                       frame_noise_px=noise)
    return figures


def summarize(data, status, wall, diverged, reason, counters, period):
    """summary.json's figures of a run's samples ``data``.

    The transient_* and torque ones are over t >= 5 s (:func:`run_figures`).
    """
    t = data["t"]
    late = run_figures(t, data["x_true"], data["x_d"], data["tau"], period)
    transient = {"transient_rms_true_error_px": late["rms_error_px"],
                 "transient_max_true_error_px": late["max_error_px"],
                 "torque_rms": late["torque_rms"], "torque_rate_rms": late["torque_rate_rms"]}
    if len(t) == 0:
        return {"diverged": diverged, "divergence_reason": reason, "final_rms_error_px": math.nan,
                "max_error_px": math.nan, "max_abs_torque": math.nan,
                "final_depth_error": math.nan, "sim_time_s": 0.0, "wall_time_s": wall,
                "realtime_factor": 0.0, **transient, **counters}
    window = t >= t[-1] - RMS_WINDOW_S + 1e-9
    sim_time = float(t[-1] + (t[1] - t[0] if len(t) > 1 else 0.0))
    # the frames against x_d at their capture, over the frames captured in the window
    captured = data.get("x_stamp", t)
    rms, peak = error_figures(data["x"], desired_at(t, data["x_d"], captured),
                              captured >= t[-1] - RMS_WINDOW_S + 1e-9)
    rms_true, peak_true = error_figures(data["x_true"], data["x_d"], window)
    depth_err = data["z_hat"][-1] - data["z"][-1]
    return {
        "diverged": diverged,
        "divergence_reason": reason,
        "final_rms_error_px": rms,
        "max_error_px": peak,
        "final_rms_true_error_px": rms_true,
        "max_true_error_px": peak_true,
        "max_abs_torque": float(np.nanmax(np.abs(data["tau"]))),
        "final_depth_error": float(depth_err[0]) if depth_err.size == 1 else depth_err.tolist(),
        "min_estimated_depth": float(np.nanmin(data["z_hat"])),
        "sim_time_s": sim_time,
        "wall_time_s": wall,
        "realtime_factor": sim_time / wall if wall > 0 else math.inf,
        **transient,
        **counters,
    }


def desired_at(t, x_d, times):
    """x_d (N, 2m) of samples at ``t`` (N,), linear between them, at ``times`` (K,) -> (K, 2m).

    NaN at a time outside the samples where x_d is defined (before the controller's
    first sample: a frame captured before the start).  A camera frame captured at
    ``times`` is judged against this: x_d where the arm should have been when the
    picture was taken, not when it arrived.
    """
    times = np.asarray(times, dtype=float)
    defined = np.isfinite(x_d).all(axis=1)
    out = np.full((len(times), x_d.shape[1]), math.nan)
    if not defined.any():
        return out
    t_d, x_d = t[defined], x_d[defined]
    inside = (times >= t_d[0] - 1e-9) & (times <= t_d[-1] + 1e-9)
    out[inside] = np.column_stack([np.interp(times[inside], t_d, x_d[:, j])
                                   for j in range(x_d.shape[1])])
    return out


def point_error(x, x_d):
    """Per-sample largest point error max_i |x_i - x_d,i| [px] of (N, 2m) arrays -> (N,)."""
    return np.linalg.norm((x - x_d).reshape(len(x), -1, 2), axis=2).max(axis=1)


def error_figures(x, x_d, window):
    """(RMS over ``window``, max) of :func:`point_error`, leaving out NaN samples."""
    err = point_error(x, x_d)
    valid = np.isfinite(err)
    rms = float(np.sqrt(np.mean(err[window & valid] ** 2))) if np.any(window & valid) else math.nan
    return rms, (float(np.max(err[valid])) if valid.any() else math.nan)


def run_figures(t, x_true, x_d, tau, period, transient=TRANSIENT_S):
    """``vas compare``'s figures of one run over t >= ``transient`` (module docstring)."""
    nan = math.nan
    err = point_error(x_true, x_d)
    window = (t >= transient - 1e-9) & np.isfinite(err)
    figures = {"rms_error_px": nan, "max_error_px": nan, "torque_rms": nan,
               "torque_rate_rms": nan, "window_s": 0.0}
    if not window.any():
        return figures
    rate = np.diff(tau, axis=0) / period
    rate_window = window[1:] & window[:-1]
    figures.update(
        rms_error_px=float(np.sqrt(np.mean(err[window] ** 2))),
        max_error_px=float(np.max(err[window])),
        torque_rms=float(np.sqrt(np.mean(np.sum(tau[window] ** 2, axis=1)))),
        torque_rate_rms=(float(np.sqrt(np.mean(np.sum(rate[rate_window] ** 2, axis=1))))
                         if rate_window.any() else nan),
        window_s=float(np.count_nonzero(window) * period))
    return figures


#: the signals :func:`divergence_origin` looks at, in the order ties are broken
GROWTH_SIGNALS = ("tau", "qd", "z_hat", "a_d", "a_z", "a_z_perp", "x_obs")


def divergence_origin(data, labels, settle=0.2, factor=10.0):
    """Which signal left its range first before a divergence: ``(name, t)`` or None.

    For every column of the signals in :data:`GROWTH_SIGNALS`, its normal range
    is the largest deviation from its start value over the first ``settle`` of
    the run (at least 20 samples); the column grew when its deviation passes
    ``factor`` times that (plus 1e-6 of its size).  The earliest such crossing
    names what grew first: a joint's torque or speed, an estimated depth, or an
    estimate.  ``labels`` maps a signal to its column names (joint names, the
    model's parameter labels).
    """
    t = data["t"]
    count = len(t)
    if count < 40:
        return None
    normal = max(20, int(settle * count))
    first = None
    for key in GROWTH_SIGNALS:
        arr = np.asarray(data[key], dtype=float).reshape(count, -1)
        finite = np.isfinite(arr)
        start = np.where(finite[0], arr[0], 0.0)
        deviation = np.abs(np.where(finite, arr, np.inf) - start)
        range_ = np.nanmax(np.where(np.isfinite(deviation[:normal]), deviation[:normal], 0.0),
                           axis=0)
        threshold = factor * range_ + 1e-6 * (np.abs(start) + 1.0)
        crossed = deviation[normal:] > threshold
        for j in np.flatnonzero(crossed.any(axis=0)):
            k = normal + int(np.argmax(crossed[:, j]))
            if first is None or t[k] < first[1]:
                names = labels.get(key)
                name = names[j] if names is not None and j < len(names) else str(j)
                first = (f"{key}[{name}]", float(t[k]))
    return first
