"""Fixtures for the bridge-client tests: a real gateway and client on a private virtual bus.

Every fixture shuts its buses down, and ``no_leaked_bus`` fails a test that leaves a python-can
virtual bus open on its channel.
"""

from __future__ import annotations

import itertools
import os
import time
from collections.abc import Callable, Iterator

import can.interfaces.virtual as virtual
import pytest

from ssi_bridge.base.udp_bus import derive_channel
from ssi_bridge.client.master import BridgeClient
from ssi_bridge.protocol.settings import BusConfig, station_settings
from ssi_bridge.sim.gateway.bus import LossyBus
from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
from ssi_bridge.sim.gateway.gateway import XnGateway
from ssi_bridge.sim.gateway.station import Station
from ssi_bridge.protocol.readout import LineReadout
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

_channels = itertools.count()


class ScriptedReader:
    """An SsiReader whose encoder value the test sets; a healthy line otherwise."""

    def __init__(self, value: int = 1234) -> None:
        self.value = value

    def read(self, t: float, n_bits: int, bit_rate_hz: float) -> LineReadout:
        data = self.value & ((1 << n_bits) - 1)
        return LineReadout(latch_time=t, n_bits=n_bits, data=data,
                           end_time=t + (n_bits + 1) / bit_rate_hz)


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
    name = f"client-{next(_channels)}-{request.node.name}"
    yield name
    with virtual.channels_lock:
        leaked = len(virtual.channels.get(name, []))
    assert leaked == 0, f"{leaked} virtual bus(es) left open on {name!r}"


def lossy_wire(config: BusConfig) -> LossyBus:
    """The master's end of the simulated wire behind a loss wrapper the tests can turn up."""
    return LossyBus(wire_bus(config))


@pytest.fixture
def station(channel: str) -> Iterator[tuple[XnGateway, BridgeClient, list[ScriptedReader]]]:
    """Gateway (node 5, one XN-1SSI on a scripted reader) and a connected client."""
    readers = [ScriptedReader(1234)]
    config = BusConfig(channel=channel, node_id=5)
    gateway = XnGateway(config, 5, [Xn1Ssi(r, slot=i + 1) for i, r in enumerate(readers)])
    client = BridgeClient(config, 5, len(readers), sdo_timeout=0.3, handshake_timeout=0.5, opener=lossy_wire)
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
    client = BridgeClient(BusConfig(interface="udp_multicast", channel=channel), 1, 1,
                          opener=wire_bus)
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
