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

"""``vas campaign``: specs, resolution to ``vas run`` commands, execution, resume, failures.

Oracles: the model's own projection for the start offsets, the config loader for
the overrides, an independent ``vas run`` process for the reproduction commands,
the closed forms of the Wilson interval at k = 0 and p = 1/2, and exact equality
between engines and between repeated campaigns.
"""

import json
import math
import os
import re
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import textwrap
import tempfile

import numpy as np
import pytest

from visual_adaptive_servo.campaigns.campaign import CSV_NAME, exclusive, read_rows, run_campaign
from visual_adaptive_servo.campaigns.engine import (
    CampaignError,
    execute_run,
    FIGURES,
    RAY_MISSING,
    RayCluster,
)
from visual_adaptive_servo.campaigns.report import markdown, summarize, wilson_interval
from visual_adaptive_servo.campaigns.spec import load_spec, SpecError, yaml_text
from visual_adaptive_servo.control.registry import CONTROLLER_NAMES
from visual_adaptive_servo.config.files import apply_overrides
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.config.sim import SIM_PARAMS
from visual_adaptive_servo.control.trajectory import SinusoidTrajectory
from visual_adaptive_servo.runner import run_scenario
from sim_bridge.simulator import Simulator

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PAPER = os.path.join(ROOT, "config", "paper_3dof.yaml")
SHORT = 0.5      # simulated seconds: the figures of the engine tests need no more


def write_spec(folder, text, name="spec.yaml"):
    path = os.path.join(folder, name)
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(textwrap.dedent(text))
    return path


SMALL = """\
    base: paper_3dof.yaml
    duration: {duration}
    fixed:
      set.controller_node.start_blend_time: 0.5
    cases:
      - {{name: offset, start_offset_px: 3.0}}
      - {{name: noisy, pixel_noise: 0.3, seed: 7}}
    grid:
      controller: [observer, velocity-lp]
    random:
      runs: 1
      seed: 3
      factors:
        estimate_scale.a_z: {{log_uniform: [0.7, 1.4]}}
"""


def small_spec(folder, duration=SHORT):
    return write_spec(folder, SMALL.format(duration=duration))


def comparable(figures):
    """``figures`` with NaN as the text 'nan' (NaN != NaN would fail every comparison)."""
    return {k: "nan" if isinstance(v, float) and math.isnan(v) else v for k, v in figures.items()}


def figures_of(rows):
    """Everything of each row but the wall time, by id."""
    return {r["id"]: (comparable({k: r[k] for k in FIGURES}), r["factors"], r["status"],
                      r["command"]) for r in rows}


# -- spec validation --------------------------------------------------------------------

