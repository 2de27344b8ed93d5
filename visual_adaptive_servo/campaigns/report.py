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

"""What a campaign's rows say: divergence rate, error and torque quantiles, worst runs, plots.

Figures are read from runs.csv (so a resumed or interrupted campaign is reported
whole).  The divergence rate is over the finished runs, with its 95 % Wilson
score interval; the quantiles are over the finished runs that did not diverge
(a diverged run's error and torque describe the blow-up, not the tracking).
"""

from __future__ import annotations

import math
import os
import re

import numpy as np

Z_95 = 1.959963984540054       # standard normal quantile of 0.975
QUANTILES = (("p5", 0.05), ("p50", 0.5), ("p95", 0.95))
QUANTILE_FIGURES = (("final_rms_true_error_px", "true RMS image error, last 5 s [px]"),
                    ("final_rms_error_px", "measured RMS image error, last 5 s [px]"),
                    ("max_true_error_px", "max true image error [px]"),
                    ("transient_rms_true_error_px", "true RMS image error after 5 s [px]"),
                    ("transient_max_true_error_px", "max true image error after 5 s [px]"),
                    ("max_abs_torque", "max abs(tau) [N m]"),
                    ("wall_time_s", "wall time per run [s]"))
WORST = 10
MAX_LEVELS = 20


def wilson_interval(successes, trials, z=Z_95):
    """Wilson score interval (low, high) of a binomial proportion; (nan, nan) for 0 trials.

    With p = k/n: (p + z^2/2n +- z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n).
    """
    if trials == 0:
        return math.nan, math.nan
    p = successes / trials
    denom = 1.0 + z * z / trials
    centre = (p + z * z / (2 * trials)) / denom
    half = z * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


