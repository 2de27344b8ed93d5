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

"""``vas tune``: the gains for one arm and camera, found by randomized campaigns with Optuna.

Every trial draws gains from the search space (:mod:`.tune_space`) with Optuna's TPE
sampler and runs them on the same R randomized runs (start offsets, initial
estimates off by up to a factor 2, noise seeds: :data:`CONDITIONS`, with the
camera's rate, latency and noise fixed), through the campaign engine's worker pool
or Ray (:mod:`.engine`).  Its objective (:func:`score`, minimised) is lexicographic:

1. the fraction of runs that diverged or failed, x 1e9: any divergence ranks
   below every trial without one;
2. the fraction of runs whose torque reached the file's ``torque_limit`` (the
   command saturated), x 1e6: the torque limit as a constraint.  It is folded into
   the value instead of Optuna's ``constraints_func`` because TPE ranks an
   infeasible trial below every pruned (diverged) one;
3. the 90 % quantile of the true RMS image error over the last 5 s [px] (capped
   at 1000 px) of the runs that did not diverge.

With at most 500 runs per trial the tiers cannot overlap.  A trial whose first
runs (the first batch the engine runs at once) diverge is pruned (Optuna's
``ThresholdPruner`` on that batch's objective): the rest of its runs can only
say how bad it is.  Trial 0 is the configuration's own gains (``enqueue_trial``).

The study lives in ``DIR/study.db`` (SQLite): the same command resumes an
interrupted tuning, and the same command with more ``--trials`` continues it.
The best trial and the configuration's own gains then run on ``--held-out``
other randomized runs (other seeds), and DIR gets ``tuned.yaml`` (the input file
with the chosen gains written in), ``report.md`` and the plots
(:mod:`.tune_report`).  Optuna is an optional extra, imported only here and only
when tuning.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import sys
import time
from dataclasses import dataclass
from functools import partial

import numpy as np
import yaml

from ..config.files import apply_overrides, read_param_file
from ..config.scenario import load_scenario
from ..schema import CONTROLLER_SECTION, ConfigError, SIM_SECTION
from .campaign import default_workers, exclusive
from .engine import CampaignError, execute_run, FIGURES, ProcessPool, RayCluster, RunResult
from .spec import load_spec, resolve_overrides, Run
from .tune_space import DEFAULT_SPACE, load_space

OPTUNA_MISSING = ('vas tune needs Optuna, an optional extra: pip install ".[tune]" '
                  "(or pip install optuna)")
STUDY_NAME = "vas-tune"
STUDY_DB = "study.db"
META_NAME = "tune.json"
TRAINING_SPEC = "training_runs.yaml"
HELD_OUT_SPEC = "held_out_runs.yaml"
HELD_OUT_CACHE = "held_out.json"
LOG_NAME = "workers.log"
TUNE_FIGURES = FIGURES + ("saturated",)
#: what varies between the runs of a trial (a campaign spec's random factors)
CONDITIONS = {
    "start_offset_px": {"uniform": [0.0, 50.0]},
    "start_offset_angle_deg": {"uniform": [0.0, 360.0]},
    "estimate_scale.a_z_perp": {"log_uniform": [0.5, 2.0]},
    "estimate_scale.a_z": {"log_uniform": [0.5, 2.0]},
    "seed": {"integer": [0, 2**31 - 1]},
}
DIVERGED_WEIGHT = 1e9
SATURATED_WEIGHT = 1e6
ERROR_CAP_PX = 1e3
MAX_RUNS_PER_TRIAL = 500
QUANTILE = 0.9
#: a batch objective above this had a divergence (tiers 2 and 3 stay below it)
PRUNE_ABOVE = SATURATED_WEIGHT + ERROR_CAP_PX
#: random trials before TPE models the objective (Optuna's default is 10)
STARTUP_TRIALS = 6


@dataclass(frozen=True)
class TuneSettings:
    """What ``vas tune`` was asked for (checked by :meth:`check` before anything runs)."""

    config: str
    out: str
    trials: int = 40
    runs_per_trial: int = 8
    duration: float = 10.0
    camera_rate: float | None = None
    camera_latency: float | None = None
    pixel_noise: float | None = None
    workers: int | None = None
    ray: str | None = None
    progress: bool | None = None
    space: str | None = None
    held_out: int = 20
    seed: int = 0

    def check(self):
        def number(name, value, low, strict=False):
            if value is None:
                return
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value) or value < low or (strict and value == low):
                rule = f"> {low:g}" if strict else f">= {low:g}"
                raise CampaignError(f"--{name}: must be a number {rule}, got {value!r}")

        def integer(name, value, low, high=None):
            if isinstance(value, bool) or not isinstance(value, int) or value < low \
                    or (high is not None and value > high):
                rule = f"in [{low}, {high}]" if high is not None else f">= {low}"
                raise CampaignError(f"--{name}: must be an integer {rule}, got {value!r}")

        integer("trials", self.trials, 1)
        integer("runs-per-trial", self.runs_per_trial, 1, MAX_RUNS_PER_TRIAL)
        integer("held-out", self.held_out, 0)
        integer("seed", self.seed, 0, 2**30)
        if self.workers is not None:
            integer("workers", self.workers, 1)
        number("duration", self.duration, 0.0, strict=True)
        number("camera-rate", self.camera_rate, 0.0)
        number("camera-latency", self.camera_latency, 0.0)
        number("pixel-noise", self.pixel_noise, 0.0)

    def camera_values(self):
        """{section: {param: value}} of the camera asked for.

        The simulated camera gets the rate, latency and noise; the controller is told
        the rate and latency, as a user writes them into ``controller_node`` (its
        derived gains and frame prediction follow from them, docs/gain_design.md).
        """
        sim, ctrl = {}, {}
        if self.camera_rate is not None:
            sim["camera_rate"] = ctrl["camera_rate"] = float(self.camera_rate)
        if self.camera_latency is not None:
            sim["camera_latency"] = ctrl["camera_latency"] = float(self.camera_latency)
        if self.pixel_noise is not None:
            sim["pixel_noise_std"] = float(self.pixel_noise)
        return {SIM_SECTION: sim, CONTROLLER_SECTION: ctrl}

    def camera_overrides(self):
        """:meth:`camera_values` as ``--set`` overrides."""
        return [f"{section}.{name}={value!r}"
                for section, values in self.camera_values().items()
                for name, value in values.items()]

    def fixed_factors(self):
        """The camera conditions every run shares (campaign factors)."""
        return {f"set.{section}.{name}": value
                for section, values in self.camera_values().items()
                for name, value in values.items()}

    def runs_spec(self, runs, draw_seed):
        """A campaign spec (as a dict) of ``runs`` randomized runs of the configuration."""
        body = {"base": os.path.abspath(self.config), "duration": float(self.duration),
                "description": "vas tune: the randomized runs of every trial"}
        if self.fixed_factors():
            body["fixed"] = self.fixed_factors()
        body["random"] = {"runs": runs, "seed": draw_seed, "factors": CONDITIONS}
        return body


def score(results):
    """A trial's figures and objective from its :class:`~.engine.RunResult` list.

    Runs the conditions cannot realise (``not started``) are the same for every
    gain set and are left out; a run that failed counts as diverged.
    """
    counted = [r for r in results if r.attempts > 0]
    bad = [r for r in counted if r.status != "finished" or r.figures["diverged"]]
    bad_ids = {r.run.index for r in bad}
    calm = [r for r in counted if r.run.index not in bad_ids]
    errors = [r.figures["final_rms_true_error_px"] for r in calm
              if math.isfinite(r.figures["final_rms_true_error_px"])]
    saturated = [r for r in calm if r.figures.get("saturated", 0) > 0]
    torques = [r.figures["max_abs_torque"] for r in calm
               if math.isfinite(r.figures["max_abs_torque"])]
    n = len(counted)
    p90 = float(np.quantile(errors, QUANTILE)) if errors else math.nan
    objective = math.inf if n == 0 else (
        DIVERGED_WEIGHT * len(bad) / n + SATURATED_WEIGHT * len(saturated) / n
        + (min(p90, ERROR_CAP_PX) if errors else ERROR_CAP_PX))
    worst = sorted(counted, key=lambda r: (r.run.index not in bad_ids, -_error(r)))
    return {
        "objective": objective, "runs": n, "diverged": len(bad), "saturated_runs": len(saturated),
        "p90_true_rms_px": p90,
        "p50_true_rms_px": float(np.quantile(errors, 0.5)) if errors else math.nan,
        "max_true_rms_px": float(max(errors)) if errors else math.nan,
        "peak_abs_torque": float(max(torques)) if torques else math.nan,
        "not_started": len(results) - n,
        "failures": sorted({r.reason for r in counted if r.status != "finished"})[:3],
        "worst_command": worst[0].run.command if worst else "",
    }


def _error(result):
    value = result.figures.get("final_rms_true_error_px", math.nan) if result.figures else math.nan
    return value if math.isfinite(value) else math.inf


def trial_runs(spec, scenario, gain_factors):
    """The spec's runs with ``gain_factors`` (campaign factors) applied to every one."""
    runs = []
    for index, (varying, factors) in enumerate(spec.factor_sets()):
        overrides, problem = resolve_overrides({**factors, **gain_factors}, scenario)
        runs.append(Run(index, varying, spec.base, spec.duration, "observer", overrides,
                        problem))
    return runs


