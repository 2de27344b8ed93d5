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

"""The layering contracts of ``.importlinter`` hold, and would catch an upward import or a cycle.

``lint-imports`` is part of the README's test command; these tests run it too
(so ``colcon test`` checks the layers), and show on a copy of the package that
each contract fails when broken -- by an import inside a function as well, since
a lazy import that dodges a cycle is the cycle still.
"""

import os
import shutil
import subprocess
import sys

import pytest

pytest.importorskip("importlinter", reason="needs import-linter (pip install -e '.[test]')")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def lint_imports(cwd):
    """Run lint-imports on the packages under ``cwd``; (exit status, output)."""
    env = dict(os.environ, PYTHONPATH=cwd, COLUMNS="200")   # no wrapped lines
    code = ("import sys\nfrom importlinter.cli import lint_imports\n"
            "sys.exit(lint_imports(no_cache=True))\n")
    done = subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=300)
    return done.returncode, done.stdout + done.stderr


def test_contracts_hold_for_the_package():
    status, output = lint_imports(ROOT)
    assert status == 0, output
    assert "0 broken" in output


@pytest.fixture
def package_copy(tmp_path):
    """visual_adaptive_servo, sim_bridge and .importlinter copied into a folder of their own."""
    for name in ("visual_adaptive_servo", "sim_bridge"):
        shutil.copytree(os.path.join(ROOT, name), tmp_path / name,
                        ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(os.path.join(ROOT, ".importlinter"), tmp_path)
    return tmp_path


def plant(root, module, code):
    """Append a function holding ``code`` (an import) to ``module`` (a path under ``root``)."""
    path = root / module
    with open(path, "a", encoding="utf-8") as handle:
        handle.write(f"\n\ndef _planted():\n    {code}\n")


@pytest.mark.parametrize("module, code, contract, evidence", [
    # the runner reaching up into the comparison (as runner.summarize once did)
    ("visual_adaptive_servo/runner.py",
     "from .campaigns.compare import read_timeseries  # noqa", "Layers",
     "visual_adaptive_servo.runner -> visual_adaptive_servo.campaigns.compare"),
    # the models importing anything of the package but their own helpers
    ("visual_adaptive_servo/models/base.py",
     "from ..control.controller import Gains  # noqa", "Layers",
     "visual_adaptive_servo.models.base -> visual_adaptive_servo.control.controller"),
    # the simulator importing the ROS nodes
    ("sim_bridge/simulator.py",
     "from visual_adaptive_servo.ros import params  # noqa", "Layers",
     "sim_bridge.simulator -> visual_adaptive_servo.ros.params"),
    # two modules of one subpackage importing each other
    ("visual_adaptive_servo/campaigns/spec.py",
     "from .campaign import run_campaign  # noqa", "No import cycle",
     "No cycles are allowed in visual_adaptive_servo.campaigns"),
    # rclpy outside the nodes
    ("visual_adaptive_servo/control/controller.py", "import rclpy  # noqa", "ROS-free core",
     "visual_adaptive_servo.control.controller -> rclpy"),
])
def test_contract_breaks_on_a_planted_import(package_copy, module, code, contract, evidence):
    plant(package_copy, module, code)
    status, output = lint_imports(str(package_copy))
    assert status != 0, output
    broken = output[output.index("Broken contracts"):]
    assert contract in broken and evidence in broken, output
