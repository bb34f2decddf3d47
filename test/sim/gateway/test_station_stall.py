"""A station process stopped (SIGSTOP) and resumed (SIGCONT) while its master sends SYNCs.

A real gateway's CAN controller holds a few frames and loses the rest; the firmware latches
when it handles a SYNC and its frames are on the wire when they are sent (docs/canopen.md
"Stalls"; CiA 301: EMCY 0x8110 "CAN overrun (objects lost)", error register bit 4). Checked
frame by frame with a passive listener on the same udp_multicast bus and against the truth
oracle (test/support/truth.py), which knows where the encoder was at any wire time from the
node's parameters and the station's motion epoch, read over SDO from object 0x4004.
QUEUE_BACKLOG (fault 11) is the queueing device: every SYNC answered after the stall, each
latched at its own SYNC's wire time, its TPDOs stamped when really sent.
"""

from __future__ import annotations

import os
import signal
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import can
import pytest
import yaml

from ssi_bridge.base.realtime import fifo_permitted, fifo_this_thread
from ssi_bridge.base.timebase import frame_wire_time, wire_now
from ssi_bridge.base.udp_bus import derive_channel, open_udp_bus
from ssi_bridge.client.master import BridgeClient
from ssi_bridge.protocol.dictionary import SIM_COMMAND, SIM_DURATION, SIM_EPOCH, SIM_RATE
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
from ssi_bridge.sim.gateway.controller import HANDLING_GRACE_S, RX_FIFO_DEPTH
from ssi_bridge.sim.gateway.simulation import FaultKind, command_word
from support.truth import TruthOracle

PERIOD = 0.005  # the master's SYNC period (200 Hz)
#: the station's SCHED_FIFO priority, as the node starts it (simulation.station_priority):
#: a station starved beyond the 20 ms grace by other load would overrun on its own
PRIORITY = 10 if fifo_permitted(10) else 0
#: the SYNC producer's priority (the node's cycle_priority): a master that wakes late puts
#: its SYNC out late, and the station's answer, sent when it has the SYNC, with it
CYCLE_PRIORITY = 5 if PRIORITY else 0
STALL = 0.5  # s the station process is stopped
PARAMS = {"joints": ["j"], "j.family": "GENERIC", "j.motion.kind": "constant",
          "j.motion.velocity": 0.25}
TPDO_POS, TPDO_IMAGE, EMCY, SYNC = 0x1E1, 0x181, 0x081, 0x080
#: what station 1 sends: TPDO1, TPDO9, EMCY, heartbeat, SDO responses
STATION_IDS = {TPDO_IMAGE, TPDO_POS, EMCY, 0x701, 0x581}


class Sniffer:
    """Every frame on the bus: (id, data, wire time, kernel receive time)."""

    def __init__(self, channel: str) -> None:
        self.frames: list[tuple[int, bytes, float, float]] = []
        self._bus = open_udp_bus(channel)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self._bus.recv(0.05)
            if msg is not None:
                self.frames.append((msg.arbitration_id, bytes(msg.data), frame_wire_time(msg),
                                    msg.timestamp))

    def close(self) -> list[tuple[int, bytes, float, float]]:
        self._stop.set()
        self._thread.join(2.0)
        self._bus.shutdown()
        return self.frames


