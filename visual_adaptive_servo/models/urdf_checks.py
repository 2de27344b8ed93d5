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

"""What PyBullet and Pinocchio would read wrongly, or not at all, in a URDF: checked first.

Where a URDF is incomplete or unphysical the two libraries read it differently,
and the simulated arm is silently not the controller's model:

* a link without ``<inertial>``: PyBullet simulates it as 1 kg with inertia
  diag(1, 1, 1) kg m^2 (Bullet's ``UrdfParser::parseLink``), Pinocchio as
  massless (the URDF convention);
* an inertia tensor whose principal moments are negative or break the triangle
  inequality (each at most the sum of the other two): PyBullet prints "Bad
  inertia tensor properties, setting inertia to zero" and simulates zero
  inertia (``BulletURDFImporter::getMassAndInertia``), Pinocchio keeps it;
* a negative mass (both take it as given) or a controlled joint below which
  nothing has mass or inertia (PyBullet leaves it still whatever the torque;
  the mass matrix is singular).

Only links that a controlled joint moves are checked: the fixed root link
(``world``, ``base_link``) and links bolted to it never move, so their inertia
does not matter (PyBullet zeroes the root's with a fixed base, Pinocchio folds
them into the universe).  Links below the chain's tip (a hand, fingers) move
with it and are checked.

A mesh PyBullet cannot find fails the whole file ("Cannot load URDF file.")
whichever link carries it, so every mesh of the file is looked for where
Bullet's ``UrdfFindMeshFile`` looks (:func:`bullet_mesh_candidates`).
Pinocchio's model reads no mesh, so the controller's model skips that check.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET

import numpy as np

from .resources import resolve_path

MOVABLE = ("revolute", "continuous", "prismatic")
INERTIA_NAMES = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
#: mesh types PyBullet reads (by the file name's last four characters, any case)
BULLET_MESH_TYPES = (".obj", ".stl", ".dae", ".cdf", ".vtk")
#: relative tolerance of the triangle inequality on computed (non-diagonal) moments
MOMENT_TOLERANCE = 1e-9
MISSING_INERTIAL = ("PyBullet simulates a link without <inertial> as 1 kg with inertia "
                    "diag(1, 1, 1) kg m^2, Pinocchio (the controller's model) as massless")


class UrdfError(ValueError):
    """A URDF the simulator or the controller's model would misread (names file, link, rule).

    A ``ValueError`` so that the configuration turns it into a ``ConfigError``
    (:func:`visual_adaptive_servo.schema.resolve_params`); :mod:`.models` sits
    beside :mod:`visual_adaptive_servo.schema` and does not import it.
    """


def check_urdf(urdf_path, joint_names=None, section="sim_node", simulator=True):
    """Refuse a URDF that PyBullet (``simulator``) or Pinocchio would read wrongly.

    Parameters
    ----------
    urdf_path : str
        The resolved file.
    joint_names : sequence of str, optional
        The controlled joints (default: every revolute, continuous and prismatic
        joint); the links they move are checked.
    section : str
        Configuration section named in the messages (``section.urdf: ...``).
    simulator : bool
        Checks for PyBullet: also every mesh, and a link without ``<inertial>``
        is refused even when it is a bare frame (PyBullet gives it 1 kg).  For
        the controller's model alone (Pinocchio, a real arm) a bare frame --
        no ``<inertial>``, no visual, no collision, like ``tool0`` -- is
        massless, as the URDF convention means it.

    Raises
    ------
    UrdfError
        Naming ``section.urdf``, the file, the link and the rule broken.
    """
    where = f"{section}.urdf"
    try:
        root = ET.parse(urdf_path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise UrdfError(f"{where}: cannot read {urdf_path}: {exc}") from None
    links = {link.get("name"): link for link in root.findall("link")}
    children = {}
    for joint in root.findall("joint"):
        parent, child = joint.find("parent"), joint.find("child")
        if parent is not None and child is not None:
            children.setdefault(parent.get("link"), []).append((joint, child.get("link")))
    if joint_names is None:
        controlled = {j.get("name") for j in root.findall("joint") if j.get("type") in MOVABLE}
    else:
        controlled = set(joint_names)
    movers = _moving_links(links, children, controlled)
    inertials = {}
    for name, link in links.items():
        if name in movers:
            inertials[name] = _inertial(link, movers[name], urdf_path, where, simulator)
    for joint_name in _in_file_order(root, controlled):
        below = [name for name in _subtree(children, _child_of(root, joint_name))
                 if name in inertials]
        if below and all(inertials[name] is None or (inertials[name][0] == 0.0
                                                     and not inertials[name][1].any())
                         for name in below):
            raise UrdfError(f"{where}: joint {joint_name!r} in {urdf_path} moves no mass: "
                            f"every link below it ({', '.join(below)}) has zero mass and zero "
                            f"inertia, so PyBullet leaves the joint still whatever the torque "
                            f"and the mass matrix M(q) is singular; give the link(s) their "
                            f"mass and inertia")
    if simulator:
        for name, link in links.items():
            _check_meshes(link, name, urdf_path, where)


def bullet_mesh_candidates(urdf_path, filename):
    """The files PyBullet tries for a mesh ``filename``, in its order, and the name it seeks.

    Bullet's ``UrdfFindMeshFile`` drops a leading ``file://``, then
    ``package://`` or ``model://``, and tries the rest as given (absolute, or
    relative to the current folder), then relative to the URDF's folder and
    each folder above it, then ``./``, ``../`` and ``../../``: it reads no
    ament index and no ``ROS_PACKAGE_PATH``.  Returns ``(name, candidates)``.
    """
    name = filename
    if name.startswith("file://"):
        name = name[len("file://"):]
    if name.startswith("package://"):
        name = name[len("package://"):]
    elif name.startswith("model://"):
        name = name[len("model://"):]
    folders = [urdf_path[:i] + "/" for i in reversed(range(len(urdf_path)))
               if urdf_path[i] in "/\\"]
    return name, [prefix + name for prefix in [""] + folders + ["./", "../", "../../"]]


def _moving_links(links, children, controlled):
    """{link: the controlled joint nearest above it} for every link a controlled joint moves."""
    child_links = {child for pairs in children.values() for _, child in pairs}
    stack = [(name, None) for name in links if name not in child_links]
    movers, seen = {}, set()
    while stack:
        link, mover = stack.pop()
        if link in seen:
            continue
        seen.add(link)
        if mover is not None:
            movers[link] = mover
        for joint, child in children.get(link, ()):
            stack.append((child, joint.get("name") if joint.get("name") in controlled else mover))
    return movers


def _in_file_order(root, controlled):
    return [j.get("name") for j in root.findall("joint") if j.get("name") in controlled]


def _child_of(root, joint_name):
    joint = next(j for j in root.findall("joint") if j.get("name") == joint_name)
    child = joint.find("child")
    return None if child is None else child.get("link")


def _subtree(children, link):
    found, stack = [], [link]
    while stack:
        name = stack.pop()
        if name is None or name in found:
            continue
        found.append(name)
        stack.extend(child for _, child in children.get(name, ()))
    return found


def _inertial(link, mover, urdf_path, where, simulator):
    """(mass, tensor (3, 3)) of a moving link after the checks; None for a massless frame."""
    name = link.get("name")
    what = f"{where}: link {name!r} in {urdf_path} (moved by joint {mover!r})"
    inertial = link.find("inertial")
    if inertial is None:
        shaped = link.find("visual") is not None or link.find("collision") is not None
        if not simulator and not shaped:
            return None
        fix = ('; give the link an <inertial> with its mass and inertia (<mass value="0"/> '
               "and a zero <inertia> for a massless frame)")
        if simulator:
            raise UrdfError(f"{what} has no <inertial>: {MISSING_INERTIAL}, so the simulated "
                            f"arm would not be the modelled one{fix}")
        raise UrdfError(f"{what} has no <inertial> but a visual or collision shape: "
                        f"{MISSING_INERTIAL}, so the controller would model it as massless"
                        f"{fix}")
    mass_element, inertia_element = inertial.find("mass"), inertial.find("inertia")
    if mass_element is None or mass_element.get("value") is None:
        raise UrdfError(f'{what}: its <inertial> needs <mass value="..."/>')
    missing = [] if inertia_element is None else [
        k for k in INERTIA_NAMES if inertia_element.get(k) is None]
    if inertia_element is None or missing:
        raise UrdfError(f"{what}: its <inertial> needs <inertia> with all of "
                        f"{', '.join(INERTIA_NAMES)} (the URDF format; missing: "
                        f"{', '.join(missing) or 'the element'})")
    try:
        mass = float(mass_element.get("value"))
        ixx, ixy, ixz, iyy, iyz, izz = (float(inertia_element.get(k)) for k in INERTIA_NAMES)
    except ValueError as exc:
        raise UrdfError(f"{what}: <mass> and <inertia> must be numbers ({exc})") from None
    tensor = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    if not (np.isfinite(mass) and np.isfinite(tensor).all()):
        raise UrdfError(f"{what}: <mass> and <inertia> must be finite, got mass {mass} and "
                        f"inertia {tensor.tolist()}")
    if mass < 0.0:
        raise UrdfError(f"{what}: mass must be >= 0, got {mass} kg (PyBullet and Pinocchio "
                        f"would both use it as given)")
    broken = inertia_rule_broken(tensor)
    if broken:
        raise UrdfError(f"{what}: inertia tensor {tensor.tolist()} kg m^2 is not a rigid "
                        f"body's: {broken}.  PyBullet would print 'Bad inertia tensor "
                        f"properties, setting inertia to zero' and simulate zero inertia, "
                        f"while Pinocchio (the controller's model) keeps the tensor; a rigid "
                        f"body's principal moments are >= 0 and each at most the sum of the "
                        f"other two")
    return mass, tensor


def inertia_rule_broken(tensor):
    """The rule a symmetric inertia tensor (3, 3) breaks, as Bullet checks it, or ''.

    Bullet takes the diagonal as the principal moments when every product of
    inertia is exactly zero, and diagonalises the tensor otherwise; then each
    moment must be >= 0 and at most the sum of the other two.  Computed moments
    get a relative slack of ``MOMENT_TOLERANCE`` (Bullet's own Jacobi sweep
    stops at 1e-6): a tensor that close to the boundary may go either way.
    """
    tensor = np.asarray(tensor, dtype=float)
    if tensor[0, 1] == 0.0 and tensor[0, 2] == 0.0 and tensor[1, 2] == 0.0:
        moments, slack, kind = np.diag(tensor), 0.0, "diagonal entries"
    else:
        moments = np.linalg.eigvalsh(tensor)
        slack = MOMENT_TOLERANCE * np.abs(moments).sum()
        kind = "principal moments"
    for k in range(3):
        others = [moments[i] for i in range(3) if i != k]
        if moments[k] < -slack:
            return f"{kind} {np.round(moments, 12).tolist()}: {moments[k]:g} < 0"
        if moments[k] > sum(others) + slack:
            return (f"{kind} {np.round(moments, 12).tolist()}: {moments[k]:g} > "
                    f"{others[0]:g} + {others[1]:g} (the triangle inequality)")
    return ""


def _check_meshes(link, name, urdf_path, where):
    for kind in ("visual", "collision"):
        for element in link.findall(kind):
            # Bullet reads the first shape of a <geometry>; <cdf> is its own mesh-like shape
            geometry = element.find("geometry")
            shape = None if geometry is None else next(iter(geometry), None)
            if shape is not None and shape.tag in ("mesh", "cdf"):
                _check_mesh(shape.get("filename") or "", f"{where}: link {name!r} in "
                            f"{urdf_path}: {kind} {shape.tag}", urdf_path)


def _check_mesh(filename, what, urdf_path):
    what = f"{what} {filename!r}"
    if len(filename) <= 4 or filename[-4:].lower() not in BULLET_MESH_TYPES:
        raise UrdfError(f"{what}: PyBullet reads only {', '.join(BULLET_MESH_TYPES)} files (by "
                        f"the name's ending) and refuses the whole URDF otherwise")
    sought, candidates = bullet_mesh_candidates(urdf_path, filename)
    if not any(os.path.isfile(path) for path in candidates):
        raise UrdfError(f"{what} not found: PyBullet (which would refuse the whole URDF with "
                        f"'Cannot load URDF file.') looks for {sought!r} as given, in the "
                        f"URDF's folder {os.path.dirname(urdf_path)} and every folder above "
                        f"it, and in the current folder {os.getcwd()} and the two above it"
                        f"{_package_mesh_hint(filename, sought)}")


def _package_mesh_hint(filename, sought):
    if not filename.startswith("package://"):
        return "; write the mesh path absolute or relative to the URDF's folder"
    package = sought.partition("/")[0]
    try:
        found = resolve_path(filename)
    except FileNotFoundError:
        found = None
    if found is not None:
        return (f"; the file is at {found} (package {package!r} of the ament index), but "
                f"PyBullet reads no ament index: load the URDF from inside that package's "
                f"share folder, or write the mesh paths absolute")
    return (f"; PyBullet finds package://{package}/... only in a folder named {package!r} "
            f"inside the URDF's folder or a folder above it (a source checkout, an installed "
            f"share/ folder): it reads no ament index")
