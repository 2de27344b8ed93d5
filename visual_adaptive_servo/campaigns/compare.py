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

"""``vas compare``: the paper's controller against its baselines, condition by condition.

The comparison is a campaign (:mod:`.campaign`): ``config/campaigns/compare.yaml``
names the conditions (cases: noise, camera delay, wrong estimates, slow and late
cameras) and crosses them with the base configurations (config/paper_3dof.yaml, the
noise-robust preset, and the package's defaults on the same arm: paper_3dof_urdf.yaml)
and every controller of
:mod:`visual_adaptive_servo.control.registry` (the paper's and its baselines).

The adaptive controllers all use the base configuration's gains, initial
estimates, bounds and torque limit; every controller gets the same camera frames.
Figures of one run, over the window after the transient (t >= 5 s;
:func:`visual_adaptive_servo.recording.summary.run_figures`):

* RMS and max of the true image error, max_i |x_true,i - x_d,i| [px], from the
  noiseless pixels: the tracking itself, not the measurement noise;
* torque RMS, sqrt(mean |tau|^2) [N m];
* torque-rate RMS, sqrt(mean |(tau_k - tau_k-1) / T|^2) [N m/s]: the chatter;
* divergence: the runner's verdict (|tau| above ``divergence_torque``,
  non-finite or runaway joint state) and when.

Outputs in the output folder: compare.md (tables), compare.json (every figure),
compare_error.png, compare_chatter.png, compare_timeseries.png, campaign/ (the
campaign's runs.csv and summary) and runs/<id>/ with each run's timeseries.csv and
summary.json.
"""

from __future__ import annotations

import argparse
import csv
import functools
import math
import os

import numpy as np

from ..control.registry import controllers
from ..models.resources import OWN_SHARE
from ..recording.summary import point_error, TRANSIENT_S

SPEC = os.path.join(OWN_SHARE["config"], "campaigns", "compare.yaml")
LABELS = {"clean": "clean", "noise_0.25": "pixel noise 0.25 px", "noise_0.5": "pixel noise 0.5 px",
          "noise_1": "pixel noise 1 px", "delay_1": "camera 5 ms late (1 frame)",
          "delay_2": "camera 10 ms late (2 frames)",
          "estimates_x0.5": "kinematic estimates x0.5", "estimates_x2": "kinematic estimates x2",
          "camera_30hz_0ms": "camera 30 Hz, 1 kHz joints",
          "camera_30hz_33ms": "camera 30 Hz, 33 ms late, 1 kHz joints",
          "camera_30hz_66ms": "camera 30 Hz, 66 ms late, 1 kHz joints",
          "camera_60hz_20ms": "camera 60 Hz, 20 ms late, 1 kHz joints"}


def read_timeseries(path):
    """t (N,), x_true (N, 2m), x_d (N, 2m), tau (N, n) from a run's timeseries.csv."""
    with open(path, encoding="utf-8", newline="") as handle:
        rows = list(csv.reader(handle))
    header, body = rows[0], rows[1:]

    def block(prefix):
        cols = [i for i, name in enumerate(header) if name.startswith(prefix + ".")]
        return np.array([[float(r[i]) for i in cols] for r in body]).reshape(len(body), -1)

    t = np.array([float(r[0]) for r in body])
    return t, block("x_true"), block("x_d"), block("tau")


def run_compare(out_dir, spec=SPEC, workers=None, ray=None, duration=None, seed=None,
                progress=None):
    """Run the comparison campaign in ``out_dir``; return the list of result dicts.

    ``duration`` and ``seed`` (the pixel-noise seed) override the spec's; the runs go
    to the campaign engine (``workers`` processes, or Ray), resumable like any campaign.
    """
    from .campaign import CSV_NAME, read_rows, run_campaign
    from .engine import execute_run
    from .spec import derived_spec, load_spec

    os.makedirs(out_dir, exist_ok=True)
    if duration is not None or seed is not None:
        spec = derived_spec(spec, os.path.join(out_dir, "compare_spec.yaml"), duration,
                            None if seed is None else {"seed": int(seed)})
    keep = os.path.join(out_dir, "runs")
    run_campaign(spec, os.path.join(out_dir, "campaign"), workers, ray,
                 run_fn=functools.partial(execute_run, keep_dir=keep), progress=progress)
    loaded = load_spec(spec)
    rows = read_rows(os.path.join(out_dir, "campaign", CSV_NAME), loaded)
    base = os.path.splitext(os.path.basename(loaded.base))[0]
    results = []
    for row in sorted(rows, key=lambda r: r["id"]):
        f = row["factors"]
        config = os.path.splitext(f.get("base") or base)[0]
        failed = row["status"] != "finished"
        results.append({
            "id": row["id"], "config": config, "scenario": f["case"],
            "scenario_label": LABELS.get(f["case"], f["case"]), "controller": f["controller"],
            "rms_error_px": row["transient_rms_true_error_px"],
            "max_error_px": row["transient_max_true_error_px"],
            "torque_rms": row["torque_rms"], "torque_rate_rms": row["torque_rate_rms"],
            "diverged": row["diverged"] and not failed,
            "diverged_at_s": row["sim_time_s"] if row["diverged"] else None,
            "peak_abs_torque": row["max_abs_torque"],
            "error": row["reason"] if failed else None,
            "timeseries": os.path.join(keep, f"{row['id']:05d}", "timeseries.csv"),
            "command": row["command"]})
    return results


