"""Liveness runs on the monotonic clock: a step of the wall clock (NTP, an operator's
``date -s``) of +-1 h neither silences a gateway whose heartbeats keep coming nor keeps a
silent one alive, and the SDO probes and the silence summaries keep their pace (CiA 301
heartbeat consumer; ``client/liveness.py``).

Both clocks are injected: the supervisor's rounds are called one by one on a made-up time
line, the same line with and without the step, and must decide alike at every step.
"""

from __future__ import annotations

import logging

import pytest

from ssi_bridge.client.liveness import SILENT_SUMMARY_S, Liveness
from ssi_bridge.client.samples import ClientCounters
from ssi_bridge.exceptions import SsiBridgeError
from ssi_bridge.protocol.dictionary import NMT_STATE_OPERATIONAL

HEARTBEAT_MS = 50
TIMEOUT = 4 * HEARTBEAT_MS / 1000.0
DT = 0.01  # one tick of the made-up time line
STEP_S = 3600.0


class Clocks:
    """The monotonic clock and the wall (wire) clock; the wall one may be stepped."""

    def __init__(self) -> None:
        self.mono = 1000.0
        self.offset = 1.7e9 - 1000.0  # wall = mono + offset

    def monotonic(self) -> float:
        return self.mono

    def wall(self) -> float:
        return self.mono + self.offset


class Receive:
    """What ``ReceiveWatch`` keeps: the newest frame stamp and the wire time the receive path
    last found nothing waiting (``seen_until`` = the later one), on the wall clock."""

    def __init__(self, clocks: Clocks) -> None:
        self._clocks = clocks
        self.rx_latest = 0.0
        self.rx_idle_at = 0.0

    def frame(self, stamp: float) -> None:
        self.rx_latest = max(self.rx_latest, stamp)

    def idle(self) -> None:
        self.rx_idle_at = self._clocks.wall()

    def seen_until(self) -> float:
        return max(self.rx_latest, self.rx_idle_at)


class Client:
    """The parts of ``BridgeClient`` the supervisor uses (``Supervised``)."""

    node_id = 1
    heartbeat_ms = HEARTBEAT_MS
    heartbeat_timeout = TIMEOUT

    def __init__(self, clocks: Clocks) -> None:
        self.counters = ClientCounters()
        self.bus = Receive(clocks)
        self.liveness = Liveness(self, clock=clocks.monotonic, wire_clock=clocks.wall)
        self.probes = 0
        self.configurations = 0

    @property
    def gateway_alive(self) -> bool:
        return self.liveness.alive()

    def read_object(self, index: int, subindex: int = 0) -> int:
        self.probes += 1
        raise SsiBridgeError("SDO timeout: no answer from node 1")

    def configure(self) -> None:
        self.configurations += 1


def run(step_at: float | None, step: float, silent_from: float, end: float,
        stall: tuple[float, float] | None = None) -> tuple[list[bool], int, int]:
    """Heartbeats every HEARTBEAT_MS until ``silent_from`` (s after the start), the wall clock
    stepped by ``step`` at ``step_at``; the receive path handles the wire every tick except
    during ``stall`` (start, end). Returns alive() at every tick, the SDO probes and the
    heartbeats handled."""
    clocks = Clocks()
    client = Client(clocks)
    live = client.liveness
    live.started()
    period = HEARTBEAT_MS / 1000.0
    alive, beats, queued = [], 0, []
    t = 0.0
    next_beat = period
    while t < end:
        t = round(t + DT, 6)
        clocks.mono += DT
        if step_at is not None and abs(t - step_at) < DT / 2:
            clocks.offset += step
        if t >= next_beat - 1e-9 and t < silent_from:
            queued.append(clocks.wall())  # on the wire now, stamped by the bus
            next_beat += period
        stalled = stall is not None and stall[0] <= t < stall[1]
        if not stalled:
            for stamp in queued:
                client.bus.frame(stamp)
                live.on_heartbeat_frame(0x701, bytearray([NMT_STATE_OPERATIONAL]), stamp)
                beats += 1
            queued.clear()
            client.bus.idle()
        alive.append(client.gateway_alive)
        if round(t / period, 6).is_integer():  # a supervisor round every period
            live._round(period)
    return alive, client.probes, beats


@pytest.mark.parametrize("step", [STEP_S, -STEP_S], ids=["forward_1h", "back_1h"])
def test_a_live_gateway_stays_alive_across_a_step(step: float) -> None:
    alive, probes, beats = run(step_at=1.0, step=step, silent_from=99.0, end=3.0)
    assert beats > 50 and all(alive), [i for i, a in enumerate(alive) if not a]
    assert probes == 0


@pytest.mark.parametrize("step", [STEP_S, -STEP_S], ids=["forward_1h", "back_1h"])
@pytest.mark.parametrize("step_at", [0.95, 1.1, 2.0], ids=["before", "while_alive", "after"])
def test_a_silent_gateway_is_found_as_without_the_step(step: float, step_at: float) -> None:
    """Silent from 1.0 s: found after the timeout, at the same tick as without a step, and
    probed over SDO just as often (every 5 heartbeat periods)."""
    expected, expected_probes, _ = run(step_at=None, step=0.0, silent_from=1.0, end=4.0)
    alive, probes, _ = run(step_at=step_at, step=step, silent_from=1.0, end=4.0)
    first_silent = expected.index(False)
    last_beat = 0.95  # the last heartbeat before 1.0 s (every 50 ms)
    assert last_beat + TIMEOUT < (first_silent + 1) * DT <= last_beat + TIMEOUT + 3 * DT
    assert not any(expected[first_silent:])
    assert alive == expected
    assert probes == expected_probes > 0


@pytest.mark.parametrize("step", [STEP_S, -STEP_S], ids=["forward_1h", "back_1h"])
def test_the_silence_summary_keeps_its_pace_across_a_step(step: float,
                                                          caplog: pytest.LogCaptureFixture
                                                          ) -> None:
    """One 'still silent' line after SILENT_SUMMARY_S of silence, not at once (a step forward)
    and not never (a step back)."""
    caplog.set_level(logging.WARNING, logger="ssi_bridge.client.liveness")
    end = 1.0 + SILENT_SUMMARY_S
    run(step_at=2.0, step=step, silent_from=1.0, end=end - 1.0)
    assert "still silent" not in caplog.text
    caplog.clear()
    run(step_at=2.0, step=step, silent_from=1.0, end=end + 1.0)
    assert caplog.text.count("still silent") == 1, caplog.text


def test_a_stalled_receive_path_is_no_silence() -> None:
    """Heartbeats on the wire but not handled (the receive path stalls 3 timeouts) do not
    count as missing: the seen_until guard, on the wire clock alone."""
    stall = (1.0, 1.0 + 3 * TIMEOUT)
    alive, _, _ = run(step_at=None, step=0.0, silent_from=99.0, end=2.0, stall=stall)
    assert all(alive), [round((i + 1) * DT, 2) for i, a in enumerate(alive) if not a]
    # the same stall while the gateway really went silent just before it: found after it
    alive, _, _ = run(step_at=None, step=0.0, silent_from=0.9, end=2.0, stall=stall)
    assert not alive[-1]
