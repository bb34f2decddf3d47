"""Simulated stations the commissioning tool must find without being told their configuration.

A test builds one or more :class:`~ssi_bridge.sim.gateway.station.Station` objects (the
simulated XN-GW-CANOPEN with its XN-1SSI modules and encoders) in this process on a
``udp_multicast`` group of its own, sets each module's REG_PARA1 as a previous set-up would
have left it, and keeps the configuration (:class:`Truth`) to itself; the tool reaches the
stations only over the bus. Every station is stopped when the test ends.
"""

from __future__ import annotations

import itertools
import os
import random
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import canopen
import pytest

from ssi_bridge.base.buses import open_python_can
from ssi_bridge.base.udp_bus import derive_channel
from ssi_bridge.protocol.dictionary import PROCESS_OUTPUT
from ssi_bridge.protocol.codes import Code
from ssi_bridge.protocol.encoder_config import EncoderConfig
from ssi_bridge.protocol.family_rules import FAMILY_CODES
from ssi_bridge.protocol.joint_encoder import joint_config
from ssi_bridge.protocol.para1 import Para1
from ssi_bridge.protocol.settings import BusConfig, JointSettings, MotionSettings, StationSettings
from ssi_bridge.sim.gateway.station import Station

_channels = itertools.count()

#: every encoder of the manuals, with the resolutions that change its frame (004 §3, 001 §5, 003)
VARIANTS: tuple[tuple[str, dict], ...] = (
    ("GENERIC", {}),
    ("AHS36", {}), ("AHS36", {"steps_per_rev": 4096}),        # 004 §3.1 MSB-justified
    ("AHM36_MULTI", {}),
    ("AFS60", {}), ("AFS60", {"steps_per_rev": 8192}),        # 004 §3.2 directly added
    ("AFM60_MULTI", {"steps_per_rev": 32768}), ("AFM60_MULTI", {}),
    ("AFS60S_PRO", {}), ("AFM60S_PRO", {}),
    ("ATM60", {}), ("ATM60_13_12", {}),                       # 004 §3.4 Figures 17/18
    ("ARS60", {}), ("ARS60", {"steps_per_rev": 32768}),       # 004 §3.5
    ("TTK70", {}), ("TTK70", {"frame_len": 28}),              # 004 §3.6: 26..31 clocks
    ("KH53", {}),
    ("TR_PROGRAMMABLE", {}), ("TR_PARITY", {}), ("TR_CHECKSUM", {}),
    ("SSI25_POWERFAIL", {}),
)


@dataclass
class TrueJoint:
    """What a simulated slot really holds."""

    node_id: int
    slot: int
    settings: JointSettings
    config: EncoderConfig
    para1: int
    #: +1 / -1: the count direction of the motion
    direction: int


@dataclass
class Truth:
    """The hidden configuration of the stations of one test."""

    channel: str
    stations: dict[int, Station] = field(default_factory=dict)
    joints: list[TrueJoint] = field(default_factory=list)
    #: node id -> the number of XN-1SSI modules (the highest slot used)
    modules: dict[int, int] = field(default_factory=dict)

    def joint(self, node_id: int, slot: int) -> TrueJoint | None:
        """The joint in ``slot`` of station ``node_id`` (None: a module with nothing on it)."""
        return next((j for j in self.joints if (j.node_id, j.slot) == (node_id, slot)), None)


