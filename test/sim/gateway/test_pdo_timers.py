"""TPDO inhibit time (0x1800+n sub 3) and event timer (sub 5) per CiA 301, on a fake clock.

CiA 301 7.5.2.35 (TPDO communication parameter): sub 3 "inhibit time", the minimum time
between two transmissions of the PDO, in multiples of 100 µs, not changeable while the PDO
exists; sub 5 "event timer", in ms: an elapsed timer is an event that sends an event-driven
(254/255) TPDO, restarted by every transmission; 0 = off. The engine's clock is replaced by a
fake one the test advances, and ``tick()`` is called directly, so nothing depends on timing.
"""

from __future__ import annotations

import threading

import pytest
from canopen.sdo import SdoAbortedError

from ssi_bridge.protocol.aborts import SdoAbort
from ssi_bridge.protocol.dictionary import tpdo_cob_base

from .conftest import NODE_ID

COB = tpdo_cob_base(9) + NODE_ID


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0  # steps below add up exactly in binary floating point from 0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def timed(station):
    """TPDO9 = 0x6820:1 (slot 1 position), type 255; frames on its COB-ID are collected."""
    st = station
    clock = FakeClock()
    st.gateway.pdo._clock = clock
    frames: list[bytes] = []
    got = threading.Event()

    def on_frame(can_id, data, timestamp):
        frames.append(bytes(data))
        got.set()

    st.network.subscribe(COB, on_frame)
    sdo = st.node.sdo
    sdo[0x1808][1].raw = 0x8000_0000 | COB
    sdo[0x1A08][0].raw = 0
    sdo[0x1A08][1].raw = 0x6820_0120
    sdo[0x1A08][0].raw = 1
    sdo[0x1808][2].raw = 255
    yield st, clock, frames, sdo
    st.network.unsubscribe(COB, on_frame)


def _operational(st) -> None:
    st.node.nmt.state = "OPERATIONAL"
    st.wait_for(lambda: st.gateway.nmt_state == "OPERATIONAL", "gateway not OPERATIONAL")


def test_inhibit_time_holds_a_change_until_it_ends(timed) -> None:
    st, clock, frames, sdo = timed
    sdo[0x1808][3].raw = 100            # 100 x 100 µs = 10 ms
    sdo[0x1808][1].raw = COB            # valid
    _operational(st)
    st.sync()
    st.wait_for(lambda: len(frames) == 1, "first TPDO not sent")
    st.readers[0].value = 1234
    clock.t += 0.005                    # 5 ms after: inside the inhibit time
    st.sync()
    assert st.gateway.pdo.tpdos[8].held is not None, "change held back by the inhibit time"
    assert len(frames) == 1
    clock.t += 0.005                    # 10 ms after the first transmission
    with st.gateway._lock:
        st.gateway.pdo.tick()
    st.wait_for(lambda: len(frames) == 2, "held TPDO not sent when the inhibit time ended")
    assert int.from_bytes(frames[1], "little") == 1234


def test_inhibit_time_cannot_change_while_the_pdo_exists(timed) -> None:
    st, clock, frames, sdo = timed
    sdo[0x1808][1].raw = COB
    with pytest.raises(SdoAbortedError) as info:
        sdo[0x1808][3].raw = 10
    assert info.value.code == SdoAbort.CANNOT_STORE_STATE
    sdo[0x1808][5].raw = 50             # the event timer may change at any time


def test_event_timer_sends_without_a_change(timed) -> None:
    st, clock, frames, sdo = timed
    sdo[0x1808][5].raw = 20             # 20 ms
    sdo[0x1808][1].raw = COB
    _operational(st)
    st.sync()                           # data changed (first time): sent, timer restarts
    st.wait_for(lambda: len(frames) >= 1, "first TPDO not sent")
    n = len(frames)
    clock.t += 0.010
    with st.gateway._lock:
        due = st.gateway.pdo.tick()
    assert len(frames) == n and due == pytest.approx(0.010)
    clock.t += 0.010                    # 20 ms without a transmission: the timer fires
    with st.gateway._lock:
        st.gateway.pdo.tick()
    st.wait_for(lambda: len(frames) == n + 1, "event timer did not send the TPDO")
    assert frames[-1] == frames[n - 1], "same data again"
    sdo[0x1808][5].raw = 0              # off: nothing more without a change
    clock.t += 1.0
    with st.gateway._lock:
        st.gateway.pdo.tick()
    assert len(frames) == n + 1
