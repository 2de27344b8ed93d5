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

"""``vas compare``: the paper's controller against its baselines, scenario by scenario.

For each base configuration (by default config/paper_3dof.yaml and the
noise-robust preset config/paper_3dof_noisy.yaml) and each :data:`SCENARIOS`
entry, the closed loop of :func:`~.runner.run_scenario` is run with each of
:data:`CONTROLLERS`:

``observer``
    the paper's controller (H. Wang 2015): image-space observer, no image velocity;
``velocity-diff``
    :class:`~.baselines.VelocityAdaptiveTracker` on the raw backward difference
    of the pixels (prediction-error gain 1e-3);
``velocity-lp``
    the same with a first-order low-pass of time constant 0.1 s;
``ibvs-calibrated``
    :class:`~.baselines.CalibratedIBVS`, true camera and arm: the upper reference.

The adaptive controllers all use the base configuration's gains, initial
estimates, bounds and torque limit.  Figures of one run, over the window after
the transient (t >= ``transient``, 5 s by default):

* RMS and max of the true image error, max_i |x_true,i - x_d,i| [px], from the
  noiseless pixels: the tracking itself, not the measurement noise;
* torque RMS, sqrt(mean |tau|^2) [N m];
* torque-rate RMS, sqrt(mean |(tau_k - tau_k-1) / T|^2) [N m/s]: the chatter;
* divergence: the runner's verdict (|tau| above ``divergence_torque``,
  non-finite or runaway joint state) and when.

Outputs in the output folder: compare.md (tables), compare.json (every figure),
compare_error.png, compare_chatter.png, compare_timeseries.png, and runs/ with
each run's timeseries.csv and summary.json.
"""

from __future__ import annotations

import csv
import functools
import math
import os
import sys
from dataclasses import dataclass

import numpy as np

PACKAGE_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# the names of controllers(), known without importing the controllers (vas start-up)
CONTROLLER_NAMES = ("observer", "velocity-diff", "velocity-lp", "ibvs-calibrated")
DEFAULT_CONFIGS = ("paper_3dof.yaml", "paper_3dof_noisy.yaml")
TRANSIENT_S = 5.0
LOW_PASS_S = 0.1
PREDICTION_GAIN = 1e-3


@dataclass(frozen=True)
class Scenario:
    """One condition: parameter overrides on top of a base configuration."""

    name: str
    label: str
    overrides: tuple


def scenarios(model):
    """The compared conditions; wrong estimates are relative to the model's true values."""
    clean = ("sim_node.pixel_noise_std=0.0", "sim_node.camera_latency=0.0")

    def estimates(factor):
        a_perp = [float(v) * factor for v in model.a_z_perp]
        a_z = [float(v) * factor for v in model.a_z]
        return clean + (f"controller_node.a_z_perp_init={a_perp}",
                        f"controller_node.a_z_init={a_z}")

    return (
        Scenario("clean", "clean", clean),
        Scenario("noise_0.25", "pixel noise 0.25 px", ("sim_node.pixel_noise_std=0.25",
                                                       "sim_node.camera_latency=0.0")),
        Scenario("noise_0.5", "pixel noise 0.5 px", ("sim_node.pixel_noise_std=0.5",
                                                     "sim_node.camera_latency=0.0")),
        Scenario("noise_1", "pixel noise 1 px", ("sim_node.pixel_noise_std=1.0",
                                                 "sim_node.camera_latency=0.0")),
        Scenario("delay_1", "camera delay 1 frame", ("sim_node.pixel_noise_std=0.0",
                                                     "sim_node.camera_latency=0.005")),
        Scenario("delay_2", "camera delay 2 frames", ("sim_node.pixel_noise_std=0.0",
                                                      "sim_node.camera_latency=0.01")),
        Scenario("estimates_x0.5", "kinematic estimates x0.5", estimates(0.5)),
        Scenario("estimates_x2", "kinematic estimates x2", estimates(2.0)),
    )


def controllers():
    """(name, description, factory) of every compared controller."""
    from .baselines import CalibratedIBVS, VelocityAdaptiveTracker
    from .controller import AdaptiveVisualTracker

    return (
        ("observer", "Wang 2015: observer, no image velocity (this package)",
         AdaptiveVisualTracker),
        ("velocity-diff", "velocity-based adaptive, backward-difference image velocity",
         functools.partial(VelocityAdaptiveTracker, prediction_gain=PREDICTION_GAIN)),
        ("velocity-lp", f"velocity-based adaptive, backward difference + {LOW_PASS_S:g} s "
         "first-order low-pass",
         functools.partial(VelocityAdaptiveTracker, filter_time=LOW_PASS_S,
                           prediction_gain=PREDICTION_GAIN)),
        ("ibvs-calibrated", "calibrated IBVS + computed torque (true camera and arm)",
         CalibratedIBVS),
    )


def controller_factory(name):
    """The factory of the controller called ``name`` (one of :data:`CONTROLLER_NAMES`)."""
    from .config import ConfigError

    for known, _, factory in controllers():
        if known == name:
            return factory
    raise ConfigError(f"controller: must be one of {list(CONTROLLER_NAMES)}, got {name!r}")


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


