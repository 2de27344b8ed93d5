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

"""What a tuning says: ``tuned.yaml``, ``report.md`` and the plots of ``vas tune``.

``tuned.yaml`` is the input file, text and comments kept, with the chosen gains
written over their values (found by their places in the YAML, so a list spread
over several lines is replaced whole) or added at the end of the
``controller_node`` parameters, each marked ``# vas tune``, under a header that
gives the figures that justify them.
"""

from __future__ import annotations

import math
import os
import re

import numpy as np
import yaml

from ..config.scenario import load_scenario
from ..models.resources import resolve_path
from ..schema import CONTROLLER_SECTION, SIM_SECTION, ConfigError
from .spec import yaml_text

TUNED_NAME = "tuned.yaml"
CAMERA_NOTE = "vas tune: the camera tuned for"
#: parameters that name files, relative to the parameter file's folder (config/scenario.py)
PATH_PARAMS = ((SIM_SECTION, "urdf"), (CONTROLLER_SECTION, "urdf"),
               (CONTROLLER_SECTION, "trajectory.file"))
FILE_NAMES = {name for _, name in PATH_PARAMS}
REPORT_NAME = "report.md"
OBJECTIVE_PLOT = "objective_over_trials.png"
GAINS_PLOT = "gains_vs_objective.png"


def _fmt(value, fmt=".4g"):
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return format(value, fmt)


def _mapping_value(mapping, key):
    for k, v in mapping.value:
        if isinstance(k, yaml.ScalarNode) and k.value == key:
            return v
    return None


def _find(mapping, name):
    """The value node of the flat parameter ``name`` (nested or dotted keys), or None."""
    if not isinstance(mapping, yaml.MappingNode):
        return None
    for k, v in mapping.value:
        key = k.value if isinstance(k, yaml.ScalarNode) else None
        if key == name:
            return v
        if key and name.startswith(key + "."):
            found = _find(v, name[len(key) + 1:])
            if found is not None:
                return found
    return None


def _end(node):
    """Where a value's text ends (a block collection: its last leaf's end)."""
    if isinstance(node, yaml.MappingNode) and node.value:
        return _end(node.value[-1][1])
    if isinstance(node, yaml.SequenceNode) and node.value and not node.flow_style:
        return _end(node.value[-1])
    return node.end_mark.index


def yaml_value(value):
    """:func:`.spec.yaml_text`, with every float in a form YAML 1.1 reads as a float.

    ``repr`` writes 1e-06, which PyYAML (YAML 1.1) reads as a string; 1.0e-06 is a
    float to every reader.
    """
    return re.sub(r"(?<![\w.])(-?\d+)e([-+]\d+)", r"\1.0e\2", yaml_text(value))


def repointed_text(text, config, out_dir):
    """``text`` (the file ``config``) with its relative file names made relative to ``out_dir``.

    A relative name in a parameter file is looked up from the current folder, then
    from the file's folder (:func:`.resources.resolve_path`); tuned.yaml lives in
    ``out_dir``, so each relative name that resolves is rewritten to the same file
    seen from there.  ``package://``, ``pybullet_data://`` and absolute names stay.
    Returns (text, [(parameter, old, new)]).
    """
    root = yaml.compose(text)
    if not isinstance(root, yaml.MappingNode):
        return text, []
    search_dirs = (os.path.dirname(os.path.abspath(config)),)
    edits, changed = [], []
    for section_name, name in PATH_PARAMS:
        section = _mapping_value(root, section_name) or _mapping_value(root, "/" + section_name)
        params = _mapping_value(section, "ros__parameters") if section is not None else None
        node = _find(params, name)
        if not isinstance(node, yaml.ScalarNode) or not node.value or "://" in node.value \
                or os.path.isabs(node.value):
            continue
        try:
            target = resolve_path(node.value, search_dirs)
        except FileNotFoundError:
            continue    # load_scenario said so already; the check below says it again
        new = os.path.relpath(target, os.path.abspath(out_dir))
        if new != node.value:
            edits.append((node.start_mark.index, node.end_mark.index, yaml_value(new)))
            changed.append((f"{section_name}.{name}", node.value, new))
    for start, end, new in sorted(edits, reverse=True):
        text = text[:start] + new + text[end:]
    return text, changed