def gain_values(gain_factors, scenario):
    """{controller parameter: value} that ``gain_factors`` give (as the runs got them).

    Read back from the runs' ``--set`` overrides by the loader's own reading of them
    (``1e-06`` is a number there, as in ROS 2, though YAML 1.1 makes it a string).
    """
    overrides, _ = resolve_overrides(gain_factors, scenario)
    sections = apply_overrides({SIM_SECTION: {}, CONTROLLER_SECTION: {}}, overrides)
    return sections[CONTROLLER_SECTION]


class Executor:
    """The campaign engine for batches of runs: a worker pool per batch, or one Ray client."""

    def __init__(self, workers, ray, log_path, on_run):
        self.run_fn = partial(execute_run, figures=TUNE_FIGURES)
        self.workers = workers or default_workers()
        self.log_path = log_path
        self.on_run = on_run
        self.ray = RayCluster(ray, workers, self.run_fn) if ray else None
        self.slots = self.ray.size if self.ray else self.workers

    def run(self, runs):
        """Execute ``runs``; their results in run order."""
        results = {}

        def record(result):
            results[result.run.index] = result
            self.on_run()

        for run in runs:
            if run.problem:
                record(RunResult(run, "failed", {}, f"not started: {run.problem}", 0, math.nan))
        runnable = [r for r in runs if not r.problem]
        if runnable:
            # a pool per batch: ProcessPool.run starts its own workers (forked from the
            # fork server, milliseconds each) and close() stops them
            engine = self.ray or ProcessPool(self.workers, self.run_fn, log_path=self.log_path)
            try:
                engine.run(runnable, record)
            finally:
                if engine is not self.ray:
                    engine.close()
        return [results[r.index] for r in runs]

    def close(self):
        if self.ray is not None:
            self.ray.close()


