"""Benchmark: the CANopen path between the bridge client and the simulated XN-GW-CANOPEN.

* register read through the 000 handshake, and a plain SDO upload through the client, each
  as a ratio to a bare canopen LocalNode/RemoteNode SDO round trip measured in the same run
  (lower ratio = less overhead);
* PDO cycle with 8 slots driven at the highest rate the simulated 1 Mbit/s wire allows
  (docs/canopen.md table, 480 Hz; 8 slots at 1 kHz fit no CAN bit rate): achieved SYNC rate
  (ratio to that rate, higher is better) and missed cycles (a cycle whose TPDOs did not all arrive before the next SYNC);
* CPU per cycle (``cycle_cpu_us``, 1 and 8 slots): ``time.process_time()`` (all threads of
  the process: client, gateway, bus) of ``sync()`` -> ``wait_cycle()`` back to back, with
  real encoders on SSI lines behind the modules as the ROS node wires them; the goal is a
  share of the 1 ms period small enough to leave the node room (<= 250 / 500 us).

Prints one JSON object per line and appends them to bench/results/latest.jsonl; never fails.
``--cpu`` runs only the CPU-per-cycle part; ``--cpu --runs N`` repeats it N times (a fresh
station each time) and reports the median of the N means, the runs in the note: the box is
shared and one run can be off by 1.5x.
"""

from __future__ import annotations

import logging
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchlib import emit as _emit  # noqa: E402
from benchlib import emit_record, save  # noqa: E402

NODE_ID = 11
ROUNDS = 300
#: the PDO cycle's wire: 8 slots at 1 Mbit/s, at the highest rate that fits (wire.py)
CYCLE_BITRATE = 1_000_000
CYCLE_SECONDS = 2.0
CPU_CYCLES = 2000
#: CPU budget per SYNC cycle (us) for 1 and 8 slots, the 1 kHz node's share for the bus
CPU_GOAL_US = {1: 250.0, 8: 500.0}


def _per_call_us(fn, rounds: int) -> float:
    fn()
    t0 = time.perf_counter()
    for _ in range(rounds):
        fn()
    return (time.perf_counter() - t0) / rounds * 1e6


def bare_sdo_us() -> float:
    """A bare canopen LocalNode/RemoteNode SDO upload of a UNSIGNED32 on the virtual bus."""
    import canopen

    from ssi_bridge.base.od import build_dictionary

    server, master = canopen.Network(), canopen.Network()
    server.NOTIFIER_CYCLE = master.NOTIFIER_CYCLE = 0.05
    server.connect(interface="virtual", channel="bench-bare")
    master.connect(interface="virtual", channel="bench-bare")
    try:
        server.add_node(canopen.LocalNode(NODE_ID, build_dictionary(NODE_ID, 1)))
        remote = canopen.RemoteNode(NODE_ID, build_dictionary(NODE_ID, 1))
        master.add_node(remote)
        return _per_call_us(lambda: remote.sdo.upload(0x1000, 0), ROUNDS)
    finally:
        master.disconnect()
        server.disconnect()


