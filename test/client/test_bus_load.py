"""Bus load from frame timestamps: the master's figures against the frame-length
formula applied to what an independent bus reader saw on the same wire."""

from __future__ import annotations

import time

import pytest

from ssi_bridge.client.master import BridgeClient
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
from ssi_bridge.sim.gateway.bus import open_bus
from ssi_bridge.sim.gateway.gateway import XnGateway
from ssi_bridge.protocol.wire import frame_bits
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi


@pytest.mark.parametrize("bitrate", [125_000, 1_000_000])
def test_bus_load_matches_the_formula_within_5_percent(channel, bitrate) -> None:
    from ssi_bridge.protocol.readout import LineReadout

    class Reader:
        def read(self, t: float, n_bits: int, bit_rate_hz: float) -> LineReadout:
            return LineReadout(latch_time=t, n_bits=n_bits, data=0x2A5A5 & ((1 << n_bits) - 1),
                               end_time=t + (n_bits + 1) / bit_rate_hz)

    config = BusConfig(channel=channel, node_id=5, bitrate=bitrate)
    gateway = XnGateway(config, 5, [Xn1Ssi(Reader(), slot=s) for s in (1, 2)])
    client = BridgeClient(config, 5, 2, sdo_timeout=1.0, opener=wire_bus)
    sniffer = open_bus(config)
    gateway.start()
    try:
        client.connect()
        seen = []
        end = time.monotonic() + 2.5
        while time.monotonic() < end:
            client.sync()
            client.wait_cycle(0.05)
            while (msg := sniffer.recv(0)) is not None:
                seen.append(msg)
            time.sleep(0.005)
        time.sleep(0.05)
        while (msg := sniffer.recv(0.01)) is not None:
            seen.append(msg)
        # the client's own SYNCs are not received by the sniffer of the same process? they are:
        # every bus on a virtual channel sees every other bus's frames
        last = max(m.timestamp for m in seen)
        figures = client.load.figures(now=last)
        window = [m for m in seen if m.timestamp >= last - client.load.window]
        busy = sum(frame_bits(m.arbitration_id, m.data, m.is_remote_frame) for m in window)
        expected = 100.0 * busy / bitrate / client.load.window
        assert float(figures["bus_load_percent"]) == pytest.approx(expected, rel=0.05, abs=0.1)
        syncs = sum(1 for m in window if m.arbitration_id == 0x80)
        assert float(figures["frames_per_cycle"]) == pytest.approx(len(window) / syncs, rel=0.05)
    finally:
        sniffer.shutdown()
        client.close()
        gateway.stop()


def test_a_wall_clock_step_back_empties_the_window_instead_of_growing_it() -> None:
    """Frames stamped before the wall clock stepped back 1 h lie 'in the future' of every
    later window: dropped, not kept (and counted) for the hour the step was."""
    import can

    from ssi_bridge.client.load import BusLoad

    load = BusLoad(500_000, window=1.0)
    t0 = 1.7e9
    for i in range(100):
        load.add(can.Message(arbitration_id=0x80, is_extended_id=False, timestamp=t0 + i * 1e-3))
    assert load.figures(now=t0 + 0.1)["frames_per_cycle"] == "1.00"
    stepped = t0 + 0.2 - 3600.0  # the clock stepped back 1 h
    load.add(can.Message(arbitration_id=0x80, is_extended_id=False, timestamp=stepped))
    figures = load.figures(now=stepped + 1e-3)
    assert len(load._frames) == 1 and figures["frames_per_cycle"] == "1.00"
    assert float(figures["bus_load_percent"]) < 0.1  # one SYNC frame in 1 s at 500 kbit/s