def quantiles(values):
    """{p5, p50, p95, max} of the finite values (linear interpolation); NaN when none."""
    finite = np.array([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if finite.size == 0:
        return {name: math.nan for name in ("p5", "p50", "p95", "max")}
    out = {name: float(np.quantile(finite, q)) for name, q in QUANTILES}
    out["max"] = float(finite.max())
    return out


def _rate(rows):
    finished = [r for r in rows if r["status"] == "finished"]
    diverged = sum(1 for r in finished if r["diverged"])
    low, high = wilson_interval(diverged, len(finished))
    return {"finished": len(finished), "diverged": diverged,
            "rate": diverged / len(finished) if finished else math.nan,
            "ci95": [low, high]}


def _severity(row):
    """Sort key, worst first: diverged, then the largest true RMS error."""
    err = row["final_rms_true_error_px"]
    return (not row["diverged"], -(err if err is not None and math.isfinite(err) else -1.0))


def summarize(rows, level_factors, total_runs, interrupted=False):
    """The campaign's figures as a JSON-ready dict.

    ``level_factors`` are the factors whose values are levels (cases, grid
    factors, random choices): each gets a divergence rate per value.
    """
    finished = [r for r in rows if r["status"] == "finished"]
    calm = [r for r in finished if not r["diverged"]]
    failed = [r for r in rows if r["status"] == "failed"]
    by_factor = {}
    for column in level_factors:
        levels = list(dict.fromkeys(r["factors"].get(column) for r in rows))
        if len(levels) > MAX_LEVELS:
            continue
        by_factor[column] = {
            str(level): {**_rate([r for r in rows if r["factors"].get(column) == level]),
                         "median_final_rms_true_error_px": quantiles(
                             [r["final_rms_true_error_px"] for r in calm
                              if r["factors"].get(column) == level])["p50"]}
            for level in levels}
    return {
        "runs_in_spec": total_runs,
        "rows": len(rows),
        "finished": len(finished),
        "failed": len(failed),
        "interrupted": interrupted,
        "divergence": _rate(rows),
        "quantiles_over": "finished runs that did not diverge",
        "quantiles": {key: quantiles([r.get(key) for r in calm])
                      for key, _ in QUANTILE_FIGURES},
        "by_factor": by_factor,
        "worst": [{"id": r["id"], "factors": r["factors"], "diverged": r["diverged"],
                   "reason": r.get("reason", "") if r["diverged"] else "",
                   "final_rms_true_error_px": r["final_rms_true_error_px"],
                   "max_true_error_px": r["max_true_error_px"],
                   "max_abs_torque": r["max_abs_torque"], "command": r["command"]}
                  for r in sorted(finished, key=_severity)[:WORST]],
        "failed_runs": [{"id": r["id"], "reason": r["reason"], "attempts": r["attempts"],
                         "command": r["command"]} for r in failed],
    }


def _fmt(value, fmt=".4g"):
    return "-" if value is None or not math.isfinite(value) else format(value, fmt)


def _pct(value):
    return "-" if not math.isfinite(value) else f"{100 * value:.1f} %"


def _factors_text(factors):
    return ", ".join(f"{k}={v}" for k, v in factors.items()) or "-"


def markdown(summary, title, plots):
    """summary.md: what was run, the divergence rate, quantiles, worst and failed runs."""
    div = summary["divergence"]
    lines = [f"# Campaign `{title}`", "",
             f"{summary['rows']} of {summary['runs_in_spec']} runs recorded: "
             f"{summary['finished']} finished, {summary['failed']} failed"
             + (" (interrupted: rerun the same command to resume)."
                if summary["rows"] < summary["runs_in_spec"] else "."), "",
             f"**Divergence:** {div['diverged']} of {div['finished']} finished runs = "
             f"{_pct(div['rate'])} (95 % Wilson interval {_pct(div['ci95'][0])} to "
             f"{_pct(div['ci95'][1])}).", "",
             f"Quantiles over the {summary['finished'] - div['diverged']} finished runs that "
             "did not diverge (linear interpolation):", "",
             "| figure | 5 % | 50 % | 95 % | max |", "|---|---:|---:|---:|---:|"]
    for key, label in QUANTILE_FIGURES:
        q = summary["quantiles"][key]
        lines.append(f"| {label} | {_fmt(q['p5'])} | {_fmt(q['p50'])} | {_fmt(q['p95'])} "
                     f"| {_fmt(q['max'])} |")
    for column, levels in summary["by_factor"].items():
        lines += ["", f"By `{column}`:", "",
                  "| value | finished | diverged | rate (95 % interval) | median true RMS [px] |",
                  "|---|---:|---:|---|---:|"]
        for level, r in levels.items():
            lines.append(f"| {level} | {r['finished']} | {r['diverged']} | {_pct(r['rate'])} "
                         f"({_pct(r['ci95'][0])} to {_pct(r['ci95'][1])}) "
                         f"| {_fmt(r['median_final_rms_true_error_px'])} |")
    lines += ["", f"## The worst {len(summary['worst'])} runs", "",
              "Diverged first, then by true RMS error.", "",
              "| id | factors | diverged | true RMS [px] | max true error [px] "
              "| max abs(tau) [N m] |", "|---:|---|---|---:|---:|---:|"]
    for r in summary["worst"]:
        lines.append(f"| {r['id']} | {_factors_text(r['factors'])} "
                     f"| {_diverged_text(r)} "
                     f"| {_fmt(r['final_rms_true_error_px'])} | {_fmt(r['max_true_error_px'])} "
                     f"| {_fmt(r['max_abs_torque'])} |")
    lines += ["", "Reproduce one:", ""]
    lines += [f"- run {r['id']}: `{r['command']}`" for r in summary["worst"]]
    if summary["failed_runs"]:
        lines += ["", "## Failed runs", "", "| id | attempts | reason | command |",
                  "|---:|---:|---|---|"]
        lines += [f"| {r['id']} | {r['attempts']} | {r['reason']} | `{r['command']}` |"
                  for r in summary["failed_runs"]]
    if plots:
        lines += ["", "## Plots", ""] + [f"![{os.path.splitext(p)[0]}]({p})" for p in plots]
    return "\n".join(lines) + "\n"


def _diverged_text(row):
    """'no', or 'yes' with why (the run's reason: what crossed its limit, what grew first)."""
    if not row["diverged"]:
        return "no"
    reason = row.get("reason", "")
    return f"yes: {reason.replace('|', '/')}" if reason else "yes"


def plot_file_name(factor):
    """error_vs_<factor>.png, with anything but letters, digits, '.', '_', '-' as '_'."""
    return "error_vs_" + re.sub(r"[^A-Za-z0-9._-]", "_", factor) + ".png"


def _positive(values):
    return [max(v, 1e-6) for v in values]


def plot_campaign(rows, sampled_factors, out_dir):
    """error_histogram.png and error_vs_<factor>.png (but the seed's); returns the file names."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    finished = [r for r in rows if r["status"] == "finished"]
    calm = [r for r in finished
            if not r["diverged"] and math.isfinite(r["final_rms_true_error_px"])]
    names = []
    fig, ax = plt.subplots(figsize=(7, 4))
    errors = _positive([r["final_rms_true_error_px"] for r in calm])
    if errors:
        low, high = min(errors), max(errors)
        log = high > 10 * low
        bins = (np.geomspace(low, high * 1.0001, 30) if log else 30)
        ax.hist(errors, bins=bins)
        if log:
            ax.set_xscale("log")
    ax.set_xlabel("true RMS image error, last 5 s [px]")
    ax.set_ylabel("runs")
    ax.set_title(f"{len(calm)} runs that did not diverge; {len(finished) - len(calm)} "
                 f"diverged or without figure; {len(rows) - len(finished)} failed", fontsize=9)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "error_histogram.png"), dpi=80)
    plt.close(fig)
    names.append("error_histogram.png")
    for factor in sampled_factors:
        if factor != "seed":        # a noise seed is a label: the error does not depend on it
            names.append(_plot_factor(plt, finished, factor, out_dir))
    return names


def _plot_factor(plt, finished, factor, out_dir):
    values = [r["factors"].get(factor) for r in finished]
    numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
    if numeric:
        xs, labels = [float(v) for v in values], None
    else:
        labels = list(dict.fromkeys(str(v) for v in values))
        xs = [labels.index(str(v)) for v in values]
    calm = [(x, r["final_rms_true_error_px"]) for x, r in zip(xs, finished)
            if not r["diverged"] and math.isfinite(r["final_rms_true_error_px"])]
    fig, ax = plt.subplots(figsize=(7, 4))
    top = max([e for _, e in calm], default=1.0) * 3
    if calm:
        ax.plot([x for x, _ in calm], _positive([e for _, e in calm]), "o", ms=4, alpha=0.6,
                label="did not diverge")
    div = [x for x, r in zip(xs, finished) if r["diverged"]]
    if div:
        ax.plot(div, [top] * len(div), "x", color="tab:red", ms=8, mew=2, label="diverged")
    ax.set_yscale("log")
    if labels is not None:
        ax.set_xticks(range(len(labels)))
        ax.set_xticklabels(labels, fontsize=8, rotation=20)
    ax.set_xlabel(factor)
    ax.set_ylabel("true RMS image error, last 5 s [px]")
    ax.grid(True, which="both", alpha=0.3)
    if calm or div:
        ax.legend(fontsize=8)
    fig.tight_layout()
    name = plot_file_name(factor)
    fig.savefig(os.path.join(out_dir, name), dpi=80)
    plt.close(fig)
    return name