def _import_optuna():
    try:
        import optuna
    except ImportError:
        raise CampaignError(OPTUNA_MISSING) from None
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    return optuna


def _sha256_file(path):
    with open(path, "rb") as handle:
        return hashlib.sha256(handle.read()).hexdigest()


def _write_spec(path, body):
    with open(path, "w", encoding="utf-8") as handle:
        handle.write("# written by vas tune; run it with vas campaign --spec THIS --out DIR\n")
        yaml.safe_dump(body, handle, sort_keys=False, default_flow_style=None)
    return load_spec(path)


@dataclass(frozen=True)
class Tuning:
    """Everything a tuning works with, checked and loaded before the first run."""

    settings: TuneSettings
    scenario: object
    space: object
    fingerprint: str


def prepare(settings):
    """Check the settings, load the configuration and the space; no run, no file written."""
    settings.check()
    _import_optuna()
    if not os.path.isfile(settings.config):
        raise CampaignError(f"--config {settings.config}: no such file")
    scenario = load_scenario(settings.config, settings.camera_overrides())
    file_params = read_param_file(settings.config)[CONTROLLER_SECTION]
    space_path = settings.space or DEFAULT_SPACE
    space = load_space(space_path, scenario, file_params, drop_shadowed=settings.space is None)
    body = {"config_sha256": _sha256_file(settings.config),
            "runs": settings.runs_spec(settings.runs_per_trial, 2 * settings.seed),
            "space": space.fingerprint()}
    body["runs"]["base"] = os.path.basename(settings.config)
    fingerprint = hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()
    return Tuning(settings, scenario, space, fingerprint)


