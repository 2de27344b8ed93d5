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

"""Resolving the file names in parameter files (URDFs, taught trajectories).

Three forms are accepted:

``package://<package>/<path>``
    With ROS 2 sourced, ``<path>`` inside the package's share directory
    (``ament_index_python``).  Without ROS, this package's own files are still
    found: ``package://visual_adaptive_servo/urdf/...`` is ``sim_bridge/urdf/...``
    and ``package://visual_adaptive_servo/config/...`` is the checkout's ``config/``
    (the same files ``colcon build`` installs under those names).
``pybullet_data://<path>``
    ``<path>`` inside PyBullet's data folder (``pybullet_data.getDataPath()``),
    e.g. ``pybullet_data://kuka_iiwa/model.urdf``.
anything else
    a file path; a relative one is looked up relative to the current folder,
    then relative to each folder in ``search_dirs`` (``vas run`` passes the
    folder of the parameter file).
"""

from __future__ import annotations

import os

PACKAGE = "visual_adaptive_servo"
#: the folder that holds the visual_adaptive_servo and sim_bridge packages (a checkout)
PACKAGE_PARENT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
#: where this package's shared files live in a checkout / pip install, by share subfolder
OWN_SHARE = {"urdf": os.path.join(PACKAGE_PARENT, "sim_bridge", "urdf"),
             "config": os.path.join(PACKAGE_PARENT, "config")}


def resolve_path(name, search_dirs=(), what="file"):
    """Absolute path of ``name`` (see the module docstring) or FileNotFoundError naming it."""
    if not isinstance(name, str) or not name:
        raise FileNotFoundError(f"{what}: no file name given")
    if name.startswith("package://"):
        package, _, rest = name[len("package://"):].partition("/")
        candidates = _package_candidates(package, rest)
    elif name.startswith("pybullet_data://"):
        import pybullet_data

        candidates = [os.path.join(pybullet_data.getDataPath(), name[len("pybullet_data://"):])]
    elif os.path.isabs(name):
        candidates = [name]
    else:
        candidates = [os.path.abspath(name)] + [os.path.join(d, name) for d in search_dirs]
    for path in candidates:
        if os.path.isfile(path):
            return os.path.abspath(path)
    raise FileNotFoundError(f"{what}: {name!r} not found (looked at {candidates})")


def _package_candidates(package, rest):
    candidates = []
    try:
        from ament_index_python.packages import (
            PackageNotFoundError,
            get_package_share_directory,
        )
    except ImportError:
        pass
    else:
        try:
            candidates.append(os.path.join(get_package_share_directory(package), rest))
        except (PackageNotFoundError, OSError, ValueError):
            # not installed there, or no ament prefix path set (ROS importable, not sourced)
            pass
    if package == PACKAGE:
        folder, _, inner = rest.partition("/")
        if folder in OWN_SHARE:
            candidates.append(os.path.join(OWN_SHARE[folder], inner))
    return candidates