def _cell(r, key, fmt):
    if r["error"]:
        return "error"
    if r["diverged"]:
        return f"div @ {r['diverged_at_s']:.2f} s"
    value = r[key]
    return "-" if not math.isfinite(value) else format(value, fmt)


def markdown(results, duration, transient=TRANSIENT_S):
    """compare.md: a headline table per base configuration, then every figure."""
    names = [name for name, _, _ in controllers()]
    lines = [f"# Observer-based adaptive tracking vs baselines ({duration:g} s per run, "
             f"figures over t >= {transient:g} s)", "",
             "Controllers:", ""]
    lines += [f"- `{name}`: {desc}" for name, desc, _ in controllers()]
    lines += ["", "Cells: true (noiseless) image error RMS [px] after the transient; "
              "`div @ t` = diverged at simulated time t.", ""]
    for config in dict.fromkeys(r["config"] for r in results):
        rows = [r for r in results if r["config"] == config]
        lines += [f"## Base configuration `{config}.yaml`", "",
                  "| scenario | " + " | ".join(f"`{n}`" for n in names) + " |",
                  "|---|" + "---:|" * len(names)]
        for scen in dict.fromkeys(r["scenario"] for r in rows):
            cells = {r["controller"]: r for r in rows if r["scenario"] == scen}
            label = next(iter(cells.values()))["scenario_label"]
            lines.append(f"| {label} | " + " | ".join(
                _cell(cells[n], "rms_error_px", ".3f") if n in cells else "" for n in names)
                + " |")
        lines += ["", "| scenario | controller | RMS err [px] | max err [px] | torque RMS "
                  "[N m] | torque-rate RMS [N m/s] | peak abs torque [N m] | result |",
                  "|---|---|---:|---:|---:|---:|---:|---|"]
        for r in rows:
            result = ("error: " + r["error"] if r["error"] else
                      f"diverged at {r['diverged_at_s']:.2f} s" if r["diverged"] else "ok")
            lines.append(
                f"| {r['scenario_label']} | `{r['controller']}` | "
                f"{_fmt(r['rms_error_px'], '.4f')} | {_fmt(r['max_error_px'], '.3f')} | "
                f"{_fmt(r['torque_rms'], '.1f')} | {_fmt(r['torque_rate_rms'], '.0f')} | "
                f"{_fmt(r['peak_abs_torque'], '.1f')} | {result} |")
        lines.append("")
    return "\n".join(lines)


def _fmt(value, fmt):
    return format(value, fmt) if value is not None and math.isfinite(value) else "-"


