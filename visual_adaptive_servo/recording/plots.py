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

"""PNG plots of a run, in the style of the paper's figures (matplotlib, no display)."""

from __future__ import annotations

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (backend first)
import numpy as np  # noqa: E402

from .messages import DIAGNOSTIC_LEVELS  # noqa: E402
from .summary import desired_at  # noqa: E402


def _save(fig, path):
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _plot_error(out_dir, t, err, label="", faint=None, faint_label=""):
    """tracking_error.png: x - x_d per coordinate, and the largest point error (log scale).

    ``err`` (N, 2m) at times ``t``, drawn solid and named ``label``; ``faint``: another
    (times, errors) of the same points, drawn light behind it (the noisy measurement).
    """
    fig, (ax, ax_max) = plt.subplots(2, 1, figsize=(7, 6.5), sharex=True,
                                     gridspec_kw={"height_ratios": (3, 2)})
    for i in range(err.shape[1]):
        axis, point = "uv"[i % 2], i // 2 + 1
        name = f"{axis}{point} - {axis}d{point}"
        color = None
        if faint is not None:
            line, = ax.plot(faint[0], faint[1][:, i], lw=0.5, alpha=0.35,
                            label=f"{name} {faint_label}")
            color = line.get_color()
        ax.plot(t, err[:, i], color=color, label=f"{name} {label}".rstrip())
    ax.set(ylabel="image error [px]", title="Image-space tracking error x - x_d (paper Fig. 2)")
    ax.grid(True)
    ax.legend(fontsize=7, ncol=2)
    # the summary figures use the largest point error, shown here on a log scale
    largest = np.linalg.norm(err.reshape(len(t), -1, 2), axis=2).max(axis=1)
    ax_max.semilogy(t, np.maximum(largest, 1e-6), lw=0.8, color="k")
    ax_max.set(xlabel="time [s]", ylabel=f"largest point error [px] {label}".rstrip())
    ax_max.grid(True, which="both", alpha=0.4)
    return _save(fig, os.path.join(out_dir, "tracking_error.png"))


def _plot_depth(t, z_hat, out_dir, t_z=None, z=None):
    """depth.png: the estimated depths, and the actual ones where known (at times ``t_z``)."""
    fig, ax = plt.subplots(figsize=(7, 4))
    for i in range(z_hat.shape[1]):
        if z is not None:
            line, = ax.plot(t_z, z[:, i], label=f"z{i + 1} actual")
            ax.plot(t, z_hat[:, i], "--", color=line.get_color(), label=f"z{i + 1} estimated")
        else:
            ax.plot(t, z_hat[:, i], "--", label=f"z{i + 1} estimated")
    ax.set(xlabel="time [s]", ylabel="depth [m]",
           title="Actual and estimated depth (paper Fig. 3)" if z is not None
           else "Estimated depth")
    ax.grid(True)
    ax.legend()
    return _save(fig, os.path.join(out_dir, "depth.png"))


def _plot_torques(t, tau, out_dir, names=()):
    fig, ax = plt.subplots(figsize=(7, 4))
    for i in range(tau.shape[1]):
        ax.plot(t, tau[:, i], label=names[i] if len(names) == tau.shape[1] else f"tau{i + 1}")
    ax.set(xlabel="time [s]", ylabel="torque [N m] (prismatic: force [N])",
           title="Joint torques")
    ax.grid(True)
    ax.legend()
    return _save(fig, os.path.join(out_dir, "torques.png"))


