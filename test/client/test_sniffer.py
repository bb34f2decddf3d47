"""The CAN sniffer logs both directions of a real exchange in python-can's candump format."""

from __future__ import annotations

import time
from pathlib import Path

import can
import pytest

from ssi_bridge.client.sniffer import CanSniffer
from ssi_bridge.protocol.settings import BusConfig


def test_sniffer_logs_every_frame_and_the_log_reads_back(tmp_path: Path):
    config = BusConfig(channel="sniffer_test")
    sniffer = CanSniffer(config, tmp_path / "can_0.log")
    a = can.Bus(interface="virtual", channel="sniffer_test")
    b = can.Bus(interface="virtual", channel="sniffer_test")
    try:
        a.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))  # SYNC
        b.send(can.Message(arbitration_id=0x181, data=bytes(range(8)), is_extended_id=False))
        deadline = time.monotonic() + 2.0
        while sniffer.frames < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        a.shutdown()
        b.shutdown()
        logged = sniffer.stop()
    assert logged == 2
    frames = list(can.LogReader(str(tmp_path / "can_0.log")))
    assert [(f.arbitration_id, bytes(f.data)) for f in frames] == [
        (0x080, b""), (0x181, bytes(range(8)))]


def test_frames_sent_just_before_stop_are_logged(tmp_path: Path):
    # nothing waits for the notifier thread here: stop() itself must drain what was received
    for attempt in range(5):
        path = tmp_path / f"burst{attempt}.log"
        sniffer = CanSniffer(BusConfig(channel=f"sniffer_burst{attempt}"), path)
        sender = can.Bus(interface="virtual", channel=f"sniffer_burst{attempt}")
        try:
            for i in range(50):
                sender.send(can.Message(arbitration_id=0x180 + i % 8, data=bytes([i]),
                                        is_extended_id=False))
        finally:
            sender.shutdown()
            logged = sniffer.stop()
        assert logged == 50
        assert [bytes(f.data)[0] for f in can.LogReader(str(path))] == list(range(50))


def test_a_full_disk_stops_the_log_cleanly_and_leaves_it_readable(tmp_path: Path, small_fs):
    # a real ENOSPC: the log lives on a 64 kB tmpfs; about 1500 candump lines fill it
    fs = small_fs(64 * 1024)
    path = fs / "can_0.log"
    errors: list[str] = []
    sniffer = CanSniffer(BusConfig(channel="sniffer_full"), path, on_error=errors.append)
    sender = can.Bus(interface="virtual", channel="sniffer_full")
    try:
        sent = 0
        deadline = time.monotonic() + 60.0
        while not errors and time.monotonic() < deadline:
            sender.send(can.Message(arbitration_id=0x181, data=bytes(8), is_extended_id=False))
            sent += 1
            if sent % 100 == 0:
                time.sleep(0.001)  # let the notifier thread keep up
        assert errors, f"no write error reported after {sent} frames"
        assert str(path) in errors[0] and "errno 28" in errors[0], errors
        # stopped: it no longer reads the bus, so nothing queues up for it
        stop_deadline = time.monotonic() + 10.0
        while not sniffer._notifier.stopped and time.monotonic() < stop_deadline:
            time.sleep(0.01)
        for _ in range(5000):
            sender.send(can.Message(arbitration_id=0x182, data=bytes(8), is_extended_id=False))
    finally:
        sender.shutdown()
        logged = sniffer.stop()  # after the error: no exception, no second report
    assert len(errors) == 1
    text = path.read_bytes()
    assert text.endswith(b"\n"), "the torn last line was cut off"
    frames = list(can.LogReader(str(path)))  # every line parses
    assert len(frames) == logged > 100
    assert all(f.arbitration_id == 0x181 for f in frames)


def test_a_udp_multicast_frame_is_logged_at_its_senders_wire_time(tmp_path: Path):
    # between processes the receive time is late by however long the sender slept past the
    # frame's end; the log keeps the wire time, so a replay stamps cycles as recorded
    import os

    from ssi_bridge.base.udp_bus import derive_channel, open_udp_bus
    from ssi_bridge.base.timebase import wire_now

    channel = derive_channel(f"sniffer-udp-{os.getpid()}")
    sniffer = CanSniffer(BusConfig(interface="udp_multicast", channel=channel),
                         tmp_path / "can_0.log")
    sender = open_udp_bus(channel)
    try:
        stamped = round(wire_now(), 3) - 0.030  # ms: the candump text keeps 6 decimals
        sender.send(can.Message(arbitration_id=0x080, is_extended_id=False, timestamp=stamped))
        deadline = time.monotonic() + 5.0
        while sniffer.frames < 1 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        sender.shutdown()
        sniffer.stop()
    (frame,) = list(can.LogReader(str(tmp_path / "can_0.log")))
    assert frame.timestamp == pytest.approx(stamped, abs=1e-6)