def _check_out_dir(out_dir, tuning):
    meta_path = os.path.join(out_dir, META_NAME)
    if os.path.exists(meta_path):
        with open(meta_path, encoding="utf-8") as handle:
            meta = json.load(handle)
        if meta.get("fingerprint") != tuning.fingerprint:
            raise CampaignError(
                f"{out_dir} holds a tuning of other settings ({meta.get('config')}, "
                f"{meta.get('runs_per_trial')} runs of {meta.get('duration_s')} s per trial, "
                f"space {meta.get('space')}): a tuning resumes only with the same --config, "
                "--space, --runs-per-trial, --duration, camera options and --seed; use another "
                f"--out, or delete {out_dir} to start again")
        return
    if os.path.exists(os.path.join(out_dir, STUDY_DB)):
        raise CampaignError(f"{out_dir} has a {STUDY_DB} without {META_NAME}: not a vas tune "
                            "folder; use another --out")
    s = tuning.settings
    with open(meta_path, "w", encoding="utf-8") as handle:
        json.dump({"fingerprint": tuning.fingerprint, "config": os.path.abspath(s.config),
                   "space": tuning.space.path, "runs_per_trial": s.runs_per_trial,
                   "duration_s": s.duration, "seed": s.seed, "fixed": s.fixed_factors()},
                  handle, indent=2)
        handle.write("\n")


def run_tuning(settings, out=sys.stdout):
    """Run (or resume) a tuning and write its outputs; returns the report's dict.

    The pool's workers start from a fresh interpreter: a script that calls this
    needs the ``if __name__ == "__main__":`` guard.
    """
    tuning = prepare(settings)
    out_dir = settings.out
    os.makedirs(out_dir, exist_ok=True)
    with exclusive(out_dir, "vas tune"):
        _check_out_dir(out_dir, tuning)
        return _tune(tuning, out)


def _tune(tuning, out):
    from ..runner import Progress
    from .tune_report import write_outputs

    optuna = _import_optuna()
    s = tuning.settings
    out_dir = s.out
    train = _write_spec(os.path.join(out_dir, TRAINING_SPEC),
                        s.runs_spec(s.runs_per_trial, 2 * s.seed))
    held = (_write_spec(os.path.join(out_dir, HELD_OUT_SPEC),
                        s.runs_spec(s.held_out, 2 * s.seed + 1)) if s.held_out else None)
    storage = f"sqlite:///{os.path.abspath(os.path.join(out_dir, STUDY_DB))}"
    probe = optuna.create_study(storage=storage, study_name=STUDY_NAME, direction="minimize",
                                load_if_exists=True)
    existing = len(probe.trials)
    # a fresh seed per call: a resumed study must not draw its first trials again
    sampler_seed = int(np.random.SeedSequence([s.seed, existing]).generate_state(1)[0])
    study = optuna.load_study(
        study_name=STUDY_NAME, storage=storage,
        sampler=optuna.samplers.TPESampler(seed=sampler_seed, n_startup_trials=STARTUP_TRIALS),
        pruner=optuna.pruners.ThresholdPruner(upper=PRUNE_ABOVE))
    base_values = tuning.scenario.controller.params
    notes = [f"left out {key}: {why}" for key, why in tuning.space.dropped]
    if existing == 0:
        params, clipped = tuning.space.defaults(base_values)
        study.enqueue_trial(params, user_attrs={"origin": "the configuration's gains"})
        notes += clipped
    _recover(study, optuna)
    for note in notes:
        print(f"vas tune: {note}", file=sys.stderr)

    finished = _finished(study, optuna)
    todo = max(0, s.trials - len(finished))
    bar = Progress(todo * s.runs_per_trial + 2 * s.held_out, s.progress)
    counter = {"runs": 0}

    def on_run():
        counter["runs"] += 1
        if not bar.enabled:
            return
        best = _best(study, optuna)
        bar.update(counter["runs"], f"trial {len(_finished(study, optuna)) + 1}/{s.trials}"
                   + (f", best {best.value:.4g}" if best is not None else ""))

    started = time.perf_counter()
    executor = Executor(s.workers, s.ray, os.path.join(out_dir, LOG_NAME), on_run)
    interrupted = False
    try:
        for _ in range(todo):
            line = _one_trial(study, optuna, tuning, train, executor)
            if not bar.enabled:
                print(line, file=out, flush=True)
        best = _best(study, optuna)
        held_out = _held_out(tuning, held, executor, best, out_dir) if held else None
    except KeyboardInterrupt:
        interrupted = True
        best, held_out = _best(study, optuna), None
    finally:
        executor.close()
        bar.close()
    wall = time.perf_counter() - started
    values = changed_values(tuning, best) if best is not None else {}
    return write_outputs(tuning, study, optuna, best, values, held_out, notes, wall,
                         interrupted, train, held)


