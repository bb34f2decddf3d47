"""An SDO answer to an earlier request is set aside and counted, never taken for the current one.

CiA 301 §7.2.4.3: the server's initiate upload / initiate download response and its abort
carry the multiplexer (index, sub-index) of the transfer in bytes 1-3; a segment response
carries the toggle bit of the segment request it answers (byte 0, bit 4). An SDO channel has
no sequence number, so a station that stalled and resumed answers its queued requests late,
and those answers reach the master while it waits for the answer to its next request. Seen
after a 2 s stall of the simulated station: the re-configuration's upload of
0x1000:00 failed with "Node returned a value for 0x1017:00 instead" (the supervisor's SDO
probe of the silent station, answered on resume).

Client: the master's ``SdoAccess`` on canopen's SDO client over a python-can virtual bus.
Server: canopen's ``LocalNode`` behind a receive pump the test pauses (a stalled station whose
CAN controller keeps the requests), or a raw python-can responder that sends what each case
needs, when it needs it.
"""

from __future__ import annotations

import dataclasses
import queue
import struct
import threading
import time
from collections.abc import Callable, Iterator

import can
import canopen
import pytest

from ssi_bridge.base.od import build_dictionary
from ssi_bridge.client.samples import ClientCounters
from ssi_bridge.client.sdo import SdoAccess
from ssi_bridge.exceptions import GatewayUnavailable, SdoAbortError
from ssi_bridge.protocol.dictionary import DEVICE_TYPE as DEVICE_TYPE_OBJECT

NODE = 5
REQUEST_ID, RESPONSE_ID = 0x600 + NODE, 0x580 + NODE
#: bound of one SDO transfer step (s): two attempts of half of it
TIMEOUT = 0.4
#: 0x1017:00 = 50 ms and 0x1000:00 = 0x00000191, as an expedited upload response (0x43:
#: 4 bytes) carries them
HEARTBEAT_ANSWER = bytes([0x43, 0x17, 0x10, 0x00]) + (50).to_bytes(4, "little")
DEVICE_TYPE = (0x191).to_bytes(4, "little")
DEVICE_TYPE_ANSWER = bytes([0x43, 0x00, 0x10, 0x00]) + DEVICE_TYPE


def _abort(index: int, subindex: int, code: int) -> bytes:
    return struct.pack("<BHBL", 0x80, index, subindex, code)


@dataclasses.dataclass
class Master:
    """The master's end: canopen's network and RemoteNode, the SdoAccess on it."""

    network: canopen.Network
    sdo: SdoAccess
    counters: ClientCounters


@pytest.fixture
def master(channel: str) -> Iterator[Master]:
    network = canopen.Network()
    network.NOTIFIER_CYCLE = 0.05  # its receive thread stops within this at the end
    counters = ClientCounters()
    sdo = SdoAccess(NODE, build_dictionary(NODE, 1), TIMEOUT, counters)
    network.add_node(sdo.node)
    network.connect(interface="virtual", channel=channel)
    try:
        yield Master(network, sdo, counters)
    finally:
        network.disconnect()


class Responder:
    """A raw python-can station: for each SDO request it receives (not the client's own
    aborts), ``script`` returns the frames to send, each after its delay (s)."""

    def __init__(self, channel: str,
                 script: Callable[[bytes], list[tuple[float, bytes]]]) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.script = script
        self.requests: list[bytes] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(0.02)
            if msg is None or msg.arbitration_id != REQUEST_ID or msg.data[0] >> 5 == 4:
                continue
            self.requests.append(bytes(msg.data))
            for delay, frame in self.script(bytes(msg.data)):
                time.sleep(delay)
                self.bus.send(can.Message(arbitration_id=RESPONSE_ID, data=frame,
                                          is_extended_id=False))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.bus.shutdown()


@pytest.fixture
def respond(channel: str) -> Iterator[Callable[..., Responder]]:
    started: list[Responder] = []

    def start(script: Callable[[bytes], list[tuple[float, bytes]]]) -> Responder:
        started.append(Responder(channel, script))
        return started[-1]
    yield start
    for r in started:
        r.close()


def _is(request: bytes, command: int, index: int, subindex: int = 0) -> bool:
    return request[:4] == struct.pack("<BHB", command, index, subindex)


