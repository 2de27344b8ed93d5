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

"""ament_pep257 with the ament convention, adapted to the project's numpydoc docstrings.

The same ignores as ruff.toml (which runs these checks where ROS is absent): the
summary stands on the first line (D212 style, so D213 is off), summaries may be
noun phrases (D401), state a formula (D402) or start with a type name (D403), and
numpydoc sections are not pydocstyle's Google sections (D413, D417).
"""

from pathlib import Path

import pytest

main = pytest.importorskip("ament_pep257.main", reason="ament_pep257 (ROS 2) not installed").main

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    rc = main(argv=[str(ROOT), "--add-ignore", "D213", "D401", "D402", "D403", "D413", "D417"])
    assert rc == 0, "Found code style errors / warnings"