def tuned_text(text, values, comments, header, sections=None):
    """The parameter file ``text`` with ``values`` ({param: value}) written in.

    ``comments`` ({param: text}) go after each value; ``header`` (lines) above
    the file.  Values are written in YAML flow style (:func:`yaml_value`).
    ``values`` go into ``controller_node``; ``sections`` ({section: ({param:
    value}, comment)}) into other sections the file has.
    """
    text = _write_into(text, CONTROLLER_SECTION, values, comments)
    for name, (more, note) in (sections or {}).items():
        text = _write_into(text, name, more, dict.fromkeys(more, note))
    return "".join(f"# {line}\n".replace("# \n", "#\n") for line in header) + text


def _write_into(text, section_name, values, comments):
    if not values:
        return text
    root = yaml.compose(text)
    section = None
    if isinstance(root, yaml.MappingNode):
        section = (_mapping_value(root, section_name)
                   or _mapping_value(root, "/" + section_name))
    params = _mapping_value(section, "ros__parameters") if section is not None else None
    if not isinstance(params, yaml.MappingNode) or not params.value:
        raise ValueError(f"no '{section_name}: ros__parameters:' mapping to write into")
    edits, added = [], []
    for name, value in values.items():
        note = f"  # {comments[name]}" if comments.get(name) else ""
        node = _find(params, name)
        if node is None or isinstance(node, yaml.MappingNode):
            added.append(f"{name}: {yaml_value(value)}{note}")
        else:
            edits.append((node.start_mark.index, _end(node), yaml_value(value) + note))
    if added:
        at = _end(params)
        line_end = text.find("\n", at)
        at = len(text) if line_end < 0 else line_end + 1
        indent = " " * params.value[0][0].start_mark.column
        block = "".join(f"{indent}{line}\n" for line in added)
        edits.append((at, at, block if text[at - 1:at] in ("\n", "") else "\n" + block))
    for start, end, new in sorted(edits, reverse=True):
        text = text[:start] + new + text[end:]
    return text


def _changes(space, best_params, base_values, values):
    """{param: comment} and one line per changed gain, for tuned.yaml and the report."""
    comments, lines = {}, []
    for d in space.dimensions:
        if d.param not in values:
            continue
        drawn = best_params[d.key]
        if d.mode == "scale":
            comments[d.param] = f"vas tune: x{drawn:.4g} of the file's value"
            lines.append(f"{d.target}: x{drawn:.4g} of the file's")
        else:
            before = base_values[d.param]
            before = float(before) if isinstance(before, (int, float)) else before
            comments[d.param] = f"vas tune (the file's: {yaml_text(before)})"
            lines.append(f"{d.target}: {yaml_text(before)} -> {yaml_text(values[d.param])}")
    return comments, lines


#: a held-out p90 above this ratio of the file's is no clear gain (neither diverging)
TIE_RATIO = 0.95


def _verdict(held_out, best, values):
    if best is None:
        return ("No trial finished without a divergence in its first runs: no gains to "
                "recommend; widen or move the space (--space), or check the configuration.")
    if not values:
        return (f"The file's own gains (trial {best.number}) scored best on the tuning runs: "
                "no better gains found, tuned.yaml is the input file unchanged; tune with more "
                "trials or another space.")
    if held_out is None:
        return (f"Best: trial {best.number} (objective {best.value:.6g} on the tuning runs); "
                "no held-out runs were asked for (--held-out 0), so nothing says it generalises.")
    tuned, file = held_out["tuned"], held_out["file"]
    figures = (f"held-out: tuned {tuned['diverged']} of {tuned['runs']} diverged, p90 true RMS "
               f"{_fmt(tuned['p90_true_rms_px'])} px; the file's {file['diverged']} of "
               f"{file['runs']} diverged, p90 {_fmt(file['p90_true_rms_px'])} px")
    ratio = None
    if not tuned["diverged"] and not file["diverged"] and file["p90_true_rms_px"] > 0.0:
        ratio = tuned["p90_true_rms_px"] / file["p90_true_rms_px"]
        figures += f"; the tuned p90 is {ratio:.2f}x the file's"
    which = f"The tuned gains (trial {best.number})"
    if tuned["objective"] < file["objective"] and ratio is not None and ratio > TIE_RATIO:
        return (f"{which} are NOT clearly better than the file's on the held-out runs "
                f"({figures}; within {1.0 - TIE_RATIO:.0%}): keep the file's gains, or tune "
                "with more trials or runs.")
    if tuned["objective"] < file["objective"]:
        return f"{which} are better on the held-out runs ({figures})."
    return (f"{which} are NOT better than the file's on the held-out runs ({figures}): keep "
            "the file's gains, or tune with more trials or runs.")