def test_a_stalled_local_node_answers_late_and_the_next_upload_takes_its_own_answer(
        master: Master, channel: str) -> None:
    # canopen's own SDO server; its receive pump paused = a stalled station whose controller
    # keeps the requests it has not handled (python-can's virtual bus queues them)
    bus = can.Bus(interface="virtual", channel=channel)
    network = canopen.Network(bus)
    station = canopen.LocalNode(NODE, build_dictionary(NODE, 1))
    network.add_node(station)
    running, stop = threading.Event(), threading.Event()

    def pump() -> None:
        while not stop.is_set():
            if not running.wait(0.01):
                continue
            msg = bus.recv(0.01)
            if msg is not None:
                network.notify(msg.arbitration_id, msg.data, msg.timestamp)
    thread = threading.Thread(target=pump, daemon=True)
    thread.start()
    try:
        with pytest.raises(GatewayUnavailable):  # the supervisor's probe of a silent station
            master.sdo.upload(0x1017, 0)
        result: queue.Queue[bytes | Exception] = queue.Queue()

        def upload() -> None:
            try:
                result.put(master.sdo.upload(0x1000, 0))
            except Exception as err:  # noqa: BLE001 - handed to the test thread
                result.put(err)
        threading.Thread(target=upload, daemon=True).start()
        time.sleep(0.05)  # the 0x1000 request is on the wire behind the two 0x1017 ones
        running.set()  # resumed: the station answers 0x1017 twice, then 0x1000
        got = result.get(timeout=2 * TIMEOUT)
    finally:
        stop.set()
        thread.join(2.0)
        bus.shutdown()
    assert got == station.sdo.upload(0x1000, 0), got
    assert master.counters.stale_sdo_answers == 2
    assert master.sdo.timeouts == 1


def test_a_late_answer_to_a_timed_out_upload_is_set_aside_while_the_next_one_waits(
        master: Master, respond: Callable[..., Responder]) -> None:
    def script(request: bytes) -> list[tuple[float, bytes]]:
        if _is(request, 0x40, 0x1000):  # the two queued probes answered first, then this one
            return [(0.0, HEARTBEAT_ANSWER), (0.0, HEARTBEAT_ANSWER),
                    (0.05, DEVICE_TYPE_ANSWER)]
        return []  # stalled: 0x1017 is not answered in time
    respond(script)
    with pytest.raises(GatewayUnavailable):
        master.sdo.upload(0x1017, 0)
    assert master.sdo.upload(0x1000, 0) == DEVICE_TYPE
    assert master.counters.stale_sdo_answers == 2
    assert master.sdo.timeouts == 1


def test_an_answer_that_arrived_between_transfers_is_counted_when_the_next_one_starts(
        master: Master, respond: Callable[..., Responder]) -> None:
    late = threading.Event()

    def script(request: bytes) -> list[tuple[float, bytes]]:
        if _is(request, 0x40, 0x1017):
            if late.is_set():
                return [(0.0, HEARTBEAT_ANSWER)]
            late.set()
            return [(TIMEOUT + 0.1, HEARTBEAT_ANSWER)]  # after the transfer gave up
        return [(0.0, DEVICE_TYPE_ANSWER)]
    responder = respond(script)
    start = time.monotonic()
    with pytest.raises(GatewayUnavailable):
        master.sdo.upload(0x1017, 0)
    # the responder's thread answers the first 0x1017 request late, then the repeat at once
    time.sleep(max(0.0, start + TIMEOUT + 0.3 - time.monotonic()))
    assert len(responder.requests) == 2
    assert master.sdo.upload(0x1000, 0) == DEVICE_TYPE
    assert master.counters.stale_sdo_answers == 2


def test_only_stale_answers_end_in_the_current_requests_own_timeout(
        master: Master, respond: Callable[..., Responder]) -> None:
    respond(lambda request: [(0.0, HEARTBEAT_ANSWER)])  # always the old 0x1017 answer
    start = time.monotonic()
    with pytest.raises(GatewayUnavailable) as caught:
        master.sdo.upload(0x1000, 0)
    waited = time.monotonic() - start
    message = str(caught.value)
    assert message.startswith("SDO upload of 0x1000:00: node 5 did not answer within 0.400 s")
    assert "0x1017" not in message, message
    assert waited >= TIMEOUT * 0.95, f"gave up after {waited:.3f} s, not its own {TIMEOUT} s"
    assert master.counters.stale_sdo_answers == 2  # one per attempt


