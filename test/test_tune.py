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

"""``vas tune``: the search space, the objective, tuned.yaml, a tuning end to end, bad input.

Oracles: the config loader (tuned.yaml must load to exactly the configuration the
best trial's runs were given as ``--set`` overrides; the space's ends must be what
the parameter specs accept), Optuna's own storage (a resumed call continues the
same study: the earlier trials unchanged), the trial figures recomputed from the
stored per-run figures' definition, and Theorem 1 on every draw.
"""

import math
import os
import subprocess
import sys
import textwrap
from functools import partial

import numpy as np
import pytest
import yaml

from visual_adaptive_servo.campaigns.engine import CampaignError, RunResult
from visual_adaptive_servo.campaigns.spec import load_spec, Run
from visual_adaptive_servo.campaigns.tune import (
    OPTUNA_MISSING,
    PRUNE_ABOVE,
    run_tuning,
    score,
    STUDY_DB,
    STUDY_NAME,
    TuneSettings,
)
from visual_adaptive_servo.campaigns.tune_report import repointed_text, tuned_text
from visual_adaptive_servo.campaigns.tune_space import DEFAULT_SPACE, load_space, SpaceError
from visual_adaptive_servo.config.files import read_param_file
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.schema import ConfigError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PAPER = os.path.join(ROOT, "config", "paper_3dof.yaml")
IIWA = os.path.join(ROOT, "config", "iiwa_3points.yaml")


def write(folder, name, text):
    path = os.path.join(str(folder), name)
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(textwrap.dedent(text))
    return path


@pytest.fixture(scope="module")
def paper():
    return load_scenario(PAPER), read_param_file(PAPER)["controller_node"]


def space_of(folder, text, base):
    scenario, file_params = base
    return load_space(write(folder, "space.yaml", text), scenario, file_params)


# -- the search space --------------------------------------------------------------------

@pytest.mark.parametrize("text, match", [
    ("controller_node.alpha: {low: -1.0, high: 5.0}",
     r"controller_node.alpha: low = -1, outside controller_node.alpha's valid range \[0, inf\]"),
    ("controller_node.frame_gain: {low: 0.5, high: 2.0}",
     r"frame_gain: high = 2, outside controller_node.frame_gain's valid range \[0.001, 1\]"),
    ("scale.controller_node.K: {low: -1.0, high: 2.0}", r"a scale factor must be > 0"),
    ("controller_node.K: {low: 0.001, high: 0.01}",
     r"K is a float_list, a range sets a number; tune scale.controller_node.K"),
    ("controller_node.alpha: {low: 1.0, high: 20.0}\n"
     "controller_node.gamma: {low: 1.0, high: 90.0}",
     r"controller_node.gamma: high 90 needs alpha > 30 \(Theorem 1: alpha > gamma/3\)"),
    ("controller_node.gamma: {low: 1.0, high: 40.0}",
     r"breaks Theorem 1 with the file's alpha 10 \(needs gamma < 3 alpha = 30\)"),
    ("controller_node.alpha: {low: 1.0, high: 3.0}",
     r"high 3 is not above gamma/3 = 3.33333 with the file's gamma 10"),
    ("controller_node.no_such_gain: {low: 1.0, high: 2.0}", r"no_such_gain is not a parameter"),
    ("controller_node.model: {choices: [urdf, paper_rrr]}", r"defines the model's structure"),
    ("scale.controller_node.a_z_init: {low: 0.5, high: 2.0}", r"drawn by the randomized runs"),
    ("scale.controller_node.alpha: {low: 0.5, high: 2.0}", r"tune controller_node.alpha itself"),
    ("controller_node.alpha: {low: 5.0, high: 2.0}", r"needs numbers low < high"),
    ("controller_node.alpha: {low: 0.0, high: 2.0, log: true}", r"a log range needs low > 0"),
    ("controller_node.alpha: {low: 1.0, hi: 2.0}", r"unknown key 'hi'"),
    ("sim_node.pixel_noise_std: {low: 0.0, high: 1.0}", r"the controller's gains are tuned"),
    ("controller_node.latency_compensation: {choices: [true, 3]}",
     r"with 3 the configuration is refused: controller_node.latency_compensation: must be "
     r"true or false"),
    ("[1, 2]", r"must be a mapping of controller_node.NAME"),
])
def test_space_outside_the_parameters_rules_is_refused(tmp_path, paper, text, match):
    with pytest.raises(SpaceError, match=match):
        space_of(tmp_path, text, paper)


