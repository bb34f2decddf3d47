"""Frames a CiA 301 service does not allow are counted as malformed, on both ends, never raised.

CiA 301 fixes the length of a heartbeat (1 byte: the NMT state), an EMCY (8), every SDO frame
(8) and an NMT command (2). Before, an empty heartbeat 0x701 raised inside canopen's
``NmtMaster.on_heartbeat`` (``callback_errors`` +1 and an ERROR line on the master), and an SDO
segment that belongs to no transfer made the station's canopen ``SdoServer`` log a traceback
(``AttributeError: 'NoneType' object has no attribute 'extend'``). Now the master counts them
in ``malformed_frames`` (published in the bus diagnostics, as ``malformed_pdos``), the station
in its listener's faults, each logged at most once per second per kind; a segment outside a
transfer and a request with command specifier 7 are answered with the abort 0x05040001
("command specifier not valid or unknown"). A real station and master on CAN over UDP
multicast (loopback), the frames sent by a third node on the same bus.
"""

from __future__ import annotations

import logging
import random
import struct
import time

import can
import pytest

from ssi_bridge.base.udp_bus import open_udp_bus
from ssi_bridge.client.master import BridgeClient
from ssi_bridge.exceptions import GatewayUnavailable, SdoAbortError

from .conftest import run_cycles, wait_until

NODE = 1
#: the abort a segment outside a transfer gets: 0x80, multiplexer 0, code 0x05040001
ABORT_INVALID_COMMAND = struct.pack("<BHBL", 0x80, 0, 0, 0x0504_0001)


@pytest.fixture
def bus_pair(udp_station):
    """The station and master of ``udp_station``, and a third node on their bus."""
    channel, station, client = udp_station
    tool = open_udp_bus(channel)
    try:
        yield station, client, tool
    finally:
        tool.shutdown()


def _send(bus: can.BusABC, can_id: int, data: bytes) -> None:
    bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))


def _drain(tool: can.BusABC) -> None:
    """Forget what the third node heard so far (the master's configuration since it joined)."""
    end = time.monotonic() + 2.0
    while tool.recv(0.05) is not None and time.monotonic() < end:
        pass


def _answers(tool: can.BusABC, n: int, timeout: float = 3.0) -> list[bytes]:
    """The next ``n`` SDO answers of the station (0x580 + id) the third node hears."""
    answers: list[bytes] = []
    end = time.monotonic() + timeout
    while len(answers) < n and time.monotonic() < end:
        msg = tool.recv(0.1)
        if msg is not None and msg.arbitration_id == 0x580 + NODE:
            answers.append(bytes(msg.data))
    return answers


def _read(client: BridgeClient, index: int = 0x1000, subindex: int = 0) -> int:
    """``index:subindex`` read by the master after the third node's SDO requests.

    They share the master's SDO channel (0x600/0x580 + id; CiA 301: one client per channel),
    so their answers reach the master's SDO client too: one still on the way when the master
    asks is taken for its answer (an abort, or a value of another object). The master asks
    again then, at most five times; each request first drops the answers queued before it."""
    for attempt in range(5):
        try:
            return int(client.read_object(index, subindex))
        except (SdoAbortError, GatewayUnavailable):
            if attempt == 4:
                raise
            time.sleep(0.05)  # the rest of the third node's answers land meanwhile
    raise AssertionError("unreachable")


def _no_tracebacks(caplog: pytest.LogCaptureFixture) -> None:
    bad = [r.getMessage() for r in caplog.records if r.exc_info or r.levelno >= logging.ERROR]
    assert not bad, bad


def test_the_master_counts_an_empty_heartbeat_a_short_emcy_and_sdo(bus_pair, caplog):
    station, client, tool = bus_pair
    caplog.set_level(logging.WARNING)
    assert run_cycles(client, 3) >= 2
    frames = [(0x700 + NODE, b""),                  # an empty heartbeat
              (0x700 + NODE, b"\x05\x00"),          # a heartbeat is 1 byte
              (0x080 + NODE, b"\x00\x70\x01"),      # an EMCY is 8 bytes
              (0x580 + NODE, b"\x43\x00\x10")]      # an SDO response is 8 bytes
    for can_id, data in frames:
        _send(tool, can_id, data)
    wait_until(lambda: client.counters.malformed_frames == len(frames),
          f"malformed frames counted: {client.counters.malformed_frames} of {len(frames)}")
    assert client.counters.callback_errors == 0 and client.counters.emergencies == 0
    lines = [r.getMessage() for r in caplog.records if "malformed so far" in r.getMessage()
             and r.getMessage().startswith("master")]
    assert lines and "0x701 [] with 0 byte(s) is no heartbeat of node 1" in lines[0], lines
    assert len(lines) <= 2, lines                   # at most once per second
    _no_tracebacks(caplog)
    # the master goes on: cycles, SDO, and the real heartbeat keeps the gateway alive
    assert run_cycles(client, 5) >= 4
    assert int(client.read_object(0x1000, 0)) == 0x191
    assert client.gateway_alive


