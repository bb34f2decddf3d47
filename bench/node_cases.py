"""The node benchmark's cases: how many encoders, at which rate, and the node that runs them.

A case is ``n_joints`` simulated encoders (joints j1..jN on slots 1..N) on a simulated CAN
wire of :data:`BITRATE`, published at :func:`case_rate`: :data:`RATE_HZ`, or the highest rate
that wire allows for the slots (docs/canopen.md rate table: 480 Hz for 8). The installed
``ssi_bridge_node`` runs a case in the namespace :data:`NODE_NS` (:func:`node_cmd`). The
latency "beyond the wire" subtracts the cycle's computed wire time (:func:`beyond_wire_us`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
NODE_EXE = REPO / "install" / "ssi_bridge" / "lib" / "ssi_bridge" / "ssi_bridge_node"

RATE_HZ = 1000.0
CASES = (1, 8)
#: the simulated wire's bit rate of every case (docs/canopen.md rate table)
BITRATE = 1_000_000
NODE_NS = "/bench_node"
#: the CPU the pinned case keeps the whole node on (the last one of this machine)
PIN_CPU = max(os.sched_getaffinity(0))


def case_rate(n_joints: int) -> float:
    """1 kHz, or the highest rate the wire allows for ``n_joints`` slots at BITRATE."""
    from ssi_bridge.protocol import wire
    return min(RATE_HZ, wire.max_cycle_rate(n_joints, BITRATE))


def after_sync_wire_s(n_joints: int) -> float:
    """Computed SYNC -> last TPDO wire time (s): the TPDOs of one cycle, worst-case stuffed."""
    from ssi_bridge.protocol import wire
    return sum(wire.worst_frame_bits(b) for b in wire.cycle_payloads(n_joints)[1:]) / BITRATE


def beyond_wire_us(n_joints: int, node: dict) -> tuple[float, Any]:
    """The computed SYNC -> last TPDO wire time (us) and the node's latencies
    (``node["latency"]``, an array in us) minus it."""
    wire_us = after_sync_wire_s(n_joints) * 1e6
    return wire_us, node["latency"] - wire_us


def node_cmd(n_joints: int, domain_id: int, work: Path,
             extra: dict | None = None) -> list[str]:
    """The installed node's command line with ``n_joints`` simulated encoders at their case
    rate, its parameters written to a file in ``work``; ``extra`` parameters override."""
    import yaml

    names = [f"j{i + 1}" for i in range(n_joints)]
    params: dict = {"publish_rate": case_rate(n_joints), "bus.bitrate": BITRATE,
                    "joints": names,
                    "bus.channel": f"bench_node_{domain_id}_{n_joints}",
                    "storage_path": str(work / f"bank{n_joints}" / "retentive.json")}
    for i, name in enumerate(names):
        params[f"{name}.slot"] = i + 1
    params.update(extra or {})
    pfile = work / f"params{n_joints}{'_x' if extra else ''}.yaml"
    pfile.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
    return [str(NODE_EXE), "--ros-args", "--params-file", str(pfile),
            "-r", f"__ns:={NODE_NS}"]