def test_space_scale_ends_are_checked_element_wise_against_the_spec(tmp_path, paper):
    # K's spec: >= 0; Gamma_z of the paper file is [0.2]*3 > 0, so any positive factor passes
    # the range, but max_dt's spec is [1e-5, 10]: 0.05 x 1000 = 50 is refused
    with pytest.raises(SpaceError, match=r"high x the file's value gives 50, outside "
                                         r"controller_node.max_dt's valid range \[1e-05, 10\]"):
        space_of(tmp_path, "scale.controller_node.max_dt: {low: 0.5, high: 1000.0}", paper)


def test_default_space_tunes_what_the_file_gives_and_the_design_of_what_it_leaves_out(paper):
    scenario, file_params = paper
    space = load_space(DEFAULT_SPACE, scenario, file_params, drop_shadowed=True)
    # the paper's file gives its gains: they are tuned (scaled), their design rates left out
    dropped = [key for key, _ in space.dropped]
    assert "controller_node.gain_design.kinematic_rate" in dropped
    assert "controller_node.gain_design.delay_bandwidth" in dropped
    assert space.dimensions[0].param == "gamma" and space.dimensions[1].param == "alpha"
    assert "scale.controller_node.Gamma_d" in [d.key for d in space.dimensions]
    # the iiwa's file gives no gain: the design rates are tuned, nothing is scaled
    iiwa = load_scenario(IIWA)
    iiwa_space = load_space(DEFAULT_SPACE, iiwa, read_param_file(IIWA)["controller_node"])
    keys = [d.key for d in iiwa_space.dimensions]
    assert "controller_node.gain_design.kinematic_rate" in keys
    assert not [key for key in keys if key.startswith("scale.")]
    assert "controller_node.gamma" not in keys


def test_a_dimension_the_file_makes_ineffective_is_refused_or_dropped(tmp_path, paper):
    text = ("controller_node.alpha: {low: 11.0, high: 20.0}\n"
            "controller_node.Gamma_d_normalized: {low: 1.0, high: 10.0}\n")
    with pytest.raises(SpaceError, match=r"Gamma_d_normalized: only sets the default of "
                                         r"Gamma_d, which the configuration gives explicitly"):
        space_of(tmp_path, text, paper)
    space = load_space(write(tmp_path, "s.yaml", text), *paper, drop_shadowed=True)
    assert [d.key for d in space.dimensions] == ["controller_node.alpha"]
    with pytest.raises(SpaceError, match=r"alpha.when_file_sets: must name a parameter of "
                                         r"controller_node, got 'nope'"):
        space_of(tmp_path, "controller_node.alpha: {low: 11.0, high: 20.0, when_file_sets: nope}",
                 paper)


def test_every_draw_keeps_theorem_1_and_its_ranges(tmp_path, paper):
    optuna = pytest.importorskip("optuna", reason="vas tune needs Optuna (pip install '.[tune]')")
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    space = space_of(tmp_path, """\
        controller_node.alpha: {low: 1.0, high: 30.0, log: true}
        controller_node.gamma: {low: 1.0, high: 60.0, log: true}
        scale.controller_node.K: {low: 0.1, high: 10.0, log: true}
        """, paper)
    study = optuna.create_study(sampler=optuna.samplers.TPESampler(seed=3, n_startup_trials=5))
    for _ in range(40):
        trial = study.ask()
        drawn = space.suggest(trial, paper[0].controller.params)
        alpha, gamma = drawn["set.controller_node.alpha"], drawn["set.controller_node.gamma"]
        assert alpha > gamma / 3 and 1.0 <= alpha <= 30.0 and 1.0 <= gamma <= 60.0
        assert 0.1 <= drawn["scale.controller_node.K"] <= 10.0
        study.tell(trial, abs(math.log(alpha / 7.0)))       # something for TPE to model


# -- the objective ---------------------------------------------------------------------

def _result(index, diverged=False, error=0.1, saturated=0, status="finished", attempts=1):
    run = Run(index, {}, PAPER, 1.0, "observer", ())
    figures = ({} if status != "finished" else
               {"diverged": diverged, "final_rms_true_error_px": error, "max_abs_torque": 50.0,
                "saturated": saturated})
    return RunResult(run, status, figures, "" if status == "finished" else "boom", attempts, 1.0)