BAD_SPECS = [
    ("duration: 1.0\ngrid: {pixel_noise: [0.0]}\n", r"base: missing"),
    ("base: nope.yaml\nduration: 1.0\ngrid: {pixel_noise: [0.0]}\n",
     r"base: 'nope.yaml' is neither beside the spec nor in"),
    ("base: paper_3dof.yaml\nduration: -1\ngrid: {pixel_noise: [0.0]}\n",
     r"duration: must be simulated seconds > 0, got -1"),
    ("base: paper_3dof.yaml\nduration: 1.0\n", r"cases/grid/random: missing"),
    ("base: paper_3dof.yaml\nduration: 1.0\ngird: {}\n", r"gird: unknown key"),
    ("base: paper_3dof.yaml\nduration: 1.0\ngrid: {pixel_nois: [0.0]}\n",
     r"grid.pixel_nois: unknown factor 'pixel_nois' \(factors: set.<section.param>"),
    ("base: paper_3dof.yaml\nduration: 1.0\ngrid: {pixel_noise: 0.5}\n",
     r"grid.pixel_noise: must be a non-empty list of values, got 0.5"),
    ("base: paper_3dof.yaml\nduration: 1.0\ngrid: {pixel_noise: [0.5, -1.0]}\n",
     r"grid.pixel_noise\[1\]: must be a number >= 0, got -1.0"),
    ("base: paper_3dof.yaml\nduration: 1.0\ngrid: {set.controller_node.alpah: [1.0]}\n",
     r"grid.set.controller_node.alpah: controller_node.alpah is not a parameter of "
     r"controller_node \(did you mean alpha\? the parameters: "
     r"visual_adaptive_servo/config/controller.py\)"),
    ("base: paper_3dof.yaml\nduration: 1.0\ngrid: {gain_scale.beta: [1.0]}\n",
     r"grid.gain_scale.beta: unknown factor"),
    ("base: paper_3dof.yaml\nduration: 1.0\ngrid: {gain_scale.alpha: [0.0]}\n",
     r"grid.gain_scale.alpha\[0\]: must be a number > 0, got 0.0"),
    ("base: paper_3dof.yaml\nduration: 1.0\ncases: [{name: a, controller: pid}]\n",
     r"cases\[0\].controller: must be one of \['observer', 'observer-uncompensated', "
     r"'velocity-diff', 'velocity-lp', "
     r"'ibvs-calibrated'\], got 'pid'"),
    ("base: paper_3dof.yaml\nduration: 1.0\ncases: [{pixel_noise: 1.0}]\n",
     r"cases\[0\].name: missing: every case needs a name"),
    ("base: paper_3dof.yaml\nduration: 1.0\ncases: [{name: a}, {name: a}]\n",
     r"cases\[1\].name: 'a' is used by an earlier case"),
    ("base: paper_3dof.yaml\nduration: 1.0\nrandom: {runs: 3, factors: {seed: {integer: "
     "[0, 9]}}}\n", r"random.seed: must be an integer >= 0"),
    ("base: paper_3dof.yaml\nduration: 1.0\nrandom: {runs: 0, seed: 1, factors: {seed: "
     "{integer: [0, 9]}}}\n", r"random.runs: must be an integer >= 1"),
    ("base: paper_3dof.yaml\nduration: 1.0\nrandom: {runs: 3, seed: 1, factors: "
     "{estimate_scale.a_z: {log_uniform: [0.0, 2.0]}}}\n",
     r"random.factors.estimate_scale.a_z.log_uniform: needs 0 < low, got \[0.0, 2.0\]"),
    ("base: paper_3dof.yaml\nduration: 1.0\nrandom: {runs: 3, seed: 1, factors: "
     "{pixel_noise: {normal: [0.0, 1.0]}}}\n",
     r"random.factors.pixel_noise: must be one of \{uniform: \[low, high\]\}"),
    ("base: paper_3dof.yaml\nduration: 1.0\nrandom: {runs: 3, seed: 1, factors: "
     "{seed: {uniform: [0, 9]}}}\n",
     r"random.factors.seed.uniform: seed takes \{integer: \[low, high\]\} or a choice"),
    ("base: paper_3dof.yaml\nduration: 1.0\nfixed: {pixel_noise: 0.1}\n"
     "grid: {pixel_noise: [0.0]}\n", r"grid.pixel_noise: also given in fixed"),
    ("base: paper_3dof.yaml\nduration: 1.0\nfixed: {set.controller_node.alpha: 12.0}\n"
     "grid: {gain_scale.alpha: [1.0, 2.0]}\n",
     r"grid.gain_scale.alpha: sets controller_node.alpha, as fixed.set.controller_node.alpha "
     r"does"),
    ("base: paper_3dof.yaml\nduration: 1.0\ngrid: {start_offset_angle_deg: [10.0]}\n",
     r"grid.start_offset_angle_deg: needs start_offset_px"),
]


@pytest.mark.parametrize("text, message", BAD_SPECS)
def test_spec_errors_name_the_file_and_the_key(tmp_path, text, message):
    path = write_spec(str(tmp_path), text)
    with pytest.raises(SpecError, match=re.escape(path) + ": " + message):
        load_spec(path)


