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

"""The compiled kinematic tensors against their numpy reference.

Oracle: the numpy implementation (``KinematicRegressor.tensors_numpy``,
``PaperRRRCamera.kinematic_tensors_numpy``), itself checked against PyBullet
and finite differences in test_urdf_kinematics.py and test_model.py.  Both
are compared at random states and at every sample of short closed-loop runs
of each shipped arm; "1e-12 relative" is relative to each tensor's largest
entry (entries that are zero in exact arithmetic come out as +-1e-17 in one
implementation and 0 in the other).
"""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT
from test_urdf_kinematics import SYNTHETIC
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.control.controller import AdaptiveVisualTracker
from visual_adaptive_servo.models import make_model, PaperRRRCamera
from visual_adaptive_servo.models.kinematic_regressor import KinematicRegressor
from visual_adaptive_servo.models.urdf_chain import load_chain
from visual_adaptive_servo.runner import run_scenario

pytest.importorskip("numba", reason="the compiled backend needs numba")

CONFIGS = ["paper_3dof.yaml", "paper_3dof_urdf.yaml", "iiwa_3points.yaml", "panda_2points.yaml"]
#: simulated seconds of the closed-loop checks (200, 200, 200, 100 control periods)
DURATIONS = {"paper_3dof.yaml": 1.0, "paper_3dof_urdf.yaml": 1.0, "iiwa_3points.yaml": 0.2,
             "panda_2points.yaml": 0.5}
NAMES = ("H", "dH", "dH_rate", "W", "W_rate")


def assert_tensors_equal(compiled, reference, where):
    for name, a, b in zip(NAMES, compiled, reference):
        assert a.shape == b.shape, f"{where}: {name} shape {a.shape} != {b.shape}"
        scale = np.max(np.abs(b)) if b.size else 0.0
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * scale,
                                   err_msg=f"{where}: {name}")


def reference_of(model):
    """The numpy implementation of ``model.kinematic_tensors``."""
    if isinstance(model, PaperRRRCamera):
        return model.kinematic_tensors_numpy
    return model.kinematics.tensors_numpy


@pytest.fixture(scope="module", params=CONFIGS)
def shipped(request):
    return request.param, load_scenario(os.path.join(ROOT, "config", request.param))


def test_shipped_models_run_the_compiled_backend_by_default(shipped):
    _, scenario = shipped
    assert scenario.controller.model.backend == "compiled"


def test_compiled_tensors_equal_numpy_at_random_states(shipped, rng):
    name, scenario = shipped
    model = scenario.controller.model
    reference = reference_of(model)
    for k in range(300):
        q = rng.uniform(-np.pi, np.pi, model.n)
        qd = rng.normal(scale=2.0, size=model.n)
        assert_tensors_equal(model.kinematic_tensors(q, qd), reference(q, qd), f"{name} #{k}")


@pytest.fixture(scope="module")
def synthetic_urdf(tmp_path_factory):
    path = tmp_path_factory.mktemp("urdf") / "synthetic.urdf"
    path.write_text(SYNTHETIC)
    return str(path)


@pytest.mark.parametrize("unknown", ["all", ["j2.x", "j2.z", "slide.y", "point1.x", "point2.z"]],
                         ids=["all_unknown", "known_lengths"])
def test_compiled_tensors_equal_numpy_with_prismatic_joint_and_known_lengths(
        synthetic_urdf, unknown, rng):
    # the synthetic chain has fixed joints and a prismatic joint, whose q_k u_k is part of
    # the known part w0 of the points (the kernel's second branch); known lengths add to it
    chain = load_chain(synthetic_urdf, "base", "tool")
    offsets = [[0.02, 0.01, 0.03], [-0.03, 0.02, 0.0], [0.0, -0.04, 0.01]]
    compiled = KinematicRegressor(chain, offsets, unknown, backend="compiled")
    numpy_ = KinematicRegressor(chain, offsets, unknown, backend="numpy")
    assert compiled.has_w0
    for k in range(200):
        q = rng.uniform(-np.pi, np.pi, chain.n)
        qd = rng.normal(scale=2.0, size=chain.n)
        assert_tensors_equal(compiled.tensors(q, qd), numpy_.tensors(q, qd), f"#{k}")


def test_compiled_tensors_equal_numpy_at_every_sample_of_a_closed_loop_run(
        shipped, tmp_path, monkeypatch):
    # the joint states of every sample of a closed loop (the tracker's compiled sample
    # evaluates the same kernel inside it, test_compiled_law.py)
    name, scenario = shipped
    model = scenario.controller.model
    states = []
    step = AdaptiveVisualTracker.step

    def recorded(self, t, q, qd, x=None, x_stamp=None):
        states.append((np.array(q, dtype=float), np.array(qd, dtype=float)))
        return step(self, t, q, qd, x, x_stamp)

    monkeypatch.setattr(AdaptiveVisualTracker, "step", recorded)
    summary = run_scenario(scenario, str(tmp_path), DURATIONS[name], progress=False,
                           record=False, plots=False)
    assert not summary["diverged"] and summary["steps"] == round(
        DURATIONS[name] / scenario.sim.control_period)
    assert len(states) == summary["steps"]
    reference = reference_of(model)
    for k, (q, qd) in enumerate(states):
        assert_tensors_equal(model.kinematic_tensors(q, qd), reference(q, qd),
                             f"{name} sample {k}")