def test_objective_ranks_divergence_then_the_torque_limit_then_the_error():
    rng = np.random.default_rng(5)

    def objective(errors, diverged=0, saturated=0):
        return score([_result(i, diverged=i < diverged, error=float(e),
                              saturated=int(diverged <= i < diverged + saturated))
                      for i, e in enumerate(errors)])["objective"]

    for _ in range(100):
        n = int(rng.integers(1, 501))
        errors = rng.uniform(0.0, 2000.0, n)        # beyond the cap, too
        trial = partial(objective, errors)

        one_diverged = trial(diverged=1)
        assert one_diverged > trial(saturated=n)          # every run at the torque limit
        assert trial(saturated=1) > trial()
        assert one_diverged > PRUNE_ABOVE >= trial(saturated=n)
    # a failed run counts as diverged; a run never started (its conditions cannot be
    # realised, the same for every gain set) does not count
    assert score([_result(0), _result(1, status="failed")])["diverged"] == 1
    assert score([_result(0, error=0.3), _result(1, status="failed", attempts=0)]) == \
        score([_result(0, error=0.3)]) | {"not_started": 1}


def test_objective_is_the_p90_of_the_true_error_without_divergence():
    errors = [0.05, 0.4, 0.2, 0.1, 0.3]
    figures = score([_result(i, error=e) for i, e in enumerate(errors)])
    np.testing.assert_allclose(figures["objective"], np.quantile(errors, 0.9), rtol=1e-15)
    assert figures["p50_true_rms_px"] == 0.2 and figures["max_true_rms_px"] == 0.4


# -- tuned.yaml ------------------------------------------------------------------------

def test_tuned_text_writes_values_in_place_and_keeps_the_file(tmp_path):
    text = textwrap.dedent("""\
        # my arm
        sim_node:
          ros__parameters:
            seed: 0
        controller_node:
          ros__parameters:
            alpha: 10.0    # observer
            Gamma_z: [0.2, 0.2,
                      0.2]
            K:
              - 0.001
              - 0.001
            joint_damping:
              diagonal: [0.0, 0.0, 0.0]
            safety.hold_time: 0.05
        # about the detector
        feature_detector:
          ros__parameters:
            tolerance: 40.0
        """)
    values = {"alpha": 7.5, "Gamma_z": [0.1, 0.1, 0.1], "K": [2e-06, 3e-21],
              "joint_damping.inertia_rate": 300.0, "safety.hold_time": 0.1, "frame_gain": 0.5}
    comments = {"alpha": "vas tune", "frame_gain": "vas tune, added"}
    new = tuned_text(text, values, comments, ["tuned", "figures here"])
    before = read_param_file(write(tmp_path, "before.yaml", text))
    after = read_param_file(write(tmp_path, "tuned.yaml", new))
    assert after["controller_node"] == {**before["controller_node"], **values}
    assert after["sim_node"] == before["sim_node"]
    assert after["feature_detector"] == before["feature_detector"]
    # 2e-06 is written so that YAML 1.1 (PyYAML, without the loader's coercion) reads a float
    assert yaml.safe_load(new)["controller_node"]["ros__parameters"]["K"] == [2e-06, 3e-21]
    assert new.startswith("# tuned\n# figures here\n# my arm\n")
    assert "alpha: 7.5  # vas tune    # observer" in new
    assert "frame_gain: 0.5  # vas tune, added" in new
    assert "# about the detector\nfeature_detector:" in new        # nothing added below it


