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

"""Images: finding the feature points in a camera picture, and drawing on it.

* :mod:`.detection`: colour-marker detection with sub-pixel centroids, an RGB image
  in and the controller's pixels out (OpenCV and numpy);
* :mod:`.apriltag`: an AprilTag's corners or centre, sub-pixel (OpenCV's AprilTag
  detector, then a fit of the tag's edges);
* :mod:`.overlay`: x, x_d and x_o drawn on a picture (numpy only, so the simulator's
  renderer uses it without importing OpenCV).
"""
