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

"""ament_python package visual_adaptive_servo (also pip-installable without ROS)."""

from glob import glob

from setuptools import find_packages, setup

package_name = "visual_adaptive_servo"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(include=[package_name, package_name + ".*", "sim_bridge"]),
    package_data={"sim_bridge": ["urdf/*.urdf"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
        ("share/" + package_name + "/config", glob("config/*.yaml") + glob("config/*.csv")),
        ("share/" + package_name + "/config/campaigns", glob("config/campaigns/*.yaml")),
        ("share/" + package_name + "/config/tune", glob("config/tune/*.yaml")),
        ("share/" + package_name + "/urdf", glob("sim_bridge/urdf/*.urdf")),
    ],
    python_requires=">=3.10",
    install_requires=[
        "setuptools",
        "numpy>=1.26",
        "pybullet>=3.2.5",
        "PyYAML>=6.0",
        "matplotlib>=3.6",
        "rosbags>=0.10.4",
        # LZ4 chunks of the rendered pictures in run.mcap; a dependency of rosbags anyway
        "lz4>=3.1",
        # Pinocchio (rigid-body dynamics of URDF arms) and scipy (its base-parameter QR);
        # with numpy 1.26 pip can only resolve pin 2.7 (pin 3+ wheels need numpy >= 2.2)
        "pin>=2.7",
        "scipy>=1.8",
        "opencv-python-headless>=4.8",
        # the compiled kinematic tensors and timeseries.csv formatting (the numpy code runs
        # without it); wheels for Python 3.10-3.12 with numpy 1.26 and 2.x (numba 0.68.1)
        "numba>=0.59",
    ],
    # ruff and flake8 (+ the plugins ament_flake8 runs) give the ament lint checks without ROS
    # ray: `vas campaign --ray` (imported only then); optuna: `vas tune` (imported only then;
    # in the test extra too, so that CI runs test_tune.py: about a minute)
    extras_require={"test": ["pytest>=7", "ruff>=0.5", "flake8>=6", "flake8-builtins",
                             "flake8-comprehensions", "flake8-quotes", "flake8-import-order",
                             "import-linter>=2.10", "optuna>=3.6"],
                    "ray": ["ray>=2.9"],
                    "tune": ["optuna>=3.6"]},
    zip_safe=True,
    maintainer="visual_adaptive_servo maintainers",
    maintainer_email="maintainers@users.noreply.h-seed-00a3853d.example",
    description="Adaptive visual tracking with an uncalibrated fixed camera, without "
                "image-space velocity (H. Wang, Automatica 2015), with a PyBullet simulator.",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "vas = visual_adaptive_servo.cli:main",
            "controller_node = visual_adaptive_servo.ros.controller_node:main",
            "sim_node = visual_adaptive_servo.ros.sim_node:main",
            "feature_detector = visual_adaptive_servo.ros.feature_detector_node:main",
            "robot_description = visual_adaptive_servo.ros.description_node:main",
        ],
    },
)
