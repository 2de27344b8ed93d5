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
    With ROS 2 sourced, ``<path>`` inside the package's share directory: the
    first prefix of ``AMENT_PREFIX_PATH`` whose ament resource index lists the
    package (``share/ament_index/resource_index/packages/<package>``), as
    ``ament_index_python.get_package_share_directory`` finds it; the index is
    read directly, so this needs no ROS Python package.  Without ROS, this
    package's own files are still found (:data:`OWN_SHARE`):
    ``package://visual_adaptive_servo/urdf/...`` is a checkout's ``sim_bridge/urdf/...``
    and ``package://visual_adaptive_servo/config/...`` its ``config/`` (the same files
    ``colcon build`` and ``pip install .`` install under those names, where an install
    finds them).
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
#: the folder that holds the visual_adaptive_servo and sim_bridge packages (a checkout, or
#: the site-packages of an install)
PACKAGE_PARENT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def own_share(parent=PACKAGE_PARENT, environ=None, prefixes=None):
    """Where this package's shared files (``urdf``, ``config``) live, by share subfolder.

    A checkout (or an editable install) has them beside the packages: ``sim_bridge/urdf``
    and ``config``.  An install (``colcon build``, ``pip install .``) has them where its
    ``data_files`` put them, ``<prefix>/share/visual_adaptive_servo/{urdf,config}``: the
    prefix whose ``lib/pythonX.Y/site-packages`` holds this package, else one of
    ``prefixes`` (default: ``sys.prefix`` and the user base of ``pip install --user``),
    else the package's share folder in the ament index of ``AMENT_PREFIX_PATH``.  When none
    has them, the checkout's places (for the error messages).
    """
    checkout = {"urdf": os.path.join(parent, "sim_bridge", "urdf"),
                "config": os.path.join(parent, "config")}
    if os.path.isdir(checkout["config"]):
        return checkout
    if prefixes is None:
        import site
        import sys

        prefixes = [sys.prefix, site.getuserbase()]
    # <prefix>/lib/pythonX.Y/site-packages -> <prefix>
    shares = [os.path.join(p, "share", PACKAGE)
              for p in [os.path.dirname(os.path.dirname(os.path.dirname(parent))), *prefixes]]
    environ = os.environ if environ is None else environ
    ament = _ament_share(PACKAGE, environ.get("AMENT_PREFIX_PATH", ""))
    if ament is not None:
        shares.append(ament)
    for share in shares:
        if os.path.isdir(os.path.join(share, "config")):
            return {"urdf": os.path.join(share, "urdf"), "config": os.path.join(share, "config")}
    return checkout


def _ament_share(package, prefix_path):
    for prefix in prefix_path.split(os.pathsep):
        marker = os.path.join(prefix, "share", "ament_index", "resource_index", "packages",
                              package)
        if prefix and os.path.isfile(marker):
            return os.path.join(prefix, "share", package)
    return None


#: where this package's shared files live here, by share subfolder (:func:`own_share`)
OWN_SHARE = own_share()


def resolve_path(name, search_dirs=(), what="file"):
    """Absolute path of ``name`` (see the module docstring) or FileNotFoundError naming it.

    The error says where it looked and, for ``package://``, which package was
    needed and what would make it resolve.
    """
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
    if name.startswith("package://") and not candidates:
        raise FileNotFoundError(f"{what}: {name!r} not found: {package_hint(package)}")
    raise FileNotFoundError(f"{what}: {name!r} not found (looked at {candidates})")


def ament_share_directory(package):
    """The share folder of ``package`` in the ament index of ``AMENT_PREFIX_PATH``, or None."""
    return _ament_share(package, os.environ.get("AMENT_PREFIX_PATH", ""))


def package_hint(package):
    """Why ``package://<package>/...`` does not resolve here, and what would resolve it."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    where = (f"no prefix of AMENT_PREFIX_PATH ({os.pathsep.join(prefixes)}) has it in its "
             f"ament index (share/ament_index/resource_index/packages/{package})" if prefixes
             else "AMENT_PREFIX_PATH is not set (no ROS 2 workspace sourced)")
    own = (f"; without ROS only package://{PACKAGE}/urdf/... and package://{PACKAGE}/config/... "
           f"resolve (to {OWN_SHARE['urdf']} and {OWN_SHARE['config']})")
    return (f"package {package!r} is needed and {where}{own}. To resolve it, source the "
            f"ROS 2 workspace that installs {package!r} (its setup script sets "
            f"AMENT_PREFIX_PATH), or give the file's path instead: absolute, or relative "
            f"(to the current folder or, with vas, to the parameter file's folder)")


def _package_candidates(package, rest):
    candidates = []
    share = ament_share_directory(package)
    if share is not None:
        candidates.append(os.path.join(share, rest))
    if package == PACKAGE:
        folder, _, inner = rest.partition("/")
        if folder in OWN_SHARE:
            candidates.append(os.path.join(OWN_SHARE[folder], inner))
    return candidates
