"""The managed node (``ssi_bridge_managed_node``) started unconfigured and driven through the
standard lifecycle services (lifecycle_msgs ``~/get_state``, ``~/change_state``)."""

from __future__ import annotations

import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState

from support.ros_process import NodeProcess, dds_env, installed_executable

#: publish_rate (Hz) of a managed node unless the test's parameters say otherwise
RATE = 50.0


def start_managed(tmp_path: Path, domain_id: int, child_preexec: Callable[[], None],
                  params: dict) -> NodeProcess:
    """Start the installed managed node in ``domain_id`` on ``params`` over a default of
    :data:`RATE`, a test-unique bus channel and the station as a child process (its PID shows
    when cleanup closes the bus); its log is ``tmp_path/node.log``."""
    values = {"bus.channel": f"test_{domain_id}_managed", "publish_rate": RATE,
              "storage_path": str(tmp_path / "bank" / "retentive.json"),
              "simulation.transport": "udp_multicast"}
    values.update(params)
    pfile = tmp_path / "params.yaml"
    pfile.write_text(yaml.safe_dump({"/**": {"ros__parameters": values}}))
    log_path = tmp_path / "node.log"
    env = dds_env(domain_id)
    with open(log_path, "wb") as log:
        proc = subprocess.Popen(
            [str(installed_executable("ssi_bridge_managed_node")), "--ros-args",
             "--params-file", str(pfile)],
            stdout=log, stderr=subprocess.STDOUT, env=env, cwd=tmp_path,
            start_new_session=True, preexec_fn=child_preexec)
    return NodeProcess(proc, domain_id, "", log_path, env=env)


def lifecycle_state(probe: Any, node: NodeProcess) -> int:
    """The node's primary state id (``lifecycle_msgs/msg/State``), asked with ``probe``."""
    return probe.call(GetState, node.topic("~/get_state"), GetState.Request()).current_state.id


def change_state(probe: Any, node: NodeProcess, transition: int) -> bool:
    """Ask the node for ``transition`` (a ``lifecycle_msgs/msg/Transition`` id); its success."""
    request = ChangeState.Request(transition=Transition(id=transition))
    return probe.call(ChangeState, node.topic("~/change_state"), request, timeout=30.0).success