def test_an_abort_of_another_object_is_not_the_current_transfers_failure(
        master: Master, respond: Callable[..., Responder]) -> None:
    def script(request: bytes) -> list[tuple[float, bytes]]:
        if _is(request, 0x40, 0x1000):
            return [(0.0, _abort(0x1017, 0, 0x08000000)), (0.02, DEVICE_TYPE_ANSWER)]
        return [(0.0, _abort(0x2200, 1, 0x06020000))]  # its own abort: not in the dictionary
    respond(script)
    assert master.sdo.upload(0x1000, 0) == DEVICE_TYPE
    assert master.counters.stale_sdo_answers == 1
    with pytest.raises(SdoAbortError) as caught:
        master.sdo.upload(0x2200, 1)
    assert caught.value.code == 0x06020000
    assert master.counters.stale_sdo_answers == 1


def test_frames_too_short_for_an_answer_are_set_aside(
        master: Master, respond: Callable[..., Responder]) -> None:
    """An empty frame and a 2-byte abort (no multiplexer, no code) on 0x580 + id answer
    nothing; before, canopen's client read bytes 1-3 of whatever came first."""
    respond(lambda request: [(0.0, b""), (0.0, b"\x80\x00"), (0.02, DEVICE_TYPE_ANSWER)])
    assert master.sdo.upload(0x1000, 0) == DEVICE_TYPE
    assert master.counters.stale_sdo_answers == 2


def test_a_download_takes_its_own_confirmation_not_an_upload_answer_of_the_same_object(
        master: Master, respond: Callable[..., Responder]) -> None:
    def script(request: bytes) -> list[tuple[float, bytes]]:
        if not _is(request, 0x2B, 0x1017):  # expedited download of 2 bytes
            return []
        return [(0.0, HEARTBEAT_ANSWER), (0.02, bytes([0x60, 0x17, 0x10, 0, 0, 0, 0, 0]))]
    respond(script)
    master.sdo.download(0x1017, 0, (100).to_bytes(2, "little"))
    assert master.counters.stale_sdo_answers == 1


def test_a_repeated_segment_answer_is_set_aside_by_its_toggle_bit(
        master: Master, respond: Callable[..., Responder]) -> None:
    text = b"XN-GW-CANOPEN"  # 13 bytes: two segments of 7 and 6

    def segment(toggle: int, chunk: bytes, last: bool) -> bytes:
        return bytes([toggle << 4 | (7 - len(chunk)) << 1 | last]) + chunk.ljust(7, b"\0")

    def script(request: bytes) -> list[tuple[float, bytes]]:
        if _is(request, 0x40, 0x1008):  # initiate: segmented, size indicated
            return [(0.0, bytes([0x41, 0x08, 0x10, 0x00]) + len(text).to_bytes(4, "little"))]
        if request[0] == 0x60:  # first segment (toggle 0)
            return [(0.0, segment(0, text[:7], False))]
        if request[0] != 0x70:
            return []
        # second segment (toggle 1): the first one's answer again, then its own
        return [(0.0, segment(0, text[:7], False)), (0.02, segment(1, text[7:], True))]
    respond(script)
    assert master.sdo.upload(0x1008, 0) == text
    assert master.counters.stale_sdo_answers == 1


def test_the_masters_counter_reaches_the_bus_diagnostics(station, channel: str) -> None:
    """Through ``BridgeClient`` on the simulated station: a stale answer on 0x580 + id is
    counted in the client's counters, which the node's bus status lists (ros/node_status.py:
    ``dataclasses.asdict(client.counters)`` into ``bus_status``)."""
    from ssi_bridge.ros.diagnostics import bus_status

    _, client, _ = station
    other = can.Bus(interface="virtual", channel=channel)
    try:  # 0x1017:00 answered once more, long after the master asked
        other.send(can.Message(arbitration_id=RESPONSE_ID, data=HEARTBEAT_ANSWER,
                               is_extended_id=False))
    finally:
        other.shutdown()
    time.sleep(0.1)
    assert client.read_object(0x1000) == DEVICE_TYPE_OBJECT
    # the planted answer, and on a busy machine also the read's own first answer when it came
    # after the read's repeat: each set aside and counted
    stale = client.counters.stale_sdo_answers
    assert stale >= 1
    status = bus_status("/ssi_bridge: bus", "can", alive=True, connected=True,
                        achieved_rate=100.0, publish_rate=100.0,
                        counters=dataclasses.asdict(client.counters))
    assert {kv.key: kv.value for kv in status.values}["stale_sdo_answers"] == str(stale)
