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

"""Robot + fixed-camera models: the regressors of Properties 1 and 4 of the paper.

* :mod:`.base`: :class:`RobotCameraModel`, what the controller needs from any arm;
* :mod:`.paper_rrr`: the paper's RRR arm and camera, derived by hand;
* :mod:`.urdf_arm`: any serial arm from its URDF with 1-3 feature points
  (:mod:`.urdf_chain` reads the chain, :mod:`.kinematic_regressor` builds
  Property 1, :mod:`.rigid_body` Property 4 with Pinocchio);
* :mod:`.kernels`: the kinematic tensors compiled with numba, and
  :mod:`.dynamics_kernels` the dynamic regressors Y_d, chosen by
  :mod:`.backend` (the numpy code stays the reference).
"""

from .backend import BACKENDS, resolve_backend
from .base import GRAVITY, RobotCameraModel
from .paper_rrr import CylinderLink, PaperRRRCamera

MODEL_NAMES = ("paper_rrr", "urdf")
#: configuration parameters that define a model's structure (read before the others)
STRUCTURE_PARAMS = ("model", "urdf", "base_link", "tip_link", "feature_points",
                    "unknown_lengths")


def make_model(name, structure=None, section="controller_node", search_dirs=(), backend=None):
    """Build a model by name (the ``model`` parameter) from its structure parameters.

    ``structure`` holds ``urdf``, ``base_link``, ``tip_link``, ``feature_points``
    and ``unknown_lengths`` (used by ``urdf``; ``paper_rrr`` is fixed).
    ``backend``: ``"compiled"`` or ``"numpy"`` kinematic tensors (default compiled
    when numba imports, see :mod:`.backend`).
    """
    if name == "paper_rrr":
        return PaperRRRCamera(backend=resolve_backend(backend, section))
    if name == "urdf":
        from .urdf_arm import UrdfArmCamera

        s = structure or {}
        unknown = s.get("unknown_lengths", ("all",))
        unknown = "all" if list(unknown) == ["all"] else list(unknown)
        return UrdfArmCamera(s.get("urdf", ""), s.get("base_link", ""), s.get("tip_link", ""),
                             s.get("feature_points", ()), unknown, section=section,
                             search_dirs=search_dirs, backend=backend)
    raise ValueError(f"model: unknown model name {name!r}; known: {list(MODEL_NAMES)}")


__all__ = ["BACKENDS", "GRAVITY", "MODEL_NAMES", "STRUCTURE_PARAMS", "CylinderLink",
           "PaperRRRCamera", "RobotCameraModel", "make_model"]
