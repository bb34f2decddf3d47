"""Benchmark: the simulated station as a process of its own vs in the node's process.

* ``station_startup_s``: spawn of the ``station`` program until its boot-up message is on the
  udp_multicast bus; baseline: building and starting the same station in this process on the
  virtual bus until its boot-up arrives (lower is better)
* ``sync_tpdo_p50_us`` / ``sync_tpdo_p99_us``: our master's SYNC until every TPDO of the cycle
  arrived, 1 slot, station child on udp_multicast; baseline: the station in-process on the
  virtual bus (lower is better)
* ``node_rate_hz``, ``node_cpu_s_per_s``, ``station_cpu_s_per_s``: the installed node at
  1 kHz with one joint, ``simulation.transport: udp_multicast`` (station child) against
  ``virtual`` (in-process), measured over the same window length in the same run; cycle
  rate from the joint_states stamps a subscriber in this process receives, CPU from
  /proc/<pid>/stat (node and its station child apart)

Prints one JSON object per line and appends them to bench/results/latest.jsonl; never fails.
"""

from __future__ import annotations

import functools
import os
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchlib import cpu_seconds, emit, percentile, run_parts, save

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
NODE_EXE = REPO / "install" / "ssi_bridge" / "lib" / "ssi_bridge" / "ssi_bridge_node"
STATION_EXE = REPO / "install" / "ssi_bridge" / "lib" / "ssi_bridge" / "station"
#: figures in s and us kept to the microsecond
_emit = functools.partial(emit, digits=6)
RATE_HZ = 1000.0
WARMUP_S = 2.0
MEASURE_S = 5.0
ROUNDS = 1000


