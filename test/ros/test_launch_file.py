"""The launch file: ROS 2's `launch` is not on PyPI, so it is checked statically here — it
must parse, start the installed executable, and default to a params file that exists."""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
LAUNCH = REPO / "launch" / "ssi_bridge.launch.py"


def test_launch_file_starts_the_node_with_the_shipped_params():
    tree = ast.parse(LAUNCH.read_text(), filename=str(LAUNCH))
    names = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
    assert "generate_launch_description" in {
        f.name for f in tree.body if isinstance(f, ast.FunctionDef)}
    assert {"Node", "DeclareLaunchArgument", "LaunchConfiguration"} <= names
    strings = {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)
               and isinstance(n.value, str)}
    assert {"ssi_bridge", "ssi_bridge_node", "params_file", "namespace",
            "ssi_bridge.yaml"} <= strings
    assert (REPO / "config" / "ssi_bridge.yaml").exists()
    setup = (REPO / "setup.py").read_text()
    assert 'glob("launch/*.launch.py")' in setup and 'glob("config/*")' in setup, \
        "launch and config files are installed to share/ssi_bridge"
