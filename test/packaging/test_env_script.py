"""scripts/env.sh gives a shell what /opt/ros/jazzy/setup.bash would: the ROS variables too.

`ros2 doctor` (and rosdep, launch files reading ``ROS_DISTRO``) take the distribution from the
environment; without ``ROS_DISTRO`` the doctor failed two of its five checks.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_env_script_names_the_jazzy_distribution():
    env = {k: v for k, v in os.environ.items()
           if k not in ("ROS_DISTRO", "ROS_VERSION", "ROS_PYTHON_VERSION")}
    # env.sh sources the venv and the install space; a tree without them still gets the names
    out = subprocess.run(
        ["bash", "-c", 'source scripts/env.sh >/dev/null 2>&1; '
                       'echo "$ROS_DISTRO $ROS_VERSION $ROS_PYTHON_VERSION"'],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=60)
    assert out.stdout.split() == ["jazzy", "2", "3"], (out.stdout, out.stderr)
