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


def _save(fig, path):
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_run(series, out_dir, labels):
    """Write the standard plots of one run; returns the list of PNG paths.

    ``series`` maps names to arrays over time: t (N,), x (measured), x_true
    (noiseless), x_d, x_obs (N, 2m),
    z, z_hat (N, m), tau (N, n), a_z_perp, a_z, a_d (N, p).
    ``labels`` maps a_z_perp / a_z / a_d to their entry names.
    """
    t = series["t"]
    paths = []
    err = series["x"] - series["x_d"]
    err_true = series["x_true"] - series["x_d"]
    noisy = bool(np.nanmax(np.abs(err - err_true)) > 1e-9) if len(t) else False
    fig, (ax, ax_max) = plt.subplots(2, 1, figsize=(7, 6.5), sharex=True,
                                     gridspec_kw={"height_ratios": (3, 2)})
    for i in range(err.shape[1]):
        axis, point = "uv"[i % 2], i // 2 + 1
        name = f"{axis}{point} - {axis}d{point}"
        if noisy:
            line, = ax.plot(t, err[:, i], lw=0.5, alpha=0.35, label=f"{name} measured")
            ax.plot(t, err_true[:, i], color=line.get_color(), label=f"{name} true")
        else:
            ax.plot(t, err[:, i], label=name)
    ax.set(ylabel="image error [px]", title="Image-space tracking error x - x_d (paper Fig. 2)")
    ax.grid(True)
    ax.legend(fontsize=7, ncol=2)
    # the summary figures use the largest point error, shown here on a log scale
    m = err.shape[1] // 2
    largest = np.linalg.norm(err_true.reshape(len(t), m, 2), axis=2).max(axis=1)
    ax_max.semilogy(t, np.maximum(largest, 1e-6), lw=0.8, color="k")
    ax_max.set(xlabel="time [s]", ylabel="largest point error [px]")
    ax_max.grid(True, which="both", alpha=0.4)
    paths.append(_save(fig, os.path.join(out_dir, "tracking_error.png")))

    fig, ax = plt.subplots(figsize=(7, 4))
    for i in range(series["z"].shape[1]):
        ax.plot(t, series["z"][:, i], label=f"z{i + 1} actual")
        ax.plot(t, series["z_hat"][:, i], "--", label=f"z{i + 1} estimated")
    ax.set(xlabel="time [s]", ylabel="depth [m]",
           title="Actual and estimated depth (paper Fig. 3)")
    ax.grid(True)
    ax.legend()
    paths.append(_save(fig, os.path.join(out_dir, "depth.png")))

    fig, ax = plt.subplots(figsize=(7, 4))
    for i in range(series["tau"].shape[1]):
        ax.plot(t, series["tau"][:, i], label=f"tau{i + 1}")
    ax.set(xlabel="time [s]", ylabel="torque [N m]", title="Joint torques")
    ax.grid(True)
    ax.legend()
    paths.append(_save(fig, os.path.join(out_dir, "torques.png")))

    fig, axes = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
    for ax, key, title in zip(axes, ("a_z_perp", "a_z", "a_d"),
                              ("a_z_perp (eq 24)", "a_z (eq 25)", "a_d (eq 23)")):
        for i, name in enumerate(labels[key]):
            ax.plot(t, series[key][:, i], label=name, lw=0.8)
        count = len(labels[key])
        ax.set(ylabel="estimate", title=f"{title}, {count} entries")
        ax.grid(True)
        if count <= 12:
            ax.legend(fontsize=7, ncol=4)
    axes[-1].set_xlabel("time [s]")
    paths.append(_save(fig, os.path.join(out_dir, "parameters.png")))

    fig, ax = plt.subplots(figsize=(6, 6))
    for i in range(series["x"].shape[1] // 2):
        u, v = 2 * i, 2 * i + 1
        tag = f"{i + 1}" if series["x"].shape[1] > 2 else ""
        first = i == 0
        ax.plot(series["x"][:, u], series["x"][:, v], ".", ms=1, alpha=0.3, color="tab:orange",
                label="x measured" if first else None)
        ax.plot(series["x_true"][:, u], series["x_true"][:, v], lw=1, color="tab:orange",
                label="x" if first else None)
        ax.plot(series["x_obs"][:, u], series["x_obs"][:, v], lw=1, color="tab:blue",
                label="x_o" if first else None)
        ax.plot(series["x_d"][:, u], series["x_d"][:, v], "k--", lw=1,
                label="x_d" if first else None)
        ax.plot(series["x_true"][0, u], series["x_true"][0, v], "go",
                label="start" if first else None)
        if tag:
            ax.annotate(tag, (series["x_true"][0, u], series["x_true"][0, v]),
                        textcoords="offset points", xytext=(5, 5))
    ax.set(xlabel="u [px]", ylabel="v [px]", title="Image-plane path")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True)
    ax.legend()
    paths.append(_save(fig, os.path.join(out_dir, "image_path.png")))
    return paths
