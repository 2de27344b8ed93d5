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

"""The defaults on arms nobody tuned them for: random arms, a guessed camera, a taught path.

Draws ``--arms`` arms (:mod:`visual_adaptive_servo.campaigns.unseen_arms`: 3-6 joints,
1-3 points, a guessed camera, lengths and inertia; seeds ``--first-seed`` on) and runs
each with the defaults, ``--duration`` simulated seconds:

* ``clean``: the camera at every control period, no noise, no latency;
* ``real s``: for each ``--noise-seeds`` s, a real camera: 30 Hz, 33 ms from capture to
  the controller, 0.5 px of pixel noise (seed s); the controller is told the rate and
  the latency, as a user writes them into controller_node.

For each run: diverged or not (and why), the true tracking error's RMS over the last
5 s and its largest value.  ``--set`` overrides go to every run (e.g.
``controller_node.gain_design.singular_fraction=0`` to measure without an option).

Usage::

    python benchmarks/unseen_arms.py [--arms 64] [--first-seed 1] [--noise-seeds 1 2]
        [--duration 30] [--workers 2] [--out runs/unseen_arms] [--guess-scale 1]
        [--set KEY=VALUE ...]

Writes OUT/results.csv (a row per run), OUT/summary.json, OUT/unseen_arms.png (each
condition's errors, sorted; divergences marked) and OUT/arms/ (the drawn files: rerun
one with ``vas run --config OUT/arms/arm<seed>.yaml``).
"""

from __future__ import annotations

import argparse
import csv
import json
import logging
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from benchlib import environment  # noqa: E402

from visual_adaptive_servo.campaigns.engine import DIVERGENCE_REASON, execute_run  # noqa: E402
from visual_adaptive_servo.campaigns.spec import DEFAULT_CONTROLLER, Run  # noqa: E402
from visual_adaptive_servo.campaigns.unseen_arms import random_arm  # noqa: E402
from visual_adaptive_servo.runner import Progress  # noqa: E402

#: the figures kept of each run (its summary.json keys)
FIGURES = ("diverged", "final_rms_true_error_px", "max_true_error_px", "max_abs_torque")

REAL_CAMERA = ("sim_node.camera_rate=30", "sim_node.camera_latency=0.033",
               "sim_node.pixel_noise_std=0.5", "controller_node.camera_rate=30",
               "controller_node.camera_latency=0.033")


def conditions(noise_seeds):
    """(name, overrides) of each run of an arm."""
    out = [("clean", ())]
    out += [(f"real {s}", REAL_CAMERA + (f"sim_node.seed={s}",)) for s in noise_seeds]
    return out


def quiet():
    """Worker start: the runs' warnings (start-up, first frame) would bury the progress."""
    logging.getLogger("visual_adaptive_servo").setLevel(logging.ERROR)


def run_one(job):
    """One run in a worker (the campaigns' run function): (arm fields, condition, figures)."""
    arm, name, overrides, duration = job
    run = Run(0, {}, arm["path"], duration, DEFAULT_CONTROLLER, overrides)
    figures = execute_run(run, figures=FIGURES)
    return arm, name, {"diverged": figures["diverged"],
                       DIVERGENCE_REASON: figures.get(DIVERGENCE_REASON, ""),
                       **{key: figures[key] for key in FIGURES[1:]}}


def summarize(rows, names):
    """Per condition: runs, divergences, p50 / p90 / max of the RMS of those that did not."""
    table = {}
    for name in names:
        mine = [r for r in rows if r["condition"] == name]
        finite = np.array([r["final_rms_true_error_px"] for r in mine if not r["diverged"]])
        table[name] = {
            "runs": len(mine), "diverged": sum(bool(r["diverged"]) for r in mine),
            "diverged_arms": sorted(r["seed"] for r in mine if r["diverged"]),
            "p50_px": float(np.percentile(finite, 50)) if finite.size else math.nan,
            "p90_px": float(np.percentile(finite, 90)) if finite.size else math.nan,
            "max_px": float(finite.max()) if finite.size else math.nan}
    return table


