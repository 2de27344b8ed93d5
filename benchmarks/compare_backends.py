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

"""Full `vas run`s of the shipped files with each backend, and whether their figures agree.

For every file (default: the shipped scenarios config/paper_3dof.yaml,
paper_3dof_noisy.yaml, paper_3dof_urdf.yaml, iiwa_3points.yaml,
panda_2points.yaml), ``vas run --no-bag`` runs in a fresh process with
``--set controller_node.backend=compiled`` and with ``=numpy``, for the file's
own duration (or ``--duration``).  Every number of the two summary.json files
(wall times and the real-time factor excepted) must agree to ``--rtol``
(default 1e-9, issue 18); the largest relative difference per file is printed
with the wall time of each run.  test_compiled_law.py checks the same on short
runs; this is the full-length check.

Usage::

    python benchmarks/compare_backends.py [--config FILE ...] [--duration S] [--rtol R]

Exit status 1 when a figure differs by more than ``--rtol``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, os.pardir)
SHIPPED = ("paper_3dof.yaml", "paper_3dof_noisy.yaml", "paper_3dof_urdf.yaml",
           "iiwa_3points.yaml", "panda_2points.yaml")
SKIPPED = ("wall", "realtime_factor")


def run(config, backend, folder, duration):
    command = [sys.executable, "-m", "visual_adaptive_servo.cli", "run", "--config", config,
               "--out", folder, "--no-bag", "--no-progress",
               "--set", f"controller_node.backend={backend}"]
    if duration:
        command += ["--duration", str(duration)]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [os.path.abspath(ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep)
                                   if p]))
    t0 = time.perf_counter()
    subprocess.run(command, check=True, env=env, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    with open(os.path.join(folder, "summary.json"), encoding="utf-8") as handle:
        return json.load(handle), wall


def numbers(summary, prefix=""):
    """Every number of a summary (nested dicts and lists flattened), by dotted key."""
    out = {}
    if isinstance(summary, dict):
        for key, value in summary.items():
            out.update(numbers(value, f"{prefix}{key}."))
    elif isinstance(summary, list):
        for k, value in enumerate(summary):
            out.update(numbers(value, f"{prefix}{k}."))
    elif isinstance(summary, (int, float)) and not isinstance(summary, bool):
        out[prefix[:-1]] = float(summary)
    return out


def difference(a, b):
    if a == b or (math.isnan(a) and math.isnan(b)):
        return 0.0
    return abs(a - b) / max(abs(a), abs(b))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", action="append", help="scenario (repeatable; default the "
                        "shipped ones)")
    parser.add_argument("--duration", type=float, help="simulated seconds (default the file's)")
    parser.add_argument("--rtol", type=float, default=1e-9)
    args = parser.parse_args(argv)
    configs = args.config or [os.path.join(ROOT, "config", name) for name in SHIPPED]
    failed = False
    print(f"| file | figures | largest relative difference (figure) | wall compiled / numpy "
          f"[s] | within {args.rtol:g} |")
    print("|---|---:|---|---:|---|")
    for config in configs:
        with tempfile.TemporaryDirectory() as folder:
            compiled, wall_c = run(config, "compiled", os.path.join(folder, "c"), args.duration)
            reference, wall_n = run(config, "numpy", os.path.join(folder, "n"), args.duration)
        a, b = numbers(compiled), numbers(reference)
        keys = [k for k in b if not any(k.startswith(s) for s in SKIPPED)]
        missing = [k for k in keys if k not in a]
        worst = max(((difference(a[k], b[k]), k) for k in keys if k in a), default=(0.0, "-"))
        ok = not missing and worst[0] <= args.rtol
        failed |= not ok
        print(f"| {os.path.basename(config)} | {len(keys)} | {worst[0]:.2e} ({worst[1]}) | "
              f"{wall_c:.1f} / {wall_n:.1f} | {'yes' if ok else 'NO'}"
              + (f", missing {missing}" if missing else "") + " |")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