def test_relative_file_names_are_repointed_to_the_tuning_folder(tmp_path, monkeypatch):
    # the SCARA example names its URDF relative to its own folder; tuned.yaml is written
    # into another folder and must load the same arm from there (a package:// name stays)
    arm = tmp_path / "my_arm"
    arm.mkdir()
    scara = os.path.join(ROOT, "docs", "examples", "scara")
    for name in ("scara.urdf", "scara.yaml"):
        (arm / name).write_text(open(os.path.join(scara, name), encoding="utf-8").read())
    out = tmp_path / "runs" / "tune"
    out.mkdir(parents=True)
    config = str(arm / "scara.yaml")
    text = (arm / "scara.yaml").read_text()
    new, moved = repointed_text(text, config, str(out))
    assert [m[0] for m in moved] == ["sim_node.urdf", "controller_node.urdf"]
    assert all(m[2] == os.path.join("..", "..", "my_arm", "scara.urdf") for m in moved)
    (out / "tuned.yaml").write_text(new)
    monkeypatch.chdir(tmp_path / "runs")      # neither folder is the current one
    before, after = load_scenario(config), load_scenario(str(out / "tuned.yaml"))
    for b, a in ((before.sim.params, after.sim.params),
                 (before.controller.params, after.controller.params)):
        assert a.keys() == b.keys()
        for name, value in b.items():
            if name != "urdf":
                np.testing.assert_array_equal(a[name], value, err_msg=name)
    # the same URDF file, read from the new name
    assert os.path.samefile(after.sim.arm.chain.urdf, before.sim.arm.chain.urdf)
    np.testing.assert_array_equal(after.sim.arm.chain.root_to_base,
                                  before.sim.arm.chain.root_to_base)
    assert repointed_text(open(PAPER, encoding="utf-8").read(), PAPER, str(out)) \
        == (open(PAPER, encoding="utf-8").read(), [])


def test_the_verdict_states_the_held_out_ratio_and_says_when_the_tuned_gains_are_not_better():
    from types import SimpleNamespace

    from visual_adaptive_servo.campaigns.tune_report import _verdict

    def figures(p90, diverged=0):
        return {"runs": 50, "diverged": diverged, "p90_true_rms_px": p90,
                "objective": score_of(p90, diverged)}

    def score_of(p90, diverged):
        return 1e9 * diverged / 50 + p90

    best = SimpleNamespace(number=35, value=0.54)
    better = _verdict({"tuned": figures(0.9558), "file": figures(1.01)}, best, {"alpha": 1.0})
    assert better.startswith("The tuned gains (trial 35) are better")
    assert "the tuned p90 is 0.95x the file's" in better
    worse = _verdict({"tuned": figures(1.2), "file": figures(1.01)}, best, {"alpha": 1.0})
    assert "are NOT better" in worse and "1.19x" in worse
    # lower, but within 5 %: not called better (the iiwa's 40 x 8 tuning: 1.176 against 1.178)
    tie = _verdict({"tuned": figures(1.176), "file": figures(1.178)}, best, {"alpha": 1.0})
    assert "are NOT clearly better" in tie and "1.00x" in tie and "within 5%" in tie
    # with a divergence the ratio of the others' errors says nothing: left out
    diverged = _verdict({"tuned": figures(0.5), "file": figures(0.4, 2)}, best, {"alpha": 1.0})
    assert "are better" in diverged and "x the file's" not in diverged


# -- a tuning end to end ---------------------------------------------------------------

def _settings(out, **kw):
    return TuneSettings(**{"config": PAPER, "out": str(out), "trials": 2, "runs_per_trial": 2,
                           "duration": 2.0, "workers": 2, "progress": False, "held_out": 2,
                           "seed": 4, **kw})


