"""Every node params file shipped in config/ starts clean: running, and no WARN or ERROR line.

A shipped example is what a user copies: a warning at every start teaches them to ignore
warnings. config/ssi_bridge_two_stations.yaml ran its SSI lines at 500 kbit/s over the
default 10 m cable, which 004 §2.7's table puts below 400 kHz (< 50 m), and warned twice at
every start.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from sensor_msgs.msg import JointState

REPO = Path(__file__).resolve().parents[2]


def _node_configs() -> list[Path]:
    """The params files of config/ that configure ssi_bridge_node (they name joints)."""
    out = []
    for path in sorted((REPO / "config").glob("*.yaml")):
        doc = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
        if any(isinstance(body, dict) and "joints" in (body.get("ros__parameters") or {})
               for body in doc.values()):
            out.append(path)
    return out


def test_the_node_configs_are_found():
    names = {p.name for p in _node_configs()}
    assert {"ssi_bridge.yaml", "ssi_bridge_two_stations.yaml", "noise_guard.yaml"} <= names


@pytest.mark.parametrize("config", _node_configs(), ids=lambda p: p.name)
def test_a_shipped_config_starts_without_a_warning(running, probe, config: Path):
    node = running(params_file=config)
    msgs = probe.subscribe(JointState, node.topic("joint_states"))
    # a few diagnostics periods: the station's line checks run on the first bursts
    probe.wait_for(lambda: len(msgs) > 150, 20.0, "150 joint_states messages", node)
    flagged = [line for line in node.log().splitlines()
               if "[WARN]" in line or "[ERROR]" in line or "Traceback" in line]
    assert not flagged, f"{config.name} starts with:\n" + "\n".join(flagged)