def test_the_station_refuses_stray_sdo_segments_and_short_requests(bus_pair, caplog):
    station, client, tool = bus_pair
    caplog.set_level(logging.WARNING)
    listener = station.gateway.listener
    _drain(tool)
    frames = [bytes([0x00]) + bytes(7),             # download segment, no transfer: 'extend'
              bytes([0x60]) + bytes(7),             # upload segment, no transfer
              bytes([0xE0, 0x00, 0x10, 0x00]) + bytes(4),   # specifier 7: none of CiA 301's
              b"\x40\x00\x10",                      # an initiate upload of 3 bytes
              b""]
    for data in frames:
        _send(tool, 0x600 + NODE, data)
    _send(tool, 0x000, b"\x81")                     # an NMT command is 2 bytes
    wait_until(lambda: listener.faults["malformed_frames"] == len(frames) + 1,
          f"station counted {dict(listener.faults)}")
    answers = _answers(tool, 3)
    assert answers[:2] == [ABORT_INVALID_COMMAND] * 2, answers
    assert answers[2] == struct.pack("<BHBL", 0x80, 0x1000, 0, 0x0504_0001), answers
    assert listener.faults["callback_errors"] == 0, dict(listener.faults)
    assert any("SDO segment outside a transfer" in r.getMessage() for r in caplog.records)
    _no_tracebacks(caplog)
    # not reset by the short NMT command, and still serving the master
    assert station.gateway.nmt_state == "OPERATIONAL"
    assert _read(client) == 0x191
    assert run_cycles(client, 5) >= 4


def test_random_sdo_requests_never_raise_in_the_station(bus_pair, caplog):
    # seeded random requests: every specifier, random multiplexers of read requests, random
    # bytes; writes are left out (they would reconfigure the station the master drives)
    station, client, tool = bus_pair
    caplog.set_level(logging.WARNING)
    rng = random.Random(34)
    for _ in range(400):
        ccs = rng.choice([0x00, 0x40, 0x60, 0x80, 0xA0, 0xC0, 0xE0])
        command = ccs | rng.randrange(0x20)
        index = rng.choice([0x1000, 0x1008, 0x1018, 0x2000, 0x6820, rng.randrange(0x10000)])
        data = struct.pack("<BHB", command, index, rng.randrange(4)) + rng.randbytes(4)
        _send(tool, 0x600 + NODE, data)
        time.sleep(0.0005)
    # answered after the burst: the station has handled every frame of it
    assert _read(client) == 0x191
    assert station.gateway.listener.faults["callback_errors"] == 0
    assert station.gateway.listener.faults["malformed_frames"] > 0
    _no_tracebacks(caplog)
    assert run_cycles(client, 5) >= 4


def test_a_stray_segment_after_a_segmented_download_writes_nothing(bus_pair, caplog):
    # CiA 301 segmented download of 0x6C01:1 (work area low limit, INTEGER32) by the master,
    # then a last segment from the third node: no transfer runs, so it is refused, and the
    # object keeps what the transfer wrote (canopen's server appended it to the finished
    # transfer's buffer and wrote the object again)
    station, client, tool = bus_pair
    caplog.set_level(logging.WARNING)
    client.node.sdo.download(0x6C01, 1, struct.pack("<i", -77), force_segment=True)
    assert station.gateway.node.sdo.segments is None
    _drain(tool)
    _send(tool, 0x600 + NODE, bytes([0x01, 1, 2, 3, 4, 5, 6, 7]))
    assert _answers(tool, 1) == [ABORT_INVALID_COMMAND]
    assert station.gateway.listener.faults["malformed_frames"] == 1
    assert _read(client, 0x6C01, 1) == -77
    _no_tracebacks(caplog)
