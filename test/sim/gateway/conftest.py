"""Fixtures for the gateway tests: a station and a bare canopen master on a private bus.

The master side here is canopen's own RemoteNode (not our client), so the gateway is checked
against the library's reading of CiA 301. Every fixture shuts its bus down; ``channel``
fails a test that leaves a virtual bus open.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import canopen
import pytest

from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.base.od import build_dictionary
from ssi_bridge.sim.gateway.gateway import XnGateway
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi
from support.virtual_bus import ScriptedReader, private_channel
from support.waiting import wait_for

NODE_ID = 7


@dataclass
class Station:
    gateway: XnGateway
    network: canopen.Network
    node: canopen.RemoteNode
    readers: list[ScriptedReader]

    def wait_for(self, condition, message: str, timeout: float = 2.0) -> None:
        """Poll ``condition`` until true; fail with ``message`` after ``timeout`` s."""
        wait_for(condition, message, timeout)

    def sync(self) -> None:
        """One SYNC, waited for until the gateway ran the cycle (no fixed sleep)."""
        before = self.gateway.cycles
        self.network.sync.transmit()
        wait_for(lambda: self.gateway.cycles > before, "gateway ran no cycle after SYNC")


@pytest.fixture
def channel(request: pytest.FixtureRequest) -> Iterator[str]:
    """A virtual channel private to this test; fails the test if a bus is left open on it."""
    yield from private_channel("gateway", request.node.name)


@contextmanager
def canopen_master(channel: str, slots: int, sdo_timeout: float = 0.5,
                   ) -> Iterator[tuple[canopen.Network, canopen.RemoteNode]]:
    """canopen's own master on ``channel`` with a RemoteNode for a station of ``slots``
    modules at NODE_ID (SDO answers awaited ``sdo_timeout`` s); disconnected on exit."""
    network = canopen.Network()
    network.NOTIFIER_CYCLE = 0.05
    try:
        network.connect(interface="virtual", channel=channel)
        node = canopen.RemoteNode(NODE_ID, build_dictionary(NODE_ID, slots))
        node.sdo.RESPONSE_TIMEOUT = sdo_timeout
        network.add_node(node)
        yield network, node
    finally:
        network.disconnect()


def make_station(channel: str, slots: int) -> Iterator[Station]:
    readers = [ScriptedReader(1000 * (s + 1)) for s in range(slots)]
    gateway = XnGateway(BusConfig(channel=channel, node_id=NODE_ID), NODE_ID,
                        [Xn1Ssi(r, slot=i + 1) for i, r in enumerate(readers)])
    gateway.start()
    try:
        with canopen_master(channel, slots) as (network, node):
            yield Station(gateway, network, node, readers)
    finally:
        gateway.stop()


@pytest.fixture
def station(channel: str) -> Iterator[Station]:
    """A two-slot station in PRE-OPERATIONAL with a canopen RemoteNode for it."""
    yield from make_station(channel, 2)


@pytest.fixture
def station8(channel: str) -> Iterator[Station]:
    """A full eight-slot station."""
    yield from make_station(channel, 8)
