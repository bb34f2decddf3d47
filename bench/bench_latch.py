"""Benchmark: where the simulated station latches its encoders, child process vs in-process.

A station latches every XN-1SSI module on the SYNC's wire time (``gateway/timebase``). Its
shaft turns at a constant ``VELOCITY``, so REG_SSI_POS of a cycle (its TPDO) gives back the
instant it was latched; minus the SYNC's wire time that is the latch error. The child's model
clock starts at an instant this process does not know, so each run's median error (a
constant: the clock's start, the line's delay to its first clock edge) is taken off and the
spread around it is reported, for both stations alike. Resolution: one encoder step, 1 /
(8192 steps/rev x VELOCITY) = 12 us.

* ``latch_error_p50_us`` / ``latch_error_p99_us``: |latch error - run median|, station child
  on udp_multicast; baseline: the station in-process on the virtual bus (lower is better)
* ``sync_receive_lag_p99_us``: kernel receive time minus wire time of the child run's SYNCs
  at a third bus on the group: what latching at the receive time would add (no baseline)

Both runs beside ``--burners`` CPU burners (default 2), one SYNC every ``PERIOD_S`` for
``MEASURE_S`` each, the next SYNC only once the cycle's TPDOs are in (no cycle overlaps).
Prints one JSON object per line and appends them to bench/results/latest.jsonl; never fails.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import signal
import statistics
import subprocess
import sys
import threading
import time
import traceback
from pathlib import Path

from benchlib import emit, emit_record, percentile, save

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
STATION_EXE = REPO / "install" / "ssi_bridge" / "lib" / "ssi_bridge" / "station"
#: shaft speed (rev/s) of the one joint (GENERIC encoder, 8192 steps/rev, 4096 turns)
VELOCITY = 10.0
PERIOD_S = 0.002
MEASURE_S = 3.0
BURNER = "while True: pass"
#: latch errors in us, kept to the nanosecond
_emit = functools.partial(emit, digits=6)


def _values(channel: str, interface: str) -> dict:
    return {"joints": ["j"], "j.slot": 1, "j.motion.velocity": VELOCITY,
            "bus.interface": interface, "bus.channel": channel}


def _spread_us(client: object, counts_per_rev: float) -> list[float]:
    """Run cycles on a connected client; |latch error - median| of each complete one (us)."""
    errors = []
    end = time.monotonic() + MEASURE_S
    while time.monotonic() < end:
        client.sync()
        if client.wait_cycle(0.1):
            sample = client.latest(1)
            if sample is not None:
                errors.append(sample.position / counts_per_rev / VELOCITY - sample.sync_time)
        time.sleep(PERIOD_S)
    if not errors:
        return []
    mid = statistics.median(errors)
    return [abs(e - mid) * 1e6 for e in errors]


def _counts_per_rev() -> float:
    from ssi_bridge.protocol.settings import station_settings
    from ssi_bridge.protocol.joint_encoder import count_factor
    from ssi_bridge.sim.gateway.station import joint_encoder

    joint = station_settings(_values("x", "virtual")).joints[0]
    encoder = joint_encoder(joint)
    return count_factor(encoder.config, joint.para1) * encoder.steps_per_rev


def _lags(channel: str, stop: threading.Event, out: list[float]) -> None:
    """Receive time minus wire time of every SYNC on ``channel`` (s), until ``stop``."""
    from ssi_bridge.base.udp_bus import open_udp_bus

    bus = open_udp_bus(channel)
    try:
        while not stop.is_set():
            msg = bus.recv(0.1)
            if msg is not None and msg.arbitration_id == 0x080:
                out.append(msg.timestamp - msg.wire_time)
    finally:
        bus.shutdown()


def child_run(counts_per_rev: float) -> tuple[list[float], list[float]]:
    from ssi_bridge.client.master import BridgeClient
    from ssi_bridge.protocol.settings import BusConfig
    from ssi_bridge.base.udp_bus import derive_channel

    channel = derive_channel(f"bench_latch_{os.getpid()}")
    args = [str(STATION_EXE), "--interface", "udp_multicast", "--channel", channel]
    for name, value in _values(channel, "udp_multicast").items():
        if not name.startswith("bus."):
            args += ["-p", f"{name}:={json.dumps(value)}"]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    stop, lags = threading.Event(), []
    watcher = threading.Thread(target=_lags, args=(channel, stop, lags), daemon=True)
    try:
        if "ready" not in (proc.stdout.readline() if proc.stdout else ""):
            raise RuntimeError("station child did not come up")
        watcher.start()
        from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
        client = BridgeClient(BusConfig(interface="udp_multicast", channel=channel), 1, 1, opener=wire_bus)
        client.connect()
        try:
            spread = _spread_us(client, counts_per_rev)
        finally:
            client.close()
    finally:
        stop.set()
        proc.send_signal(signal.SIGINT)
        proc.wait(10)
    watcher.join(2)
    return spread, [lag * 1e6 for lag in lags]


def inprocess_run(counts_per_rev: float) -> list[float]:
    from ssi_bridge.client.master import BridgeClient
    from ssi_bridge.protocol.settings import BusConfig
    from ssi_bridge.protocol.settings import station_settings
    from ssi_bridge.sim.gateway.station import Station

    channel = f"bench_latch_virtual_{os.getpid()}"
    station = Station(station_settings(_values(channel, "virtual")))
    station.start()
    from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
    client = BridgeClient(BusConfig(channel=channel), 1, 1, opener=wire_bus)
    try:
        client.connect()
        return _spread_us(client, counts_per_rev)
    finally:
        client.close()
        station.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--burners", type=int, default=2, help="CPU burners beside (default 2)")
    burners_n = parser.parse_args().burners
    records: list[dict] = []
    burners = [subprocess.Popen([sys.executable, "-c", BURNER]) for _ in range(burners_n)]
    try:
        counts = _counts_per_rev()
        child, lags = child_run(counts)
        inproc = inprocess_run(counts)
        load = f"{burners_n} CPU burner(s) beside"
        for q, name in ((0.5, "p50"), (0.99, "p99")):
            _emit(records, f"latch_error_{name}_us", percentile(child, q), "us", percentile(inproc, q),
                  f"|latch - SYNC wire time - run median|, {len(child)} cycles: station child "
                  f"on udp_multicast vs {len(inproc)} in-process on virtual; {load}; lower "
                  "is better")
        _emit(records, "sync_receive_lag_p99_us", percentile(lags, 0.99), "us",
              note=f"kernel receive minus wire time of {len(lags)} SYNCs on udp_multicast: "
                   f"what latching at the receive time would add; {load}")
    except Exception as err:  # noqa: BLE001 - a bench never fails the run
        emit_record(records, {"metric": "latch", "error": f"{type(err).__name__}: {err}",
                              "note": traceback.format_exc(limit=3)[-800:]})
    finally:
        for proc in burners:
            proc.kill()
            proc.wait()
    save(records)


if __name__ == "__main__":
    sys.exit(main())
