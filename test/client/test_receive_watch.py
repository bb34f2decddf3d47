"""``ReceiveWatch.seen_until``: the wire time up to which the master's receive path has
handled the wire (what liveness takes off a heartbeat's age, ``client/liveness.py``).

A real python-can virtual bus carries the frames; the wall (wire) clock the watch reads is
replaced to step it back by an hour, as NTP or ``date -s`` would.
"""

from __future__ import annotations

import time
import uuid

import can
import pytest

from ssi_bridge.client import bus as client_bus
from ssi_bridge.client.bus import ReceiveWatch

STEP_S = 3600.0


@pytest.fixture
def buses():
    channel = f"watch_{uuid.uuid4().hex}"
    master = can.Bus(interface="virtual", channel=channel)
    # the sender keeps the stamps it is given: the frames' stamps follow the stepped clock
    other = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)
    watch = ReceiveWatch(master)
    yield watch, other
    watch.shutdown()
    other.shutdown()


def _heartbeat(stamp: float) -> can.Message:
    return can.Message(arbitration_id=0x701, data=[5], is_extended_id=False, timestamp=stamp)


def test_seen_until_follows_frames_and_idle_receives(buses):
    watch, other = buses
    other.send(_heartbeat(time.time()))
    msg = watch.recv(1.0)
    assert msg is not None and watch.seen_until() == pytest.approx(msg.timestamp)
    assert watch.recv(0.0) is None  # nothing waiting: seen up to now
    assert msg.timestamp <= watch.seen_until() <= time.time()


def test_after_the_wall_clock_steps_back_seen_until_is_not_in_the_future(buses, monkeypatch):
    """Frames stamped before a step back must not hold ``seen_until`` an hour ahead of the
    wire clock: the first receive that finds the bus idle brings it back to now."""
    watch, other = buses
    other.send(_heartbeat(time.time()))
    assert watch.recv(1.0) is not None
    monkeypatch.setattr(client_bus, "wire_now", lambda: time.time() - STEP_S)
    assert watch.recv(0.0) is None
    assert watch.seen_until() <= client_bus.wire_now()
    # frames stamped on the stepped clock move it on again
    other.send(_heartbeat(time.time() - STEP_S))
    stepped = watch.recv(1.0)
    assert stepped is not None
    assert watch.seen_until() == pytest.approx(stepped.timestamp)
