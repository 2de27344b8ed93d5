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

"""``vas campaign``: many randomized closed-loop runs, on every core or on a Ray cluster.

``vas campaign --spec FILE --out DIR [--workers N] [--ray auto|ADDRESS] [--runs N]``
resolves every run of the spec (:mod:`.spec`), executes the ones DIR
does not hold yet (:mod:`.engine`) and reports them all
(:mod:`.report`).  In DIR:

* ``campaign.json``: the spec and its fingerprint (a DIR made by another spec is
  refused), ``campaign.lock`` (one campaign at a time in a DIR);
* ``runs.csv``: one row per run, written and flushed as each run ends, so an
  interrupted campaign keeps its rows and the same command resumes it;
* ``workers.log``: what the worker processes printed (a crash's traceback);
* ``summary.md``, ``summary.json``, ``error_histogram.png`` and one
  ``error_vs_<factor>.png`` per grid or random factor.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import json
import math
import os
import sys
import time

from .engine import (CampaignError, execute_run, FIGURES, ProcessPool, RayCluster,
                     RunResult)
from .spec import load_spec, yaml_text

CSV_NAME = "runs.csv"
META_NAME = "campaign.json"
LOG_NAME = "workers.log"
LOCK_NAME = "campaign.lock"


def columns_of(spec):
    """The header of runs.csv."""
    return (["id"] + spec.factor_columns + list(FIGURES)
            + ["wall_time_s", "status", "reason", "attempts", "command"])


def _cell(value):
    if value is None:
        return ""
    if isinstance(value, str):
        return value
    return yaml_text(value)


def _figure_cell(key, result):
    if key not in result.figures:
        return ""
    value = result.figures[key]
    if key == "diverged":
        return "true" if value else "false"
    return repr(float(value))


def row_cells(result, spec):
    """The cells of one runs.csv row (floats exact: ``repr`` reads back the same)."""
    run = result.run
    return ([str(run.index)] + [_cell(run.factors.get(c)) for c in spec.factor_columns]
            + [_figure_cell(key, result) for key in FIGURES]
            + [repr(float(result.wall_time_s)), result.status, result.reason,
               str(result.attempts), run.command])


def _parse_factor(text):
    if text == "":
        return None
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _parse_figure(text):
    return float(text) if text else math.nan


def read_rows(path, spec):
    """The rows of runs.csv as dicts (id, factors, figures, status, ...)."""
    rows = []
    with open(path, encoding="utf-8", newline="") as handle:
        for cells in csv.DictReader(handle):
            rows.append({
                "id": int(cells["id"]),
                "factors": {c: _parse_factor(cells[c]) for c in spec.factor_columns},
                "diverged": cells["diverged"] == "true",
                **{k: _parse_figure(cells[k]) for k in FIGURES if k != "diverged"},
                "wall_time_s": _parse_figure(cells["wall_time_s"]),
                "status": cells["status"], "reason": cells["reason"],
                "attempts": int(cells["attempts"]), "command": cells["command"]})
    return rows


def _finished_ids(path, columns):
    """Ids already in runs.csv; drops a last line cut short by a hard stop."""
    with open(path, "rb+") as handle:
        data = handle.read()
        if data and not data.endswith(b"\n"):
            handle.truncate(data.rfind(b"\n") + 1)
    with open(path, encoding="utf-8", newline="") as handle:
        reader = csv.reader(handle)
        header = next(reader, None)
        if header != columns:
            raise CampaignError(f"{path}: its columns are not this spec's; use another --out")
        return {int(cells[0]) for cells in reader if len(cells) == len(columns)}


@contextlib.contextmanager
def exclusive(out_dir, command="vas campaign"):
    """Hold DIR/campaign.lock: two campaigns appending to one runs.csv would mix rows.

    ``command`` names the kind of job in the refusal (``vas tune`` holds the same lock).
    """
    import fcntl

    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, LOCK_NAME), "w", encoding="utf-8") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise CampaignError(f"{out_dir} is in use by another {command}; wait for it "
                                "or use another --out") from None
        yield


def prepare_out_dir(out_dir, spec, columns):
    """Create DIR or check that it holds this spec's campaign; return the ids done."""
    os.makedirs(out_dir, exist_ok=True)
    meta_path = os.path.join(out_dir, META_NAME)
    csv_path = os.path.join(out_dir, CSV_NAME)
    fingerprint = spec.fingerprint()
    if os.path.exists(meta_path):
        with open(meta_path, encoding="utf-8") as handle:
            meta = json.load(handle)
        if meta.get("fingerprint") != fingerprint:
            raise CampaignError(
                f"{out_dir} holds the campaign of another spec ({meta.get('spec_path')}, "
                f"fingerprint {str(meta.get('fingerprint'))[:12]}; this spec and its base "
                f"configurations give {fingerprint[:12]}): use another --out, or delete "
                f"{out_dir} to start again")
    elif os.path.exists(csv_path):
        raise CampaignError(f"{csv_path} exists without {META_NAME}: not a campaign folder; "
                            "use another --out")
    else:
        with open(meta_path, "w", encoding="utf-8") as handle:
            json.dump({"spec_path": spec.path, "fingerprint": fingerprint, "spec": spec.raw},
                      handle, indent=2, default=str)
            handle.write("\n")
    if not os.path.exists(csv_path):
        with open(csv_path, "w", encoding="utf-8", newline="") as handle:
            csv.writer(handle).writerow(columns)
        return set()
    return _finished_ids(csv_path, columns)