def true_joint(rng: random.Random, node_id: int, slot: int, family: str,
               extra: dict) -> TrueJoint:
    """A joint of ``family``: a code the manual offers, a clear constant motion, REG_PARA1
    that fits the frame (000 Table 19), a random bit rate and invalid LSB bits."""
    codes = [c for c in FAMILY_CODES[family].codes if c in (Code.BINARY, Code.GRAY)]
    code = rng.choice(codes)
    sign = rng.choice((1, -1))
    probe = JointSettings(f"j{node_id}_{slot}", slot, family=family, code=code.value,
                          steps_per_rev=int(extra.get("steps_per_rev", 0)))
    cfg = joint_config(probe)
    if cfg.linear:
        speed = 0.01 if cfg.measuring_step_m < 1e-5 else 0.05
        motion = MotionSettings(kind="constant", velocity=sign * speed, start=5.0)
    else:
        motion = MotionSettings(kind="constant", velocity=sign * rng.uniform(0.15, 0.35),
                                start=rng.uniform(20.0, 60.0))
    settings = JointSettings(probe.name, slot, family=family, code=code.value,
                             steps_per_rev=probe.steps_per_rev, motion=motion, station=node_id)
    frame_len = int(extra.get("frame_len", min(cfg.frame_bits, 32)))
    para1 = Para1(ssi_frame_len=frame_len, ssi_bit_rate=rng.choice((1, 2, 3)),
                  invalid_bits_lsb=rng.choice((0, 0, 1)), ssi_code_gray=code is Code.GRAY,
                  # a frame longer than the 32 bits the module clocks ends in a 1 at times:
                  # its ZERO test must be off (000 Table 19 DIS_ERR_SSI)
                  dis_err_ssi=cfg.frame_bits > 32)
    return TrueJoint(node_id, slot, settings, cfg, para1.encode(), sign)


def start_stations(channel: str, layout: dict[int, list[TrueJoint]]) -> Truth:
    """Start one simulated station per node id of ``layout`` on ``channel``, its modules'
    REG_PARA1 set as the joints say."""
    truth = Truth(channel)
    for node_id, joints in layout.items():
        settings = StationSettings(joints=tuple(j.settings for j in joints),
                                   bus=BusConfig("udp_multicast", channel, 500_000, node_id))
        station = Station(settings)
        for joint in joints:
            station.sim.modules[joint.slot - 1].write_para1(joint.para1)
        truth.modules[node_id] = len(station.sim.modules)
        truth.joints += joints
        station.start()
        truth.stations[node_id] = station
    return truth


def random_layout(rng: random.Random, variants: list[tuple[str, dict]],
                  gateways: int) -> dict[int, list[TrueJoint]]:
    """``variants`` spread over ``gateways`` stations at random node ids and slots (gaps
    between the slots are modules with no encoder)."""
    node_ids = rng.sample(range(1, 128), gateways)
    layout: dict[int, list[TrueJoint]] = {n: [] for n in node_ids}
    shares = [variants[i::gateways] for i in range(gateways)]
    for node_id, share in zip(node_ids, shares):
        slots = sorted(rng.sample(range(1, 9), len(share)))
        for slot, (family, extra) in zip(slots, share):
            layout[node_id].append(true_joint(rng, node_id, slot, family, extra))
    return {n: j for n, j in layout.items() if j}


def leave_outputs(truth: Truth, read_address: int) -> None:
    """Leave REG_RD_ADR = ``read_address`` in every slot's process output image (0x2100), as
    a master that ran before would have (its idle read)."""
    network = canopen.Network(open_python_can(BusConfig("udp_multicast", truth.channel)))
    network.connect()
    try:
        for node_id, modules in truth.modules.items():
            node = network.add_node(node_id, canopen.ObjectDictionary())
            for slot in range(1, modules + 1):
                node.sdo.download(PROCESS_OUTPUT, slot, bytes((0, 0, 0, 0, read_address,
                                                               0, 0, 0)))
    finally:
        network.disconnect()


def read_addresses(truth: Truth) -> dict[tuple[int, int], int]:
    """REG_RD_ADR (output byte 4) each slot's module holds now, by (node id, slot)."""
    return {(node_id, slot + 1): out[4]
            for node_id, station in truth.stations.items()
            for slot, out in enumerate(station.gateway.objects.outputs)}


@pytest.fixture
def bus_channel(request: pytest.FixtureRequest) -> str:
    """A udp_multicast channel (group and port) of this test alone."""
    return derive_channel(f"commission-{os.getpid()}-{next(_channels)}-{request.node.name}")


@pytest.fixture
def stations(bus_channel: str) -> Iterator[Callable[[dict[int, list[TrueJoint]]], Truth]]:
    """Factory: start stations on the test's channel; all are stopped at the end."""
    started: list[Truth] = []

    def _start(layout: dict[int, list[TrueJoint]]) -> Truth:
        truth = start_stations(bus_channel, layout)
        started.append(truth)
        return truth

    yield _start
    for truth in started:
        for station in truth.stations.values():
            station.stop()