def plot_compare(results, out_dir, transient=TRANSIENT_S):
    """Bar charts of the image error and the chatter, and error time series; returns paths."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [name for name, _, _ in controllers()]
    configs = list(dict.fromkeys(r["config"] for r in results))
    paths = []
    for key, ylabel, fname in (
            ("rms_error_px", f"true image error RMS, t >= {transient:g} s [px]",
             "compare_error.png"),
            ("torque_rate_rms", "torque-rate RMS [N m/s] (chatter)", "compare_chatter.png")):
        fig, axes = plt.subplots(len(configs), 1, figsize=(10, 3.6 * len(configs)),
                                 squeeze=False)
        for ax, config in zip(axes[:, 0], configs):
            rows = [r for r in results if r["config"] == config]
            scens = list(dict.fromkeys(r["scenario"] for r in rows))
            width = 0.8 / len(names)
            finite = [r[key] for r in rows if not r["diverged"] and math.isfinite(r[key])]
            top = max(finite) * 3 if finite else 1.0
            for j, name in enumerate(names):
                xs, hs, divs = [], [], []
                for i, scen in enumerate(scens):
                    r = next((r for r in rows if r["scenario"] == scen
                              and r["controller"] == name), None)
                    pos = i + (j - (len(names) - 1) / 2) * width
                    if r is None:
                        continue
                    if r["diverged"] or not math.isfinite(r[key]):
                        divs.append(pos)
                    else:
                        xs.append(pos)
                        hs.append(r[key])
                bars = ax.bar(xs, hs, width, label=name)
                ax.plot(divs, [top] * len(divs), "x", color=bars.patches[0].get_facecolor()
                        if bars.patches else "k", markersize=9, mew=2)
            ax.set_yscale("log")
            ax.set_xticks(range(len(scens)))
            ax.set_xticklabels([s.replace("_", " ") for s in scens], fontsize=8)
            ax.set_ylabel(ylabel, fontsize=8)
            ax.set_title(f"{config}.yaml (x at the top: diverged)", fontsize=9)
            ax.grid(True, axis="y", which="both", alpha=0.3)
        axes[0, 0].legend(fontsize=8, ncol=len(names))
        fig.tight_layout()
        path = os.path.join(out_dir, fname)
        fig.savefig(path, dpi=80)
        plt.close(fig)
        paths.append(path)
    paths.append(_plot_timeseries(results, out_dir, configs, names, plt))
    return paths


def _plot_timeseries(results, out_dir, configs, names, plt):
    shown = ("clean", "noise_0.5", "camera_30hz_33ms")
    fig, axes = plt.subplots(len(configs), len(shown), figsize=(12, 3.2 * len(configs)),
                             squeeze=False, sharex=True)
    for row, config in enumerate(configs):
        for col, scen in enumerate(shown):
            ax = axes[row, col]
            for name in names:
                path = next((r["timeseries"] for r in results if r["config"] == config
                             and r["scenario"] == scen and r["controller"] == name), "")
                if not os.path.exists(path):
                    continue
                t, x_true, x_d, _ = read_timeseries(path)
                err = point_error(x_true, x_d)
                every = max(1, len(t) // 600)       # keeps the PNG small
                ax.semilogy(t[::every], np.maximum(err[::every], 1e-4), lw=0.8, label=name)
            ax.set_ylim(1e-4, 1e2)
            ax.set_title(f"{config}.yaml, {scen.replace('_', ' ')}", fontsize=9)
            ax.grid(True, which="both", alpha=0.3)
            if col == 0:
                ax.set_ylabel("true image error [px]", fontsize=8)
            if row == len(configs) - 1:
                ax.set_xlabel("t [s]", fontsize=8)
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    path = os.path.join(out_dir, "compare_timeseries.png")
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def cmd_compare(args):
    """``vas compare``: run the comparison campaign, write compare.md/.json and the plots."""
    from ..recording.recorder import write_json

    results = run_compare(args.out, args.spec, args.workers, args.ray, args.duration, args.seed,
                          args.progress)
    duration = args.duration or _spec_duration(args.spec)
    text = markdown(results, duration)
    with open(os.path.join(args.out, "compare.md"), "w", encoding="utf-8") as handle:
        handle.write(text + "\n")
    write_json(os.path.join(args.out, "compare.json"),
               {"duration_s": duration, "transient_s": TRANSIENT_S, "runs": results})
    plots = [] if args.no_plots else plot_compare(results, args.out)
    print(text)
    print(f"outputs in {args.out}: compare.md, compare.json"
          + "".join(f", {os.path.basename(p)}" for p in plots) + ", campaign/, runs/")
    return 1 if any(r["error"] for r in results) else 0


def _spec_duration(spec):
    from .spec import load_spec

    return load_spec(spec).duration


def add_parser(subparsers):
    """Register ``vas compare`` (called by :func:`visual_adaptive_servo.cli.build_parser`)."""
    cmp = subparsers.add_parser("compare", help="the paper's controller against baselines "
                                "(velocity-based adaptive, calibrated IBVS), as a campaign")
    cmp.add_argument("--out", required=True, help="output folder (created; rerun to resume)")
    cmp.add_argument("--spec", default=SPEC, help="the comparison campaign (default: "
                     "config/campaigns/compare.yaml)")
    cmp.add_argument("--duration", type=float, help="simulated seconds per run (default: "
                     "the spec's, 30 s)")
    cmp.add_argument("--seed", type=int, help="pixel-noise seed (default: the configuration's)")
    cmp.add_argument("--workers", type=int, help="worker processes (default: every core)")
    cmp.add_argument("--ray", metavar="auto|ADDRESS", help="run on Ray (pip install '.[ray]')")
    cmp.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                     help="progress bar (default: on a terminal)")
    cmp.add_argument("--no-plots", action="store_true", help="tables only")
    cmp.set_defaults(func=cmd_compare)
    return cmp
