"""Fixtures for the bridge-client tests: a real gateway and client on a private virtual bus.

Every fixture shuts its buses down, and ``no_leaked_bus`` fails a test that leaves a python-can
virtual bus open on its channel.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator

import pytest

from ssi_bridge.base.udp_bus import derive_channel
from ssi_bridge.client.master import BridgeClient
from ssi_bridge.protocol.settings import BusConfig, station_settings
from ssi_bridge.sim.gateway.bus import LossyBus
from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
from ssi_bridge.sim.gateway.gateway import XnGateway
from ssi_bridge.sim.gateway.station import Station
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi
from support.virtual_bus import ScriptedReader, private_channel


#: the SDO timeout (s) of the clients of the simulated stations these fixtures start in this
#: process (see :func:`station`)
STATION_SDO_TIMEOUT = 2.0


def run_cycles(client: BridgeClient, n: int, timeout: float = 0.5) -> int:
    """Run ``n`` SYNC cycles, each waited for up to ``timeout`` s; return how many came back
    complete (raises if SYNC fails)."""
    done = 0
    for _ in range(n):
        client.sync()
        done += client.wait_cycle(timeout)
    return done


@pytest.fixture
def channel(request: pytest.FixtureRequest) -> Iterator[str]:
    """A virtual channel private to this test; fails the test if a bus is left open on it."""
    yield from private_channel("client", request.node.name)


def lossy_wire(config: BusConfig) -> LossyBus:
    """The master's end of the simulated wire behind a loss wrapper the tests can turn up."""
    return LossyBus(wire_bus(config))


@pytest.fixture
def station(channel: str) -> Iterator[tuple[XnGateway, BridgeClient, list[ScriptedReader]]]:
    """Gateway (node 5, one XN-1SSI on a scripted reader) and a connected client.

    The gateway answers SDO from a thread of this process: beside test workers and CPU
    burners it was starved past the 0.15 s each of the two tries of a 0.3 s transfer waits,
    and the configuration failed. These tests are about liveness, faults and the handshake,
    not about the SDO bound (``bus.sdo_timeout``, docs/parameters.md: "the margin is for a
    busy master computer"), so the client waits as long as :func:`udp_station`'s does."""
    readers = [ScriptedReader(1234)]
    config = BusConfig(channel=channel, node_id=5)
    gateway = XnGateway(config, 5, [Xn1Ssi(r, slot=i + 1) for i, r in enumerate(readers)])
    client = BridgeClient(config, 5, len(readers), sdo_timeout=STATION_SDO_TIMEOUT,
                          handshake_timeout=0.5, opener=lossy_wire)
    gateway.start()
    try:
        client.connect()
        yield gateway, client, readers
    finally:
        client.close()
        gateway.stop()


@pytest.fixture
def udp_station(request: pytest.FixtureRequest):
    """A simulated station (node 1, one joint) and a connected master on a private
    udp_multicast channel (CAN over UDP multicast on loopback): (channel, station, client)."""
    channel = derive_channel(f"udp-{os.getpid()}-{request.node.name}")
    station = Station(station_settings({"joints": ["j"], "j.slot": 1,
                                        "bus.interface": "udp_multicast",
                                        "bus.channel": channel}))
    station.start()
    # the station runs in this process: beside four test workers and two CPU burners its SDO
    # server can take longer than the driver's 0.5 s default to answer the configuration
    # (these tests are about hostile frames, not about the SDO bound)
    client = BridgeClient(BusConfig(interface="udp_multicast", channel=channel), 1, 1,
                          opener=wire_bus, sdo_timeout=STATION_SDO_TIMEOUT)
    try:
        client.connect()
        yield channel, station, client
    finally:
        client.close()
        station.stop()


def wait_until(condition: Callable[[], bool], what: str, timeout: float = 3.0) -> None:
    """Wait until ``condition()`` holds; fail the test with ``what`` after ``timeout`` s."""
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            pytest.fail(what)
        time.sleep(0.005)