def _figures_line(name, f):
    return (f"{name}: {f['diverged']} of {f['runs']} runs diverged, {f['saturated_runs']} at the "
            f"torque limit, true RMS last 5 s p50 {_fmt(f['p50_true_rms_px'])} / p90 "
            f"{_fmt(f['p90_true_rms_px'])} / max {_fmt(f['max_true_rms_px'])} px, peak |tau| "
            f"{_fmt(f['peak_abs_torque'])} N m")


def write_outputs(tuning, study, optuna, best, values, held_out, notes, wall, interrupted, train,
                  held):
    """tuned.yaml (when a trial completed), report.md and the plots; returns a summary dict.

    ``values``: {controller parameter: value} of the best trial's gains (as its runs got them).
    """
    s = tuning.settings
    out_dir = s.out
    trials = [t for t in study.get_trials(deepcopy=False)
              if t.state != optuna.trial.TrialState.WAITING]
    verdict = ("Interrupted: rerun the same command to resume." if interrupted
               else _verdict(held_out, best, values))
    outputs = []
    base_values = tuning.scenario.controller.params
    changes = []
    if best is not None and not interrupted:
        comments, changes = _changes(tuning.space, best.params, base_values, values)
        header = [f"vas tune: {os.path.basename(s.config)} with the gains of trial {best.number} "
                  f"of {len(trials)} ({s.runs_per_trial} randomized runs of {s.duration:g} s "
                  f"per trial{_conditions(s)})",
                  _figures_line("tuning runs", best.user_attrs)]
        if held_out is not None:
            header += [_figures_line(f"held-out ({s.held_out} runs, other seeds), tuned",
                                     held_out["tuned"]),
                       _figures_line("held-out, the file's gains", held_out["file"])]
        with open(s.config, encoding="utf-8") as handle:
            text, moved = repointed_text(handle.read(), s.config, out_dir)
        header += [verdict, "changed: " + ("; ".join(changes) or "nothing")]
        camera = s.camera_values()
        if any(camera.values()):
            header.append("the camera tuned for (--camera-rate, --camera-latency, --pixel-noise) "
                          "is written in too: the controller is told its rate and latency, "
                          "the simulator simulates it")
        header += [f"{param}: {old!r} -> {new!r} (the same file, named from this folder)"
                   for param, old, new in moved] + [""]
        told = {**camera[CONTROLLER_SECTION], **values}
        comments = {**dict.fromkeys(camera[CONTROLLER_SECTION], CAMERA_NOTE), **comments}
        tuned_path = os.path.join(out_dir, TUNED_NAME)
        with open(tuned_path, "w", encoding="utf-8") as handle:
            handle.write(tuned_text(text, told, comments, _wrap(header),
                                    {SIM_SECTION: (camera[SIM_SECTION], CAMERA_NOTE)}))
        outputs.append(TUNED_NAME)
        notes = notes + _check_tuned(tuned_path, s.config, told, camera[SIM_SECTION])
    plots = plot_tuning(trials, tuning.space, optuna, out_dir)
    lines = _markdown(tuning, trials, best, held_out, notes, wall, verdict, changes, plots,
                      optuna, train, held)
    with open(os.path.join(out_dir, REPORT_NAME), "w", encoding="utf-8") as handle:
        handle.write("\n".join(lines) + "\n")
    outputs += [REPORT_NAME, *plots, "study.db"]
    return {"verdict": verdict, "outputs": outputs, "interrupted": interrupted, "best": best,
            "held_out": held_out, "trials": len(trials), "wall_time_s": wall}


