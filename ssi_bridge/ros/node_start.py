"""What the node decides and says around its start, beside opening the bus and the cycle.

The bus a log replay plays onto (a channel of this process only), how activate prepares the
process for the cycle (CPU pinning, the GIL switch interval) and the one log line that says
what the node bridges.
"""

from __future__ import annotations

import dataclasses
import os
import sys
from collections.abc import Callable, Iterable

from ssi_bridge.base.realtime import pin_process
from ssi_bridge.ros import logbridge
from ssi_bridge.ros.params import NodeSettings


def replay_settings(settings: NodeSettings, owner: object) -> NodeSettings:
    """``settings`` with a ``replay.can_log`` played onto a virtual channel of this process
    only (named after the process and ``owner``): the sniffer of a re-recording and the
    diagnostics' hardware_id name that channel. Unchanged without a replay."""
    if not settings.replay_can_log:
        return settings
    return dataclasses.replace(settings, bus_interface="virtual",
                               bus_channel=f"ssi_bridge_replay_{os.getpid()}_{id(owner):x}")


def prepare_process(s: NodeSettings, info: Callable[[str], None]) -> None:
    """Before the cycle starts: pin the process to ``cpu_affinity`` (said with ``info``) and
    shorten the GIL switch interval to a quarter period.

    Python hands the GIL to a waiting thread only every switch interval (5 ms by default): a
    service burst's CPU-bound handlers would hold the cycle that long.

    :raises OSError: the CPUs cannot be set (``pin_process``)
    """
    if s.cpu_affinity:
        pin_process(s.cpu_affinity)
        info(f"process pinned to CPU(s) {list(s.cpu_affinity)}")
    sys.setswitchinterval(min(sys.getswitchinterval(), 0.25 / s.publish_rate))


def bridging_line(s: NodeSettings, joints: Iterable[str], joint_topic: str, status_topic: str,
                  node_name: str) -> str:
    """The log line of an activated node: joints, bus, mode, topics, rates, where the
    services are (``node_name``: the node's fully qualified name)."""
    mode = ("simulated station" if s.simulation else
            f"replay of {s.replay_can_log}" if s.replay_can_log else
            "listen-only" if s.listen_only else "real station")
    names = logbridge.clip(str(list(joints)), 200)  # echoed input: kept short
    return (f"bridging {len(s.joints)} joint(s) {names} on "
            f"{s.bus_interface}:{s.bus_channel} node {s.node_id} "
            f"({mode}); publishing "
            f"{joint_topic} at {s.publish_rate:g} Hz, {status_topic}, "
            f"/diagnostics every {s.diagnostics_period:g} s; services under {node_name}/")


__all__ = ["bridging_line", "prepare_process", "replay_settings"]