def plot(rows, names, path, title):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for name in names:
        mine = sorted((r for r in rows if r["condition"] == name),
                      key=lambda r: (bool(r["diverged"]), r["final_rms_true_error_px"]))
        values = [r["final_rms_true_error_px"] for r in mine]
        ranks = np.arange(1, len(values) + 1)
        line, = ax.semilogy(ranks, values, ".-", lw=0.8, label=name)
        gone = [i for i, r in enumerate(mine) if r["diverged"]]
        if gone:
            ax.semilogy(ranks[gone], np.clip(np.array(values)[gone], 1e-3, None), "x",
                        color=line.get_color(), ms=9)
    ax.set(xlabel="run (sorted by error; x: diverged)",
           ylabel="true RMS error, last 5 s [px]", title=title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arms", type=int, default=64)
    parser.add_argument("--first-seed", type=int, default=1)
    parser.add_argument("--noise-seeds", type=int, nargs="*", default=[1, 2])
    parser.add_argument("--duration", type=float, default=30.0)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default="runs/unseen_arms")
    parser.add_argument("--guess-scale", type=float, default=1.0,
                        help="the guessed camera's and lengths' errors times this (2: the "
                             "camera 0.3 m off per axis, focal length and lengths x0.6-1.5)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None)
    args = parser.parse_args(argv)
    if args.arms < 1 or args.workers < 1 or not args.duration > 0.0:
        parser.error("--arms and --workers must be >= 1 and --duration > 0")
    if not 0.0 <= args.guess_scale < 4.0:
        parser.error("--guess-scale must be in [0, 4) (4: lengths guessed x0 at worst), got "
                     f"{args.guess_scale}")

    folder = os.path.join(args.out, "arms")
    started = time.perf_counter()
    arms = [random_arm(seed, folder, guess_scale=args.guess_scale) for seed in
            range(args.first_seed, args.first_seed + args.arms)]
    drawn = time.perf_counter() - started
    names = [name for name, _ in conditions(args.noise_seeds)]
    jobs = [({"path": a.path, "seed": a.seed, "n": a.n, "m": a.m, "prismatic": a.prismatic,
              "condition_number": a.condition}, name, tuple(overrides) + tuple(args.set),
             args.duration)
            for a in arms for name, overrides in conditions(args.noise_seeds)]
    rows = []
    bar = Progress(len(jobs), args.progress)
    with ProcessPoolExecutor(args.workers, initializer=quiet) as pool:
        for done, (arm, name, figures) in enumerate(pool.map(run_one, jobs), 1):
            rows.append({**arm, "condition": name, **figures})
            bar.update(done, f"arm {arm['seed']} {name}")
    bar.close()
    wall = time.perf_counter() - started

    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "results.csv"), "w", newline="", encoding="utf-8") as h:
        writer = csv.DictWriter(h, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    table = summarize(rows, names)
    result = {"environment": environment(), "arms": args.arms, "first_seed": args.first_seed,
              "duration_s": args.duration, "guess_scale": args.guess_scale, "set": args.set,
              "wall_s": wall, "draw_s": drawn,
              "joints": {str(n): sum(a.n == n for a in arms) for n in range(3, 7)},
              "points": {str(m): sum(a.m == m for a in arms) for m in range(1, 4)},
              "conditions": table}
    with open(os.path.join(args.out, "summary.json"), "w", encoding="utf-8") as handle:
        json.dump(result, handle, indent=2)
        handle.write("\n")
    notes = args.set + ([f"guess x{args.guess_scale:g}"] if args.guess_scale != 1.0 else [])
    title = f"{args.arms} unseen arms, defaults" + (f" ({', '.join(notes)})" if notes else "")
    plot(rows, names, os.path.join(args.out, "unseen_arms.png"), title)
    print("| condition | runs | diverged | p50 / p90 / max true RMS [px] |\n|---|---:|---:|---|")
    for name, row in table.items():
        gone = ", ".join(map(str, row["diverged_arms"]))
        arms_gone = f" (arms {gone})" if row["diverged"] else ""
        print(f"| {name} | {row['runs']} | {row['diverged']}{arms_gone} | "
              f"{row['p50_px']:.3f} / {row['p90_px']:.3f} / {row['max_px']:.3f} |")
    print(f"\n{len(jobs)} runs in {wall:.0f} s ({args.workers} workers; drawing the arms "
          f"{drawn:.0f} s); {args.out}/results.csv, summary.json, unseen_arms.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
