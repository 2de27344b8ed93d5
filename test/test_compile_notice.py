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


"""The notice that the kernels are compiling (a first start's half minute does not look hung)."""

import logging
import os
import subprocess
import sys
import time

import pytest

from conftest import ROOT
from visual_adaptive_servo.models.backend import compile_notice, NOTICE_LOGGER


@pytest.fixture
def notice_records():
    """The notice logger's records, filled as it logs.

    A handler on the logger, not pytest's caplog: with ROS sourced, launch_testing's plugin
    makes new loggers not propagate, so caplog sees nothing under ``colcon test``
    (conftest.logged_warnings, at INFO).
    """
    records = []
    handler = logging.Handler(logging.INFO)
    handler.emit = records.append
    logger = logging.getLogger(NOTICE_LOGGER)
    level = logger.level
    logger.setLevel(logging.INFO)
    logger.addHandler(handler)
    try:
        yield records
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)


def notices(records):
    return [r.getMessage() for r in list(records)]


def test_a_long_block_is_announced_while_it_runs_and_timed_at_its_end(notice_records):
    seen_inside = []
    with compile_notice("test kernels", after=0.05):
        deadline = time.monotonic() + 10.0
        while not notices(notice_records) and time.monotonic() < deadline:
            time.sleep(0.01)
        seen_inside.extend(notices(notice_records))
    # the notice came while the block still ran, from the timer, not at its end
    assert len(seen_inside) == 1 and "compiling the test kernels with numba" in seen_inside[0]
    lines = notices(notice_records)
    assert len(lines) == 2 and lines[1].startswith("test kernels compiled in ")


def test_a_short_block_and_a_block_within_another_say_nothing_of_their_own(notice_records):
    with compile_notice("quick kernels", after=30.0):
        pass
    assert notices(notice_records) == []
    with compile_notice("outer kernels", after=0.05):
        with compile_notice("inner kernels", after=0.0):
            deadline = time.monotonic() + 10.0
            while not notices(notice_records) and time.monotonic() < deadline:
                time.sleep(0.01)
    lines = notices(notice_records)
    assert len(lines) == 2 and all("outer kernels" in line for line in lines), lines
    with pytest.raises(RuntimeError):            # a failing block counts its depth down too
        with compile_notice("failing kernels", after=30.0):
            raise RuntimeError("boom")
    with compile_notice("later kernels", after=0.05):
        deadline = time.monotonic() + 10.0
        while len(notices(notice_records)) < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
    assert "later kernels" in notices(notice_records)[2]


def test_vas_run_says_it_compiles_on_a_first_start_and_not_on_the_next(tmp_path):
    # a cache of its own (XDG_CACHE_HOME, models/kernels.py): the first run compiles every
    # kernel (tens of seconds), the second loads them
    pytest.importorskip("numba", reason="the compiled backend needs numba")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(XDG_CACHE_HOME=str(tmp_path / "cache"),
               PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))

    def run(out):
        done = subprocess.run(
            [sys.executable, "-m", "visual_adaptive_servo.cli", "run", "--config",
             os.path.join(ROOT, "config", "paper_3dof.yaml"), "--duration", "0.01",
             "--out", str(tmp_path / out), "--no-bag"],
            env=env, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr
        return done.stderr

    first = run("first")
    assert "INFO visual_adaptive_servo.compile: compiling the " in first, first
    assert "first start after an install" in first
    assert " compiled in " in first
    assert "compiling" not in run("second")