def test_two_trial_tuning_on_the_paper_arm_writes_valid_outputs_and_resumes(tmp_path, capsys):
    optuna = pytest.importorskip("optuna", reason="vas tune needs Optuna (pip install '.[tune]')")
    # the file's alpha, gamma and K are outside this space: every trial, the first (the
    # file's gains moved into the space) too, changes the gains
    space = write(tmp_path, "space.yaml", """\
        controller_node.gamma: {low: 4.0, high: 8.0}
        controller_node.alpha: {low: 6.0, high: 9.0}
        scale.controller_node.K: {low: 1.5, high: 3.0, log: true}
        """)
    out = tmp_path / "tune"
    camera = {"camera_rate": 100.0, "camera_latency": 0.01}
    report = run_tuning(_settings(out, space=space, **camera))
    for name in ("tuned.yaml", "report.md", "objective_over_trials.png", "gains_vs_objective.png",
                 STUDY_DB, "training_runs.yaml", "held_out_runs.yaml"):
        assert (out / name).stat().st_size > 0, name
    assert report["trials"] == 2 and report["best"] is not None
    best = report["best"]
    # tuned.yaml loads, validates, and is exactly the file with the best trial's gains
    tuned = load_scenario(str(out / "tuned.yaml"))
    alpha, gamma = best.params["controller_node.alpha"], best.params["controller_node.gamma"]
    k = [0.001 * best.params["scale.controller_node.K"]] * 2
    # ... and the camera tuned for: the controller told it, the simulator simulating it
    told = [f"{section}.{name}={value!r}" for section in ("sim_node", "controller_node")
            for name, value in camera.items()]
    oracle = load_scenario(PAPER, [f"controller_node.alpha={alpha!r}",
                                   f"controller_node.gamma={gamma!r}",
                                   f"controller_node.K=[{k[0]!r}, {k[1]!r}]"] + told)
    for got, want in ((tuned.controller.params, oracle.controller.params),
                      (tuned.sim.params, oracle.sim.params)):
        assert got.keys() == want.keys()
        for name, value in want.items():
            np.testing.assert_array_equal(got[name], value, err_msg=name)
    assert tuned.controller.params["camera_rate"] == tuned.sim.params["camera_rate"] == 100.0
    runs = load_spec(str(out / "training_runs.yaml"))
    for _, factors in runs.factor_sets():
        assert factors["set.controller_node.camera_latency"] == 0.01
    text = (out / "tuned.yaml").read_text()
    assert "# the paper's gains" in text and text.count("# vas tune") >= 3
    assert text.startswith("# vas tune: paper_3dof.yaml with the gains of trial")
    assert tuned.controller.params["alpha"] > tuned.controller.params["gamma"] / 3
    # the held-out runs draw other conditions than the tuning runs
    seeds = [{f["seed"] for _, f in load_spec(str(out / name)).factor_sets()}
             for name in ("training_runs.yaml", "held_out_runs.yaml")]
    assert not seeds[0] & seeds[1]
    assert "## Held-out runs: 2 runs with other seeds" in (out / "report.md").read_text()

    storage = f"sqlite:///{out / STUDY_DB}"
    first = optuna.load_study(study_name=STUDY_NAME, storage=storage).trials
    # a hard stop leaves a trial RUNNING: the next call fails it and runs its gains again
    stale = optuna.load_study(study_name=STUDY_NAME, storage=storage)
    stale.enqueue_trial({"controller_node.gamma": 5.0, "controller_node.alpha": 7.0,
                         "scale.controller_node.K": 2.0})
    scenario = load_scenario(PAPER)
    load_space(space, scenario, read_param_file(PAPER)["controller_node"]).suggest(
        stale.ask(), scenario.controller.params)
    report = run_tuning(_settings(out, space=space, trials=4, **camera))
    trials = optuna.load_study(study_name=STUDY_NAME, storage=storage).trials
    state = optuna.trial.TrialState
    assert [t.state for t in trials] == [state.COMPLETE] * 2 + [state.FAIL] + [state.COMPLETE] * 2
    for old, new in zip(first, trials):          # the same study, continued
        assert (old.params, old.value, old.user_attrs) == (new.params, new.value, new.user_attrs)
    assert trials[3].params == trials[2].params == {"controller_node.gamma": 5.0,
                                                    "controller_node.alpha": 7.0,
                                                    "scale.controller_node.K": 2.0}
    assert report["trials"] == 5
    # nothing left to do: a third call runs no trial and takes the held-out figures from
    # its cache, so it reports the same
    again = run_tuning(_settings(out, space=space, trials=4, **camera))
    assert len(optuna.load_study(study_name=STUDY_NAME, storage=storage).trials) == 5
    assert again["held_out"] == report["held_out"] and again["verdict"] == report["verdict"]
    # another setting is another tuning: refused, the study untouched
    with pytest.raises(CampaignError, match="holds a tuning of other settings"):
        run_tuning(_settings(out, space=space, runs_per_trial=3, **camera))