def _plot_parameters(t, groups, out_dir):
    """parameters.png: one panel per (title, entry names, values (N, p)) of ``groups``."""
    fig, axes = plt.subplots(len(groups), 1, figsize=(9, 8), sharex=True, squeeze=False)
    styles = ("-", "--", ":")      # past the 10 colours of the cycle, a line style tells them
    for ax, (title, names, values) in zip(axes[:, 0], groups):
        for i, name in enumerate(names):
            ax.plot(t, values[:, i], styles[(i // 10) % 3], label=name, lw=0.8)
        ax.set(ylabel="estimate", title=f"{title}, {len(names)} entries")
        ax.grid(True)
        if len(names) <= 12:
            # beside the panel, not over its curves
            ax.legend(fontsize=6, ncol=1 + len(names) // 7, loc="upper left",
                      bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    axes[-1, 0].set_xlabel("time [s]")
    return _save(fig, os.path.join(out_dir, "parameters.png"))


def _plot_image_path(out_dir, x_d, x_obs, x_meas=None, x_true=None):
    """image_path.png: x_d, x_o, the measured pixels and (from a simulation) the true ones."""
    fig, ax = plt.subplots(figsize=(6, 6))
    for i in range(x_d.shape[1] // 2):
        u, v = 2 * i, 2 * i + 1
        first = i == 0
        if x_meas is not None and len(x_meas):
            # a frame at every sample is a cloud; a 30 Hz camera's frames are dots to see
            sparse = np.count_nonzero(np.isfinite(x_meas[:, u])) < 2000
            ax.plot(x_meas[:, u], x_meas[:, v], ".", ms=3 if sparse else 1,
                    alpha=0.6 if sparse else 0.3, color="tab:orange",
                    label="x measured" if first else None)
        if x_true is not None:
            ax.plot(x_true[:, u], x_true[:, v], lw=1, color="tab:orange",
                    label="x" if first else None)
        ax.plot(x_obs[:, u], x_obs[:, v], lw=1, color="tab:blue", label="x_o" if first else None)
        ax.plot(x_d[:, u], x_d[:, v], "k--", lw=1, label="x_d" if first else None)
        start = (x_true if x_true is not None else x_obs)[0]
        ax.plot(start[u], start[v], "go", label="start" if first else None)
        if x_d.shape[1] > 2:
            ax.annotate(f"{i + 1}", (start[u], start[v]), textcoords="offset points",
                        xytext=(5, 5))
    ax.set(xlabel="u [px]", ylabel="v [px]", title="Image-plane path")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True)
    ax.legend()
    return _save(fig, os.path.join(out_dir, "image_path.png"))


def plot_run(series, out_dir, labels):
    """Write the standard plots of one run; returns the list of PNG paths.

    ``series`` maps names to arrays over time: t (N,), x (measured: the frame
    applied at t, NaN without one), x_stamp (N,) (its capture time), x_true
    (noiseless), x_d, x_obs (N, 2m),
    z, z_hat (N, m), tau (N, n), a_z_perp, a_z, a_d (N, p).
    ``labels`` maps a_z_perp / a_z / a_d to their entry names.
    """
    t = series["t"]
    err, err_true = series["x"] - series["x_d"], series["x_true"] - series["x_d"]
    gap = np.abs(err - err_true)
    noisy = bool(np.nanmax(gap) > 1e-9) if np.isfinite(gap).any() else False  # (no frame: no)
    # each frame at its capture, against x_d then
    captured = series.get("x_stamp", t)
    frame_err = series["x"] - desired_at(t, series["x_d"], captured)
    kept = np.isfinite(frame_err).all(axis=1)
    measured = (captured[kept], frame_err[kept])
    return [
        _plot_error(out_dir, t, err_true, "true", measured, "measured") if noisy
        else _plot_error(out_dir, t, err),
        _plot_depth(t, series["z_hat"], out_dir, t, series["z"]),
        _plot_torques(t, series["tau"], out_dir),
        _plot_parameters(t, [(title, labels[key], series[key]) for key, title in (
            ("a_z_perp", "a_z_perp (eq 24)"), ("a_z", "a_z (eq 25)"), ("a_d", "a_d (eq 23)"))],
            out_dir),
        _plot_image_path(out_dir, series["x_d"], series["x_obs"], series["x"], series["x_true"])]


#: the estimates' panels of plot_recording: the ~/parameters label's prefix, the title
PARAMETER_GROUPS = (("a_z_perp.", "a_z_perp (eq 24)"), ("a_z.", "a_z (eq 25)"),
                    ("a_d.", "a_d (eq 23)"))


def _broken(t, values, factor=5.0):
    """``(t, values)`` with a NaN row in each gap over ``factor`` x the median interval.

    A line is then not drawn across the time a topic was silent (a stalled node).
    """
    if len(t) < 3:
        return t, values
    steps = np.diff(t)
    gaps = np.flatnonzero(steps > factor * np.median(steps))
    if not len(gaps):
        return t, values
    return (np.insert(t, gaps + 1, t[gaps] + 0.5 * steps[gaps]),
            np.insert(values, gaps + 1, np.nan, axis=0))


def plot_recording(series, diagnostics, out_dir):
    """The plots of a recorded run (``vas report``) from whatever it holds; the PNG paths.

    ``series`` maps error, frame_error, desired, observed, features (x - x_d as the
    law saw it, the frames' x - x_d at capture, x_d, x_o, the camera's pixels),
    torque, z_hat, z, parameters and joint_states to
    ``(t (N,), values (N, w), labels)``, each with its own times; missing keys
    leave their plot out.  ``diagnostics``: (t, name, level, message) tuples.
    """
    paths = []
    if "error" in series:
        t, err = _broken(*series["error"][:2])
        paths.append(_plot_error(out_dir, t, err, "(~/tracking_error)", series.get(
            "frame_error"), "(camera frames)"))
    if "z_hat" in series:
        t, z_hat, _ = series["z_hat"]
        t_z, z, _ = series.get("z", (None, None, None))
        paths.append(_plot_depth(t, z_hat, out_dir, t_z, z))
    if "torque" in series:
        t, tau, names = series["torque"]
        paths.append(_plot_torques(t, tau, out_dir, names))
    if "parameters" in series:
        t, values, labels = series["parameters"]
        groups = [(title, [label[len(prefix):] for label in labels if label.startswith(prefix)],
                   values[:, [j for j, label in enumerate(labels) if label.startswith(prefix)]])
                  for prefix, title in PARAMETER_GROUPS]
        groups = [group for group in groups if group[1]] or [
            ("estimates", [f"{j + 1}" for j in range(values.shape[1])], values)]
        paths.append(_plot_parameters(t, groups, out_dir))
    if "desired" in series and "observed" in series:
        x_meas = series["features"][1] if "features" in series else None
        paths.append(_plot_image_path(out_dir, series["desired"][1], series["observed"][1],
                                      x_meas))
    paths.append(_plot_timing(series, out_dir))
    if diagnostics:
        paths.append(_plot_diagnostics(diagnostics, out_dir))
    return [path for path in paths if path is not None]


def _plot_timing(series, out_dir):
    """timing.png: the interval before each joint state, command and camera frame [ms].

    One panel each, so that none hides another; a log scale only where the intervals
    span more than a factor of 10.
    """
    shown = [(key, label) for key, label in (("joint_states", "joint states"),
                                             ("torque", "commands"),
                                             ("features", "camera frames"))
             if key in series and len(series[key][0]) > 1
             and np.isfinite(series[key][0]).all()]
    if not shown:
        return None
    fig, axes = plt.subplots(len(shown), 1, figsize=(7, 1.2 + 1.8 * len(shown)), sharex=True,
                             squeeze=False)
    for ax, (key, label) in zip(axes[:, 0], shown):
        t = np.sort(series[key][0])
        steps = np.diff(t) * 1e3
        ax.plot(t[1:], steps, ".", ms=2)
        if steps.max() > 10 * max(steps.min(), 1e-6):
            ax.set_yscale("log")
        else:
            ax.set_ylim(0.0, 1.2 * steps.max())
        ax.set(ylabel="[ms]", title=f"{label}: interval since the previous stamp")
        ax.grid(True, which="both", alpha=0.4)
    axes[-1, 0].set_xlabel("time [s]")
    return _save(fig, os.path.join(out_dir, "timing.png"))


def _plot_diagnostics(diagnostics, out_dir):
    """diagnostics.png: each /diagnostics status's level over time (OK 0 ... STALE 3)."""
    names = sorted({name for _, name, _, _ in diagnostics})
    fig, ax = plt.subplots(figsize=(7, 1.2 + 0.5 * len(names)))
    for row, name in enumerate(names):
        found = [(t, DIAGNOSTIC_LEVELS.get(level, 3)) for t, n, level, _ in diagnostics
                 if n == name]
        t, level = np.array(found).T
        ax.step(t, row + 0.2 * level, where="post", label=name)
    ax.set_yticks(range(len(names)), names)
    ax.set(xlabel="time [s]", title="/diagnostics: each status's level (a step up: WARN, "
           "two: ERROR)")
    ax.grid(True, alpha=0.4)
    return _save(fig, os.path.join(out_dir, "diagnostics.png"))