def run_figures(t, x_true, x_d, tau, period, transient=TRANSIENT_S):
    """The figures of one run over t >= ``transient`` (see the module docstring)."""
    from .runner import point_error     # lazy like run_compare's: keeps `vas` start-up light

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


def run_compare(out_dir, configs=None, duration=30.0, transient=TRANSIENT_S, seed=None,
                progress=sys.stderr):
    """Run every (configuration, scenario, controller); return the list of result dicts."""
    from .config import ConfigError, load_scenario
    from .runner import run_scenario

    configs = list(configs) if configs else default_configs()
    ctls = controllers()
    results = []
    for config in configs:
        base = os.path.splitext(os.path.basename(config))[0]
        model = load_scenario(config).controller.model
        for scen in scenarios(model):
            overrides = scen.overrides + ((f"sim_node.seed={seed}",) if seed is not None else ())
            try:
                scenario = load_scenario(config, overrides)
            except ConfigError as exc:
                results += [_refused(base, scen, name, str(exc)) for name, _, _ in ctls]
                continue
            period = scenario.sim.control_period
            for name, _, factory in ctls:
                run_dir = os.path.join(out_dir, "runs", base, scen.name, name)
                if progress is not None:
                    print(f"{base} / {scen.name} / {name}", file=progress, flush=True)
                summary = run_scenario(scenario, run_dir, duration=duration, progress=False,
                                       record=False, plots=False, controller_factory=factory)
                figures = run_figures(*read_timeseries(os.path.join(run_dir, "timeseries.csv")),
                                      period, transient)
                results.append({
                    "config": base, "scenario": scen.name, "scenario_label": scen.label,
                    "controller": name, **figures,
                    "diverged": bool(summary["diverged"]),
                    "divergence_reason": summary["divergence_reason"],
                    "diverged_at_s": (summary["sim_time_s"] if summary["diverged"] else None),
                    "peak_abs_torque": summary["max_abs_torque"],
                    "saturated_samples": summary["saturated"],
                    "error": summary.get("error"),
                })
    return results


def default_configs():
    paths = [os.path.join(PACKAGE_ROOT, "config", name) for name in DEFAULT_CONFIGS]
    return [p for p in paths if os.path.exists(p)]


def _refused(base, scen, name, reason):
    return {"config": base, "scenario": scen.name, "scenario_label": scen.label,
            "controller": name, "rms_error_px": math.nan, "max_error_px": math.nan,
            "torque_rms": math.nan, "torque_rate_rms": math.nan, "window_s": 0.0,
            "diverged": False, "divergence_reason": "", "diverged_at_s": None,
            "peak_abs_torque": math.nan, "saturated_samples": 0, "error": reason}


def _cell(r, key, fmt):
    if r["error"]:
        return "error"
    if r["diverged"]:
        return f"div @ {r['diverged_at_s']:.2f} s"
    value = r[key]
    return "-" if not math.isfinite(value) else format(value, fmt)


def markdown(results, duration, transient):
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
                      f"diverged at {r['diverged_at_s']:.2f} s: {r['divergence_reason']}"
                      if r["diverged"] else "ok")
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
    from .runner import point_error

    shown = ("clean", "noise_0.5", "delay_2")
    fig, axes = plt.subplots(len(configs), len(shown), figsize=(12, 3.2 * len(configs)),
                             squeeze=False, sharex=True)
    for row, config in enumerate(configs):
        for col, scen in enumerate(shown):
            ax = axes[row, col]
            for name in names:
                path = os.path.join(out_dir, "runs", config, scen, name, "timeseries.csv")
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
    """``vas compare``: run everything, write compare.md/.json and the plots."""
    from .recording import write_json

    os.makedirs(args.out, exist_ok=True)
    results = run_compare(args.out, args.config, args.duration, args.transient, args.seed)
    text = markdown(results, args.duration, args.transient)
    with open(os.path.join(args.out, "compare.md"), "w", encoding="utf-8") as handle:
        handle.write(text + "\n")
    write_json(os.path.join(args.out, "compare.json"),
               {"duration_s": args.duration, "transient_s": args.transient, "runs": results})
    plots = [] if args.no_plots else plot_compare(results, args.out, args.transient)
    print(text)
    print(f"outputs in {args.out}: compare.md, compare.json"
          + "".join(f", {os.path.basename(p)}" for p in plots) + ", runs/")
    return 1 if any(r["error"] for r in results) else 0


def add_parser(subparsers):
    """Register ``vas compare`` (called by :func:`~.cli.build_parser`)."""
    cmp = subparsers.add_parser("compare", help="the paper's controller against baselines "
                                "(velocity-based adaptive, calibrated IBVS)")
    cmp.add_argument("--out", required=True, help="output folder (created)")
    cmp.add_argument("--duration", type=float, default=30.0, help="simulated seconds per run")
    cmp.add_argument("--config", action="append", metavar="FILE",
                     help="base configuration (repeatable; default: config/paper_3dof.yaml "
                     "and config/paper_3dof_noisy.yaml)")
    cmp.add_argument("--transient", type=float, default=TRANSIENT_S,
                     help="figures are taken over t >= this [s]")
    cmp.add_argument("--seed", type=int, help="pixel-noise seed (default: the configuration's)")
    cmp.add_argument("--no-plots", action="store_true", help="tables only")
    cmp.set_defaults(func=cmd_compare)
    return cmp
