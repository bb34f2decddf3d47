"""A lost interface (``client/link.py``): the master's bus is closed, reopened with back-off,
and the station configured again; the master's cycle never raises meanwhile.

The master is a real :class:`BridgeClient` on python-can's virtual bus whose calls fail as
socketcan's do on a lost network device (``CanOperationError`` with ``error_code`` ENETDOWN)
and which cannot be opened while "unplugged" (ENODEV); the station a real simulated gateway.
"""

from __future__ import annotations

import errno
import logging
import time

import can
import pytest
from can.interfaces.virtual import VirtualBus

from ssi_bridge.client.link import BACKOFF_FIRST_S, BACKOFF_MAX_S, ReopeningBus, lost_reason
from ssi_bridge.client.master import BridgeClient
from ssi_bridge.exceptions import BusError
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.gateway import XnGateway
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

from support.virtual_bus import ScriptedReader

from .conftest import run_cycles

NODE = 5
ENETDOWN = can.CanOperationError("Failed to transmit: Network is down", errno.ENETDOWN)


def test_what_counts_as_a_lost_interface() -> None:
    """An errno from the OS (directly, as socketcan's ``error_code``, or as the cause) is a
    lost interface; a frame python-can cannot decode or a full transmit buffer is not."""
    assert "Network is down" in lost_reason(OSError(errno.ENETDOWN, "Network is down"))
    assert "[Errno 100]" in lost_reason(ENETDOWN)
    try:
        try:
            raise OSError(errno.ENODEV, "No such device")
        except OSError as err:
            raise can.CanOperationError("Error receiving") from err
    except can.CanOperationError as wrapped:
        assert "No such device" in lost_reason(wrapped)
    assert lost_reason(can.CanOperationError("could not unpack received message")) is None
    assert lost_reason(can.CanOperationError("Transmit buffer full")) is None
    assert lost_reason(ValueError("no")) is None


class Cable:
    """The test's hand on the interface: unplugged (cannot be opened), or its link down (opens,
    but every call fails: socketcan after ``ip link set can0 down``)."""

    unplugged = False
    link_down = False


class UnpluggableVirtual(VirtualBus):
    """python-can's virtual bus failing like a lost socketcan device while unplugged."""

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if Cable.unplugged or Cable.link_down:
            raise ENETDOWN
        super().send(msg, timeout)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if Cable.unplugged or Cable.link_down:
            time.sleep(0.001)
            raise can.CanOperationError("Error receiving: Network is down", errno.ENETDOWN)
        return super()._recv_internal(timeout)


def _open(config: BusConfig) -> can.BusABC:
    if Cable.unplugged:
        raise BusError(f"cannot open CAN bus virtual:{config.channel}: [Errno 19] No such device")
    return UnpluggableVirtual(channel=config.channel, preserve_timestamps=True)


@pytest.fixture
def unplugged_later(channel: str):
    gateway = XnGateway(BusConfig(channel=channel, node_id=NODE), NODE,
                        [Xn1Ssi(ScriptedReader(77), slot=1)])
    Cable.unplugged = Cable.link_down = False
    client = BridgeClient(BusConfig(channel=channel, node_id=NODE), NODE, 1, sdo_timeout=0.3,
                          handshake_timeout=0.5, heartbeat_ms=20, opener=_open)
    gateway.start()
    try:
        client.connect()
        yield client
    finally:
        Cable.unplugged = Cable.link_down = False
        client.close()
        gateway.stop()


def test_the_lost_interface_is_reopened_and_the_station_configured_again(
        unplugged_later: BridgeClient) -> None:
    client = unplugged_later
    link = client.master.link
    assert isinstance(link, ReopeningBus)
    assert run_cycles(client, 5) >= 4
    configured = client.counters.configurations
    Cable.unplugged = True
    deadline = time.monotonic() + 2.0
    while not link.lost and time.monotonic() < deadline:
        client.sync()  # never raises: a cycle whose SYNC did not go out
        time.sleep(0.01)
    assert link.lost and "Network is down" in link.problem(), link.problem()
    assert client.master.interface_problem() == link.problem()
    for _ in range(20):
        client.sync()
        assert not client.wait_cycle(0.01)
    time.sleep(4 * BACKOFF_FIRST_S)
    assert link.attempts >= 2 and "No such device" in link.problem(), link.problem()
    Cable.unplugged = False
    deadline = time.monotonic() + BACKOFF_MAX_S + 3.0
    while (link.lost or client.counters.configurations == configured) \
            and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not link.lost and link.reopens == 1 and link.losses == 1
    assert client.counters.configurations > configured, "the station was not configured again"
    assert run_cycles(client, 10) >= 8, "the master must cycle again"
    assert client.latest(1).position == 77
    assert client.master.link_figures() == {"interface_losses": 1, "interface_reopens": 1,
                                            "interface_reopen_attempts": link.attempts}


def test_a_link_still_down_is_no_new_loss_and_the_log_stays_quiet(
        unplugged_later: BridgeClient, caplog: pytest.LogCaptureFixture) -> None:
    """socketcan after ``ip link set can0 down``: the device opens but every call fails. Each
    such reopen is a failed attempt (the back-off goes on), not a loss and a return each
    time: one line when lost, one when it works again."""
    client = unplugged_later
    link = client.master.link
    caplog.set_level(logging.INFO, logger="ssi_bridge.client.link")
    Cable.link_down = True
    deadline = time.monotonic() + 2.0
    while not link.lost and time.monotonic() < deadline:
        client.sync()
        time.sleep(0.01)
    end = time.monotonic() + 1.6  # attempts at 0.1, 0.3, 0.7, 1.5 s open and fail again
    while time.monotonic() < end:
        client.sync()
        time.sleep(0.01)
    assert link.lost and link.losses == 1 and link.attempts >= 3, link.figures()
    assert "Network is down" in link.problem()
    Cable.link_down = False
    deadline = time.monotonic() + BACKOFF_MAX_S + 3.0
    while link.lost and time.monotonic() < deadline:
        client.sync()
        time.sleep(0.01)
    assert not link.lost and link.losses == 1 and link.reopens == 1, link.figures()
    lines = [r.getMessage() for r in caplog.records
             if r.name == "ssi_bridge.client.link" and r.levelno >= logging.WARNING]
    assert len(lines) == 2 and "lost" in lines[0] and "open again" in lines[1], lines
