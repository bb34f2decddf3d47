"""The client receives the TPDOs it maps as raw frames, once each, also after re-configuring.

``client/receive.py``: the client's handlers sit on the COB-IDs of TPDO 1..n (process input
images) and 9.. (slot-pair positions, 000 Table 15); canopen's PdoMap handlers, which
``PdoMap.save`` subscribes during the SDO set-up, are taken off again.
"""

from __future__ import annotations

import can
from canopen.network import MessageListener

from ssi_bridge.client.master import BridgeClient
from ssi_bridge.client.receive import FrameListener, TpdoRoutes
from ssi_bridge.client.samples import ClientCounters
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
from ssi_bridge.sim.gateway.gateway import XnGateway
from ssi_bridge.protocol.registers import Reg
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

from support.virtual_bus import ScriptedReader

NODE = 5


#: TPDO COB-IDs of a 3-slot station (000 Table 15): images 1-3, positions of slots 1+2, 3
ROUTED = {0x185: 1, 0x285: 2, 0x385: 3, 0x1E5: 9, 0x2E5: 10}


def _assert_routed(client: BridgeClient) -> None:
    assert client.network is not None and client.node is not None
    for cob_id, pdo_no in ROUTED.items():
        # the route, straight from the listener; canopen's PdoMap handler taken off again
        assert cob_id in client.network.routes, f"0x{cob_id:03X} not routed"
        handlers = client.network.subscribers.get(cob_id, [])
        assert handlers == [], f"0x{cob_id:03X} has canopen subscribers {handlers}"
        assert client.node.tpdo[pdo_no].on_message not in handlers, "PdoMap still subscribed"


def test_routes_cover_the_mapped_tpdos() -> None:
    routes = TpdoRoutes(NODE, 3, lambda *a: None, lambda *a: None)
    assert routes.pdo_numbers == ROUTED


def test_one_handler_per_tpdo_after_connect_and_reconfigure(channel: str) -> None:
    readers = [ScriptedReader(1000), ScriptedReader(2000), ScriptedReader(3000)]
    config = BusConfig(channel=channel, node_id=NODE)
    gateway = XnGateway(config, NODE, [Xn1Ssi(r, slot=i + 1) for i, r in enumerate(readers)])
    client = BridgeClient(config, NODE, 3, sdo_timeout=0.3, handshake_timeout=0.5, opener=wire_bus)
    gateway.start()
    try:
        client.connect()
        _assert_routed(client)
        client.configure()
        _assert_routed(client)
        for value in (10, 20):
            for r in readers:
                r.value += value
            client.sync()
            assert client.wait_cycle(1.0), "cycle incomplete"
            for slot, module in enumerate(gateway.modules, start=1):
                sample = client.latest(slot)
                assert sample is not None
                assert sample.position == module.read_register(Reg.REG_SSI_POS)
                assert sample.process_input == module.process_input()
        assert client.latest(1).counter == client.latest(3).counter  # type: ignore[union-attr]
    finally:
        client.close()
        gateway.stop()


def test_frame_listener_counts_and_forwards() -> None:
    import canopen

    seen: list[tuple[int, bytes]] = []
    network = canopen.Network()  # not connected: the listener only dispatches to subscribers
    network.subscribe(0x185, lambda can_id, data, t: seen.append((can_id, bytes(data))))
    counters = ClientCounters()
    listener = FrameListener(network, counters)
    assert isinstance(listener, MessageListener)
    listener(can.Message(arbitration_id=0x185, is_extended_id=False, data=b"\x01"))
    listener(can.Message(is_error_frame=True))
    assert counters.frames == 2 and counters.can_errors == 1
    assert seen == [(0x185, b"\x01")], "the error frame must not be dispatched"


def test_the_receive_thread_takes_the_masters_priority_at_its_first_frame(channel: str) -> None:
    """CanMaster(priority=N): the notifier thread that hands the TPDOs to the cycle names
    itself ssi_can_rx and runs SCHED_FIFO N (or, without the right, normally); the master's
    ``receive_scheduling`` says which (docs/node.md "Scheduling")."""
    import os
    import threading
    import time
    from pathlib import Path

    from ssi_bridge.client.bus_master import CanMaster
    from ssi_bridge.sim.gateway.bus import open_bus
    from ssi_bridge.base.realtime import fifo_this_thread

    permitted: list[bool] = []
    probe = threading.Thread(target=lambda: permitted.append(fifo_this_thread(1)))
    probe.start()
    probe.join()
    config = BusConfig(channel=channel, node_id=NODE)
    master = CanMaster(config, priority=3, opener=wire_bus)
    master.connect()
    other = open_bus(config)
    try:
        assert master.receive_scheduling == "", "nothing received yet"
        other.send(can.Message(arbitration_id=0x705, data=b"\x05", is_extended_id=False))
        deadline = time.monotonic() + 5.0
        while not master.receive_scheduling and time.monotonic() < deadline:
            time.sleep(0.01)
        names = {}
        for task in Path("/proc/self/task").iterdir():
            try:
                names[(task / "comm").read_text().strip()] = int(task.name)
            except OSError:
                continue
        assert "ssi_can_rx" in names, sorted(names)
        tid = names["ssi_can_rx"]
        if permitted[0]:
            assert master.receive_scheduling == "SCHED_FIFO 3"
            assert (os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority) == \
                (os.SCHED_FIFO, 3)
        else:
            assert master.receive_scheduling == "normal"
            assert os.sched_getscheduler(tid) == os.SCHED_OTHER
    finally:
        other.shutdown()
        master.close()