def test_camera_latency_is_the_sim_node_parameter_when_it_exists(tmp_path):
    path = write_spec(str(tmp_path), "base: paper_3dof.yaml\nduration: 1.0\n"
                      "grid: {camera_latency: [0.01]}\n")
    if "camera_latency" in {s.name for s in SIM_PARAMS}:
        assert "sim_node.camera_latency=0.01" in load_spec(path).runs()[0].overrides
    else:
        with pytest.raises(SpecError, match="grid.camera_latency: sim_node.camera_latency is "
                                            "not a parameter of sim_node"):
            load_spec(path)


def test_shipped_specs_resolve():
    names = sorted(os.listdir(os.path.join(ROOT, "config", "campaigns")))
    assert names == ["compare.yaml", "late_stamps_paper_urdf.yaml", "noise_preset_1000.yaml",
                     "noise_preset_sweep.yaml", "noisy_pixels_iiwa.yaml",
                     "real_camera_iiwa.yaml", "real_camera_own_guess.yaml",
                     "real_camera_panda.yaml", "real_camera_paper_urdf.yaml",
                     "robustness.yaml", "start_and_estimates.yaml"]
    runs = {name: load_spec(os.path.join(ROOT, "config", "campaigns", name)).runs()
            for name in names}
    for name, spec_runs in runs.items():
        assert not any(r.problem for r in spec_runs), name
    assert len(runs["start_and_estimates.yaml"]) == 200
    assert len(runs["noise_preset_1000.yaml"]) == 1000
    assert len(runs["noise_preset_sweep.yaml"]) == 32 * 4
    for name in ("noisy_pixels_iiwa.yaml", "real_camera_iiwa.yaml", "real_camera_panda.yaml",
                 "real_camera_paper_urdf.yaml"):
        assert len(runs[name]) == 100, name
    # the late stamps: the paper arm's real-camera draws, each in its four cases
    late, real = runs["late_stamps_paper_urdf.yaml"], runs["real_camera_paper_urdf.yaml"]
    assert len(late) == 4 * 100
    for run in late:
        draw = real[run.index // 4].factors
        assert {k: run.factors[k] for k in draw} == draw
    # each shipped arm with its file's own guess: no estimate_scale factor
    own = runs["real_camera_own_guess.yaml"]
    assert len(own) == 3 * 40
    assert {os.path.basename(r.base) for r in own} == {"iiwa_3points.yaml",
                                                       "panda_2points.yaml",
                                                       "paper_3dof_urdf.yaml"}
    assert not any("estimate_scale" in key for r in own for key in r.factors)
    compare = runs["compare.yaml"]
    assert len(compare) == 12 * 3 * 5
    assert {r.controller for r in compare} == set(CONTROLLER_NAMES)
    assert {os.path.basename(r.base) for r in compare} == {"paper_3dof.yaml",
                                                           "paper_3dof_noisy.yaml",
                                                           "paper_3dof_urdf.yaml"}


# -- resolution to overrides ------------------------------------------------------------

def resolved(tmp_path, factors):
    """The validated scenario of one run with ``factors`` fixed."""
    body = "".join(f"  {k}: {v}\n" for k, v in factors.items())
    path = write_spec(str(tmp_path), f"base: paper_3dof.yaml\nduration: 1.0\nfixed:\n{body}"
                      "cases: [{name: only}]\n")
    run = load_spec(path).runs()[0]
    assert not run.problem
    return run, load_scenario(run.base, run.overrides)


def test_factors_become_the_parameters_they_name(tmp_path):
    base = load_scenario(PAPER)
    run, scen = resolved(tmp_path, {
        "pixel_noise": 0.25, "seed": 11, "set.controller_node.alpha": 12.5,
        "scale.controller_node.Gamma_d": 0.5, "gain_scale.gamma": 0.3,
        "estimate_scale.a_z": 2.0, "estimate_scale.a_z_perp": 0.7,
        "trajectory.amplitude_scale": 1.5, "trajectory.frequency_scale": 0.5})
    sim, ctl, model = scen.sim, scen.controller, base.controller.model
    assert sim.pixel_noise_std == 0.25 and sim.seed == 11 and ctl.alpha == 12.5
    np.testing.assert_array_equal(ctl.Gamma_d, base.controller.Gamma_d * 0.5)
    assert ctl.gamma == base.controller.gamma * 0.3
    np.testing.assert_array_equal(ctl.a_z_init, model.a_z * 2.0)
    np.testing.assert_array_equal(ctl.a_z_perp_init, model.a_z_perp * 0.7)
    np.testing.assert_array_equal(ctl["trajectory.a_cos"], base.controller["trajectory.a_cos"]
                                  * 1.5)
    np.testing.assert_array_equal(ctl["trajectory.a_sin"], base.controller["trajectory.a_sin"]
                                  * 1.5)
    assert ctl["trajectory.omega"] == base.controller["trajectory.omega"] * 0.5
    assert run.controller == "observer"


@pytest.mark.parametrize("offset, angle", [(5.0, None), (20.0, 135.0), (0.0, None)])
def test_start_offset_puts_the_feature_that_far_from_the_trajectory_start(tmp_path, offset,
                                                                          angle):
    factors = {"start_offset_px": offset, "trajectory.amplitude_scale": 1.2}
    if angle is not None:
        factors["start_offset_angle_deg"] = angle
    _, scen = resolved(tmp_path, factors)
    ctl = scen.controller
    x_start = SinusoidTrajectory(ctl["trajectory.offset"], ctl["trajectory.a_cos"],
                                 ctl["trajectory.a_sin"], ctl["trajectory.omega"])(0.0)[0]
    direction = (np.array([0.6, -0.8]) if angle is None else
                 np.array([math.cos(math.radians(angle)), math.sin(math.radians(angle))]))
    sim = Simulator(scen.sim)            # the oracle: PyBullet's arm seen by the true camera
    try:
        x0 = sim.measure().true_pixels
    finally:
        sim.close()
    np.testing.assert_allclose(x0, x_start + offset * direction, atol=1e-6)


def test_start_offset_joint_adds_to_the_initial_positions(tmp_path):
    _, scen = resolved(tmp_path, {"start_offset_joint": "[0.1, -0.2, 0.05]"})
    np.testing.assert_allclose(scen.sim.initial_positions,
                               load_scenario(PAPER).sim.initial_positions
                               + np.array([0.1, -0.2, 0.05]), atol=1e-15)


@pytest.mark.parametrize("value", [0.1, 1e-05, 1.5e20, 3, -2.5, [0.1, 1e-07, 7.0], math.inf,
                                   True, "gravity_compensation"])
def test_override_text_reads_back_to_the_same_value(value):
    sections = {"sim_node": {}, "controller_node": {}}
    got = apply_overrides(sections, [f"sim_node.x={yaml_text(value)}"])["sim_node"]["x"]
    assert got == value and type(got) is type(value)


def test_random_draws_are_reproducible_and_independent_of_the_count(tmp_path):
    text = """\
        base: paper_3dof.yaml
        duration: 1.0
        random:
          runs: {runs}
          seed: {seed}
          factors:
            start_offset_px: {{uniform: [0.0, 30.0]}}
            estimate_scale.a_z: {{log_uniform: [0.5, 2.0]}}
            seed: {{integer: [0, 1000]}}
            controller: {{choice: [observer, velocity-lp]}}
    """

    def draws(runs, seed):
        path = write_spec(str(tmp_path), text.format(runs=runs, seed=seed), f"s{runs}{seed}.yaml")
        return [(r.factors, r.overrides, r.controller) for r in load_spec(path).runs()]

    first = draws(20, 3)
    assert first == draws(20, 3)
    assert draws(10, 3) == first[:10]
    assert draws(20, 4) != first
    values = [f["start_offset_px"] for f, _, _ in first]
    assert all(0.0 <= v <= 30.0 for v in values) and len(set(values)) == 20
    assert all(0.5 <= f["estimate_scale.a_z"] <= 2.0 for f, _, _ in first)
    assert all(isinstance(f["seed"], int) for f, _, _ in first)
    assert {c for _, _, c in first} == {"observer", "velocity-lp"}


def test_cases_grid_and_draws_multiply_with_draws_outermost(tmp_path):
    path = write_spec(str(tmp_path), """\
        base: paper_3dof.yaml
        duration: 1.0
        cases: [{name: a, pixel_noise: 0.1}, {name: b, seed: 3}]
        grid: {controller: [observer, velocity-lp, ibvs-calibrated]}
        random: {runs: 2, seed: 0, factors: {gain_scale.K: {uniform: [0.5, 2.0]}}}
    """)
    spec = load_spec(path)
    runs = spec.runs()
    assert len(runs) == 2 * 2 * 3
    assert spec.factor_columns == ["case", "pixel_noise", "seed", "controller",
                                   "gain_scale.K"]
    assert [r.factors["case"] for r in runs[:6]] == ["a"] * 3 + ["b"] * 3
    assert len({r.factors["gain_scale.K"] for r in runs[:6]}) == 1     # one draw, all cases
    assert runs[0].factors["gain_scale.K"] != runs[6].factors["gain_scale.K"]
    assert "seed" not in runs[0].factors and "pixel_noise" not in runs[3].factors


# -- statistics -------------------------------------------------------------------------

def test_wilson_interval_matches_its_closed_forms():
    z2 = 1.959963984540054 ** 2
    # k = 0: [0, z^2 / (n + z^2)]
    np.testing.assert_allclose(wilson_interval(0, 10), (0.0, z2 / (10 + z2)), rtol=1e-12)
    # p = 1/2: 1/2 -+ z sqrt(n + z^2) / (2 (n + z^2))
    half = math.sqrt(z2) * math.sqrt(10 + z2) / (2 * (10 + z2))
    np.testing.assert_allclose(wilson_interval(5, 10), (0.5 - half, 0.5 + half), rtol=1e-12)
    np.testing.assert_allclose(wilson_interval(10, 10), (10 / (10 + z2), 1.0), rtol=1e-12)
    assert all(math.isnan(v) for v in wilson_interval(0, 0))


# -- execution --------------------------------------------------------------------------

def test_rows_repeat_exactly_and_their_commands_reproduce_them(tmp_path):
    spec = small_spec(str(tmp_path))
    first = run_campaign(spec, str(tmp_path / "a"), workers=2, progress=False)
    assert first["rows"] == 4 and first["failed"] == 0
    rows = read_rows(str(tmp_path / "a" / CSV_NAME), load_spec(spec))
    run_campaign(spec, str(tmp_path / "b"), workers=2, progress=False)
    again = read_rows(str(tmp_path / "b" / CSV_NAME), load_spec(spec))
    assert figures_of(rows) == figures_of(again)
    for name in ("summary.md", "summary.json", "error_histogram.png",
                 "error_vs_controller.png", "error_vs_estimate_scale.a_z.png"):
        assert os.path.exists(tmp_path / "a" / name), name
    # the transient (after 5 s) is summarised beside the last 5 s, so that a longer
    # transient shows where the end is better (these runs are shorter than 5 s: NaN)
    assert all(math.isnan(first["quantiles"][key]["p50"])
               for key in ("transient_rms_true_error_px", "transient_max_true_error_px"))
    rng = np.random.default_rng(3)
    longer = [{**r, "transient_rms_true_error_px": a, "transient_max_true_error_px": b}
              for r, (a, b) in zip(rows, rng.random((len(rows), 2)))]
    calm = [r for r in longer if r["status"] == "finished" and not r["diverged"]]
    summary = summarize(longer, [], len(longer))
    for key in ("transient_rms_true_error_px", "transient_max_true_error_px"):
        values = [r[key] for r in calm]
        expected = np.quantile(values, 0.95)
        assert summary["quantiles"][key]["p95"] == pytest.approx(expected, rel=1e-12), key
        assert summary["quantiles"][key]["max"] == max(values), key
    text = markdown(summary, "t", [])
    assert "| max true image error after 5 s [px] |" in text
    # an offset start with a baseline: the row's command, run by vas in its own process
    row = next(r for r in rows if r["factors"]["case"] == "offset"
               and r["factors"]["controller"] == "velocity-lp")
    words = shlex.split(row["command"])
    assert words[:2] == ["vas", "run"]
    subprocess.run([sys.executable, "-m", "visual_adaptive_servo.cli"] + words[1:],
                   cwd=tmp_path, check=True, capture_output=True)
    with open(tmp_path / f"vas-run-{row['id']}" / "summary.json", encoding="utf-8") as handle:
        summary = json.load(handle)
    assert (comparable({k: summary[k] for k in FIGURES})
            == comparable({k: row[k] for k in FIGURES}))


def test_resume_after_a_limit_and_after_ctrl_c_records_every_run_once(tmp_path):
    spec = small_spec(str(tmp_path))
    out = str(tmp_path / "out")
    assert run_campaign(spec, out, workers=2, limit=1, progress=False)["rows"] == 1
    with open(os.path.join(out, CSV_NAME), "a", encoding="utf-8") as handle:
        handle.write("2,noisy,,0.3")        # a row cut short by a hard stop

    seen = []

    def ctrl_c_after_two(result):
        seen.append(result.run.index)
        if len(seen) == 2:
            raise KeyboardInterrupt
    interrupted = run_campaign(spec, out, workers=2, progress=False, on_row=ctrl_c_after_two)
    assert interrupted["interrupted"] and interrupted["rows"] == 3
    done = run_campaign(spec, out, workers=2, progress=False)
    assert done["resumed_rows"] == 3 and done["executed_now"] == 1
    ids = [r["id"] for r in read_rows(os.path.join(out, CSV_NAME), load_spec(spec))]
    assert sorted(ids) == [0, 1, 2, 3]
    other = write_spec(str(tmp_path), SMALL.format(duration=0.6), "other.yaml")
    with pytest.raises(CampaignError, match="holds the campaign of another spec"):
        run_campaign(other, out, workers=2, progress=False)
    with exclusive(out), pytest.raises(CampaignError, match="in use by another vas campaign"):
        run_campaign(spec, out, workers=2, progress=False)


def test_the_same_factors_in_another_order_are_another_campaign(tmp_path):
    # the draws take the factors in file order: a spec with them reordered (a YAML dumped
    # with sorted keys, say) draws other runs, so its folder must not be resumed as this one's
    text = """\
        base: paper_3dof.yaml
        duration: 0.2
        random:
          runs: 3
          seed: 5
          factors:
            {first}
            {second}
    """
    a_z = "estimate_scale.a_z: {log_uniform: [0.5, 2.0]}"
    noise = "pixel_noise: {uniform: [0.2, 1.0]}"
    one = load_spec(write_spec(str(tmp_path), text.format(first=noise, second=a_z), "one.yaml"))
    two = load_spec(write_spec(str(tmp_path), text.format(first=a_z, second=noise), "two.yaml"))
    assert one.raw == two.raw                       # equal as mappings
    draws_one = [varying for varying, _ in one.factor_sets()]
    draws_two = [varying for varying, _ in two.factor_sets()]
    assert draws_one != draws_two
    assert one.fingerprint() != two.fingerprint()
    again = load_spec(write_spec(str(tmp_path), text.format(first=noise, second=a_z),
                                 "again.yaml"))
    assert again.fingerprint() == one.fingerprint()


def exit_or_raise(run):
    """Run 1's worker dies every time; run 2 raises; the others run."""
    if run.index == 1:
        os._exit(1)
    if run.index == 2:
        raise ValueError("bad luck")
    return execute_run(run)


def test_a_run_whose_worker_always_dies_fails_after_two_attempts(tmp_path):
    spec = small_spec(str(tmp_path))
    summary = run_campaign(spec, str(tmp_path / "out"), workers=2, run_fn=exit_or_raise,
                           progress=False)
    rows = {r["id"]: r for r in read_rows(str(tmp_path / "out" / CSV_NAME), load_spec(spec))}
    assert sorted(rows) == [0, 1, 2, 3] and summary["failed"] == 2
    assert (rows[1]["status"], rows[1]["attempts"]) == ("failed", 2)
    assert rows[1]["reason"] == "worker died with exit code 1, twice"
    assert (rows[2]["status"], rows[2]["attempts"], rows[2]["reason"]) == (
        "failed", 1, "ValueError: bad luck")
    for i in (0, 3):
        assert (rows[i]["status"], rows[i]["attempts"]) == ("finished", 1)


def test_a_worker_killed_mid_run_is_replaced_and_the_run_retried(tmp_path):
    spec = small_spec(str(tmp_path), duration=2.0)
    killed = []

    def kill_first_start_of_run_1(run, pid):
        if run.index == 1 and not killed:
            killed.append(pid)
            os.kill(pid, signal.SIGKILL)
    run_campaign(spec, str(tmp_path / "out"), workers=2, progress=False,
                 on_start=kill_first_start_of_run_1)
    rows = {r["id"]: r for r in read_rows(str(tmp_path / "out" / CSV_NAME), load_spec(spec))}
    assert killed and sorted(rows) == [0, 1, 2, 3]
    assert all(r["status"] == "finished" for r in rows.values())
    assert [rows[i]["attempts"] for i in range(4)] == [1, 2, 1, 1]


def die_in_the_middle_of_run_1(run):
    """Run 1's worker dies at its 100th period, inside the run; the others run."""
    if run.index == 1:
        from visual_adaptive_servo.runner import Simulator

        apply, periods = Simulator.apply, []

        def apply_then_die(self, tau):
            periods.append(1)
            if len(periods) == 100:
                os._exit(1)
            return apply(self, tau)
        Simulator.apply = apply_then_die
    return execute_run(run)


def test_a_worker_that_dies_in_a_run_leaves_no_scratch_folder(tmp_path, monkeypatch):
    scratch = tmp_path / "scratch"         # the workers' temporary folder
    scratch.mkdir()
    monkeypatch.setenv("TMPDIR", str(scratch))
    monkeypatch.setattr(tempfile, "tempdir", None)
    spec = small_spec(str(tmp_path))
    run_campaign(spec, str(tmp_path / "out"), workers=2, run_fn=die_in_the_middle_of_run_1,
                 progress=False)
    rows = {r["id"]: r for r in read_rows(str(tmp_path / "out" / CSV_NAME), load_spec(spec))}
    assert rows[1]["reason"] == "worker died with exit code 1, twice"
    assert not [p.name for p in scratch.iterdir() if p.name.startswith("vas-")]


def test_a_run_without_a_folder_writes_nothing_and_records_nothing():
    scenario = load_scenario(PAPER)
    with pytest.raises(ValueError, match="out_dir None writes nothing: record and plots must"):
        run_scenario(scenario, None, duration=0.1, progress=False, record=True, plots=False)
    summary = run_scenario(scenario, None, duration=0.1, progress=False, record=False,
                           plots=False)
    assert summary["steps"] == 20 and summary["outputs"] == []


def test_workers_import_this_package_whatever_the_working_directory(tmp_path):
    # vas run from inside another checkout: its package must not reach the workers
    vas = shutil.which("vas", path=os.path.dirname(sys.executable)) or shutil.which("vas")
    if vas is None:
        pytest.skip("the vas command is not installed")
    decoy = tmp_path / "visual_adaptive_servo"
    decoy.mkdir()
    (decoy / "__init__.py").write_text("raise RuntimeError('the decoy package was imported')\n")
    spec = small_spec(str(tmp_path))
    subprocess.run([vas, "campaign", "--spec", spec, "--out", "out", "--workers", "2",
                    "--runs", "2"], cwd=tmp_path, check=True, capture_output=True)
    rows = read_rows(str(tmp_path / "out" / CSV_NAME), load_spec(spec))
    assert [(r["status"], r["reason"]) for r in rows] == [("finished", "")] * 2


def test_ray_missing_is_said_plainly(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)       # import ray -> ImportError
    with pytest.raises(CampaignError, match=re.escape(RAY_MISSING)):
        RayCluster("auto")


def test_ray_address_where_nothing_listens_is_refused_at_once():
    pytest.importorskip("ray", reason="Ray is an optional extra: pip install '.[ray]'")
    with socket.socket() as probe:      # a port that was free a moment ago
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    with pytest.raises(CampaignError, match=f"--ray 127.0.0.1:{port}: no Ray cluster answers"):
        RayCluster(f"127.0.0.1:{port}")


def test_ray_gives_the_same_rows_as_the_process_pool(tmp_path):
    pytest.importorskip("ray", reason="Ray is an optional extra: pip install '.[ray]'")
    spec = small_spec(str(tmp_path))
    run_campaign(spec, str(tmp_path / "pool"), workers=2, progress=False)
    summary = run_campaign(spec, str(tmp_path / "ray"), workers=2, ray="auto", progress=False)
    assert summary["engine"] == "ray auto"
    pool = read_rows(str(tmp_path / "pool" / CSV_NAME), load_spec(spec))
    ray = read_rows(str(tmp_path / "ray" / CSV_NAME), load_spec(spec))
    assert figures_of(ray) == figures_of(pool)
    assert all(r["status"] == "finished" and r["attempts"] == 1 for r in ray)


def test_vas_campaign_refuses_a_bad_spec_with_its_message(tmp_path, capsys):
    from visual_adaptive_servo.cli import main

    path = write_spec(str(tmp_path), "base: paper_3dof.yaml\nduration: 0\ngrid: {seed: [1]}\n")
    assert main(["campaign", "--spec", path, "--out", str(tmp_path / "out")]) == 2
    assert "duration: must be simulated seconds > 0" in capsys.readouterr().err


def test_a_case_may_give_its_own_duration(tmp_path):
    spec = tmp_path / "s.yaml"
    spec.write_text("base: paper_3dof.yaml\nduration: 10.0\ncases:\n"
                    "  - {name: short}\n  - {name: long, duration: 20.0}\n")
    runs = load_spec(str(spec)).runs()
    assert [r.duration for r in runs] == [10.0, 20.0]
    assert "--duration 20.0" in runs[1].command
    spec.write_text("base: paper_3dof.yaml\nduration: 10.0\n"
                    "cases:\n  - {name: bad, duration: 0}\n")
    with pytest.raises(SpecError, match="duration"):
        load_spec(str(spec))


def test_a_diverged_run_says_why_in_its_row_and_in_the_summary(tmp_path):
    # a divergence torque below the paper's start-up torque: the run diverges at once
    spec = write_spec(str(tmp_path), f"""\
        base: paper_3dof.yaml
        duration: {SHORT}
        cases:
          - {{name: calm}}
          - {{name: strict, set.controller_node.divergence_torque: 1.0}}
        """)
    run_campaign(spec, str(tmp_path / "out"), workers=1, progress=False)
    rows = {r["factors"]["case"]: r for r in read_rows(str(tmp_path / "out" / CSV_NAME),
                                                       load_spec(spec))}
    assert (rows["calm"]["diverged"], rows["calm"]["reason"]) == (False, "")
    strict = rows["strict"]
    assert strict["status"] == "finished" and strict["diverged"]
    assert re.match(r"commanded \|tau\| = \S+ N m \(before the torque limit\) > "
                    r"divergence_torque 1 at t=\d",
                    strict["reason"]), strict["reason"]
    # what vas run says of the same run (it exits with 1: diverged)
    words = shlex.split(strict["command"])
    done = subprocess.run([sys.executable, "-m", "visual_adaptive_servo.cli"] + words[1:],
                          cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 1, done.stderr
    with open(tmp_path / f"vas-run-{strict['id']}" / "summary.json", encoding="utf-8") as handle:
        assert json.load(handle)["divergence_reason"] == strict["reason"]
    summary = (tmp_path / "out" / "summary.md").read_text(encoding="utf-8")
    assert f"| yes: {strict['reason'].replace('|', '/')} |" in summary
