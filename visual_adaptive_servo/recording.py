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

"""Recording a run: a rosbag2 MCAP file with the nodes' topics, a CSV and summary.json.

The MCAP file holds the same topics and message types the ROS nodes publish
(DESIGN.md section 2), built with the same conversion functions, so
``ros2 bag info/play``, Foxglove and PlotJuggler open it.
"""

from __future__ import annotations

import csv
import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from . import messages as m

SIM_NS = "/sim_node"
CONTROLLER_NS = "/controller_node"

TOPICS = {
    "/clock": "Clock",
    "/joint_states": "JointState",
    "/camera/features": "PolygonStamped",
    "/effort_controller/commands": "Float64MultiArray",
    f"{SIM_NS}/true_depth": "Float64MultiArray",
    f"{CONTROLLER_NS}/desired": "PolygonStamped",
    f"{CONTROLLER_NS}/observed": "PolygonStamped",
    f"{CONTROLLER_NS}/tracking_error": "PolygonStamped",
    f"{CONTROLLER_NS}/estimated_depth": "Float64MultiArray",
    f"{CONTROLLER_NS}/parameters": "Float64MultiArray",
    "/diagnostics": "DiagnosticArray",
}


class McapRecorder:
    """Stream messages into ``path`` (a single MCAP file), closed even on errors.

    rosbags writes a bag directory (metadata.yaml + one .mcap); the .mcap is
    self-describing, so on close it is moved to ``path`` and the directory
    removed.  Use as a context manager.
    """

    def __init__(self, path):
        from rosbags.rosbag2 import StoragePlugin, Writer

        self.path = Path(path)
        self.msgs = m.rosbags_messages()
        self._tmp = Path(tempfile.mkdtemp(prefix="vas-bag-", dir=self.path.parent))
        self._bagdir = self._tmp / self.path.stem
        self.writer = Writer(self._bagdir, version=9, storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        self.connections = {}
        for topic, short in TOPICS.items():
            msgtype = m.MESSAGE_TYPES[short]
            self.connections[topic] = (self.writer.add_connection(
                topic, msgtype, typestore=self.msgs.typestore), msgtype)

    def write(self, topic, t, msg):
        conn, msgtype = self.connections[topic]
        self.writer.write(conn, int(round(t * 1e9)),
                          self.msgs.typestore.serialize_cdr(msg, msgtype))

    def close(self):
        if self.writer is None:
            return
        try:
            self.writer.close()
            produced = self._bagdir / f"{self._bagdir.name}.mcap"
            os.replace(produced, self.path)
        finally:
            self.writer = None
            shutil.rmtree(self._tmp, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def write_csv(path, columns, rows):
    """Write rows (sequences of numbers) under ``columns``."""
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(columns)
        for row in rows:
            writer.writerow([f"{v:.10g}" if isinstance(v, float) else v for v in row])


def write_json(path, data):
    def default(obj):
        if isinstance(obj, np.generic):
            return obj.item()
        if isinstance(obj, np.ndarray):
            return obj.tolist()
        raise TypeError(type(obj))

    with open(path, "w", encoding="utf-8") as handle:
        json.dump(data, handle, indent=2, default=default, allow_nan=True)
        handle.write("\n")