def default_workers():
    """The cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def _eta(seconds):
    if not math.isfinite(seconds):
        return "--"
    minutes, secs = divmod(int(round(seconds)), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}h{minutes:02d}m" if hours else f"{minutes}m{secs:02d}s"


def run_campaign(spec_path, out_dir, workers=None, ray=None, limit=None, run_fn=execute_run,
                 progress=None, on_start=None, on_row=None):
    """Run (or resume) a campaign and write its report; return the summary dict.

    The pool's workers start from a fresh interpreter (a fork server): a script that
    calls this needs the usual ``if __name__ == "__main__":`` guard.

    Parameters
    ----------
    spec_path, out_dir : str
    workers : int, optional
        Worker processes (default: every core); with ``ray``, runs in flight.
    ray : str, optional
        ``auto`` (start Ray here) or a cluster address; default: the process pool.
    limit : int, optional
        Execute only the first ``limit`` runs of the spec (the rest on a later call).
    run_fn : callable
        ``run_fn(run) -> figures``, executed in the workers (tests inject failures).
    progress : bool, optional
        Progress bar with ETA on stderr; default: when stderr is a terminal.
    on_start, on_row : callable, optional
        ``on_start(run, pid)`` when a pool worker starts a run; ``on_row(result)``
        after each row is written.  Both run in this process.
    """
    spec = load_spec(spec_path)
    runs = spec.runs()
    with exclusive(out_dir):
        return _run_and_report(spec, runs, out_dir, workers, ray, limit, run_fn, progress,
                               on_start, on_row)


def _run_and_report(spec, runs, out_dir, workers, ray, limit, run_fn, progress, on_start,
                    on_row):
    from ..recording.recorder import write_json
    from .report import markdown, plot_campaign, summarize

    columns = columns_of(spec)
    done = prepare_out_dir(out_dir, spec, columns)
    selected = runs if limit is None else runs[:max(0, limit)]
    todo = [run for run in selected if run.index not in done]
    engine = (f"ray {ray}" if ray else f"{workers or default_workers()} processes")
    executed, interrupted, wall = _execute(todo, spec, out_dir, workers, ray, run_fn, progress,
                                           on_start, on_row)
    rows = read_rows(os.path.join(out_dir, CSV_NAME), spec)
    summary = summarize(rows, spec.level_factors, len(runs), interrupted)
    summary.update(spec=spec.path, fingerprint=spec.fingerprint(), duration_s=spec.duration,
                   executed_now=executed, resumed_rows=len(done), engine=engine,
                   wall_time_s=wall)
    plots = plot_campaign(rows, spec.sampled_factors, out_dir)
    with open(os.path.join(out_dir, "summary.md"), "w", encoding="utf-8") as handle:
        handle.write(markdown(summary, spec.name, plots))
    write_json(os.path.join(out_dir, "summary.json"), summary)
    return summary


def _execute(todo, spec, out_dir, workers, ray, run_fn, progress, on_start, on_row):
    """Run ``todo``, appending a row as each ends; (rows written, interrupted, wall s)."""
    from ..runner import Progress

    bar = Progress(len(todo), progress)
    counts = {"done": 0, "failed": 0}
    started = time.perf_counter()
    interrupted = False
    engine = None
    with open(os.path.join(out_dir, CSV_NAME), "a", encoding="utf-8", newline="") as handle:
        writer = csv.writer(handle)

        def record(result):
            writer.writerow(row_cells(result, spec))
            handle.flush()
            counts["done"] += 1
            counts["failed"] += result.status == "failed"
            if bar.enabled:
                elapsed = time.perf_counter() - started
                eta = elapsed / counts["done"] * (len(todo) - counts["done"])
                bar.update(counts["done"], f"{counts['done']}/{len(todo)} runs, "
                           f"{counts['failed']} failed, ETA {_eta(eta)}")
            if on_row is not None:
                on_row(result)

        try:
            for run in todo:
                if run.problem:
                    record(RunResult(run, "failed", {}, f"not started: {run.problem}", 0,
                                     math.nan))
            runnable = [run for run in todo if not run.problem]
            if runnable:
                engine = (RayCluster(ray, workers, run_fn) if ray else
                          ProcessPool(workers or default_workers(), run_fn, on_start,
                                      os.path.join(out_dir, LOG_NAME)))
                engine.run(runnable, record)
        except KeyboardInterrupt:
            interrupted = True
        finally:
            if engine is not None:
                engine.close()
            bar.close()
    return counts["done"], interrupted, time.perf_counter() - started


def cmd_campaign(args):
    """``vas campaign``: run or resume, print where the outputs are."""
    try:
        summary = run_campaign(args.spec, args.out, args.workers, args.ray, args.runs,
                               progress=args.progress)
    except CampaignError as exc:
        print(f"vas campaign: {exc}", file=sys.stderr)
        return 2
    div = summary["divergence"]
    if summary["resumed_rows"]:
        print(f"resumed: {summary['resumed_rows']} rows were already in {args.out}",
              file=sys.stderr)
    print(f"{summary['rows']} of {summary['runs_in_spec']} runs recorded "
          f"({summary['executed_now']} now, {summary['wall_time_s']:.1f} s): "
          f"{summary['failed']} failed, {div['diverged']} of {div['finished']} diverged")
    print(f"outputs in {args.out}: {CSV_NAME}, summary.md, summary.json, plots")
    if summary["interrupted"]:
        return 130
    return 1 if summary["failed"] else 0


def add_parser(subparsers):
    """Register ``vas campaign`` (called by :func:`visual_adaptive_servo.cli.build_parser`)."""
    cmd = subparsers.add_parser("campaign", help="many randomized runs from a spec, on every "
                                "core or on a Ray cluster; resumable")
    cmd.add_argument("--spec", required=True, help="campaign spec (YAML), e.g. "
                     "config/campaigns/start_and_estimates.yaml")
    cmd.add_argument("--out", required=True, help="output folder; rerun the same command to "
                     "resume an interrupted campaign")
    cmd.add_argument("--workers", type=int, help="worker processes (default: every core); "
                     "with --ray, runs in flight (default: the cluster's CPUs)")
    cmd.add_argument("--ray", metavar="auto|ADDRESS", help="run as Ray tasks: auto starts "
                     "Ray here, ADDRESS joins a cluster (pip install '.[ray]')")
    cmd.add_argument("--runs", type=int, metavar="N", help="execute only the first N runs "
                     "of the spec (the rest on a later call)")
    cmd.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                     help="progress bar with ETA (default: on a terminal)")
    cmd.set_defaults(func=cmd_campaign)
    return cmd