def _finished(study, optuna):
    states = (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.PRUNED)
    return study.get_trials(deepcopy=False, states=states)


def _best(study, optuna):
    """The completed trial of the lowest objective (pruned trials diverged), or None."""
    complete = study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,))
    return min(complete, key=lambda t: (t.value, t.number)) if complete else None


def _recover(study, optuna):
    """Trials left running by a hard stop: failed, and their gains queued to run again."""
    for trial in study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.RUNNING,)):
        # stopped before its gains were drawn, it has only the queued ones (if any)
        params = trial.params or trial.system_attrs.get("fixed_params", {})
        study.tell(trial.number, state=optuna.trial.TrialState.FAIL)
        study.enqueue_trial(params, user_attrs=dict(trial.user_attrs))


def _one_trial(study, optuna, tuning, train, executor):
    """Ask, run (pruning after the first batch), tell; returns a one-line account."""
    trial = study.ask()
    try:
        drawn = tuning.space.suggest(trial, tuning.scenario.controller.params)
        runs = trial_runs(train, tuning.scenario, drawn)
        first = runs[:executor.slots]
        results = executor.run(first)
        figures = score(results)
        trial.report(figures["objective"], step=len(first))
        pruned = len(first) < len(runs) and trial.should_prune()
        if not pruned:
            results += executor.run(runs[len(first):])
            figures = score(results)
        for key, value in figures.items():
            trial.set_user_attr(key, value)
    except KeyboardInterrupt:
        study.tell(trial, state=optuna.trial.TrialState.FAIL)
        study.enqueue_trial(trial.params, user_attrs={"origin": "interrupted, run again"})
        raise
    if pruned:
        study.tell(trial, state=optuna.trial.TrialState.PRUNED)
        return (f"trial {trial.number}: pruned, {figures['diverged']} of its first "
                f"{figures['runs']} runs diverged")
    study.tell(trial, figures["objective"])
    return (f"trial {trial.number}: objective {figures['objective']:.6g} "
            f"({figures['diverged']} of {figures['runs']} diverged, "
            f"{figures['saturated_runs']} at the torque limit, "
            f"p90 true RMS {figures['p90_true_rms_px']:.4g} px)")


def changed_values(tuning, trial):
    """{controller parameter: value} of ``trial``'s gains that differ from the file's."""
    base = tuning.scenario.controller.params
    values = gain_values(trial_factors(tuning.space, trial.params), tuning.scenario)
    return {name: value for name, value in values.items()
            if not np.array_equal(np.asarray(value, dtype=object),
                                  np.asarray(base[name], dtype=object))}


def trial_factors(space, params):
    """{campaign factor: value} of a trial's Optuna params."""
    return {d.factor: params[d.key] for d in space.dimensions if d.key in params}