def bridge_us(records: list[dict], baseline: float) -> None:
    from ssi_bridge.client.master import BridgeClient
    from ssi_bridge.protocol.settings import BusConfig
    from ssi_bridge.sim.gateway.gateway import XnGateway
    from ssi_bridge.protocol.registers import Reg
    from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

    config = BusConfig(channel="bench-bridge", node_id=NODE_ID)
    with XnGateway(config, NODE_ID, [Xn1Ssi(None, slot=1)]):
        from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
        with BridgeClient(config, NODE_ID, 1, assist_after=0.0005, opener=wire_bus) as client:
            _emit(records, "bus_sdo_upload_us", _per_call_us(
                lambda: client.read_object(0x6820, 1), ROUNDS), "us", baseline)
            _emit(records, "bus_register_read_handshake_us", _per_call_us(
                lambda: client.read_register(1, Reg.REG_MAGIC_NO), ROUNDS), "us", baseline)
            _emit(records, "bus_register_write_handshake_us", _per_call_us(
                lambda: client.write_register(1, Reg.REG_CMP1, 1), ROUNDS // 3), "us", baseline)


def pdo_cycle(records: list[dict]) -> None:
    from ssi_bridge.client.master import BridgeClient
    from ssi_bridge.protocol.settings import BusConfig
    from ssi_bridge.sim.gateway.gateway import XnGateway
    from ssi_bridge.protocol.readout import LineReadout
    from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

    class Reader:
        def read(self, t: float, n_bits: int, bit_rate_hz: float) -> LineReadout:
            return LineReadout(latch_time=t, n_bits=n_bits, data=int(t * 1e4) & 0xFFFFFF)

    from ssi_bridge.protocol.wire import max_cycle_rate
    cycle_hz = max_cycle_rate(8, CYCLE_BITRATE)
    config = BusConfig(channel="bench-cycle", node_id=NODE_ID, bitrate=CYCLE_BITRATE)
    modules = [Xn1Ssi(Reader(), slot=s) for s in range(1, 9)]
    with XnGateway(config, NODE_ID, modules):
        from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
        with BridgeClient(config, NODE_ID, 8, opener=wire_bus) as client:
            period = 1.0 / cycle_hz
            n = int(CYCLE_SECONDS * cycle_hz)
            missed = 0
            t0 = time.perf_counter()
            next_t = t0
            for _ in range(n):
                client.sync()
                next_t += period
                if not client.wait_cycle(max(next_t - time.perf_counter(), 0.0)):
                    missed += 1
                while time.perf_counter() < next_t:
                    pass
            rate = n / (time.perf_counter() - t0)
    _emit(records, "bus_pdo_cycle_8_slots_rate", rate, "cycles/s", cycle_hz,
          note=f"8 slots at {cycle_hz:g} Hz on the simulated {CYCLE_BITRATE} bit/s wire")
    _emit(records, "bus_pdo_cycle_8_slots_missed", float(missed), "cycles")
    _emit(records, "bus_pdo_cycle_8_slots_missed_fraction", missed / n, "fraction")


def cycle_cpu(records: list[dict], slots: int, runs: int = 1) -> None:
    """CPU time per sync -> all TPDOs received, gateway + client + modules in one process."""
    results = [_cycle_cpu_run(slots, f"bench-cpu-{slots}-{run}") for run in range(runs)]
    results.sort(key=lambda r: r[0])
    mean_us, p50_us, p99_us, incomplete = results[len(results) // 2]
    runs_note = (f"median of {runs} runs ({', '.join(f'{r[0]:.0f}' for r in results)} us), "
                 if runs > 1 else "")
    note = (f"process CPU per sync -> all TPDOs received, {slots} slot(s), {CPU_CYCLES} "
            f"cycles back to back; {runs_note}p50 {p50_us:.0f} us, p99 {p99_us:.0f} us, "
            f"{incomplete} incomplete; baseline = goal; lower is better")
    _emit(records, f"bus_cycle_cpu_us_{slots}_slot{'s' if slots > 1 else ''}", mean_us, "us",
          CPU_GOAL_US[slots], note)


def _cycle_cpu_run(slots: int, channel: str) -> tuple[float, float, float, int]:
    """One measurement: (mean, p50, p99 in us, incomplete cycles)."""
    from ssi_bridge.client.master import BridgeClient
    from ssi_bridge.sim.encoder.encoder import make_encoder
    from ssi_bridge.sim.encoder.motion import Sine
    from ssi_bridge.protocol.settings import BusConfig
    from ssi_bridge.sim.gateway.gateway import XnGateway
    from ssi_bridge.sim.line.line import LineConfig, SsiLine
    from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

    config = BusConfig(channel=channel, node_id=NODE_ID)
    modules = [Xn1Ssi(SsiLine(make_encoder("GENERIC", Sine(2.0, 1.0, offset=10.0 + s)),
                              LineConfig(check_cable_table=False)), slot=s)
               for s in range(1, slots + 1)]
    with XnGateway(config, NODE_ID, modules):
        from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
        with BridgeClient(config, NODE_ID, slots, opener=wire_bus) as client:
            for _ in range(50):  # warm-up: first samples, caches
                client.sync()
                client.wait_cycle(0.05)
            incomplete = 0
            per_cycle = []
            clock = time.process_time
            t0 = clock()
            for _ in range(CPU_CYCLES):
                c0 = clock()
                client.sync()
                if not client.wait_cycle(0.05):
                    incomplete += 1
                per_cycle.append(clock() - c0)
            total = clock() - t0
    per_cycle.sort()
    return (total / CPU_CYCLES * 1e6, per_cycle[len(per_cycle) // 2] * 1e6,
            per_cycle[int(len(per_cycle) * 0.99)] * 1e6, incomplete)


def main() -> None:
    logging.basicConfig(level=logging.ERROR)
    records: list[dict] = []
    args = sys.argv[1:]
    cpu_only = "--cpu" in args
    runs = int(args[args.index("--runs") + 1]) if "--runs" in args else 1
    try:
        if not cpu_only:
            baseline = bare_sdo_us()
            _emit(records, "bus_bare_canopen_sdo_upload_us", baseline, "us")
            bridge_us(records, baseline)
            pdo_cycle(records)
        for slots in (1, 8):
            cycle_cpu(records, slots, runs)
    except Exception as err:  # noqa: BLE001 - a benchmark reports, it never fails the run
        emit_record(records, {"metric": "bus_benchmark_error", "error": repr(err)})
    save(records)


if __name__ == "__main__":
    main()
