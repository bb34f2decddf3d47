"""The master owns the NMT state of its station; no heartbeat content kills its supervisor.

Another node on the bus (a second python-can ``virtual`` bus on the
test's channel) sends what any CAN tool may send: a heartbeat whose state byte is none of
CiA 301's (§7.2.8.3.2.1 heartbeat protocol: 0 boot-up, 4 STOPPED, 5 OPERATIONAL, 127
PRE-OPERATIONAL), and NMT module control commands (§7.2.8.3.1: 0x02 stop, 0x80 enter
PRE-OPERATIONAL) to the station. The master is a real BridgeClient, the station a real
simulated XN-GW-CANOPEN (000 chapter 4: it serves SDO in PRE-OPERATIONAL and OPERATIONAL only,
PDOs in OPERATIONAL only).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator

import can
import canopen
import pytest

from ssi_bridge.client.master import BridgeClient
from ssi_bridge.client.sdo import FIRST_POSITION_PDO
from ssi_bridge.protocol.dictionary import NMT_ENTER_PRE_OPERATIONAL, NMT_STOP, tpdo_cob_base
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.gateway import XnGateway
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

from support.virtual_bus import ScriptedReader

from .conftest import run_cycles, lossy_wire

NODE = 5
#: a state byte outside CiA 301 (0x35 = 53), as a CAN tool sent it
INVALID_STATE = 0x35


@pytest.fixture
def foreign(channel: str) -> Iterator[can.BusABC]:
    """Another node's bus on the station's wire."""
    bus = can.Bus(interface="virtual", channel=channel)
    yield bus
    bus.shutdown()


def _send(bus: can.BusABC, can_id: int, data: bytes) -> None:
    bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))


def _until(cond: Callable[[], bool], timeout: float) -> bool:
    end = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > end:
            return False
        time.sleep(0.002)
    return True


def _supervisor_alive() -> bool:
    return any(t.name == f"bridge-supervisor-{NODE}" and t.is_alive()
               for t in threading.enumerate())


def test_a_heartbeat_in_no_cia301_state_is_counted_and_the_station_still_supervised(
        station: tuple[XnGateway, BridgeClient, list], foreign: can.BusABC,
        caplog: pytest.LogCaptureFixture) -> None:
    """``0x705 [0x35]``: counted in ``invalid_nmt_states``, logged once, no exception; the
    supervisor thread lives, and a station that reboots afterwards is configured again.
    Before: KeyError 53 in canopen's NMT state lookup ended the supervisor thread, silently,
    and the rebooted station was never configured again."""
    gateway, client, _ = station
    configured = client.counters.configurations
    for _ in range(3):
        _send(foreign, 0x700 + NODE, bytes([INVALID_STATE]))
    assert _until(lambda: client.counters.invalid_nmt_states == 3, 1.0)
    time.sleep(0.2)  # a supervisor round or more
    assert _supervisor_alive()
    assert client.counters.supervisor_errors == 0
    lines = [r for r in caplog.records if "none of CiA 301" in r.getMessage()]
    assert len(lines) == 1, "logged at most once per second"
    assert run_cycles(client, 5, timeout=0.3) >= 4
    gateway.restart()  # boot-up, PRE-OPERATIONAL, PDOs invalid (000 chapter 4)
    assert _until(lambda: client.counters.configurations > configured
                  and gateway.nmt_state == "OPERATIONAL", 3.0), "station not re-configured"
    assert run_cycles(client, 5, timeout=0.3) >= 4


@pytest.mark.parametrize("command, seen", [(NMT_STOP, "STOPPED"),
                                           (NMT_ENTER_PRE_OPERATIONAL, "PRE-OPERATIONAL")])
def test_a_station_another_node_took_out_of_operational_is_started_again(
        station: tuple[XnGateway, BridgeClient, list], foreign: can.BusABC,
        command: int, seen: str) -> None:
    """Another node's NMT stop / enter PRE-OPERATIONAL to the station: within the liveness
    time (4 heartbeat periods, 0.2 s) the station is OPERATIONAL again by NMT start alone (the
    command kept its dictionary, CiA 301 §7.2.8.2.1: no SDO re-configuration), cycles
    complete, and ``nmt_restarts`` counts it. Before (stop): the master re-tried its SDO
    configuration every 0.55 s, which a STOPPED node cannot answer, and never sent an NMT
    command; later it configured every PDO again, ~30 SDO transfers before data flowed."""
    gateway, client, _ = station
    assert run_cycles(client, 3, timeout=0.3) >= 2
    configured = client.counters.configurations
    sent = time.monotonic()
    _send(foreign, 0x000, bytes([command, NODE]))
    assert _until(lambda: gateway.nmt_state == seen, 0.5)
    assert _until(lambda: gateway.nmt_state == "OPERATIONAL", 2.0), \
        f"station left {gateway.nmt_state}"
    took = time.monotonic() - sent
    assert _until(lambda: client.counters.nmt_restarts == 1, 0.5)
    assert run_cycles(client, 10, timeout=0.3) >= 9
    # the liveness time (heartbeat_timeout) plus one configuration over SDO, with the slack a
    # loaded 2-core machine needs
    assert took < client.heartbeat_timeout + 0.5, f"started again after {took:.3f} s"
    assert client.counters.configurations == configured, "configured again over SDO"


def test_a_station_stopped_after_another_tool_changed_its_pdos_is_configured_again(
        station: tuple[XnGateway, BridgeClient, list], foreign: can.BusABC) -> None:
    """Another tool writes TPDO9's COB-ID invalid over SDO (CiA 301: bit 31), then stops the
    station: NMT start alone would leave the positions off, so the master, reading the
    COB-IDs back after its start, configures the station again; cycles complete."""
    gateway, client, _ = station
    assert run_cycles(client, 3, timeout=0.3) >= 2
    configured = client.counters.configurations
    tool = canopen.Network(foreign).connect()  # the tool's SDO client on the same wire
    remote = tool.add_node(NODE, canopen.ObjectDictionary())
    try:
        cob = tpdo_cob_base(FIRST_POSITION_PDO) + NODE
        remote.sdo.download(0x1800 + FIRST_POSITION_PDO - 1, 1,
                            ((1 << 31) | cob).to_bytes(4, "little"))
        _send(foreign, 0x000, bytes([NMT_STOP, NODE]))
        assert _until(lambda: client.counters.configurations == configured + 1
                      and client.counters.nmt_restarts == 1, 3.0)
    finally:
        tool.disconnect()
    assert _until(lambda: gateway.nmt_state == "OPERATIONAL", 1.0)
    assert run_cycles(client, 10, timeout=0.3) >= 9


class _ConfigureFailsOnce(BridgeClient):
    """A BridgeClient whose first re-configuration meets an unexpected error (not a bus
    error): what any bug in one supervisor round would raise."""

    failed = False

    def configure(self) -> None:
        if self.counters.configurations and not self.failed:
            self.failed = True
            raise RuntimeError("unexpected")
        super().configure()


def test_an_unexpected_error_in_a_supervisor_round_does_not_end_the_thread(
        channel: str, caplog: pytest.LogCaptureFixture) -> None:
    """A round that raises: counted in ``supervisor_errors``, logged once with the thread's
    name, and the next round re-configures the rebooted station. Before: the exception ended
    the thread (stderr only), and the station was never configured again."""
    config = BusConfig(channel=channel, node_id=NODE)
    gateway = XnGateway(config, NODE, [Xn1Ssi(ScriptedReader(1), slot=1)])
    client = _ConfigureFailsOnce(config, NODE, 1, sdo_timeout=0.3, handshake_timeout=0.5,
                                 opener=lossy_wire)
    gateway.start()
    try:
        client.connect()
        gateway.restart()
        assert _until(lambda: client.counters.configurations == 2
                      and gateway.nmt_state == "OPERATIONAL", 3.0)
        assert client.failed and client.counters.supervisor_errors == 1
        assert _supervisor_alive()
        lines = [r for r in caplog.records if "round failed" in r.getMessage()]
        assert len(lines) == 1 and f"bridge-supervisor-{NODE}" in lines[0].getMessage()
    finally:
        client.close()
        gateway.stop()