def _held_out(tuning, held, executor, best, out_dir):
    """The configuration's gains and the best trial's on the held-out runs (cached)."""
    cache_path = os.path.join(out_dir, HELD_OUT_CACHE)
    cache = {}
    if os.path.exists(cache_path):
        with open(cache_path, encoding="utf-8") as handle:
            cache = json.load(handle)
    fingerprint = held.fingerprint()
    outcome = {}
    candidates = {"file": {}}
    if best is not None and changed_values(tuning, best):
        candidates["tuned"] = trial_factors(tuning.space, best.params)
    for name, factors in candidates.items():
        key = hashlib.sha256(json.dumps([fingerprint, sorted(factors.items())],
                                        default=str).encode()).hexdigest()
        if key not in cache:
            cache[key] = score(executor.run(trial_runs(held, tuning.scenario, factors)))
            with open(cache_path, "w", encoding="utf-8") as handle:
                json.dump(cache, handle, indent=1)
        outcome[name] = cache[key]
    # the best trial's gains are the file's: the same runs, run once
    outcome.setdefault("tuned", outcome["file"])
    return outcome


def cmd_tune(args):
    """``vas tune``: tune, print where the outputs are and the held-out verdict."""
    settings = TuneSettings(
        config=args.config, out=args.out, trials=args.trials, runs_per_trial=args.runs_per_trial,
        duration=args.duration, camera_rate=args.camera_rate, camera_latency=args.camera_latency,
        pixel_noise=args.pixel_noise, workers=args.workers, ray=args.ray,
        progress=args.progress, space=args.space, held_out=args.held_out, seed=args.seed)
    try:
        report = run_tuning(settings)
    except CampaignError as exc:
        print(f"vas tune: {exc}", file=sys.stderr)
        return 2
    except ConfigError as exc:
        print(f"vas tune: invalid input: {exc}", file=sys.stderr)
        return 2
    print(report["verdict"])
    print(f"outputs in {settings.out}: {', '.join(report['outputs'])}")
    if report["interrupted"]:
        print("interrupted: rerun the same command to resume", file=sys.stderr)
        return 130
    return 0 if report["best"] is not None else 1


def add_parser(subparsers):
    """Register ``vas tune`` (called by :func:`visual_adaptive_servo.cli.build_parser`)."""
    cmd = subparsers.add_parser("tune", help="gains for this arm and camera, found by "
                                "randomized campaigns with Optuna (pip install '.[tune]')")
    cmd.add_argument("--config", required=True, help="the parameter file to tune, e.g. "
                     "config/paper_3dof.yaml")
    cmd.add_argument("--out", required=True, help="output folder; rerun the same command to "
                     "resume, with more --trials to continue")
    cmd.add_argument("--trials", type=int, default=40, help="trials in the study (default 40)")
    cmd.add_argument("--runs-per-trial", type=int, default=8, metavar="R",
                     help="randomized runs per trial (default 8)")
    cmd.add_argument("--duration", type=float, default=10.0, metavar="S",
                     help="simulated seconds per run (default 10)")
    cmd.add_argument("--camera-rate", type=float, metavar="HZ",
                     help="camera frames per second (default: the file's)")
    cmd.add_argument("--camera-latency", type=float, metavar="S",
                     help="camera latency [s] (default: the file's)")
    cmd.add_argument("--pixel-noise", type=float, metavar="STD",
                     help="pixel noise std [px] (default: the file's)")
    engine = cmd.add_mutually_exclusive_group()
    engine.add_argument("--workers", type=int, help="worker processes (default: every core)")
    engine.add_argument("--ray", metavar="auto|ADDRESS", help="run on Ray (pip install '.[ray]')")
    cmd.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                     help="progress bar (default: on a terminal)")
    cmd.add_argument("--space", metavar="FILE", help="search space (default: "
                     "config/tune/default_space.yaml)")
    cmd.add_argument("--held-out", type=int, default=20, metavar="N",
                     help="held-out runs (other seeds) for the best and the file's gains "
                     "(default 20; 0: none)")
    cmd.add_argument("--seed", type=int, default=0, help="seed of the run draws and the sampler")
    cmd.set_defaults(func=cmd_tune)
    return cmd