def test_a_trial_whose_first_runs_diverge_is_pruned(tmp_path):
    optuna = pytest.importorskip("optuna", reason="vas tune needs Optuna (pip install '.[tune]')")
    # the paper's gains under 1 px of noise diverge within about a second (DESIGN.md 4):
    # a one-point space at those gains (trial 0 = the file's) and 4 runs, 2 at a time
    space = write(tmp_path, "space.yaml", "scale.controller_node.K: {low: 0.999, high: 1.0}\n")
    out = tmp_path / "tune"
    run_tuning(_settings(out, space=space, trials=1, runs_per_trial=4, pixel_noise=1.0,
                         held_out=0))
    storage = f"sqlite:///{out / STUDY_DB}"
    trial = optuna.load_study(study_name=STUDY_NAME, storage=storage).trials[0]
    assert trial.intermediate_values[2] > PRUNE_ABOVE
    assert trial.state == optuna.trial.TrialState.PRUNED
    assert trial.user_attrs["runs"] == 2 and trial.user_attrs["diverged"] >= 1
    assert "No trial finished" in (out / "report.md").read_text()
    assert not (out / "tuned.yaml").exists()


# -- bad input: refused before any run -------------------------------------------------

@pytest.mark.parametrize("change, match", [
    ({"trials": 0}, r"--trials: must be an integer >= 1, got 0"),
    ({"runs_per_trial": 501}, r"--runs-per-trial: must be an integer in \[1, 500\], got 501"),
    ({"duration": 0.0}, r"--duration: must be a number > 0, got 0.0"),
    ({"pixel_noise": -0.5}, r"--pixel-noise: must be a number >= 0, got -0.5"),
    ({"held_out": -1}, r"--held-out: must be an integer >= 0"),
    ({"config": "/nonexistent/arm.yaml"}, r"--config /nonexistent/arm.yaml: no such file"),
    ({"space": "/nonexistent/space.yaml"}, r"--space /nonexistent/space.yaml: cannot read it"),
])
def test_bad_settings_are_refused_before_any_run(tmp_path, change, match):
    pytest.importorskip("optuna", reason="vas tune needs Optuna (pip install '.[tune]')")
    out = tmp_path / "tune"
    with pytest.raises((CampaignError, ConfigError), match=match):
        run_tuning(_settings(out, **change))
    assert not out.exists()


def test_a_file_that_does_not_load_and_a_bad_space_are_refused_before_any_run(tmp_path):
    pytest.importorskip("optuna", reason="vas tune needs Optuna (pip install '.[tune]')")
    out = tmp_path / "tune"
    broken = write(tmp_path, "broken.yaml", "sim_node: [unclosed\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        run_tuning(_settings(out, config=broken))
    with open(PAPER, encoding="utf-8") as handle:
        text = handle.read()
    bad_gain = write(tmp_path, "bad_gain.yaml", text.replace("gamma: 10.0", "gamma: 40.0"))
    with pytest.raises(ConfigError, match=r"alpha: Theorem 1 requires alpha > gamma/3"):
        run_tuning(_settings(out, config=bad_gain))
    space = write(tmp_path, "space.yaml", "controller_node.frame_gain: {low: 0.0, high: 1.0}\n")
    with pytest.raises(SpaceError, match=r"space.yaml: controller_node.frame_gain: low = 0, "
                                         r"outside controller_node.frame_gain's valid range"):
        run_tuning(_settings(out, space=space))
    assert not out.exists()


def test_without_optuna_the_error_says_how_to_install_it(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "optuna", None)        # `import optuna` raises ImportError
    with pytest.raises(CampaignError) as info:
        run_tuning(_settings(tmp_path / "tune"))
    assert str(info.value) == OPTUNA_MISSING and 'pip install ".[tune]"' in OPTUNA_MISSING
    assert not (tmp_path / "tune").exists()


def test_the_command_line_refuses_trials_0_and_vas_run_does_not_import_optuna(tmp_path):
    env = {**os.environ, "PYTHONPATH": ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")}
    probe = subprocess.run(
        [sys.executable, "-c", "import sys, visual_adaptive_servo.cli as c; "
         "c.build_parser().parse_args(['tune', '--config', 'x', '--out', 'y']); "
         "print('optuna' in sys.modules)"], capture_output=True, text=True, env=env, check=True)
    assert probe.stdout.strip() == "False"
    pytest.importorskip("optuna", reason="vas tune needs Optuna (pip install '.[tune]')")
    done = subprocess.run([sys.executable, "-m", "visual_adaptive_servo.cli", "tune", "--config",
                           PAPER, "--out", str(tmp_path / "t"), "--trials", "0"],
                          capture_output=True, text=True, env=env)
    assert done.returncode == 2
    assert "vas tune: --trials: must be an integer >= 1, got 0" in done.stderr
    assert not (tmp_path / "t").exists()
