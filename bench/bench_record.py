"""Benchmark of the record/ stage (``make bench ONLY=record``); reports, never fails.

* ``record_write_throughput``: JointState + Status messages/s through BagRecorder (clean CDR,
  zstd chunks), baseline: the plain ``mcap_ros2`` writer on the same content in the same run.
* ``replay_timing_error_p50/p99``: lateness of replayed publications against the recorded
  timestamps, 1 s of 1 kHz JointState played through rclpy publishers.
* ``cpu_seconds_per_second`` is a helper the lead can use for recording on vs off in the node.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import benchlib

T0 = 1_700_000_000_000_000_000
N = 5000


def emit(metric: str, value: float, unit: str, baseline: float | None = None,
         ratio_note: str = "") -> None:
    """Print one figure and append it to bench/results/latest.jsonl at once."""
    rows: list[dict] = []
    benchlib.emit(rows, metric, value, unit, baseline, ratio_note)
    benchlib.save(rows)


def cpu_seconds_per_second(work: Callable[[], None], seconds: float) -> float:
    """Process CPU time per wall second while ``work`` runs repeatedly for ``seconds``."""
    wall0, cpu0 = time.monotonic(), time.process_time()
    while time.monotonic() - wall0 < seconds:
        work()
    return (time.process_time() - cpu0) / (time.monotonic() - wall0)


def bench_write(tmp: Path) -> None:
    from mcap_ros2.writer import Writer as Ros2Writer
    from sensor_msgs.msg import JointState

    from ssi_bridge.record.bag import BagRecorder
    from ssi_bridge.record.schema import build_schema
    from ssi_bridge_msgs.msg import ChannelStatus, Status

    joints = JointState(name=["a", "b"], position=[1.0, 2.0], velocity=[0.1, 0.2])
    status = Status(channels=[ChannelStatus(joint="a"), ChannelStatus(joint="b")])
    rec = BagRecorder.open(tmp / "ours")
    rec.add_topic("/joint_states", "sensor_msgs/msg/JointState")
    rec.add_topic("/status", "ssi_bridge_msgs/msg/Status")
    start = time.perf_counter()
    for i in range(N):
        rec.write("/joint_states", joints, T0 + i)
        rec.write("/status", status, T0 + i)
    rec.close()
    ours = 2 * N / (time.perf_counter() - start)

    js_schema, st_schema = (build_schema("sensor_msgs/msg/JointState"),
                            build_schema("ssi_bridge_msgs/msg/Status"))
    js_dict = {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
               "name": ["a", "b"], "position": [1.0, 2.0], "velocity": [0.1, 0.2], "effort": []}
    ch = {f: 0 for f in ChannelStatus.get_fields_and_field_types()}
    st_dict = {"header": js_dict["header"],
               "channels": [dict(ch, joint="a", process_input=[0] * 8),
                            dict(ch, joint="b", process_input=[0] * 8)]}
    with open(tmp / "plain.mcap", "wb") as f:
        writer = Ros2Writer(f)
        s1 = writer.register_msgdef(js_schema.name, js_schema.text)
        s2 = writer.register_msgdef(st_schema.name, st_schema.text)
        start = time.perf_counter()
        for i in range(N):
            writer.write_message("/joint_states", s1, js_dict, T0 + i, T0 + i)
            writer.write_message("/status", s2, st_dict, T0 + i, T0 + i)
        writer.finish()
        plain = 2 * N / (time.perf_counter() - start)
    emit("record_write_throughput", ours, "messages/s", plain,
         "higher is better; baseline = plain mcap_ros2 writer (dict messages)")


def bench_replay(tmp: Path) -> None:
    import rclpy
    from sensor_msgs.msg import JointState

    from ssi_bridge.record.bag import BagRecorder
    from ssi_bridge.record.reader import Bag
    from ssi_bridge.record.bag_replay import Player, ReplayOptions

    rec = BagRecorder.open(tmp / "replay")
    rec.add_topic("/bench_joint_states", "sensor_msgs/msg/JointState")
    for i in range(1000):
        rec.write("/bench_joint_states", JointState(position=[i * 1e-3]), T0 + i * 1_000_000)
    rec.close()
    rclpy.init()
    try:
        node = rclpy.create_node("bench_replay")
        with Bag(tmp / "replay") as bag:
            player = Player(node, bag, ReplayOptions())
            player.play_once()
        late = np.array(player.lateness) * 1e6
        emit("replay_timing_error_p50", float(np.percentile(late, 50)), "us",
             ratio_note="lower is better; publish time - recorded schedule")
        emit("replay_timing_error_p99", float(np.percentile(late, 99)), "us",
             ratio_note="lower is better")
        node.destroy_node()
    finally:
        rclpy.try_shutdown()


def bench_node_recording(tmp: Path) -> None:
    """The node's CPU at 1 kHz (1 encoder) with recording on vs off, measured in one run.

    Uses the node benchmark's harness (installed node + subscriber process, node_measure.py);
    the recording also builds ~/status every cycle, which is part of what recording costs.
    """
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from node_cases import NODE_NS, node_cmd
    from node_measure import measure
    from node_procs import dds_env, domain_id

    domain = domain_id()
    env = dds_env(domain)
    topic = f"{NODE_NS}/joint_states"
    off = measure("rec_off", node_cmd(1, domain, tmp), topic, env, tmp)
    on = measure("rec_on", node_cmd(1, domain, tmp, {
        "record.enabled": True, "record.root": str(tmp / "sessions")}), topic, env, tmp)
    emit("node_recording_cpu_s_per_s", on["cpu_s_per_s"], "s/s", off["cpu_s_per_s"],
         "node process CPU per second at 1 kHz with recording on; baseline: recording off, "
         "same run; lower is better")
    emit("node_recording_rate_hz", on["rate_hz"], "Hz", off["rate_hz"],
         "joint_states received per second with recording on; baseline: off; higher is better")


def main() -> int:
    with tempfile.TemporaryDirectory(prefix="bench_record_") as tmp:
        for bench in (bench_write, bench_replay, bench_node_recording):
            try:
                bench(Path(tmp))
            except Exception as err:  # a benchmark reports, it never fails the run
                print(json.dumps({"metric": bench.__name__, "error": repr(err)}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