def test_queued_received_frames_give_the_figures_of_frames_counted_as_they_came() -> None:
    """The receive thread only queues a frame (``BusLoad.received``), a sent one is measured
    at once and queued behind it (``add``); the cycle thread once its cycle is over
    (``count_queued``), or the reader, counts them: the figures equal those of counting every
    frame as it came, and a frame is counted once however they meet."""
    import can

    from ssi_bridge.client.load import BusLoad

    t0 = 1.7e9
    eager, queued = BusLoad(1_000_000), BusLoad(1_000_000)
    for cycle in range(50):
        t = t0 + cycle * 2e-3
        sync = can.Message(arbitration_id=0x80, is_extended_id=False, timestamp=t)
        eager.add(sync)
        queued.add(sync)
        for k in range(12):  # an 8-slot cycle's TPDOs, changing payloads (stuff bits differ)
            data = ((cycle * 7919 + k * 104729) & 0xFFFFFFFF).to_bytes(4, "little") * 2
            tpdo = can.Message(arbitration_id=0x181 + k, data=data, is_extended_id=False,
                               timestamp=t + (k + 1) * 1.3e-4)
            eager.add(tpdo)
            queued.received(tpdo)
        if cycle % 3:
            queued.count_queued()
            assert not queued._queued
    queued.received(can.Message(arbitration_id=0x1, is_error_frame=True, timestamp=t0))
    now = t0 + 0.2
    figures = queued.figures(now=now)
    assert figures == eager.figures(now=now)
    assert figures["frames_per_cycle"] == "13.00"
    assert queued.figures(now=now) == figures  # counted once, not again at the next read


def test_the_figures_are_those_of_the_frames_in_the_window_however_many_came_before() -> None:
    """The window's wire time and SYNCs come from running totals (client/load.py): after
    3 s of frames, SYNC and TPDOs of varying content, the last second's figures equal the
    sum over exactly that second's frames (frame length by protocol/wire.frame_bits)."""
    import can

    from ssi_bridge.client.load import BusLoad

    load = BusLoad(1_000_000, window=1.0)
    t0 = 1.7e9
    sent: list[tuple[float, int, bool]] = []
    for cycle in range(3000):
        t = t0 + cycle * 1e-3
        frames = [can.Message(arbitration_id=0x80, is_extended_id=False, timestamp=t, data=b"")]
        frames += [can.Message(arbitration_id=0x180 + 5, is_extended_id=False,
                               timestamp=t + 1e-4 * (k + 1),
                               data=(cycle * 7919 + k).to_bytes(4, "little") + b"\0\0\0\0")
                   for k in range(cycle % 3)]
        for m in frames:
            load.add(m)
            sent.append((m.timestamp, frame_bits(m.arbitration_id, m.data, False),
                         m.arbitration_id == 0x80))
    now = sent[-1][0]
    window = [(b, s) for t, b, s in sent if now - 1.0 <= t <= now + 1.0]
    busy = sum(b for b, _ in window) / 1_000_000
    syncs = sum(1 for _, s in window if s)
    figures = load.figures(now=now)
    assert figures["bus_load_percent"] == f"{100.0 * busy:.1f}"
    assert figures["frames_per_cycle"] == f"{len(window) / syncs:.2f}"
    assert figures["wire_ms_per_cycle"] == f"{1e3 * busy / syncs:.3f}"
    assert len(load._frames) == len(window)  # nothing older kept


def test_a_received_frame_no_classic_frame_can_be_is_left_out_and_said_once(caplog) -> None:
    """An interface may hand over an 11-bit id above 0x7FF (python-can's ``virtual`` bus
    passes anything): no classic CAN frame has it (ISO 11898-1: 11 identifier bits), so it
    has no length on the wire. It is left out of the figures, counted in ``not_counted`` and
    logged once; the frames around it are counted as if it had not come, wherever the queue
    is counted (the cycle thread, the diagnostics' reader, a sender past the queue limit)."""
    import logging

    import can

    from ssi_bridge.client.load import BusLoad

    t0 = 1.7e9
    clean, dirty = BusLoad(1_000_000), BusLoad(1_000_000)
    caplog.set_level(logging.WARNING, logger="ssi_bridge.client.load")
    for cycle in range(20):
        t = t0 + cycle * 1e-3
        frames = [can.Message(arbitration_id=0x80, is_extended_id=False, timestamp=t),
                  can.Message(arbitration_id=0x181, data=bytes(8), is_extended_id=False,
                              timestamp=t + 2e-4)]
        for m in frames:
            clean.received(m)
            dirty.received(m)
        dirty.received(can.Message(arbitration_id=0x800 + cycle, data=b"\1",
                                   is_extended_id=False, timestamp=t + 4e-4))
        if cycle == 10:
            dirty.count_queued()  # the cycle thread's count meets a bad frame: no error
    figures = dirty.figures(now=t0 + 0.05)
    assert figures == clean.figures(now=t0 + 0.05)
    assert figures["frames_per_cycle"] == "2.00"
    assert dirty.not_counted == 20
    said = [r for r in caplog.records if "not a classic CAN frame" in r.getMessage()]
    assert len(said) == 1, [r.getMessage() for r in said]