def _check_tuned(tuned_path, config, values, sim_values):
    """tuned.yaml must load to the configuration the best trial's runs had; notes if not."""
    overrides = [f"{CONTROLLER_SECTION}.{k}={yaml_text(v)}" for k, v in values.items()]
    overrides += [f"{SIM_SECTION}.{k}={yaml_text(v)}" for k, v in sim_values.items()]
    expected = load_scenario(config, overrides)
    try:
        got = load_scenario(tuned_path)
    except (ConfigError, FileNotFoundError) as exc:
        return [f"{TUNED_NAME} does not load from {os.path.dirname(tuned_path)} ({exc})"]

    def same(a, b):
        return np.array_equal(np.asarray(a, dtype=object), np.asarray(b, dtype=object))

    wrong = [f"{section}.{k}" for section, e, g in
             ((CONTROLLER_SECTION, expected.controller.params, got.controller.params),
              (SIM_SECTION, expected.sim.params, got.sim.params))
             for k in e if k not in FILE_NAMES and not same(g[k], e[k])]
    if wrong:
        raise RuntimeError(f"{tuned_path}: {wrong} differ from the tuned runs' values")
    return []


def _wrap(lines, width=95):
    out = []
    for line in lines:
        words, current = line.split(" "), ""
        for word in words:
            if current and len(current) + 1 + len(word) > width:
                out.append(current)
                current = "  " + word
            else:
                current = f"{current} {word}" if current else word
        out.append(current)
    return out


def _conditions(s):
    parts = [f"{name} {value:g}{unit}" for name, value, unit in (
        ("camera rate", s.camera_rate, " Hz"), ("camera latency", s.camera_latency, " s"),
        ("pixel noise", s.pixel_noise, " px")) if value is not None]
    return (", " + ", ".join(parts)) if parts else ", the file's camera"


def _markdown(tuning, trials, best, held_out, notes, wall, verdict, changes, plots, optuna,
              train, held):
    s = tuning.settings
    state = optuna.trial.TrialState
    counts = {k: sum(1 for t in trials if t.state == v) for k, v in
              (("complete", state.COMPLETE), ("pruned", state.PRUNED), ("failed", state.FAIL))}
    lines = [f"# vas tune: `{os.path.basename(s.config)}`", "",
             f"{len(trials)} trials ({counts['complete']} complete, {counts['pruned']} pruned "
             f"after diverging in their first runs, {counts['failed']} failed or interrupted), "
             f"{s.runs_per_trial} randomized runs of {s.duration:g} s each{_conditions(s)}; "
             f"{wall:.0f} s of wall time in this call. Space: `{tuning.space.path}`. Runs: "
             f"`{os.path.basename(train.path)}` (a campaign spec: start 0-50 px off in any "
             "direction, initial kinematic estimates x0.5-2 of the true ones, a noise seed).", "",
             f"**{verdict}**", ""]
    if held_out is not None:
        lines += [f"## Held-out runs: {s.held_out} runs with other seeds "
                  f"(`{os.path.basename(held.path)}`)", "",
                  "| gains | diverged | at torque limit | p50 true RMS [px] | p90 true RMS [px] "
                  "| max true RMS [px] | peak abs(tau) [N m] | objective |",
                  "|---|---:|---:|---:|---:|---:|---:|---:|"]
        for name, label in (("file", "the file's"), ("tuned", "tuned")):
            if name in held_out:
                f = held_out[name]
                lines.append(f"| {label} | {f['diverged']} of {f['runs']} | {f['saturated_runs']} "
                             f"| {_fmt(f['p50_true_rms_px'])} | {_fmt(f['p90_true_rms_px'])} "
                             f"| {_fmt(f['max_true_rms_px'])} | {_fmt(f['peak_abs_torque'])} "
                             f"| {_fmt(f['objective'], '.6g')} |")
        worst = held_out.get("tuned", held_out["file"])["worst_command"]
        lines += ["", f"The tuned gains' worst held-out run: `{worst}`", ""]
    if changes:
        lines += ["## Chosen gains (written into tuned.yaml)", ""]
        lines += [f"- {c}" for c in changes] + [""]
    lines += ["## Objective", "",
              "Minimised: 1e9 x (fraction of runs diverged or failed) + 1e6 x (fraction whose "
              "torque reached torque_limit) + the 90 % quantile of the true RMS image error over "
              "the last 5 s (capped at 1000 px), so any divergence ranks below every trial "
              "without one, and a trial at the torque limit below every trial within it.", ""]
    if notes:
        lines += ["## Notes", ""] + [f"- {n}" for n in notes] + [""]
    dims = tuning.space.dimensions
    lines += ["## Trials", "",
              "| trial | state | objective | diverged | at torque limit | p90 true RMS [px] "
              "| peak abs(tau) [N m] | " + " | ".join(f"`{d.key}`" for d in dims) + " |",
              "|---:|---|---:|---:|---:|---:|---:|" + "---:|" * len(dims)]
    for t in trials:
        a = t.user_attrs
        mark = " (best)" if best is not None and t.number == best.number else ""
        runs = f"{a.get('diverged', '-')} of {a.get('runs', '-')}"
        lines.append(f"| {t.number}{mark} | {t.state.name.lower()} | {_fmt(t.value, '.6g')} "
                     f"| {runs} | {a.get('saturated_runs', '-')} "
                     f"| {_fmt(a.get('p90_true_rms_px'))} | {_fmt(a.get('peak_abs_torque'))} | "
                     + " | ".join(_fmt(t.params.get(d.key)) if not d.choices
                                  else str(t.params.get(d.key, "-")) for d in dims) + " |")
    lines += ["", "Trial 0 is the configuration's own gains (moved into the space where they "
              "are outside it, see Notes). Scale dimensions are factors of the file's values.", ""]
    if plots:
        lines += ["## Plots", ""] + [f"![{os.path.splitext(p)[0]}]({p})" for p in plots]
    return lines