def startup(records: list[dict]) -> None:
    from ssi_bridge.sim.supervisor.boot import BootWatch
    from ssi_bridge.protocol.settings import BusConfig
    from ssi_bridge.sim.gateway.bus import open_bus
    from ssi_bridge.base.udp_bus import derive_channel
    from ssi_bridge.protocol.settings import station_settings
    from ssi_bridge.sim.gateway.station import Station

    child, inproc = [], []
    for k in range(3):
        channel = derive_channel(f"bench_station_{os.getpid()}_{k}")
        cfg = BusConfig(interface="udp_multicast", channel=channel)
        watch = open_bus(cfg)
        t0 = time.monotonic()
        proc = subprocess.Popen([str(STATION_EXE), "--interface", "udp_multicast",
                                 "--channel", channel], stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        try:
            BootWatch(watch, 1).wait(30.0)
            child.append(time.monotonic() - t0)
        finally:
            watch.shutdown()
            proc.send_signal(signal.SIGINT)
            proc.wait(10)
        vcfg = BusConfig(channel=f"bench_station_{os.getpid()}_{k}")
        watch = open_bus(vcfg)
        t0 = time.monotonic()
        station = Station(station_settings({"bus.channel": vcfg.channel}))
        station.start()
        BootWatch(watch, 1).wait(30.0)
        inproc.append(time.monotonic() - t0)
        watch.shutdown()
        station.stop()
    _emit(records, "station_startup_s", statistics.median(child), "s",
          statistics.median(inproc), "spawn -> boot-up on udp_multicast (median of 3) vs "
          "in-process start on virtual")


def round_trip(records: list[dict]) -> None:
    from ssi_bridge.client.master import BridgeClient
    from ssi_bridge.protocol.settings import BusConfig
    from ssi_bridge.base.udp_bus import derive_channel
    from ssi_bridge.protocol.settings import station_settings
    from ssi_bridge.sim.gateway.station import Station

    def measure(client: BridgeClient) -> list[float]:
        out = []
        for _ in range(ROUNDS):
            t0 = time.perf_counter()
            client.sync()
            if client.wait_cycle(0.1):
                out.append((time.perf_counter() - t0) * 1e6)
            time.sleep(0.001)
        return out

    channel = derive_channel(f"bench_rt_{os.getpid()}")
    proc = subprocess.Popen([str(STATION_EXE), "--interface", "udp_multicast", "--channel",
                             channel], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    try:
        proc.stdout.readline()
        from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
        client = BridgeClient(BusConfig(interface="udp_multicast", channel=channel), 1, 1, opener=wire_bus)
        client.connect()
        udp = measure(client)
        client.close()
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(10)
    vchan = f"bench_rt_virtual_{os.getpid()}"
    station = Station(station_settings({"bus.channel": vchan}))
    station.start()
    from ssi_bridge.sim.gateway.bus import open_bus as wire_bus
    client = BridgeClient(BusConfig(channel=vchan), 1, 1, opener=wire_bus)
    client.connect()
    virt = measure(client)
    client.close()
    station.stop()
    for q, name in ((0.5, "p50"), (0.99, "p99")):
        _emit(records, f"sync_tpdo_{name}_us", percentile(udp, q), "us", percentile(virt, q),
              f"SYNC -> all TPDOs of the cycle, 1 slot, {len(udp)}/{ROUNDS} cycles complete; "
              "station child on udp_multicast vs in-process on virtual")


def node_run(transport: str, domain: int) -> dict:
    """Run the node at 1 kHz with ``transport``; rate, missed cycles and CPU in the window."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState

    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    tmp = Path(tempfile.mkdtemp(prefix="bench_station_"))
    pfile = tmp / "p.yaml"
    pfile.write_text("/**:\n  ros__parameters:\n"
                     f"    publish_rate: {RATE_HZ}\n    simulation.transport: {transport}\n"
                     f"    bus.channel: bench_{os.getpid()}_{transport}\n")
    node = subprocess.Popen([str(NODE_EXE), "--ros-args", "--params-file", str(pfile)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    sub_node = rclpy.create_node("bench_station_sub", context=ctx)
    stamps: list[int] = []
    sub_node.create_subscription(JointState, "/joint_states", lambda m: stamps.append(
        m.header.stamp.sec * 10**9 + m.header.stamp.nanosec), 100)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(sub_node)
    try:
        deadline = time.monotonic() + 30
        while not stamps and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.05)
        end = time.monotonic() + WARMUP_S
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.01)
        kids = [int(c) for t in Path(f"/proc/{node.pid}/task").iterdir()
                for c in (t / "children").read_text().split()]
        cpu0 = cpu_seconds(node.pid), sum(cpu_seconds(k) for k in kids)
        first = len(stamps)
        t0 = time.monotonic()
        while time.monotonic() < t0 + MEASURE_S:
            ex.spin_once(timeout_sec=0.01)
        window = time.monotonic() - t0
        cpu1 = cpu_seconds(node.pid), sum(cpu_seconds(k) for k in kids)
        got = stamps[first:]
    finally:
        node.send_signal(signal.SIGINT)
        node.wait(15)
        ex.shutdown()
        sub_node.destroy_node()
        ctx.try_shutdown()
    gaps = [(b - a) / 1e9 for a, b in zip(got, got[1:])]
    missed = sum(round(g * RATE_HZ) - 1 for g in gaps if g > 1.5 / RATE_HZ)
    span = (got[-1] - got[0]) / 1e9 if len(got) > 1 else window
    return {"rate": (len(got) - 1) / span if span > 0 else 0.0, "missed": missed,
            "cycles": len(got), "node_cpu": (cpu1[0] - cpu0[0]) / window,
            "station_cpu": (cpu1[1] - cpu0[1]) / window}


def node_compare(records: list[dict]) -> None:
    domain = random.Random(os.getpid()).randrange(150, 230)
    child = node_run("udp_multicast", domain)
    inproc = node_run("virtual", domain)
    _emit(records, "node_rate_hz", child["rate"], "Hz", inproc["rate"],
          "1 kHz, 1 joint: station child (udp_multicast) vs in-process (virtual); higher is "
          "better")
    _emit(records, "node_cycles_missed", child["missed"], "cycles", inproc["missed"] or None,
          f"stamp gaps over {MEASURE_S:g} s (in-process: {inproc['missed']})")
    _emit(records, "node_cpu_s_per_s", child["node_cpu"], "s/s", inproc["node_cpu"],
          "node process only; in-process baseline includes the station")
    _emit(records, "node_plus_station_cpu_s_per_s", child["node_cpu"] + child["station_cpu"],
          "s/s", inproc["node_cpu"], "node + station child vs node with station in-process")


def main() -> None:
    records: list[dict] = []
    run_parts(records, (startup, round_trip, node_compare))
    save(records)


if __name__ == "__main__":
    sys.exit(main())