@pytest.fixture
def rig(tmp_path: Path) -> Iterator[tuple[subprocess.Popen, BridgeClient, str, float]]:
    """A station process on a private udp_multicast bus, our master OPERATIONAL on it."""
    channel = derive_channel(f"stall-{os.getpid()}-{time.monotonic_ns()}")
    params = tmp_path / "params.yaml"
    nested = {"joints": ["j"], "j": {"family": "GENERIC",
                                     "motion": {"kind": "constant", "velocity": 0.25}}}
    params.write_text(yaml.safe_dump({"ssi_bridge": {"ros__parameters": nested}}))
    proc = subprocess.Popen(
        [sys.executable, "-m", "ssi_bridge.sim.program", "--params-file", str(params),
         "--interface", "udp_multicast", "--channel", channel, "--priority", str(PRIORITY)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout is not None
    line = proc.stdout.readline().decode()
    assert line.startswith("station ready"), line
    client = BridgeClient(BusConfig(interface="udp_multicast", channel=channel), 1, 1,
                          opener=wire_bus)
    try:
        client.connect()
        epoch = client.read_object(SIM_EPOCH) / 1e6
        yield proc, client, channel, epoch
    finally:
        client.close()
        proc.send_signal(signal.SIGCONT)
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=20)


def _run(proc: subprocess.Popen, client: BridgeClient, channel: str
         ) -> tuple[list[tuple[int, bytes, float, float]], list[float], float, float]:
    """SYNCs at 200 Hz: 0.3 s, the station stopped for STALL s, 0.5 s after; returns the
    frames seen, the wire times of every SYNC on the bus (the master's handshake sends some
    of its own), and the wire times of the stop and the resume."""
    sniffer = Sniffer(channel)
    times: dict[str, float] = {}

    def cycle() -> None:  # the master's SYNC producer, SCHED_FIFO as the node's cycle thread
        fifo_this_thread(CYCLE_PRIORITY)
        start = time.monotonic()
        k = 0
        while True:
            elapsed = time.monotonic() - start
            if "stopped" not in times and elapsed >= 0.3:
                proc.send_signal(signal.SIGSTOP)
                times["stopped"] = wire_now()
            if "stopped" in times and "resumed" not in times and elapsed >= 0.3 + STALL:
                proc.send_signal(signal.SIGCONT)
                times["resumed"] = wire_now()
            if elapsed >= 0.8 + STALL:
                return
            client.sync()
            k += 1
            time.sleep(max(0.0, start + k * PERIOD - time.monotonic()))

    try:
        producer = threading.Thread(target=cycle, name="test-sync")
        producer.start()
        producer.join(10.0)
        time.sleep(0.1)
    finally:
        frames = sniffer.close()
    stopped, resumed = times["stopped"], times["resumed"]
    return frames, [f[2] for f in frames if f[0] == SYNC], stopped, resumed


def _position(oracle: TruthOracle, data: bytes) -> float:
    """The joint position the node makes of TPDO9's 0x6820:1 (INTEGER32, 000 Table 40)."""
    return oracle.joints["j"].scale.position(struct.unpack_from("<i", data)[0])


def test_a_stopped_station_keeps_its_fifo_latches_when_it_handles_and_says_overrun(rig) -> None:
    proc, client, channel, epoch = rig
    oracle = TruthOracle.from_params(PARAMS, epoch)
    counts_per_s = oracle.max_speed("j") * oracle.counts_per_unit("j")
    frames, syncs, stopped, resumed = _run(proc, client, channel)
    own = [f for f in frames if f[0] in STATION_IDS]
    # nothing is stamped before it was sent: a frame's wire time is not far before the
    # moment it reached us (before this change, late answers claimed times 0.5 s back);
    # a frame the stop caught between its end on the wire and its datagram arrives late
    assert max(rx - wire for _, _, wire, rx in own if wire > stopped) < 0.1
    assert not [f for f in own if stopped + 0.05 < f[2] < resumed - 0.01]
    # one overrun episode, one EMCY 0x8110, communication error bit (CiA 301)
    overruns = [f for f in own if f[0] == EMCY and f[1][:2] == b"\x10\x81" and f[2] > stopped]
    assert len(overruns) == 1, overruns
    assert overruns[0][1][2] & 0x10 and overruns[0][2] >= resumed
    # SYNCs handled back to back read the SSI line one after the other: no false ERR_SSI
    # (000 "Error detection": EMCY 0x7000 would carry the SSI error bit 0x02)
    assert not [f for f in own if f[0] == EMCY and f[1][:2] == b"\x00\x70"]
    # every answer after the resume latched then or later, none at a SYNC of the stall
    after = [f for f in own if f[0] == TPDO_POS and f[2] >= resumed]
    assert after
    for _, data, wire, _ in after:
        lag = -oracle.residual("j", wire, _position(oracle, data)) / counts_per_s  # latch = wire - lag
        assert -2.0 / counts_per_s <= lag, "latched after it was sent"
        assert wire - lag >= resumed - HANDLING_GRACE_S - 0.005, \
            f"latched {resumed - (wire - lag):.3f} s before the resume"
    # the answers to SYNCs of the stall: at most what the FIFO held
    next_sync = min(s for s in syncs if s > resumed)
    assert len([f for f in after if f[2] < next_sync]) <= RX_FIFO_DEPTH
    # and the station runs on: later SYNCs answered, nearly all latched at their own wire
    # time (one its process got to beyond the grace latched when it got to it, above)
    later = [f for f in after if f[2] > next_sync + 0.1]
    assert len(later) > 30
    exact = [f for f in later
             if abs(oracle.residual("j", max(s for s in syncs if s < f[2]),
                                    _position(oracle, f[1]))) <= 1.0]
    assert len(exact) >= 0.9 * len(later)


def test_queue_backlog_answers_every_sync_of_the_stall_at_its_own_latch(rig) -> None:
    proc, client, channel, epoch = rig
    client.write_object(SIM_RATE, 0, 0.0)
    client.write_object(SIM_DURATION, 0, 0)
    client.write_object(SIM_COMMAND, 0, command_word(FaultKind.QUEUE_BACKLOG, 0))
    oracle = TruthOracle.from_params(PARAMS, epoch)
    frames, syncs, stopped, resumed = _run(proc, client, channel)
    own = [f for f in frames if f[0] in STATION_IDS]
    assert not [f for f in own if f[0] == EMCY and f[1][:2] == b"\x10\x81"]
    assert not [f for f in own if stopped + 0.05 < f[2] < resumed - 0.01]
    stall_syncs = [s for s in syncs if stopped + 0.01 < s < resumed]
    assert len(stall_syncs) > 50
    late = sorted((f for f in own if f[0] == TPDO_POS and f[2] >= resumed), key=lambda f: f[2])
    # every SYNC of the stall answered after it, in order, latched at that SYNC's wire time
    answers = {}
    for _, data, wire, _ in late:
        for s in stall_syncs:
            if abs(oracle.residual("j", s, _position(oracle, data))) <= 1.0:
                answers[s] = wire
                break
    # (a few may go unanswered: the master's supervisor, which saw the heartbeat stop, sends
    # NMT commands that queue with them, and no PDO goes out outside OPERATIONAL)
    assert len(answers) >= 0.9 * len(stall_syncs)
    assert all(wire >= resumed for wire in answers.values())  # stamped when really sent