def plot_tuning(trials, space, optuna, out_dir):
    """objective_over_trials.png and gains_vs_objective.png; returns the file names."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    done = [t for t in trials if t.state in (optuna.trial.TrialState.COMPLETE,
                                             optuna.trial.TrialState.PRUNED)]
    if not done:
        return []

    def tracked(t):
        return t.state == optuna.trial.TrialState.COMPLETE and t.user_attrs.get("diverged") == 0

    calm = [t for t in done if tracked(t)]
    top = max((t.user_attrs["p90_true_rms_px"] for t in calm
               if math.isfinite(t.user_attrs.get("p90_true_rms_px", math.nan))), default=1.0) * 3
    fig, ax = plt.subplots(figsize=(7, 4))
    if calm:
        ax.plot([t.number for t in calm], [max(t.user_attrs["p90_true_rms_px"], 1e-6)
                                           for t in calm], "o", label="no divergence")
        best, xs, ys = math.inf, [], []
        for t in sorted(calm, key=lambda t: t.number):
            best = min(best, t.user_attrs["p90_true_rms_px"])
            xs.append(t.number)
            ys.append(max(best, 1e-6))
        ax.step(xs, ys, where="post", color="tab:green", label="best so far")
    div = [t.number for t in done if not tracked(t)]
    if div:
        ax.plot(div, [top] * len(div), "x", color="tab:red", ms=8, mew=2,
                label="diverged (pruned or complete)")
    ax.set_yscale("log")
    ax.set_xlabel("trial")
    ax.set_ylabel("p90 true RMS image error, last 5 s [px]")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, OBJECTIVE_PLOT), dpi=80)
    plt.close(fig)
    dims = space.dimensions
    cols = min(4, len(dims))
    rows = math.ceil(len(dims) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.8 * rows), squeeze=False)
    for ax, d in zip(axes.flat, dims):
        pts = [(t.params[d.key], t.user_attrs["p90_true_rms_px"]) for t in calm
               if d.key in t.params]
        bad = [t.params[d.key] for t in done if not tracked(t) and d.key in t.params]
        if d.choices:
            labels = [str(c) for c in d.choices]
            pts = [(labels.index(str(x)), y) for x, y in pts]
            bad = [labels.index(str(x)) for x in bad]
            ax.set_xticks(range(len(labels)))
            ax.set_xticklabels(labels, fontsize=7)
        elif d.log:
            ax.set_xscale("log")
        if pts:
            ax.plot([x for x, _ in pts], [max(y, 1e-6) for _, y in pts], "o", ms=4)
        if bad:
            ax.plot(bad, [top] * len(bad), "x", color="tab:red", ms=6, mew=2)
        ax.set_yscale("log")
        # labels on the decades only: the minor ones of a narrow log range overlap
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.yaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel(d.key.replace(f"{CONTROLLER_SECTION}.", ""), fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
    for ax in list(axes.flat)[len(dims):]:
        ax.axis("off")
    axes[0][0].set_ylabel("p90 true RMS [px]")
    fig.suptitle("each gain against the p90 true RMS error (red x: diverged)", fontsize=9)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, GAINS_PLOT), dpi=80)
    plt.close(fig)
    return [OBJECTIVE_PLOT, GAINS_PLOT]
