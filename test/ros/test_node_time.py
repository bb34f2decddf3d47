"""header.stamp in the one time base (docs/canopen.md "Time and the wire"): strictly
increasing, the SYNC's wire time, and with use_sim_time nothing before the first /clock."""

from __future__ import annotations

import time

import pytest
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState


def test_stamps_are_wire_times_and_strictly_increasing(running, probe):
    node = running({"publish_rate": 200.0})
    msgs = probe.subscribe(JointState, node.topic("joint_states"), qos=500)
    probe.wait_for(lambda: len(msgs) > 200, 20.0, "200 joint_states", node)
    got = list(msgs)
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in got]
    assert all(b > a for a, b in zip(stamps, stamps[1:])), "header.stamp not increasing"
    # ROS system time is wire time: each stamp (the SYNC on the wire) lies in the past of
    # the moment the message was received, by less than a second on this host
    now_ns = time.time_ns()
    assert all(0 < now_ns - s < 60 * 10**9 for s in stamps)


def test_use_sim_time_without_clock_publishes_nothing_then_follows_clock(start_node, probe):
    node = start_node({"use_sim_time": True, "publish_rate": 100.0})
    msgs = probe.subscribe(JointState, node.topic("joint_states"), qos=100)
    probe.wait_for(lambda: "waiting for /clock" in node.log(), 30.0,
                   "the node saying it waits for /clock", node)
    assert node.log().count("waiting for /clock") == 1
    time.sleep(0.5)  # the node cycles meanwhile (100 Hz): none of its cycles may publish
    assert msgs == [], f"{len(msgs)} joint_states published without /clock"
    pub = probe.node.create_publisher(Clock, "/clock", 10)
    sim_s = 1000

    def tick() -> None:
        nonlocal sim_s
        sim_s += 1
        pub.publish(Clock(clock=__import__("builtin_interfaces.msg").msg.Time(sec=sim_s)))

    timer = probe.node.create_timer(0.05, tick)
    try:
        probe.wait_for(lambda: len(msgs) > 5, 20.0, "joint_states after /clock", node)
    finally:
        probe.node.destroy_timer(timer)
    for _, m in msgs:
        sec = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
        assert 999 < sec < sim_s + 2, sec
    assert node.log().count("waiting for /clock") == 1


@pytest.mark.parametrize("transport", ["virtual", "udp_multicast"])
def test_a_rate_the_wire_cannot_carry_is_warned_and_runs_complete_cycles_at_the_rate_that_does(
        running, probe, transport, tmp_path):
    """8 slots at 1 kHz on 500 kbit/s: one cycle takes ~3 ms of wire (docs/canopen.md).

    The start warns with the highest rate that fits (the default start, one joint at 100 Hz,
    warns nothing: test_node_logs.py). (Merged: a test of its own before, on 4 slots.)

    The master does not send a SYNC while the cycle's TPDOs are still on the wire, so the
    cycles it runs are complete and published, and the measured bus load stays physical.
    The published joint_states are counted in the node's own recording: a subscriber on a
    loaded machine may lose messages (the publisher keeps the last 10), the node's count not.
    """
    from diagnostic_msgs.msg import DiagnosticArray

    from ssi_bridge.protocol import wire
    from ssi_bridge.record.reader import Bag

    node = running({"joints": [f"j{i}" for i in range(1, 9)], "publish_rate": 1000.0,
                    "bus.bitrate": 500_000, "simulation.transport": transport,
                    "diagnostics_period": 0.5, "record.enabled": True,
                    "record.root": str(tmp_path / "rec"), "record.path": "cycles"})
    diags = probe.subscribe(DiagnosticArray, "/diagnostics", qos=100)
    best = wire.max_cycle_rate(8, 500_000)
    assert f"the highest rate that fits is {best:g} Hz" in node.log(), node.log()[-2000:]
    assert "publish_rate 1000 Hz does not fit the CAN wire" in node.log()
    time.sleep(2.0)  # start-up and the load meter's first second
    window = time.time_ns()  # header.stamp is the SYNC's wire time: ROS (system) time
    time.sleep(4.0)
    window = (window, time.time_ns())
    time.sleep(0.6)  # the diagnostics of the window's last second
    # the bus statuses whose 1 s rate window lies inside ours: on a loaded machine the rate
    # moves from second to second, so one status alone may not be the window's rate
    inside = [(arr.header.stamp.sec * 10**9 + arr.header.stamp.nanosec, st)
              for _, arr in list(diags) for st in arr.status if st.name.endswith(": bus")]
    inside = [st for t, st in inside if window[0] + 10**9 <= t <= window[1] + 5 * 10**8]
    assert inside, "no bus status in the window"
    assert node.stop() == 0, node.log()[-3000:]  # closes the recording
    with Bag(next((tmp_path / "rec" / "cycles").glob("*.mcap"))) as bag:
        stamps = [r.publish_time for _, r in bag.messages([node.topic("joint_states")])]
    published = sum(window[0] <= s < window[1] for s in stamps) / ((window[1] - window[0]) / 1e9)
    values = {kv.key: kv.value for kv in inside[-1].values}
    rates = [float(kv.value) for st in inside for kv in st.values if kv.key == "achieved_rate_hz"]
    achieved = sum(rates) / len(rates)
    wire_rate = 1.0 / wire.cycle_seconds(8, 500_000)  # ~340 Hz: no more cycles fit a second
    assert achieved <= wire_rate, values
    assert float(values["bus_load_percent"]) <= 100.0, values
    # every cycle run is complete: joint_states carries the cycle rate (before: 45 of 469 Hz
    # with the station child, 189 of 314 Hz in-process)
    assert published >= 0.8 * achieved > 0, (published, values)