def test_closed_loop_figures_are_the_same_with_either_backend(shipped, tmp_path):
    name, _ = shipped
    path = os.path.join(ROOT, "config", name)
    runs = {}
    for backend in ("compiled", "numpy"):
        scenario = load_scenario(path)
        scenario.controller.model.set_backend(backend)
        assert scenario.controller.model.backend == backend
        out = tmp_path / backend
        run_scenario(scenario, str(out), DURATIONS[name], progress=False, record=False,
                     plots=False)
        summary = json.loads((out / "summary.json").read_text())
        table = np.genfromtxt(out / "timeseries.csv", delimiter=",", skip_header=1)[:, :-1]
        runs[backend] = summary, table
    (s_c, t_c), (s_n, t_n) = runs["compiled"], runs["numpy"]
    for key, value in s_n.items():
        if isinstance(value, float) and not key.startswith("wall") and key != "realtime_factor":
            np.testing.assert_allclose(s_c[key], value, rtol=1e-9, err_msg=key)
    np.testing.assert_allclose(t_c, t_n, rtol=1e-9, atol=1e-9 * np.nanmax(np.abs(t_n)))


def test_unknown_backend_is_refused_naming_the_parameter():
    with pytest.raises(ValueError, match=r"controller_node\.backend: one of \['compiled', "
                                         r"'numpy'\], got 'fast'"):
        make_model("paper_rrr", backend="fast")
    with pytest.raises(ValueError, match=r"controller_node\.backend: one of"):
        make_model("urdf", {"urdf": os.path.join(ROOT, "sim_bridge", "urdf", "paper_rrr.urdf"),
                            "base_link": "base_link", "tip_link": "tip",
                            "feature_points": [0.0, 0.0, 0.0]}, backend="Numba")


def test_shape_errors_are_refused_before_the_kernel_reads_memory():
    model = PaperRRRCamera(backend="compiled")
    with pytest.raises(ValueError, match=r"q and q_dot need shape \(3,\)"):
        model.kinematic_tensors(np.zeros(2), np.zeros(3))


def run_python(code, **env):
    """Run ``code`` in a fresh interpreter on this tree, without a NUMBA_CACHE_DIR of ours."""
    base = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    base["PYTHONPATH"] = ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")
    return subprocess.run([sys.executable, "-c", code], env=dict(base, **env),
                          capture_output=True, text=True, timeout=300)


def test_without_numba_the_default_is_numpy_and_compiled_is_refused():
    # a real missing numba: the import fails (sys.modules entry None), in a fresh process
    code = (
        "import sys, logging\n"
        "sys.modules['numba'] = None\n"
        "logging.basicConfig(level=logging.INFO, format='%(levelname)s %(message)s')\n"
        "from visual_adaptive_servo.models import make_model\n"
        "print('default', make_model('paper_rrr').backend)\n"
        "try:\n"
        "    make_model('paper_rrr', backend='compiled')\n"
        "except ValueError as exc:\n"
        "    print('refused', exc)\n")
    done = run_python(code)
    assert done.returncode == 0, done.stderr
    assert "default numpy" in done.stdout
    assert "refused controller_node.backend: compiled needs numba" in done.stdout
    assert done.stderr.count("kinematic tensors: numpy backend") == 1, done.stderr


def test_kernels_are_cached_in_the_user_cache_dir_and_loaded_from_it(tmp_path):
    # no NUMBA_CACHE_DIR: the kernels go to $XDG_CACHE_HOME/visual_adaptive_servo/numba
    # (writable also for a read-only install); a second process loads them from there
    code = ("from visual_adaptive_servo.models import PaperRRRCamera, kernels\n"
            "PaperRRRCamera(backend='compiled')\n"
            "print(kernels.cache_dir())\n"
            "print(sum(kernels.paper_tensors.stats.cache_hits.values()))\n")
    first = run_python(code, XDG_CACHE_HOME=str(tmp_path))
    assert first.returncode == 0, first.stderr
    where, hits = first.stdout.split()
    assert os.path.dirname(where) == str(tmp_path / "visual_adaptive_servo" / "numba")
    assert hits == "0"
    assert any(f.endswith(".nbi") for _, _, files in os.walk(where) for f in files)
    second = run_python(code, XDG_CACHE_HOME=str(tmp_path))
    assert second.returncode == 0, second.stderr
    assert second.stdout.split()[1] == "1"


def test_the_cache_folder_changes_with_any_source_of_the_package(tmp_path):
    # numba checks a cached kernel against its own file only: the whole sample
    # (sample_kernels.py) compiles the law (law_kernels.py) in, so an edit of the law alone
    # must move the cache, or the cached sample would run the old law
    import shutil

    tree = tmp_path / "tree"
    shutil.copytree(os.path.join(ROOT, "visual_adaptive_servo"),
                    tree / "visual_adaptive_servo",
                    ignore=shutil.ignore_patterns("__pycache__"))
    code = ("from visual_adaptive_servo.models import kernels\n"
            "print(kernels.cache_dir())\n")

    def where():
        done = subprocess.run([sys.executable, "-c", code], cwd=tree, capture_output=True,
                              text=True, timeout=120,
                              env=dict(os.environ, PYTHONPATH=str(tree),
                                       NUMBA_CACHE_DIR=str(tmp_path / "cache")))
        assert done.returncode == 0, done.stderr
        return done.stdout.strip()

    first = where()
    assert os.path.dirname(first) == str(tmp_path / "cache")
    assert where() == first                     # the same sources: the same folder
    law = tree / "visual_adaptive_servo" / "control" / "law_kernels.py"
    law.write_text(law.read_text().replace("alpha, gamma, kappa = scalars[0]",
                                           "alpha, gamma, kappa = 1.0 * scalars[0]", 1))
    assert where() != first
